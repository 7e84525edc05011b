"""A run's files, its terrain file included, appear together or not at all (issue 26, item 1):
a real ``python -m symtrack simulate --terrain-in F --terrain-out F`` killed (SIGKILL) at many
moments leaves F byte-identical, or advanced by exactly that run (its history says so) with its whole
folder (completed from its journal when the kill came after the commit point); two writers of one
terrain file never mix; the terrain file's history (schema 3) and the older schemas' empty history.
The kill at every step of the commit, by fault injection: tests/test_commit_point.py."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.presets import soil_preset
from symtrack.reports import run_files
from symtrack.reports.run_files import terrain_lock, write_folder
from symtrack.terrain import storage as persist
from symtrack.terrain.storage import Grid, Terrain

ROOT = Path(__file__).resolve().parent.parent

# one pass of 0.5 m on a 32 x 16 field, on the terrain engine: the simulation is milliseconds, the
# run's seconds are start-up and writing (the moments a kill lands in). Without figures (run.figures =
# false): a run draws them in memory before it writes anything (Result.write), so a kill while drawing
# leaves what a kill at start-up does, and they were about half of each run's CPU (12 runs); the run
# folder's figures are tested in tests/test_outputs.py
SCENARIO = TINY_INPLACE_TOML.replace("output_dt_s = 0.05", "output_dt_s = 0.01").replace(
    "stop_after_distance_m = 0.3", "stop_after_distance_m = 0.5").replace("[run]\n", "[run]\nfigures = false\n")
assert "output_dt_s = 0.01" in SCENARIO and "stop_after_distance_m = 0.5" in SCENARIO
assert "figures = false" in SCENARIO


def _cmd(scenario: Path, out: Path, f: Path) -> list[str]:
    return [sys.executable, "-m", "symtrack", "simulate", str(scenario), "--out", str(out), "--quiet",
            "--terrain-in", str(f), "--terrain-out", str(f)]


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def _staging(out: Path) -> list[Path]:
    return list(out.parent.glob(f".{out.name}.staging-*"))


def _check(out: Path, f: Path, before: bytes, before_history: int) -> str:
    """The all-or-nothing rule for one (possibly killed) run; returns which side it was on."""
    if not (out / "summary.json").exists() and (out / run_files.JOURNAL).is_file() and f.read_bytes() != before:
        # killed after the commit point (the terrain file renamed): the next writer completes the folder
        assert run_files.recover(out) is not None
    if not (out / "summary.json").exists():
        assert f.read_bytes() == before  # no summary: the terrain file is the one it was
        return "none"
    s = json.loads((out / "summary.json").read_text())
    t = persist.load(f)
    assert len(t.history) == before_history + 1 and t.history[-1]["run_id"] == s["terrain_run_id"]
    assert t.history[-1]["passes"] == 1 and t.history[-1]["scenario"] == "tiny_inplace"
    assert (out / "report.html").stat().st_size > 0 and (out / "trajectory.csv").stat().st_size > 0
    return "whole"


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("commit")
    sc = d / "tiny.toml"
    sc.write_text(SCENARIO)
    f = d / "F.npz"
    persist.save(f, Terrain(Grid((-2.0, -2.0), 0.25, (32, 16))), soil_preset("clayey_soil_thailand_38"))
    first_id = persist.load(f).file_id
    # an uninterrupted run: its duration places the kills, its write phase is timed from the staging
    # folder's appearance to summary.json's
    out = d / "full"
    t0 = time.monotonic()
    p = subprocess.Popen(_cmd(sc, out, f), env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t_stage = t_summary = None
    while p.poll() is None:
        now = time.monotonic()
        if t_stage is None and _staging(out):
            t_stage = now
        if t_summary is None and (out / "summary.json").exists():
            t_summary = now
        time.sleep(0.001)
    err = p.stderr.read().decode()
    assert p.returncode == 0, err
    # --quiet without matplotlib's animation line: tests/test_outputs.py (the default draws no animation)
    total = time.monotonic() - t0
    write = (t_summary - t_stage) if t_stage is not None and t_summary is not None else 0.05
    return d, sc, f, first_id, total, max(write, 0.005)


def test_an_uninterrupted_run_advances_the_file_and_its_history_says_so(setup):
    d, sc, f, first_id, _, _ = setup
    t = persist.load(f)
    s = json.loads((d / "full" / "summary.json").read_text())
    assert [h["run_id"] for h in t.history] == [s["terrain_run_id"]]
    assert t.history[0]["input_file_id"] == first_id != t.file_id
    assert len(t.history[0]["scenario_sha256"]) == 64 and s["terrain_out"] == str(f)
    assert np.count_nonzero(t.phase) > 0
    assert not _staging(d / "full") and not list(d.glob(".F.npz.*.tmp"))


def test_killed_at_8_moments_the_terrain_file_is_as_before_or_advanced_with_a_summary(setup):
    d, sc, f0, _, total, write = setup
    before_history = len(persist.load(f0).history)
    # three kills by the clock (start-up, simulation, results), five in the write phase: from the
    # moment the staging folder appears, at 0 to 4 times the write phase an uninterrupted run took (the
    # runs here go two at once, slower than that one: the later kills reach the renames)
    plans = [("clock", 0.3 * total), ("clock", 0.55 * total), ("clock", 0.8 * total)]
    plans += [("staged", k * write) for k in (0.0, 0.5, 1.0, 2.0, 4.0)]
    seen = []
    for pair in (plans[i:i + 2] for i in range(0, len(plans), 2)):  # two at once: 2 cores
        running = []
        for k, (how, delay) in enumerate(pair):
            case = d / f"kill_{len(seen) + k}"
            case.mkdir()
            f = case / "F.npz"
            shutil.copyfile(f0, f)
            out = case / "out"
            p = subprocess.Popen(_cmd(sc, out, f), env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            running.append((p, how, delay, out, f, time.monotonic(), None))
        while any(r[0].poll() is None and r[6] != "killed" for r in running):
            now = time.monotonic()
            for i, (p, how, delay, out, f, t0, state) in enumerate(running):
                if state == "killed" or p.poll() is not None:
                    continue
                if how == "staged" and state is None and _staging(out):
                    running[i] = (p, how, delay, out, f, now, "staged")
                    t0, state = now, "staged"
                if (how == "clock" or state == "staged") and now - t0 >= delay:
                    p.send_signal(signal.SIGKILL)
                    running[i] = (p, how, delay, out, f, t0, "killed")
            time.sleep(0.001)
        for p, _, _, out, f, _, _ in running:
            p.wait()
            seen.append(_check(out, f, f0.read_bytes(), before_history))
            # a later writer of the same folder removes the killed writer's staging folder
            write_folder(out, {"note.md": "x"}, clear=False)
            assert not _staging(out)
    print("run", round(total, 2), "s, write phase", round(write, 4), "s, outcomes:", seen)
    assert "none" in seen  # the kills landed before the commit at least once


def test_two_writers_of_one_terrain_file_never_mix(setup):
    d, sc, f0, _, _, _ = setup
    case = d / "two"
    case.mkdir()
    f = case / "F.npz"
    shutil.copyfile(f0, f)
    before = f.read_bytes()
    n0 = len(persist.load(f).history)
    # a holder in this process: a writer fails at once with a message, the file untouched
    with terrain_lock(f):
        r = subprocess.run(_cmd(sc, case / "held", f), env=_env(), capture_output=True, text=True)
    assert r.returncode == 2 and "another symtrack process" in r.stderr and str(os.getpid()) in r.stderr
    assert f.read_bytes() == before and not (case / "held" / "summary.json").exists()
    # two real writers at once: one runs, the other fails with the message; the file holds one run
    ps = [subprocess.Popen(_cmd(sc, case / f"w{k}", f), env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True) for k in range(2)]
    outs = [(p.wait(), p.stderr.read()) for p in ps]
    codes = sorted(c for c, _ in outs)
    assert codes == [0, 2], outs
    assert "another symtrack process" in next(e for c, e in outs if c == 2)
    t = persist.load(f)
    winner = next(k for k, (c, _) in enumerate(outs) if c == 0)
    s = json.loads((case / f"w{winner}" / "summary.json").read_text())
    assert len(t.history) == n0 + 1 and t.history[-1]["run_id"] == s["terrain_run_id"]


def test_history_chains_and_older_schemas_load_with_an_empty_history(tmp_path):
    soil = soil_preset("clayey_soil_thailand_38")
    t = Terrain(Grid((0.0, 0.0), 0.5, (4, 3)), soil)
    f = tmp_path / "t.npz"
    run = {"run_id": "a" * 32, "time_utc": "2026-01-01T00:00:00+00:00", "scenario": "s", "scenario_sha256": "0" * 64,
           "passes": 2}
    t.save(f, run=run)
    first = persist.load(f)
    first_id = first.file_id
    assert first.history == [{**run, "input_file_id": None}] and first_id == t.file_id
    first.save(f, run={**run, "run_id": "b" * 32})
    second = persist.load(f)
    assert [h["run_id"] for h in second.history] == ["a" * 32, "b" * 32]
    assert second.history[1]["input_file_id"] == first_id != second.file_id == first.file_id
    assert "2 saved run(s)" in repr(second) and "4 x 3 cells" in repr(second)
    # a schema-2 file (as the last symtrack wrote it): no history, no id
    with np.load(f) as z:
        d = {k: z[k] for k in z.files if k not in ("file_id", "history_json")}
    d["schema_version"] = np.array(2)
    old = tmp_path / "old.npz"
    np.savez(old, **d)
    o = persist.load(old)
    assert o.history == [] and o.file_id is None
    with pytest.raises(Exception, match="lacks run_id"):
        t.save(f, run={"scenario": "s"})
