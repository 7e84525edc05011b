"""Field operations driven end to end (docs/studies.md, "Field operations").

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

from .followers import MPCFollower, PathFollower, follower_of, mpc_follower, steering_map
from .footprints import (
    check_plan,
    count_passes,
    count_passes_and_times,
    field_mask,
    field_shares,
    footprint_mask,
    headland_mask,
    swath_mask,
    sweep_windows,
    track_rects,
)
from .outputs import (
    TRAFFIC_COLUMNS,
    OperationResult,
    TrafficComparison,
    animation,
    counts_npz,
    map_pngs,
    traffic_files,
    traffic_row,
)
from .plans import (
    MAX_TRACK_LINES,
    OperationPlan,
    inner_ring,
    k_turn_angles_deg,
    k_turn_headland_m,
    lane_positions_m,
    line_positions_m,
    plan_operation,
    sample_roles,
)
from .season import Path_, SeasonResult, run_operation, run_season, traffic_comparison
from .settings import (
    COUNT_SAMPLE_S,
    FIELD_PACKAGE,
    FOLLOWERS,
    MAP_CURVATURES,
    OPERATION_KEYS,
    OPERATION_RTI_STEP_HALVINGS,
    OPERATION_RUN_KEYS,
    PASS_GAP_S,
    PATH_DS_M,
    PLAN_ACCEL_M_S2,
    SCHEMA_VERSION,
    SEASON_KEYS,
    TERRAIN_KEYS_OF_OPERATION,
    TOP_KEYS,
    TRACKS,
    TURNS,
    OperationSettings,
    parse_operation,
)
from .spec import (
    OperationSpec,
    is_operation_doc,
    is_operation_document,
    load_operation_spec,
    operation_of,
    operation_spec_from_dict,
)

__all__ = ["COUNT_SAMPLE_S", "FIELD_PACKAGE", "FOLLOWERS", "MAP_CURVATURES", "MAX_TRACK_LINES", "MPCFollower",
           "OPERATION_KEYS", "OPERATION_RTI_STEP_HALVINGS", "OPERATION_RUN_KEYS", "OperationPlan", "OperationResult",
           "OperationSettings", "OperationSpec", "PASS_GAP_S", "PATH_DS_M", "PLAN_ACCEL_M_S2", "PathFollower", "Path_",
           "SCHEMA_VERSION", "SEASON_KEYS", "SeasonResult", "TERRAIN_KEYS_OF_OPERATION", "TOP_KEYS", "TRACKS",
           "TRAFFIC_COLUMNS", "TURNS", "TrafficComparison", "animation", "check_plan", "count_passes",
           "count_passes_and_times",
           "counts_npz", "field_mask", "field_shares", "follower_of", "footprint_mask", "headland_mask", "inner_ring",
           "is_operation_doc", "is_operation_document", "k_turn_angles_deg", "k_turn_headland_m", "lane_positions_m",
           "line_positions_m", "load_operation_spec", "map_pngs", "mpc_follower", "operation_of",
           "operation_spec_from_dict", "parse_operation", "plan_operation", "run_operation", "run_season",
           "sample_roles", "steering_map", "swath_mask", "sweep_windows", "track_rects", "traffic_comparison",
           "traffic_files", "traffic_row"]
