"""The terrain query: the ground's height, its surface normal and the cell under points of the field.

The query reads the cell storage (:class:`~symtrack.terrain.storage.Terrain`), vectorised over
points (any array shape; scalars too). For each point (x, y) it returns (:class:`SurfaceQuery`):

- ``cell``: the flat index i * ny + j of the cell that holds the point (cell (i, j) covers
  [x0 + i dx, x0 + (i + 1) dx) x [y0 + j dx, y0 + (j + 1) dx); a point on the field's upper
  edge belongs to the last cell);
- ``elevation_m``: the height z0 of the *undisturbed* ground surface (before any rut) of the cell:
  the field's elevation (``Terrain.elevation``, the ground's shape: symtrack/terrain/surface.py),
  0 on a flat field. Piecewise constant per cell, as the sinkage is;
- ``sinkage_m``: the cell's stored sinkage z (positive down: the rut depth), and its ``phase``;
- ``height_m``: the ground as a body meets it, **elevation minus sinkage** (what a vehicle that
  heaves on uneven, rutted ground rests on: the ruts of a pass are the ground of the next);
- ``gradient``: (dz0/dx, dz0/dy) of the undisturbed surface at the cell, shape (..., 2), by
  central differences of the neighbouring cells' elevations, (z0[i+1] - z0[i-1]) / (2 dx), one-sided
  at the field's edge (exact on a plane; on furrows of wavelength L the cells' difference gives
  sin(k dx) / (k dx) of the slope, k = 2 pi / L: a 3D vehicle that needs the exact gradient of an
  analytic surface takes it from :meth:`symtrack.terrain.surface.Surface.function`);
- ``normal``: the unit normal of the undisturbed surface, (-gx, -gy, 1) / sqrt(gx^2 + gy^2 + 1),
  shape (..., 3); flat: (0, 0, 1). (The rut's own slope is the sinkage field's business, not the
  elevation's.)

A point outside the field is an error naming the point and the field's extent
(``outside="nan"``: NaN heights, gradients and normals, cell -1, instead).

The same query in C for the engine: symtrack/native/terrain_query.h (``terrain_query``, same
rule for the cell and the same numbers, bit for bit), compiled into the terrain engine and exported
on its own storage (``eng_surface``: :meth:`symtrack.integrators.engine.TerrainEngine.surface`);
tests/test_terrain_query.py compares them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..foundations.errors import SimulationError
from .storage import Grid, Terrain

__all__ = ["OUTSIDE_MODES", "SurfaceQuery", "cell_gradient", "cell_of", "height_m", "normal", "query"]

OUTSIDE_MODES = ("raise", "nan")


@dataclass(frozen=True)
class SurfaceQuery:
    """The terrain under points (module doc); every array has the points' shape (``normal``: + (3,))."""

    cell: np.ndarray  # int64, -1 outside the field (outside="nan")
    elevation_m: np.ndarray
    sinkage_m: np.ndarray
    height_m: np.ndarray
    normal: np.ndarray
    phase: np.ndarray  # int8, -1 outside
    gradient: np.ndarray  # (..., 2): dz0/dx, dz0/dy of the undisturbed surface


def cell_of(grid: Grid, x_m, y_m, outside: str = "raise") -> np.ndarray:
    """The flat cell index i * ny + j under each point (module doc); -1 outside with ``outside="nan"``."""
    if outside not in OUTSIDE_MODES:
        raise ValueError(f"outside = {outside!r} is not one of {', '.join(OUTSIDE_MODES)}")
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float))
    x0, x1, y0, y1 = grid.bounds()
    nx, ny = grid.shape
    inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)  # False for NaN
    if outside == "raise" and not np.all(inside):
        k = np.unravel_index(int(np.argmin(inside)), inside.shape) if inside.ndim else ()
        n_out = int(np.size(inside) - np.count_nonzero(inside))
        raise SimulationError(f"terrain query at ({float(x[k]):g}, {float(y[k]):g}) m: outside the field, which "
                              f"spans x in [{x0:g}, {x1:g}] m and y in [{y0:g}, {y1:g}] m "
                              f"({n_out} of {np.size(inside)} points outside)")
    with np.errstate(invalid="ignore"):
        i = np.minimum(np.floor((np.where(inside, x, x0) - x0) / grid.cell_m).astype(np.int64), nx - 1)
        j = np.minimum(np.floor((np.where(inside, y, y0) - y0) / grid.cell_m).astype(np.int64), ny - 1)
    return np.where(inside, i * ny + j, -1)


def cell_gradient(grid: Grid, elevation: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dz0/dx, dz0/dy) of the elevation (flat, i * ny + j) at the cells (valid indices): central
    differences of the neighbours, one-sided at the field's edge, 0 along an axis of one cell
    (module doc; terrain_query.h computes the same expressions)."""
    nx, ny = grid.shape
    i, j = np.divmod(cell, ny)
    ip, im = np.minimum(i + 1, nx - 1), np.maximum(i - 1, 0)
    jp, jm = np.minimum(j + 1, ny - 1), np.maximum(j - 1, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        gx = np.where(ip > im, (elevation[ip * ny + j] - elevation[im * ny + j]) / ((ip - im) * grid.cell_m), 0.0)
        gy = np.where(jp > jm, (elevation[i * ny + jp] - elevation[i * ny + jm]) / ((jp - jm) * grid.cell_m), 0.0)
    return gx, gy


def query(terrain: Terrain, x_m, y_m, outside: str = "raise") -> SurfaceQuery:
    """The terrain under the points (x_m, y_m) (broadcast together): module doc."""
    cell = cell_of(terrain.grid, x_m, y_m, outside)
    inside = cell >= 0
    safe = np.where(inside, cell, 0)
    nan = np.where(inside, 0.0, np.nan)
    sinkage = terrain.z[safe] + nan
    n = np.zeros(cell.shape + (3,))
    g = np.zeros(cell.shape + (2,))
    if terrain.elevation is None:  # a flat field
        elevation = np.zeros(cell.shape) + nan
        n[..., 2] = 1.0
    else:
        elevation = terrain.elevation[safe] + nan
        gx, gy = cell_gradient(terrain.grid, terrain.elevation, safe)
        r = np.sqrt(gx * gx + gy * gy + 1.0)
        g[..., 0], g[..., 1] = gx, gy
        n[..., 0], n[..., 1], n[..., 2] = -gx / r, -gy / r, 1.0 / r
    n += nan[..., None]
    g += nan[..., None]
    phase = np.where(inside, terrain.phase[safe], -1).astype(np.int8)
    return SurfaceQuery(cell, elevation, sinkage, elevation - sinkage, n, phase, g)


def height_m(terrain: Terrain, x_m, y_m, outside: str = "raise") -> np.ndarray:
    """The ground's height under the points: elevation minus sinkage (module doc)."""
    return query(terrain, x_m, y_m, outside).height_m


def normal(terrain: Terrain, x_m, y_m, outside: str = "raise") -> np.ndarray:
    """The unit normal of the undisturbed surface under the points, shape (..., 3)."""
    return query(terrain, x_m, y_m, outside).normal
