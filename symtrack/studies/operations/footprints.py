"""The tracks' footprints on the field's cells: the swath and footprint masks, the plan's check against the
field's border (:func:`check_plan`), the passes per cell (:func:`count_passes_and_times`) and the field's,
headland's and trafficked shares (:func:`field_shares`).

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import math

import numpy as np

from ...foundations import caches
from ...foundations.errors import ScenarioError
from ...terrain.world import padding_m
from ...vehicles.planar import contact_rectangles
from .. import boundary as bnd
from .plans import OperationPlan, inner_ring, k_turn_headland_m, sample_roles
from .settings import PASS_GAP_S, PATH_DS_M, OperationSettings


def swath_mask(plan: OperationPlan, shape, cell_m: float) -> np.ndarray:
    """The cells (nx, ny) bool whose centres the implement's swath covers: the worked lines
    (between the headlands) and the headland rounds, each ``working_width_m`` wide about the path
    (a raster of the plan, for the coverage check)."""
    fs = plan.settings
    roles = sample_roles(plan)
    keep = (roles == 3) | (roles == 0)
    return _sweep(plan.path.x[keep], plan.path.y[keep], plan.path.psi[keep], shape, cell_m,
                  [(0.0, PATH_DS_M, 0.5 * fs.working_width_m)], overlap=False)


def footprint_mask(x, y, psi, params: dict, shape, cell_m: float) -> np.ndarray:
    """The cells (nx, ny) bool whose square overlaps a track's l x b contact rectangle at one of the
    poses (x, y, psi): an independent raster of the tracks' footprint (separating axes)."""
    rects, lateral = track_rects(params)
    return _sweep(np.asarray(x, float), np.asarray(y, float), np.asarray(psi, float), shape, cell_m,
                  rects, lateral=lateral, overlap=True)


def track_rects(params: dict):
    """The two tracks' contact rectangles in the body frame (the vehicle's, planar.contact_rectangles):
    [(centre ahead, half l, half b)], [lateral]."""
    rects = contact_rectangles(params)
    return [(float(ahead), hl, hb) for ahead, _, hl, hb in rects], [lat for _, lat, _, _ in rects]


def _sweep(x, y, psi, shape, cell_m, rects, lateral=None, overlap=True) -> np.ndarray:
    """Union over poses of body-frame rectangles (centre ahead c, half length, half width; centred
    ``lateral`` to the left): cells whose square overlaps (``overlap``) or whose centre is inside."""
    mask = np.zeros(shape, dtype=bool)
    for _, (i0, i1, j0, j1), inside in sweep_windows(x, y, psi, shape, cell_m, rects, lateral, overlap):
        mask[i0:i1, j0:j1] |= inside
    return mask


def sweep_windows(x, y, psi, shape, cell_m, rects, lateral=None, overlap=True):
    """Per pose k and rectangle: (k, (i0, i1, j0, j1), the window's bool cells inside), the window
    the rectangle's bounding box in the grid (poses whose rectangle is off the grid give none)."""
    nx, ny = shape
    lateral = lateral or [0.0] * len(rects)
    h = 0.5 * cell_m if overlap else 0.0
    centres = []
    for (c, hl, hb), lat in zip(rects, lateral, strict=True):
        centres.append((x + c * np.cos(psi) - lat * np.sin(psi), y + c * np.sin(psi) + lat * np.cos(psi), hl, hb))
    for k in range(x.size):
        ca_, sa = math.cos(psi[k]), math.sin(psi[k])
        for cx, cy, hl, hb in centres:
            reach = math.hypot(hl, hb) + cell_m
            i0 = max(int(math.floor((cx[k] - reach) / cell_m)), 0)
            i1 = min(int(math.ceil((cx[k] + reach) / cell_m)), nx)
            j0 = max(int(math.floor((cy[k] - reach) / cell_m)), 0)
            j1 = min(int(math.ceil((cy[k] + reach) / cell_m)), ny)
            if i1 <= i0 or j1 <= j0:
                continue
            px = (np.arange(i0, i1) + 0.5) * cell_m - cx[k]
            py = (np.arange(j0, j1) + 0.5) * cell_m - cy[k]
            u = px[:, None] * ca_ + py[None, :] * sa
            v = -px[:, None] * sa + py[None, :] * ca_
            if overlap:
                ext_x = hl * abs(ca_) + hb * abs(sa)
                ext_y = hl * abs(sa) + hb * abs(ca_)
                rot = h * (abs(ca_) + abs(sa))
                inside = ((np.abs(u) < hl + rot) & (np.abs(v) < hb + rot)
                          & (np.abs(px)[:, None] < h + ext_x) & (np.abs(py)[None, :] < h + ext_y))
            else:
                inside = (np.abs(u) <= hl) & (np.abs(v) <= hb)
            yield k, (i0, i1, j0, j1), inside


