"""What a terrain run writes by default and with ``run.all_figures = true`` (issue 26, item 2):
the default leaves out the slow figures (the pass animations, the earlier passes' sinkage maps
and trajectory plots) and report.html says so; every image report.html shows is a file of the
folder; a bad value is an error naming the key."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from symtrack.cli import main
from symtrack.foundations.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["--set", "run.stop_after_distance_m=0.3"]


def _run(out, *sets) -> str:
    assert main(["simulate", "multipass", "--out", str(out), "--quiet", *SHORT, *sets]) == 0
    return _check(out)


def _check(out) -> str:
    page = (out / "report.html").read_text()
    shown = re.findall(r"<figcaption>([^<]+)</figcaption>", page)
    assert shown and all((out / name).is_file() for name in shown)  # the report shows written files only
    return page


def test_the_default_writes_the_figures_read_first_and_the_report_says_what_it_left_out(tmp_path):
    out = tmp_path / "two"
    page = _run(out, "--set", "terrain.passes=2")
    assert not list(out.rglob("*.gif"))
    for name in ("passes.png", "sinkage_map_pass_2.png", "rut_section.png", "risk_map.png", "density_map.png",
                 "pass_2/path.png", "pass_2/torques.png", "pass_1/trajectory.csv", "pass_1/summary.json"):
        assert (out / name).is_file(), name
    assert not (out / "sinkage_map_pass_1.png").exists() and not list((out / "pass_1").glob("*.png"))
    assert "Not drawn" in page and "run.all_figures = true" in page and "passes 1 to 1" in page
    one = tmp_path / "one"
    page = _run(one, "--set", "terrain.passes=1")
    assert (one / "sinkage_map.png").is_file() and (one / "path.png").is_file() and not (one / "animation.gif").exists()
    assert "pass animations" in page and "passes 1 to" not in page


def test_all_figures_writes_the_animations_and_every_pass_plots(tmp_path):
    """In a process of its own, as a user runs it: --quiet prints no matplotlib line
    ("Animation.save using ...", issue 26's newcomer's list) while the GIFs are written."""
    out = tmp_path / "all"
    r = subprocess.run([sys.executable, "-m", "symtrack", "simulate", "multipass", "--out", str(out), "--quiet",
                        *SHORT, "--set", "terrain.passes=2", "--set", "run.all_figures=true"],
                       env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")},
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "Animation" not in r.stderr and "MovieWriter" not in r.stderr, r.stderr
    page = _check(out)
    for name in ("animation_pass_1.gif", "animation_pass_2.gif", "sinkage_map_pass_1.png", "sinkage_map_pass_2.png",
                 "pass_1/path.png", "pass_2/path.png"):
        assert (out / name).stat().st_size > 0, name
    assert "Not drawn" not in page and "animation_pass_1.gif" in page


def test_all_figures_must_be_true_or_false(tmp_path, capsys):
    assert main(["simulate", "multipass", "--out", str(tmp_path / "a"), "--quiet", "--set", "run.all_figures=1"]) == 2
    err = capsys.readouterr().err
    assert "run.all_figures = 1" in err and "true or false" in err
    assert not (tmp_path / "a").exists()
    # a field study draws no per-pass figures: the key is not one of its [run] keys
    from symtrack.studies.field import load_field_spec

    with pytest.raises(ScenarioError, match="all_figures"):
        load_field_spec("field_traffic", ["run.all_figures=true"])


def test_the_bench_row_of_the_outputs_adds_up():
    """symtrack bench's output-cost row (symtrack/bench/outputs.py) on a short pass: the command
    and the timed run ran, the parts add up to the timed run; no wall-time bound."""
    from symtrack.bench.outputs import case_row

    r = case_row("one short pass", "multipass", ["terrain.passes=1", "run.stop_after_distance_m=0.1"])
    assert r["images"] == 12 and r["command_wall_s"] > 0 and 0 < r["time_loop_s"] <= r["simulate_s"]
    parts = r["start_up_s"] + r["simulate_s"] + r["figures_s"] + r["write_s"]
    assert parts == pytest.approx(r["timed_run_wall_s"]) and r["import_s"] <= r["start_up_s"]
    assert r["outputs_over_simulate"] > 0 and "x the simulation" in r["note"]
