"""An operation's path (:class:`OperationPlan`): the headland rounds, the track lines or lanes, the turns that join
them (U, bulb, K) and a polygon field's plan (:func:`plan_operation`).

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...control.path import Path, Segment
from ...foundations.errors import ScenarioError
from .. import boundary as bnd
from .settings import PATH_DS_M, OperationSettings


# ---- the plan -------------------------------------------------------------------------------------------
@dataclass
class OperationPlan:
    """One operation's path: the :class:`~symtrack.control.path.Path` (its segments), per segment
    its role ("headland": a round's straight or corner, "line": a track line, "turn") and, for
    lines, the line's index and worked x range; the lines' lateral positions; the field."""

    path: Path
    roles: list
    line_of_segment: list
    line_y_m: list
    worked_x_m: tuple  # the lines' worked range [x0, x1] (between the headlands)
    turns: int
    settings: OperationSettings
    worked_x_of_line: list | None = None  # per line its own range (a polygon field); None: worked_x_m for all

    @property
    def start(self) -> tuple[float, float, float]:
        return float(self.path.x[0]), float(self.path.y[0]), float(self.path.psi[0])


MAX_TRACK_LINES = 10_000  # an operation's plan holds at most this many lines or lanes (a bound, not physics)


def _band(fs: OperationSettings) -> tuple[float, float, float]:
    """The in-field area's y range (the headlands' inner edges) and the field's centre y."""
    if fs.boundary is not None:
        ring = np.array(fs.boundary)
        inner = inner_ring(fs)
        return float(inner[:, 1].min()), float(inner[:, 1].max()), 0.5 * float(ring[:, 1].min() + ring[:, 1].max())
    return fs.headland_m, fs.size_m[1] - fs.headland_m, 0.5 * fs.size_m[1]


def inner_ring(fs: OperationSettings) -> np.ndarray:
    """A polygon field's in-field ring: the boundary offset inward by the headland (refused, naming
    the key, when the headland leaves no polygon)."""
    try:
        return bnd.offset_ring(np.array(fs.boundary), fs.headland_m)
    except ScenarioError as err:
        raise ScenarioError(f"operation.headland_passes = {fs.headland_passes}: the headland of {fs.headland_m:g} m "
                            f"inside {bnd.BOUNDARY_KEY} = {fs.boundary_file!r} leaves no in-field polygon ({err}); "
                            "fewer headland passes or a narrower implement") from None


def lane_positions_m(fs: OperationSettings) -> np.ndarray:
    """The permanent lanes (world y) of controlled traffic: ``lane_spacing_m`` apart, centred
    across the field, as many as fit between the headlands (a lane's swath of one spacing inside)."""
    S = fs.lanes_m
    lo_edge, hi_edge, centre = _band(fs)
    inner = hi_edge - lo_edge
    if not inner / S <= MAX_TRACK_LINES:
        raise ScenarioError(f"operation.lane_spacing_m = {S:g}: {inner / S:.3g} lanes across the field, more than "
                            f"{MAX_TRACK_LINES} (the allowed range is [{inner / MAX_TRACK_LINES:.3g}, 1000] m here)")
    n = int(math.floor(inner / S + 1e-9))
    return centre + (np.arange(n) - 0.5 * (n - 1)) * S