def check_plan(plan: OperationPlan, params: dict, model_opts) -> dict:
    """The plan against the vehicle and the soil, before anything runs: the footprint stays in
    the field along the whole path (with the engine's padding and one cell), the turn radius is one
    the vehicle holds on this soil at the turn speed (a trim). Returns the trims of the steering
    map's turn points. Raises :class:`ScenarioError` naming the key, the value and the reason."""
    fs = plan.settings
    Lx, Ly = fs.size_m
    p = plan.path
    n_end = int(np.nonzero(p.segment == -1)[0][0]) + 1
    x, y, psi = p.x[:n_end], p.y[:n_end], p.psi[:n_end]
    half_l = 0.5 * params["contact_length_m"] + abs(params["cg_ahead_of_contact_centre_m"])
    half_w = 0.5 * (params["track_gauge_m"] + params["track_width_m"])
    room = padding_m(fs.cell_m) + fs.cell_m
    if fs.turn == "k" and len(plan.line_y_m) > 1 and fs.boundary is None:  # (a polygon's: the footprint check)
        _check_k_turns(plan, half_l, half_w, room, 0.5 * float(params["track_gauge_m"]))
    if fs.boundary is not None:
        _check_in_polygon(plan, x, y, psi, half_l + room, half_w + room)
        return {}
    ext_x = half_l * np.abs(np.cos(psi)) + half_w * np.abs(np.sin(psi)) + room
    ext_y = half_l * np.abs(np.sin(psi)) + half_w * np.abs(np.cos(psi)) + room
    out = (x - ext_x < 0) | (x + ext_x > Lx) | (y - ext_y < 0) | (y + ext_y > Ly)
    if out.any():
        k = int(np.argmax(out))
        seg = int(p.segment[k])
        role = plan.roles[seg] if seg >= 0 else "end"
        raise ScenarioError(f"the plan leaves the field: at ({x[k]:.2f}, {y[k]:.2f}) m on a {role} segment the "
                            f"vehicle's footprint (half length {half_l:g} m, half width {half_w:g} m, {room:.3g} m of "
                            f"the engine's padding) crosses the border of the {Lx:g} m x {Ly:g} m field; with "
                            f"operation.turn_radius_m = {fs.turn_radius_m:g} and operation.working_width_m = "
                            f"{fs.working_width_m:g} the headland of {fs.headland_passes} rounds ({fs.headland_m:g} m) "
                            "is too narrow: raise operation.headland_passes or lower the radius")
    return {}


