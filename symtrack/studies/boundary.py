"""Polygon field boundaries (docs/studies.md, "Field operations: a polygon field").

``operation.boundary_file`` names the field's boundary in the field's own metric coordinates (m,
the grid's: x east, y north, the grid [0, size_x] x [0, size_y] of ``operation.size_m``), in one of
two formats:

- **GeoJSON** (``.geojson`` or ``.json``, RFC 7946's geometry objects): a ``Polygon`` geometry, a
  ``Feature`` whose geometry is one, or a ``FeatureCollection`` of exactly one such feature. Only
  the exterior ring is used; a polygon with holes is refused. The ring is closed (its last position
  repeats its first, as RFC 7946 requires); positions are ``[x_m, y_m]`` (a third value, an
  elevation, is ignored). RFC 7946 itself prescribes WGS 84 longitudes and latitudes: export the
  boundary from the farm's GIS in a projected CRS (UTM) and shift it to the grid's origin; a
  ``crs`` member is not read.
- **CSV** (``.csv``): a header ``x_m,y_m`` and one vertex a row, the ring closed (the last row
  repeats the first).

Refused before anything runs, naming the key: a ring that is not closed, fewer than three distinct
vertices, a non-finite coordinate, a ring that is not simple (two edges crossing or touching, a
repeated vertex), a vertex outside the grid, a field too small for one working width. Either
orientation is accepted (the ring is made counter-clockwise).

The geometry is numpy only (no GIS library): the inward offsets of the headland rounds are mitred
(each vertex moved along its bisector so that every edge moves by the same distance; an offset
that makes an edge vanish or fold is refused), the track lines are clipped by the crossings of
the horizontal line with the inner ring, the masks are matplotlib's point-in-polygon.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from ..foundations.errors import ScenarioError
from ..foundations.files import read_text

__all__ = ["BOUNDARY_KEY", "area_m2", "contains", "is_simple", "line_crossings", "offset_ring", "read_boundary"]

BOUNDARY_KEY = "operation.boundary_file"


def area_m2(ring: np.ndarray) -> float:
    """The signed area of a ring (m, 2) (shoelace; positive counter-clockwise)."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _orient(a, b, c) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a, b, c, tol) -> bool:
    """c on the segment a-b (collinear within tol, inside its box)."""
    scale = max(1.0, math.hypot(b[0] - a[0], b[1] - a[1]))
    return abs(_orient(a, b, c)) <= tol * scale and min(a[0], b[0]) - tol <= c[0] <= max(a[0], b[0]) + tol \
        and min(a[1], b[1]) - tol <= c[1] <= max(a[1], b[1]) + tol


def _segments_meet(a, b, c, d, tol) -> bool:
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    if ((o1 > 0 > o2) or (o1 < 0 < o2)) and ((o3 > 0 > o4) or (o3 < 0 < o4)):
        return True
    return _on_segment(a, b, c, tol) or _on_segment(a, b, d, tol) or _on_segment(c, d, a, tol) \
        or _on_segment(c, d, b, tol)


def is_simple(ring: np.ndarray, tol: float = 1e-9) -> tuple[bool, str]:
    """Whether the closed ring (m, 2) is simple: no two edges cross or touch, except adjacent edges
    at their shared vertex (and those do not fold back onto each other). Returns (ok, why). O(m^2):
    a field's boundary has tens to hundreds of vertices."""
    m = len(ring)
    P = [tuple(map(float, v)) for v in ring]
    for i in range(m):
        a, b = P[i], P[(i + 1) % m]
        if math.hypot(b[0] - a[0], b[1] - a[1]) <= tol:
            return False, f"vertex {(i + 1) % m} repeats vertex {i}"
    for i in range(m):
        a, b = P[i], P[(i + 1) % m]
        for j in range(i + 1, m):
            c, d = P[j], P[(j + 1) % m]
            if j == i + 1:  # shared vertex b = c: folds when d is on a-b or a on c-d
                bad = _on_segment(a, b, d, tol) or _on_segment(c, d, a, tol)
            elif i == 0 and j == m - 1:  # shared vertex a = d
                bad = _on_segment(a, b, c, tol) or _on_segment(c, d, b, tol)
            else:
                bad = _segments_meet(a, b, c, d, tol)
            if bad:
                return False, f"edge {i} (vertices {i}-{(i + 1) % m}) meets edge {j} (vertices {j}-{(j + 1) % m})"
    return True, ""


