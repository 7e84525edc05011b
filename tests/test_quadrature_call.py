"""Issue 26 item 3: a large track quadrature as one call node in generated C only.

Beyond ``INLINE_QUADRATURE_MAX_POINTS`` points per track, a model built with
``ModelOptions.quadrature_call`` (the compiled builders' twin, ``SystemModel.codegen_twin``) sums the
tracks' quadrature by one mapped CasADi Function: the same values and Jacobians as the expanded sum,
code that does not grow with the points, a cache key of its own; CVODES/IDAS keep the expanded form
(CasADi's virtual machine evaluates a call node slowly), and the compiled Rosenbrock on the twin
gives CVODES's validation figures (docs/codegen.md, "Large quadratures")."""

from __future__ import annotations

import dataclasses
import functools

import casadi as ca
import numpy as np
import pytest
from conftest import run_once

from symtrack.foundations.errors import ScenarioError
from symtrack.integrators import grid_rosenbrock as grid_integrator
from symtrack.integrators import registry
from symtrack.integrators.grid_rosenbrock import grid_library
from symtrack.integrators.settings import IntegratorSettings
from symtrack.model import ModelOptions, SystemModel
from symtrack.model.system import PARAM_NAMES
from symtrack.native import cache as compiled
from symtrack.native.grid_rosenbrock import step_functions
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.simulation.result import summarise
from symtrack.simulation.scenario import load_scenario
from symtrack.toolchain import cache as build_cache
from symtrack.vehicles import planar as vehicle
from symtrack.vehicles.planar import VEHICLE_STATES, codegen_options

REFINED = ("model.lateral_split=false", "model.lateral_segments=64", "model.gauss_points=5")  # 320 points
needs_cc = pytest.mark.skipif(build_cache.find_compiler() is None, reason="no C compiler")


def n_calls(f: ca.Function) -> int:
    """The call nodes of an SX Function."""
    return sum(f.instruction_id(k) == ca.OP_CALL for k in range(f.n_instructions()))


def _point(model):
    x = np.zeros(model.nx)
    for name, v in (("u_m_s", 2.0), ("v_m_s", 0.05), ("yaw_rate_rad_s", 0.3), ("omega_left_rad_s", 4.5),
                    ("omega_right_rad_s", 7.5), ("shear_left_m", -0.02), ("shear_right_m", 0.05)):
        x[model.state_index(name)] = v
    for name in model.state_names:
        if name.startswith(("lateral_shear_", "shear_twist_")):
            x[model.state_index(name)] = 0.01 if "lateral" in name else 0.03
        if name.startswith("z_") or "sinkage" in name:
            x[model.state_index(name)] = 0.002
    P = {**vehicle_preset("reference_crawler"), **soil_preset("sandy_loam_15")}
    return x, np.array([0.3, 0.4]), np.array([3000.0, 5000.0]), np.array(model.param_vector(P))


# 16 x 5 = 80 points a track (above INLINE_QUADRATURE_MAX_POINTS): the expanded models of 64 x 5 took 4.5-5.7 s
# of CPU each to build, these 0.9-1.6 s; the mapped model's code is checked not to grow up to 64 x 5
@pytest.mark.parametrize("opts", [
    ModelOptions(lateral_law="shear_quasistatic", lateral_split=False, lateral_segments=16, gauss_points=5,
                 shear_strength_pressure="local"),
    ModelOptions(lateral_law="shear", lateral_split=False, lateral_segments=16, gauss_points=5),
    ModelOptions(lateral_law="creep", lateral_split=False, lateral_segments=16, gauss_points=5),
    # the split rule (its nodes move with the state): 6 x 10 = 60 points
    ModelOptions(lateral_law="shear", shear_points=10, shear_strength_pressure="local"),
    ModelOptions(vehicle="3d", lateral_split=False, lateral_segments=16, gauss_points=5),  # its shear_forces
], ids=["shear_quasistatic-local", "shear", "creep", "shear-split", "3d"])
def test_the_mapped_sum_and_its_jacobian_equal_the_expanded_ones(opts):
    expanded = SystemModel(opts)
    mapped = expanded.codegen_twin
    assert mapped is not expanded and mapped.opts.quadrature_call and vehicle.quadrature_is_mapped(mapped.opts)
    assert n_calls(expanded.dae) == 0 and n_calls(mapped.dae) == 2  # one per track
    assert mapped.dae.n_instructions() * 4 < expanded.dae.n_instructions()
    if not opts.lateral_split:  # the mapped sum's code does not grow with the points: the same at 64 x 5
        finer = SystemModel(dataclasses.replace(mapped.opts, lateral_segments=64))
        assert vehicle.quadrature_is_mapped(finer.opts)
        assert finer.dae.n_instructions() == mapped.dae.n_instructions()
    x, z, u, p = _point(expanded)
    got, ref = (np.concatenate([np.array(v).ravel() for v in m.dae(x, z, u, p)]) for m in (mapped, expanded))
    assert np.abs(ref).max() > 1.0  # the forces are not all zero
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)
    jac_mapped, jac_expanded = (np.array(ca.Function("J", [m.x], [ca.jacobian(m.dae(m.x, z, u, p)[0], m.x)])(x))
                                for m in (mapped, expanded))
    assert np.abs(jac_expanded).max() > 1.0
    np.testing.assert_allclose(jac_mapped, jac_expanded, rtol=1e-9, atol=1e-6)