def _check_in_polygon(plan: OperationPlan, x, y, psi, hl: float, hw: float) -> None:
    """The footprint (a rectangle of half length ``hl``, half width ``hw`` about each pose) inside
    the boundary: its corners and the midpoints of its sides inside, and no boundary vertex inside
    it (a reflex vertex poking into the footprint)."""
    fs = plan.settings
    ring = np.array(fs.boundary)
    c, s_ = np.cos(psi), np.sin(psi)
    pts = []
    for a, b in ((1, 1), (1, -1), (-1, 1), (-1, -1), (1, 0), (-1, 0), (0, 1), (0, -1)):
        pts.append(np.column_stack([x + a * hl * c - b * hw * s_, y + a * hl * s_ + b * hw * c]))
    inside = np.all(np.stack([bnd.contains(ring, q) for q in pts]), axis=0)
    for vx, vy in ring:
        u = (vx - x) * c + (vy - y) * s_
        v = -(vx - x) * s_ + (vy - y) * c
        inside &= ~((np.abs(u) < hl) & (np.abs(v) < hw))
    if not inside.all():
        k = int(np.argmax(~inside))
        seg = int(plan.path.segment[k])
        role = plan.roles[seg] if seg >= 0 else "end"
        raise ScenarioError(f"the plan leaves the field: at ({x[k]:.2f}, {y[k]:.2f}) m on a {role} segment the "
                            f"vehicle's footprint (half length {hl:.3g} m, half width {hw:.3g} m with the engine's "
                            f"padding) crosses the boundary of {bnd.BOUNDARY_KEY} = {fs.boundary_file!r}; with "
                            f"operation.turn_radius_m = {fs.turn_radius_m:g} the headland of {fs.headland_passes} "
                            f"rounds ({fs.headland_m:g} m) is too narrow there: raise operation.headland_passes or "
                            "lower the radius")


def _check_k_turns(plan: OperationPlan, half_l: float, half_w: float, room: float, half_gauge: float) -> None:
    """A K-turn whose footprint reaches beyond the headland (:func:`k_turn_headland_m`, plus the
    engine's padding ``room``) is refused, naming the key and the radii that fit."""
    fs = plan.settings
    S = float(np.max(np.diff(plan.line_y_m)))  # the reach grows with the spacing: the widest turn decides
    R, H = fs.turn_radius_m, fs.headland_m

    def need(r):
        return k_turn_headland_m(S, r, half_l, half_w) + room

    if need(R) <= H + 1e-9:
        return
    lo = max(0.5 * S, half_gauge)  # a K-turn needs 2 R > S; a turn, R > half the gauge
    if need(lo * (1 + 1e-9)) > H:
        fit = f"no K-turn radius fits this headland (even R -> {lo:.3g} m reaches {need(lo * (1 + 1e-9)):.3g} m)"
    else:
        a, b = lo, R  # need() grows with R (R sin alpha does): bisect need(r) = H
        for _ in range(60):
            m = 0.5 * (a + b)
            a, b = (m, b) if need(m) <= H else (a, m)
        fit = f"the allowed range of operation.turn_radius_m is ({lo:.3g}, {a:.3g}] m here"
    passes = int(math.ceil(need(R) / fs.working_width_m - 1e-9))
    raise ScenarioError(f"operation.turn = \"k\": a K-turn of operation.turn_radius_m = {R:g} between lines {S:.3g} m "
                        f"apart reaches {need(R):.3g} m beyond the line's end (the path {R:g} sin alpha, the "
                        f"vehicle's footprint and {room:.3g} m of the engine's padding), more than the headland's "
                        f"{H:g} m (operation.headland_passes = {fs.headland_passes} x operation.working_width_m = "
                        f"{fs.working_width_m:g}): {fit}, or operation.headland_passes >= {passes}")


def count_passes(traj: np.ndarray, params: dict, shape, cell_m: float) -> np.ndarray:
    """Passes per cell (nx, ny) uint16 from driven poses (t, x, y, yaw) (module doc: a cell counts a
    pass when a track's contact comes over it after PASS_GAP_S out of every contact)."""
    return count_passes_and_times(traj, params, shape, cell_m)[0]


