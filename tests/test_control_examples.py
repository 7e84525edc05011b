"""The control examples and the timing comparison, run at small size (no wall-clock assertions)."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from symtrack.control import bench

ROOT = Path(__file__).resolve().parents[1]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_lqr_example(tmp_path):
    mod = _load("lqr_speed_yaw")
    s = mod.run(duration_s=6.0, dt=0.02, out=tmp_path)
    assert s["closed_loop_max_real_eig_per_s"] < 0
    # speed step of 0.3 m/s at 1 s, yaw-rate step of 0.02 rad/s at 3 s, on the nonlinear model
    assert abs(s["final_speed_error_m_s"]) < 0.03
    assert abs(s["final_yaw_rate_error_rad_s"]) < 0.01
    assert json.loads((tmp_path / "lqr_summary.json").read_text())["schema_version"] == 1
    assert (tmp_path / "lqr_response.png").read_bytes()[:4] == b"\x89PNG"


def test_mpc_example(tmp_path):
    mod = _load("mpc_headland_uturn")
    # 5 steps of a 4-step horizon: the example's code path (build, closed loop, files, report) at the
    # smallest NLP (its build is most of the test's CPU and grows with the horizon: 5.1 s of CPU at 8 steps,
    # 3.6 s at 4)
    s = mod.run(out=tmp_path, solver="fatrop", max_steps=5, horizon_steps=4)
    assert s["solves"] == 5 and s["failed_solves"] == 0
    assert s["max_lateral_error_m"] < 0.05  # the run starts on the path
    assert (tmp_path / "summary.json").exists()
    # the report: what ran and how it went, its figures embedded
    page = (tmp_path / "report.html").read_text()
    assert "symtrack mpc: headland_uturn" in page and "5 solves, 0 failed" in page and "data:image/png" in page


@pytest.mark.slow  # a JIT build: gcc of the fatrop solver every run (a short horizon: the smallest C; make test-slow)
def test_jit_build_runs(tmp_path, monkeypatch):
    import dataclasses

    from symtrack.control import closedloop, scenario
    from symtrack.model import SystemModel

    # on the creep law (12 vehicle states against the default's 16): the jit path is the same, its NLP's C is
    # a quarter (gcc of the NLP 4.6 s of CPU, against 16 s on the default law; the horizon barely matters)
    sc = scenario.load("headland_uturn", ["model.lateral_law=creep"])
    sc = dataclasses.replace(sc, mpc=dataclasses.replace(sc.mpc, solver="fatrop", jit=True, horizon_steps=6,
                                                         jit_dir=str(tmp_path / "jit")))
    # a working directory of this test's own: the repository's is shared with the tests that run
    # at the same time on the other worker (a first Hypothesis run creates .hypothesis/ there)
    (tmp_path / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "cwd")
    before = set(Path.cwd().iterdir())
    res = closedloop.run(sc, model=SystemModel(sc.model), max_steps=3)
    assert res.summary["jit"] and res.summary["failed_solves"] == 0
    # the compiler ran in the jit folder: nothing new in the working directory
    assert (tmp_path / "jit").is_dir()
    assert set(Path.cwd().iterdir()) == before


def test_timing_comparison_rows():
    # an 8-step horizon: the rows are the subject, and the NMPC's build grows with the horizon (18.8 s of
    # CPU at the scenario's 20 steps, 11.8 s at 8); the creep law by an override: the comparison runs the
    # scenario's [model] as overridden (it built the default model and refused the override)
    rows = bench.timing_comparison(max_steps=5, include=("nmpc_ipopt_plain", "linear_mpc"),
                                   overrides=("mpc.horizon_steps=8", "model.lateral_law=creep"))
    assert [r["controller"] for r in rows] == ["nmpc_ipopt_plain", "linear_mpc"]
    for r in rows:
        assert r["solves"] == 5 and np.isfinite(r["solve_time_median_ms"])
    table = bench.table_markdown(rows)
    assert table.count("\n") == 4


def test_freezing_the_cells_changes_little():
    d = bench.prediction_effect(horizon_steps=10)
    # the terrain cells act on the vehicle only through the compaction resistance: freezing
    # them moves the 1 s prediction by far less than a millimetre
    assert d["max_abs_diff_vehicle_vs_full_y_m"] < 1e-4
    assert d["max_abs_diff_vehicle_vs_full_u_m_s"] < 1e-4
    # and the collocation prediction agrees with the plant (CVODES) to a few mm
    assert d["max_abs_diff_full_vs_plant_y_m"] < 5e-3


def test_fast_config_is_a_valid_setting():
    from symtrack.control.mpc import MPCSettings

    assert MPCSettings(**bench.FAST_CONFIG).jit