def test_the_default_quadrature_stays_expanded_and_the_flag_is_no_scenario_key():
    m = SystemModel(load_scenario("validation").model)  # the model of generated/ (12 points per track)
    assert m.codegen_twin is m and n_calls(m.dae) == 0
    assert SystemModel(ModelOptions()).codegen_twin.opts.quadrature_call is False  # 24 points: expanded
    assert not vehicle.quadrature_is_mapped(ModelOptions(quadrature_call=True))
    # the 3D vehicle's creep law sums over its contact segments, not this quadrature: no twin
    refined_3d_creep = ModelOptions(vehicle="3d", lateral_law="creep", lateral_split=False, lateral_segments=64,
                                    gauss_points=5)
    assert vehicle.codegen_options(refined_3d_creep) == refined_3d_creep
    with pytest.raises(ScenarioError, match="quadrature_call"):
        load_scenario("validation", ["model.quadrature_call=true"])
    assert "quadrature_call" not in load_scenario("validation", list(REFINED)).to_dict()["model"]


def test_cvodes_and_idas_with_a_large_quadrature_build_the_expanded_form():
    """The slow path (a call node on CasADi's virtual machine, 0.1 x real time) must not come back."""
    m = SystemModel(load_scenario("validation", list(REFINED)).model)
    assert m.codegen_twin is not m  # a compiled build would take the call node
    for method in ("cvodes", "idas"):
        oracle = registry.get(method).stepper("homogeneous", m, IntegratorSettings(method=method)).F.oracle()
        assert n_calls(oracle) == 0, method
        assert oracle.n_instructions() > 10_000, method  # the 2 x 320 points expanded (about 18,000 in dae)


@pytest.mark.slow  # compiles the 64 x 5 twin (about 20 s; make test-slow)
@needs_cc
def test_the_compiled_twin_has_its_own_cache_key_and_matches_the_expanded_model(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMTRACK_CACHE", str(tmp_path))
    m = SystemModel(load_scenario("validation", list(REFINED)).model)
    assert compiled.library(m).source is m  # the compiled CVODES/IDAS: expanded
    lib = compiled.library(m, quadrature_call=True)  # the compiled Rosenbrock's
    assert lib.source is m.codegen_twin
    lib.load("dae")
    assert lib.compiled
    gen_twin, gen_expanded = lib.gens["dae"], compiled.model_functions(m, "homogeneous", ("dae",))
    assert gen_twin.file_hash("homogeneous_dae") != gen_expanded.file_hash("homogeneous_dae")
    assert lib.paths["dae"].parent.name.startswith("homogeneous_dae-" + gen_twin.file_hash("homogeneous_dae")[:8])
    x, z, u, p = _point(m)
    for short, args in (("dae", (x, z, u, p)), ("accel", (x, u, p))):
        f = lib.f(short)
        assert f.class_name() == "External"
        ref = gen_expanded.function(f"homogeneous_{short}")(*args)
        got = f(*args)
        for a, b in zip(got if isinstance(got, tuple) else (got,), ref if isinstance(ref, tuple) else (ref,),
                        strict=True):
            np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-12, atol=1e-9)
    jac = lib.f("dae").jacobian()  # the compiled jac_homogeneous_dae
    ref = gen_expanded.function("homogeneous_dae").jacobian()
    out, want = jac(x, z, u, p, 0, 0), ref(x, z, u, p, 0, 0)
    for a, b in zip(out, want, strict=True):
        np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-10, atol=1e-6)