def line_positions_m(fs: OperationSettings) -> np.ndarray:
    """The in-field track lines (world y of the CG), in driving order (increasing y)."""
    H, w = fs.headland_m, fs.working_width_m
    lo_edge, hi_edge, _ = _band(fs)
    lo, hi = lo_edge + 0.5 * w, hi_edge - 0.5 * w
    if fs.tracks == "controlled":
        lanes = lane_positions_m(fs)
        k = fs.working_width_m / fs.lanes_m
        if abs(k - round(k)) > 1e-6 or round(k) < 1:
            raise ScenarioError(f"operation.working_width_m = {fs.working_width_m:g} must be a whole multiple of "
                                f"operation.lane_spacing_m = {fs.lanes_m:g} (controlled traffic: the implement spans "
                                "whole lanes)")
        k = int(round(k))
        if lanes.size == 0:
            raise ScenarioError(f"operation.lane_spacing_m = {fs.lanes_m:g}: no lane fits between the headlands")
        # an implement of k lanes drives lanes (k - 1)/2, ... : every k-th lane from the first
        # whose swath stays inside; with k even it straddles two lanes (lanes at the implement's edges)
        ys = lanes[::k]
        if not ys.size:
            ys = lanes[:1]
        return ys
    if hi < lo - 1e-9:
        raise ScenarioError(f"operation.working_width_m = {w:g}: no line fits between the headlands of "
                            f"operation.headland_passes = {fs.headland_passes} rounds ({H:g} m each side) across a "
                            f"field {fs.size_m[1]:g} m wide")
    # one working width apart; the last line's swath may reach into the far headland (worked twice
    # there) so that every turn has the full spacing
    n_f = (hi - lo) / w
    if not n_f <= MAX_TRACK_LINES:
        raise ScenarioError(f"operation.working_width_m = {w:g}: {n_f:.3g} track lines across a field "
                            f"{fs.size_m[1]:g} m wide, more than {MAX_TRACK_LINES} (the allowed range is "
                            f"[{(hi - lo) / MAX_TRACK_LINES:.3g}, {min(fs.size_m):g}] m here)")
    n = int(math.ceil(n_f - 1e-9)) + 1
    ys = lo + w * np.arange(n)
    if fs.tracks == "random":
        r = abs(fs.random_offset_m)  # (a -0.0 as 0.0: numpy refuses the interval [0, -0])
        off = np.random.default_rng(fs.seed).uniform(-r, r, ys.size)
        # not clipped back to the headland's edge: the last AB line may lie beyond it (its swath reaches
        # into the far headland), and pulling it back brought it within a turn's diameter of the line
        # before (a plan refused on every field whose width is not a whole number of swaths)
        ys = np.sort(ys + off)
    return ys


def _fillet_segments(points, heading0: float, radius: float, speed_line, speed_turn):
    """Straights between the corners of a polyline of 90 deg turns, each corner an arc of ``radius``;
    returns (segments, [(kind, index of the corner or leg)], the end heading)."""
    segs, tags = [], []
    psi = heading0
    pts = [np.asarray(q, float) for q in points]
    # per corner its turn (signed, rad) and how far the arc cuts back along its legs: R tan(|turn| / 2)
    # (R at a right angle, exactly: the rectangle's corners)
    turn, cut = [0.0] * len(pts), [0.0] * len(pts)
    for i in range(1, len(pts) - 1):
        d0, d1 = pts[i] - pts[i - 1], pts[i + 1] - pts[i]
        cross, dot = d0[0] * d1[1] - d0[1] * d1[0], d0[0] * d1[0] + d0[1] * d1[1]
        turn[i] = math.atan2(cross, dot)
        cut[i] = radius if dot == 0.0 else radius * math.tan(0.5 * abs(turn[i]))
    for i in range(1, len(points)):
        p0, p1 = pts[i - 1], pts[i]
        L = float(np.hypot(*(p1 - p0)))
        cut0 = cut[i - 1] if i > 1 else 0.0
        cut1 = cut[i] if i < len(points) - 1 else 0.0
        straight = L - cut0 - cut1
        if straight < -1e-9:
            raise ScenarioError(f"operation.turn_radius_m = {radius:g}: a headland round's side of {L:g} m is "
                                f"too short for two corners of that radius; lower the radius or the headland passes")
        if straight > 1e-9:
            segs.append(Segment("straight", straight, speed_m_s=speed_line))
            tags.append(("headland", None))
        if i < len(points) - 1 and abs(turn[i]) > 1e-12:
            sign = 1.0 if turn[i] > 0 else -1.0
            segs.append(Segment("arc", radius_m=sign * radius, angle_deg=math.degrees(abs(turn[i])),
                                speed_m_s=speed_turn))
            tags.append(("headland", None))
            psi += turn[i]
    return segs, tags, psi


def k_turn_angles_deg(spacing: float, radius: float) -> tuple[float, float]:
    """The K-turn (three-point turn) between lines ``spacing`` apart (0 <= spacing < 2 R), three
    arcs of ``radius``: forward by alpha, backwards by beta (the heading turning on the same way,
    the arc's centre on the other side), forward by alpha onto the next line, alpha + beta + alpha
    = 180 deg. With the line's end at the origin heading +x and the centres C1 = (0, R),
    C2 = C1 + 2 R (sin a, -cos a), C3 = C2 + 2 R (-sin(pi - a), cos(pi - a)), the end
    C3 + (0, R) lies on the next line, y = spacing, when cos a = (2 R - spacing) / (4 R); it is
    then at x = 0 (the next line starts where the last ended) and both cusps are at x = R sin a,
    the turn's reach into the headland."""
    ca_ = (2.0 * radius - spacing) / (4.0 * radius)
    alpha = math.degrees(math.acos(ca_))
    return alpha, 180.0 - 2.0 * alpha


