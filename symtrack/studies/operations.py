"""Field operations driven end to end (issue 23; docs/studies.md, "Field operations").

A field operation works a rectangular field [0, size_x] x [0, size_y] (or a polygon inside that
grid, ``boundary_file``: :func:`_plan_polygon`, :mod:`symtrack.studies.boundary`) with an implement of
``working_width_m``: first ``headland_passes`` rounds around the border (an inward spiral,
counter-clockwise, each round ``working_width_m`` inside the last, the corners arcs of
``turn_radius_m``), then the in-field track lines along x between the headlands (the headland is
``headland_passes * working_width_m`` wide on every side), joined at the headlands by turns driven
on the soil. The whole operation is **one continuous path** (:class:`OperationPlan`), driven by a
path-following torque law (:class:`PathFollower`) on the terrain engine from a set-down at its
start to a lift-off at its end: every turn is driven, its compaction and shear written into the
cells; nothing is lifted between the lines.

Track lines (``tracks``):

- ``"ab"``: parallel lines one working width apart from the first headland's inner edge (the last
  line's swath may reach into the far headland, so that every turn spans one working width);
- ``"controlled"``: permanent traffic lanes ``lane_spacing_m`` apart, centred across the field
  (the same lanes for every operation of a season, whatever its width); an implement of
  ``working_width_m`` = k ``lane_spacing_m`` drives every k-th lane;
- ``"random"``: the AB lines, each moved across by an offset drawn uniformly in
  [-``random_offset_m``, +``random_offset_m``] (numpy's default generator, ``seed``): the
  uncoordinated traffic of a field without guidance.

Turns (``turn``): ``"k"`` (the K-turn: forward, backwards, forward, :func:`k_turn_angles_deg`),
``"u"`` (quarter arc, straight across, quarter arc: needs a line spacing of at
least twice the radius), ``"bulb"`` (the omega turn: away by beta, round by 180 + 2 beta, back by
beta, three arcs of the radius; for spacings below twice the radius), ``"auto"`` (U where it
fits, else bulb). The radius must be one the vehicle can hold on the field's soil at the turn
speed: a trim (:func:`symtrack.control.trim.trim`, on the quasi-static shear law, whose steady
states are those of the lagged shear law: docs/turning.md section 8) is solved before anything
runs, and its failure refuses the plan with the trim's reason. A plan whose vehicle footprint
leaves the field anywhere along the path, a working width wider than the field, lanes that do not
fit: refused before anything runs (:func:`check_plan`).

Passes per cell: a cell counts one pass each time it comes under a track's contact after having
been out of every track's contact for at least :data:`PASS_GAP_S` (the driven poses sampled every
:data:`COUNT_SAMPLE_S`; a cell counts when its square overlaps a track's l x b rectangle). The
trafficked share of the summary is the soil's own record: the cells the engine stressed
(``World.pass_sigma > 0``: a track's contact overlapped them at a macro step's end).
"""

from __future__ import annotations

import copy
import dataclasses
import io
import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from ..control.closedloop import TrackingLaw
from ..control.mpc import MPCSettings, PathTrackingMPC
from ..control.path import Path, Segment
from ..control.trim import TrimError, trim
from ..foundations.config import check_document, check_keys, integer, number, read_document, to_toml
from ..foundations.errors import ScenarioError
from ..foundations.files import check_output_folder, npz_bytes
from ..simulation import loop
from ..simulation.builder import system_model
from ..simulation.plants import make_plant
from ..simulation.scenario import SIMULATION_RUN_KEYS, scenario_from_dict
from ..terrain.settings import PATH_KEYS as TERRAIN_PATH_KEYS
from ..terrain.storage import Terrain
from ..terrain.world import padding_m
from . import boundary as bnd
from .boundary import read_boundary

__all__ = ["OPERATION_KEYS", "OperationPlan", "OperationResult", "OperationSettings", "OperationSpec",
           "PathFollower", "SeasonResult", "check_plan", "follower_of", "footprint_mask", "is_operation_doc",
           "is_operation_document", "load_operation_spec", "operation_spec_from_dict", "plan_operation",
           "run_operation", "run_season", "swath_mask", "traffic_comparison", "traffic_files", "traffic_row"]

FIELD_PACKAGE = "symtrack.studies.fields"
SCHEMA_VERSION = 1
TRACKS = ("ab", "controlled", "random")
TURNS = ("auto", "u", "bulb", "k")
FOLLOWERS = ("auto", "law", "rti")  # follower_of: the MPC, the law where the plan reverses | PathFollower | MPCFollower
OPERATION_KEYS = ("name", "size_m", "boundary_file", "cell_m",
                  "working_width_m", "headland_passes", "tracks", "lane_spacing_m",
                  "random_offset_m", "seed", "turn", "turn_radius_m", "speed_m_s", "turn_speed_m_s",
                  "torque_limit_N_m", "max_lateral_error_m", "vehicle", "lines", "turn_lane_m", "follower")
TOP_KEYS = ("name", "description", "run", "model", "vehicle", "soil", "terrain", "engine", "operation", "season")
SEASON_KEYS = ("operations", "compare", "tracks")
OPERATION_RUN_KEYS = tuple(k for k in SIMULATION_RUN_KEYS if k not in ("stop_after_distance_m", "stop_distance_event"))
TERRAIN_KEYS_OF_OPERATION = ("size_m", "cell_m", "origin_m", "passes", "initial_state")

# the path's sampling (control.path.Path) and the room the footprint check keeps to the border
PATH_DS_M = 0.05
# passes per cell: driven poses every COUNT_SAMPLE_S; a cell out of every contact for PASS_GAP_S
# counts a new pass when a track comes over it again (0.1 s at 3 m/s is 0.3 m, an eighth of the
# 2.4 m contact, so a cell under a passing track is seen at every sample)
COUNT_SAMPLE_S = 0.1
PASS_GAP_S = 1.0
# the follower's speed profile: the largest deceleration / acceleration it plans with (m/s^2); a
# moderate value (the crawler's 2000 N m accelerate it at about 1 m/s^2 on the clay)
PLAN_ACCEL_M_S2 = 0.4
# An operation's vehicle step and omega_smoothing_rad_s are the package's (one vehicle step per macro step,
# halved by the engine's error control, EngineSettings.vehicle_tolerance; ModelOptions' 0.01 rad/s):
# the 2.5 ms substeps and 0.1 rad/s that operations once forced are no longer needed (docs/studies.md).

# the MPC follower's (operation.follower = "rti") step halvings on the collocation defect before a
# relinearisation and the NLP fallback (MPCSettings.rti_step_halvings, 3 there). Measured on
# operation_small (one run each, clay / sandy loam): 3 gives 1 / 4 failed solves and 5 / 3 IPOPT
# fallbacks (the slowest solve 1.6 / 1.7 s) at the U-turns' entries; 6 none of either on both soils
# (the slowest solve 5.5 / 6.1 ms)
OPERATION_RTI_STEP_HALVINGS = 6
# (the follower keeps one relinearisation and the cold start's shifted preparation, as it was measured
# with; MPCSettings' defaults for the MPC scenarios are 3 and "solution")
# the steering map's curvatures (1/m) besides the turn's own: straight running to a 12 m radius
MAP_CURVATURES = (0.0, 1 / 400, 1 / 150, 1 / 60, 1 / 30, 1 / 12)


@dataclass(frozen=True)
class OperationSettings:
    """The ``[operation]`` section (module doc; the built-in ``operation_small.toml`` documents every key)."""

    name: str = "operation"
    size_m: tuple = (60.0, 40.0)
    cell_m: float = 0.1
    working_width_m: float = 3.0
    headland_passes: int = 2
    tracks: str = "ab"
    lane_spacing_m: float | None = None  # None: working_width_m
    random_offset_m: float = 0.5
    seed: int = 1
    turn: str = "auto"
    turn_radius_m: float = 4.0
    speed_m_s: float = 2.5
    turn_speed_m_s: float = 1.0
    # the sprocket torque limit: one home, the MPC's (MPCSettings.torque_max_N_m, ASSUMED there)
    torque_limit_N_m: float = MPCSettings.torque_max_N_m
    max_lateral_error_m: float = 1.0
    vehicle: dict = dataclasses.field(default_factory=dict)  # overrides of [vehicle] for this operation
    lines: int | None = None  # None: all that fit; else the first n lines (small tests)
    # a polygon field (symtrack.studies.boundary): the file and its ring (counter-clockwise, m); None: the rectangle
    boundary_file: str | None = None
    boundary: tuple | None = None
    # controlled traffic: the depth from the border of the headland lane the U-turns cross on (m; "auto": the
    # deepest lane the turn reaches from the headland's inner edge); None: the turns at the headland's edge
    turn_lane_m: float | str | None = None
    # who drives the path: "rti" (the path-tracking MPC, real-time iteration: MPCFollower), "law" (PathFollower) or
    # "auto" (follower_of: the MPC, except on a plan with K-turns, whose reverse arcs only the law drives)
    follower: str = "auto"

    @property
    def headland_m(self) -> float:
        return self.headland_passes * self.working_width_m

    @property
    def lanes_m(self) -> float:
        return self.lane_spacing_m if self.lane_spacing_m is not None else self.working_width_m


