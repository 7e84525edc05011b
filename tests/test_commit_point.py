"""One commit point per run (issue 38, item 2): an in-place run (``symtrack simulate --terrain-in F
--terrain-out F`` into a folder holding an earlier run) is killed (SIGKILL, by fault injection:
``SYMTRACK_KILL_AT_COMMIT_STEP`` = k) at every step of its commit, each write, rename and removal.
Every outcome is the old state (F byte-identical, the folder's files those of the earlier run) or the
new one (F holds the run once; its files are completed by the next symtrack process), and the rerun
of the same command gives the terrain of an uninterrupted run bit for bit, the run once in its
history, the folder whole and no temporary file or staging folder left.

The runs are forked from this process (the scenario and its compiled code loaded once) with the
figures stubbed (they are not what is tested): some 20 kills and 20 reruns in a few seconds."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.cli.main import main
from symtrack.reports import run_files
from symtrack.terrain import storage as persist

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the runs are forked (POSIX)")


def _fork_cli(argv: list[str], kill_at: int | None = None) -> int:
    """Run ``symtrack argv`` in a forked child (killed at its ``kill_at``-th commit step); the exit
    code, or -signal when it was killed."""
    pid = os.fork()
    if pid == 0:  # the child: no output, no cleanup on exit (as a killed process)
        code = 70
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115 (the child ends with os._exit)
            run_files._step_count = 0
            if kill_at is not None:
                os.environ[run_files.KILL_AT_STEP_ENV] = str(kill_at)
            code = main(argv)
        except SystemExit as err:
            code = err.code if isinstance(err.code, int) else 1
        except BaseException:
            code = 71
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)


def _visible(folder: Path) -> dict[str, bytes]:
    """The files of a run's folder a user sees (not the dot files: manifest, journal, lock)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.name.startswith(".")}


def _arrays(f: Path) -> dict[str, bytes]:
    t = persist.load(f)
    return {k: np.ascontiguousarray(v).tobytes() for k, v in t.arrays().items()}


def _leftovers(case: Path) -> list[str]:
    """Temporary files, staging folders and journals anywhere in the case's folder."""
    return sorted(p.name for p in case.rglob("*") if p.name.endswith(".tmp") or ".staging-" in p.name
                  or p.name in (run_files.JOURNAL, run_files.OUTPUT_LOCK, "F.npz.lock"))


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """An earlier run (F0 and its folder out0), and an uninterrupted in-place run from them: its
    terrain arrays, its folder's file names and the number of its commit steps."""
    d = tmp_path_factory.mktemp("commit_point")
    sc = d / "tiny.toml"
    sc.write_text(TINY_INPLACE_TOML)
    mp = pytest.MonkeyPatch()
    # the figures are not what is tested: one small file instead of each (simulation_files' shape kept)
    mp.setattr(run_files, "figures", lambda kinds, *a, **k: {f"{kinds[0] if isinstance(kinds, tuple) else kinds}"
                                                           ".png": b"\x89PNG figure"})
    mp.setattr(run_files, "report_html", lambda *a, **k: "<html>report</html>")
    f0, out0 = d / "F0.npz", d / "out0"
    assert _fork_cli(["simulate", str(sc), "--out", str(out0), "--terrain-out", str(f0), "--quiet"]) == 0
    # a file of the earlier run that the next does not write (its manifest lists it): removed at the commit
    (out0 / "earlier_only.csv").write_text("x\n")
    run_files._write_manifest(out0, [*run_files.read_manifest(out0), "earlier_only.csv"])
    ref = d / "ref"
    ref.mkdir()
    shutil.copyfile(f0, ref / "F.npz")
    shutil.copytree(out0, ref / "out")
    before = run_files._step_count
    with contextlib.redirect_stdout(open(os.devnull, "w")):  # noqa: SIM115
        assert main(_argv(sc, ref)) == 0
    steps = run_files.COMMIT_STEPS[before:run_files._step_count]
    yield d, sc, f0, out0, _arrays(ref / "F.npz"), set(_visible(ref / "out")), steps
    mp.undo()


def _argv(sc: Path, case: Path) -> list[str]:
    return ["simulate", str(sc), "--out", str(case / "out"), "--quiet", "--terrain-in", str(case / "F.npz"),
            "--terrain-out", str(case / "F.npz")]


