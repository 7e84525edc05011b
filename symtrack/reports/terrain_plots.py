"""Terrain plots: the sinkage map (top view, like the seed's figure 7) and the rut cross-section."""

from __future__ import annotations

import numpy as np

from .plots import plt, png_bytes

__all__ = ["rut_section_png", "sinkage_map_png"]


def _window(world, maps, margin_cells=10):
    touched = np.zeros(world.grid.shape, dtype=bool)
    for z in maps:
        touched |= z > 0
    if not touched.any():
        return slice(0, world.grid.shape[0]), slice(0, world.grid.shape[1])
    ii, jj = np.nonzero(touched)
    return (slice(max(ii.min() - margin_cells, 0), ii.max() + margin_cells + 1),
            slice(max(jj.min() - margin_cells, 0), jj.max() + margin_cells + 1))


def sinkage_map_png(world, z, pass_no: int, maps=None) -> bytes:
    si, sj = _window(world, maps or [z])
    g = world.grid
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    fig, ax = plt.subplots(figsize=(10, 3.5))
    im = ax.imshow(1e3 * z[si, sj].T, origin="lower", extent=ext, aspect="equal", cmap="viridis")
    fig.colorbar(im, ax=ax, label="sinkage [mm]")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"terrain sinkage after pass {pass_no} (cell {dx:g} m)")
    return png_bytes(fig)


def rut_section_png(world, maps, results, line) -> bytes:
    """Sinkage across the driven line, at the middle of the path of the first pass."""
    g = world.grid
    X = results[0].X
    mid = len(X) // 2
    xm, ym, psi = X[mid, 0], X[mid, 1], X[mid, 2]
    # sample along the body's lateral axis at the mid point
    across = np.arange(-1.5, 1.5 + 1e-9, g.cell_m / 2)
    px, py = xm - np.sin(psi) * across, ym + np.cos(psi) * across
    i = np.clip(np.floor((px - g.origin_m[0]) / g.cell_m).astype(int), 0, g.shape[0] - 1)
    j = np.clip(np.floor((py - g.origin_m[1]) / g.cell_m).astype(int), 0, g.shape[1] - 1)
    fig, ax = plt.subplots(figsize=(8, 4))
    for k, z in enumerate(maps):
        ax.step(across, -1e3 * z[i, j], where="mid", label=f"after pass {k + 1}")
    ax.set_xlabel("lateral position from the vehicle's centre line [m] (left +)")
    ax.set_ylabel("surface [mm] (sinkage down)")
    ax.set_title(f"rut cross-section at x = {xm:.2f} m, y = {ym:.2f} m")
    ax.grid(True)
    ax.legend()
    return png_bytes(fig)
