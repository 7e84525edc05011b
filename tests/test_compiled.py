"""Compiled vs interpreted: functions to 1e-12, CVODES/IDAS on compiled code, the fixed-step
integrator against CVODES (1 % on the validation figures) and its order, the standalone program,
the cache and the fallback without a C compiler.

The compiled library lives in the user cache ($SYMTRACK_CACHE or ~/.cache/symtrack): the first
run on a clean machine compiles it once (about 30 s), later runs reuse it.
"""

from __future__ import annotations

import logging

import casadi as ca
import numpy as np
import pytest
from conftest import run_once

from symtrack.foundations.errors import ScenarioError, SimulationError
from symtrack.integrators.fixed_step import FixedStepper
from symtrack.integrators.settings import IntegratorSettings
from symtrack.model import SystemModel
from symtrack.model.static import static_state
from symtrack.native import cache as compiled
from symtrack.native.generate import GROUPS
from symtrack.simulation.result import summarise
from symtrack.simulation.scenario import load_scenario
from symtrack.toolchain import cache as build_cache

pytestmark = pytest.mark.skipif(build_cache.find_compiler() is None, reason="no C compiler")

FIGURES = ("distance_after_idle_m", "lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm",
           "sinkage_idler_mm", "shear_driven_max_m", "shear_idle_min_m", "speed_final_m_s", "sim_time_s")


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("validation")


@pytest.fixture(scope="module")
def model(scenario):
    return SystemModel(scenario.model)


@pytest.fixture(scope="module")
def lib(model):
    lib = compiled.library(model)
    for group in GROUPS:
        lib.load(group)
    assert lib.compiled and all(p.exists() for p in lib.paths.values())
    return lib


@pytest.fixture(scope="module")
def rosenbrock_run(model):
    sc = load_scenario("validation", ["run.integrator=rosenbrock"])
    return run_once(sc, model)


def _points(model, scenario, n=8, seed=1):
    rng = np.random.default_rng(seed)
    x0 = static_state(model, scenario.params)
    p = np.array(model.param_vector(scenario.params))
    for _ in range(n):
        x = x0.copy()
        x[:3] += rng.normal(0, [5, 5, 0.5])
        x[3:6] = rng.normal(0, [3, 0.05, 0.1])
        x[6:8] = x[3] / 0.38 + rng.normal(0, 1, 2)
        x[8:10] = rng.normal(0, 0.01, 2)
        x[10:12] = rng.uniform(-3000, 3000, 2)
        x[12::2] *= rng.uniform(0.5, 1.5, 4)
        x[13::2] = rng.normal(0, 0.01, 4)
        z = rng.normal(0, 1, 2)
        u = rng.uniform(-3000, 3000, 2)
        yield x, z, u, p


def _call(f, *args):
    return f.call([ca.DM(np.asarray(a, dtype=float)) for a in args])


def _close(a, b, rtol=1e-12):
    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    scale = max(1.0, float(np.max(np.abs(b)))) if b.size else 1.0
    return float(np.max(np.abs(a - b))) <= rtol * scale if b.size else True


def test_compiled_functions_agree_with_interpreted(lib, model, scenario):
    interp = lib.interpreted
    checked = 0
    for x, z, u, p in _points(model, scenario):
        for name, args in (("ode", (x, u, p)), ("dae", (x, z, u, p)), ("outputs", (x, u, p)), ("accel", (x, u, p)),
                           ("linearize", (x, u, p)), ("linearize_outputs", (x, u, p))):
            full = f"homogeneous_{name}"
            for a, b in zip(_call(lib.functions[full], *args), _call(interp[full], *args), strict=True):
                assert _close(a, b), (name, np.max(np.abs(np.array(a) - np.array(b))))
                checked += 1
        # the exact Jacobians casadi.external loads (jac_<name>) against the interpreted ones
        for name, args in (("ode", (x, u, p)), ("dae", (x, z, u, p))):
            ext, ref = lib.f(name).jacobian(), interp[f"homogeneous_{name}"].jacobian()
            assert ext.name() == f"jac_homogeneous_{name}"
            outs = [np.zeros((ref.size1_in(i), ref.size2_in(i))) for i in range(len(args), ref.n_in())]
            for a, b in zip(_call(ext, *args, *outs), _call(ref, *args, *outs), strict=True):
                assert _close(a, b)
        # one fixed step
        for a, b in zip(_call(lib.f("rosenbrock_step"), x, z, u, p, 1e-3),
                        _call(interp["homogeneous_rosenbrock_step"], x, z, u, p, 1e-3), strict=True):
            assert _close(a, b)
    assert checked == 8 * 9


