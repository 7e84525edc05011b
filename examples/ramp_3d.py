"""A climb and a descent of a ramp in 3D
=====================================

A climb and a descent of a headland ramp with the 3D vehicle (``model.vehicle = "3d"``;
docs/vehicle3d.md "Studies: a ramp").

    python examples/ramp_3d.py                                  # 10 deg, 8 s each
    python examples/ramp_3d.py --slope-deg 15 --plot /tmp/ramp_3d.png

``[terrain.surface]`` offers a uniform slope (``slope_x_deg``), no ramp that starts partway, so both
runs start from rest on the slope (the hull settled on it by ``static_state``), heading +x,
homogeneous soil (clayey soil 38 %, the creep law), the compiled Rosenbrock (the scenario's default):

- **climb**: the ground rises toward +x; both sprockets at ``--climb-factor`` times the holding torque
  r W sin t / 2 (the weight's component along the slope, carried by the two sprockets);
- **descent**: the ground falls toward +x; the sprockets brake at ``--brake-factor`` times the holding
  torque (a negative torque), so the vehicle rolls down slowly, held back by the tracks.

The checks against the geometry and statics (printed, and held by tests/test_vehicle3d_studies.py):
the CG's rise over a stretch equals the distance along the slope times sin t (the horizontal distance
times tan t); the hull's pitch equals the ramp's (nose up on the climb, nose down on the descent) to
within the difference of the ends' sinkages over the contact; the tracks carry W cos t between them
(the weight's component normal to the ground, plus m times the small normal acceleration).

Prints a JSON summary of both runs; ``--plot`` writes a figure (matplotlib): the CG's height against
the distance along the slope with the line s sin t, the pitch, and the pressures under the idler (front)
and the sprocket (rear).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

import symtrack
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.vehicles.planar import GRAVITY_M_S2
from symtrack.vehicles.vehicle3d import running_gear_momentum_ratio

SOIL = "clayey_soil_thailand_38"
SETTLE_S = 1.0  # the stretch for the checks starts after the set-off (the shear building up)
TAIL_S = 2.0  # the loads, pressures and pitch: means over the run's last seconds


def ramp_scenario(slope_deg: float, torque_N_m: float, duration_s: float, dt_s: float = 0.05):
    """The 3D vehicle from rest on a uniform slope of ``slope_deg`` (rising toward +x; negative: falling),
    heading +x, both sprockets at ``torque_N_m`` from t = 0."""
    return scenario_from_dict({
        "name": f"ramp_{slope_deg:g}deg", "run": {"duration_s": float(duration_s), "output_dt_s": float(dt_s)},
        "model": {"vehicle": "3d", "lateral_law": "creep"}, "vehicle": {"preset": "reference_crawler"},
        "soil": {"preset": SOIL}, "terrain": {"surface": {"slope_x_deg": float(slope_deg)}},
        "torque": [{"t_s": 0.0, "left_N_m": float(torque_N_m), "right_N_m": float(torque_N_m)}]})


def holding_torque_N_m(params: dict, slope_deg: float) -> float:
    """r W sin t / 2: each sprocket's share of the weight's component along the slope."""
    W = params["mass_kg"] * GRAVITY_M_S2
    return params["sprocket_radius_m"] * W * math.sin(math.radians(abs(slope_deg))) / 2


def drive(slope_deg: float, torque_N_m: float, duration_s: float) -> dict:
    """One run; its columns and the checks' figures."""
    sc = ramp_scenario(slope_deg, torque_N_m, duration_s)
    run = symtrack.simulate(sc).runs[0]
    cols = {n: np.asarray(run.column(n)) for n in (
        "x_m", "y_m", "z_m", "pitch_rad", "roll_rad", "u_m_s", "normal_load_left_N", "normal_load_right_N",
        "p_idler_left_Pa", "p_sprocket_left_Pa", "sinkage_idler_left_m", "sinkage_sprocket_left_m")}
    cols["t_s"] = np.asarray(run.t)
    t = math.radians(slope_deg)
    dx = cols["x_m"] - cols["x_m"][0]
    cols["along_m"] = dx / math.cos(t)  # the distance along the slope (the path is straight)
    return {"scenario": sc, "cols": cols, "slope_rad": t, "params": sc.params}


def summary(r: dict) -> dict:
    """The checks' figures: the CG's rise over the run after the set-off against s sin t, the pitch and
    the loads as means over the last :data:`TAIL_S` with the idler pressure's range there (a braked
    descent chattered before the running gear's angular momentum was in the hull's pitch:
    docs/vehicle3d.md, "Studies: a ramp")."""
    c, t, P = r["cols"], r["slope_rad"], r["params"]
    W = P["mass_kg"] * GRAVITY_M_S2
    k = int(np.searchsorted(c["t_s"], SETTLE_S))
    tail = c["t_s"] >= c["t_s"][-1] - TAIL_S
    ds = c["along_m"][-1] - c["along_m"][k]
    dz = c["z_m"][-1] - c["z_m"][k]
    l = P["contact_length_m"]

    def mean(name):
        return float(np.mean(c[name][tail]))
    # the pitch of the tracks' line: the ramp's, less the ends' sinkage difference over the contact
    end_tilt = (mean("sinkage_sprocket_left_m") - mean("sinkage_idler_left_m")) / l
    return {
        "slope_deg": math.degrees(t),
        "distance_along_slope_m": float(c["along_m"][-1]),
        "speed_final_m_s": float(c["u_m_s"][-1]),
        "cg_rise_m": float(dz),
        "cg_rise_geometry_m": float(ds * math.sin(t)),
        "cg_rise_error_rel": float(dz / (ds * math.sin(t)) - 1) if abs(ds) > 1e-6 else float("nan"),
        "pitch_mean_deg": math.degrees(mean("pitch_rad")),
        "pitch_expected_deg": math.degrees(t + end_tilt),
        "roll_max_abs_deg": math.degrees(float(np.max(np.abs(c["roll_rad"])))),
        "normal_load_sum_over_W_cos_t": (mean("normal_load_left_N") + mean("normal_load_right_N")) / (W * math.cos(t)),
        "p_idler_kPa": 1e-3 * mean("p_idler_left_Pa"),
        "p_sprocket_kPa": 1e-3 * mean("p_sprocket_left_Pa"),
        "p_idler_range_kPa": [1e-3 * float(c["p_idler_left_Pa"][tail].min()),
                              1e-3 * float(c["p_idler_left_Pa"][tail].max())],
        "sinkage_idler_mm": 1e3 * mean("sinkage_idler_left_m"),
        "sinkage_sprocket_mm": 1e3 * mean("sinkage_sprocket_left_m"),
        **pressure_centre(r, tail),
    }