def _number_pair(v, where: str):
    if not isinstance(v, (list, tuple)) or len(v) < 2 or not all(
            isinstance(c, (int, float)) and not isinstance(c, bool) for c in v[:2]):
        raise ScenarioError(f"{where}: a position must be [x_m, y_m] numbers, got {v!r}")
    return float(v[0]), float(v[1])


def _geojson_ring(doc, label: str) -> list:
    if not isinstance(doc, dict):
        raise ScenarioError(f"{label}: not a GeoJSON object")
    t = doc.get("type")
    if t == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list) or len(feats) != 1:
            raise ScenarioError(f"{label}: a FeatureCollection must hold exactly one Feature (the field), it holds "
                                f"{len(feats) if isinstance(feats, list) else 'no list of'} features")
        return _geojson_ring(feats[0], label)
    if t == "Feature":
        return _geojson_ring(doc.get("geometry"), label)
    if t != "Polygon":
        raise ScenarioError(f"{label}: the geometry is a {t!r}; a field boundary is a GeoJSON \"Polygon\"")
    rings = doc.get("coordinates")
    if not isinstance(rings, list) or not rings:
        raise ScenarioError(f"{label}: a Polygon's coordinates must be a list of rings")
    if len(rings) > 1:
        raise ScenarioError(f"{label}: the polygon has {len(rings) - 1} hole(s); a field with holes is not supported "
                            "(give its exterior ring only)")
    if not isinstance(rings[0], list):
        raise ScenarioError(f"{label}: the exterior ring must be a list of positions")
    return [_number_pair(v, label) for v in rings[0]]


def _csv_ring(text: str, label: str) -> list:
    rows = list(csv.reader(text.splitlines()))
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows or [c.strip() for c in rows[0]] != ["x_m", "y_m"]:
        raise ScenarioError(f"{label}: a boundary CSV starts with the header x_m,y_m")
    out = []
    for k, r in enumerate(rows[1:], start=2):
        if len(r) != 2:
            raise ScenarioError(f"{label}: line {k} has {len(r)} values, not x_m,y_m")
        try:
            out.append((float(r[0]), float(r[1])))
        except ValueError as err:
            raise ScenarioError(f"{label}: line {k}: {err}") from err
    return out


def read_boundary(path, size_m, min_width_m: float = 0.0) -> np.ndarray:
    """The boundary at ``path`` (module doc) as a counter-clockwise ring (m, 2) without the
    repeated vertex, checked: closed, simple, at least three vertices, inside the grid
    [0, size_m[0]] x [0, size_m[1]], its inscribed room at least ``min_width_m`` (an inward offset
    by half of it leaves a polygon). Raises :class:`ScenarioError` naming ``operation.boundary_file``."""
    label = f"{BOUNDARY_KEY} = {str(path)!r}"
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{label}: no such file")
    text = read_text(p, BOUNDARY_KEY + " file")
    if p.suffix.lower() in (".geojson", ".json"):
        try:
            doc = json.loads(text)
        except ValueError as err:
            raise ScenarioError(f"{label}: not valid JSON ({err})") from err
        pts = _geojson_ring(doc, label)
    elif p.suffix.lower() == ".csv":
        pts = _csv_ring(text, label)
    else:
        raise ScenarioError(f"{label}: the file must be GeoJSON (.geojson, .json) or CSV (.csv)")
    ring = np.array(pts, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(ring)):
        raise ScenarioError(f"{label}: a coordinate is not finite")
    if len(ring) < 4 or not np.array_equal(ring[0], ring[-1]):
        raise ScenarioError(f"{label}: the ring is not closed: its last vertex must repeat its first "
                            f"({ring[0].tolist() if len(ring) else []} ... {ring[-1].tolist() if len(ring) else []})")
    ring = ring[:-1]
    if len(np.unique(ring, axis=0)) < 3:
        raise ScenarioError(f"{label}: a polygon needs at least three distinct vertices, it has "
                            f"{len(np.unique(ring, axis=0))}")
    Lx, Ly = size_m
    out = (ring[:, 0] < 0) | (ring[:, 0] > Lx) | (ring[:, 1] < 0) | (ring[:, 1] > Ly)
    if out.any():
        k = int(np.argmax(out))
        raise ScenarioError(f"{label}: vertex {k} at ({ring[k, 0]:g}, {ring[k, 1]:g}) m is outside the grid "
                            f"[0, {Lx:g}] x [0, {Ly:g}] m of operation.size_m")
    ok, why = is_simple(ring)
    if not ok:
        raise ScenarioError(f"{label}: the boundary is not a simple polygon: {why}")
    if area_m2(ring) < 0:
        ring = ring[::-1].copy()
    if min_width_m > 0:
        try:
            offset_ring(ring, 0.5 * min_width_m)
        except ScenarioError as err:
            raise ScenarioError(f"{label}: the field is too small for one working width of {min_width_m:g} m "
                                f"({err})") from None
    return ring


