"""Across and along furrows in 3D
==============================

Driving across and along furrows with the 3D vehicle (``model.vehicle = "3d"``;
docs/vehicle3d.md "Studies: furrows").

    python examples/furrows_3d.py                               # furrows 0.1 m deep
    python examples/furrows_3d.py --spacings 2.4 4.8 --plot /tmp/furrows_3d.png
    python examples/furrows_3d.py --convergence 8 16 32 64 --spacings 9.6 --torque 2000   # docs: "Limits"

Runs from rest on homogeneous soil (clayey soil 38 %, the creep law), both sprockets at ``--torque``
N m, heading +x, CVODES (``run.integrator = "cvodes"``: no C compile per ground), ``--segments``
contact segments a track:

- **across** the furrows (``furrow_heading_deg = 90``: they run along y, the ground undulates along
  x), one run per spacing: the hull pitches with the furrow wavelength. The reference is the rigid
  ground's geometry (the sinkage, 1-2 mm, is small against the furrows' 0.1 m): the track, a straight
  line of length l, rests on the profile's upper hull under it, on the hull's edge below the CG
  (:func:`rigid_pitch`): where the CG is over a crest the track rests on the crest and pitches with the
  ground's slope; over a trough it bridges from flank to flank. Its pitch is periodic in the distance
  with the furrow spacing (checked by the pitch's spectrum), and flat (bridging from crest to crest)
  when the contact spans whole periods, small spacings.
- **along** the furrows (``furrow_heading_deg = 0``: they run along x, spacing ``--along-spacing``,
  1 m = 2 B / 3): centred on a ridge (y = 0; the tracks at y = +-B/2 on the same height by symmetry,
  here mid-flank) the roll is 0 and the tracks share the load equally; a quarter spacing to the left
  (the left track runs on a ridge and the right one in a furrow) the hull rolls by atan(d / B) and the
  lower track carries cos t / 2 + h sin t / B of the weight (the rigid body on a tilted support, as on
  a side slope).

Prints a JSON summary; ``--plot`` writes a figure (matplotlib): across the furrows the pitch with the
rigid-ground reference, the heave and the track ends' penetration; along them the roll and pitch, the
load split and the sinkage, and the drift with the creep law's closed form, against the distance.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

import symtrack
from symtrack.api import IncompleteSimulation
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.vehicles.planar import GRAVITY_M_S2

SOIL = "clayey_soil_thailand_38"
SETTLE_M = 1.0  # the stretch compared starts after this distance (the set-off)


def furrow_scenario(spacing_m: float, depth_m: float, heading_deg: float, torque_N_m: float, duration_s: float,
                    segments: int, start_y_m: float = 0.0, dt_s: float = 0.02, soil: dict | None = None):
    """The 3D vehicle from rest at (0, ``start_y_m``) heading +x on furrows (a ridge at s = 0); ``soil``:
    soil parameters over the preset's."""
    return scenario_from_dict({
        "name": f"furrows_{spacing_m:g}m_{heading_deg:g}deg",
        "run": {"duration_s": float(duration_s), "output_dt_s": float(dt_s), "integrator": "cvodes"},
        "model": {"vehicle": "3d", "lateral_law": "creep", "contact_segments": int(segments)},
        "vehicle": {"preset": "reference_crawler"}, "soil": {"preset": SOIL, **(soil or {})},
        "start": {"x_m": 0.0, "y_m": float(start_y_m), "yaw_deg": 0.0},
        "terrain": {"surface": {"furrow_spacing_m": float(spacing_m), "furrow_depth_m": float(depth_m),
                                "furrow_heading_deg": float(heading_deg)}},
        "torque": [{"t_s": 0.0, "left_N_m": float(torque_N_m), "right_N_m": float(torque_N_m)}]})


COLUMNS = ("x_m", "y_m", "z_m", "pitch_rad", "roll_rad", "u_m_s", "normal_load_left_N", "normal_load_right_N",
           "sinkage_idler_left_m", "sinkage_sprocket_left_m", "sinkage_idler_right_m", "sinkage_sprocket_right_m")