def _num(key, value, low, high, low_open=False):
    return number(f"operation.{key}", value, low, high, low_open)


def parse_operation(t: dict, base: OperationSettings | None = None, where: str = "operation") -> OperationSettings:
    """An ``[operation]`` table (or a season entry over ``base``) -> :class:`OperationSettings`."""
    check_keys(where, t, OPERATION_KEYS)
    d = base or OperationSettings()
    kw = {}
    if "name" in t:
        if not isinstance(t["name"], str) or not t["name"]:
            raise ScenarioError(f"{where}.name = {t['name']!r} must be a non-empty string")
        kw["name"] = t["name"]
    if "size_m" in t:
        size = t["size_m"]
        if not isinstance(size, (list, tuple)) or len(size) != 2:
            raise ScenarioError(f"{where}.size_m = {size!r} must be a pair [x, y] of lengths in m")
        kw["size_m"] = tuple(_num(f"size_m[{i}]", v, 5.0, 1e4) for i, v in enumerate(size))
    for k, lo, hi, lo_open in (("cell_m", 0.01, 1.0, False), ("working_width_m", 0.0, 100.0, True),
                               ("random_offset_m", 0.0, 50.0, False), ("turn_radius_m", 0.5, 100.0, False),
                               ("speed_m_s", 0.1, 5.0, False), ("turn_speed_m_s", 0.1, 5.0, False),
                               ("torque_limit_N_m", 0.0, 1e5, True), ("max_lateral_error_m", 0.05, 20.0, False)):
        if k in t:
            kw[k] = _num(k, t[k], lo, hi, lo_open)
    if "lane_spacing_m" in t:
        v = t["lane_spacing_m"]
        kw["lane_spacing_m"] = None if v in (None, "none") else _num("lane_spacing_m", v, 0.0, 1e3, True)
    if "headland_passes" in t:
        kw["headland_passes"] = integer(f"{where}.headland_passes", t["headland_passes"], 1, 20)
    if "seed" in t:
        kw["seed"] = integer(f"{where}.seed", t["seed"], 0, 2 ** 62)
    if "lines" in t:
        v = t["lines"]
        kw["lines"] = None if v in (None, "all") else integer(f"{where}.lines", v, 1, 10_000)
    for k, choices in (("tracks", TRACKS), ("turn", TURNS), ("follower", FOLLOWERS)):
        if k in t:
            if t[k] not in choices:
                raise ScenarioError(f"{where}.{k} = {t[k]!r} is not one of {', '.join(choices)}")
            kw[k] = t[k]
    if "turn_lane_m" in t:
        v = t["turn_lane_m"]
        kw["turn_lane_m"] = None if v in (None, "none") else "auto" if v == "auto" else \
            _num("turn_lane_m", v, 0.0, 1e3, True)
    if "boundary_file" in t:
        v = t["boundary_file"]
        if v in (None, "none"):
            kw.update(boundary_file=None, boundary=None)
        elif not isinstance(v, str) or not v:
            raise ScenarioError(f"{where}.boundary_file = {v!r} must be the path of a GeoJSON or CSV boundary "
                                "(docs/studies.md, \"A polygon field\") or \"none\"")
        else:
            ring = read_boundary(v, kw.get("size_m", d.size_m), kw.get("working_width_m", d.working_width_m))
            kw.update(boundary_file=v, boundary=tuple(map(tuple, ring.tolist())))
    if "vehicle" in t:
        if not isinstance(t["vehicle"], dict):
            raise ScenarioError(f"{where}.vehicle = {t['vehicle']!r} must be a table of [vehicle] keys")
        kw["vehicle"] = {**d.vehicle, **t["vehicle"]}
    return dataclasses.replace(d, **kw)


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
        inner = _inner_ring(fs)
        return float(inner[:, 1].min()), float(inner[:, 1].max()), 0.5 * float(ring[:, 1].min() + ring[:, 1].max())
    return fs.headland_m, fs.size_m[1] - fs.headland_m, 0.5 * fs.size_m[1]


def _inner_ring(fs: OperationSettings) -> np.ndarray:
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


def _plan_polygon(fs: OperationSettings) -> OperationPlan:
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
    inner = _inner_ring(fs)
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
    path = Path(pts[0][0], pts[0][1], heading0, segs, fs.speed_m_s, fs.turn_speed_m_s, ds_m=PATH_DS_M,
                extension_m=5.0)
    lo = min(a for a, _ in spans)
    hi = max(b for _, b in spans)
    return OperationPlan(path, roles, line_of, [float(y) for y in ys], (lo, hi), turns, fs, spans)


def plan_operation(fs: OperationSettings) -> OperationPlan:
    """The continuous path of an operation (module doc). Geometry only: :func:`check_plan` checks
    it against the vehicle and the soil."""
    Lx, Ly = fs.size_m
    w, R = fs.working_width_m, fs.turn_radius_m
    if w > min(Lx, Ly):
        raise ScenarioError(f"operation.working_width_m = {w:g} is outside the allowed range (0, {min(Lx, Ly):g}] m "
                            f"(the field is {Lx:g} m x {Ly:g} m)")
    if fs.boundary is not None:
        return _plan_polygon(fs)
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
    path = Path(pts[0][0], pts[0][1], 0.0, segs, fs.speed_m_s, fs.turn_speed_m_s, ds_m=PATH_DS_M, extension_m=5.0)
    return OperationPlan(path, roles, line_of, [float(y) for y in ys], (H, Lx - H), turns, fs)


def _sample_roles(plan: OperationPlan) -> np.ndarray:
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


def swath_mask(plan: OperationPlan, shape, cell_m: float) -> np.ndarray:
    """The cells (nx, ny) bool whose centres the implement's swath covers: the worked lines
    (between the headlands) and the headland rounds, each ``working_width_m`` wide about the path
    (a raster of the plan, for the coverage check)."""
    fs = plan.settings
    roles = _sample_roles(plan)
    keep = (roles == 3) | (roles == 0)
    return _sweep(plan.path.x[keep], plan.path.y[keep], plan.path.psi[keep], shape, cell_m,
                  [(0.0, PATH_DS_M, 0.5 * fs.working_width_m)], overlap=False)


def footprint_mask(x, y, psi, params: dict, shape, cell_m: float) -> np.ndarray:
    """The cells (nx, ny) bool whose square overlaps a track's l x b contact rectangle at one of the
    poses (x, y, psi): an independent raster of the tracks' footprint (separating axes)."""
    rects, lateral = _track_rects(params)
    return _sweep(np.asarray(x, float), np.asarray(y, float), np.asarray(psi, float), shape, cell_m,
                  rects, lateral=lateral, overlap=True)


def _track_rects(params: dict):
    """The two tracks' contact rectangles in the body frame: [(centre ahead, half l, half b)], [lateral]."""
    half_l = 0.5 * params["contact_length_m"]
    half_b = 0.5 * params["track_width_m"]
    e = float(params["cg_ahead_of_contact_centre_m"])
    off = 0.5 * params["track_gauge_m"]
    return [(-e, half_l, half_b), (-e, half_l, half_b)], [off, -off]


def _sweep(x, y, psi, shape, cell_m, rects, lateral=None, overlap=True) -> np.ndarray:
    """Union over poses of body-frame rectangles (centre ahead c, half length, half width; centred
    ``lateral`` to the left): cells whose square overlaps (``overlap``) or whose centre is inside."""
    mask = np.zeros(shape, dtype=bool)
    for _, (i0, i1, j0, j1), inside in _sweep_windows(x, y, psi, shape, cell_m, rects, lateral, overlap):
        mask[i0:i1, j0:j1] |= inside
    return mask


def _sweep_windows(x, y, psi, shape, cell_m, rects, lateral=None, overlap=True):
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


# ---- the steering map and the follower -------------------------------------------------------------------
def _trim_model(model_opts):
    from ..model import SystemModel
    from ..model.options import ModelOptions

    law = model_opts.lateral_law
    # the lagged shear law's steady states are the quasi-static law's (docs/turning.md section 8)
    if law in ("shear", "shear_transient"):
        model_opts = dataclasses.replace(model_opts, lateral_law="shear_quasistatic")
    assert isinstance(model_opts, ModelOptions)
    return SystemModel(model_opts)


