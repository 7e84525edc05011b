"""The oscillation study: torque steps and sign()
==============================================

The oscillation study of the Politecnico di Milano thesis "Model of a Tracked Vehicle for
Agricultural Applications" (docs/model.md, "References"): torque step vs filtered torque, and sign()
vs tanh.

The thesis (section 2) reports two kinds of oscillation of the shear displacement:

- numerical, from the sign() functions, reduced by approximating sign() with tanh;
- model-related, from the coupling torque -> tractive effort -> shear -> motion, excited by a
  torque step and reduced by a first-order torque filter (realistic: no actuator is instantaneous).

This runs the validation manoeuvre (both sprockets 2000 N m, left idle at t = 4 s) four times:
sign() with a torque step, the thesis's tanh with a torque step, the smooth form with a torque
step, and the smooth form with the 0.1 s torque filter of the reference crawler. Like the
thesis's Simulink runs, it integrates with a fixed step (classic Runge-Kutta 4, 0.5 ms, CasADi's
``rk`` integrator on the model's own ODE), because the error-controlled CVODES gives up on the
discontinuous sign() (``CV_TOO_MUCH_WORK`` within 2 ms: the Coulomb-like switch of the internal
resistance at omega = 0 is exactly the source of the numerical oscillations). It writes
``oscillation_study.png`` (shear displacements of each variant) and ``oscillation_study.json``
(an oscillation measure per variant), and prints a table.

Usage: python examples/oscillation_study.py [--out DIR] [--duration S]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import casadi as ca
import numpy as np

from symtrack.foundations.files import atomic_write_bytes, atomic_write_text
from symtrack.model import SystemModel
from symtrack.model.static import static_state
from symtrack.simulation.scenario import load_scenario

# A torque "step": an actuator time constant 100 x shorter than the reference crawler's.
STEP_TIME_CONSTANT_S = 0.001

VARIANTS = (
    ("sign(), torque step", "sign", STEP_TIME_CONSTANT_S),
    ("sign(), filtered torque", "sign", None),
    ("tanh (thesis), torque step", "tanh", STEP_TIME_CONSTANT_S),
    ("smooth, torque step", "smooth", STEP_TIME_CONSTANT_S),
    ("smooth, filtered torque", "smooth", None),
)


def oscillation_mm(t, j, window_s=0.25):
    """RMS of the shear displacement about its centred moving average [mm]: the oscillation."""
    dt = t[1] - t[0]
    n = max(int(round(window_s / dt)), 1) | 1
    kernel = np.ones(n) / n
    pad = np.pad(j, n // 2, mode="edge")
    smooth = np.convolve(pad, kernel, mode="valid")
    return 1e3 * float(np.sqrt(np.mean((j - smooth) ** 2)))


def fixed_step_run(scenario, duration_s, output_dt_s, substeps):
    """Fixed-step RK4 run of a scenario's model (the torque schedule of the scenario)."""
    model = SystemModel(scenario.model)
    p = model.param_vector(scenario.params)
    dae = {"x": model.x, "u": model.u, "p": model.p, "ode": model.ode_expr}
    F = ca.integrator("rk4", "rk", dae, 0.0, output_dt_s, {"number_of_finite_elements": substeps,
                                                          "simplify": True})
    x = static_state(model, scenario.params)
    n = int(round(duration_s / output_dt_s))
    t = np.arange(n + 1) * output_dt_s
    X = np.empty((n + 1, model.nx))
    X[0] = x
    t0 = time.perf_counter()
    for i in range(n):
        u = scenario.torque_at(t[i])
        x = np.array(F(x0=x, p=p, u=u)["xf"]).ravel()
        if not np.all(np.isfinite(x)):
            raise RuntimeError(f"{scenario.model.traction_sign}: non-finite state at t = {t[i + 1]:.4f} s")
        X[i + 1] = x
    return t, X, model.state_names, time.perf_counter() - t0


def chatter_rad_s(t, omega, until_s=0.012):
    """Numerical chattering of a sprocket speed at start-up: its total variation over the first
    ``until_s`` seconds minus its net change (zero for a monotonic start) [rad/s]. 12 ms is how
    long the filtered torque (0.1 s) stays below r R_in (about 230 N m of 2000 N m)."""
    w = omega[t <= until_s]
    return float(np.abs(np.diff(w)).sum() - abs(w[-1] - w[0]))


