"""The compiled grid Rosenbrock integrator (symtrack/integrators/grid_rosenbrock.py) against IDAS on a
small field, its convergence under step refinement, and that its generated code is compiled."""

import copy
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from symtrack import toolchain as compiled
from symtrack.bench.terrain import pool_run
from symtrack.foundations.errors import ScenarioError
from symtrack.integrators import grid_idas
from symtrack.integrators.grid_rosenbrock import grid_library
from symtrack.simulation.result import summarise
from symtrack.simulation.scenario import scenario_from_dict

# A 12 m x 4 m field at 0.25 m (768 cells, M = 18): from rest, both sprockets at 2000 N m, then the
# left one idle at 0.3 s: the vehicle accelerates and begins to turn.
SMALL = {
    "name": "grid_rosenbrock_vs_idas",
    "run": {"duration_s": 0.6, "output_dt_s": 0.01, "integrator": "idas", "fixed_step_s": 0.000625},
    "vehicle": {"preset": "reference_crawler"},
    "soil": {"preset": "clayey_soil_thailand_38"},
    "start": {"x_m": -3.0},
    "terrain": {"size_m": [12.0, 4.0], "cell_m": 0.25, "origin_m": [-6.0, -2.0], "settle_s": 0.1},
    "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0},
               {"t_s": 0.3, "left_N_m": 0.0, "right_N_m": 2000.0}],
}

# Stated tolerances (measured over 1 s of this programme at a 0.625 ms step: pose 1.1 um,
# sinkage 28 nm against IDAS at reltol 1e-7; at 1.25 ms 0.9 mm and 10 um)
POSE_TOL_M = 2e-5
SINKAGE_TOL_M = 5e-7  # against sinkages of about 1 mm
RATE_TOL = 1e-3  # velocities, speeds, shears, torques: relative to 1 + abs(value)


def _run(integrator, fixed_step_s=0.000625, **run):
    d = copy.deepcopy(SMALL)
    d["run"].update(integrator=integrator, fixed_step_s=fixed_step_s, **run)
    return pool_run(scenario_from_dict(d), SMALL["run"]["duration_s"])


@pytest.fixture(scope="module")
def runs():
    # the IDAS reference built without CasADi's cse (the same numbers to the last bit: grid_idas.CSE): for its
    # 0.6 s of steps the cse's build costs more than it saves (measured 10.9 -> 7.6 s of CPU, the run's states and
    # sinkages equal)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(grid_idas, "CSE", False)
        idas = _run("idas")
    return {"idas": idas, "rb": _run("rosenbrock"), "rb_fine": _run("rosenbrock", 0.0003125),
            "rb_off": _run("rosenbrock", fixed_step_tolerance=0.0),
            "rb_tight": _run("rosenbrock", fixed_step_tolerance=1e-5)}


@pytest.mark.slow  # IDAS and two fixed-step runs on 768 cells (make test-slow)
def test_grid_rosenbrock_matches_idas(runs):
    (wi, ri), (wr, rr) = runs["idas"], runs["rb"]
    assert rr.scenario.run.integrator == "rosenbrock" and rr.stats["n_calls"] > 0 and rr.stats["nsteps"] > 0
    assert rr.X[-1, 0] - rr.X[0, 0] > 0.1  # it did drive
    assert np.max(np.abs(rr.X[:, :3] - ri.X[:, :3])) < POSE_TOL_M
    assert np.max(np.abs(rr.X[:, 3:12] - ri.X[:, 3:12]) / (1 + np.abs(ri.X[:, 3:12]))) < RATE_TOL
    zi, zr = wi.z_at_pass_end, wr.z_at_pass_end
    assert zi.max() > 5e-4
    assert np.max(np.abs(zr - zi)) < SINKAGE_TOL_M
    assert np.max(np.abs(wr.storage.z - wi.storage.z)) < SINKAGE_TOL_M  # after the lift as well