_MAP_CACHE: dict = {}


def steering_map(params: dict, model_opts, speeds_m_s, turn_radius_m: float, turn_speed_m_s: float) -> dict:
    """The steady torques of the vehicle on this soil: per speed, the curvatures of
    :data:`MAP_CURVATURES` (and the turn's) with their mean torque and torque difference
    (right - left) from trims. The turn's own trim must exist (else :class:`ScenarioError`: the
    radius cannot be held on this soil at this speed); curvatures a speed cannot hold are left out
    of its row. Cached per (params, law, speeds, radius) in the process."""
    key = (tuple(sorted(params.items())), model_opts, tuple(speeds_m_s), turn_radius_m, turn_speed_m_s)
    if key in _MAP_CACHE:
        return _MAP_CACHE[key]
    model = _trim_model(model_opts)
    try:
        tp = trim(model, params, turn_speed_m_s, turn_radius_m)
    except TrimError as err:
        raise ScenarioError(f"operation.turn_radius_m = {turn_radius_m:g} at operation.turn_speed_m_s = "
                            f"{turn_speed_m_s:g}: the vehicle cannot hold this turn on this soil ({err})") from err
    rows = {}
    for v in sorted(set(speeds_m_s)):
        ks, mean, diff, om_mean, om_diff = [], [], [], [], []
        # the turn's curvature and one 40 % tighter (room for the follower's corrections), where held
        for kappa in sorted(set(MAP_CURVATURES) | {1.0 / turn_radius_m, 1.4 / turn_radius_m}):
            if v > turn_speed_m_s + 1e-9 and kappa > 1.0 / 30 + 1e-12:
                continue  # a line's speed is not driven through tight curves
            try:
                # backwards (v < 0: a K-turn's reverse arc) the same yaw rate kappa |v| is a trim radius of -1/kappa
                t = tp if (v == turn_speed_m_s and kappa == 1.0 / turn_radius_m) else \
                    trim(model, params, v, None if kappa == 0 else math.copysign(1.0, v) / kappa)
            except TrimError as err:
                if v < 0 and kappa == 1.0 / turn_radius_m:
                    raise ScenarioError(f"operation.turn_radius_m = {turn_radius_m:g} at operation.turn_speed_m_s = "
                                        f"{turn_speed_m_s:g} backwards (a K-turn's reverse arc): the vehicle cannot "
                                        f"hold this turn on this soil ({err})") from err
                continue
            ks.append(kappa)
            mean.append(0.5 * float(t.u[0] + t.u[1]))
            diff.append(float(t.u[1] - t.u[0]))
            om_l, om_r = t.state("omega_left_rad_s"), t.state("omega_right_rad_s")
            om_mean.append(0.5 * (om_l + om_r))
            om_diff.append(om_r - om_l)
        rows[v] = (np.array(ks), np.array(mean), np.array(diff), np.array(om_mean), np.array(om_diff))
    _MAP_CACHE[key] = rows
    return rows


def _map_eval(rows: dict, v: float, kappa: float) -> tuple[float, float, float, float]:
    """Mean torque, torque difference, mean sprocket speed and speed difference (right - left) at
    speed v, curvature kappa (the differences odd in kappa), interpolated; v < 0 (backwards) from
    the rows of negative speeds."""
    speeds = sorted(s for s in rows if (s < 0) == (v < 0))  # backwards (v < 0): the reverse rows
    a = abs(kappa)

    def at(s):
        ks = rows[s][0]
        return np.array([float(np.interp(a, ks, col)) for col in rows[s][1:]])
    if v <= speeds[0] or len(speeds) == 1:
        out = at(speeds[0])
    elif v >= speeds[-1]:
        out = at(speeds[-1])
    else:
        i = int(np.searchsorted(speeds, v)) - 1
        f = (v - speeds[i]) / (speeds[i + 1] - speeds[i])
        out = at(speeds[i]) + f * (at(speeds[i + 1]) - at(speeds[i]))
    m, dd, om, dom = (float(z) for z in out)
    return m, math.copysign(dd, kappa), om, math.copysign(dom, kappa)


def _speed_profile(path: Path, creep_m_s: float) -> np.ndarray:
    """The followers' speed profile: the path's, limited by :data:`PLAN_ACCEL_M_S2` in deceleration before
    its slow parts and in acceleration after them (the line's speed asked for at once after a turn made
    the mean torque and the sprockets' speed references step, and the tracks spin: measured, the state
    diverged at the exit of a U-turn on the sandy loam); 0 at a K-turn's cusps (where the path's direction
    reverses: the vehicle stops there) with a creep floor of ``creep_m_s`` so that it gets there and
    starts back."""
    v = path.speed.copy()
    ds = np.diff(path.s)
    cusp_idx = np.searchsorted(path.s, path.cusps_s)
    v[cusp_idx] = 0.0
    for i in range(v.size - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * PLAN_ACCEL_M_S2 * ds[i]))
    for i in range(1, v.size):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * PLAN_ACCEL_M_S2 * ds[i - 1]))
    if cusp_idx.size:
        v = np.maximum(v, np.minimum(creep_m_s, path.speed))
    return v


def _map_stiffness(rows: dict, v: float) -> float:
    """The soil's steering stiffness at speed v: the steering map's torque difference per curvature at
    straight running (N m per 1/m: its first step, 0 to 1/400 1/m), interpolated in the speed; v < 0 from
    the reverse rows. Measured: 2.4e5 on the clay, 4.7e5 on the sandy loam (1 and 2.5 m/s)."""
    speeds = sorted(s for s in rows if (s < 0) == (v < 0))
    vals = []
    for sp in speeds:
        ks, diff = rows[sp][0], rows[sp][2]
        j = int(np.nonzero(ks > 0)[0][0])
        vals.append(float(diff[j] / ks[j]))
    return float(np.interp(v, speeds, vals))