def pressure_centre(r: dict, tail) -> dict:
    """The load's centre behind the contact centre two ways, as means over ``tail``: from the rigid
    track's Bekker pressures k z^n at its segment centres, z linear between the measured end sinkages
    (the model's contact on virgin soil: right where every segment sinks deeper than those ahead, the
    climb), and from the statics of the hull on the ground line,
    x_p = [h (W sin t + m a) + 2 kappa J a / r] / (W cos t) + e (the weight's component along the slope and
    the inertial force at the CG's height h, the thrust and the resistances on the ground line; a the
    acceleration along the slope; 2 kappa J a / r the reaction of the two tracks' running gear spinning up,
    nose up: :func:`~symtrack.vehicles.vehicle3d.running_gear_momentum_ratio`)."""
    c, t, P = r["cols"], r["slope_rad"], r["params"]
    W, m = P["mass_kg"] * GRAVITY_M_S2, P["mass_kg"]
    l, h, e, n = P["contact_length_m"], P["cg_height_m"], P["cg_ahead_of_contact_centre_m"], P["bekker_n"]
    spin = 2 * running_gear_momentum_ratio(l, P["sprocket_radius_m"]) * P["sprocket_inertia_kg_m2"] \
        / P["sprocket_radius_m"]
    n_seg = 8  # the model's default contact_segments (ramp_scenario does not change it)
    s = (np.arange(n_seg) + 0.5) * l / n_seg  # from the front
    zi, zs = float(np.mean(c["sinkage_idler_left_m"][tail])), float(np.mean(c["sinkage_sprocket_left_m"][tail]))
    p = np.maximum(zi + (zs - zi) * s / l, 0.0) ** n
    a = float(np.mean(np.gradient(c["u_m_s"], c["t_s"])[tail])) / math.cos(t)
    return {"pressure_centre_behind_m": float(np.sum((s - l / 2) * p) / np.sum(p)),
            "pressure_centre_statics_m": (h * (W * math.sin(t) + m * a) + spin * a) / (W * math.cos(t)) + e,
            "accel_along_slope_m_s2": a}


def plot(runs: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.5))
    for name, r in runs.items():
        c, t = r["cols"], r["slope_rad"]
        s = c["along_m"]
        line, = ax[0].plot(s, c["z_m"] - c["z_m"][0], label=f"{name}: CG height")
        ax[0].plot(s, s * math.sin(t), ls=":", color=line.get_color(), label=f"{name}: s sin t")
        ax[1].plot(s, np.degrees(c["pitch_rad"]), color=line.get_color(), label=f"{name}: pitch")
        ax[1].axhline(math.degrees(t), ls=":", color=line.get_color())
        ax[2].plot(s, 1e-3 * c["p_idler_left_Pa"], color=line.get_color(), label=f"{name}: idler (front)")
        ax[2].plot(s, 1e-3 * c["p_sprocket_left_Pa"], color=line.get_color(), ls="--",
                   label=f"{name}: sprocket (rear)")
    ax[0].set(xlabel="distance along the slope s [m]", ylabel="CG height change [m]",
              title="the CG's rise against the geometry")
    ax[1].set(xlabel="distance along the slope s [m]", ylabel="pitch [deg] (nose up +)",
              title="the hull's pitch (dotted: the ramp's)")
    ax[2].set(xlabel="distance along the slope s [m]", ylabel="pressure [kPa]",
              title="the left track's end pressures")
    for a in ax:
        a.grid(True)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--slope-deg", type=float, default=10.0, help="the ramp, (0, 20] deg")
    ap.add_argument("--climb-factor", type=float, default=1.4, help="climb torque / holding torque")
    ap.add_argument("--brake-factor", type=float, default=0.75, help="descent's braking torque / holding torque")
    ap.add_argument("--duration", type=float, default=8.0, help="each run [s]")
    ap.add_argument("--plot", default=None, help="write the figure here (.png)")
    a = ap.parse_args(argv)
    params = ramp_scenario(a.slope_deg, 0.0, 1.0).params
    hold = holding_torque_N_m(params, a.slope_deg)
    runs = {"climb": drive(a.slope_deg, a.climb_factor * hold, a.duration),
            "descent": drive(-a.slope_deg, -a.brake_factor * hold, a.duration)}
    out = {"holding_torque_N_m": hold, **{k: summary(v) for k, v in runs.items()}}
    print(json.dumps(out, indent=2))
    if a.plot:
        plot(runs, a.plot)
    return out


if __name__ == "__main__":
    main()