def drive(sc) -> dict:
    """The run's columns; a run the package stops (the hull turned over: the contact has no hull, so
    what would follow is outside the model) is kept up to the stop, its message in ``stopped``."""
    try:
        res, stopped = symtrack.simulate(sc), None
    except IncompleteSimulation as err:
        res, stopped = err.result, str(err)
    run = res.runs[0]
    c = {n: np.asarray(run.column(n)) for n in COLUMNS}
    c["t_s"] = np.asarray(run.t)
    c["stopped"] = stopped
    c["distance_m"] = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(c["x_m"]), np.diff(c["y_m"])))])
    return c


def upper_hull(x, z):
    """The upper convex hull of the points (x sorted ascending): the indices of its vertices."""
    hull: list[int] = []
    for i in range(len(x)):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (x[b] - x[a]) * (z[i] - z[a]) - (z[b] - z[a]) * (x[i] - x[a]) >= 0:  # b below the chord a-i
                hull.pop()
            else:
                break
        hull.append(i)
    return hull


def rigid_pitch(x_cg, profile, contact_m: float, samples: int = 801) -> np.ndarray:
    """The pitch [rad] of a straight track of length ``contact_m`` resting on rigid ground z0 =
    ``profile(x)`` with the CG's vertical at ``x_cg`` (each value): the slope of the upper hull of the
    ground under the track, on the edge below the CG (a track centred under the CG, the reference
    crawler's e = 0)."""
    out = []
    for xc in np.atleast_1d(x_cg):
        xs = np.linspace(xc - contact_m / 2, xc + contact_m / 2, samples)
        zs = profile(xs)
        h = upper_hull(xs, zs)
        k = min(max(int(np.searchsorted(xs[h], xc)), 1), len(h) - 1)
        a, b = h[k - 1], h[k]
        out.append(math.atan((zs[b] - zs[a]) / (xs[b] - xs[a])))
    return np.array(out)


def dominant_wavelength_m(s, y) -> float:
    """The wavelength [m] of the largest peak of y's spectrum over the distance s (resampled evenly)."""
    grid = np.linspace(s[0], s[-1], 4096)
    v = np.interp(grid, s, y)
    v = (v - v.mean()) * np.hanning(len(v))
    f = np.fft.rfftfreq(len(v), grid[1] - grid[0])
    k = 1 + int(np.argmax(np.abs(np.fft.rfft(v))[1:]))
    return float(1.0 / f[k])


def across(spacing_m, depth_m, torque_N_m, duration_s, segments) -> dict:
    sc = furrow_scenario(spacing_m, depth_m, 90.0, torque_N_m, duration_s, segments)
    c = drive(sc)
    P = sc.params
    a, k = depth_m / 2, 2 * math.pi / spacing_m
    ref = rigid_pitch(c["x_m"], lambda x: a * np.cos(k * x), P["contact_length_m"])
    keep = c["distance_m"] >= SETTLE_M
    pitch = c["pitch_rad"][keep]
    return {"cols": c, "ref_pitch_rad": ref, "params": P, "summary": {
        "spacing_m": spacing_m, "spacing_over_contact_length": spacing_m / P["contact_length_m"],
        "distance_m": float(c["distance_m"][-1]), "speed_final_m_s": float(c["u_m_s"][-1]),
        "pitch_range_deg": [math.degrees(float(pitch.min())), math.degrees(float(pitch.max()))],
        "rigid_ground_pitch_range_deg": [math.degrees(float(ref[keep].min())), math.degrees(float(ref[keep].max()))],
        "ground_slope_max_deg": math.degrees(math.atan(a * k)),
        "pitch_rms_difference_deg": math.degrees(float(np.sqrt(np.mean((pitch - ref[keep]) ** 2)))),
        "pitch_wavelength_m": dominant_wavelength_m(c["distance_m"][keep], pitch),
        "roll_max_abs_deg": math.degrees(float(np.max(np.abs(c["roll_rad"])))),
        "sinkage_sprocket_max_mm": 1e3 * float(np.max(c["sinkage_sprocket_left_m"][keep])),
        "time_s": float(c["t_s"][-1]), "stopped": c["stopped"],
    }}