@pytest.mark.slow  # IDAS and two fixed-step runs on 768 cells (make test-slow)
def test_grid_rosenbrock_converges_under_step_refinement(runs):
    ri, rr, rf = runs["idas"][1], runs["rb"][1], runs["rb_fine"][1]
    err = np.max(np.abs(rr.X[:, :3] - ri.X[:, :3]))
    err_fine = np.max(np.abs(rf.X[:, :3] - ri.X[:, :3]))
    step_change = np.max(np.abs(rr.X[:, :3] - rf.X[:, :3]))
    print(f"pose error against IDAS: {err:.3g} m at 0.625 ms, {err_fine:.3g} m at 0.3125 ms; "
          f"0.625 vs 0.3125 ms: {step_change:.3g} m")
    assert err_fine < POSE_TOL_M and step_change < POSE_TOL_M


@pytest.mark.slow  # IDAS and four fixed-step runs on 768 cells (make test-slow)
def test_grid_rosenbrock_controls_its_error(runs):
    """The error control of the grid Rosenbrock (symtrack/integrators/grid_rosenbrock.py). At the default
    tolerance every step of this field is within it (measured: 0.15 x its tolerance at 0.625 ms) and none is
    halved; off (run.fixed_step_tolerance = 0) the ratio is the same, measured, and nothing is halved; at a
    tolerance of 1e-5 the macro steps above it are taken again in halves until every step kept is within it
    (measured: 48 of 1,120 steps halved, 0.02 x). The summary reports both figures."""
    on, off, tight = runs["rb"][1], runs["rb_off"][1], runs["rb_tight"][1]
    assert 0.0 < on.stats["fixed_step_error_max"] <= 1.0 and on.stats["fixed_step_steps_halved"] == 0
    assert off.stats["fixed_step_error_max"] == on.stats["fixed_step_error_max"]
    assert off.stats["fixed_step_steps_halved"] == 0 and off.stats["fixed_step_tolerance"] == 0.0
    assert tight.stats["fixed_step_steps_halved"] > 0 and tight.stats["fixed_step_error_max"] <= 1.0
    assert tight.stats["nsteps"] > on.stats["nsteps"]
    s = summarise(tight)
    assert s["fixed_step_error_max"] == tight.stats["fixed_step_error_max"] and s["fixed_step_steps_halved"] > 0
    # all within the stated tolerances of IDAS on the pose
    ri = runs["idas"][1]
    for r in (on, off, tight):
        assert np.max(np.abs(r.X[:, :3] - ri.X[:, :3])) < POSE_TOL_M


def test_grid_rosenbrock_refuses_steps_above_the_measured_bound():
    with pytest.raises(ScenarioError, match="fixed_step_s"):
        _run("rosenbrock", 0.00125)


def test_grid_code_is_compiled():
    from symtrack.model.options import ModelOptions

    if compiled.find_compiler() is None:
        pytest.skip("no C compiler")
    f, is_compiled = grid_library(ModelOptions(), 64, 2)
    assert is_compiled
    assert f.class_name() == "External"
    libs = list(Path(compiled.cache_root()).glob("grid-*/libgrid_rosenbrock.so"))
    assert libs
    # the external function runs and equals the interpreted one
    fi, _ = grid_library(ModelOptions(), 64, 2, compiled=False)
    rng = np.random.default_rng(0)
    args = [rng.uniform(0, 1e-3, 128), np.zeros(f.size1_in(1)), [100.0, 100.0], None, 1e-4, 1e-3]  # w: 16 + 2
    # (the default law); rtol 1e-3 for the error ratio
    n_p = fi.size1_in(3)
    p = np.zeros(n_p)
    p[:n_p - 2 - 5 * 64] = 1.0
    args[3] = p
    a = [np.array(v).ravel() for v in f(*args)]
    b = [np.array(v).ravel() for v in fi(*args)]
    for x, y in zip(a, b, strict=True):
        assert np.allclose(x, y, rtol=1e-10, atol=1e-14, equal_nan=True)
    assert isinstance(f, ca.Function)