class PathFollower:
    """The path-following torque law (a :class:`~symtrack.simulation.loop.SampledLaw`, sampled
    every ``sample_time_s``, held over the engine's macro steps):

    - kinematic outer loop: the yaw rate asked for, r_d = kappa v - (w_n^2 / v) e - 2 zeta w_n e_psi
      (e: lateral error, positive left of the path; e_psi: heading error), w_n = :attr:`OMEGA_N`,
      zeta = 1; kappa at a preview of :attr:`PREVIEW_S` ahead (the torque lag and the yaw response);
    - the torque difference (right - left): the steering map's at the path's curvature (the
      feed-forward), plus a PI law on the yaw rate, K_r (r_d - r) + K_i integral(r_d - r), both
      gains proportional to the soil's steering stiffness (the map's torque per curvature at straight
      running, twice as large on the sandy loam as on the clay) and to the speed above
      :attr:`GAIN_SPEED_M_S`; the integral is held in N m (a gain that grows with the speed does not
      scale what it learnt at a lower one) and limited to the map's torque at a curvature of
      :attr:`YAW_INTEGRAL_LIMIT_1_M`. The feedback stays in torque and is not passed through the
      map: the map is nearly a step at zero curvature (the turning resistance must be overcome
      before the vehicle yaws at all: on the clay 600 N m from 0 to 1/400 1/m, 380 N m from 1/12
      to 1/3 1/m), so a correction through it reverses the torques (measured: a bang-bang
      oscillation in the first headland corner);
    - a PI law on the speed for the mean torque, over the map's mean torque; the speed reference
      the path's, limited by :data:`PLAN_ACCEL_M_S2` in deceleration before its slow parts and in
      acceleration after them;
    - each sprocket's speed held to the steering map's trim speed at the same curvature,
      :attr:`SPROCKET_GAIN_N_M_S` per rad/s: in a tight turn the braked inner track's soil force is
      at its saturation (dF/dj ~ 0), so without it the sprocket's speed integrates the torque error
      (measured: it stuck at 0 and slipped, period 1 s; docs/studies.md).

    It ends the run (returns None) at the path's end, or when the lateral error exceeds
    ``max_lateral_error_m`` (``failure`` says so). The yaw gains: :attr:`YAW_GAIN_S_M`,
    :attr:`YAW_INTEGRAL_1_M` (chosen on the small operation on clay and sandy loam, docs/studies.md);
    the speed's r m / (2 :attr:`SPEED_TAU_S`) corrects a speed error
    in SPEED_TAU_S."""

    SAMPLE_TIME_S = 0.02  # measured: 0.05 s let the yaw loop oscillate in the headland corners
    OMEGA_N = 1.2  # 1/s: the lateral error's closing rate (0.8: RMS 0.17 / 0.22 m on the lines, clay / sandy loam)
    PREVIEW_S = 0.3
    WINDOW_S = 1.0  # the feed-forward's curvature: the path's averaged over this time at the speed (0: none)
    DIFF_SLEW_N_M_S = 1e9  # the torque difference's largest rate of change
    # the yaw-rate PI law in units of the soil's steering stiffness S (:func:`_map_stiffness`, N m per 1/m),
    # so that it is the same loop on every soil: K_r = YAW_GAIN_S_M S g (N m per rad/s), the integral
    # K_i = YAW_INTEGRAL_1_M S g (N m per rad), held in N m and limited to the torque of a curvature of
    # YAW_INTEGRAL_LIMIT_1_M (the map's error it is there to learn). ASSUMED, chosen on operation_small
    # (both soils; docs/studies.md): on the clay K_r = 13500 N m per rad/s at 1 m/s
    YAW_GAIN_S_M = 0.055
    YAW_INTEGRAL_1_M = 0.025
    YAW_INTEGRAL_LIMIT_1_M = 0.018
    GAIN_SPEED_M_S = 1.0  # the yaw gains grow with the speed above this
    RESET_INTEGRAL = False
    CORRECTION_CURVATURE_1_M = 1.0 / 150.0
    SPEED_TAU_S = 1.0
    # the sprockets' speed loop: N m per rad/s of sprocket speed below the steering map's (ASSUMED,
    # chosen on operation_small, both soils: K / J = 10 1/s, the torque lag's bandwidth; 600 gave the
    # same figures, 0 let the braked inner track stick and slip in the turns)
    SPROCKET_GAIN_N_M_S = 300.0
    # a K-turn's cusps: the cusp counts as reached this close to it (the speed profile is 0 there), and the
    # profile's floor about it (ASSUMED: a creep that reaches the cusp and starts back; chosen on the K-turn test)
    CUSP_TOL_M = 0.1
    CUSP_CREEP_M_S = 0.15

    def __init__(self, plan: OperationPlan, params: dict, rows: dict, state_names, sample_time_s: float,
                 substep_s: float, torque_limit_N_m: float, max_lateral_error_m: float):
        self.plan, self.path, self.rows = plan, plan.path, rows
        self.sample_time_s, self.substep_s = sample_time_s, substep_s
        self.limit, self.max_err = torque_limit_N_m, max_lateral_error_m
        idx = {n: i for i, n in enumerate(state_names)}
        self.ix, self.iy, self.ipsi = idx["x_m"], idx["y_m"], idx["yaw_rad"]
        self.iu, self.ir = idx["u_m_s"], idx["yaw_rate_rad_s"]
        self.iom = (idx["omega_left_rad_s"], idx["omega_right_rad_s"])
        r = params["sprocket_radius_m"]
        self.kp_v = r * params["mass_kg"] / (2 * self.SPEED_TAU_S)
        self.ki_v = self.kp_v / (2 * self.SPEED_TAU_S)
        self.int_r = self.int_v = 0.0
        self.segment = 0
        self.diff_prev = None
        self.s = 0.0
        self.roles = _sample_roles(plan)
        self.v_profile = _speed_profile(self.path, self.CUSP_CREEP_M_S)
        # the path between cusps: one direction each; the projection never crosses a cusp it has not reached
        self.phase_s = np.concatenate([[-np.inf], self.path.cusps_s, [np.inf]])
        self.phase_dir = [float(self.path.direction[min(int(np.searchsorted(self.path.s, a)), self.path.s.size - 1)])
                          for a in np.concatenate([[0.0], self.path.cusps_s])]
        self.phase = 0
        self.log = []  # (t, s, e_lat, e_psi, role)
        self.failure = None
        self.done = False
        # the law's signals per sample (a list to append to: the diagnosis of docs/studies.md), None: not kept
        self.trace = None

    @property
    def progress_fraction(self) -> float:
        """The share of the path driven (the run's progress bar: the time limit is 4 x the plan's)."""
        return min(self.s / max(self.path.length_m, 1e-9), 1.0)

    def _kappa(self, s: float, window_m: float) -> float:
        """The path's curvature averaged over [s - window/2, s + window/2] (exactly, piecewise constant)."""
        p = self.path
        lo, hi = s - 0.5 * window_m, s + 0.5 * window_m
        i0 = max(int(np.searchsorted(p.s, lo, side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(p.s, hi, side="right")), p.s.size - 1)
        if i1 <= i0 + 1:
            return float(p.kappa[i0])
        edges = np.clip(p.s[i0:i1 + 1], lo, hi)
        return float(np.sum(np.diff(edges) * p.kappa[i0:i1]) / max(hi - lo, 1e-9))

    def __call__(self, t_s, x, final=False):
        if final:
            return None
        X, Y, psi = float(x[self.ix]), float(x[self.iy]), float(x[self.ipsi])
        u, r = float(x[self.iu]), float(x[self.ir])
        lo, hi = self.phase_s[self.phase], self.phase_s[self.phase + 1]
        self.s = self.path.project(X, Y, self.s, window_m=(max(-1.0, lo - self.s), min(3.0, hi - self.s)))
        if self.s >= hi - self.CUSP_TOL_M:  # a cusp reached: on to the next direction
            self.phase += 1
            self.int_v = 0.0
        d = self.phase_dir[self.phase]
        e, e_psi = self.path.errors(X, Y, psi, self.s)
        i = min(int(np.searchsorted(self.path.s, self.s)), self.roles.size - 1)
        self.log.append((t_s, self.s, e, e_psi, int(self.roles[i])))
        if self.s >= self.path.length_m - 0.05:
            self.done = True
            return None
        if abs(e) > self.max_err:
            self.failure = (f"the vehicle left the path: lateral error {e:.2f} m at s = {self.s:.1f} m "
                            f"(t = {t_s:.1f} s) "
                            f"exceeds operation.max_lateral_error_m = {self.max_err:g}")
            return None
        v = max(abs(u), 0.3)
        ahead = min(self.s + v * self.PREVIEW_S, self.phase_s[self.phase + 1])  # not past a cusp
        kappa = self._kappa(ahead, max(v * self.WINDOW_S, 0.05))
        w = self.OMEGA_N
        # backwards (d = -1) de/dt = -v e_psi: the lateral term's sign turns so that e closes as forwards
        r_d = kappa * v - d * (w * w / v) * e - 2 * w * e_psi
        r_d = max(min(r_d, 0.8), -0.8)
        # the speed reference, ramped from the start
        v_ref = d * min(float(np.interp(self.s, self.path.s, self.v_profile)),
                        0.3 + PLAN_ACCEL_M_S2 * t_s)
        h = self.sample_time_s
        er, ev = r_d - r, v_ref - u
        # the yaw law's gains: the soil's steering stiffness at this speed times the law's own (class doc)
        g = max(v / self.GAIN_SPEED_M_S, 1.0)
        stiff = _map_stiffness(self.rows, v_ref)
        lim_i = stiff * self.YAW_INTEGRAL_LIMIT_1_M
        self.int_r = max(min(self.int_r + h * g * stiff * self.YAW_INTEGRAL_1_M * er, lim_i), -lim_i)
        self.int_v = max(min(self.int_v + h * ev, 2.0), -2.0)
        seg = int(self.path.segment[i])
        if self.RESET_INTEGRAL and seg != self.segment:  # a new segment: the integral learnt the last one's map error
            self.segment, self.int_r = seg, 0.0
        # the map at the path's curvature plus the correction's, the correction limited to
        # CORRECTION_CURVATURE_1_M: near straight running it overcomes the turning resistance's step
        # (the threshold a PI law alone would wait for: a stick-slip weave); in a turn, where the map is
        # flat, it moves the torques little (unlimited, it reversed them)
        corr = max(min(r_d / v - kappa, self.CORRECTION_CURVATURE_1_M), -self.CORRECTION_CURVATURE_1_M)
        mean_ff, diff, om_mean, om_diff = _map_eval(self.rows, v_ref, kappa + corr)
        diff_ff, int_r_now = diff, self.int_r
        diff += g * stiff * self.YAW_GAIN_S_M * er + self.int_r
        mean = mean_ff + self.kp_v * ev + self.ki_v * self.int_v
        if self.diff_prev is not None:
            step = self.DIFF_SLEW_N_M_S * h
            diff = min(max(diff, self.diff_prev - step), self.diff_prev + step)
        self.diff_prev = diff
        left, right = mean - 0.5 * diff, mean + 0.5 * diff
        if self.SPROCKET_GAIN_N_M_S:
            k = self.SPROCKET_GAIN_N_M_S
            left += k * (om_mean - 0.5 * om_diff - float(x[self.iom[0]]))
            right += k * (om_mean + 0.5 * om_diff - float(x[self.iom[1]]))
        lim = self.limit
        if self.trace is not None:
            self.trace.append((t_s, self.s, e, e_psi, r_d, r, kappa, diff_ff, diff, int_r_now, v_ref, u, mean_ff, mean,
                               om_mean - 0.5 * om_diff, om_mean + 0.5 * om_diff, float(x[self.iom[0]]),
                               float(x[self.iom[1]]), left, right, seg))
        return (max(min(left, lim), -lim), max(min(right, lim), -lim))


class MPCFollower:
    """The project's path-tracking MPC (:class:`symtrack.control.mpc.PathTrackingMPC`, real-time
    iteration on the scenario's lateral law, the settings of ``symtrack mpc --solver rti`` but
    :data:`OPERATION_RTI_STEP_HALVINGS`) as an operation's follower:
    :class:`symtrack.control.closedloop.TrackingLaw` sampled every ``mpc.sample_time_s`` (held over
    the engine's macro steps) on the operation's path, with the follower's bookkeeping of
    :class:`PathFollower` (``log``, ``s``, ``done``, ``failure``, ``progress_fraction``). The
    prediction's cells are those of steady straight running at the first line's speed (the grid
    plant carries no homogeneous cells), as ``symtrack mpc --plant grid`` has them."""

    def __init__(self, plan: OperationPlan, law, max_lateral_error_m: float):
        self.plan, self.path, self.law, self.max_err = plan, plan.path, law, max_lateral_error_m
        self.sample_time_s, self.substep_s = law.sample_time_s, law.substep_s
        self.roles = _sample_roles(plan)
        self.log, self.failure, self.done, self.s = [], None, False, 0.0

    @property
    def progress_fraction(self) -> float:
        return min(self.s / max(self.path.length_m, 1e-9), 1.0)

    def __call__(self, t_s, x, final=False):
        u = self.law(t_s, x, final)
        r = self.law.rows
        if final or not r["s"]:
            return u
        self.s, e, e_psi = r["s"][-1], r["e_lat"][-1], r["e_psi"][-1]
        i = min(int(np.searchsorted(self.path.s, self.s)), self.roles.size - 1)
        self.log.append((t_s, self.s, e, e_psi, int(self.roles[i])))
        if self.s >= self.path.length_m - 0.05 or u is None:
            self.done = self.s >= self.path.length_m - 0.05
            return None
        if abs(e) > self.max_err:
            self.failure = (f"the vehicle left the path: lateral error {e:.2f} m at s = {self.s:.1f} m "
                            f"(t = {t_s:.1f} s) exceeds operation.max_lateral_error_m = {self.max_err:g}")
            return None
        return u


def follower_of(fs: OperationSettings, plan: OperationPlan) -> str:
    """Who drives ``plan``: ``fs.follower``, or for "auto" the project's MPC ("rti": issue 23, the path follower
    is the MPC; measured on season_4ha: 0 failed solves of 71 935, RMS 1.9 mm on the lines, docs/studies.md)
    except on a plan with K-turns, whose reverse arcs the MPC's forward-only reference does not take ("law")."""
    if fs.follower != "auto":
        return fs.follower
    return "law" if plan.path.cusps_s.size else "rti"


def _mpc_follower(plan: OperationPlan, sc, plant, fs: OperationSettings, duration_s: float):
    """The :class:`MPCFollower` of an operation and the plant's start state (trim of straight running
    at the first segment's speed, placed at the path's start)."""
    model = system_model(sc.model, sc.surface)
    settings = MPCSettings(solver="rti", torque_max_N_m=fs.torque_limit_N_m,
                           rti_step_halvings=OPERATION_RTI_STEP_HALVINGS, rti_relinearisations=1,
                           rti_cold_start="shift")
    mpc = PathTrackingMPC(model, sc.params, settings)
    v0 = float(plan.path.speed[0])
    tp = trim(model, sc.params, v0)
    xv = tp.x[model.layout.block("vehicle")].copy()
    names = tuple(plant.state_names)
    if names != tuple(model.layout.vehicle_names):
        raise ScenarioError("operation.follower = \"rti\": the plant's state is not the vehicle's (the MPC reads it)")
    x0, y0, psi0 = plan.start
    for n, val in (("x_m", x0), ("y_m", y0), ("yaw_rad", psi0)):
        xv[names.index(n)] = val
    cells = tp.x[model.layout.block("cells")]
    # the MPC's reference at the followers' speed profile (the path's own steps from the lines' speed to
    # the turns')
    path = copy.copy(plan.path)
    path.speed = _speed_profile(plan.path, 0.0)
    path.speed[0] = v0
    # TrackingLaw reads the scenario's mpc settings, run.duration_s and name only
    view = _MPCView(fs.name, settings, duration_s)
    # the engine's macro step is the operation's run.output_dt_s (each 0.1 s sample held over them)
    law = TrackingLaw(view, mpc, path, names, tp.u.copy(), cells, sc.run.output_dt_s)
    return MPCFollower(plan, law, fs.max_lateral_error_m), loop.StartPoint(x0, y0, psi0, tp.u.copy(), xv), mpc


@dataclass(frozen=True)
class _RunView:
    duration_s: float


class _MPCView:
    """What :class:`~symtrack.control.closedloop.TrackingLaw` reads of an MPC scenario: name, mpc, run.duration_s."""

    def __init__(self, name: str, mpc: MPCSettings, duration_s: float):
        self.name, self.mpc, self.run = name, mpc, _RunView(duration_s)


# ---- the spec -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OperationSpec:
    """A validated operation or season: the operations in order (each its settings, its plan, the
    scenario of its vehicle on the field and its steering map), the traffic systems to compare,
    the resolved document."""

    name: str
    description: str
    operations: tuple  # of (OperationSettings, OperationPlan, Scenario, steering rows)
    compare: tuple
    document: dict
    base_doc: dict
    base: OperationSettings


def _scenario_doc(doc: dict, fs: OperationSettings) -> dict:
    run = dict(doc.get("run", {}))
    check_keys("run", run, OPERATION_RUN_KEYS)
    run.setdefault("integrator", "grid_fast")
    # 10 ms macro steps, one vehicle step each (the engine's error control halves where needed)
    run.setdefault("output_dt_s", 0.01)
    terrain = dict(doc.get("terrain", {}))
    for k in TERRAIN_KEYS_OF_OPERATION:
        if k in terrain:
            raise ScenarioError(f"terrain.{k} = {terrain[k]!r}: the [operation] section sets the field "
                                "(operation.size_m, operation.cell_m); leave it out of [terrain]")
    terrain.update(size_m=list(fs.size_m), cell_m=fs.cell_m, origin_m=[0.0, 0.0])
    terrain.setdefault("max_speed_m_s", max(4.0, fs.speed_m_s + 1.0))
    vehicle = {**doc.get("vehicle", {}), **fs.vehicle}
    out = {"name": doc.get("name", "operation"), "run": run, "vehicle": vehicle, "terrain": terrain,
           "torque": [{"t_s": 0.0, "left_N_m": 0.0, "right_N_m": 0.0}]}
    for k in ("model", "soil", "engine"):
        if k in doc:
            out[k] = dict(doc[k])
    return out


def _operation(doc: dict, fs: OperationSettings):
    sc = scenario_from_dict(_scenario_doc(doc, fs), fs.name)
    if sc.model.lateral_law == "creep":
        raise ScenarioError("model.lateral_law = \"creep\": the creep law holds no turn tighter than about 100 m on "
                            "these soils (docs/turning.md section 5); a field operation drives its headland turns on "
                            "the lagged shear law: set [model] lateral_law = \"shear\"")
    if sc.run.integrator != "grid_fast":
        raise ScenarioError(f"run.integrator = {sc.run.integrator!r}: a field operation runs on the terrain engine "
                            "(\"grid_fast\")")
    if fs.speed_m_s > sc.terrain.max_speed_m_s:
        raise ScenarioError(f"operation.speed_m_s = {fs.speed_m_s:g} is outside the allowed range (0, "
                            f"{sc.terrain.max_speed_m_s:g}] (terrain.max_speed_m_s, the speed the channel pool is "
                            "sized for)")
    half_gauge = 0.5 * float(sc.params["track_gauge_m"])
    if not fs.turn_radius_m > half_gauge:
        raise ScenarioError(f"operation.turn_radius_m = {fs.turn_radius_m:g} is outside the allowed range "
                            f"({half_gauge:g}, 100] m: a turn must be wider than half the track gauge (a tighter one "
                            "turns on the spot, without a steady forward speed)")
    if not fs.cell_m < sc.params["track_width_m"]:
        raise ScenarioError(f"operation.cell_m = {fs.cell_m:g} must be smaller than the track width "
                            f"{sc.params['track_width_m']:g} m")
    plan = plan_operation(fs)
    check_plan(plan, sc.params, sc.model)
    if fs.follower == "rti" and plan.path.cusps_s.size:
        raise ScenarioError("operation.follower = \"rti\" with operation.turn = \"k\": the MPC's reference "
                            "(control.path.Path.reference) and its prediction run forwards only, a K-turn's "
                            "reverse arc is not taken; use operation.follower = \"law\" or a \"u\" or \"bulb\" turn")
    speeds = (fs.turn_speed_m_s, fs.speed_m_s) + ((-fs.turn_speed_m_s,) if plan.path.cusps_s.size else ())
    rows = steering_map(sc.params, sc.model, speeds, fs.turn_radius_m, fs.turn_speed_m_s)
    return fs, plan, sc, rows


def operation_spec_from_dict(doc: dict, default_name: str = "operation", tracks: str | None = None) -> OperationSpec:
    """An operation (``[operation]``) or a season (``[operation]`` the defaults, ``[season]``
    ``operations`` a list of tables over them) -> :class:`OperationSpec`, every operation planned
    and checked (footprint in the field, the turn held on the soil) before any work. ``tracks``
    replaces every operation's track system (the traffic comparison)."""
    check_document("operation", doc, TOP_KEYS)
    if "operation" not in doc:
        raise ScenarioError("a field operation needs an [operation] section (docs/studies.md, \"Field operations\")")
    base = parse_operation(doc["operation"])
    season = doc.get("season", {})
    check_keys("season", season, SEASON_KEYS)
    entries = season.get("operations", [{}])
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ScenarioError(f"season.operations = {entries!r} must be a non-empty list of tables of [operation] keys")
    compare = season.get("compare", ())
    if not isinstance(compare, (list, tuple)):
        raise ScenarioError(f"season.compare = {compare!r} must be a list of track systems ({', '.join(TRACKS)})")
    compare = tuple(compare)
    for c in compare:
        if c not in TRACKS:
            raise ScenarioError(f"season.compare = {list(compare)!r}: {c!r} is not one of {', '.join(TRACKS)}")
    if "tracks" in season:  # every operation under one system: a case of the comparison (traffic_sweep)
        if season["tracks"] not in TRACKS:
            raise ScenarioError(f"season.tracks = {season['tracks']!r} is not one of {', '.join(TRACKS)}")
        if tracks is None:
            tracks = season["tracks"]
        compare = ()
    ops = []
    for k, e in enumerate(entries):
        fs = parse_operation(e, base, where=f"season.operations[{k}]")
        if fs.size_m != base.size_m or fs.cell_m != base.cell_m or fs.boundary != base.boundary:
            raise ScenarioError(f"season.operations[{k}]: size_m, cell_m and boundary_file are the field's: set them "
                                "in [operation]")
        if tracks is not None:
            fs = dataclasses.replace(fs, tracks=tracks)
        if "name" not in e:
            fs = dataclasses.replace(fs, name=f"{base.name}_{k + 1}" if len(entries) > 1 else base.name)
        try:
            ops.append(_operation(doc, fs))
        except ScenarioError as err:
            if "season" not in doc:
                raise
            raise ScenarioError(f"season.operations[{k}] ({fs.name!r}, over [operation]): {err}") from err
    names = [o[0].name for o in ops]
    if len(set(names)) != len(names):
        raise ScenarioError(f"season.operations: the names {names} must differ")
    return OperationSpec(doc.get("name", default_name), doc.get("description", ""), tuple(ops), compare, doc, doc,
                         base)


def load_operation_spec(name_or_path, overrides=None, tracks: str | None = None) -> OperationSpec:
    """A built-in operation or season (``symtrack/studies/fields/``) or a TOML file, with ``--set`` overrides."""
    doc, default_name = read_document(name_or_path, FIELD_PACKAGE, "field operation", overrides,
                                      paths=TERRAIN_PATH_KEYS + (("operation", "boundary_file"),))
    return operation_spec_from_dict(doc, default_name, tracks)


def is_operation_doc(doc) -> bool:
    """Whether a document is a field operation or a season (an [operation] or a [season] section;
    the latter without the former is then refused naming [operation])."""
    return isinstance(doc, dict) and ("operation" in doc or "season" in doc)


def is_operation_document(name_or_path) -> bool:
    """Whether a built-in name or TOML file is a field operation or a season (:func:`is_operation_doc`)."""
    try:
        doc, _ = read_document(name_or_path, FIELD_PACKAGE, "field study")
    except ScenarioError:
        return False
    return is_operation_doc(doc)


# ---- running it -----------------------------------------------------------------------------------------
@dataclass
class OperationResult:
    """One operation driven: its figures (summary), the passes per cell (nx, ny) uint16, the cells
    the engine stressed (nx, ny) bool, the follower's log, the terrain after it (shared, not copied)."""

    name: str
    figures: dict
    counts: np.ndarray
    stressed: np.ndarray
    log: np.ndarray
    trajectory: np.ndarray  # t, x, y, yaw every COUNT_SAMPLE_S
    error: str | None = None
    first_contact_s: np.ndarray | None = None  # (nx, ny) float32: when a track first came over the cell (inf: never)


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
    rects, lateral = _track_rects(params)
    traj = np.asarray(traj, dtype=float)
    # per pose, the window of each track (the work is local: a 4-million-cell field is not swept per pose)
    for k, (i0, i1, j0, j1), inside in _sweep_windows(traj[:, 1], traj[:, 2], traj[:, 3], shape, cell_m, rects,
                                                      lateral, overlap=True):
        t = traj[k, 0]
        lw = last[i0:i1, j0:j1]
        new = inside & (t - lw > PASS_GAP_S)
        counts[i0:i1, j0:j1][new] += 1
        fw = first[i0:i1, j0:j1]
        fw[inside & np.isinf(fw)] = t
        lw[inside] = t
    return counts, first


_MASK_CACHE: dict = {}  # a polygon field's cell masks (point-in-polygon over every cell: about 1 s at 4 million)


def _ring_mask(ring: np.ndarray, shape, cell_m: float) -> np.ndarray:
    key = (ring.tobytes(), tuple(shape), cell_m)
    if key not in _MASK_CACHE:
        if len(_MASK_CACHE) > 8:
            _MASK_CACHE.clear()
        _MASK_CACHE[key] = bnd.cell_mask(ring, shape, cell_m)
    return _MASK_CACHE[key]


def field_mask(fs: OperationSettings, shape, cell_m: float) -> np.ndarray:
    """The grid's cells (nx, ny) that are the field: all of them on a rectangle, those whose centre
    is inside the boundary on a polygon field."""
    if fs.boundary is None:
        return np.ones(shape, dtype=bool)
    return _ring_mask(np.array(fs.boundary), shape, cell_m).copy()


def _headland_mask(fs: OperationSettings, shape, cell_m: float) -> np.ndarray:
    if fs.boundary is not None:  # the field's cells outside the in-field ring
        return field_mask(fs, shape, cell_m) & ~_ring_mask(_inner_ring(fs), shape, cell_m)
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
    head = _headland_mask(fs, stressed.shape, fs.cell_m)
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


def run_operation(op, plant, progress: bool = False) -> OperationResult:
    """Drive one planned operation ((settings, plan, scenario, steering rows)) on a plant (not started)
    from its set-down to its lift-off. The terrain is the plant's world's storage, advanced in place."""
    fs, plan, sc, rows = op
    world = plant.world
    shape, cell = world.grid.shape, world.grid.cell_m
    # the time limit: the path at a quarter of its speeds
    limit = 4.0 * float(np.sum(np.diff(plan.path.s) / np.maximum(plan.path.speed[:-1], 0.1))) + 60.0
    run_sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=limit))
    x0, y0, psi0 = plan.start
    mpc = None
    follower = follower_of(fs, plan)
    if follower == "rti":
        law, start, mpc = _mpc_follower(plan, sc, plant, fs, limit)
    else:
        law = PathFollower(plan, sc.params, rows, plant.state_names, PathFollower.SAMPLE_TIME_S, sc.run.output_dt_s,
                           fs.torque_limit_N_m, fs.max_lateral_error_m)
        start = loop.StartPoint(x0, y0, psi0, np.zeros(2))
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    error = None
    try:
        res = loop.run(run_sc, plant, progress=progress, label=f"operation {fs.name}", torque_law=law,
                       start=start)
    except loop.IncompleteRun as err:
        res, error = err.partial, str(err)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    if law.failure:
        error = law.failure
    elif error is None and not law.done:
        error = f"the operation did not reach the path's end in {limit:.0f} s of simulated time"
    names = plant.state_names
    X = res.X
    ix, iy, ipsi = names.index("x_m"), names.index("y_m"), names.index("yaw_rad")
    every = max(1, int(round(COUNT_SAMPLE_S / sc.run.output_dt_s)))
    traj = np.column_stack([res.t, X[:, ix], X[:, iy], X[:, ipsi]])[::every]
    t_count = time.perf_counter()
    counts, first = count_passes_and_times(traj, sc.params, shape, cell)
    count_s = time.perf_counter() - t_count
    stressed = (world.storage.sigma_max[:, 0] > 0).reshape(shape) if world.storage.subsoil_depths_m else \
        (world.storage.z != 0).reshape(shape)
    log = np.array(law.log) if law.log else np.zeros((0, 5))
    dt = np.diff(res.t)
    om = [names.index(f"omega_{k}_rad_s") for k in ("left", "right")]
    tq = [names.index(f"torque_{k}_N_m") for k in ("left", "right")]
    power = X[:-1, tq[0]] * X[:-1, om[0]] + X[:-1, tq[1]] * X[:-1, om[1]]
    yn = res.output_names
    comp = res.Y[:-1, yn.index("compaction_power_W")] if "compaction_power_W" in yn else None
    lines = log[log[:, 4] == 3] if log.size else log
    turns = log[log[:, 4] == 1] if log.size else log
    dist = float(np.sum(np.hypot(np.diff(X[:, ix]), np.diff(X[:, iy]))))
    turns_done = plan.turns if error is None else sum(
        1 for k in range(plan.turns) if _turn_end_s(plan, k) <= law.s)
    fig = {"name": fs.name, "complete": error is None, "error": error, "tracks": fs.tracks, "turn": fs.turn,
           "working_width_m": fs.working_width_m, "headland_passes": fs.headland_passes,
           "headland_width_m": fs.headland_m, "turn_radius_m": fs.turn_radius_m, "lines": len(plan.line_y_m),
           "line_y_m": plan.line_y_m, "turns_planned": plan.turns, "turns_driven": turns_done, "turns_lifted": 0,
           "path_length_m": plan.path.length_m, "distance_m": dist, "sim_time_s": float(res.t[-1]),
           "energy_sprockets_J": float(np.sum(power * dt)),
           "energy_compaction_J": float(np.sum(comp * dt)) if comp is not None else None,
           "rms_lateral_error_lines_m": float(np.sqrt(np.mean(lines[:, 2] ** 2))) if lines.size else None,
           "max_lateral_error_lines_m": float(np.abs(lines[:, 2]).max()) if lines.size else None,
           "rms_lateral_error_turns_m": float(np.sqrt(np.mean(turns[:, 2] ** 2))) if turns.size else None,
           "rms_lateral_error_all_m": float(np.sqrt(np.mean(log[:, 2] ** 2))) if log.size else None,
           "wall_time_s": wall, "cpu_time_s": cpu, "pass_count_wall_time_s": count_s,
           "x_real_time_wall": float(res.t[-1]) / wall if wall > 0 else None,
           "rut_max_depth_mm": 1e3 * float(world.storage.z.max()),
           "rut_mean_depth_mm": 1e3 * float(world.storage.z[stressed.ravel()].mean()) if stressed.any() else 0.0,
           "vehicle_mass_kg": sc.params["mass_kg"],
           # the engine's vehicle steps and how many its error control halved (EngineSettings.vehicle_tolerance)
           "vehicle_steps": int(res.stats.get("n_vehicle_steps", 0)),
           "vehicle_steps_halved": int(res.stats.get("n_vehicle_halved", 0))}
    fig["follower"] = follower
    if mpc is not None:  # the MPC's solves (closedloop.summarise's figures)
        ms = mpc.stats.solve_times_ms() if mpc.stats.solves else np.array([np.nan])
        fig.update(solves=len(mpc.stats.solves), failed_solves=int(mpc.stats.failed),
                   fallback_solves=int(mpc.stats.fallbacks), solve_time_median_ms=float(np.median(ms)),
                   solve_time_p95_ms=float(np.percentile(ms, 95)), solve_time_max_ms=float(np.max(ms)))
    # this operation's own stressed cells (pass_sigma of its one engine pass)
    own = (world.pass_sigma[:, 0] > 0).reshape(shape) if world.storage.subsoil_depths_m else stressed
    fig["operation_trafficked_fraction"] = float(own.mean())
    fig.update({f"operation_{k}": v for k, v in field_shares(own, counts, fs).items()
                if k in ("headland_trafficked_fraction", "infield_trafficked_fraction")})
    return OperationResult(fs.name, fig, counts, own, log, traj, error, first)