def cvodes_status(scenario, duration_s=0.05):
    """Does the error-controlled CVODES get through the start of the manoeuvre?"""
    from symtrack import simulate
    from symtrack.foundations.errors import SimulationError

    sc = dataclasses.replace(scenario, run=dataclasses.replace(
        scenario.run, integrator="cvodes", duration_s=duration_s, stop_after_distance_m=None,
        stop_distance_event=None))
    try:
        simulate(sc)
    except SimulationError as err:
        return "fails: " + ("CV_TOO_MUCH_WORK" if "TOO_MUCH_WORK" in str(err) else str(err).splitlines()[0])
    return "ok"


def study(duration_s: float = 6.0, output_dt_s: float = 0.002, substeps: int = 4, check_cvodes: bool = True):
    results = []
    for label, mode, tau in VARIANTS:
        sets = [f'model.traction_sign="{mode}"']
        if tau is not None:
            sets.append(f"vehicle.torque_time_constant_s={tau}")
        sc = load_scenario("validation", sets)
        t, X, names, wall = fixed_step_run(sc, duration_s, output_dt_s, substeps)
        jl, jr = X[:, names.index("shear_left_m")], X[:, names.index("shear_right_m")]
        results.append({
            "variant": label,
            "sign_function": mode,
            "torque_time_constant_s": sc.vehicle["torque_time_constant_s"],
            "fixed_step_s": output_dt_s / substeps,
            "t": t, "shear_left_m": jl, "shear_right_m": jr,
            "oscillation_left_mm": oscillation_mm(t, jl),
            "oscillation_right_mm": oscillation_mm(t, jr),
            "omega_left_rad_s": X[:, names.index("omega_left_rad_s")],
            "startup_chatter_rad_s": chatter_rad_s(t, X[:, names.index("omega_left_rad_s")]),
            "cvodes_first_0.05_s": cvodes_status(sc) if check_cvodes else "not checked",
            "wall_time_s": wall,
        })
    return results


def plot(results) -> bytes:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results) + 1, 1, figsize=(9, 2.4 * (len(results) + 1)))
    for ax, r in zip(axes, results, strict=False):
        ax.plot(r["t"], 1e3 * r["shear_right_m"], label="right (driven)")
        ax.plot(r["t"], 1e3 * r["shear_left_m"], label="left (idle after 4 s)")
        ax.set_title(f"{r['variant']}: oscillation {r['oscillation_right_mm']:.3f} / "
                     f"{r['oscillation_left_mm']:.3f} mm rms")
        ax.set_ylabel("shear [mm]")
        ax.grid(True)
        ax.set_xlabel("t [s]")
    axes[0].legend(loc="lower right")
    ax = axes[-1]
    for r in results:
        if r["torque_time_constant_s"] != STEP_TIME_CONSTANT_S:
            sel = r["t"] <= 0.05
            ax.plot(1e3 * r["t"][sel], r["omega_left_rad_s"][sel], ".-", ms=3,
                    label=f"{r['variant']} (chatter {r['startup_chatter_rad_s']:.4f} rad/s)")
    ax.set_title("left sprocket speed at start-up: sign() chatters while the torque is below r R_in")
    ax.set_xlabel("t [ms]")
    ax.set_ylabel("omega [rad/s]")
    ax.grid(True)
    ax.legend()
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/oscillation_study")
    ap.add_argument("--duration", type=float, default=6.0)
    ap.add_argument("--no-cvodes-check", action="store_true", help="skip the CVODES start-up check")
    args = ap.parse_args(argv)
    results = study(args.duration, check_cvodes=not args.no_cvodes_check)
    out = Path(args.out)
    atomic_write_bytes(out / "oscillation_study.png", plot(results))
    table = [{k: v for k, v in r.items() if not isinstance(v, np.ndarray)} for r in results]
    atomic_write_text(out / "oscillation_study.json", json.dumps({"schema_version": 1, "variants": table}, indent=2))
    print(f"{'variant':26s} {'shear osc. R/L [mm rms]':>24s} {'start chatter [rad/s]':>22s}  CVODES")
    for r in table:
        print(f"{r['variant']:26s} {r['oscillation_right_mm']:11.3f} /{r['oscillation_left_mm']:11.3f} "
              f"{r['startup_chatter_rad_s']:22.5f}  {r['cvodes_first_0.05_s']}")


if __name__ == "__main__":
    main()