def test_kill_at_each_commit_step_leaves_old_or_new_and_the_rerun_equals_one_run(base):
    d, sc, f0, out0, ref_arrays, ref_names, steps = base
    assert 15 <= len(steps) <= 60, steps  # every staged file, the terrain, the journal, the renames
    commit = steps.index("terrain file renamed into place (the commit point)") + 1
    old_bytes, old_files = f0.read_bytes(), _visible(out0)
    old_runs = persist.load(f0).history
    outcomes = []
    for k in range(1, len(steps) + 1):
        case = d / f"kill_{k}"
        case.mkdir()
        f, out = case / "F.npz", case / "out"
        shutil.copyfile(f0, f)
        shutil.copytree(out0, out)
        assert _fork_cli(_argv(sc, case), kill_at=k) == -signal.SIGKILL, f"step {k} ({steps[k - 1]})"
        if f.read_bytes() == old_bytes:  # the old state: the terrain file and the folder's files untouched
            assert k <= commit, f"step {k} ({steps[k - 1]}): killed after the commit point, F is the old file"
            assert _visible(out) == old_files, f"step {k} ({steps[k - 1]})"
            outcomes.append("old")
        else:  # the new state: F holds the run once; its journal (if still there) completes the folder
            assert k > commit, f"step {k} ({steps[k - 1]}): F changed before the commit point"
            t = persist.load(f)
            assert t.history[:-1] == old_runs and t.history[-1]["passes"] == 1
            journal = out / run_files.JOURNAL
            assert journal.is_file() or json.loads((out / "summary.json").read_text())["terrain_run_id"] == \
                t.history[-1]["run_id"]
            outcomes.append("new")
        # the rerun of the same command: the passes once, the folder whole, nothing left behind
        assert _fork_cli(_argv(sc, case)) == 0, f"rerun after step {k} ({steps[k - 1]})"
        t = persist.load(f)
        assert _arrays(f) == ref_arrays, f"rerun after step {k} ({steps[k - 1]}): not the terrain of one run"
        assert t.history[:-1] == old_runs, f"rerun after step {k} ({steps[k - 1]}): the passes applied twice"
        s = json.loads((out / "summary.json").read_text())
        assert s["terrain_run_id"] == t.history[-1]["run_id"]
        assert set(_visible(out)) == ref_names
        assert run_files.read_manifest(out) == sorted(ref_names)
        assert _leftovers(case) == [], f"after step {k} ({steps[k - 1]})"
    assert outcomes == ["old"] * commit + ["new"] * (len(steps) - commit), outcomes


def test_a_temporary_terrain_file_of_a_killed_write_is_removed_by_the_next_run(base, tmp_path):
    d, sc, f0, out0, ref_arrays, _, steps = base
    k = steps.index("terrain file written to its temporary file") + 1
    shutil.copyfile(f0, tmp_path / "F.npz")
    shutil.copytree(out0, tmp_path / "out")
    assert _fork_cli(_argv(sc, tmp_path), kill_at=k) == -signal.SIGKILL
    assert [p.name for p in tmp_path.glob(".F.npz.*.tmp")]  # the killed write's
    assert any(tmp_path.glob(".out.staging-*"))
    # another file's writer (a different --out) on F: it removes them under F's lock
    argv = _argv(sc, tmp_path)
    argv[argv.index("--out") + 1] = str(tmp_path / "other")
    assert _fork_cli(argv) == 0
    assert not list(tmp_path.glob(".F.npz.*.tmp"))
    assert _fork_cli(_argv(sc, tmp_path)) == 0  # and the folder's next run removes the staging folder
    assert _leftovers(tmp_path) == []
    assert len(persist.load(tmp_path / "F.npz").history) == len(persist.load(f0).history) + 2


def test_a_journal_that_names_anything_outside_its_own_files_moves_and_removes_nothing(tmp_path, caplog):
    """A journal (someone else's file of that name, or a damaged one) naming a folder, a file or a
    temporary file that are not its commit's is removed with a warning; what it names stays."""
    out = tmp_path / "out"
    out.mkdir()
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.md").write_text("x")
    (tmp_path / "data.csv").write_text("y")
    stage = tmp_path / ".out.staging-1-abc"
    stage.mkdir()
    bad = [
        {"staging": str(precious)},  # not a staging folder of this folder
        {"staging": str(stage), "files": ["../data.csv"]},  # a name outside the folder
        {"staging": str(stage), "terrain": {"path": str(tmp_path / "F.npz"), "tmp": str(tmp_path / "data.csv"),
                                            "run_id": "a" * 32, "file_id": "b" * 32}},  # not its temporary file
    ]
    for change in bad:
        journal = {"kind": "symtrack-commit", "schema_version": 1, "staging": str(stage), "files": ["a.csv"],
                   "manifest": ["a.csv"], "clear": False, "terrain": None, **change}
        (out / run_files.JOURNAL).write_text(json.dumps(journal))
        assert run_files.recover(out) is None
        assert not (out / run_files.JOURNAL).exists() and "not a symtrack commit journal" in caplog.text
        assert (precious / "thesis.md").is_file() and (tmp_path / "data.csv").is_file() and stage.is_dir()
        caplog.clear()