def _turn_end_s(plan: OperationPlan, k: int) -> float:
    """The arc length at the end of the k-th turn."""
    idx = [i for i, r in enumerate(plan.roles) if r == "turn"]
    # turns are runs of consecutive "turn" segments
    groups, cur = [], []
    for i in idx:
        if cur and i != cur[-1] + 1:
            groups.append(cur)
            cur = []
        cur.append(i)
    if cur:
        groups.append(cur)
    last = groups[k][-1]
    return float(plan.path.s[np.nonzero(plan.path.segment == last)[0][-1] + 1])


@dataclass
class SeasonResult:
    spec: OperationSpec
    operations: list
    summary: dict
    counts: np.ndarray
    terrain: Terrain
    written: list


def _map_pngs(counts, z, fs: OperationSettings, label: str) -> dict:
    from . import field_plots

    ext = (0.0, fs.size_m[0], 0.0, fs.size_m[1])
    return {"passes_map.png": field_plots.passes_map_png(counts, ext, f"passes per cell: {label}"),
            "rut_map.png": field_plots.sinkage_map_png(z, ext, f"rut depth: {label}")}


def _animation(r: OperationResult, terrain: Terrain, fs: OperationSettings, label: str, progress: bool) -> bytes:
    """The operation's GIF over the rut map (:func:`symtrack.studies.field_plots.operation_gif`), with progress."""
    from ..foundations.progress import Progress
    from . import field_plots

    bar = Progress(1.0, f"animation {fs.name}", enabled=progress)
    gif = field_plots.operation_gif(terrain.z.reshape(r.counts.shape), r.first_contact_s, r.trajectory,
                                    (0.0, fs.size_m[0], 0.0, fs.size_m[1]), label,
                                    progress=lambda k, n: bar.update(k / n, f"frame {k}/{n}"))
    bar.close()
    return gif


