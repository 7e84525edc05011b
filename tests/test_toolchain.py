"""The compile-and-cache API (symtrack.toolchain): the key follows the sources and the flags, a second
build is a cache hit, an interrupted build leaves no half-written artefact, a missing or failing
compiler gives a clear error, the log tells the user what is compiling. (Two processes building
one key at once: tests/test_cache_concurrency.py.)"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from symtrack import toolchain as build
from symtrack.codegen.standalone import build_program
from symtrack.control.solver_cache import problem_key
from symtrack.foundations.errors import SimulationError
from symtrack.toolchain import cache as build_cache

pytestmark = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler")

REPO = Path(__file__).resolve().parent.parent
ANSWER = b'__attribute__((visibility("default"))) int symtrack_answer(void) { return %d; }\n'


def _spec(root: Path, value: int, calls: list | None = None, **kw) -> build.BuildSpec:
    source = ANSWER % value

    def sources():
        if calls is not None:
            calls.append(value)
        return {"answer.c": source}

    return build.BuildSpec(kind="answer", key=build.digest(source, " ".join(kw.get("cflags") or ())),
                           output="libanswer.so", sources=sources, what=f"the answer {value}", root=root, **kw)


def test_a_second_build_is_a_cache_hit_and_the_key_follows_the_sources(tmp_path, caplog, monkeypatch):
    monkeypatch.delenv(build.OPT_LEVEL_ENV, raising=False)  # the folder names of the tuned flags
    calls: list[int] = []
    n0 = len(build.builds)
    with caplog.at_level(logging.INFO, logger="symtrack.toolchain"):
        so = build.build(_spec(tmp_path, 42, calls))
    assert ctypes.CDLL(str(so)).symtrack_answer() == 42
    assert so.parent.parent == tmp_path and so.parent.name == f"answer-{build.digest(ANSWER % 42, '')[:16]}"
    # no temporary folder left; the artefact's size and SHA-256 recorded beside it
    assert sorted(p.name for p in so.parent.iterdir()) == [".lock", "libanswer.so", "libanswer.so.sha256.json"]
    assert any(f"compiling the answer 42 (first run; cached in {so.parent})" in r.getMessage()
               for r in caplog.records)
    assert len(build.builds) == n0 + 1 and build.builds[-1].path == so and build.builds[-1].kind == "answer"
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="symtrack.toolchain"):
        assert build.build(_spec(tmp_path, 42, calls)) == so  # the hit: no sources made, no compiler, no log
    assert calls == [42] and len(build.builds) == n0 + 1 and not caplog.records
    other = build.build(_spec(tmp_path, 7, calls))  # other sources: another entry
    assert other.parent != so.parent and ctypes.CDLL(str(other)).symtrack_answer() == 7
    assert calls == [42, 7]


def test_the_opt_level_overrides_the_flags_but_not_a_tuned_build_s_and_has_its_own_entries(tmp_path, monkeypatch):
    seen = []
    real_run = build_cache.subprocess.Popen

    def spy(cmd, *a, **k):
        if "-c" in cmd:  # the compile commands (not the link's)
            seen.append(cmd)
        return real_run(cmd, *a, **k)

    monkeypatch.setattr(build_cache.subprocess, "Popen", spy)
    monkeypatch.delenv(build.OPT_LEVEL_ENV, raising=False)
    monkeypatch.delenv(build.TUNED_OPT_LEVEL_ENV, raising=False)
    tuned_flags = build.build(_spec(tmp_path, 3, cflags=("-O2", "-Wall")))
    assert "-O2" in seen[-1] and "-O0" not in seen[-1]
    monkeypatch.setenv(build.OPT_LEVEL_ENV, "0")
    assert build.opt_level() == 0
    at_0 = build.build(_spec(tmp_path, 3, cflags=("-O2", "-Wall")))
    assert "-O0" in seen[-1] and "-O2" not in seen[-1] and "-Wall" in seen[-1]
    assert at_0.parent.name == tuned_flags.parent.name + "-O0" and ctypes.CDLL(str(at_0)).symtrack_answer() == 3
    default = build.build(_spec(tmp_path, 4))  # the default flags (no cflags) too
    assert "-O0" in seen[-1] and "-O2" not in seen[-1]
    tuned = build.build(_spec(tmp_path, 5, cflags=("-O2",), tuned=True))  # a tuned build keeps its flags
    assert "-O2" in seen[-1] and "-O0" not in seen[-1] and not tuned.parent.name.endswith("-O0")
    assert default.exists() and tuned.exists()
    # the tuned builds' own level: their other flags kept, an entry of its own
    monkeypatch.setenv(build.TUNED_OPT_LEVEL_ENV, "1")
    assert build.opt_level(tuned=True) == 1 and build.opt_level() == 0
    tuned_1 = build.build(_spec(tmp_path, 5, cflags=("-O2", "-Wall"), tuned=True))
    assert "-O1" in seen[-1] and "-O2" not in seen[-1] and "-Wall" in seen[-1]
    assert tuned_1.parent.name.endswith("-O1") and ctypes.CDLL(str(tuned_1)).symtrack_answer() == 5
    monkeypatch.setenv(build.TUNED_OPT_LEVEL_ENV, "3x")
    with pytest.raises(SimulationError, match="SYMTRACK_TUNED_OPT_LEVEL = '3x' is not one of 0, 1, 2, 3"):
        build.opt_level(tuned=True)
    monkeypatch.setenv(build.OPT_LEVEL_ENV, "fast")
    with pytest.raises(SimulationError, match="SYMTRACK_OPT_LEVEL = 'fast' is not one of 0, 1, 2, 3"):
        build.opt_level()


def test_the_key_follows_the_flags(tmp_path):
    a = build.build(_spec(tmp_path, 1, cflags=("-O0",)))
    b = build.build(_spec(tmp_path, 1, cflags=("-O2",)))
    assert a.parent != b.parent and a.exists() and b.exists()
    # the callers' keys: the MPC's (flags in its key) and the standalone programs'
    assert problem_key(b"problem", ("-O1",)) != problem_key(b"problem", ("-O2",))
    main = tmp_path / "src" / "main.c"
    main.parent.mkdir()
    main.write_text('#include <stdio.h>\n#include "value.h"\nint main(void) { printf("%d\\n", VALUE); return 0; }\n')
    header = tmp_path / "src" / "value.h"
    header.write_text("#define VALUE 5\n")
    os.environ["SYMTRACK_CACHE"], saved = str(tmp_path / "cache"), os.environ.get("SYMTRACK_CACHE")
    try:
        p1 = build_program("toy", main, [header], ("-O0",))
        assert build_program("toy", main, [header], ("-O0",)) == p1
        p2 = build_program("toy", main, [header], ("-O1",))
        header.write_text("#define VALUE 6\n")
        p3 = build_program("toy", main, [header], ("-O1",))
    finally:
        if saved is None:
            del os.environ["SYMTRACK_CACHE"]
        else:
            os.environ["SYMTRACK_CACHE"] = saved
    assert len({p1, p2, p3}) == 3 and all(p.parent.parent == tmp_path / "cache" for p in (p1, p2, p3))
    assert [subprocess.run([str(p)], capture_output=True, text=True).stdout for p in (p1, p3)] == ["5\n", "6\n"]


INTERRUPTED = textwrap.dedent("""
    import sys
    from pathlib import Path
    from symtrack import toolchain as build
    src = b'int symtrack_answer(void) { return 3; }\\n'
    build.build(build.BuildSpec(kind="answer", key=build.digest(src), output="libanswer.so",
                                sources=lambda: {"answer.c": src}, what="the answer", root=Path(sys.argv[1])),
                cc=sys.argv[2])