def k_turn_headland_m(spacing: float, radius: float, half_length_m: float, half_width_m: float) -> float:
    """How far beyond a line's end the K-turn's footprint reaches (a rectangle of half length
    ``half_length_m`` along the heading and ``half_width_m`` across): the maximum over the first
    arc (heading theta in [0, alpha], the centre at (R sin theta, R (1 - cos theta))) of
    (R + half_width) sin theta + half_length cos theta; the reverse arc and the last arc reach no
    further (the last mirrors the first; the reverse arc's x falls from both cusps, for R >
    half_width). Closed form: sqrt((R + b)^2 + l^2) when the maximising heading atan((R + b) / l)
    is within the arc, else its value at alpha."""
    alpha = math.radians(k_turn_angles_deg(spacing, radius)[0])
    a = radius + half_width_m
    theta = math.atan2(a, half_length_m)
    if theta <= alpha:
        return math.hypot(a, half_length_m)
    return a * math.sin(alpha) + half_length_m * math.cos(alpha)


def _turn_segments(spacing: float, radius: float, left: bool, kind: str, speed: float):
    """The turn from one line to the next, ``spacing`` across (> 0), to the left or right: "u",
    "bulb" (module doc) or "k" (:func:`k_turn_angles_deg`)."""
    sg = 1.0 if left else -1.0
    if kind == "auto":
        kind = "u" if spacing >= 2 * radius - 1e-9 else "bulb"
    if kind == "u":
        if spacing < 2 * radius - 1e-9:
            raise ScenarioError(f"operation.turn = \"u\": lines {spacing:.3g} m apart need a U-turn radius of at most "
                                f"{0.5 * spacing:.3g} m, operation.turn_radius_m = {radius:g}; use turn = \"bulb\" "
                                "or \"auto\"")
        segs = [Segment("arc", radius_m=sg * radius, angle_deg=90.0, speed_m_s=speed)]
        if spacing - 2 * radius > 1e-9:
            segs.append(Segment("straight", spacing - 2 * radius, speed_m_s=speed))
        segs.append(Segment("arc", radius_m=sg * radius, angle_deg=90.0, speed_m_s=speed))
        return segs, "u"
    if kind == "k":
        if not spacing < 2 * radius - 1e-9:
            raise ScenarioError(f"operation.turn = \"k\": lines {spacing:.3g} m apart are at least twice "
                                f"operation.turn_radius_m = {radius:g} apart; a K-turn needs a spacing below 2 R, so "
                                f"the allowed range of operation.turn_radius_m is ({0.5 * spacing:.3g}, 100] m here "
                                "(or use turn = \"u\")")
        alpha, beta = k_turn_angles_deg(spacing, radius)
        segs = [Segment("arc", radius_m=sg * radius, angle_deg=alpha, speed_m_s=speed),
                Segment("arc", radius_m=sg * radius, angle_deg=beta, speed_m_s=speed, reverse=True),
                Segment("arc", radius_m=sg * radius, angle_deg=alpha, speed_m_s=speed)]
        return segs, "k"
    if spacing > 2 * radius + 1e-9:
        raise ScenarioError(f"operation.turn = \"bulb\": lines {spacing:.3g} m apart are more than twice "
                            f"operation.turn_radius_m = {radius:g} apart; a bulb turn needs a spacing below 2 R "
                            "(use turn = \"u\" or \"auto\")")
    xc = math.sqrt(max(4 * radius ** 2 - (radius + 0.5 * spacing) ** 2, 0.0))
    beta = 90.0 - math.degrees(math.atan2(radius + 0.5 * spacing, xc))
    segs = [Segment("arc", radius_m=-sg * radius, angle_deg=beta, speed_m_s=speed)] if beta > 1e-6 else []
    segs.append(Segment("arc", radius_m=sg * radius, angle_deg=180.0 + 2 * beta, speed_m_s=speed))
    if beta > 1e-6:
        segs.append(Segment("arc", radius_m=-sg * radius, angle_deg=beta, speed_m_s=speed))
    return segs, "bulb"


