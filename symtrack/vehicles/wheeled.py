"""A wheeled machine's pass over a field: the tyres' footprints (symtrack/vehicles/tyre.py) moved along
a path, the largest vertical stress each cell's soil carries at the terrain's subsoil depths, folded
into the terrain's record and, with the soil's own weight, into its compression state as a crawler's
pass is (docs/subsoil.md, "Wheeled machines" and "One soil"; no rut, so no rut bound). Python/numpy
over the terrain's arrays; the terrain engine is not involved, and the surface (sinkage, ruts) is
not changed.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..foundations.errors import ParameterError
from ..soil import density
from ..terrain.storage import Terrain
from .tyre import Contact, footprint_stress_at_depth

__all__ = ["Wheel", "terrain_soils", "wheeled_pass"]

# cells farther than this from every wheel centre get no stress from it (the stress at 0.1-0.8 m
# depth 1.5 m beside a 0.3-0.7 m contact is below 1 % of the peak for xi >= 3)
DEFAULT_REACH_M = 1.5


@dataclasses.dataclass(frozen=True)
class Wheel:
    """One wheel of a machine: its contact (tyre.contact) and its centre in the machine's frame
    (x forward, y left) [m]."""

    contact: Contact
    x_m: float
    y_m: float


def terrain_soils(terrain: Terrain) -> list[dict]:
    """The terrain's soils as density.py takes them: soil 0 the terrain's own, then its soil map's."""
    if terrain.soil is None:
        raise ParameterError("the terrain has no soil parameters (a terrain made without a soil)")
    return [dict(terrain.soil)] + [{**terrain.soil, **sp} for _, sp in terrain.soil_table]


