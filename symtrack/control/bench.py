"""Timing comparison of the path-tracking controllers, for ``symtrack bench`` to call.

:func:`timing_comparison` runs the same closed-loop scenario (default: ``straight_offset``) with

- ``nmpc_ipopt_plain``: the nonlinear MPC with IPOPT, interpreted (CasADi VM, ``expand``), no
  compilation: the reference point;
- ``nmpc_fast``: the fast configuration (:data:`FAST_CONFIG`);
- ``linear_mpc``: a linear MPC on the exact linearization at straight running (path frame:
  lateral offset and heading error kept), discretised with zero-order hold, solved as a sparse
  QP with OSQP through ``casadi.conic``;

and reports per row the build time, the solve-time median / p95 / max, the failed solves and
the tracking errors. The machine and its load decide the absolute numbers: compare the ratios
measured in one run. Nothing here asserts a time.

:func:`prediction_effect` measures what freezing the terrain cells in the prediction model costs:
the open-loop predictions of the "vehicle" and the "full" prediction variants from the same
state and the same torque plan.
"""

from __future__ import annotations

import dataclasses
import time

import casadi as ca
import numpy as np

from ..model import SystemModel
from ..simulation.builder import system_model
from . import closedloop
from . import scenario as scenario_mod
from .linearization import linearize
from .mpc import TORQUE_SCALE_N_M, MPCStats, SolveInfo
from .trim import trim

__all__ = ["FAST_CONFIG", "LinearMPC", "bench_rows", "prediction_effect", "table_markdown", "timing_comparison"]

# The fast configuration: fatrop (Riccati-structured interior point) with its functions
# jit-compiled (gcc -O1), and the pseudo-Huber lateral penalty (delta 0.2 m), with which fatrop
# converged on every solve of the built-in scenarios (with the plain quadratic penalty it failed
# in the 1 m approach of straight_offset, where IPOPT does not). Measured in docs/control.md.
FAST_CONFIG = {"solver": "fatrop", "jit": True, "lateral_huber_m": 0.2}
# the real-time iteration (symtrack.control.rti) with its functions compiled (cached);
# the pseudo-Huber lateral penalty and a x5 terminal lateral weight keep its Gauss-Newton steps
# contracting in the 1 m approach on the creep law (with x50 they diverge there: docs/control.md).
# qrqp named: DAQP is the RTI's default QP solver (the row nmpc_rti_daqp adds it).
RTI_CONFIG = {"solver": "rti", "jit": True, "lateral_huber_m": 0.2, "terminal_lateral_factor": 5.0,
              "rti_qp_solver": "qrqp"}