def along(spacing_m, depth_m, torque_N_m, duration_s, segments, start_y_m) -> dict:
    """Along the furrows, starting ``start_y_m`` to the left of the line of the ridge at y = 0: with
    ``spacing_m`` = B both tracks run in furrows (start near 0) or on ridges (near spacing / 2), at one
    height, so the roll stays 0 and the load is shared equally. Off the centre by delta, each track
    lies on a flank of slope a k sin(k delta) (a = d / 2, k = 2 pi / spacing), so the ground's normal
    pushes the hull sideways with N a k sin(k delta), toward the furrow's bottom; the creep law's
    lateral force mu N tanh(v / eps_v) carries it at the drift speed v = eps_v atanh(a k sin(k delta) /
    mu) (the side slope's closed form, docs/vehicle3d.md): linearised, delta(t) = delta_0 exp(-+ eps_v a
    k^2 t / mu), back into the furrow (stable) or off the ridge (unstable)."""
    sc = furrow_scenario(spacing_m, depth_m, 0.0, torque_N_m, duration_s, segments, start_y_m)
    P = sc.params
    if not math.isclose(spacing_m, P["track_gauge_m"], rel_tol=1e-9):
        raise ValueError(f"along the furrows the spacing must be the track gauge B = {P['track_gauge_m']:g} m "
                         f"(both tracks at one height), not {spacing_m:g} m: docs/vehicle3d.md says why")
    c = drive(sc)
    W, B, h = P["mass_kg"] * GRAVITY_M_S2, P["track_gauge_m"], P["cg_height_m"]
    a, k = depth_m / 2, 2 * math.pi / spacing_m
    z_left, z_right = (a * math.cos(k * (start_y_m + side * B / 2)) for side in (1, -1))
    roll_ref = math.atan((z_left - z_right) / B)  # left side up positive
    # the tracks at y +- B/2 = y +- spacing / 2: the nearest line where both lie in furrows or on ridges
    on_ridge = math.cos(k * (start_y_m + B / 2)) > 0
    centre = (round(start_y_m / spacing_m - 0.5) + 0.5) * spacing_m if on_ridge else \
        round(start_y_m / spacing_m) * spacing_m
    rate = P["lateral_creep_speed_m_s"] * a * k**2 / P["lateral_friction_coeff"]
    in_furrows = not on_ridge
    delta0 = start_y_m - centre
    y_ref = centre + delta0 * np.exp((-rate if in_furrows else rate) * c["t_s"])
    keep = c["distance_m"] >= SETTLE_M
    total = c["normal_load_left_N"] + c["normal_load_right_N"]
    lower = "right" if roll_ref >= 0 else "left"
    share = c[f"normal_load_{lower}_N"] / total
    t = abs(roll_ref)
    return {"cols": c, "params": P, "lower": lower, "share": share, "y_ref": y_ref, "summary": {
        "spacing_m": spacing_m, "start_y_m": start_y_m, "tracks": "in the furrows" if in_furrows else "on the ridges",
        "distance_m": float(c["distance_m"][-1]),
        "roll_mean_deg": math.degrees(float(np.mean(c["roll_rad"][keep]))),
        "roll_geometry_deg": math.degrees(roll_ref),
        "roll_max_abs_deg": math.degrees(float(np.max(np.abs(c["roll_rad"][keep])))),
        "pitch_max_abs_deg": math.degrees(float(np.max(np.abs(c["pitch_rad"][keep])))),
        "lower_share_mean": float(np.mean(share[keep])),
        "lower_share_rigid_body": math.cos(t) / 2 + h * math.sin(t) / B,
        "normal_load_sum_over_W": float(np.mean(total[keep]) / W),
        "offset_start_m": float(delta0), "offset_end_m": float(c["y_m"][-1] - centre),
        "offset_end_creep_closed_form_m": float(y_ref[-1] - centre),
        "cg_height_end_m": float(c["z_m"][-1]),
        "sinkage_sprocket_left_mm": 1e3 * float(np.mean(c["sinkage_sprocket_left_m"][keep])),
        "sinkage_sprocket_right_mm": 1e3 * float(np.mean(c["sinkage_sprocket_right_m"][keep])),
    }}


