"""Real-time iteration, cached compiled MPC functions, real-time honesty and Ctrl-C (issue 13)."""

import dataclasses
import json
import logging
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from symtrack.control import closedloop as CL
from symtrack.control import scenario as S
from symtrack.control.mpc import MPCSettings, MPCStats, PathTrackingMPC, SolveInfo, realtime_figures
from symtrack.control.rti import gn_solve
from symtrack.foundations.errors import ParameterError
from symtrack.model import ModelOptions, SystemModel

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def model():
    return SystemModel()


def _problem(model, name="straight_offset", overrides=(), **mpc):
    sc = S.load(name, list(overrides))
    sc = dataclasses.replace(sc, mpc=dataclasses.replace(sc.mpc, **mpc))
    x, u = CL.initial_state(model, sc)
    ref = sc.build_path().reference(0.0, sc.mpc.horizon_steps, sc.mpc.sample_time_s, x[2])
    return sc, x, u, ref


def test_rti_settings_validation():
    with pytest.raises(ParameterError, match="mpc.rti_qp_solver"):
        MPCSettings(solver="rti", rti_qp_solver="gurobi")
    with pytest.raises(ParameterError, match="mpc.rti_max_defect"):
        MPCSettings(solver="rti", rti_max_defect=0.0)
    with pytest.raises(ParameterError, match=r"mpc.rti_relinearisations = -1 must be an integer in \[0, 10\]"):
        MPCSettings(solver="rti", rti_relinearisations=-1)
    with pytest.raises(ParameterError, match="mpc.jit = 'yes' must be true or false"):
        MPCSettings(solver="rti", jit="yes")
    assert MPCSettings(solver="rti").solver == "rti"
    # the RTI's defaults (issue 21): compiled, DAQP; the NLP solvers interpreted unless asked
    assert MPCSettings(solver="rti").uses_jit and MPCSettings(solver="rti").rti_qp_solver == "daqp"
    assert not MPCSettings(solver="ipopt").uses_jit and MPCSettings(solver="ipopt", jit=True).uses_jit
    assert not MPCSettings(solver="rti", jit=False).uses_jit


def test_the_default_solver_is_the_rti():
    """The solver that meets the sample time is the default, of MPCSettings and of every built-in
    scenario (issue 37: IPOPT, the default before, failed solves and overran the sample time)."""
    assert MPCSettings().solver == "rti" and MPCSettings().uses_jit
    for name in S.builtin_names():
        assert S.load(name).mpc.solver == "rti", name


def test_the_cold_start_prepares_the_first_feedback_at_its_own_measurement(model):
    """The closed loop steps on the measurement the cold start solved for: the first feedback is
    linearised at the cold solution (the measurement's own state), not at its shift one sample
    ahead, which started straight_offset's first sample (1 m offset) 1.9 off the dynamics and failed."""
    sc, x, u, ref = _problem(model, solver="rti", jit=False)
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    assert mpc.prepare(x[:model.layout.nv], x[model.layout.nv:], u, ref).success
    x0s = mpc._x0s(x[:model.layout.nv], u)
    np.testing.assert_allclose(mpc.rti.lin["X"][0], x0s, rtol=0, atol=1e-12)
    u1, info = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, ref)
    assert info.success and "fallback" not in info.status and "re-linearised" not in info.status, info.status


@pytest.mark.parametrize("huber", [0.0, 0.2])
def test_least_squares_residuals_are_the_nlp_cost(model, huber):
    """The Gauss-Newton residuals r of the RTI give the NLP's stage and terminal costs, |r|^2."""
    sc, x, u, ref = _problem(model, lateral_huber_m=huber, solver="rti")
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    rng = np.random.default_rng(1)
    for _ in range(5):
        xs = rng.normal(size=mpc.nxa)
        us = rng.normal(size=2)
        ks = rng.normal(size=mpc.nk)
        rf = ref[3] + rng.normal(scale=0.3, size=5)
        cost = float(mpc.stage_fn(xs, us, ks, rf, mpc.p_model, x[model.layout.nv:])[3])
        r = np.asarray(mpc.res_fn(xs, us, rf)[0]).ravel()
        assert float(r @ r) == pytest.approx(cost, rel=1e-10)
        costN = float(mpc._term_fn(xs, rf))
        rN = np.asarray(mpc.res_term_fn(xs, rf)[0]).ravel()
        assert float(rN @ rN) == pytest.approx(costN, rel=1e-10)


