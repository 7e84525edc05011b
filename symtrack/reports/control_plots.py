"""Plots of a closed loop (the MPC tracking a path; :mod:`symtrack.control.closedloop`), PNG bytes."""

from __future__ import annotations

import numpy as np

from .plots import plt, png_bytes
from .terrain_plots import sinkage_map_png

__all__ = ["closed_loop_pngs", "closed_loop_terrain_pngs"]


def closed_loop_pngs(res) -> dict[str, bytes]:
    """The closed loop's plots (``path.png``, ``errors.png``, ``torques.png``, ``solve_times.png``)
    of a :class:`~symtrack.control.closedloop.ClosedLoopResult`."""
    out = {}
    p = res.path
    ix, iy = res.state_names.index("x_m"), res.state_names.index("y_m")
    fig, (ax, ae) = plt.subplots(2, 1, figsize=(8, 9), gridspec_kw={"height_ratios": [3, 1]})
    on = p.segment >= 0
    ax.plot(p.x[on], p.y[on], "k--", lw=1, label="reference path")
    ax.plot(res.X[:, ix], res.X[:, iy], "C0", lw=1.5, label="vehicle (CG)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend()
    ax.set_title(f"{res.scenario.name}: path (true scale; the error below, magnified)")
    # the centimetre errors the true-scale path hides: lateral error along the path, with the band
    # of the largest error on the straights
    ae.plot(res.s, 100 * res.e_lat, "C0")
    band = 100 * float(np.max(np.abs(res.e_lat[res.straight]))) if res.straight.any() else 0.0
    ae.axhspan(-band, band, color="C0", alpha=0.12, label=f"max on straights: {band:.1f} cm")
    ae.axhline(0.0, color="k", lw=0.8)
    ae.set_xlabel("path length s [m]")
    ae.set_ylabel("lateral error [cm]")
    ae.grid(True)
    ae.legend(fontsize=8)
    out["path.png"] = png_bytes(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    a1.plot(res.s, 100 * res.e_lat)
    a1.set_ylabel("lateral error [cm]")
    a1.grid(True)
    a2.plot(res.s, np.degrees(res.e_psi))
    a2.set_ylabel("heading error [deg]")
    a2.set_xlabel("path length s [m]")
    a2.grid(True)
    for a in (a1, a2):
        lo, hi = a.get_ylim()
        a.fill_between(res.s, lo, hi, where=~res.straight, color="0.9", step="mid", label="turn")
        a.set_ylim(lo, hi)
    a1.set_title("tracking errors (grey: turns)")
    out["errors.png"] = png_bytes(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    for k, name in enumerate(("left", "right")):
        ax.step(res.t, res.U[:, k], where="post", label=f"{name} command")
        ax.plot(res.t, res.X[:, res.state_names.index(f"torque_{name}_N_m")], "--", label=f"{name} actual")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("torque [N m]")
    ax.grid(True)
    ax.legend()
    out["torques.png"] = png_bytes(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(res.t[:len(res.solve_ms)], res.solve_ms, ".", ms=3)
    bad = ~res.solve_ok
    ax.plot(res.t[:len(res.solve_ms)][bad], res.solve_ms[bad], "rx", label="failed")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("solve time [ms]")
    ax.set_title(f"solver {res.scenario.mpc.solver}{' (jit)' if res.scenario.mpc.uses_jit else ''}")
    ax.grid(True)
    out["solve_times.png"] = png_bytes(fig)
    return out


def closed_loop_terrain_pngs(res) -> dict[str, bytes]:
    """The final terrain of a closed loop on a grid plant: ``sinkage_map.png`` (top view); {} on
    the homogeneous plant."""
    plant = res.plant
    if getattr(plant, "kind", None) != "grid":
        return {}
    return {"sinkage_map.png": sinkage_map_png(plant.world, plant.world.storage.copy_z(), 1)}
