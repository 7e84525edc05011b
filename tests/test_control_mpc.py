"""MPC path tracking: settings and scenario validation, paths, a short closed loop, failures."""

import dataclasses
import json
import math

import numpy as np
import pytest

from symtrack.control import closedloop as CL
from symtrack.control import scenario as S
from symtrack.control.mpc import MPCSettings, PathTrackingMPC
from symtrack.control.path import Path, Segment, field_segments
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.model import SystemModel


@pytest.fixture(scope="module")
def model():
    return SystemModel()


FAST = {"horizon_steps": 20, "sample_time_s": 0.1}


def fast_scenario(name="straight_offset", **mpc):
    sc = S.load(name)
    return dataclasses.replace(sc, mpc=dataclasses.replace(sc.mpc, **{**FAST, **mpc}))


@pytest.mark.parametrize("kw, field", [
    ({"horizon_steps": 1}, "horizon_steps"), ({"sample_time_s": 0.0}, "sample_time_s"),
    ({"solver": "snopt"}, "solver"), ({"torque_max_N_m": -1.0}, "torque_max_N_m"),
    ({"collocation_degree": 4}, "collocation_degree"), ({"weight_lateral": -1.0}, "weight_lateral"),
    ({"prediction": "cells"}, "prediction"), ({"jit": "yes"}, "jit"),
])
def test_settings_validation(kw, field):
    with pytest.raises(ParameterError, match=f"mpc.{field}"):
        MPCSettings(**kw)


@pytest.mark.parametrize("override, match", [
    ("mpc.horizon_step=5", "unknown key"),
    ("path.speed_m_s=50", r"path.speed_m_s = 50 is outside the allowed range \[0.1, 10\]"),
    ("run.integrator='rk4'", "run.integrator"),
    ("soil.preset='moon_dust'", "moon_dust"),
    ("start.speed_m_s=-1", "start.speed_m_s"),
])
def test_scenario_validation(override, match):
    with pytest.raises(ScenarioError, match=match):
        S.load("straight_offset", [override])