""")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_an_interrupted_build_leaves_no_half_written_library(tmp_path, sig):
    """Ctrl-C (the build cleans up) or a killed worker (the next build cleans up) while the compiler
    runs: no library appears, and the next build of the entry succeeds."""
    started = tmp_path / "started"
    cc = tmp_path / "cc"  # a compiler that hangs after writing half an object
    cc.write_text(f"#!/bin/sh\necho $$ > {started}\nfor a; do case $a in *.o) echo half > $a;; esac; done\n"
                  "exec sleep 60\n")
    cc.chmod(0o755)
    root = tmp_path / "cache"
    # SIGINT as a terminal delivers it, whatever this worker's disposition (a Dask test before it may have left
    # SIGINT ignored, which a child inherits: its Python would then never raise KeyboardInterrupt)
    p = subprocess.Popen([sys.executable, "-c", INTERRUPTED, str(root), str(cc)],
                         env=dict(os.environ, PYTHONPATH=str(REPO)), stderr=subprocess.PIPE,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t0 = time.monotonic()
    while not (started.exists() and started.read_text().strip()):
        assert p.poll() is None and time.monotonic() - t0 < 60, p.stderr.read().decode()
        time.sleep(0.05)
    time.sleep(0.2)  # the half object written
    p.send_signal(sig)
    p.wait(timeout=60)
    p.stderr.close()
    with contextlib.suppress(ProcessLookupError, ValueError):  # the killed build's compiler, orphaned
        os.kill(int(started.read_text()), signal.SIGKILL)
    assert p.returncode != 0
    (entry,) = root.iterdir()
    assert not (entry / "libanswer.so").exists()
    leftovers = list(entry.glob(".build-*"))
    assert (leftovers == []) == (sig == signal.SIGINT)  # Ctrl-C cleans up; a kill leaves the folder
    so = build.build(build.BuildSpec(kind="answer", key=build.digest(b"int symtrack_answer(void) { return 3; }\n"),
                                     output="libanswer.so", what="the answer", root=root,
                                     sources=lambda: {"answer.c": b"int symtrack_answer(void) { return 3; }\n"},
                                     shared_cflags=("-fPIC",)))
    assert so.parent == entry and ctypes.CDLL(str(so)).symtrack_answer() == 3
    # the killed build's folder is gone
    assert sorted(q.name for q in entry.iterdir()) == [".lock", "libanswer.so", "libanswer.so.sha256.json"]


def test_a_missing_compiler_is_a_clear_error(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(build_cache, "find_compiler", lambda: None)
    with pytest.raises(SimulationError, match=r"no C compiler found \(looked for \$CC, cc, gcc\): cannot build "
                                              r"the answer 5; install gcc \(or set \$CC\)"):
        build.build(_spec(tmp_path, 5))
    assert list(tmp_path.iterdir()) == []
    # callers with an interpreted fallback: a warning once, or an error when compiled code is required
    monkeypatch.setattr(build_cache, "_warned_no_compiler", False)
    with caplog.at_level(logging.WARNING, logger="symtrack.toolchain"):
        assert build.compiler() is None and build.compiler() is None
    assert sum("no C compiler found" in r.getMessage() for r in caplog.records) == 1
    monkeypatch.setattr(build_cache, "_require", True)
    with pytest.raises(SimulationError, match="compiled code is required"):
        build.compiler()


def test_a_compiler_error_names_the_build_and_leaves_nothing(tmp_path):
    spec = build.BuildSpec(kind="broken", key=build.digest(b"broken"), output="libbroken.so", what="the broken one",
                           sources=lambda: {"broken.c": b"int f(void) { return }\n"}, root=tmp_path)
    with pytest.raises(SimulationError, match=r"(?s)compiling broken.c of the broken one failed .*error: expected"):
        build.build(spec)
    assert sorted(q.name for q in spec.folder.iterdir()) == [".lock"]


def test_the_cache_root_is_the_environment_variable_or_the_user_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(build.OPT_LEVEL_ENV, raising=False)
    monkeypatch.setenv("SYMTRACK_CACHE", str(tmp_path))
    assert build.cache_root() == tmp_path
    spec = build.BuildSpec(kind="k", key="0123456789abcdef0123", output="x", sources=dict, what="x", group="mpc",
                           digits=20, suffix="-b2")
    assert spec.path == tmp_path / "mpc" / "k-0123456789abcdef0123-b2" / "x"
    monkeypatch.delenv("SYMTRACK_CACHE")
    assert build.cache_root() == Path.home() / ".cache" / "symtrack"


@pytest.mark.parametrize("damage", ["truncated", "overwritten", "no record"])
def test_a_damaged_cached_library_is_rebuilt_not_loaded(tmp_path, caplog, damage):
    # a truncated shared library crashed the loader ("Bus error", exit 135): the cache checks the size
    # and SHA-256 recorded when it was written, and builds a damaged one again
    so = build.build(_spec(tmp_path, 42))
    good = so.read_bytes()
    record = so.with_name(so.name + ".sha256.json")
    if damage == "truncated":
        so.write_bytes(good[: len(good) // 3])
    elif damage == "overwritten":
        so.write_bytes(bytes(len(good)))
    else:
        record.unlink()
    n0 = len(build.builds)
    with caplog.at_level(logging.INFO, logger="symtrack.toolchain"):
        assert build.build(_spec(tmp_path, 42)) == so
    assert len(build.builds) == n0 + 1 and so.read_bytes() == good and record.exists()
    assert f"the cached {so} is not used" in caplog.text
    # and a subprocess loads it (a damaged library would kill it with SIGBUS)
    code = f"import ctypes; print(ctypes.CDLL({str(so)!r}).symtrack_answer())"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).stdout.strip() == b"42"


@pytest.mark.parametrize("how", ["a file", "under a file", "read-only"])
def test_an_unwritable_cache_folder_falls_back_to_a_private_one_with_a_warning(tmp_path, monkeypatch, caplog, how):
    if how == "read-only" and os.geteuid() == 0:  # root writes into a 0555 folder: make the probe fail instead
        monkeypatch.setattr(build_cache.tempfile, "mkstemp", _refuse(build_cache.tempfile.mkstemp, tmp_path))
    bad = tmp_path / "cache"
    if how == "a file":
        bad.write_text("not a folder")
    elif how == "under a file":
        (tmp_path / "file").write_text("x")
        bad = tmp_path / "file" / "cache"
    else:
        bad.mkdir()
        bad.chmod(0o555)
    monkeypatch.setenv("SYMTRACK_CACHE", str(bad))
    with caplog.at_level(logging.WARNING, logger="symtrack.toolchain"):
        root = build.cache_root()
        assert build.cache_root() == root  # decided once
    assert root != bad and root.is_dir() and os.access(root, os.W_OK)
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1 and f"SYMTRACK_CACHE {bad} cannot be written" in warnings[0]
    assert "private temporary cache" in warnings[0]
    spec = build.BuildSpec(kind="answer", key=build.digest(ANSWER % 5), output="libanswer.so", what="the answer 5",
                           sources=lambda: {"answer.c": ANSWER % 5})
    assert ctypes.CDLL(str(build.build(spec))).symtrack_answer() == 5 and spec.path.is_relative_to(root)
    if how == "read-only":
        bad.chmod(0o755)


def _refuse(mkstemp, below: Path):
    def refused(*a, dir=None, **k):
        if dir is not None and Path(dir).is_relative_to(below / "cache"):
            raise PermissionError(13, "Permission denied")
        return mkstemp(*a, dir=dir, **k)
    return refused


def test_a_file_as_cache_is_a_warning_in_a_fresh_process_not_a_traceback(tmp_path):
    bad = tmp_path / "cache"
    bad.write_text("x")
    code = textwrap.dedent(f"""
        import logging
        from symtrack import toolchain as build
        logging.basicConfig(level=logging.WARNING, format="%(message)s")
        src = {ANSWER % 9!r}
        spec = build.BuildSpec(kind="answer", key=build.digest(src), output="libanswer.so", what="the answer",
                               sources=lambda: {{"answer.c": src}})
        print(build.build(spec))
    """)
    env = {**os.environ, "SYMTRACK_CACHE": str(bad), "PYTHONPATH": str(REPO)}
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr.strip().startswith(f"SYMTRACK_CACHE {bad} cannot be written (a file, not a folder)")
    assert not Path(res.stdout.strip()).exists()  # the private cache is removed at exit