@pytest.mark.parametrize("law, rate, max_iter", [("shear", 0.95, 150), ("creep", 0.7, 60)])
def test_rti_iterates_converge_to_the_converged_nmpc(law, rate, max_iter):
    """Repeated RTI steps on one problem (a stationary reference, no shift) converge to the
    solution of the fully converged NMPC (IPOPT at tol 1e-9) of the same NLP; the first steps
    from a perturbed plan already contract. Gauss-Newton converges linearly, at a rate set by the
    curvature it neglects: measured 0.928 per iteration on the default shear law (100 iterations to
    1e-9), 0.623 on the creep law (19)."""
    model = SystemModel(ModelOptions(lateral_law=law))
    # the NMPC on the RTI's own NLP: the exact law in both, said (symtrack.control.mpc.prediction_model)
    sc, x, u, ref = _problem(model, overrides=["start.y_m=0.3", f"model.lateral_law={law}"], tol=1e-9,
                             prediction_sliding_smoothing=None, prediction_sliding_sign="model")
    nmpc = PathTrackingMPC(model, sc.params, sc.mpc)
    assert nmpc.prepare(x[:model.layout.nv], x[model.layout.nv:], u, ref).success
    w_star = nmpc._w.copy()
    rti = PathTrackingMPC(model, sc.params, dataclasses.replace(sc.mpc, solver="rti"))
    x0s = rti._x0s(x[:model.layout.nv], u)
    # a perturbed plan: torques off by 0.2 kN m (the states and collocation values are then off
    # the dynamics too)
    w0 = w_star.copy()
    blk, nxa = rti.block, rti.nxa
    for k in range(rti.N):
        w0[k * blk + nxa:k * blk + nxa + 2] += 0.2 * np.array([1.0, -1.0])
    steps = []
    w, ok, iters, status = gn_solve(rti, x0s, x[model.layout.nv:], ref, w0, max_iter=max_iter, tol=1e-9,
                                    steps=steps)
    assert ok, status
    dist0 = np.max(np.abs(w0 - w_star))
    assert np.max(np.abs(w - w_star)) < 1e-5 * dist0
    # linear convergence: the later steps shrink by a common factor below 1
    ratios = np.array(steps[3:10]) / np.array(steps[2:9])
    assert np.all(ratios < rate), ratios
    # the torque plan of the RTI equals the NMPC's
    W = w[:rti.N * blk].reshape(rti.N, blk)
    Ws = w_star[:rti.N * blk].reshape(rti.N, blk)
    np.testing.assert_allclose(W[:, nxa:nxa + 2], Ws[:, nxa:nxa + 2], atol=1e-6)


def test_rti_closed_loop_preparation_feedback(model):
    """A short RTI closed loop on the U-turn: every solve is one QP (no fallback on the
    straight approach), the preparation time is recorded apart from the feedback time, the
    tracking stays on the path, and the summary has the real-time figures."""
    sc, *_ = _problem(model, "headland_uturn", solver="rti")
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    res = CL.run(sc, model=model, mpc=mpc, max_steps=25)
    s = res.summary
    assert s["failed_solves"] == 0 and s["fallback_solves"] == 0
    assert all(i.iterations == 1 and i.status.startswith(f"rti {sc.mpc.rti_qp_solver}") for i in mpc.stats.solves)
    assert all(i.preparation_time_s > 0 for i in mpc.stats.solves)
    assert np.max(np.abs(res.e_lat)) < 0.01
    for key in ("overrun_samples", "overrun_worst_ms", "preparation_time_median_ms",
                "computation_per_sample_median_ms"):
        assert key in s
    assert s["preparation_time_median_ms"] > 0


