"""What a new user meets first: outputs checked before any work, terrain files validated on load,
built-in runs changed from the command line, Ctrl-C, a fast --help."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from symtrack.cli import main

# (without figures: what these tests check is the command's behaviour and the folder, not the drawings,
# which tests/test_outputs.py checks; they were most of a run's CPU here)
FAST = ["--quiet", "--set", "run.integrator=rosenbrock", "--set", "run.duration_s=0.2",
        "--set", "run.stop_after_distance_m=none", "--set", "run.figures=false"]

TINY_GRID = """
name = "tiny_grid"
[run]
duration_s = 0.3
integrator = "idas"
reltol = 1e-5
abstol = 1e-8
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[terrain]
size_m = [6.0, 4.0]
cell_m = 0.25
settle_s = 0.05
[[torque]]
t_s = 0.0
left_N_m = 3000.0
right_N_m = 3000.0
"""


def _timed_main(argv):
    t0 = time.perf_counter()
    rc = main(argv)
    return rc, time.perf_counter() - t0


def _fails_before_any_work(argv) -> tuple[int, str]:
    """Run the CLI in a fresh interpreter; (exit code, stderr). It must fail without importing
    CasADi: the check came before any model was built (a deterministic stand-in for "in under a
    second"; the wall time is printed, not asserted)."""
    code = ("import sys, time\nt0 = time.perf_counter()\nfrom symtrack.cli import main\n"
            f"rc = main({argv!r})\n"
            "print('RC', rc, 'CASADI', 'casadi' in sys.modules, 'SECONDS', time.perf_counter() - t0)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    print(r.stdout.strip())
    assert "CASADI False" in r.stdout, r.stdout + r.stderr
    return int(r.stdout.split("RC")[1].split()[0]), r.stderr


def test_out_is_an_existing_file(tmp_path):
    f = tmp_path / "results"
    f.write_text("keep me")
    rc, err = _fails_before_any_work(["simulate", "validation", "--out", str(f), *FAST])
    assert rc == 2 and "is an existing file" in err and "Traceback" not in err
    assert f.read_text() == "keep me"


def test_out_below_a_file_and_terrain_out_a_folder(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    rc, err = _fails_before_any_work(["simulate", "validation", "--out", str(f / "sub"), *FAST])
    assert rc == 2 and "is a file" in err
    folder = tmp_path / "adir"
    folder.mkdir()
    tiny = tmp_path / "tiny.toml"
    tiny.write_text(TINY_GRID)
    rc, err = _fails_before_any_work(["simulate", str(tiny), "--out", str(tmp_path / "o"), "--quiet",
                                      "--terrain-out", str(folder)])
    assert rc == 2 and "is a folder" in err
    assert not (tmp_path / "o").exists()
    # --terrain-out on a scenario without a field
    rc, _ = _timed_main(["simulate", "validation", "--out", str(tmp_path / "o"), *FAST,
                         "--terrain-out", str(tmp_path / "t.npz")])
    assert rc == 2 and "no [terrain] section" in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["truncated", "text", "nan", "not_a_terrain"])
def test_damaged_terrain_files_are_refused_clearly(tmp_path, capsys, kind):
    from symtrack.presets import soil_preset
    from symtrack.terrain.storage import Grid, Terrain

    tiny = tmp_path / "tiny.toml"
    tiny.write_text(TINY_GRID)
    good = tmp_path / "good.npz"
    t = Terrain(Grid((-3.0, -2.0), 0.25, (24, 16)))
    t.save(good, soil_preset("clayey_soil_thailand_38"))
    bad = tmp_path / "bad.npz"
    if kind == "truncated":
        bad.write_bytes(good.read_bytes()[:200])
    elif kind == "text":
        bad.write_text("this is not a terrain\n")
    elif kind == "nan":
        t.z[5] = np.nan
        t.save(bad, soil_preset("clayey_soil_thailand_38"))
    else:
        np.savez(bad, kind=np.array("something-else"))
    rc, dt = _timed_main(["simulate", str(tiny), "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(bad)])
    err = capsys.readouterr().err
    print(f"refused in {dt:.2f} s")  # reported, not asserted (wall time)
    assert rc == 2
    assert "Traceback" not in err and "allow_pickle" not in err
    assert {"truncated": "not a symtrack terrain file", "text": "not a symtrack terrain file",
            "nan": "non-finite", "not_a_terrain": "not a symtrack terrain file"}[kind] in err
    assert not (tmp_path / "o").exists()


def test_terrain_in_on_a_scenario_without_terrain_names_the_grid_scenarios(tmp_path, capsys):
    f = tmp_path / "t.npz"
    f.write_bytes(b"")
    rc = main(["simulate", "validation", "--out", str(tmp_path / "o"), *FAST, "--terrain-in", str(f)])
    err = capsys.readouterr().err
    assert rc == 2 and "no [terrain] section" in err and "validation_grid" in err and "multipass" in err


def test_a_folder_named_like_a_builtin_does_not_shadow_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "validation").mkdir()
    assert main(["simulate", "validation", "--out", "o", *FAST]) == 0
    assert json.loads(Path("o/summary.json").read_text())["scenario"] == "validation"


def test_a_reused_out_is_cleared_of_the_previous_run(tmp_path):
    out = tmp_path / "o"
    assert main(["simulate", "validation", "--out", str(out), *FAST]) == 0
    # files of an earlier run that this one does not write (recorded in the folder's manifest), and the user's
    from symtrack.reports.run_files import write_folder

    write_folder(out, {"stale_plot.png": b"old", "pass_3/summary.json": "{}"}, clear=False)
    (out / "notes.txt").write_text("mine")
    assert main(["simulate", "validation", "--out", str(out), *FAST]) == 0
    assert not (out / "stale_plot.png").exists() and not (out / "pass_3").exists()
    assert (out / "notes.txt").read_text() == "mine" and (out / "summary.json").exists()


def test_a_run_that_leaves_the_field_keeps_what_it_computed(tmp_path, capsys):
    tiny = tmp_path / "tiny.toml"
    # on the terrain engine (on IDAS the channel pool takes about 30 s to get there; the pool's own check of
    # the field's edge: tests/test_terrain_world.py)
    tiny.write_text(TINY_GRID.replace("duration_s = 0.3", "duration_s = 6.0")
                    .replace('integrator = "idas"', 'integrator = "grid_fast"'))
    out = tmp_path / "o"
    assert main(["simulate", str(tiny), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "left the terrain field" in err and "complete = false" in err
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and "left the terrain field" in s["error"]
    assert 0.3 < s["sim_time_s"] < 6.0
    rows = (out / "trajectory.csv").read_text().splitlines()
    assert len(rows) > 30  # the trajectory up to the last completed step


def test_help_and_version_are_fast_and_import_no_heavy_package():
    code = ("import sys, time\nt0 = time.perf_counter()\nfrom symtrack.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('SECONDS', time.perf_counter() - t0)\n"
            "print('HEAVY', [m for m in ('casadi', 'control', 'scipy', 'matplotlib') if m in sys.modules])\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "simulate" in r.stdout
    assert "HEAVY []" in r.stdout
    seconds = float(r.stdout.split("SECONDS")[1].split()[0])
    print(f"--help in {seconds:.3f} s")  # reported, not asserted (wall time)
    r = subprocess.run([sys.executable, "-m", "symtrack", "--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("symtrack ")


def test_ctrl_c_stops_simulate_with_exit_130_and_writes_nothing(tmp_path):
    out = tmp_path / "o"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "symtrack", "simulate", "validation", "--out", str(out),
                          "--set", "run.integrator=idas", "--set", "run.duration_s=600",
                          "--set", "run.stop_after_distance_m=none"],
                         stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # a terminal's default
    # wait for the first progress line ("validation:   0.0% after ..."): the model is built and the
    # time loop running (a fixed sleep was too short on a loaded machine, e.g. the parallel suite)
    lines = []

    def read():
        for line in p.stderr:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 120
        while not any(line.startswith("validation:") for line in list(lines)) and time.monotonic() < deadline:
            assert p.poll() is None, "".join(lines)
            time.sleep(0.05)
        time.sleep(1.0)  # well inside the loop
        p.send_signal(signal.SIGINT)
        t0 = time.perf_counter()
        p.wait(timeout=60)
        print(f"stopped {time.perf_counter() - t0:.2f} s after SIGINT")
        reader.join(10)
        p.stdout.read()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    err = "".join(lines)
    assert p.returncode == 130, err
    # (CasADi itself prints that IDAS's residual was interrupted; symtrack reports no failure)
    assert "symtrack: interrupted" in err and "Traceback" not in err and "symtrack: error" not in err
    assert "100.0%" not in err  # the progress shown stops where the run stopped
    assert not (out / "summary.json").exists() and not out.exists()


def test_presets_list_and_show_units_and_sources(capsys):
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    assert "reference_crawler" in out and "heavy_clay_wes_40" in out
    assert main(["presets", "reference_crawler", "--wide"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| mass_kg |"))
    assert "| kg |" in row and "calibrated against the validation table" in row
    assert main(["presets", "clayey_soil_thailand_38", "--wide"]) == 0
    out = capsys.readouterr().out
    assert "Wong Table 2.3" in next(line for line in out.splitlines() if line.startswith("| bekker_n |"))
    assert "Chrono SCM's default damping" in next(line for line in out.splitlines()
                                                  if line.startswith("| cell_damping_Pa_s_per_m |"))


def test_a_user_preset_file(tmp_path, capsys):
    f = tmp_path / "my_crawler.toml"
    f.write_text('description = "heavier"\nbase = "reference_crawler"\nmass_kg = 7000.0\n'
                 '[sources]\nmass_kg = "weighed on the farm scale"\n')
    assert main(["presets", str(f), "--kind", "vehicle"]) == 0
    assert "weighed on the farm scale" in capsys.readouterr().out
    out = tmp_path / "o"
    assert main(["simulate", "validation", "--out", str(out), *FAST, "--set", f'vehicle.preset="{f}"']) == 0
    assert "mass_kg = 7000.0" in (out / "scenario.resolved.toml").read_text()
    f.write_text("mass_kgg = 1.0\n")
    assert main(["simulate", "validation", "--out", str(out), *FAST, "--set", f'vehicle.preset="{f}"']) == 2
    assert "mass_kgg" in capsys.readouterr().err