def test_library_is_cached_and_reused(lib, model, monkeypatch):
    def no_compile(*a, **k):
        raise AssertionError("compiled again although the cache holds the library")

    monkeypatch.setattr(build_cache, "_compile", no_compile)
    compiled._cache.clear()
    again = compiled.library(model)
    again.f("rosenbrock_step")
    again.f("ode")
    assert again.paths == {"rosenbrock": lib.paths["rosenbrock"], "ode": lib.paths["ode"]}
    stem = "homogeneous_rosenbrock"
    assert again.paths["rosenbrock"].parent.name.startswith(stem + "-" + lib.gens["rosenbrock"].file_hash(stem)[:16])


def test_no_compiler_falls_back_once_or_fails_when_required(model, monkeypatch, caplog):
    monkeypatch.setattr(build_cache, "find_compiler", lambda: None)
    monkeypatch.setattr(build_cache, "_warned_no_compiler", False)
    compiled._cache.clear()
    try:
        with caplog.at_level(logging.WARNING, logger="symtrack.toolchain"):
            lib = compiled.library(model)
            y = lib.f("outputs")
            compiled._cache.clear()
            compiled.library(model).f("accel")
        assert not lib.compiled and y.class_name() != "External"
        assert sum("no C compiler" in r.message for r in caplog.records) == 1
        monkeypatch.setattr(build_cache, "_require", True)
        compiled._cache.clear()
        with pytest.raises(SimulationError, match="no C compiler"):
            compiled.library(model).f("outputs")
    finally:
        compiled._cache.clear()


def test_cvodes_and_idas_on_compiled_model_match_interpreted(model):
    for method in ("cvodes", "idas"):
        res = {}
        for comp in (False, True):
            sc = load_scenario("validation", [f"run.integrator={method}", f"run.compiled={str(comp).lower()}"])
            res[comp] = summarise(run_once(sc, model))
        for k in FIGURES:
            assert res[True][k] == pytest.approx(res[False][k], rel=1e-7, abs=1e-12), (method, k)


def test_rosenbrock_agrees_with_tight_cvodes_within_one_percent(model, rosenbrock_run):
    sc = load_scenario("validation", ["run.integrator=cvodes", "run.reltol=1e-10", "run.abstol=1e-12"])
    ref = summarise(run_once(sc, model))
    got = summarise(rosenbrock_run)
    assert got["stopped_by"] == "distance" and got["nose_up"] == ref["nose_up"]
    for k in FIGURES:
        assert got[k] == pytest.approx(ref[k], rel=0.01), k
    assert rosenbrock_run.stats["compiled"]


def test_rosenbrock_converges_at_fifth_order(model, scenario, rosenbrock_run):
    """Step refinement over 0.2 s of steady turning (no switching of the piecewise laws):
    errors against a 1/256-step solution fall as h^p with p close to 5 (the method's order)."""
    k = int(np.searchsorted(rosenbrock_run.t, 6.0))
    x0, u = rosenbrock_run.X[k], np.array([0.0, 2000.0])
    p = np.array(model.param_vector(scenario.params))
    span = 0.2
    scale = np.maximum(np.abs(rosenbrock_run.X).max(axis=0), 1e-12)

    def solve(n):
        st = FixedStepper(model, IntegratorSettings("rosenbrock", fixed_step_s=span / n))
        z0 = np.array(st.lib.f("accel")(x0, u, p)).ravel()
        return np.array(st.advance(x0, z0, u, p, span)[0]).ravel()

    ref = solve(256)
    errs = [np.max(np.abs(solve(n) - ref) / scale) for n in (8, 16, 32)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 4.5) & (orders < 6.0)), (errs, orders)


def test_stepper_interface_for_rosenbrock(model, scenario):
    from symtrack.integrators.sundials import SundialsStepper as Stepper

    st = FixedStepper(model, IntegratorSettings("rosenbrock", fixed_step_s=0.005))
    x0 = static_state(model, scenario.params)
    p = model.param_vector(scenario.params)
    x1 = st.step(x0, [2000.0, 2000.0], p, 0.1)
    # 20 steps of 5 ms; a step its error control halves costs two more
    assert x1[3] > 0 and st.stats()["nsteps"] == 20 + 2 * st.stats()["fixed_step_steps_halved"]
    cv = Stepper(model, IntegratorSettings("cvodes", 1e-10, 1e-12)).step(x0, [2000.0, 2000.0], p, 0.1)
    assert np.allclose(x1, cv, rtol=1e-3, atol=1e-6)  # the start from rest is the hardest part


def test_standalone_program_reproduces_python(model):
    from symtrack.codegen.standalone import build_standalone, run_standalone

    got = run_standalone(build_standalone(), 1)
    # the standalone program controls its steps' error as the Python run does (its default tolerance)
    ref = summarise(run_once(load_scenario("validation", ["run.integrator=rosenbrock"]), model))
    for k in FIGURES + ("distance_m", "lateral_deviation_signed_m", "fixed_step_error_max"):
        assert got[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-12), k
    assert got["fixed_step_steps_halved"] == ref["fixed_step_steps_halved"] > 0
    assert got["stopped_by"] == ref["stopped_by"] and got["nose_up"] == ref["nose_up"]