def _season_report(spec, summary: dict, files: dict, results) -> str:
    """report.html of an operation or a season: what ran, each operation's scalar figures, the season's
    maps (the animation is its own file), the resolved run file."""
    from ..reports.html import report_html

    images = {n: d for n, d in files.items() if n.endswith(".png") and "/" not in n}
    names = [r.figures.get("name", f"operation {k + 1}") for k, r in enumerate(results)]
    keys = [k for k, v in results[0].figures.items() if isinstance(v, (bool, int, float, str))] if results else []
    rows = [[k, *(r.figures.get(k) for r in results)] for k in keys]
    note = (f"'{spec.name}': {len(results)} operation(s), {summary.get('turns_driven', 0)} turns driven; "
            f"{'complete' if summary.get('complete') else 'incomplete: ' + str(summary.get('error'))}."
            + (f" The animation: {summary['animation_gif']}." if summary.get("animation_gif") else ""))
    return report_html(f"symtrack field: {spec.name}", summary, images, files["operation.resolved.toml"], note=note,
                       tables={"Operations": (["figure", *map(str, names)], rows)} if results else None)


def _counts_npz(counts, cell_m) -> bytes:
    return npz_bytes(kind=np.array("symtrack-field-passes"), schema_version=np.array(SCHEMA_VERSION),
                     origin_m=np.zeros(2), cell_m=np.array(cell_m), shape=np.array(counts.shape), passes=counts)