class LinearMPC:
    """Linear MPC on the linearization at straight running at the path's speed (path frame).

    Same interface as PathTrackingMPC for :func:`closedloop.run`: deviation states are the kept
    states of :func:`linearize` with ``path_frame=True``, except that y_m and yaw_rad are replaced
    by the lateral and heading errors to the reference (exact for straight paths). Weights and
    bounds are those of the MPCSettings given; the torque rate is penalised and bounded.
    """

    def __init__(self, model: SystemModel, params: dict, settings, speed_m_s: float):
        self.model, self.settings = model, settings
        s = settings
        tp = trim(model, params, speed_m_s)
        self.lin = linearize(model, tp, path_frame=True)
        self.tp = tp
        self.pred_names = model.layout.vehicle_names
        self.cell_names = model.layout.cell_names
        self.N = s.horizon_steps
        self.stats = MPCStats()
        import control  # python-control, imported on first use: its scipy.signal import takes seconds

        sysd = control.c2d(self.lin.sys, s.sample_time_s, "zoh")
        Ad, Bd = np.asarray(sysd.A), np.asarray(sysd.B) * TORQUE_SCALE_N_M  # inputs in kN m
        n, m, N = Ad.shape[0], 2, self.N
        names = self.lin.state_names
        self.n = n
        w = np.zeros(n)
        w[names.index("y_m")] = s.weight_lateral
        w[names.index("yaw_rad")] = s.weight_heading
        w[names.index("u_m_s")] = s.weight_speed
        w[names.index("yaw_rate_rad_s")] = s.weight_yaw_rate
        # condensed: x_k = Phi_k dx0 + sum_j Gam_kj du_j (states eliminated; the QP has only the
        # 2 N torque deviations, which keeps it well conditioned despite the stiff cell modes)
        Phi = [np.eye(n)]
        for _ in range(N):
            Phi.append(Ad @ Phi[-1])
        Gam = np.zeros((N + 1, n, m * N))
        for k in range(1, N + 1):
            Gam[k] = Ad @ Gam[k - 1]
            Gam[k][:, (k - 1) * m:k * m] += Bd
        nz = m * N
        H = np.zeros((nz, nz))
        F = np.zeros((nz, n))  # linear term: 2 F dx0
        for k in range(1, N + 1):
            Wk = np.diag(w) * (s.terminal_factor if k == N else 1.0)
            H += 2 * Gam[k].T @ Wk @ Gam[k]
            F += 2 * Gam[k].T @ Wk @ Phi[k]
        D = np.eye(nz) - np.eye(nz, k=-m)  # du_k - du_{k-1} (the first row against u_prev)
        H += 2 * s.weight_torque_rate * D.T @ D + 2 * s.weight_torque * np.eye(nz)
        H = 0.5 * (H + H.T)
        self.F, self.D = F, D
        self.nz = nz
        self.qp = ca.conic("lmpc", "osqp", {"h": ca.DM(H).sparsity(), "a": ca.DM(D).sparsity()},
                           {"osqp": {"verbose": False, "eps_abs": 1e-7, "eps_rel": 1e-7, "max_iter": 10000,
                                     "polish": False},
                            "error_on_fail": False, "print_time": False})
        self.Hd, self.Dd = ca.DM(H), ca.DM(D)
        tmax = s.torque_max_N_m / TORQUE_SCALE_N_M
        u0 = np.tile(tp.u / TORQUE_SCALE_N_M, N)
        self.lbx, self.ubx = -tmax - u0, tmax - u0
        self.rate = s.torque_rate_max_N_m_s * s.sample_time_s / TORQUE_SCALE_N_M
        self.keep = [model.state_names.index(nm) for nm in self.lin.state_names]
        self._plan = None

    def prepare(self, *args, **kw):
        return SolveInfo(True, 0.0, 0, "linear")

    def _deviation(self, x_pred, x_cells, ref):
        x = np.concatenate([np.asarray(x_pred, float), np.asarray(x_cells, float)])
        dx = x[self.keep] - self.lin.x0
        xr, yr, psir = ref[0, 0], ref[0, 1], ref[0, 2]
        lay = self.model.layout
        X, Y, psi = x[lay.pose_index]
        names = self.lin.state_names
        dx[names.index("y_m")] = -(X - xr) * np.sin(psir) + (Y - yr) * np.cos(psir)
        dx[names.index("yaw_rad")] = psi - psir
        dx[names.index("u_m_s")] = x[lay.index("u_m_s")] - ref[0, 3]
        return dx

    def step(self, x_pred, x_cells, u_prev, ref):
        m, N = 2, self.N
        dx0 = self._deviation(x_pred, x_cells, ref)
        du_prev = (np.asarray(u_prev, float) - self.tp.u) / TORQUE_SCALE_N_M
        g = self.F @ dx0
        # the first rate term (u_0 - u_prev)^2 links to the known previous command
        g[:m] -= 2 * self.settings.weight_torque_rate * du_prev
        lba = -self.rate * np.ones(self.nz)
        uba = self.rate * np.ones(self.nz)
        lba[:m] += du_prev
        uba[:m] += du_prev
        t0 = time.perf_counter()
        try:
            sol = self.qp(h=self.Hd, g=g, a=self.Dd, lba=lba, uba=uba, lbx=self.lbx, ubx=self.ubx)
            ok = bool(self.qp.stats().get("success", False))
            z = np.array(sol["x"]).ravel()
            ok = ok and bool(np.all(np.isfinite(z)))
        except RuntimeError:
            ok, z = False, None
        info = SolveInfo(ok, time.perf_counter() - t0, 0, "linear QP")
        self.stats.solves.append(info)
        if ok:
            self._plan = self.tp.u + TORQUE_SCALE_N_M * z.reshape(N, m)
            self._age = 0
            return self._plan[0].copy(), info
        self.stats.failed += 1
        if self._plan is None:
            return np.asarray(u_prev, float).copy(), info
        self._age += 1
        return self._plan[min(self._age, N - 1)].copy(), info


def _row(name, description, build_s, res) -> dict:
    s = res.summary
    return {
        "controller": name,
        "description": description,
        "build_s": build_s,
        "solve_time_median_ms": s["solve_time_median_ms"],
        "solve_time_p95_ms": s["solve_time_p95_ms"],
        "solve_time_max_ms": s["solve_time_max_ms"],
        "failed_solves": s["failed_solves"],
        "solves": s["solves"],
        "rms_lateral_error_m": s["rms_lateral_error_m"],
        "max_lateral_error_m": s["max_lateral_error_m"],
        "max_lateral_error_straights_m": s["max_lateral_error_straights_m"],
        "horizon_s": s["horizon_s"],
        "sample_time_s": s["sample_time_s"],
        "path_completed": s["path_completed"],
        "scenario": s["scenario"],
        "fallback_solves": s.get("fallback_solves", 0),
        "preparation_time_median_ms": s.get("preparation_time_median_ms"),
        "overrun_samples": s.get("overrun_samples"),
    }


