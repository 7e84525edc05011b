"""The ground's shape: the ``[terrain.surface]`` table and :class:`Surface`, the field's initial
elevation z0(x, y) numerically (numpy, for the grid's cells) and symbolically (CasADi, for the
homogeneous terrain and a 3D vehicle's contact: z0 and its gradient at a point).

Schema (docs/terrain.md, "The ground's shape"; every key optional, unknown keys are errors)::

    [terrain.surface]
    slope_x_deg = 5.0           # the ground rises toward +x: dz0/dx = tan(slope_x)
    slope_y_deg = 0.0           # the ground rises toward +y: dz0/dy = tan(slope_y)
    furrow_spacing_m = 0.75     # furrows: a sinusoid of this wavelength across them, (0, 20] m,
    furrow_depth_m = 0.10       # this depth from ridge to trough, [0, GROUND_CLEARANCE_M] m,
    furrow_heading_deg = 0.0    # running in this direction (0: along x, 90: along y), [-360, 360]
    elevation_file = "dem.npy"  # a raster of heights in metres, added to the above
    elevation_cell_m = 0.5      # .npy only: its pixel, (0, 1000] m (required with a .npy)
    elevation_origin_m = [x, y] # .npy only: world (x, y) of its lower-left corner (default: the field's)

The elevation, in metres, is

    z0(x, y) = tan(slope_x) x + tan(slope_y) y                 (the planes pass through 0 at world (0, 0))
             + (d / 2) cos(2 pi s / lambda),  s = -x sin(h) + y cos(h)   (furrows; a ridge at s = 0)
             + the raster's bilinear interpolation at (x, y)

with d the furrow depth, lambda the spacing and h the heading: s is the distance across the
furrows, so furrows with h = 0 run along x and the ground undulates along y.

The raster: a ``.npy`` 2-D float array ``a[i, j]``, i along x, j along y (the field's own
indexing: symtrack.terrain.storage), the height at the centre of pixel (i, j), which lies at
origin + ((i + 1/2) elevation_cell_m, (j + 1/2) elevation_cell_m); or a GeoTIFF (the extra
``symtrack[gis]``; one band of real or integer heights, north up, in a projected CRS in metres:
symtrack.terrain.gis), whose transform gives its origin and pixels (elevation_cell_m and
elevation_origin_m are then errors) and whose CRS the terrain keeps (it must match a soil map's).
Between pixel centres heights are bilinear; within half a pixel of the raster's edge they are the
edge's (no extrapolation). The raster must cover the whole field and hold no NaN (nor, for a
GeoTIFF, a nodata pixel) there; at least 2 x 2 pixels.

Limits (checked before anything is built, each naming the key, the value and the range):

- the steepest slope of the ground's plane, atan(|grad z0|) of the slopes and the raster (not the
  furrows': below), at most :data:`MAX_SLOPE_DEG` = 20 deg. Why: the terrain's cells are vertical
  columns (docs/model.md: the sinkage measured vertically, the pressure the vertical load over
  the horizontal cell area), while Bekker's law is a plate's pressed normal to the ground; on ground
  inclined by t they differ by cos t (the sinkage) and cos^2 t (the pressure: the load's normal
  component, cos t, over an area 1 / cos t larger): 6 % and 12 % at 20 deg, 13 % and 25 % at 30 deg.
  (A side slope steep enough for the reference crawler to slide on the 38 % Thailand clay, about
  22 deg by Mohr-Coulomb, is thus beyond the limit; on the 55 % clay it slides from about 15 deg.)
  The bound checked is atan(hypot(tan slope_x, tan slope_y) + the raster's steepest bilinear
  gradient). The furrows' flanks (up to atan(pi d / lambda): 23 deg for ridges 0.1 m deep every
  0.75 m) are not held to it, a modelling choice: a track bridges furrows that run across it and
  rests on the ridges (or in a furrow) of furrows along it, so its load stays normal to the mean
  plane and the flanks are pressed down vertically, as a rut's walls are; their limits are the
  depth and the spacing below.
- the furrow depth at most :data:`GROUND_CLEARANCE_M`: the vehicle's hull rides above the ridges
  only while the furrows are shallower than its ground clearance. The vehicle parameters have no
  clearance yet (symtrack/model/parameters.py); 0.40 m is ASSUMED for the reference crawler (an
  order of magnitude for a medium agricultural crawler, not taken from a data sheet). The 3D
  vehicle may make it a vehicle parameter: then this limit takes it.
- a furrow spacing of at least 4 cells (``terrain.cell_m``): the cells sample a furrow period
  with four points at least (checked where the field's cell size is known: :meth:`Surface.check_field`).

A flat surface (every key 0 or absent) is no surface: the field then carries no elevation array
and everything runs as before it (bit for bit).
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ScenarioError
from . import gis
from .storage import Grid

__all__ = ["GROUND_CLEARANCE_M", "MAX_SLOPE_DEG", "MIN_FURROW_CELLS", "PATH_KEYS", "SURFACE_KEYS", "ElevationRaster",
           "Surface", "parse_surface"]

MAX_SLOPE_DEG = 20.0  # module doc: the vertical-column cells' errors cos t, cos^2 t (6 %, 12 % at 20 deg)
GROUND_CLEARANCE_M = 0.40  # module doc: ASSUMED for the reference crawler (no vehicle parameter yet)
MIN_FURROW_CELLS = 4  # cells per furrow period at least
SURFACE_KEYS = ("slope_x_deg", "slope_y_deg", "furrow_spacing_m", "furrow_depth_m", "furrow_heading_deg",
                "elevation_file", "elevation_cell_m", "elevation_origin_m")
# the keys of a scenario document that hold the surface's file (resolved against a scenario file's folder)
PATH_KEYS = (("terrain", "surface", "elevation_file"),)
WHERE = "terrain.surface"


@dataclasses.dataclass(frozen=True, eq=False)
class ElevationRaster:
    """Heights at pixel centres: ``values`` (nx, ny) float64, i along x, j along y; pixel (i, j)
    centred at origin + ((i + 1/2) pixel_m, (j + 1/2) pixel_m). ``origin_m`` None: the field's
    lower-left corner (:meth:`placed`). ``crs_wkt``: a GeoTIFF's CRS."""

    path: str
    values: np.ndarray
    pixel_m: float
    origin_m: tuple[float, float] | None = None
    crs_wkt: str | None = None

    def placed(self, origin_m) -> ElevationRaster:
        """This raster with its origin (the field's when it had none)."""
        if self.origin_m is not None:
            return self
        return dataclasses.replace(self, origin_m=(float(origin_m[0]), float(origin_m[1])))

    def bounds(self) -> tuple[float, float, float, float]:
        x0, y0 = self.origin_m
        nx, ny = self.values.shape
        return x0, x0 + nx * self.pixel_m, y0, y0 + ny * self.pixel_m

    def _uv(self, x, y):
        """Fractional pixel-centre coordinates, clamped to the centres' hull."""
        nx, ny = self.values.shape
        u = np.clip((np.asarray(x, dtype=float) - self.origin_m[0]) / self.pixel_m - 0.5, 0.0, nx - 1.0)
        v = np.clip((np.asarray(y, dtype=float) - self.origin_m[1]) / self.pixel_m - 0.5, 0.0, ny - 1.0)
        return u, v

    def sample(self, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The bilinear height at (x, y) and its gradient (d/dx, d/dy; 0 along an axis where the
        point is clamped to the edge)."""
        a = self.values
        nx, ny = a.shape
        u, v = self._uv(x, y)
        i = np.minimum(np.floor(u).astype(np.int64), nx - 2)
        j = np.minimum(np.floor(v).astype(np.int64), ny - 2)
        s, t = u - i, v - j
        z00, z10, z01, z11 = a[i, j], a[i + 1, j], a[i, j + 1], a[i + 1, j + 1]
        z = (1 - s) * (1 - t) * z00 + s * (1 - t) * z10 + (1 - s) * t * z01 + s * t * z11
        x_in = (np.asarray(x) - self.origin_m[0]) / self.pixel_m - 0.5
        y_in = (np.asarray(y) - self.origin_m[1]) / self.pixel_m - 0.5
        gx = np.where((x_in > 0) & (x_in < nx - 1), ((1 - t) * (z10 - z00) + t * (z11 - z01)) / self.pixel_m, 0.0)
        gy = np.where((y_in > 0) & (y_in < ny - 1), ((1 - s) * (z01 - z00) + s * (z11 - z10)) / self.pixel_m, 0.0)
        return z, gx, gy

    def casadi(self, x, y):
        """The bilinear height as a CasADi expression of x, y (SX or MX): CasADi's B-spline interpolant of
        degree 1 on the pixel centres (the bilinear interpolation itself), the point clamped to their hull
        as in :meth:`sample`. Not the "linear" interpolant: the same heights, but its second derivatives
        are wrong (its d2z/dxdy is 0; a Jacobian of its Jacobian gave NaN in the 3D vehicle's static
        settle and 1.0 where 0 was due, measured with CasADi 3.8), and the 3D vehicle's Jacobian takes
        second derivatives of the ground (the penetration's rate); the B-spline's derivatives are B-splines
        of lower degree (the bilinear patch's gradient, its cross derivative, 0 along each axis) and are
        code-generated."""
        nx, ny = self.values.shape
        xc = self.origin_m[0] + (np.arange(nx) + 0.5) * self.pixel_m
        yc = self.origin_m[1] + (np.arange(ny) + 0.5) * self.pixel_m
        f = ca.interpolant("elevation_raster", "bspline", [xc, yc], self.values.ravel(order="F"),
                           {"degree": [1, 1]})
        xs = ca.fmin(ca.fmax(x, xc[0]), xc[-1])
        ys = ca.fmin(ca.fmax(y, yc[0]), yc[-1])
        return f(ca.vertcat(xs, ys))

    def steepest_gradient(self) -> float:
        """The largest |grad| of the bilinear surface (at a pixel corner of some bilinear patch)."""
        a, h = self.values, self.pixel_m
        dx = np.diff(a, axis=0) / h  # (nx - 1, ny)
        dy = np.diff(a, axis=1) / h  # (nx, ny - 1)
        # in patch (i, j) the gradient is bilinear in (s, t): its largest norm is at a corner
        gx = np.stack([dx[:, :-1], dx[:, 1:]])  # t = 0, 1
        gy = np.stack([dy[:-1, :], dy[1:, :]])  # s = 0, 1
        corners = [np.hypot(gx[t], gy[s]) for s in (0, 1) for t in (0, 1)]
        return float(np.max(corners))


@dataclasses.dataclass(frozen=True, eq=False)
class Surface:
    """The parsed ``[terrain.surface]`` (module doc): the analytic part and an optional raster.
    ``raw`` is the table as given (written back by the scenario's to_dict)."""

    slope_x_deg: float = 0.0
    slope_y_deg: float = 0.0
    furrow_spacing_m: float | None = None
    furrow_depth_m: float = 0.0
    furrow_heading_deg: float = 0.0
    raster: ElevationRaster | None = None
    raw: dict = dataclasses.field(default_factory=dict, repr=False)

    # -- what it is ------------------------------------------------------------------------------------
    @property
    def is_flat(self) -> bool:
        return self.slope_x_deg == 0.0 and self.slope_y_deg == 0.0 and self.furrow_depth_m == 0.0 and \
            self.raster is None

    @property
    def crs_wkt(self) -> str | None:
        return None if self.raster is None else self.raster.crs_wkt

    def _coefficients(self):
        gx, gy = math.tan(math.radians(self.slope_x_deg)), math.tan(math.radians(self.slope_y_deg))
        if self.furrow_depth_m > 0.0:
            h = math.radians(self.furrow_heading_deg)
            k = 2.0 * math.pi / self.furrow_spacing_m
            return gx, gy, 0.5 * self.furrow_depth_m, k, -math.sin(h), math.cos(h)
        return gx, gy, 0.0, 0.0, 0.0, 0.0

    def plane_steepest(self) -> float:
        """An upper bound of the ground plane's ``|grad z0|`` (the slopes and the raster; not the furrows,
        module doc): hypot(tan sx, tan sy) + the raster's steepest gradient."""
        gx, gy = math.tan(math.radians(self.slope_x_deg)), math.tan(math.radians(self.slope_y_deg))
        return math.hypot(gx, gy) + (self.raster.steepest_gradient() if self.raster is not None else 0.0)

    # -- numerically (numpy) ---------------------------------------------------------------------------
    def elevation(self, x_m, y_m) -> np.ndarray:
        """z0 at the points (broadcast), float64 metres."""
        return self.evaluate(x_m, y_m)[0]

    def evaluate(self, x_m, y_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """z0 and its gradient (dz0/dx, dz0/dy) at the points (broadcast)."""
        x, y = np.broadcast_arrays(np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float))
        gx, gy, a, k, sx, sy = self._coefficients()
        z = gx * x + gy * y
        dzx = np.full(x.shape, gx)
        dzy = np.full(x.shape, gy)
        if a:
            phase = k * (sx * x + sy * y)
            z = z + a * np.cos(phase)
            dzx = dzx - a * k * sx * np.sin(phase)
            dzy = dzy - a * k * sy * np.sin(phase)
        if self.raster is not None:
            zr, rx, ry = self.raster.sample(x, y)
            z, dzx, dzy = z + zr, dzx + rx, dzy + ry
        return z, dzx, dzy

    def cell_elevation(self, grid: Grid) -> np.ndarray:
        """z0 at every cell centre of ``grid``, flat float64 (i * ny + j)."""
        nx, ny = grid.shape
        xc, yc = grid.centres(np.arange(nx), np.arange(ny))
        return np.ascontiguousarray(self.elevation(xc[:, None], yc[None, :]).ravel())

    # -- symbolically (CasADi) -------------------------------------------------------------------------
    def casadi(self, x, y):
        """z0 as a CasADi expression of x, y (SX or MX; the same formula as :meth:`evaluate`)."""
        gx, gy, a, k, sx, sy = self._coefficients()
        z = gx * x + gy * y
        if a:
            z = z + a * ca.cos(k * (sx * x + sy * y))
        if self.raster is not None:
            z = z + self.raster.casadi(x, y)
        return z

    def function(self) -> ca.Function:
        """``surface_elevation(x, y) -> (z0, dz0_dx, dz0_dy)`` (a 3D vehicle's contact: the height
        and the gradient of the ground at a point, by CasADi's algorithmic differentiation)."""
        x, y = ca.SX.sym("x_m"), ca.SX.sym("y_m")  # (a raster's interpolant is a call node in SX)
        z = self.casadi(x, y)
        return ca.Function("surface_elevation", [x, y], [z, ca.jacobian(z, x), ca.jacobian(z, y)],
                           ["x_m", "y_m"], ["z0_m", "dz0_dx", "dz0_dy"])

    def points_function(self, n: int, point: ca.Function | None = None) -> ca.Function:
        """:meth:`function` at ``n`` points in one evaluation: ``surface_elevation_<n>(x, y) -> (z0, dz0_dx,
        dz0_dy)``, each a 1 x n row (point i in column i), the same arithmetic point by point (a serial
        map). Called with SX it is one call node (``never_inline``), and so are its derivatives (those of
        a map are maps): the 3D vehicle's contact evaluates an elevation raster at all its points through
        it, where a call of :meth:`function` per point put a call node to the raster's interpolant per
        point and per derivative into its expressions, their Jacobians and the generated C
        (symtrack.vehicles.vehicle3d, ``Vehicle3D.grounds``). ``point``: this surface's :meth:`function`
        when it is built already (a large raster's interpolant takes seconds to build: 17 s for 600 x 600
        pixels, measured with CasADi 3.8)."""
        point = self.function() if point is None else point
        x, y = ca.MX.sym("x_m", 1, n), ca.MX.sym("y_m", 1, n)
        return ca.Function(f"surface_elevation_{n}", [x, y], point.map(n, "serial")(x, y),
                           ["x_m", "y_m"], ["z0_m", "dz0_dx", "dz0_dy"], {"never_inline": True})

    # -- the field -------------------------------------------------------------------------------------
    def placed(self, grid: Grid) -> Surface:
        """This surface on ``grid``: a raster without an origin takes the field's; checked (:meth:`check_field`)."""
        s = self if self.raster is None else dataclasses.replace(self, raster=self.raster.placed(grid.origin_m))
        s.check_field(grid)
        return s

    def check_field(self, grid: Grid) -> None:
        """A :class:`ScenarioError` unless the furrows are resolved by the cells and the raster covers the field."""
        if self.furrow_depth_m > 0.0 and self.furrow_spacing_m < MIN_FURROW_CELLS * grid.cell_m:
            raise ScenarioError(f"{WHERE}.furrow_spacing_m = {self.furrow_spacing_m!r} must be at least "
                                f"{MIN_FURROW_CELLS} cells ({MIN_FURROW_CELLS} x terrain.cell_m = "
                                f"{MIN_FURROW_CELLS * grid.cell_m:g} m): the cells sample a furrow with "
                                f"{MIN_FURROW_CELLS} points at least")
        r = self.raster
        if r is None or r.origin_m is None:
            return
        x0, x1, y0, y1 = grid.bounds()
        left, right, bottom, top = r.bounds()
        tol = 1e-6 * grid.cell_m
        if x0 < left - tol or x1 > right + tol or y0 < bottom - tol or y1 > top + tol:
            raise ScenarioError(
                f"{WHERE}.elevation_file = {r.path!r} covers x in [{left:.10g}, {right:.10g}] m, y in "
                f"[{bottom:.10g}, {top:.10g}] m; the field is x in [{x0:.10g}, {x1:.10g}] m, y in [{y0:.10g}, "
                f"{y1:.10g}] m: the raster must cover the whole field (move it with elevation_origin_m, or "
                "the field with terrain.origin_m and size_m)")

    def to_dict(self) -> dict:
        return dict(self.raw)


# ---- parsing -----------------------------------------------------------------------------------------

def _num(key, value, low, high, low_open=False):
    return number(f"{WHERE}.{key}", value, low, high, low_open)


def _read_npy(path: str, pixel_m: float, origin_m) -> ElevationRaster:
    a = gis.read_npy(path, f"{WHERE}.elevation_file")
    if a.ndim != 2 or a.dtype.kind not in "iuf":
        raise ScenarioError(f"{WHERE}.elevation_file = {path!r}: a 2-D array of heights in m (i along x, j along "
                            f"y) is needed, the file holds {a.dtype} {a.shape}")
    return ElevationRaster(path, a.astype(np.float64), pixel_m, origin_m)


def _read_geotiff(path: str) -> ElevationRaster:
    where = f"{WHERE}.elevation_file"
    h = gis.read_header(path, where, values="real")
    if not np.isclose(h.pixel_x_m, h.pixel_y_m, rtol=1e-9, atol=0.0):
        raise ScenarioError(f"{where} = {path!r} has pixels of {h.pixel_x_m:g} x {h.pixel_y_m:g} m: an elevation "
                            "raster's pixels must be square (warp it first: gdalwarp -tr)")
    data = gis.read_band(path, where)  # rows from the top
    a = np.asarray(data, dtype=np.float64).T[:, ::-1]  # (width, height): i along x, j along +y
    if h.nodata is not None:
        a = np.where(a == h.nodata, np.nan, a)
    return ElevationRaster(path, np.ascontiguousarray(a), h.pixel_x_m, (h.left_m, h.bottom_m), h.crs_wkt)


def parse_surface(t) -> Surface:
    """The ``surface`` table -> :class:`Surface`; every key checked (module doc), the raster read
    and checked for NaN and for the slope limit. The field's coverage is checked later, where the
    field is known (:meth:`Surface.check_field`, from the terrain settings and the world)."""
    if not isinstance(t, dict):
        raise ScenarioError(f"{WHERE} = {t!r} must be a table ({', '.join(SURFACE_KEYS)})")
    check_keys(WHERE, t, list(SURFACE_KEYS))
    limit = MAX_SLOPE_DEG
    sx, sy = (_num(k, t.get(k, 0.0), -90.0, 90.0, low_open=True) for k in ("slope_x_deg", "slope_y_deg"))
    for k, v in (("slope_x_deg", sx), ("slope_y_deg", sy)):
        if abs(v) > limit:
            raise ScenarioError(f"{WHERE}.{k} = {t[k]!r} is outside the allowed range [{-limit:g}, {limit:g}] deg: the "
                                "cells are vertical columns, valid on ground inclined by at most 20 deg (at 20 deg "
                                "their sinkage errs by 1 - cos t = 6 %, their pressure by 1 - cos^2 t = 12 %)")
    depth = _num("furrow_depth_m", t.get("furrow_depth_m", 0.0), 0.0, 1e3)
    if depth > GROUND_CLEARANCE_M:
        raise ScenarioError(f"{WHERE}.furrow_depth_m = {t['furrow_depth_m']!r} is outside the allowed range "
                            f"[0, {GROUND_CLEARANCE_M:g}] m: furrows deeper than the vehicle's ground clearance "
                            f"({GROUND_CLEARANCE_M:g} m, assumed for the reference crawler) would ground its hull")
    if depth > 0.0 and "furrow_spacing_m" not in t:
        raise ScenarioError(f"{WHERE}.furrow_depth_m = {t['furrow_depth_m']!r} needs furrow_spacing_m (the distance "
                            "between furrows, in (0, 20] m)")
    spacing = _num("furrow_spacing_m", t["furrow_spacing_m"], 0.0, 20.0, low_open=True) \
        if "furrow_spacing_m" in t else None
    heading = _num("furrow_heading_deg", t.get("furrow_heading_deg", 0.0), -360.0, 360.0)
    raster = None
    path = t.get("elevation_file")
    if path is None:
        for k in ("elevation_cell_m", "elevation_origin_m"):
            if k in t:
                raise ScenarioError(f"{WHERE}.{k} is given without elevation_file (it describes that raster)")
    else:
        if not isinstance(path, str) or not (path.endswith(".npy") or gis.is_geotiff(path)):
            raise ScenarioError(f"{WHERE}.elevation_file = {path!r} must be the path of a .npy file of heights or of "
                                f"a GeoTIFF ({', '.join(gis.GEOTIFF_SUFFIXES)})")
        if gis.is_geotiff(path):
            for k in ("elevation_cell_m", "elevation_origin_m"):
                if k in t:
                    raise ScenarioError(f"{WHERE}.{k} = {t[k]!r}: a GeoTIFF's transform gives its pixel and origin; "
                                        "leave the key out")
            raster = _read_geotiff(path)
        else:
            if "elevation_cell_m" not in t:
                raise ScenarioError(f"{WHERE}.elevation_file = {path!r} needs elevation_cell_m (the .npy's pixel in "
                                    "m, (0, 1000])")
            pixel = _num("elevation_cell_m", t["elevation_cell_m"], 0.0, 1000.0, low_open=True)
            origin = t.get("elevation_origin_m")
            if origin is not None:
                if not isinstance(origin, (list, tuple)) or len(origin) != 2:
                    raise ScenarioError(f"{WHERE}.elevation_origin_m = {origin!r} must be a pair [x, y] in m")
                origin = tuple(_num(f"elevation_origin_m[{i}]", v, -1e7, 1e7) for i, v in enumerate(origin))
            raster = _read_npy(path, pixel, origin)
        if min(raster.values.shape) < 2:
            raise ScenarioError(f"{WHERE}.elevation_file = {path!r} has {raster.values.shape[0]} x "
                                f"{raster.values.shape[1]} pixels: at least 2 x 2 are needed (bilinear heights)")
        bad = ~np.isfinite(raster.values)
        if bad.any():
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise ScenarioError(f"{WHERE}.elevation_file = {path!r} holds {int(bad.sum())} NaN, inf or nodata "
                                f"pixel(s) (the first at i, j = {i}, {j}): every pixel needs a height")
        if np.abs(raster.values).max() > 1e5:
            raise ScenarioError(f"{WHERE}.elevation_file = {path!r}: heights must be metres in [-1e5, 1e5], the "
                                f"raster has {float(np.abs(raster.values).max()):g}")
    s = Surface(sx, sy, spacing, depth, heading, raster, dict(t))
    steep = s.plane_steepest()
    if math.degrees(math.atan(steep)) > limit + 1e-9:
        parts = ", ".join(f"{k} = {t[k]!r}" for k in ("slope_x_deg", "slope_y_deg", "elevation_file") if k in t)
        raise ScenarioError(
            f"{WHERE}: {parts} make a slope of up to {math.degrees(math.atan(steep)):.3g} deg; the allowed range is "
            f"[0, {limit:g}] deg (the cells are vertical columns: at t = 20 deg their sinkage errs by 1 - cos t = 6 %, "
            "their pressure by 1 - cos^2 t = 12 %; the steepest = atan(hypot(tan slope_x, tan slope_y) + the "
            "raster's steepest gradient))")
    return s