def run_season(spec: OperationSpec, out=None, *, progress: bool = False, through_files: bool = True,
               figures: bool = True) -> SeasonResult:
    """Drive every operation of ``spec`` in order on one persistent field. Between two operations
    the field is saved (``<op>/field.npz``) and, with ``through_files``, the next operation starts from
    the file read back (the persistence a season depends on, tested bit for bit); an operation with
    another vehicle gets a plant of its own on the same field. Writes ``out`` (docs/studies.md)."""
    import tempfile

    folder = check_output_folder(str(out)) if out is not None else None
    t_start = time.perf_counter()
    terrain = None
    results, files = [], {}
    total = None
    build_s = 0.0
    tmp = tempfile.TemporaryDirectory(prefix="symtrack-season-") if folder is None and through_files else None
    try:
        for k, op in enumerate(spec.operations):
            fs, plan, sc, rows = op
            tb = time.perf_counter()
            plant = make_plant(sc, terrain=terrain)
            build_s += time.perf_counter() - tb
            r = run_operation(op, plant, progress=progress)
            terrain = plant.world.storage
            results.append(r)
            total = r.counts.astype(np.uint32) if total is None else total + r.counts
            label = f"{fs.name} ({fs.tracks}, {fs.working_width_m:g} m)"
            sub = f"{k + 1:02d}_{fs.name}"
            if folder is not None:
                op_files = {f"{sub}/summary.json": json.dumps(r.figures, indent=2) + "\n",
                            f"{sub}/passes_per_cell.npz": _counts_npz(r.counts, fs.cell_m)}
                if figures:
                    op_files |= {f"{sub}/{n}": b for n, b in
                                 _map_pngs(r.counts, terrain.z.reshape(r.counts.shape), fs, label).items()}
                    op_files[f"{sub}/animation.gif"] = _animation(r, terrain, fs, label, progress)
                    if k == 0:
                        op_files["animation.gif"] = op_files[f"{sub}/animation.gif"]
                files |= op_files
            if r.error:
                break
            if through_files and k + 1 < len(spec.operations):
                path = (folder / sub / "field.npz") if folder is not None else Path_(tmp.name) / f"{sub}.npz"
                path.parent.mkdir(parents=True, exist_ok=True)
                terrain.save(path, run={"run_id": f"{spec.name}-{k + 1}", "scenario": fs.name, "passes": 1,
                                        "scenario_sha256": "", "time_utc": ""})
                terrain = Terrain.load(path, sc.params)
    finally:
        if tmp is not None:
            tmp.cleanup()
    fs0 = spec.base
    counts = np.minimum(total, np.iinfo(np.uint16).max).astype(np.uint16)
    stressed = (terrain.sigma_max[:, 0] > 0).reshape(counts.shape) if terrain.subsoil_depths_m else \
        (terrain.z != 0).reshape(counts.shape)
    summary = {"schema_version": SCHEMA_VERSION, "kind": "symtrack-field-operations", "name": spec.name,
               "description": spec.description, "complete": all(r.error is None for r in results)
               and len(results) == len(spec.operations),
               "error": next((r.error for r in results if r.error), None),
               "operations_run": [r.name for r in results], "field_size_m": list(fs0.size_m),
               "field_cell_m": fs0.cell_m,
               "field_cells": int(counts.size),
               **field_shares(stressed, counts, fs0),
               "turns_driven": sum(r.figures["turns_driven"] for r in results), "turns_lifted": 0,
               "sim_time_s": sum(r.figures["sim_time_s"] for r in results),
               "distance_m": sum(r.figures["distance_m"] for r in results),
               "energy_sprockets_J": sum(r.figures["energy_sprockets_J"] for r in results),
               "energy_compaction_J": sum(r.figures["energy_compaction_J"] or 0.0 for r in results),
               "rms_lateral_error_lines_m": _rms_of(results, 3), "rms_lateral_error_turns_m": _rms_of(results, 1),
               "max_lateral_error_lines_m": max((r.figures["max_lateral_error_lines_m"] or 0.0) for r in results),
               "rut_max_depth_mm": 1e3 * float(terrain.z.max()),
               "build_s": build_s, "drive_wall_time_s": sum(r.figures["wall_time_s"] for r in results),
               "wall_time_s": time.perf_counter() - t_start,
               "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
               "trafficked_note": "trafficked_fraction: the cells the engine stressed over the season (sigma_max > 0 "
                                  "at the first subsoil depth: a track's contact overlapped them); passes per cell: "
                                  "the driven poses' footprints (a new pass after 1 s out of every contact)",
               "animation_gif": "animation.gif" if (folder is not None and figures and results) else None,
               "operations": [r.figures for r in results]}
    written = []
    if folder is not None:
        files["operation.resolved.toml"] = to_toml(spec.document)
        files["passes_per_cell.npz"] = _counts_npz(counts, fs0.cell_m)
        if figures:
            files |= _map_pngs(counts, terrain.z.reshape(counts.shape), fs0, f"{spec.name}, {len(results)} operations")
        files["report.html"] = _season_report(spec, summary, files, results).encode()
        files["summary.json"] = json.dumps(summary, indent=2) + "\n"
        from ..reports.run_files import write_folder

        written = write_folder(folder, files, clear=False)
        terrain.save(folder / "field.npz")
        written.append(folder / "field.npz")
    return SeasonResult(spec, results, summary, counts, terrain, written)