def count_passes_and_times(traj: np.ndarray, params: dict, shape, cell_m: float):
    """:func:`count_passes` and, per cell, the time a track's contact first came over it (float32,
    inf where none did): the animation's reveal time."""
    counts = np.zeros(shape, dtype=np.uint16)
    last = np.full(shape, -np.inf, dtype=np.float64)
    first = np.full(shape, np.inf, dtype=np.float32)
    rects, lateral = track_rects(params)
    traj = np.asarray(traj, dtype=float)
    # per pose, the window of each track (the work is local: a 4-million-cell field is not swept per pose)
    for k, (i0, i1, j0, j1), inside in sweep_windows(traj[:, 1], traj[:, 2], traj[:, 3], shape, cell_m, rects,
                                                      lateral, overlap=True):
        t = traj[k, 0]
        lw = last[i0:i1, j0:j1]
        new = inside & (t - lw > PASS_GAP_S)
        counts[i0:i1, j0:j1][new] += 1
        fw = first[i0:i1, j0:j1]
        fw[inside & np.isinf(fw)] = t
        lw[inside] = t
    return counts, first


# a polygon field's cell masks (point-in-polygon over every cell: about 1 s at 4 million; symtrack.foundations.caches)
_MASK_CACHE = caches.cache("field_masks", 8)


def _ring_mask(ring: np.ndarray, shape, cell_m: float) -> np.ndarray:
    key = (ring.tobytes(), tuple(shape), cell_m)
    return _MASK_CACHE.get_or_build(key, lambda: bnd.cell_mask(ring, shape, cell_m))


def field_mask(fs: OperationSettings, shape, cell_m: float) -> np.ndarray:
    """The grid's cells (nx, ny) that are the field: all of them on a rectangle, those whose centre
    is inside the boundary on a polygon field."""
    if fs.boundary is None:
        return np.ones(shape, dtype=bool)
    return _ring_mask(np.array(fs.boundary), shape, cell_m).copy()


def headland_mask(fs: OperationSettings, shape, cell_m: float) -> np.ndarray:
    if fs.boundary is not None:  # the field's cells outside the in-field ring
        return field_mask(fs, shape, cell_m) & ~_ring_mask(inner_ring(fs), shape, cell_m)
    nx, ny = shape
    xc = (np.arange(nx) + 0.5) * cell_m
    yc = (np.arange(ny) + 0.5) * cell_m
    H = fs.headland_m
    inx = (xc >= H) & (xc <= fs.size_m[0] - H)
    iny = (yc >= H) & (yc <= fs.size_m[1] - H)
    return ~(inx[:, None] & iny[None, :])


def field_shares(stressed: np.ndarray, counts: np.ndarray, fs: OperationSettings) -> dict:
    """The trafficked shares (in the field, the headland and the in-field area) and the area run
    over once, twice, three times or more."""
    head = headland_mask(fs, stressed.shape, fs.cell_m)
    field = field_mask(fs, stressed.shape, fs.cell_m)
    area = fs.cell_m ** 2
    out = {"trafficked_fraction": float(stressed[field].mean()),
           "headland_trafficked_fraction": float(stressed[head].mean()),
           "infield_trafficked_fraction": float(stressed[field & ~head].mean()),
           "headland_area_m2": float(head.sum() * area), "field_area_m2": float(field.sum() * area)}
    c = counts.astype(np.int64)[field]
    for k, name in ((1, "once"), (2, "twice")):
        out[f"area_run_over_{name}_m2"] = float((c == k).sum() * area)
    out["area_run_over_3_or_more_m2"] = float((c >= 3).sum() * area)
    out["repeated_coverage_fraction"] = float(c.sum() / c.size)  # Kroulik's "repeated coverage": passes x area / field
    if fs.boundary is not None:  # (a polygon field's grid holds cells outside it: traffic there is outside the field)
        out["outside_field_trafficked_m2"] = float((stressed & ~field).sum() * area)
    out["passes_per_cell_max"] = int(c.max()) if c.size else 0
    return out