def _turn_lane_extension_m(fs: OperationSettings, ys) -> float:
    """How far the lines run on (unworked) into the headland so that the U-turns cross it on the
    headland lane ``turn_lane_m`` deep from the border (controlled traffic; a lane is (j + 1/2)
    ``lane_spacing_m`` deep, as the headland rounds of an implement of an odd number of lanes are):
    headland - radius - depth, at least 0. 0 without ``turn_lane_m``."""
    if fs.turn_lane_m is None:
        return 0.0
    S, H, R = fs.lanes_m, fs.headland_m, fs.turn_radius_m
    where = "operation.turn_lane_m"
    if fs.tracks != "controlled":
        raise ScenarioError(f"{where} = {fs.turn_lane_m!r}: headland lanes are controlled traffic's "
                            f"(operation.tracks = \"controlled\"), not {fs.tracks!r}; set it to \"none\"")
    if fs.boundary is not None:
        raise ScenarioError(f"{where} = {fs.turn_lane_m!r}: headland lanes are planned on the rectangle only, not on "
                            f"{bnd.BOUNDARY_KEY}; set it to \"none\"")
    spacings = np.diff(np.asarray(ys, float))
    kinds = {("u" if fs.turn == "auto" and sp >= 2 * R - 1e-9 else fs.turn) for sp in spacings}
    if kinds - {"u"}:
        raise ScenarioError(f"{where} = {fs.turn_lane_m!r}: the turns crossing a headland lane are U-turns; "
                            f"operation.turn = {fs.turn!r} gives {', '.join(sorted(kinds - {'u'}))} turns here")
    deepest = H - R  # a U-turn from the headland's inner edge crosses it this deep from the border
    if fs.turn_lane_m == "auto":
        j = math.floor(deepest / S - 0.5 + 1e-9)
        if j < 0:
            raise ScenarioError(f"{where} = \"auto\": no headland lane ((j + 1/2) x {S:g} m deep) is within the "
                                f"{deepest:g} m a U-turn of radius {R:g} reaches into the {H:g} m headland")
        depth = (j + 0.5) * S
    else:
        depth = float(fs.turn_lane_m)
        j = depth / S - 0.5
        if abs(j - round(j)) > 1e-6 or round(j) < 0:
            raise ScenarioError(f"{where} = {depth:g} is not a headland lane: the lanes are (j + 1/2) x "
                                f"operation.lane_spacing_m = {S:g} m deep ({0.5 * S:g}, {1.5 * S:g}, ...)")
        if depth > deepest + 1e-9:
            raise ScenarioError(f"{where} = {depth:g} is outside the allowed range (0, {deepest:g}] m: a U-turn of "
                                f"operation.turn_radius_m = {R:g} from the headland's inner edge ({H:g} m) crosses "
                                f"at most {deepest:g} m deep")
    return deepest - depth


