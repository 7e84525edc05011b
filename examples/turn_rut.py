"""The rut of a steady turn
========================

The rut of a steady turn against the rut of a straight pass at the same speed, on the grid terrain
(the terrain engine, ``run.integrator = "grid_fast"``; docs/turning.md section 5).

    python examples/turn_rut.py                                   # sandy loam, R = 10 m, 2 m/s, shear law
    python examples/turn_rut.py --soil clayey_soil_thailand_38 --radius 20 --plot /tmp/rut.png

Both runs start at their trim (symtrack.control.trim on the homogeneous model: the vehicle states of
the steady motion, placed on the grid) and keep the trim's torques: a steady turn of radius R (left)
through ``--turn-deg`` degrees, and straight running over the same arc length. The cells are then
read under each track: those whose centre lies within b/2 of the track's centre line (the turn's
circle is fitted to the CG's path, the tracks at R -/+ B/2 from its centre), away from the first and
last 3 m of the run (the vehicle set down and lifted off). Per track: the mean and the largest
permanent sinkage (the rut, after the cells have unloaded), the mean of the largest sinkage under
load (z_max), and the mean number of load cycles (passes) the cells saw.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from symtrack.control.trim import trim
from symtrack.model import ModelOptions, SystemModel
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.simulation import loop
from symtrack.simulation.plants import make_plant
from symtrack.simulation.scenario import scenario_from_dict

EDGE_M = 3.0  # the first and last metres of a run left out of the figures (set-down, lift-off)
BAND_EXTRA_M = 0.3  # the band read around a track: b/2 and this on each side (a turning track sweeps wider)


def _scenario(soil, law, torques, duration_s, size_m, origin_m, cell_m):
    return scenario_from_dict({
        "name": "turn_rut", "run": {"duration_s": duration_s, "integrator": "grid_fast"},
        "model": {"lateral_law": law}, "vehicle": {"preset": "reference_crawler"}, "soil": {"preset": soil},
        "terrain": {"size_m": list(size_m), "cell_m": cell_m, "origin_m": list(origin_m)},
        "torque": [{"t_s": 0.0, "left_N_m": float(torques[0]), "right_N_m": float(torques[1])}]})


def _drive(soil, law, speed_m_s, radius_m, arc_m, cell_m):
    """One run from the trim at (speed, radius) (radius None: straight) over arc_m; returns the world,
    the CG path and the trim."""
    params = {**vehicle_preset("reference_crawler"), **soil_preset(soil)}
    model = SystemModel(ModelOptions(lateral_law=law))
    tp = trim(model, params, speed_m_s, radius_m)
    margin = 6.0
    if radius_m is None:
        size, origin = (arc_m + 2 * margin, 2 * margin), (-margin, -margin)
        x0, y0 = 0.0, 0.0
    else:
        R = abs(radius_m)
        # the turn's centre at (0, 0), the start at (0, -R) heading +x (a left turn)
        size, origin = (2 * (R + margin),) * 2, (-(R + margin),) * 2
        x0, y0 = 0.0, -R
    duration = arc_m / speed_m_s
    sc = _scenario(soil, law, tp.u, duration, size, origin, cell_m)
    plant = make_plant(sc)
    xv = tp.x[model.layout.block("vehicle")].copy()
    names = model.layout.vehicle_names
    xv[names.index("x_m")], xv[names.index("y_m")], xv[names.index("yaw_rad")] = x0, y0, 0.0
    res = loop.run(sc, plant, start=loop.StartPoint(x0, y0, 0.0, np.array(tp.u), xv))
    X = res.X[:, list(res.state_names).index("x_m")]
    Y = res.X[:, list(res.state_names).index("y_m")]
    return plant.world, np.column_stack([X, Y]), tp, params


def _fit_circle(xy):
    """Least-squares circle through the points (Kasa's fit): centre, radius."""
    A = np.column_stack([2 * xy[:, 0], 2 * xy[:, 1], np.ones(len(xy))])
    b = (xy**2).sum(axis=1)
    cx, cy, c = np.linalg.lstsq(A, b, rcond=None)[0]
    return np.array([cx, cy]), math.sqrt(c + cx**2 + cy**2)


def _track_sections(world, params, path, radius_m):
    """{track: (cell mask of its band, section index of each cell, section length [m])}: the band
    within b/2 + BAND_EXTRA_M of the track's centre line (wide enough for the swept width of a track in a
    turn), cut into sections one cell long along the centre line (the turn's circle fitted to the CG's
    path, the tracks at R -/+ B/2 from its centre; module doc), away from the run's first and last
    EDGE_M."""
    g = world.grid
    ii, jj = np.meshgrid(np.arange(g.shape[0]), np.arange(g.shape[1]), indexing="ij")
    cx, cy = (np.asarray(c).reshape(g.shape) for c in g.centres(ii.ravel(), jj.ravel()))
    B, b = params["track_gauge_m"], params["track_width_m"]
    half = b / 2 + BAND_EXTRA_M
    out = {}
    if radius_m is None:
        y_path = float(np.mean(path[:, 1]))
        x_lo, x_hi = path[0, 0] + EDGE_M, path[-1, 0] - EDGE_M
        along = (cx > x_lo) & (cx < x_hi)
        sec = np.floor((cx - x_lo) / g.cell_m).astype(int)
        for k, off in (("left", B / 2), ("right", -B / 2)):
            out[k] = (along & (np.abs(cy - (y_path + off)) < half), sec, g.cell_m)
        return out, None
    centre, R = _fit_circle(path[len(path) // 10:])
    rr = np.hypot(cx - centre[0], cy - centre[1])
    ang = np.unwrap(np.arctan2(path[:, 1] - centre[1], path[:, 0] - centre[0]))
    a = np.arctan2(cy - centre[1], cx - centre[0])
    a_lo, a_hi = ang[0] + EDGE_M / R, ang[-1] - EDGE_M / R
    a = np.where(a < a_lo - 1e-9, a + 2 * np.pi, a)  # the angles along the turn, from its start
    along = (a > a_lo) & (a < a_hi)
    for k, r_k in (("left", R - B / 2), ("right", R + B / 2)):
        sec = np.floor((a - a_lo) * r_k / g.cell_m).astype(int)
        out[k] = (along & (np.abs(rr - r_k) < half), sec, g.cell_m)
    return out, R


def _rut(world, sections):
    """Per track: the rut's depth (the deepest permanent sinkage of each section, averaged over the
    sections), its cross-section area (the permanent sinkage integrated across the band: volume per
    metre along the track), its width (area / depth), the same depth for z_max (the deepest sinkage
    under load) and the mean number of load cycles (passes) of the cells the rut covers."""
    st, g = world.storage, world.grid
    z, zmax = st.z.reshape(g.shape), st.zmax.reshape(g.shape)
    cyc = st.cycles.reshape(g.shape)
    out = {}
    for k, (mask, sec, length) in sections.items():
        s = sec[mask]
        ids = np.unique(s)
        depth = np.array([z[mask][s == i].max() for i in ids])
        depth_max = np.array([zmax[mask][s == i].max() for i in ids])
        area = np.array([z[mask][s == i].sum() for i in ids]) * g.cell_m**2 / length
        rutted = mask & (z > 0.1 * depth.mean())
        out[k] = {"sections": int(ids.size), "depth_mm": 1e3 * float(depth.mean()),
                  "depth_sd_mm": 1e3 * float(depth.std()), "area_mm_m": 1e3 * float(area.mean()),
                  "width_m": float(area.mean() / depth.mean()), "z_max_depth_mm": 1e3 * float(depth_max.mean()),
                  "load_cycles_mean": float(cyc[rutted].mean())}
    return out


def _profile(z, grid, mask, offset_fn):
    """The rut's mean cross-section: permanent sinkage against the offset from the track's centre
    line (positive: away from the turn's centre / to the left), in bins of half a cell."""
    ii, jj = np.nonzero(mask)
    cx, cy = grid.centres(ii, jj)
    off = offset_fn(np.asarray(cx), np.asarray(cy))
    edges = np.arange(-0.5, 0.5001, grid.cell_m / 2)
    idx = np.digitize(off, edges)
    mid, val = [], []
    for k in range(1, len(edges)):
        sel = idx == k
        if sel.any():
            mid.append(0.5 * (edges[k - 1] + edges[k]))
            val.append(1e3 * float(z[ii[sel], jj[sel]].mean()))
    return np.array(mid), np.array(val)


def _plot(path, turn_maps, path_t, masks_t, centre, straight_maps, masks_s, path_s, params, out):
    from symtrack.reports.plots import plt, png_bytes

    z, g = turn_maps
    B = params["track_gauge_m"]
    R = out["radius_fitted_m"]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5.5))
    ext = (g.origin_m[0], g.origin_m[0] + g.shape[0] * g.cell_m, g.origin_m[1], g.origin_m[1] + g.shape[1] * g.cell_m)
    im = ax.imshow(1e3 * z.T, origin="lower", extent=ext, cmap="viridis")
    ax.plot(path_t[:, 0], path_t[:, 1], "w-", lw=0.8, label="CG path")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"steady turn R = {out['radius_m']:g} m, {out['speed_m_s']:g} m/s, {out['soil']}", fontsize=10)
    fig.colorbar(im, ax=ax, label="permanent sinkage [mm]")
    ax.legend(loc="upper right", fontsize=8)
    for k, r_k, lab in (("left", R - B / 2, "inner (turn)"), ("right", R + B / 2, "outer (turn)")):
        mid, val = _profile(z, g, masks_t[k][0], lambda x, y, r_k=r_k: np.hypot(x - centre[0], y - centre[1]) - r_k)
        ax2.plot(mid, val, "o-", ms=3, label=lab)
    zs, gs = straight_maps
    y_path = float(np.mean(path_s[:, 1]))
    mid, val = _profile(zs, gs, masks_s["left"][0], lambda x, y: y - (y_path + B / 2))
    ax2.plot(mid, val, "k--", label="straight pass")
    ax2.set_xlabel("offset from the track's centre line [m] (turn: outwards positive)")
    ax2.set_ylabel("permanent sinkage, mean along the rut [mm]")
    ax2.set_title(f"rut cross-section, law {out['law']}, cells {g.cell_m:g} m", fontsize=10)
    ax2.grid(alpha=0.4)
    ax2.legend(fontsize=8)
    with open(path, "wb") as f:
        f.write(png_bytes(fig))