def convergence(spacing_m, depth_m, torque_N_m, duration_s, segments_list, soil=None) -> list:
    """Across the furrows at each of ``segments_list`` contact segments a track: the speed at the end,
    the tracks' total normal load over the weight and the largest heave rate after the set-off, the
    compaction resistance's mean and the CPU time of the time loop (docs/vehicle3d.md, "Limits")."""
    rows = []
    for n in segments_list:
        sc = furrow_scenario(spacing_m, depth_m, 90.0, torque_N_m, duration_s, n, soil=soil)
        run = symtrack.simulate(sc).runs[0]
        col = {k: np.asarray(run.column(k)) for k in ("x_m", "y_m", "u_m_s", "heave_rate_m_s", "normal_load_left_N",
                                                      "normal_load_right_N", "compaction_resistance_left_N",
                                                      "compaction_resistance_right_N")}
        dist = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(col["x_m"]), np.diff(col["y_m"])))])
        keep = dist >= SETTLE_M
        W = sc.params["mass_kg"] * GRAVITY_M_S2
        load = (col["normal_load_left_N"] + col["normal_load_right_N"])[keep] / W
        rows.append({"segments": n, "speed_final_m_s": float(col["u_m_s"][-1]),
                     "normal_load_over_W": [float(load.min()), float(load.max())],
                     "heave_rate_max_m_s": float(np.max(np.abs(col["heave_rate_m_s"][keep]))),
                     "compaction_resistance_mean_N": float(np.mean((col["compaction_resistance_left_N"]
                                                                    + col["compaction_resistance_right_N"])[keep])),
                     "cpu_time_s": float(run.cpu_time_s)})
    return rows