def _plan_polygon(fs: OperationSettings, ds_m: float = PATH_DS_M) -> OperationPlan:
    """A polygon field's path (docs/studies.md, "A polygon field"): the headland rounds are the
    boundary's mitred offsets at (i + 1/2) w, driven counter-clockwise as one inward spiral (the
    last edge of round i meets the first edge of round i + 1; the last round's meets the first
    line), every corner an arc of ``turn_radius_m``; the track lines along x, spaced as on the
    rectangle across the inner ring's y range, each worked between its crossings with the inner
    ring (the boundary offset by the headland), the turns at the headland end of the longer of the
    two lines they join (the shorter extended, unworked, to it)."""
    w, R, n = fs.working_width_m, fs.turn_radius_m, fs.headland_passes
    key = f"{bnd.BOUNDARY_KEY} = {fs.boundary_file!r}"
    ring0 = np.array(fs.boundary)
    rings = []
    for i in range(n):
        try:
            rings.append(bnd.offset_ring(ring0, (i + 0.5) * w))
        except ScenarioError as err:
            raise ScenarioError(f"operation.headland_passes = {n}: headland round {i + 1} ({(i + 0.5) * w:g} m inside "
                                f"{key}) is not a polygon like the boundary ({err}); fewer headland passes, a "
                                "narrower implement or a simpler boundary") from None
    inner = inner_ring(fs)
    ys = line_positions_m(fs)
    if fs.lines is not None:
        ys = ys[:fs.lines]
    # a line beyond the inner ring's top (the last line's centre may lie up to a width beyond the
    # in-field edge, as on the rectangle) is left out: its swath would work only the headland
    ys = ys[ys < inner[:, 1].max()]
    spans = []
    for y in ys:
        xs = bnd.line_crossings(inner, float(y))
        if xs.size != 2:
            raise ScenarioError(f"{key}: the track line at y = {y:.3g} m crosses the in-field polygon in "
                                f"{xs.size // 2} pieces; a plan drives one piece per line (a boundary whose inner "
                                "polygon every horizontal line crosses once: convex along y)")
        spans.append((float(xs[0]), float(xs[1])))
    # the spiral starts where the last round's downward (west) edge crosses the first line
    last = rings[-1]
    q = np.roll(last, -1, axis=0)
    y0 = float(ys[0])
    down = np.nonzero((q[:, 1] < last[:, 1]) & (np.minimum(last[:, 1], q[:, 1]) <= y0)
                      & (y0 < np.maximum(last[:, 1], q[:, 1])))[0]
    if down.size == 0:
        raise ScenarioError(f"{key}: no edge of the last headland round crosses the first line at y = {y0:.3g} m")
    xcross = last[down, 0] + (y0 - last[down, 1]) / (q[down, 1] - last[down, 1]) * (q[down, 0] - last[down, 0])
    e = int(down[np.argmin(xcross)])
    order = (np.arange(len(ring0)) + e + 1) % len(ring0)  # edge e the last: v0 its end
    rings = [r[order] for r in rings]

    def meet(p0, p1, q0, q1):  # the crossing of the lines p0-p1 and q0-q1
        d, f = p1 - p0, q1 - q0
        den = d[0] * f[1] - d[1] * f[0]
        if abs(den) < 1e-12:
            raise ScenarioError(f"{key}: two consecutive headland legs are parallel; a simpler boundary")
        t = ((q0[0] - p0[0]) * f[1] - (q0[1] - p0[1]) * f[0]) / den
        return p0 + t * d

    v0, v1 = rings[0][0], rings[0][1]
    pts = [tuple(v0 + R * bnd.unit(v1 - v0))]
    for i in range(n):
        r = rings[i]
        pts += [tuple(v) for v in r[1:]]
        if i + 1 < n:
            pts.append(tuple(meet(r[-1], r[0], rings[i + 1][0], rings[i + 1][1])))
        else:
            pts.append(tuple(meet(r[-1], r[0], np.array([0.0, y0]), np.array([1.0, y0]))))
    # the turn points: east ends (even lines run east) at the longer line's end, west ends likewise
    ends = []
    for k in range(len(ys)):
        east = k % 2 == 0
        if k + 1 < len(ys):
            ends.append(max(spans[k][1], spans[k + 1][1]) if east else min(spans[k][0], spans[k + 1][0]))
        else:
            ends.append(spans[k][1] if east else spans[k][0])
    if ends[0] <= pts[-1][0] + 1e-6:
        raise ScenarioError(f"{key}: the first line ends at x = {ends[0]:.3g} m, before the headland's corner onto it")
    pts.append((ends[0], y0))
    segs, tags, _ = _fillet_segments(pts, math.atan2(v1[1] - v0[1], v1[0] - v0[0]), R, fs.speed_m_s,
                                     fs.turn_speed_m_s)
    tags[-1] = ("line", 0)
    line_of = [t[1] for t in tags]
    roles = [t[0] for t in tags]
    turns = 0
    for k in range(1, len(ys)):
        spacing = float(ys[k] - ys[k - 1])
        tsegs, _ = _turn_segments(spacing, R, left=k % 2 == 1, kind=fs.turn, speed=fs.turn_speed_m_s)
        segs += tsegs
        roles += ["turn"] * len(tsegs)
        line_of += [None] * len(tsegs)
        turns += 1
        L = abs(ends[k] - ends[k - 1])
        if L <= 1e-6:
            raise ScenarioError(f"{key}: the track line at y = {ys[k]:.3g} m has no length between its turns")
        segs.append(Segment("straight", L, speed_m_s=fs.speed_m_s))
        roles.append("line")
        line_of.append(k)
    heading0 = math.atan2(v1[1] - v0[1], v1[0] - v0[0])
    path = Path(pts[0][0], pts[0][1], heading0, segs, fs.speed_m_s, fs.turn_speed_m_s, ds_m=ds_m,
                extension_m=5.0)
    lo = min(a for a, _ in spans)
    hi = max(b for _, b in spans)
    return OperationPlan(path, roles, line_of, [float(y) for y in ys], (lo, hi), turns, fs, spans)