def wheeled_pass(terrain: Terrain, wheels, poses, xi: float, reach_m: float = DEFAULT_REACH_M,
                 soils=None, tables=None, cell_params=None) -> dict:
    """Drive the machine of ``wheels`` through ``poses`` (n, 3): world (X, Y, psi) of its frame,
    spaced at most a quarter of the cell size apart along the path for the maxima to be sampled.
    Updates ``terrain.sigma_max`` (Pa) and ``terrain.specific_volume`` in place; returns the pass's
    figures: ``subsoil_sigma_z_max_kPa`` and ``bulk_density_max_Mg_per_m3`` per depth, the cells
    loaded. ``soils``: the field's soil parameter sets by soil index (a World's ``soils``: the day's
    moisture applied); default :func:`terrain_soils`. Each wheel at each pose looks only at the cells
    of the index window around it (the same cells within ``reach_m`` as over the whole field).
    ``tables``: one :class:`~symtrack.vehicles.tyre.FootprintTable` per wheel (of its contact, the
    terrain's depths and ``xi``): the stress at a cell is then the sum of every wheel's table value
    there (bilinear; 0 beyond a table), tens of microseconds per wheel and pose instead of tens of
    milliseconds for the direct sum over the contact's elements. ``cell_params``: each cell's own
    compression parameters (:func:`symtrack.soil.density.pass_update`; a World's ``cell_day``)."""
    depths = terrain.subsoil_depths_m
    if not depths:
        raise ParameterError("the terrain has no subsoil depths (terrain.subsoil_depths_m is empty)")
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    if poses.ndim != 2 or poses.shape[1] != 3 or not np.all(np.isfinite(poses)):
        raise ParameterError(f"poses has shape {poses.shape}; expected (n, 3) finite (X, Y, psi)")
    if len(poses) > 1:
        step = float(np.max(np.hypot(*np.diff(poses[:, :2], axis=0).T)))
        if step > terrain.grid.cell_m / 4 + 1e-12:
            raise ParameterError(f"poses are {step:.4g} m apart, more than a quarter of the cell size "
                                 f"({terrain.grid.cell_m / 4:.4g} m): sample the path more finely")
    if not wheels:
        raise ParameterError("wheels is empty: a machine needs at least one wheel")
    g = terrain.grid
    nx, ny = g.shape
    (x0, y0), dx = g.origin_m, g.cell_m

    def window(wx, wy):
        """(flat indices, centre x, centre y) of the cells within reach_m of (wx, wy)."""
        i0 = max(0, int(math.floor((wx - reach_m - x0) / dx)) - 1)
        i1 = min(nx, int(math.ceil((wx + reach_m - x0) / dx)) + 1)
        j0 = max(0, int(math.floor((wy - reach_m - y0) / dx)) - 1)
        j1 = min(ny, int(math.ceil((wy + reach_m - y0) / dx)) + 1)
        if i0 >= i1 or j0 >= j1:
            return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
        ii, jj = np.arange(i0, i1), np.arange(j0, j1)
        xc, yc = g.centres(ii, jj)
        XC, YC = np.meshgrid(xc, yc, indexing="ij")
        K = (ii[:, None] * ny + jj[None, :]).ravel()
        XC, YC = XC.ravel(), YC.ravel()
        inside = np.hypot(XC - wx, YC - wy) <= reach_m
        return K[inside], XC[inside], YC[inside]

    n_d = len(depths)
    sig = np.zeros((g.n_cells, n_d))  # the pass's largest vertical stress (the density's and the risk's)
    if tables is not None:
        if len(tables) != len(wheels):
            raise ParameterError(f"tables has {len(tables)} entries for {len(wheels)} wheels")
        for tb in tables:
            if tuple(tb.depths_m) != tuple(float(d) for d in depths) or tb.xi != float(xi):
                raise ParameterError(f"a footprint table is of depths {list(tb.depths_m)} and xi = {tb.xi}; the pass "
                                     f"needs the terrain's {list(depths)} and xi = {float(xi)}")
    for X, Y, psi in poses:
        c, s = math.cos(psi), math.sin(psi)
        if tables is not None:
            centres = [(X + c * w.x_m - s * w.y_m, Y + s * w.x_m + c * w.y_m) for w in wheels]
            found = [window(wx, wy) for wx, wy in centres]
            near = np.concatenate([f[0] for f in found])
            near, first = np.unique(near, return_index=True)
            if near.size == 0:
                continue
            nxc, nyc = np.concatenate([f[1] for f in found])[first], np.concatenate([f[2] for f in found])[first]
            sz = np.zeros((near.size, n_d))
            for (wx, wy), tb in zip(centres, tables, strict=True):
                dxw, dyw = nxc - wx, nyc - wy
                sz += tb.sigma_z(c * dxw + s * dyw, -s * dxw + c * dyw)
            sig[near] = np.maximum(sig[near], sz)
            continue
        for w in wheels:
            wx, wy = X + c * w.x_m - s * w.y_m, Y + s * w.x_m + c * w.y_m
            near, nxc, nyc = window(wx, wy)
            if near.size == 0:
                continue
            ex = wx + c * w.contact.x_m - s * w.contact.y_m
            ey = wy + s * w.contact.x_m + c * w.contact.y_m
            # the superposition of all wheels at this pose at the cells near this wheel
            fx = [ex]
            fy = [ey]
            ff = [w.contact.force_kN]
            for o in wheels:
                if o is w:
                    continue
                ox, oy = X + c * o.x_m - s * o.y_m, Y + s * o.x_m + c * o.y_m
                if math.hypot(ox - wx, oy - wy) <= 2 * reach_m:
                    fx.append(ox + c * o.contact.x_m - s * o.contact.y_m)
                    fy.append(oy + s * o.contact.x_m + c * o.contact.y_m)
                    ff.append(o.contact.force_kN)
            sz, _ = footprint_stress_at_depth(np.concatenate(fx), np.concatenate(fy), np.concatenate(ff),
                                              nxc, nyc, depths, xi)
            np.maximum.at(sig, near, sz)
    loaded = np.flatnonzero(sig.max(axis=1) > 0)
    np.maximum(terrain.sigma_max, (1e3 * sig).astype(np.float32), out=terrain.sigma_max)
    soils = terrain_soils(terrain) if soils is None else soils
    density.pass_update(terrain.specific_volume, (1e3 * sig).astype(np.float32), terrain.soil_index, soils,
                        cells=loaded, cell_params=cell_params,
                        geostatic_Pa=density.geostatic_table(soils, depths), depths_m=depths)
    return {"subsoil_depths_m": list(depths),
            "subsoil_sigma_z_max_kPa": [float(v) for v in sig.max(axis=0)],
            "bulk_density_max_Mg_per_m3": density.field_max(terrain.specific_volume, terrain.soil_index, soils,
                                                            depths),
            "cells_loaded": int(loaded.size)}