def plot(runs_across: list, runs_along: list, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 3, figsize=(18, 8))
    for r in runs_across:
        c, s = r["cols"], r["summary"]
        line, = ax[0, 0].plot(c["distance_m"], np.degrees(c["pitch_rad"]),
                              label=f"spacing {s['spacing_m']:g} m (l / {s['spacing_over_contact_length'] ** -1:.2g})")
        ax[0, 0].plot(c["distance_m"], np.degrees(r["ref_pitch_rad"]), ls=":", color=line.get_color())
        ax[0, 1].plot(c["distance_m"], c["z_m"], color=line.get_color(), label=f"spacing {s['spacing_m']:g} m")
        ax[0, 2].plot(c["distance_m"], 1e3 * c["sinkage_idler_left_m"], color=line.get_color(),
                      label=f"spacing {s['spacing_m']:g} m: idler (front)")
        ax[0, 2].plot(c["distance_m"], 1e3 * c["sinkage_sprocket_left_m"], color=line.get_color(), ls="--",
                      label="sprocket (rear)")
    ax[0, 0].set(xlabel="distance [m]", ylabel="pitch [deg] (nose up +)",
                 title="across the furrows: pitch (dotted: rigid ground's geometry)")
    ax[0, 1].set(xlabel="distance [m]", ylabel="CG height z [m]", title="across the furrows: heave")
    ax[0, 2].set(xlabel="distance [m]", ylabel="penetration [mm] (< 0: in the air)",
                 title="across the furrows: the left track's ends")
    sink = ax[1, 1].twinx()
    for r in runs_along:
        c, s = r["cols"], r["summary"]
        lab = s["tracks"]
        line, = ax[1, 0].plot(c["distance_m"], np.degrees(c["roll_rad"]), label=f"{lab}: roll")
        ax[1, 0].plot(c["distance_m"], np.degrees(c["pitch_rad"]), ls="--", color=line.get_color(),
                      label=f"{lab}: pitch")
        ax[1, 1].plot(c["distance_m"], 100 * r["share"], color=line.get_color(),
                      label=f"{lab}: {r['lower']} track's share")
        sink.plot(c["distance_m"], 1e3 * c["sinkage_sprocket_left_m"], color=line.get_color(), ls=":",
                  label=f"{lab}: left sprocket sinkage")
        centre = s["start_y_m"] - s["offset_start_m"]
        ax[1, 2].plot(c["distance_m"], 1e3 * (c["y_m"] - centre), color=line.get_color(), label=f"{lab}")
        ax[1, 2].plot(c["distance_m"], 1e3 * (r["y_ref"] - centre), ls=":", color=line.get_color(),
                      label=f"{lab}: the creep law's closed form")
    ax[1, 0].set(xlabel="distance [m]", ylabel="[deg]", title="along the furrows: roll and pitch")
    ax[1, 1].set(xlabel="distance [m]", ylabel="share of the load [%] (solid)",
                 title="along the furrows: load split and sinkage")
    sink.set_ylabel("sinkage [mm] (dotted)")
    sink.legend(fontsize=7, loc="lower right")
    ax[1, 2].set(xlabel="distance [m]", ylabel="offset from the line [mm]",
                 title="along the furrows: drift into the furrows, off the ridges")
    for a in ax.ravel():
        a.grid(True)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--depth-m", type=float, default=0.10, help="furrow depth, ridge to trough [m]")
    ap.add_argument("--spacings", type=float, nargs="+", default=[1.2, 2.4, 4.8, 9.6],
                    help="furrow spacings across the track [m]")
    ap.add_argument("--along-spacing", type=float, default=1.5,
                    help="furrow spacing along the track [m] (the gauge B: both tracks in furrows or on ridges)")
    ap.add_argument("--along-offset", type=float, default=0.5,
                    help="the second run along: start y / spacing (0.5: on the ridges)")
    ap.add_argument("--along-shift-m", type=float, default=0.05, help="both runs along start this far off centre [m]")
    ap.add_argument("--torque", type=float, default=1500.0, help="both sprockets [N m]")
    ap.add_argument("--duration", type=float, default=8.0, help="each run [s]")
    ap.add_argument("--segments", type=int, default=16, help="model.contact_segments")
    ap.add_argument("--plot", default=None, help="write the figure here (.png)")
    ap.add_argument("--convergence", type=int, nargs="+", default=None, metavar="SEGMENTS",
                    help="instead: across the furrows of the first --spacings at these contact segments a track "
                         "(docs/vehicle3d.md, \"Limits\")")
    ap.add_argument("--soil", nargs="+", default=[], metavar="KEY=VALUE",
                    help="soil parameters over the preset's (e.g. elastic_stiffness_Pa_per_m=4e6)")
    a = ap.parse_args(argv)
    soil = {k: float(v) for k, v in (kv.split("=", 1) for kv in a.soil)}
    if a.convergence:
        out = {"convergence": convergence(a.spacings[0], a.depth_m, a.torque, a.duration, a.convergence, soil)}
        print(json.dumps(out, indent=2))
        return out
    if soil:
        ap.error("--soil is taken with --convergence only")
    runs_across = [across(lam, a.depth_m, a.torque, a.duration, a.segments) for lam in a.spacings]
    runs_along = [along(a.along_spacing, a.depth_m, a.torque, a.duration, a.segments, y0)
                  for y0 in (a.along_shift_m, a.along_offset * a.along_spacing + a.along_shift_m)]
    out = {"across": [r["summary"] for r in runs_across], "along": [r["summary"] for r in runs_along]}
    print(json.dumps(out, indent=2))
    if a.plot:
        plot(runs_across, runs_along, a.plot)
    return out


if __name__ == "__main__":
    main()