def compare(soil="sandy_loam_15", law="shear", speed_m_s=2.0, radius_m=10.0, turn_deg=180.0, cell_m=0.1,
            plot=None) -> dict:
    """The rut under the inner and the outer track of a steady left turn and under the tracks of a
    straight pass over the same arc length at the same speed; relative differences."""
    arc = abs(radius_m) * math.radians(turn_deg)
    w_t, path_t, tp_t, params = _drive(soil, law, speed_m_s, radius_m, arc, cell_m)
    masks_t, R_fit = _track_sections(w_t, params, path_t, radius_m)
    turn = _rut(w_t, masks_t)
    turn_maps = (w_t.storage.z.reshape(w_t.grid.shape).copy(), w_t.grid)
    centre_t = _fit_circle(path_t[len(path_t) // 10:])[0]
    del w_t
    w_s, path_s, tp_s, _ = _drive(soil, law, speed_m_s, None, arc, cell_m)
    masks_s, _ = _track_sections(w_s, params, path_s, None)
    straight = _rut(w_s, masks_s)
    w_s_z, w_s_grid = w_s.storage.z.reshape(w_s.grid.shape).copy(), w_s.grid
    figs = ("depth_mm", "area_mm_m", "z_max_depth_mm")
    s_mean = {f: 0.5 * (straight["left"][f] + straight["right"][f]) for f in figs}
    n_soil = params.get("bekker_n")
    N_in, N_out = (float(tp_t.outputs[f"normal_load_{k}_N"]) for k in ("left", "right"))
    N_s = float(tp_s.outputs["normal_load_left_N"])
    out = {"soil": soil, "law": law, "speed_m_s": speed_m_s, "radius_m": radius_m, "radius_fitted_m": R_fit,
           "turn_deg": turn_deg, "cell_m": cell_m,
           "torques_turn_N_m": [float(v) for v in tp_t.u], "torques_straight_N_m": [float(v) for v in tp_s.u],
           "normal_load_inner_outer_N": [N_in, N_out], "normal_load_straight_N": N_s,
           "turn": {"inner": turn["left"], "outer": turn["right"]}, "straight": straight}
    for side, k in (("inner", "left"), ("outer", "right")):
        for f in figs:
            out[f"{side}_vs_straight_{f}"] = turn[k][f] / s_mean[f] - 1
    if n_soil is not None:
        # Bekker z ~ p^(1/n): the depth the load transfer alone would give
        out["bekker_load_transfer_inner_outer"] = [(N_in / N_s) ** (1 / n_soil) - 1, (N_out / N_s) ** (1 / n_soil) - 1]
    if plot:
        _plot(plot, turn_maps, path_t, masks_t, centre_t, (w_s_z, w_s_grid), masks_s, path_s, params, out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soil", default="sandy_loam_15")
    ap.add_argument("--law", default="shear")
    ap.add_argument("--speed", type=float, default=2.0)
    ap.add_argument("--radius", type=float, default=10.0)
    ap.add_argument("--turn-deg", type=float, default=180.0)
    ap.add_argument("--cell", type=float, default=0.1)
    ap.add_argument("--plot", default=None, help="PNG of the turn's rut")
    a = ap.parse_args(argv)
    print(json.dumps(compare(a.soil, a.law, a.speed, a.radius, a.turn_deg, a.cell, a.plot), indent=1))


if __name__ == "__main__":
    main()

