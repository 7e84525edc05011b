"""LQR of the speed and the yaw rate
=================================

LQR with integral action for speed and yaw rate, designed on the exact linearization at a
steady turn and run on the nonlinear model (the full simulator, CVODES).

    PYTHONPATH=. .venv/bin/python examples/lqr_speed_yaw.py --out out/lqr

Design: trim at V = 2 m/s on a 20 m left turn (sandy loam); linearize (17 states, positions
dropped); add two integrators of the speed and yaw-rate errors; continuous LQR from
python-control. On the nonlinear model the controller is u = u_trim - K [x - x_trim; integrals],
applied with a zero-order hold every ``--dt`` seconds; the references step in speed and then in
yaw rate. Writes lqr_response.png and lqr_summary.json (schema_version 1) to --out.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import control
import numpy as np

from symtrack.control.linearization import linearize
from symtrack.control.trim import trim
from symtrack.foundations.files import atomic_write_bytes, atomic_write_text
from symtrack.integrators.settings import IntegratorSettings
from symtrack.integrators.sundials import SundialsStepper as Stepper
from symtrack.model import SystemModel
from symtrack.presets import soil_preset, vehicle_preset


def design(lin, q_speed=30.0, q_yaw=300.0, q_int_speed=30.0, q_int_yaw=300.0, r_torque_per_kNm=1.0):
    """LQR on [x; integral of (u - u_ref); integral of (r - r_ref)] (deviation variables)."""
    n = lin.A.shape[0]
    iu, ir = lin.state_names.index("u_m_s"), lin.state_names.index("yaw_rate_rad_s")
    Cr = np.zeros((2, n))
    Cr[0, iu] = 1.0
    Cr[1, ir] = 1.0
    Aa = np.block([[lin.A, np.zeros((n, 2))], [Cr, np.zeros((2, 2))]])
    Ba = np.vstack([lin.B, np.zeros((2, 2))])
    Q = np.zeros((n + 2, n + 2))
    Q[iu, iu], Q[ir, ir] = q_speed, q_yaw
    Q[n, n], Q[n + 1, n + 1] = q_int_speed, q_int_yaw
    R = np.eye(2) * r_torque_per_kNm / 1e6  # per (N m)^2
    K, _, E = control.lqr(Aa, Ba, Q, R)
    return K, E, Cr


def run(duration_s=8.0, dt=0.01, out=None, speed_step_m_s=0.3, yaw_rate_step_rad_s=0.02):
    params = {**vehicle_preset("reference_crawler"), **soil_preset("sandy_loam_15")}
    model = SystemModel()
    tp = trim(model, params, 2.0, 20.0)
    lin = linearize(model, tp)
    K, E, Cr = design(lin)
    keep = [model.state_names.index(n) for n in lin.state_names]
    stepper = Stepper(model, IntegratorSettings("cvodes"))
    x = tp.x.copy()
    integ = np.zeros(2)
    ts, refs, ys, us = [], [], [], []
    t = 0.0
    for _ in range(int(round(duration_s / dt))):
        ref = np.array([tp.speed_m_s + (speed_step_m_s if t >= 1.0 else 0.0),
                        tp.yaw_rate_rad_s + (yaw_rate_step_rad_s if t >= 0.5 * duration_s else 0.0)])
        y = Cr @ x[keep]
        dx = x[keep] - lin.x0
        u = tp.u - K @ np.concatenate([dx, integ])
        ts.append(t)
        refs.append(ref)
        ys.append(y)
        us.append(u)
        x = stepper.step(x, u, tp.p, dt)
        integ += dt * (Cr @ x[keep] - ref)
        t += dt
    ts, refs, ys, us = (np.array(a) for a in (ts, refs, ys, us))
    tail = ts >= ts[-1] - 0.5
    summary = {
        "schema_version": 1,
        "trim": {"speed_m_s": tp.speed_m_s, "radius_m": tp.radius_m, "torque_N_m": tp.u.tolist()},
        "closed_loop_max_real_eig_per_s": float(np.max(E.real)),
        "final_speed_error_m_s": float(np.mean(ys[tail, 0] - refs[tail, 0])),
        "final_yaw_rate_error_rad_s": float(np.mean(ys[tail, 1] - refs[tail, 1])),
        "max_torque_N_m": float(np.max(np.abs(us))),
        "duration_s": duration_s,
        "control_period_s": dt,
    }
    if out is not None:
        from symtrack.reports.plots import plt, png_bytes

        out = Path(out)
        fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        ax[0].plot(ts, ys[:, 0], label="u_m_s")
        ax[0].plot(ts, refs[:, 0], "k--", label="reference")
        ax[1].plot(ts, ys[:, 1], label="yaw_rate_rad_s")
        ax[1].plot(ts, refs[:, 1], "k--", label="reference")
        ax[2].plot(ts, us[:, 0], label="torque_cmd_left_N_m")
        ax[2].plot(ts, us[:, 1], label="torque_cmd_right_N_m")
        ax[0].set_ylabel("speed u [m/s]")
        ax[1].set_ylabel("yaw rate [rad/s]")
        ax[2].set_ylabel("torque command [N m]")
        ax[2].set_xlabel("t [s]")
        for a in ax:
            a.grid(True)
            a.legend()
        ax[0].set_title("LQR (linearized at R = 20 m, 2 m/s) on the nonlinear model")
        atomic_write_bytes(out / "lqr_response.png", png_bytes(fig))
        atomic_write_text(out / "lqr_summary.json", json.dumps(summary, indent=2) + "\n")
    return summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=8.0, help="simulated time [s]")
    ap.add_argument("--dt", type=float, default=0.01, help="control period [s]")
    ap.add_argument("--out", default="out/lqr", help="output folder")
    args = ap.parse_args(argv)
    s = run(args.duration, args.dt, args.out)
    print(json.dumps(s, indent=2))


if __name__ == "__main__":
    main()