def timing_comparison(scenario: str = "straight_offset", max_steps: int | None = None, fast_config: dict | None = None,
                      jit_dir: str | None = None, include=("nmpc_ipopt_plain", "nmpc_fast", "linear_mpc", "nmpc_rti",
                                                         "nmpc_rti_daqp", "nmpc_rti_default"),
                      model: SystemModel | None = None, overrides=()) -> list[dict]:
    """Run the scenario (with ``overrides``, 'section.key=value' strings as for ``symtrack mpc
    --set``) with each controller in ``include``; returns one dict per row."""
    from .mpc import PathTrackingMPC

    base = scenario_mod.load(scenario, overrides)
    model = model or system_model(base.model, base.surface)  # the scenario's [model] (an override's too)
    rows = []
    fast = dict(FAST_CONFIG if fast_config is None else fast_config)
    if jit_dir is not None:
        fast["jit_dir"] = jit_dir
    for name in include:
        if name == "linear_mpc":
            sc = base
            t0 = time.perf_counter()
            ctrl = LinearMPC(model, sc.params, sc.mpc, sc.build_path().at(0.0)["speed_m_s"])
            desc = f"linear MPC (OSQP) on the linearization at straight running, N = {sc.mpc.horizon_steps}"
        else:
            rti = name.startswith("nmpc_rti")
            cfg = {"solver": "ipopt"} if name == "nmpc_ipopt_plain" else (dict(RTI_CONFIG) if rti else fast)
            if name == "nmpc_rti_daqp":  # the same RTI with DAQP (dual active set) on the dense QP
                cfg["rti_qp_solver"] = "daqp"
            if name == "nmpc_rti_default":  # the RTI's defaults (jit, DAQP, the scenario's cost)
                cfg = {"solver": "rti"}
            if rti and jit_dir is not None:
                cfg["jit_dir"] = jit_dir
            sc = dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, **cfg))
            t0 = time.perf_counter()
            ctrl = PathTrackingMPC(model, sc.params, sc.mpc)
            desc = (f"NMPC {sc.mpc.solver}{' + jit' if sc.mpc.uses_jit else ''}, Radau-{sc.mpc.collocation_degree} "
                    f"collocation, N = {sc.mpc.horizon_steps}")
            if rti:
                desc = (f"RTI{' defaults' if name == 'nmpc_rti_default' else ''}: 1 Gauss-Newton SQP step/sample "
                        f"(re-linearised once after a rejected step), {sc.mpc.rti_qp_solver} on the condensed QP, "
                        f"{'compiled' if sc.mpc.uses_jit else 'interpreted'}, Huber {sc.mpc.lateral_huber_m:g} m, "
                        f"terminal lateral x{sc.mpc.terminal_lateral_factor:g}, "
                        f"N = {sc.mpc.horizon_steps}")
        build = time.perf_counter() - t0
        res = closedloop.run(sc, model=model, mpc=ctrl, max_steps=max_steps)
        rows.append(_row(name, desc, build, res))
    return rows


def table_markdown(rows: list[dict]) -> str:
    def f(v, scale=1.0, fmt="{:.1f}"):
        return "-" if v is None else fmt.format(scale * v)

    lines = ["| scenario | controller | build [s] | median [ms] | p95 [ms] | max [ms] | RTI preparation median [ms] "
             "| over 0.1 s | failed (fallbacks) | RMS lat. straights [cm] "
             "| max lat. (all) [cm] | path completed |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.get('scenario', '-')} | {r['controller']} ({r['description']}) | {f(r['build_s'])} "
                     f"| {f(r['solve_time_median_ms'])} | {f(r['solve_time_p95_ms'])} | {f(r['solve_time_max_ms'])} "
                     f"| {f(r.get('preparation_time_median_ms') or None, 1, '{:.2f}')} "
                     f"| {r.get('overrun_samples', '-')} "
                     f"| {r['failed_solves']}/{r['solves']} ({r.get('fallback_solves', 0)}) "
                     f"| {f(r['rms_lateral_error_m'], 100, '{:.2f}')} | {f(r['max_lateral_error_m'], 100)} "
                     f"| {'yes' if r['path_completed'] else 'no'} |")
    return "\n".join(lines) + "\n"