def offset_ring(ring: np.ndarray, d: float) -> np.ndarray:
    """The counter-clockwise ring moved inward by ``d`` (mitred: vertex k at the crossing of its two
    edges' offset lines, the vertices in the same order). Raises :class:`ScenarioError` when an
    edge vanishes or folds back (the offset polygon is then another polygon) or the result is not
    simple."""
    p, q = ring, np.roll(ring, -1, axis=0)
    t = q - p
    L = np.hypot(*t.T)
    t = t / L[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])  # the left normal: inward on a counter-clockwise ring
    n_prev = np.roll(n, 1, axis=0)
    c = np.sum(n * n_prev, axis=1)
    if np.any(c <= -1 + 1e-9):
        raise ScenarioError("an edge turns back on the one before it")
    out = p + d * (n + n_prev) / (1.0 + c)[:, None]
    t2 = np.roll(out, -1, axis=0) - out
    if np.any(np.sum(t2 * t, axis=1) <= 1e-9):
        k = int(np.argmax(np.sum(t2 * t, axis=1) <= 1e-9))
        raise ScenarioError(f"offset {d:g} m inward, edge {k} of the boundary vanishes")
    ok, why = is_simple(out)
    if not ok or area_m2(out) <= 0:
        raise ScenarioError(f"offset {d:g} m inward, the ring is no longer simple ({why or 'it turned over'})")
    return out


def line_crossings(ring: np.ndarray, y: float) -> np.ndarray:
    """The sorted x where the horizontal line at ``y`` crosses the ring's edges (half-open rule:
    an edge counts from its lower end, so a vertex on the line counts once)."""
    p, q = ring, np.roll(ring, -1, axis=0)
    ylo, yhi = np.minimum(p[:, 1], q[:, 1]), np.maximum(p[:, 1], q[:, 1])
    m = (ylo <= y) & (y < yhi)
    f = (y - p[m, 1]) / (q[m, 1] - p[m, 1])
    return np.sort(p[m, 0] + f * (q[m, 0] - p[m, 0]))


def contains(ring: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Whether each point (k, 2) is inside the ring (matplotlib's point-in-polygon)."""
    from matplotlib.path import Path as MPath

    return MPath(np.vstack([ring, ring[:1]]), closed=True).contains_points(points)


def cell_mask(ring: np.ndarray, shape, cell_m: float) -> np.ndarray:
    """The cells (nx, ny) whose centre is inside the ring."""
    nx, ny = shape
    xc = (np.arange(nx) + 0.5) * cell_m
    yc = (np.arange(ny) + 0.5) * cell_m
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    return contains(ring, np.column_stack([X.ravel(), Y.ravel()])).reshape(shape)


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / math.hypot(*v)
