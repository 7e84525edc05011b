"""Lane keeping in the ruts of an earlier pass
===========================================

Lane keeping on compacted ground (controlled traffic): the MPC on the grid plant follows the rut
pair of an earlier pass.

    PYTHONPATH=. .venv/bin/python examples/lane_keeping_ruts.py --out out/lane_keeping [--baseline]

1. **First pass**: the MPC drives a straight on fresh soil (the grid plant: the terrain engine)
   and leaves a rut pair; the vehicle is lifted off (the terrain keeps the rebound).
2. **The lanes from the terrain**: per row of cells along the pass, the sinkage-weighted centre
   of each rut; a straight line fitted through the midpoints of the pair is the reference of
   the second pass (the ruts' gauge is reported beside the vehicle's track gauge).
3. **Second pass**: the vehicle starts ``offset_m`` to the side of the lanes, parallel to them;
   the MPC converges onto the reference and keeps the tracks in the old ruts.
4. **Figures**: the RMS lateral error after convergence (from ``settle_m`` of path on) and the
   share of the second pass's new sinkage volume (final sinkage after pass 2 minus after pass 1,
   where positive, times the cell area) that falls outside the first pass's rut cells (cells
   loaded in pass 1, z_max > 1 um), over the whole pass and over the cells the tracks loaded
   after convergence (the approach from the offset necessarily runs on fresh soil).

``baseline=True`` adds the counterfactual: the same second pass driven parallel to the ruts at
the offset (no controlled traffic), from the terrain after pass 1 (the plant's checkpoint).

The MPC's prediction model is the homogeneous-terrain model (fresh soil); the rut does not steer
the vehicle in the model (no lateral rut-wall forces): following it is the controller's job.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from symtrack.control import closedloop, scenario
from symtrack.control.mpc import MPCStats, PathTrackingMPC
from symtrack.model import SystemModel

SCHEMA_VERSION = 1
# cells loaded in pass 1: as closedloop.rut_figures (z_max above 1 um)
RUT_ZMAX_M = 1e-6
# converged: |lateral error| below this from then on
CONVERGED_M = 0.05


def scenario_dict(name, path_xy, heading_deg, length_m, start_xy, speed_m_s, field_origin, field_size, cell_m,
                  settle_m, horizon_steps):
    return {
        "name": name,
        "start": {"x_m": start_xy[0], "y_m": start_xy[1], "yaw_deg": heading_deg, "speed_m_s": speed_m_s},
        "path": {"x_m": path_xy[0], "y_m": path_xy[1], "heading_deg": heading_deg, "speed_m_s": speed_m_s,
                 "segments": [{"straight_m": length_m}]},
        "run": {"duration_s": 3.0 * length_m / speed_m_s, "rms_exclude_first_m": settle_m},
        "mpc": {"horizon_steps": horizon_steps},
        "terrain": {"cell_m": cell_m, "max_speed_m_s": 4.0, "origin_m": list(field_origin),
                    "size_m": list(field_size)},
    }


def rut_lanes(storage, rut: np.ndarray, z: np.ndarray, x_range):
    """The rut pair of a straight pass along x: per row of cells (x) inside ``x_range``, the
    sinkage-weighted centre of the rut cells left and right of the row's weighted centre; the
    line fitted through the midpoints. Returns (y0, slope, gauge_m, rows): the centre line
    y = y0 + slope x, the mean distance between the two ruts, the rows used."""
    g = storage.grid
    cx, cy = g.centres(np.arange(g.shape[0]), np.arange(g.shape[1]))
    Z = np.where(rut, z, 0.0).reshape(g.shape)
    xs, mids, gauges = [], [], []
    for i in np.nonzero((cx >= x_range[0]) & (cx <= x_range[1]))[0]:
        w = Z[i]
        if w.sum() <= 0:
            continue
        yc = float(np.sum(w * cy) / w.sum())
        lo, hi = w * (cy < yc), w * (cy >= yc)
        if lo.sum() <= 0 or hi.sum() <= 0:
            continue
        y_lo, y_hi = float(np.sum(lo * cy) / lo.sum()), float(np.sum(hi * cy) / hi.sum())
        xs.append(cx[i])
        mids.append(0.5 * (y_lo + y_hi))
        gauges.append(y_hi - y_lo)
    if len(xs) < 3:
        raise ValueError("no rut pair found in the first pass's terrain")
    slope, y0 = np.polyfit(xs, mids, 1)
    return float(y0), float(slope), float(np.mean(gauges)), len(xs)


def convergence_s(res, tol_m=CONVERGED_M) -> float:
    """The path length from which |lateral error| stays below tol_m (inf: never)."""
    bad = np.nonzero(np.abs(res.e_lat) >= tol_m)[0]
    if bad.size == 0:
        return float(res.s[0])
    if bad[-1] + 1 >= len(res.s):
        return math.inf
    return float(res.s[bad[-1] + 1])


def new_sinkage_figures(storage, rut1, z1, z2, x_after=None) -> dict:
    """The second pass's new sinkage (z2 - z1 where positive) and its share outside rut1; with
    ``x_after``, only over the cells with centres beyond x_after (along the pass)."""
    g = storage.grid
    new = np.maximum(z2 - z1, 0.0)
    keep = np.ones(new.size, bool)
    if x_after is not None:
        cx, _ = g.centres(np.arange(g.shape[0]), np.arange(g.shape[1]))
        keep = np.repeat(cx > x_after, g.shape[1])
    a = g.cell_m ** 2
    total = float(new[keep].sum() * a)
    outside = float(new[keep & ~rut1].sum() * a)
    first = float(np.where(rut1 & keep, z1, 0.0).sum() * a)
    return {"new_sinkage_volume_m3": total, "new_sinkage_outside_volume_m3": outside,
            "first_pass_rut_volume_m3": first, "new_to_first_pass_volume": total / first if first > 0 else None,
            "new_sinkage_outside_fraction": outside / total if total > 0 else 0.0,
            "new_sinkage_max_outside_mm": 1e3 * float(new[keep & ~rut1].max()) if (keep & ~rut1).any() else 0.0,
            "new_sinkage_max_inside_mm": 1e3 * float(new[keep & rut1].max()) if (keep & rut1).any() else 0.0}


def run(out=None, length_m=16.0, offset_m=0.4, settle_m=6.0, speed_m_s=2.0, cell_m=0.25, y_first_m=0.1,
        horizon_steps=20, baseline=False, quiet=True) -> dict:
    """The two passes (module doc); returns the summary (and writes the files to ``out``)."""
    margin = 3.0
    origin = (-margin, min(y_first_m, y_first_m + offset_m, y_first_m - offset_m) - margin)
    size = (length_m + 2 * margin, 2 * margin + 2 * abs(offset_m))
    common = dict(speed_m_s=speed_m_s, field_origin=origin, field_size=size, cell_m=cell_m, settle_m=settle_m,
                  horizon_steps=horizon_steps)
    sc1 = scenario.scenario_from_dict(scenario_dict("lane_first_pass", (0.0, y_first_m), 0.0, length_m,
                                                    (0.0, y_first_m), **common))
    model = SystemModel()
    mpc = PathTrackingMPC(model, sc1.params, sc1.mpc)
    plant = closedloop.make_plant(sc1, model)

    def drive(sc):
        mpc.reset()
        mpc.stats = MPCStats()
        return closedloop.run(sc, plant=plant, model=model, mpc=mpc, progress=not quiet)

    res1 = drive(sc1)
    st = plant.world.storage
    z1 = st.z.copy()
    rut1 = plant.world.touched & (st.zmax > RUT_ZMAX_M)
    # the lanes, from the rows the whole contact passed over (not the set-down and the stop)
    L = float(sc1.params["contact_length_m"])
    x_end = float(res1.X[-1, 0])
    y0, slope, gauge, rows = rut_lanes(st, rut1, z1, (L, x_end - L))
    heading = math.degrees(math.atan(slope))
    # the second pass: the same straight back at its start, along the detected lane centre line,
    # starting offset_m to the left of it (perpendicular), parallel to it
    c, s = math.cos(math.radians(heading)), math.sin(math.radians(heading))
    p0 = (0.0, y0)
    start = (p0[0] - s * offset_m, p0[1] + c * offset_m)
    sc2 = scenario.scenario_from_dict(scenario_dict("lane_second_pass", p0, heading, length_m, start, **common))
    saved = plant.checkpoint() if baseline else None
    res2 = drive(sc2)
    z2 = st.z.copy()
    conv = convergence_s(res2)
    # the cells the tracks loaded after convergence: the contact's rear end past the convergence point
    x_conv = p0[0] + c * conv + 0.5 * L + cell_m
    summ = {
        "schema_version": SCHEMA_VERSION,
        "first_pass": {k: res1.summary[k] for k in ("rut_cells", "rut_max_depth_mm", "rut_mean_depth_mm",
                                                    "rut_volume_m3", "failed_solves", "path_completed")},
        "lanes": {"centre_y0_m": y0, "centre_slope": slope, "heading_deg": heading, "gauge_m": gauge,
                  "vehicle_track_gauge_m": float(sc1.params["track_gauge_m"]), "rows": rows,
                  "first_pass_reference_y_m": y_first_m},
        "second_pass": {
            "start_offset_m": offset_m,
            "rms_lateral_error_m": res2.summary["rms_lateral_error_m"],
            "rms_note": f"lateral error to the lane centre line, from s = {settle_m:g} m of path on",
            "max_lateral_error_after_settle_m": res2.summary["max_lateral_error_straights_m"],
            "converged_from_s_m": conv,
            "converged_note": f"|lateral error| < {CONVERGED_M * 100:g} cm from here on",
            "failed_solves": res2.summary["failed_solves"],
            "path_completed": res2.summary["path_completed"],
            "plant": res2.summary["plant"],
            "plant_wall_time_s": res2.summary["plant_wall_time_s"],
            "whole_pass": new_sinkage_figures(st, rut1, z1, z2),
            "after_convergence": {"x_after_m": x_conv, **new_sinkage_figures(st, rut1, z1, z2, x_conv)},
        },
    }
    if baseline:
        plant.restore(saved)  # the terrain after pass 1 again
        sc3 = scenario.scenario_from_dict(scenario_dict("lane_offset_pass", start, heading, length_m, start,
                                                        **common))
        res3 = drive(sc3)
        z3 = st.z.copy()
        summ["baseline_offset_pass"] = {
            "note": f"the same pass parallel to the ruts, {offset_m:g} m to the side (no controlled traffic)",
            "rms_lateral_error_m": res3.summary["rms_lateral_error_m"],
            "whole_pass": new_sinkage_figures(st, rut1, z1, z3),
            "after_convergence": {"x_after_m": x_conv, **new_sinkage_figures(st, rut1, z1, z3, x_conv)},
        }
        st.z[:] = z2  # leave the plant's terrain as the controlled-traffic pass made it (for the map)
    if out is not None:
        out = Path(out)
        closedloop.write(out / "first_pass", res1)
        closedloop.write(out / "second_pass", res2)
        _plot(out / "lanes.png", st, rut1, z1, z2, res1, res2)
        (out / "lane_keeping_summary.json").write_text(json.dumps(summ, indent=2) + "\n")
    return summ


def _plot(path, storage, rut1, z1, z2, res1, res2):
    from symtrack.reports.plots import plt, png_bytes

    g = storage.grid
    ext = [g.origin_m[0], g.origin_m[0] + g.shape[0] * g.cell_m, g.origin_m[1], g.origin_m[1] + g.shape[1] * g.cell_m]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    im = a1.imshow(1e3 * z1.reshape(g.shape).T, origin="lower", extent=ext, aspect="auto", cmap="viridis")
    fig.colorbar(im, ax=a1, label="sinkage after pass 1 [mm]")
    a1.plot(res1.X[:, 0], res1.X[:, 1], "w--", lw=1, label="pass 1 (CG)")
    a1.plot(res2.X[:, 0], res2.X[:, 1], "r-", lw=1, label="pass 2 (CG)")
    a1.legend(fontsize=8, loc="upper right")
    new = np.maximum(z2 - z1, 0.0)
    im = a2.imshow(1e3 * new.reshape(g.shape).T, origin="lower", extent=ext, aspect="auto", cmap="magma")
    fig.colorbar(im, ax=a2, label="new sinkage of pass 2 [mm]")
    a2.contour(*np.meshgrid(*g.centres(np.arange(g.shape[0]), np.arange(g.shape[1])), indexing="ij"),
               rut1.reshape(g.shape).astype(float), levels=[0.5], colors="c", linewidths=0.8)
    a2.set_xlabel("x [m]")
    for a in (a1, a2):
        a.set_ylabel("y [m]")
    a1.set_title("controlled traffic: pass 2 from an offset onto the ruts of pass 1 (cyan: pass 1's rut cells)")
    path.write_bytes(png_bytes(fig))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/lane_keeping")
    ap.add_argument("--length", type=float, default=16.0, help="pass length [m]")
    ap.add_argument("--offset", type=float, default=0.4, help="start offset of the second pass [m]")
    ap.add_argument("--settle", type=float, default=6.0, help="path length left out of the RMS [m]")
    ap.add_argument("--baseline", action="store_true", help="also the offset pass without controlled traffic")
    args = ap.parse_args(argv)
    print(json.dumps(run(args.out, args.length, args.offset, args.settle, baseline=args.baseline, quiet=False),
                     indent=2))


if __name__ == "__main__":
    main()
