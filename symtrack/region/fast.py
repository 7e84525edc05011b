"""The fast fidelity: a field's season as the planned paths swept by each machine's quasi-static footprint
(docs/region.md, "The fast fidelity").

For each operation of the season, in the order of the days they are worked:

1. **The plan**: :func:`symtrack.studies.operations.plan_operation` on the field's polygon (or rectangle),
   the same plan the full fidelity drives: headland rounds, track lines, headland turns.
2. **The footprint**: every segment of the plan (straights and arcs) swept by the machine's wheel or track
   strips (each at its lateral offset from the path line, rigidly: a trailed implement's off-tracking in the
   turns is not modelled, as in :mod:`symtrack.studies.traffic_seasons`), rasterised in closed form on the
   field's cells. A cell is under a strip when its centre is (``rule = "centre"``: the area is unbiased) or
   when its square overlaps the strip (``rule = "overlap"``: the terrain engine's rule, which the full
   fidelity's trafficked share counts). One pass per segment that covers a cell (a tractor's front and rear
   tyres in line are one pass), times the operation's repeats. On an arc a track is its rigid l x b contact
   turned about the turn's centre (:func:`symtrack.region.fleet.arc_bands`): its ends sweep beyond its edges,
   and a cell beyond a track's outer edge is passed twice, by its front end and then by its rear end
   (:func:`~symtrack.region.fleet.arc_stays`).
3. **The stress**: the pass's largest vertical stress at each depth of a cell under a strip is the machine's
   stress profile (:func:`symtrack.region.fleet.stress_profile`, built once per machine and soil) at the
   cell's lateral distance from the path line (on an arc, its radial distance from the path's circle, and a
   track's profile the turned contact's: :func:`~symtrack.region.fleet.turn_profile`). Where the plan's speed
   changes (the followers' speed profile, :data:`~symtrack.studies.operations.PLAN_ACCEL_M_S2` before and after
   its slow parts), a tracked machine whose centre of gravity's height is known has the terrain engine's
   pitched pressure line (:func:`~symtrack.region.fleet.pressure_line`): the stress profile of that line, and
   its peak's share of the static pressure for the rut (step 4b). As in the terrain engine, the stress is
   recorded under the footprint only.
4. **The density**: each pass is folded into the cells' compression state by
   :func:`symtrack.soil.density.pass_update` (the function the full fidelity's world folds its passes
   with) with the soil of the day's matric suction (its moisture class, :mod:`symtrack.region.inputs`) and
   the soil's own weight (:func:`~symtrack.soil.density.geostatic_table`): an operation that passes a
   cell k times folds it k times at the operation's stress there.
   4b. A tracked machine leaves a rut, and the rut bounds the compression below it, as the terrain engine's
   world bounds it (:func:`symtrack.soil.density.cap_to_rut`): after each tracked pass the cells it passed
   get the rut of their N tracked passes so far, the first pass's quasi-static plastic rut
   (:func:`symtrack.region.fleet.first_pass_rut_m`) times N^beta (the engine's cycle law). A cell the track
   covers in part carries that share of its pressure (the engine's channel weight) and gets the smaller rut;
   a cell a pitched line passes carries its peak (the whole contact passes over it) and gets the larger one.
   Wheels leave no rut here, as in the package's wheeled pass (symtrack/vehicles/wheeled.py), so their
   compression is not bounded.
5. **The risk**: (traffic stress + own weight) / the day's precompression stress, graded by
   :func:`symtrack.soil.subsoil.risk_class`; the season keeps each cell's largest ratio.
6. **Tillage** (an operation with ``loosens_to_m``): after it, every cell of the field above that depth is
   back at the soil's initial state (ASSUMED: tillage restores the initial bulk density of the layer it
   works; no source gives the density a tilled layer returns to). Below it the state persists from season
   to season; no recovery rate is applied (none adopted: Berisso et al. 2012, Soil & Tillage Research 122,
   42-51, found a loamy subsoil's compaction persisting 14 years after the load).

The season's own record (passes per cell, largest stress, largest risk ratio) starts empty each season; the
compression state carries over.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..soil import density, subsoil
from ..studies.operations import PLAN_ACCEL_M_S2, OperationSettings, plan_operation
from ..studies.operations.followers import speed_profile
from ..studies.traffic_seasons import segment_geometry
from .fleet import Machine, StressProfile, arc_bands, arc_stays, peak_pressure_factor, stress_profile, turn_profile

__all__ = ["RULES", "FastOp", "SeasonMaps", "build_profiles", "fold_operation", "run_season_fast",
           "sweep_operation"]

RULES = ("centre", "overlap")
# a straight segment is rasterised in pieces at most this long (their bounding boxes stay narrow on a
# diagonal edge of a polygon's headland); the pieces are half-open intervals along it, so they partition it
PIECE_M = 10.0
# the plan's path sampled every metre: the fast fidelity uses the plan's segments, not its samples (the
# followers' 5 cm sampling costs three quarters of a field-season's time and changes no segment)
PLAN_DS_M = 1.0


@dataclass(frozen=True)
class FastOp:
    """One operation of a fast season: its plan's settings, the machine, its repeats on the same plan, the
    depth it loosens to (None: no tillage), the stress profile of the machine on the field's soil and the soil
    of the day (a parameter set: the day's matric suction applied) with its name for the tables' cache."""

    name: str
    settings: OperationSettings
    machine: Machine
    repeat: int
    loosens_to_m: float | None
    profile: StressProfile
    soil_day: dict
    day: int = 0
    # a tracked machine's first-pass plastic rut [m] at each share of the track's static pressure a cell carries
    # (fleet.rut_table_m, at fleet.PRESSURE_FRACTIONS) and the soil's repeated-loading exponent: the rut after N
    # passes, the first pass's N^beta, bounds the column's compression (step 4b); None: wheels
    rut_table_m: tuple | None = None
    rut_exponent: float = 0.0


@dataclass
class SeasonMaps:
    """A field-season's maps on the field's grid (nx, ny): passes per cell, the largest traffic stress [Pa]
    and the largest risk ratio by depth (nx, ny, n_depths), the compression state after the season
    (n_cells, n_depths) float32 (0: the soil's initial state) and the figures of each operation."""

    counts: np.ndarray
    sigma_max_Pa: np.ndarray
    risk_ratio_max: np.ndarray
    state: np.ndarray
    operations: list


def sweep_operation(op: FastOp, shape, cell_m: float, rule: str = "centre"):
    """The operation's passes per cell (nx, ny) int32, its largest stress per cell (nx, ny, n_depths) float32
    [Pa] and the largest share of the static pressure each cell carries (nx, ny) float32 (its width across the
    path under the strip over its width, the terrain engine's channel weight, times the pitched line's peak over
    the static pressure where the plan's speed changes) from one drive of its plan (module doc, steps
    1-3; the repeats not applied)."""
    plan = plan_operation(op.settings, ds_m=PLAN_DS_M)
    geo = segment_geometry(plan)
    nx, ny = shape
    nd = op.profile.sigma_Pa.shape[1]
    counts = np.zeros(shape, dtype=np.int32)
    sig = np.zeros((nx, ny, nd), dtype=np.float32)
    cover = np.zeros(shape, dtype=np.float32)
    out = (counts, sig, cover)
    bands = tuple((lat - 0.5 * b, lat + 0.5 * b) for lat, b in op.machine.strips())
    reach = op.machine.reach_m
    pad = 0.5 * cell_m if rule == "overlap" else 0.0
    # where the plan's speed changes, a tracked machine's pressure line pitches (fleet.pressure_line): the stress
    # and the pressure share of its pitched line there
    m = op.machine
    ramps = _ramps(plan) if m.tracks is not None and m.cg_height_m is not None else {}
    ramp = None
    if ramps:
        ramp = (stress_profile(m, op.profile.depths_m, op.profile.xi, accel_m_s2=PLAN_ACCEL_M_S2),
                peak_pressure_factor(m, PLAN_ACCEL_M_S2))
    for i, (kind, x0, y0, psi0, g) in enumerate(geo):
        c, s = math.cos(psi0), math.sin(psi0)
        if kind == "straight":
            for w0, w1, pitched in ramps.get(i, ((0.0, g, False),)):
                profile, factor = ramp if pitched else (op.profile, 1.0)
                n_pieces = max(1, int(math.ceil((w1 - w0) / PIECE_M)))
                for k in range(n_pieces):
                    u0, u1 = w0 + (w1 - w0) * k / n_pieces, w0 + (w1 - w0) * (k + 1) / n_pieces
                    px0, py0 = x0 + u0 * c, y0 + u0 * s
                    _straight(px0, py0, c, s, u1 - u0, bands, reach, pad, profile, shape, cell_m, out, factor)
        else:
            # a track's rigid contact turned about the turn's centre: its ends sweep beyond its width, and its
            # stress is the turned footprint's (fleet.arc_bands, fleet.turn_profile; wheels: their strips)
            R = g[0]
            profile = turn_profile(op.machine, op.profile.depths_m, op.profile.xi, R) or op.profile
            _arc(x0, y0, c, s, g, op.machine, arc_bands(op.machine, R), pad, profile, shape, cell_m, out)
    return counts, sig, cover


def build_profiles(op: FastOp) -> None:
    """Build the operation's turned and pitched stress profiles (:func:`sweep_operation` builds them when it
    first needs them; fleet caches them per process): a caller that times the tables apart from the sweep."""
    m = op.machine
    if m.tracks is None:
        return
    plan = plan_operation(op.settings, ds_m=PLAN_DS_M)
    for kind, _x0, _y0, _psi0, g in segment_geometry(plan):
        if kind != "straight":
            turn_profile(m, op.profile.depths_m, op.profile.xi, g[0])
    if m.cg_height_m is not None and _ramps(plan):
        stress_profile(m, op.profile.depths_m, op.profile.xi, accel_m_s2=PLAN_ACCEL_M_S2)


def _ramps(plan) -> dict:
    """The stretches of each straight segment of the plan where the followers' speed profile (symtrack.studies.
    operations.followers: the path's speeds, reached at :data:`~symtrack.studies.operations.PLAN_ACCEL_M_S2` in
    deceleration before its slow parts and in acceleration after them) changes the speed: {segment index:
    ((u0, u1, pitched), ...)} covering [0, length] in order, ``pitched`` where the speed changes. The profile is
    the plan's, sampled every :data:`PLAN_DS_M`: a stretch's ends to that."""
    path = plan.path
    v = speed_profile(path, 0.0)
    out = {}
    s0 = 0.0
    for i, seg in enumerate(path.segments):
        L = seg.length_m if seg.kind == "straight" else abs(seg.radius_m) * math.radians(seg.angle_deg)
        if seg.kind == "straight" and L > 0:
            u = np.linspace(0.0, L, max(2, int(math.ceil(L / (0.25 * PLAN_DS_M))) + 1))
            vv = np.interp(s0 + u, path.s, v)
            acc = np.diff(vv ** 2) / (2.0 * np.diff(u))
            flag = np.abs(acc) > 0.5 * PLAN_ACCEL_M_S2
            if flag.any():
                cuts = np.flatnonzero(np.diff(flag.astype(np.int8))) + 1
                edges = np.concatenate([[0], cuts, [flag.size]])
                out[i] = tuple((float(u[a]), float(u[b]), bool(flag[a])) for a, b in zip(edges[:-1], edges[1:],
                                                                                          strict=True))
        s0 += L
    return out


def _window(xs, ys, shape, cell_m):
    nx, ny = shape
    i0 = max(int(math.floor(min(xs) / cell_m)) - 1, 0)
    i1 = min(int(math.ceil(max(xs) / cell_m)) + 1, nx)
    j0 = max(int(math.floor(min(ys) / cell_m)) - 1, 0)
    j1 = min(int(math.ceil(max(ys) / cell_m)) + 1, ny)
    return i0, i1, j0, j1


def _apply(i0, i1, j0, j1, under, v, hv, bands, profile, out, stays=None, factor=1.0):
    counts, sig, cover = out
    if not under.any():
        return
    counts[i0:i1, j0:j1] += under if stays is None else np.where(under, stays, 0)
    ii, jj = np.nonzero(under)
    vv = v[ii, jj]
    st = profile.at(vv).astype(np.float32)
    w = sig[i0:i1, j0:j1]
    w[ii, jj] = np.maximum(w[ii, jj], st)
    f = np.zeros(vv.size)
    for lo, hi in bands:  # the cell's extent across the path, [v - hv, v + hv], under the strip's band
        f = np.maximum(f, np.clip((np.minimum(vv + hv, hi) - np.maximum(vv - hv, lo)) / (2 * hv), 0.0, 1.0))
    cw = cover[i0:i1, j0:j1]
    cw[ii, jj] = np.maximum(cw[ii, jj], (factor * f).astype(np.float32))


def _straight(x0, y0, c, s, L, bands, reach, pad, profile, shape, cell_m, out, factor=1.0):
    r = reach + pad
    xs = [x0 - r * s, x0 + r * s, x0 + L * c - r * s, x0 + L * c + r * s]
    ys = [y0 + r * c, y0 - r * c, y0 + L * s + r * c, y0 + L * s - r * c]
    i0, i1, j0, j1 = _window(xs, ys, shape, cell_m)
    if i1 <= i0 or j1 <= j0:
        return
    px = (np.arange(i0, i1) + 0.5) * cell_m
    py = (np.arange(j0, j1) + 0.5) * cell_m
    u = (px[:, None] - x0) * c + (py[None, :] - y0) * s
    v = -(px[:, None] - x0) * s + (py[None, :] - y0) * c
    # the overlap rule: a cell's square reaches pad (|c| + |s|) beyond its centre along any direction
    pv = pad * (abs(c) + abs(s))
    along = (u >= 0.0) & (u < L) if pv == 0 else (u >= -pv) & (u < L + pv)
    under = np.zeros(u.shape, dtype=bool)
    for lo, hi in bands:
        under |= (v >= lo - pv) & (v < hi + pv)
    # the cell's half-width across the path: its square's projection
    _apply(i0, i1, j0, j1, under & along, v, 0.5 * cell_m * (abs(c) + abs(s)), bands, profile, out, None, factor)


def _arc(x0, y0, c, s, g, machine, bands, pad, profile, shape, cell_m, out):
    R, sweep = g
    sg = 1.0 if R > 0 else -1.0
    cx, cy = x0 - R * s, y0 + R * c
    rr = abs(R) + max(max(abs(lo), abs(hi)) for lo, hi in bands) + pad
    i0, i1, j0, j1 = _window([cx - rr, cx + rr], [cy - rr, cy + rr], shape, cell_m)
    if i1 <= i0 or j1 <= j0:
        return
    px = (np.arange(i0, i1) + 0.5) * cell_m
    py = (np.arange(j0, j1) + 0.5) * cell_m
    dx, dy = px[:, None] - cx, py[None, :] - cy
    r = np.hypot(dx, dy)
    theta0 = math.atan2(y0 - cy, x0 - cx)
    a = np.mod(sg * (np.arctan2(dy, dx) - theta0), 2 * math.pi)
    along = a < sweep
    v = sg * (abs(R) - r)  # left of the path line positive (a left turn's centre is on its left)
    pv = math.sqrt(2.0) * pad if pad else 0.0
    under = np.zeros(r.shape, dtype=bool)
    for lo, hi in bands:
        under |= (v >= lo - pv) & (v < hi + pv)
    under &= along
    # a cell beyond a track's outer edge is under its front end, then its rear end: two passes (fleet.arc_stays)
    stays = arc_stays(machine, R, sweep, r, a, 0.5 * cell_m) if under.any() else None
    _apply(i0, i1, j0, j1, under, v, 0.5 * cell_m, bands, profile, out, stays)


def fold_operation(state: np.ndarray, counts: np.ndarray, sig: np.ndarray, op: FastOp, depths_m, arrays: dict,
                   geostatic_Pa: np.ndarray, track_passes: np.ndarray | None = None, cover: np.ndarray | None = None,
                   rut_first: np.ndarray | None = None) -> int:
    """Fold an operation's passes into the compression state (module doc, step 4): cells passed k times are
    folded k times at the operation's stress there; after each pass of a tracked machine, the column's
    compression of the cells it passed is bounded by their rut (step 4b): ``track_passes`` (n_cells,) the
    tracked passes each cell has had so far, ``rut_first`` (n_cells,) the largest first-pass rut a track has
    left in it (both updated in place), ``cover`` (nx, ny) the share of each cell under the machine's tracks.
    Returns the (cell, depth) entries that yielded."""
    flat_c = counts.ravel()
    p = sig.reshape(-1, sig.shape[-1])
    si = np.zeros(flat_c.size, dtype=np.int32)
    moved = 0
    for k in range(1, int(flat_c.max(initial=0)) + 1):
        cells = np.flatnonzero(flat_c >= k)
        before = state[cells].copy()  # what the earlier passes compressed (kept by the rut's cap, as in the world)
        moved += density.pass_update(state, p, si, [op.soil_day], cells=cells, geostatic_Pa=geostatic_Pa,
                                     depths_m=list(depths_m), arrays=arrays)
        if op.rut_table_m is not None and track_passes is not None:
            from .fleet import PRESSURE_FRACTIONS

            track_passes[cells] += 1
            r1 = np.interp(cover.ravel()[cells], PRESSURE_FRACTIONS, op.rut_table_m)
            rut_first[cells] = np.maximum(rut_first[cells], r1)
            rut = rut_first[cells] * track_passes[cells].astype(np.float64) ** op.rut_exponent
            v0 = np.broadcast_to(arrays["v0"][0], (cells.size, len(depths_m)))
            density.cap_to_rut(state, cells, v0, list(depths_m), rut, before)
    return moved


def run_season_fast(ops, shape, cell_m: float, depths_m, state: np.ndarray | None = None,
                    field_mask: np.ndarray | None = None, rule: str = "centre") -> SeasonMaps:
    """A field's season in the fast fidelity (module doc): ``ops`` (:class:`FastOp`) in the order they are
    worked, on a grid of ``shape`` cells of ``cell_m``; ``state`` the compression state the season starts
    from (n_cells, n_depths) float32, 0 the soil's initial state (None: all initial); ``field_mask`` the
    field's cells (tillage loosens them; None: every cell)."""
    if rule not in RULES:
        raise ValueError(f"rule = {rule!r} is not one of {', '.join(RULES)}")
    nx, ny = shape
    nd = len(depths_m)
    state = np.zeros((nx * ny, nd), dtype=np.float32) if state is None else state.copy()
    counts = np.zeros(shape, dtype=np.int32)
    sig_max = np.zeros((nx, ny, nd), dtype=np.float32)
    ratio_max = np.zeros((nx, ny, nd), dtype=np.float32)
    figs = []
    depths = np.asarray(depths_m, dtype=float)
    track_passes = np.zeros(nx * ny, dtype=np.int32)
    rut_first = np.zeros(nx * ny, dtype=np.float64)
    for op in ops:
        t0 = time.perf_counter()
        c1, sig, cover = sweep_operation(op, shape, cell_m, rule)
        c = c1 * op.repeat
        arrays = density.soil_arrays([op.soil_day], list(depths_m))
        geo = density.geostatic_table([op.soil_day], list(depths_m))
        moved = fold_operation(state, c, sig, op, depths_m, arrays, geo, track_passes, cover, rut_first)
        # the season's records, on the cells the operation passed (the stress is recorded there only)
        idx = np.flatnonzero(c1.ravel())
        s_op = sig.reshape(-1, nd)[idx]
        # (graded where the traffic loaded the depth, as the terrain's risk layer: terrain/gis.py)
        ratio = np.where(s_op > 0, (s_op + geo[0]) / arrays["pc"][0], 0.0).astype(np.float32)
        rm, sm = ratio_max.reshape(-1, nd), sig_max.reshape(-1, nd)
        rm[idx] = np.maximum(rm[idx], ratio)
        sm[idx] = np.maximum(sm[idx], s_op)
        counts += c
        if op.loosens_to_m is not None:
            above = depths < op.loosens_to_m
            cells = np.flatnonzero(field_mask.ravel()) if field_mask is not None else slice(None)
            sub = state[cells]
            sub[:, above] = 0.0
            state[cells] = sub
        figs.append({"name": op.name, "machine": op.machine.name, "day": op.day, "repeat": op.repeat,
                     "matric_suction_kPa": float(op.soil_day["matric_suction_kPa"]),
                     "precompression_stress_topsoil_kPa": 1e-3 * float(arrays["pc"][0, 0]),
                     "cells_passed": int(np.count_nonzero(c1)), "entries_yielded": moved,
                     "loosens_to_m": op.loosens_to_m, "wall_time_s": time.perf_counter() - t0})
    return SeasonMaps(np.minimum(counts, np.iinfo(np.uint16).max).astype(np.uint16), sig_max, ratio_max, state, figs)


def density_change(state: np.ndarray, soil: dict, depths_m) -> np.ndarray:
    """rho_b - rho_b,initial [Mg/m^3] per cell and depth of a compression state (0 where initial)."""
    a = density.soil_arrays([soil], list(depths_m))
    v = state.astype(np.float64)
    v0 = a["v0"][0][None, :]
    v = np.where(v > 0, v, v0)
    return a["rho_s"][0][None, :] / v - a["rho_s"][0][None, :] / v0


def risk_classes(ratio: np.ndarray) -> np.ndarray:
    """Terranimo's classes of the largest ratio (0 low, 1 medium, 2 high; 0 where nothing passed)."""
    return subsoil.risk_class(ratio, 1.0)
