"""An operation's settings: the ``[operation]`` section's keys, their ranges and defaults (:class:`OperationSettings`,
:func:`parse_operation`), and the constants of the operations.

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ...control.mpc import MPCSettings
from ...foundations.config import check_keys, integer, list_hint, number
from ...foundations.errors import ScenarioError
from ...simulation.scenario import SIMULATION_RUN_KEYS
from ..boundary import read_boundary

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
# (an operation draws its own figures: the run folder's switch is not one of its keys)
OPERATION_RUN_KEYS = tuple(k for k in SIMULATION_RUN_KEYS
                           if k not in ("stop_after_distance_m", "stop_distance_event", "figures"))
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
            raise ScenarioError(f"{where}.size_m = {size!r} must be a pair [x, y] of lengths in m"
                                f"{list_hint(f'{where}.size_m', size)}")
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
