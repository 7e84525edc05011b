"""Two processes that build the same cache entry at once (parallel test workers, sweep workers on
one machine): both succeed, the library is whole and loads, and it is compiled only once (the
second waits on the entry's lock and finds the first's library)."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from symtrack import toolchain as build

pytestmark = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler")

REPO = Path(__file__).resolve().parent.parent

# (the library is built with -fvisibility=hidden: the one function is exported by name)
SOURCE = b'__attribute__((visibility("default"))) int symtrack_race_answer(void) { return 42; }\n'

BUILD = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from symtrack.toolchain import BuildSpec, build
    root, cc, go = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
    src = sys.stdin.buffer.read()
    while not go.exists():  # both processes start compiling at the same moment
        time.sleep(0.01)
    out_so = build(BuildSpec(kind="race", key="0123456789abcdef", output="librace.so", sources=lambda: {"race.c": src},
                             what="the race library", root=root), cc)
    print("built", out_so.exists())
""")


def test_two_concurrent_builds_of_one_key_both_succeed_and_compile_once(tmp_path):
    calls = tmp_path / "cc_calls.txt"
    cc = tmp_path / "cc"
    # a slow compiler (1 s per call), so that the two builds overlap; it logs every call
    cc.write_text(f"#!/bin/sh\necho \"$@\" >> {calls}\nsleep 1\nexec {build.find_compiler()} \"$@\"\n")
    cc.chmod(0o755)
    out_so = tmp_path / "cache" / "race-0123456789abcdef" / "librace.so"
    go = tmp_path / "go"
    env = dict(os.environ, PYTHONPATH=str(REPO), SYMTRACK_OPT_LEVEL="")  # the tuned flags' folder name
    procs = [subprocess.Popen([sys.executable, "-c", BUILD, str(out_so.parent.parent), str(cc), str(go)], env=env,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for _ in range(2)]
    for p in procs:
        p.stdin.write(SOURCE)
        p.stdin.close()
    time.sleep(0.5)
    go.touch()
    results = [(p.wait(timeout=120), p.stdout.read().decode(), p.stderr.read().decode()) for p in procs]
    for rc, out, err in results:
        assert rc == 0, err[-2000:]
        assert "built True" in out
    lines = calls.read_text().splitlines()
    assert len(lines) == 2, lines  # one compile, one link: the second build found the first's library
    assert sum("-c" in line.split() for line in lines) == 1 and sum("-shared" in line.split() for line in lines) == 1
    assert ctypes.CDLL(str(out_so)).symtrack_race_answer() == 42
    assert not list(out_so.parent.glob(".build-*"))  # no temporary folder left behind
    assert sorted(p.name for p in out_so.parent.iterdir()) == [".lock", "librace.so", "librace.so.sha256.json"]