def test_run_settings_for_compiled_integrators():
    sc = load_scenario("validation", ["run.integrator=rosenbrock", "run.fixed_step_s=0.005", "run.compiled=true"])
    assert sc.run.fixed_step_s == 0.005 and sc.run.compiled is True
    with pytest.raises(ScenarioError, match=r"run.fixed_step_s = 0.5 is outside the allowed range \[1e-05, 0.1\]"):
        load_scenario("validation", ["run.fixed_step_s=0.5"])
    with pytest.raises(ScenarioError, match="run.compiled"):
        load_scenario("validation", ["run.compiled=1"])


def test_cli_simulate_rosenbrock_and_codegen_check(tmp_path, capsys, monkeypatch):
    from symtrack.cli import main

    monkeypatch.setattr(build_cache, "_require", False)  # restored after the test (--require-compiled sets it)

    assert main(["simulate", "validation", "--integrator", "rosenbrock", "--require-compiled", "--quiet",
                 "--out", str(tmp_path / "run")]) == 0
    assert (tmp_path / "run" / "summary.json").exists()
    assert main(["codegen", "--check"]) == 0


def test_bench_table_and_report():
    from symtrack.bench import homogeneous as bench

    rows = [{"group": "g", "case": "c", "integrator": "rosenbrock", "sim_time_s": 6.87, "wall_time_s": 0.0061,
             "real_time_factor": 1126.2, "note": "n"}, {"group": "g", "case": "other"}]
    t = bench.table(rows)
    assert "| g | c | rosenbrock | 6.87 | 0.0061 | 1126 | n |" in t
    rep = bench.report(rows)
    assert rep["schema_version"] == bench.BENCH_SCHEMA_VERSION and rep["rows"] == rows


def test_fresh_model_without_generated_sources(tmp_path, monkeypatch):
    """A model that differs from generated/ (another option) gets its sources generated afresh
    and compiled into its own cache entry."""
    from symtrack.model import ModelOptions

    monkeypatch.setenv("SYMTRACK_CACHE", str(tmp_path))
    m = SystemModel(ModelOptions(lateral_segments=1, gauss_points=1, accel_newton_iterations=1))
    lib = compiled.library(m, compiled=False)
    lib.load("rosenbrock")
    gen = lib.gens["rosenbrock"]
    srcs = compiled.generated_sources(gen, "homogeneous_rosenbrock")
    assert sorted(srcs) == ["homogeneous_rosenbrock.c", "homogeneous_rosenbrock.h"]
    assert srcs["homogeneous_rosenbrock.c"] != (compiled.REPO_GENERATED / "homogeneous_rosenbrock.c").read_bytes()
    assert not lib.compiled and lib.f("rosenbrock_step").class_name() != "External"


def test_bench_calls_the_providers_that_exist(monkeypatch):
    import sys
    import types

    from symtrack.bench import homogeneous as bench

    fake = types.ModuleType("fake_bench_provider")
    fake.bench_rows = lambda quick: [{"group": "grid", "case": f"quick={quick}"}]
    monkeypatch.setitem(sys.modules, "fake_bench_provider", fake)
    monkeypatch.setattr(bench, "PROVIDERS", ("fake_bench_provider", "symtrack.no_such_bench_module"))
    monkeypatch.setattr(bench, "homogeneous_rows", lambda quick, repeats: [{"group": "h", "case": "x"}])
    rows = bench.collect(quick=True)
    assert rows == [{"group": "h", "case": "x"}, {"group": "grid", "case": "quick=True"}]


def test_chunked_run_matches_the_step_by_step_loop_with_substeps(model, monkeypatch):
    """The batch plant (256 steps per call, output intervals cut into 3 steps that straddle the
    chunk boundaries) against the step plant driving the same FixedStepper one output step per call."""
    from symtrack.simulation import loop
    from symtrack.simulation.plants import BatchPlant, StepPlant

    sc = load_scenario("validation", ["run.integrator=rosenbrock", "run.fixed_step_s=0.004"])
    settings = sc.run.integrator_settings()
    plant = BatchPlant(model, sc.params, FixedStepper(model, settings), sc.run.output_dt_s)
    assert plant.max_intervals == 85  # 256 steps per call, 3 steps per output interval
    chunked = summarise(loop.run(sc, plant))
    looped = summarise(loop.run(sc, StepPlant(model, sc.params, FixedStepper(model, settings))))
    for k in FIGURES + ("distance_m",):
        assert chunked[k] == pytest.approx(looped[k], rel=1e-7, abs=1e-12), k