def _rms_of(results, role: int):
    parts = [r.log[r.log[:, 4] == role, 2] for r in results if r.log.size]
    e = np.concatenate(parts) if parts else np.zeros(0)
    return float(np.sqrt(np.mean(e ** 2))) if e.size else None


def Path_(p):
    from pathlib import Path as _P

    return _P(p)


TRAFFIC_COLUMNS = ("tracks", "complete", "trafficked_fraction", "headland_trafficked_fraction",
                   "infield_trafficked_fraction",
                   "area_run_over_once_m2", "area_run_over_twice_m2", "area_run_over_3_or_more_m2",
                   "repeated_coverage_fraction", "rut_max_depth_mm", "distance_m", "sim_time_s", "energy_sprockets_J",
                   "turns_driven", "turns_lifted", "rms_lateral_error_lines_m", "wall_time_s")


def traffic_row(system: str, summary: dict | None) -> dict:
    """A row of the traffic table (:data:`TRAFFIC_COLUMNS`) from a system's season summary (None:
    the season did not finish: complete false, the figures empty)."""
    summary = summary or {"complete": False}
    return {"tracks": system, **{k: summary.get(k) for k in TRAFFIC_COLUMNS if k != "tracks"}}


def traffic_files(rows) -> dict:
    """The comparison's table and figure: ``traffic.csv``, ``traffic.png``, ``traffic.json``."""
    import csv

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TRAFFIC_COLUMNS)
    for r in rows:
        w.writerow(["" if r[c] is None else r[c] for c in TRAFFIC_COLUMNS])
    return {"traffic.csv": buf.getvalue(), "traffic.png": _traffic_png(rows),
            "traffic.json": json.dumps(rows, indent=2) + "\n"}


def traffic_comparison(doc: dict, systems, out=None, progress: bool = False, name: str = "operation") -> dict:
    """The same season under each traffic system of ``systems`` (e.g. ("random", "controlled")), each
    on a new field, one after another in this process: one table (``traffic.csv``, a row per system)
    and one figure (``traffic.png``). :func:`symtrack.studies.traffic.traffic_sweep` runs the same
    comparison as a resumable sweep on Dask."""
    rows = []
    folder = check_output_folder(str(out)) if out is not None else None
    # every system's season planned and checked before any runs
    specs = [(sys_, operation_spec_from_dict(doc, name, tracks=sys_)) for sys_ in systems]
    for sys_, spec in specs:
        res = run_season(spec, None if folder is None else folder / sys_, progress=progress)
        rows.append(traffic_row(sys_, res.summary))
    if folder is not None:
        from ..reports.run_files import write_folder

        write_folder(folder, traffic_files(rows), clear=False)
    return {"rows": rows}


def _traffic_png(rows) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [("trafficked_fraction", "trafficked (whole field)"), ("infield_trafficked_fraction", "in-field"),
            ("headland_trafficked_fraction", "headland"), ("repeated_coverage_fraction", "repeated coverage")]
    fig, ax = plt.subplots(figsize=(7.0, 3.6))
    n = len(rows)
    width = 0.8 / n
    for i, r in enumerate(rows):
        ax.bar(np.arange(len(keys)) + i * width, [r[k] or 0.0 for k, _ in keys], width, label=r["tracks"])
    # Kroulik et al. 2009 (Soil & Tillage Research): the share run over at least once in their DGPS-logged seasons
    for share, lab, ls in ((0.953, "Kroulik 2009: conventional 95.3 %", "-"), (0.728, "minimum tillage 72.8 %", "--"),
                           (0.557, "direct seeding 55.7 %", ":")):
        ax.hlines(share, -0.5 * width, 0.8 - 0.5 * width, colors="k", linestyles=ls, linewidth=1.0, label=lab)
    ax.set_xticks(np.arange(len(keys)) + 0.4 - width / 2, [lab for _, lab in keys])
    ax.set_ylabel("share of the area")
    ax.legend(fontsize=7)
    ax.set_title("traffic systems: the same season on new fields")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()