def test_scenario_segment_validation(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('[path]\nsegments = [{arc_radius_m = 0.5, angle_deg = 90.0}]\n')
    with pytest.raises(ScenarioError, match=r"segments\[0\].arc_radius_m"):
        S.load(str(f))
    f.write_text('[path]\nkind = "field"\npasses = 0\n')
    with pytest.raises(ScenarioError, match="path.passes"):
        S.load(str(f))


def test_builtin_scenarios_load():
    names = S.builtin_names()
    assert {"straight_offset", "headland_uturn", "field_pattern"} <= set(names)
    for n in names:
        sc = S.load(n)
        assert sc.mpc.horizon_s >= 2.0
        sc.build_path()


def _walked(x, y, psi, segments, extension_m=30.0, ds_m=0.02):
    """A path's samples walked step by step (each straight step along the heading, each arc step along its
    circle), the reference the vectorised Path reproduces to the last bit: the closed-loop runs on it
    (test_control_rti's re-linearised step at the apex of the shear law's cone) depend on its last bits."""
    xs, ys, ps = [x], [y], [psi]
    for seg in [*segments, Segment("straight", extension_m)]:
        kappa = 0.0 if seg.kind == "straight" else 1.0 / seg.radius_m
        L = seg.length_m if seg.kind == "straight" else abs(seg.radius_m) * math.radians(seg.angle_deg)
        n = max(1, math.ceil(L / ds_m))
        h, sgn = L / n, (-1.0 if seg.reverse else 1.0)
        for _ in range(n):
            if kappa == 0.0:
                x += sgn * h * math.cos(psi)
                y += sgn * h * math.sin(psi)
            else:
                x += sgn * (math.sin(psi + h * kappa) - math.sin(psi)) / kappa
                y -= sgn * (math.cos(psi + h * kappa) - math.cos(psi)) / kappa
                psi += h * kappa
            xs.append(x)
            ys.append(y)
            ps.append(psi)
    return np.array(xs), np.array(ys), np.array(ps)


def test_a_path_is_the_step_by_step_walk_to_the_last_bit():
    segs = [Segment("straight", 7.3), Segment("arc", radius_m=4.0, angle_deg=180.0),
            Segment("arc", radius_m=-3.0, angle_deg=75.0, reverse=True), Segment("straight", 2.01, reverse=True)]
    p = Path(1.5, -2.25, 0.3, segs, 1.5, 0.8)
    for got, want in zip((p.x, p.y, p.psi), _walked(1.5, -2.25, 0.3, segs), strict=True):
        assert np.array_equal(got, want)
    assert list(np.unique(p.segment)) == [-1, 0, 1, 2, 3] and set(p.direction) == {-1.0, 1.0}


def test_field_path_geometry():
    p = Path(0, 0, 0, field_segments(3, 20.0, 6.0), 2.0, 1.0)
    assert p.length_m == pytest.approx(3 * 20 + 2 * math.pi * 3, rel=1e-6)
    end = p.at(p.length_m)
    # after two U-turns (left then right) the heading is back to 0, and 12 m to the left
    assert end["yaw_rad"] == pytest.approx(0.0, abs=1e-9)
    assert end["y_m"] == pytest.approx(12.0, abs=1e-6)
    assert end["x_m"] == pytest.approx(20.0, abs=1e-6)
    # the turn speed applies on arcs
    assert p.at(21.0)["speed_m_s"] == 1.0 and not p.at(21.0)["straight"]
    # projection with a hint never jumps to the parallel pass
    s = p.project(10.0, 6.5, s_hint=10.0)
    assert s == pytest.approx(10.0, abs=0.05)
    e_lat, _ = p.errors(10.0, 0.5, 0.0, 10.0)
    assert e_lat == pytest.approx(0.5)


def test_reference_yaw_continuity():
    p = Path(0, 0, 0, [Segment("straight", 5.0), Segment("arc", radius_m=2.0, angle_deg=180)], 1.0)
    ref = p.reference(4.0, 40, 0.1, 2 * math.pi)
    assert ref[0, 2] == pytest.approx(2 * math.pi)
    assert np.all(np.diff(ref[:, 2]) >= -1e-12)


def test_closed_loop_straight_offset(model, tmp_path):
    sc = fast_scenario()
    res = CL.run(sc, model=model, max_steps=30)
    s = res.summary
    for key in ("rms_lateral_error_m", "max_lateral_error_m", "solve_time_median_ms", "solve_time_p95_ms",
                "solve_time_max_ms", "failed_solves", "horizon_s", "sample_time_s"):
        assert key in s
    assert s["failed_solves"] == int(np.sum(~res.solve_ok)) <= 3
    assert s["horizon_s"] == pytest.approx(2.0)
    # the 1 m offset is being removed: after 3 s the vehicle is within 20 cm
    assert abs(res.e_lat[0]) == pytest.approx(1.0, abs=1e-6)
    assert abs(res.e_lat[-1]) < 0.2
    # torque and torque-rate bounds hold
    st = sc.mpc
    assert np.max(np.abs(res.U)) <= st.torque_max_N_m * (1 + 1e-6)
    rate = np.max(np.abs(np.diff(res.U[:-1], axis=0))) / st.sample_time_s
    assert rate <= st.torque_rate_max_N_m_s * (1 + 1e-4)
    CL.write(tmp_path, res)
    d = json.loads((tmp_path / "summary.json").read_text())
    assert d["schema_version"] == CL.SUMMARY_SCHEMA_VERSION
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert {"t_s", "x_m", "lateral_error_m", "torque_cmd_left_N_m", "solve_time_ms"} <= set(header)
    for png in ("path.png", "errors.png", "torques.png", "solve_times.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"
    # the notebook view: what ran and the summary's figures with their units, a well-formed fragment
    import xml.etree.ElementTree as ET

    root = ET.fromstring(res._repr_html_())
    text = "".join(root.itertext())
    assert f"scenario: {sc.name}" in text and f"solver: {sc.mpc.solver}" in text and "plant: homogeneous" in text
    rows = {tr[0].text: (tr[1].text, tr[2].text) for tr in root.find("table").iter("tr") if tr[0].tag == "td"}
    assert rows["solve_time_median_ms"][1] == "ms" and rows["rms_lateral_error_m"][1] == "m"


def test_mpcs_of_one_problem_share_its_solvers_and_solve_alike(model):
    """Two MPCs of the same problem (model, settings) share the NLP solvers built once in the process
    (symtrack.control.mpc._NLPSOLS; the RTI's cold start solves with the fallback), with their own starts:
    the second's first step is the first's;
    another problem (a longer horizon) gets solvers of its own."""
    sc = fast_scenario()
    a, b = (PathTrackingMPC(model, sc.params, sc.mpc) for _ in range(2))
    assert a.fallback is not None and a.fallback is b.fallback and a.solver is b.solver
    x, u = CL.initial_state(model, sc)
    ref = sc.build_path().reference(0.0, a.N, sc.mpc.sample_time_s, 0.0)
    nv = model.layout.nv
    ua, ia = a.step(x[:nv], x[nv:], u, ref)
    ub, ib = b.step(x[:nv], x[nv:], u, ref)
    assert ia.success and ib.success
    np.testing.assert_array_equal(ua, ub)
    c = PathTrackingMPC(model, sc.params, dataclasses.replace(sc.mpc, horizon_steps=21))
    assert c.fallback is not a.fallback


def test_failed_solve_reuses_shifted_plan(model):
    sc = fast_scenario()
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    x, u = CL.initial_state(model, sc)
    path = sc.build_path()
    ref = path.reference(0.0, mpc.N, sc.mpc.sample_time_s, 0.0)
    info = mpc.prepare(x[:model.layout.nv], x[model.layout.nv:], u, ref)
    assert info.success
    _, plan = mpc.predicted()
    # a reference with NaN makes the solver fail: no exception, the shifted plan is applied
    bad = ref.copy()
    bad[:, 0] = np.nan
    u1, info1 = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, bad)
    assert not info1.success and mpc.stats.failed == 1
    np.testing.assert_allclose(u1, plan[1])
    u2, _ = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, bad)
    np.testing.assert_allclose(u2, plan[2])
    assert mpc.stats.failed == 2