def test_rti_qp_failure_uses_the_fallback(model, monkeypatch):
    """A failed QP: the fallback NLP solver (IPOPT) solves from the prepared guess and its plan
    is applied (a fallback, not a failure); when that fails too, the shifted previous plan."""
    sc, x, u, ref = _problem(model, "headland_uturn", solver="rti")
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    assert mpc.prepare(x[:model.layout.nv], x[model.layout.nv:], u, ref).success
    _, plan = mpc.predicted()
    monkeypatch.setattr(mpc.rti, "feedback", lambda x0s, ref: (None, False, "forced failure"))
    u1, info = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, ref)
    assert info.success and "forced failure -> fallback ipopt" in info.status
    assert mpc.stats.fallbacks == 1 and mpc.stats.failed == 0
    # the applied command is the fallback's plan, not a stale one
    assert np.all(np.isfinite(u1))
    _, plan2 = mpc.predicted()
    np.testing.assert_allclose(u1, plan2[0])
    # both fail (a NaN reference): the shifted previous plan, counted as failed
    bad = ref.copy()
    bad[:, 0] = np.nan
    u2, info2 = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, bad)
    assert not info2.success and mpc.stats.failed == 1
    np.testing.assert_allclose(u2, plan2[1])
    del plan


def test_realtime_figures_count_overruns(caplog):
    st = MPCStats()
    for t in (0.02, 0.15, 0.03, 0.25):
        st.solves.append(SolveInfo(True, t, 1, "x", preparation_time_s=0.01))
    with caplog.at_level(logging.WARNING, logger="symtrack.control.mpc"):
        f = realtime_figures(st, 0.1)
    assert f["overrun_samples"] == 2
    assert f["overrun_worst_ms"] == pytest.approx(260.0)
    assert not caplog.records  # median 0.1 s = the sample time: no warning
    st.solves.append(SolveInfo(True, 0.3, 1, "x"))
    with caplog.at_level(logging.WARNING, logger="symtrack.control.mpc"):
        f = realtime_figures(st, 0.1)
    assert f["overrun_samples"] == 3
    assert any("not real-time" in r.getMessage() for r in caplog.records)


CACHE_SCRIPT = textwrap.dedent("""
    import json, logging, sys
    import numpy as np
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    from symtrack.control import solver_cache, scenario as S, closedloop as CL
    from symtrack.control.mpc import PathTrackingMPC
    from symtrack.model import ModelOptions, SystemModel
    # (the paper's creep law and a short horizon: the smallest generated C that exercises the cache)
    model = SystemModel(ModelOptions(lateral_law="creep"))
    sc = S.load("headland_uturn", [f"mpc.solver='{sys.argv[1]}'", "mpc.jit=true", "mpc.horizon_steps=4",
                                   "model.lateral_law='creep'"])
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    x, u = CL.initial_state(model, sc)
    ref = sc.build_path().reference(0.0, mpc.N, 0.1, 0.0)
    mpc.prepare(x[:model.layout.nv], x[model.layout.nv:], u, ref)
    u1, info = mpc.step(x[:model.layout.nv], x[model.layout.nv:], u, ref)
    print(json.dumps({"builds": len(solver_cache.builds), "u": list(u1), "ok": info.success,
                      "external": mpc.rti.coll.class_name() if mpc.rti else None}))
""")


# IPOPT's NLP functions are one large C file (gcc's longest compile of the MPC; once, in the first process):
# the slow set (make test-slow; CI runs it)
@pytest.mark.parametrize("solver, n_libs", [("rti", 5), pytest.param("ipopt", 1, marks=pytest.mark.slow)])
def test_compiled_mpc_cached_across_processes(tmp_path, solver, n_libs):
    """The first process compiles the RTI functions (or IPOPT's NLP functions) into the cache and
    says so; a second process with the same problem calls no compiler (a CC wrapper logs every
    call) and gets the same command."""
    calls = tmp_path / "cc_calls.txt"
    cc = tmp_path / "cc"
    cc.write_text(f"#!/bin/sh\necho \"$@\" >> {calls}\nexec gcc \"$@\"\n")
    cc.chmod(0o755)
    env = dict(os.environ, SYMTRACK_CACHE=str(tmp_path / "cache"), CC=str(cc), PYTHONPATH=str(REPO))
    runs = []
    for _ in range(2):
        p = subprocess.run([sys.executable, "-c", CACHE_SCRIPT, solver], env=env, capture_output=True, text=True,
                           timeout=600)
        assert p.returncode == 0, p.stderr[-3000:]
        runs.append((json.loads(p.stdout.strip().splitlines()[-1]), p.stderr,
                     calls.read_text().count("\n") if calls.exists() else 0))
    (r1, err1, n1), (r2, err2, n2) = runs
    assert r1["ok"] and r2["ok"] and r1["external"] in ("External", None)
    assert r1["builds"] == n_libs and n1 == n_libs and "compiling MPC" in err1 and "compiled MPC" in err1
    assert r2["builds"] == 0 and n2 == n1 and "compiling" not in err2
    np.testing.assert_array_equal(r1["u"], r2["u"])
    assert len(list((tmp_path / "cache" / "mpc").glob("*/lib*.so"))) == n_libs