@needs_cc
@pytest.mark.slow
def test_compiled_rosenbrock_on_a_64x5_rule_gives_the_cvodes_figures(monkeypatch):
    """The compiled call-node Rosenbrock (0.5 ms steps: its own error 1e-8, where 1 ms steps leave
    2e-4 on the sinkage) against tight CVODES on the expanded model, over the validation's programme
    with the idle instant at 1 s (not 4 s), to 1.6 s (a 1 s straight and the start of the turn, the left
    sprocket idle): every state at the end and the figures of the run within 1e-6 relative, 3e-6 where
    the idle track's shear enters (measured: the states within 2.2e-6, the figures within 6.1e-7, the
    idle track's shear minimum 1.0e-6; over the whole validation within 1.4e-8, the idle track's shear
    minimum apart: 1.2e-6; its path crosses the soil's switch from loading to unloading at the idle
    instant, a kink where the fixed step is of second order; docs/model.md, "Track kinematics and shear
    displacement"; 7.9e-9 without the elastic unloading, where its tolerance was 1e-6)."""
    # a 1 s straight, not the validation's 4 s: CVODES at reltol 1e-10 on the expanded model is most of the
    # test's CPU (16 s for these 1.6 s, 29 s for 4.6 s), and 0.6 s of the turn still yaws the crawler 1.3e-3 rad
    T_IDLE, T_END = 1.0, 1.6
    figures = ("lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm", "sinkage_idler_mm",
               "shear_driven_max_m", "shear_idle_min_m", "speed_final_m_s")
    # its own build at -O1 (tests/conftest.py sets -O0): 3,200 steps of the compiled Rosenbrock run here, and
    # gcc -O1 of the call-node model is small (empty cache: 38 s of CPU for the test at -O1, 51 s at -O0)
    monkeypatch.setenv("SYMTRACK_OPT_LEVEL", "1")
    m = SystemModel(load_scenario("validation", list(REFINED)).model)
    runs = {}
    for integ, extra in (("rosenbrock", ["run.fixed_step_s=0.0005"]),
                         ("cvodes", ["run.reltol=1e-10", "run.abstol=1e-12"])):
        sc = load_scenario("validation", [*REFINED, f"run.integrator={integ}", *extra])
        # the validation's programme with the idle instant at 1 s, not 4 s: the same quadrature, the same
        # switch of the idle track's soil from loading to unloading, a third of the steps
        straight, idle = sc.torque
        sc = dataclasses.replace(sc, torque=(straight, dataclasses.replace(idle, t_s=T_IDLE)),
                                 run=dataclasses.replace(sc.run, duration_s=T_END, stop_after_distance_m=None,
                                                         stop_distance_event=None))
        runs[integ] = run_once(sc, m)
    assert runs["rosenbrock"].stats["compiled"]
    lib = compiled.library(m, quadrature_call=True)  # the run's (one Library per model and mode)
    step = lib.gens["rosenbrock"].function("homogeneous_rosenbrock_step")
    assert n_calls(step) > 0 and step.n_instructions() < 20_000  # the call node (expanded: about 300,000)
    a, b = runs["rosenbrock"], runs["cvodes"]
    assert a.t[-1] == pytest.approx(T_END) and b.t[-1] == pytest.approx(T_END)
    assert a.state("yaw_rad")[-1] > 1e-3  # it turned
    # (the lagged shear law's states, about 7e-4 m, within 3.3e-9 m: atol 1e-8 in SI units)
    np.testing.assert_allclose(np.asarray(a.X)[-1], np.asarray(b.X)[-1], rtol=3e-6, atol=1e-8)
    got, ref = summarise(a), summarise(b)
    for k in figures:
        assert got[k] == pytest.approx(ref[k], rel=3e-6 if k == "shear_idle_min_m" else 1e-6, abs=1e-12), k


@needs_cc
@pytest.mark.slow
def test_the_compiled_grid_step_takes_the_call_node_and_equals_the_expanded_one(monkeypatch):
    # each of the two steps built once: grid_library builds the same two as the assertions below (a 64 x 5
    # step is some 4 s of CPU to build)
    built = functools.cache(step_functions)
    monkeypatch.setattr(grid_integrator, "step_functions", built)
    opts = load_scenario("validation", list(REFINED)).model
    assert n_calls(built(codegen_options(opts), 4, 1)["vehicle_F"]) == 2
    assert n_calls(built(opts, 4, 1)["vehicle_F"]) == 0
    f, is_compiled = grid_library(opts, 4, 1)
    fi, _ = grid_library(opts, 4, 1, compiled=False)  # the interpreter's: expanded
    assert is_compiled and f.class_name() == "External"
    P = {**vehicle_preset("reference_crawler"), **soil_preset("sandy_loam_15")}
    p = [float(P[k]) for k in PARAM_NAMES] + [0.25, 0.1]  # the terrain's globals: cell size, end strip (m)
    p += [0.0] * (fi.size1_in(3) - len(p))  # no channel loaded
    w = np.zeros(fi.size1_in(1))
    for name, v in (("u_m_s", 2.0), ("v_m_s", 0.05), ("yaw_rate_rad_s", 0.3), ("omega_left_rad_s", 4.5),
                    ("omega_right_rad_s", 7.5), ("shear_left_m", -0.02), ("shear_right_m", 0.05)):
        w[VEHICLE_STATES.index(name)] = v
    args = [np.full(8, 1e-3), w, [3000.0, 5000.0], p, 1e-3, 1e-3]  # ..., h, the error ratio's rtol
    got, ref = ([np.array(v).ravel() for v in g(*args)] for g in (f, fi))
    assert np.abs(ref[1] - w).max() > 1e-4  # the step moved the vehicle
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)