class _RecordingPlant:
    """Any object with the Plant protocol (here one that delegates and counts its steps)."""

    def __init__(self, model, sc):
        self.inner = CL.make_plant(sc, model)
        self.calls = 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def advance(self):
        self.calls += 1
        return self.inner.advance()


def test_any_plant_with_the_plant_protocol(model):
    sc = fast_scenario()
    plant = _RecordingPlant(model, sc)
    res = CL.run(sc, model=model, plant=plant, max_steps=5)
    assert plant.calls == 5
    assert len(res.t) == 6


def test_mpc_cli(tmp_path):
    from symtrack.cli import main

    out = tmp_path / "o"
    rc = main(["mpc", "straight_offset", "--out", str(out), "--quiet", "--set", "mpc.horizon_steps=6",
               "--set", "run.duration_s=1.0"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["horizon_steps"] == 6 and s["sim_time_s"] == pytest.approx(1.0)
    assert main(["mpc", "no_such_scenario", "--out", str(out)]) == 2


class _ExtendedPlant:
    """A plant whose state has more entries than the model's (as a grid-terrain plant would)."""

    def __init__(self, model, sc):
        self.inner = CL.make_plant(sc, model)
        self.state_names = self.inner.state_names + ("channel_0_sinkage_m",)
        self.extra = 0.0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        self.extra = state[-1]
        x, y = self.inner.start(x_m, y_m, yaw_rad, u0, state[:-1])
        return np.append(x, self.extra), y

    def advance(self):
        X = self.inner.advance()
        return np.hstack([X, np.full((len(X), 1), self.extra)])


def test_plant_with_another_state_layout_needs_x0(model):
    from symtrack.foundations.errors import SimulationError

    sc = fast_scenario()
    plant = _ExtendedPlant(model, sc)
    with pytest.raises(SimulationError, match="give x0"):
        CL.run(sc, model=model, plant=plant, max_steps=2)
    x, _ = CL.initial_state(model, sc)
    res = CL.run(sc, model=model, plant=plant, x0=np.concatenate([x, [0.0]]), max_steps=3)
    assert res.X.shape == (4, model.nx + 1)
    # the first command continues the trim torques (read from the plant state)
    assert res.summary["failed_solves"] == 0