def prediction_effect(speed_m_s: float = 2.0, radius_m: float = 10.0, horizon_steps: int = 20,
                      sample_time_s: float = 0.1, soil: str = "sandy_loam_15") -> dict:
    """Largest difference over a horizon between the predictions with the cells frozen
    ("vehicle") and with the cells integrated ("full"): from straight running at speed, the
    torque plan that ramps to the steady turn of radius_m is integrated by both variants (same
    Radau collocation, solved as a root-finding problem) and by the plant (CVODES)."""
    from ..integrators.settings import IntegratorSettings
    from ..integrators.sundials import SundialsStepper
    from ..presets import soil_preset, vehicle_preset
    from .mpc import MPCSettings, PathTrackingMPC

    params = {**vehicle_preset("reference_crawler"), **soil_preset(soil)}
    model = SystemModel()
    st = trim(model, params, speed_m_s)
    tu = trim(model, params, speed_m_s, radius_m)
    N = horizon_steps
    U = np.array([st.u + (tu.u - st.u) * min(1.0, (k + 1) / 5) for k in range(N)])
    out = {}
    traj = {}
    for pred in ("vehicle", "full"):
        # the exact law in the prediction (no regularisation of the sliding direction): the
        # comparison is with the plant, started at the exact law's trim
        mpc = PathTrackingMPC(model, params, MPCSettings(horizon_steps=N, sample_time_s=sample_time_s, solver="ipopt",
                                                         prediction=pred, prediction_sliding_smoothing=None,
                                                         prediction_sliding_sign="model"), solvers=False)
        fn = mpc.stage_fn
        xs = np.concatenate([st.x[mpc.pred_index], st.u]) / mpc.sx
        xc = st.x[model.layout.block("cells")] if pred == "vehicle" else np.zeros(0)
        X = [xs[mpc.pred] * mpc.sx[mpc.pred]]
        Kv = ca.SX.sym("k", mpc.nk)
        for k in range(N):
            us = U[k] / TORQUE_SCALE_N_M
            g = fn(xs, us, Kv, np.zeros(5), mpc.p_model, xc)[1]
            rf = ca.rootfinder("coll", "newton", ca.Function("g", [Kv], [g]), {"abstol": 1e-10})
            k0 = np.tile(np.concatenate([xs[mpc.pred], np.zeros(mpc.nz)]), mpc.d)
            Ksol = np.array(rf(k0)).ravel()
            xn = np.array(fn(xs, us, Ksol, np.zeros(5), mpc.p_model, xc)[0]).ravel()
            xs = xn
            X.append(xs[mpc.pred] * mpc.sx[mpc.pred])
        traj[pred] = np.array(X)[:, model.layout.block("vehicle")]
    stepper = SundialsStepper(model, IntegratorSettings("cvodes"))
    x = st.x.copy()
    vs = model.layout.block("vehicle")
    P = [x[vs]]
    for k in range(N):
        x = stepper.step(x, U[k], st.p, sample_time_s)
        P.append(x[vs])
    traj["plant"] = np.array(P)
    names = model.layout.vehicle_names
    for key in ("x_m", "y_m", "yaw_rad", "u_m_s", "yaw_rate_rad_s"):
        i = names.index(key)
        out[f"max_abs_diff_vehicle_vs_full_{key}"] = float(np.max(np.abs(traj["vehicle"][:, i] - traj["full"][:, i])))
        out[f"max_abs_diff_full_vs_plant_{key}"] = float(np.max(np.abs(traj["full"][:, i] - traj["plant"][:, i])))
    out["horizon_s"] = N * sample_time_s
    return out


def _cm(v) -> str:
    return "n/a" if v is None else f"{100 * v:.2f} cm"


def bench_rows(quick: bool) -> list[dict]:
    """Rows for ``symtrack bench``: the MPC timing comparison on ``straight_offset`` and
    ``headland_uturn`` (plain IPOPT without compilation, the fast configuration, the linear MPC,
    the RTI), measured in the bench's process. ``quick`` stops each closed loop after 60 samples."""
    rows = []
    for scen in ("straight_offset", "headland_uturn"):  # both scenarios of the RTI targets
        for r in timing_comparison(scen, max_steps=60 if quick else None):
            note = (f"solve median {r['solve_time_median_ms']:.1f} / p95 {r['solve_time_p95_ms']:.1f} / "
                    f"max {r['solve_time_max_ms']:.1f} ms; failed {r['failed_solves']}/{r['solves']} "
                    f"(fallbacks {r['fallback_solves']}); over the sample time {r['overrun_samples']}; "
                    f"rms lateral {_cm(r['rms_lateral_error_m'])}; horizon {r['horizon_s']:g} s; "
                    f"build {r['build_s']:.1f} s; path completed: {r['path_completed']}")
            rows.append({"group": f"MPC {scen} (homogeneous plant)", "case": r["controller"],
                         "integrator": "cvodes plant", "note": note, **r})
    return rows