def plan_operation(fs: OperationSettings, ds_m: float = PATH_DS_M) -> OperationPlan:
    """The continuous path of an operation (module doc). Geometry only: :func:`check_plan` checks
    it against the vehicle and the soil. ``ds_m``: the path's sampling (the followers drive the samples;
    a user of the segments alone, the region's fast fidelity, samples it coarsely)."""
    Lx, Ly = fs.size_m
    w, R = fs.working_width_m, fs.turn_radius_m
    if w > min(Lx, Ly):
        raise ScenarioError(f"operation.working_width_m = {w:g} is outside the allowed range (0, {min(Lx, Ly):g}] m "
                            f"(the field is {Lx:g} m x {Ly:g} m)")
    if fs.boundary is not None:
        return _plan_polygon(fs, ds_m)
    H = fs.headland_m
    if 2 * H >= min(Lx, Ly):
        raise ScenarioError(f"operation.headland_passes = {fs.headland_passes}: {fs.headland_passes} rounds of "
                            f"{w:g} m make headlands of {H:g} m, which leave no room inside a field of {Lx:g} m x "
                            f"{Ly:g} m")
    ys = line_positions_m(fs)
    if fs.lines is not None:
        ys = ys[:fs.lines]
    n = fs.headland_passes
    d = [(i + 0.5) * w for i in range(n)]
    pts = [(d[0] + R, d[0])]
    for i in range(n):
        nxt = d[i + 1] if i + 1 < n else float(ys[0])
        pts += [(Lx - d[i], d[i]), (Lx - d[i], Ly - d[i]), (d[i], Ly - d[i]), (d[i], nxt)]
    # the last corner turns onto the first line: its leg is the line (added below)
    x_line_end = Lx - H
    pts.append((x_line_end, float(ys[0])))
    segs, tags, _ = _fillet_segments(pts, 0.0, R, fs.speed_m_s, fs.turn_speed_m_s)
    tags[-1] = ("line", 0)  # the last straight: the first line up to its end
    line_of = [t[1] for t in tags]
    roles = [t[0] for t in tags]
    turns = 0
    ext = _turn_lane_extension_m(fs, ys)
    for k in range(1, len(ys)):
        spacing = float(ys[k] - ys[k - 1])
        east = k % 2 == 1  # line k-1 ran east (+x) when k-1 is even
        tsegs, _ = _turn_segments(spacing, R, left=east, kind=fs.turn, speed=fs.turn_speed_m_s)
        if ext > 1e-9:  # on into the headland to the turn lane, and back out (unworked, the line's own)
            segs.append(Segment("straight", ext, speed_m_s=fs.turn_speed_m_s))
            roles.append("line")
            line_of.append(k - 1)
        segs += tsegs
        roles += ["turn"] * len(tsegs)
        line_of += [None] * len(tsegs)
        turns += 1
        if ext > 1e-9:
            segs.append(Segment("straight", ext, speed_m_s=fs.turn_speed_m_s))
            roles.append("line")
            line_of.append(k)
        segs.append(Segment("straight", Lx - 2 * H, speed_m_s=fs.speed_m_s))
        roles.append("line")
        line_of.append(k)
    path = Path(pts[0][0], pts[0][1], 0.0, segs, fs.speed_m_s, fs.turn_speed_m_s, ds_m=ds_m, extension_m=5.0)
    return OperationPlan(path, roles, line_of, [float(y) for y in ys], (H, Lx - H), turns, fs)


def sample_roles(plan: OperationPlan) -> np.ndarray:
    """Per path sample: 0 headland, 1 turn, 2 line outside the worked range, 3 worked line."""
    seg = plan.path.segment
    out = np.zeros(seg.size, dtype=np.int8)
    for i, r in enumerate(plan.roles):
        m = seg == i
        if r == "turn":
            out[m] = 1
        elif r == "line":
            x = plan.path.x[m]
            k = plan.line_of_segment[i]
            x0, x1 = plan.worked_x_m if plan.worked_x_of_line is None else plan.worked_x_of_line[k]
            out[m] = np.where((x >= x0 - 1e-9) & (x <= x1 + 1e-9), 3, 2)
    out[seg < 0] = 2
    return out