def test_ctrl_c_stops_symtrack_mpc(tmp_path):
    """SIGINT during the closed loop of `symtrack mpc` (the solvers' callbacks swallow KeyboardInterrupt):
    exit 130, no summary.json (a run that went on would finish, write it and exit 0). The signal is sent once
    the loop's first progress line is out, on a run slowed to 0.5 m/s (about 12 s of loop on an idle machine;
    at 2 m/s the whole run took under 8 s, and a SIGINT that came as the interpreter exited killed it, -2). No
    wall-clock bound: a SIGINT that arrives inside a long C call acts when the call returns."""
    out = tmp_path / "o"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([sys.executable, "-m", "symtrack", "mpc", "straight_offset", "--out", str(out),
                          "--set", "path.speed_m_s=0.5", "--set", "start.speed_m_s=0.5", "--set", "run.duration_s=300"],
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # a terminal's default
    try:
        seen = []
        for line in p.stderr:  # the model, the trim and the solver built: the loop's first progress line
            seen.append(line)
            if line.startswith("straight_offset:") and "% after" in line:
                break
        assert p.poll() is None, "".join(seen)[-2000:]
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        err = "".join(seen) + err
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err[-2000:]
    assert "interrupted" in err
    assert not (out / "summary.json").exists()


def test_mpc_cli_rti(tmp_path):
    from symtrack.cli import main

    out = tmp_path / "o"
    rc = main(["mpc", "headland_uturn", "--solver", "rti", "--out", str(out), "--quiet",
               "--set", "run.duration_s=1.0"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["solver"] == "rti" and s["failed_solves"] == 0
    assert s["overrun_samples"] >= 0 and s["preparation_time_median_ms"] > 0


def test_rti_on_the_lagged_shear_law_relinearises_the_rejected_step():
    """The RTI on the lagged shear law (the default), clay, a U-turn after 4 m of straight. When
    the turn's curvature enters the horizon the plan sits at exactly symmetric straight running,
    the apex of the law's cone, and its Gauss-Newton step is rejected after the halvings (its
    defect grows linearly with the step: docs/control.md); one more iteration, re-linearised at
    the shortest step, takes it: no failed solve and no NLP fallback. Without the
    re-linearisation the same sample goes to the NLP fallback (or fails)."""
    def run(relin, max_steps=None):
        sc = S.load("headland_uturn", ["soil.preset=clayey_soil_thailand_38", "model.lateral_law=shear",
                                       "mpc.solver=rti", "mpc.jit=false", f"mpc.rti_relinearisations={relin}",
                                       "path.segments=[{straight_m=4.0},{arc_radius_m=4.0,angle_deg=180.0}]"])
        model = SystemModel(sc.model)
        mpc = PathTrackingMPC(model, sc.params, sc.mpc)
        return CL.run(sc, model=model, mpc=mpc, max_steps=max_steps), mpc

    res, mpc = run(1)
    s = res.summary
    assert s["path_completed"] and s["failed_solves"] == 0 and s["fallback_solves"] == 0
    assert any("re-linearised" in i.status for i in mpc.stats.solves), s["solve_status_counts"]
    assert np.max(np.abs(res.e_lat)) < 0.05
    assert abs(res.X[-1, res.state_names.index("yaw_rad")] - np.pi) < 0.2
    # the turn enters the horizon at once: the rejected step is the second sample's (measured), so 5
    # samples of the loop without the re-linearisation hold it (the whole turn: 107)
    res0, _ = run(0, max_steps=5)
    s0 = res0.summary
    assert s0["failed_solves"] + s0["fallback_solves"] >= 1
    assert any("halvings" in k and "re-linearised" not in k for k in s0["solve_status_counts"])
