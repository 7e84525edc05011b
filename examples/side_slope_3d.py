"""A side slope and furrows in 3D
==============================

The 3D vehicle (``model.vehicle = "3d"``, docs/vehicle3d.md) driving along a side slope and across
furrows on homogeneous soil: the path over the elevation, roll and pitch against distance, the load
split between the tracks.

    python examples/side_slope_3d.py                               # 10 deg side slope, furrows 0.1 m / 1.5 m
    python examples/side_slope_3d.py --slope-deg 12 --plot /tmp/side_slope_3d.png

Two runs from rest, both sprockets at ``--torque`` N m (a 0.1 s actuator lag), CVODES:

- along a side slope (the ground rises toward +y, the vehicle heads +x): it drifts downhill, its
  lower (right) track carries W cos t / 2 + W h sin t / B and sinks deeper, the hull rolls by t;
- across furrows (they run along y, so the ground undulates along x): the hull pitches and heaves as
  its rigid tracks bridge the ridges.

Prints a JSON summary of each run; ``--plot`` writes a figure (matplotlib).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from symtrack.integrators.settings import IntegratorSettings
from symtrack.integrators.sundials import SundialsStepper
from symtrack.model import SystemModel
from symtrack.model.options import ModelOptions
from symtrack.model.static import static_state
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.terrain.surface import parse_surface
from symtrack.vehicles.planar import GRAVITY_M_S2
from symtrack.vehicles.vehicle3d import make_vehicle


def drive(surface: dict, torque_N_m: float, duration_s: float, law: str = "creep", dt_s: float = 0.02,
          soil: str = "clayey_soil_thailand_38") -> dict:
    """One run of the 3D vehicle from rest on ``surface`` (a ``[terrain.surface]`` table); the time
    series of the pose, the attitude and the tracks' loads."""
    params = {**vehicle_preset("reference_crawler"), **soil_preset(soil)}
    opts = ModelOptions(lateral_law=law, vehicle="3d")
    surf = parse_surface(surface)
    model = SystemModel(opts, vehicle=make_vehicle(opts, surf))
    x = static_state(model, params)
    p = model.param_vector(params)
    stepper = SundialsStepper(model, IntegratorSettings("cvodes", 1e-6, 1e-9))
    u = np.array([torque_N_m, torque_N_m])
    names = ("x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "normal_load_left_N", "normal_load_right_N",
             "sinkage_sprocket_left_m", "sinkage_sprocket_right_m", "ground_z_m")
    rows = []
    for k in range(int(round(duration_s / dt_s)) + 1):
        if k:
            x = stepper.step(x, u, p, dt_s)
        y = dict(zip(model.output_names, np.array(model.outputs(x, u, p)).ravel(), strict=True))
        y["x_m"], y["y_m"] = x[model.layout.index("x_m")], x[model.layout.index("y_m")]
        rows.append([y[n] for n in names])
    out = {n: np.array(col) for n, col in zip(names, zip(*rows, strict=True), strict=True)}
    out["t_s"] = np.arange(len(rows)) * dt_s
    out["distance_m"] = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(out["x_m"]), np.diff(out["y_m"])))])
    out["surface"], out["params"] = surf, params
    return out


def summary(run: dict) -> dict:
    P = run["params"]
    W = P["mass_kg"] * GRAVITY_M_S2
    return {
        "distance_m": float(run["distance_m"][-1]),
        "drift_y_m": float(run["y_m"][-1] - run["y_m"][0]),
        "roll_deg_final": math.degrees(run["roll_rad"][-1]),
        "pitch_deg_range": [math.degrees(float(run["pitch_rad"].min())), math.degrees(float(run["pitch_rad"].max()))],
        "load_share_right_final": float(run["normal_load_right_N"][-1] / W),
        "sinkage_sprocket_left_mm": 1e3 * float(run["sinkage_sprocket_left_m"][-1]),
        "sinkage_sprocket_right_mm": 1e3 * float(run["sinkage_sprocket_right_m"][-1]),
    }


def plot(runs: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(runs), 3, figsize=(14, 4 * len(runs)), squeeze=False)
    for row, (title, run) in enumerate(runs.items()):
        x0, x1 = run["x_m"].min() - 2, run["x_m"].max() + 2
        y0, y1 = run["y_m"].min() - 3, run["y_m"].max() + 3
        gx, gy = np.meshgrid(np.linspace(x0, x1, 200), np.linspace(y0, y1, 120))
        z = run["surface"].elevation(gx, gy)
        a = ax[row, 0]
        cs = a.contourf(gx, gy, z, 30, cmap="terrain")
        fig.colorbar(cs, ax=a, label="elevation z0 [m]")
        a.plot(run["x_m"], run["y_m"], "k-", lw=2, label="CG path")
        a.set(xlabel="x [m]", ylabel="y [m]", title=f"{title}: path over the elevation")
        a.legend()
        a = ax[row, 1]
        a.plot(run["distance_m"], np.degrees(run["roll_rad"]), label="roll (left up)")
        a.plot(run["distance_m"], np.degrees(run["pitch_rad"]), label="pitch (nose up)")
        a.set(xlabel="distance [m]", ylabel="[deg]", title="attitude")
        a.legend()
        a = ax[row, 2]
        W = run["params"]["mass_kg"] * GRAVITY_M_S2
        a.plot(run["distance_m"], run["normal_load_left_N"] / W, label="left (upper) track")
        a.plot(run["distance_m"], run["normal_load_right_N"] / W, label="right (lower) track")
        a.set(xlabel="distance [m]", ylabel="normal load / W", title="load split")
        a.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--slope-deg", type=float, default=10.0)
    ap.add_argument("--furrow-depth-m", type=float, default=0.10)
    ap.add_argument("--furrow-spacing-m", type=float, default=1.5)
    ap.add_argument("--torque", type=float, default=1500.0, help="both sprockets [N m]")
    ap.add_argument("--duration", type=float, default=8.0, help="each run [s]")
    ap.add_argument("--plot", default=None, help="write the figure here (.png)")
    a = ap.parse_args(argv)
    runs = {
        f"side slope {a.slope_deg:g} deg": drive({"slope_y_deg": a.slope_deg}, a.torque, a.duration),
        f"furrows {a.furrow_depth_m:g} m / {a.furrow_spacing_m:g} m across": drive(
            {"furrow_depth_m": a.furrow_depth_m, "furrow_spacing_m": a.furrow_spacing_m, "furrow_heading_deg": 90.0},
            a.torque, a.duration),
    }
    out = {k: summary(v) for k, v in runs.items()}
    print(json.dumps(out, indent=2))
    if a.plot:
        plot(runs, a.plot)
    return out


if __name__ == "__main__":
    main()
