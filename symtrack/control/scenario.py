"""MPC path-tracking scenarios: TOML files validated on load (built-in ones in
``symtrack/control/scenarios/``).

Schema (unknown keys are errors; ranges in brackets)::

    name = "straight_offset"          # defaults to the file name
    description = "..."
    [vehicle]
    preset = "reference_crawler"      # any vehicle parameter may follow as an override
    [soil]
    preset = "sandy_loam_15"          # any soil parameter may follow as an override
    [start]                           # the vehicle starts in steady straight running (trim)
    x_m = 0.0                         # [-1e6, 1e6]
    y_m = 1.0                         # [-1e6, 1e6]
    yaw_deg = 0.0                     # [-360, 360]
    speed_m_s = 2.0                   # [0.1, 10]
    [path]
    x_m = 0.0                         # start pose of the path
    y_m = 0.0
    heading_deg = 0.0
    speed_m_s = 2.0                   # [0.1, 10] reference speed on straights
    turn_speed_m_s = 1.5              # [0.1, 10] reference speed on arcs (default: speed_m_s)
    kind = "segments"                 # segments | field
    # kind = "segments": a list of segments
    segments = [{straight_m = 40.0}, {arc_radius_m = 5.0, angle_deg = 180.0}]
    # kind = "field": parallel passes joined by headland U-turns of radius spacing_m / 2
    passes = 4                        # [1, 100]
    pass_length_m = 40.0              # [1, 1e4]
    spacing_m = 8.0                   # [1, 100]
    first_turn = "left"               # left | right
    [run]
    integrator = "cvodes"             # plant integrator: homogeneous plant cvodes | idas; grid plant
                                      # grid_fast (the terrain engine; also what cvodes means there)
                                      # | idas (the reference) | rosenbrock
    duration_s = 120.0                # (0, 1e5] time limit; the run ends at the path's end
    rms_exclude_first_m = 0.0         # [0, 1e6] path length at the start left out of the RMS
                                      # (the approach from an initial offset)
    output_dt_s = 0.01                # the terrain engine's macro step (grid plant, grid_fast);
                                      # the MPC sample is split into steps no longer than this
    [mpc]                             # any field of symtrack.control.mpc.MPCSettings
    horizon_steps = 20
    sample_time_s = 0.1
    solver = "rti"                    # rti (default) | ipopt | fatrop
    [model]                           # optional: any field of symtrack.model.options.ModelOptions,
    lateral_law = "creep"             # for the plant and the prediction (docs/turning.md; default:
                                      # "shear", the soil's own strength)
    [terrain]                         # optional: the plant is then the vehicle on the persistent
    cell_m = 0.25                     # grid terrain (MPCScenario.plant_setup); keys
                                      # and ranges of symtrack/terrain/settings.py (docs/terrain.md).
                                      # Without size_m and origin_m the field covers the path
                                      # plus 4 m; passes must be 1; the plant runs the terrain
                                      # engine unless run.integrator is idas or rosenbrock.
    [engine]                          # optional: the terrain engine's scheme (grid plant, grid_fast;
    vehicle_substeps = 4              # symtrack.integrators.settings.EngineSettings; the shear
                                      # law needs 0.5 ms vehicle steps: with output_dt_s = 0.002,
                                      # vehicle_substeps = 4; docs/turning.md)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ..foundations.config import builtin_names as _package_names
from ..foundations.config import check_document, check_keys, integer, number, read_document, with_version
from ..foundations.errors import ParameterError, ScenarioError
from ..integrators.grid_rosenbrock import MAX_STEP_S
from ..integrators.settings import EngineSettings, IntegratorSettings
from ..model import plausibility
from ..model.options import ModelOptions, scenario_keys
from ..model.parameters import known_soil_names, soil_params, vehicle_params
from ..presets import soil_preset, vehicle_preset
from ..simulation.scenario import PlantSetup, RunSettings, parse_engine, parse_ground, parse_params, parse_run
from ..terrain.settings import PATH_KEYS as TERRAIN_PATH_KEYS
from ..terrain.settings import TerrainSettings
from ..terrain.surface import Surface
from .mpc import MPCSettings
from .path import Path as RefPath
from .path import Segment, field_segments

__all__ = ["FIELD_MARGIN_M", "GRID_ABSTOL", "GRID_DEFAULT_TERRAIN", "GRID_RELTOL", "GRID_SUBSTEP_S", "MPCScenario",
           "MPC_RUN_DEFAULTS", "MPC_RUN_KEYS", "SCENARIO_PACKAGE", "StartSettings", "TOP_KEYS", "builtin_names",
           "field_from_path", "grid_integrator", "load", "scenario_from_dict"]

TOP_KEYS = ("name", "description", "vehicle", "soil", "start", "path", "run", "mpc", "model", "terrain", "engine")
SCENARIO_PACKAGE = "symtrack.control.scenarios"
# the [terrain] section that plant="grid" (symtrack mpc --plant grid) adds to a scenario without one:
# 0.25 m cells (the track is 0.45 m wide) and a speed bound of 4 m/s for the channel modulus M
# keep a closed loop of a minute or two affordable (docs/control.md); the field covers the path
GRID_DEFAULT_TERRAIN = {"cell_m": 0.25, "max_speed_m_s": 4.0}
# IDAS tolerances of the grid plant: those of `symtrack simulate validation_grid` (docs/terrain.md:
# every validation figure equal to 3 digits against 1e-7 / 1e-9, in half the time)
GRID_RELTOL = 1e-5
GRID_ABSTOL = 1e-8
# the grid plant's macro step (the world manager's step: footprint prediction, release) with IDAS or
# the compiled Rosenbrock; the MPC's sample is split into macro steps no longer than this. The terrain
# engine's macro step is its integration step, run.output_dt_s (default 0.01 s, the step its accuracy
# was measured at: docs/terrain.md, "The terrain engine"; the shear law needs 2 ms: docs/turning.md)
GRID_SUBSTEP_S = 0.02
# margin around the reference path when the field is sized from it
FIELD_MARGIN_M = 4.0


@dataclass(frozen=True)
class StartSettings:
    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = 0.0
    speed_m_s: float = 2.0


# the [run] keys of an MPC scenario (symtrack.simulation.scenario.RunSettings) and their defaults
MPC_RUN_KEYS = ("integrator", "duration_s", "rms_exclude_first_m", "output_dt_s")
MPC_RUN_DEFAULTS = RunSettings(duration_s=120.0)


@dataclass(frozen=True)
class MPCScenario:
    name: str
    description: str
    vehicle_preset: str
    soil_preset: str
    params: dict
    start: StartSettings
    path_spec: dict
    run: RunSettings
    mpc: MPCSettings
    terrain: TerrainSettings | None = None  # the [terrain] section (None: homogeneous plant)
    model: ModelOptions = ModelOptions()  # the [model] section (plant and prediction)
    engine: EngineSettings | None = None  # the [engine] section (the grid plant's terrain engine)
    # the ground's shape under the 3D vehicle (model.vehicle = "3d" and a [terrain] section holding
    # only [terrain.surface]: homogeneous soil following it, as symtrack simulate; docs/vehicle3d.md)
    surface: Surface | None = None

    @property
    def plant(self) -> str:
        return "homogeneous" if self.terrain is None else "grid"

    def build_path(self) -> RefPath:
        d = self.path_spec
        if d["kind"] == "field":
            segs = field_segments(d["passes"], d["pass_length_m"], d["spacing_m"], d["first_turn"])
        else:
            segs = d["segments"]
        return RefPath(d["x_m"], d["y_m"], math.radians(d["heading_deg"]), segs, d["speed_m_s"],
                       d.get("turn_speed_m_s"))

    def plant_setup(self, grid: bool, terrain=None) -> PlantSetup:
        """The MPC's plant (:class:`~symtrack.simulation.scenario.PlantSetup` of the one plant factory,
        :func:`symtrack.simulation.plants.make_plant`). On the homogeneous terrain: ``run.integrator``
        at its default tolerances, one MPC sample per advance. On the grid (``terrain``: a Terrain or
        terrain file to continue from, whose geometry it takes): the integrator of
        :func:`grid_integrator`; the ``[terrain]`` section, without size_m and origin_m the field
        covering the path plus :data:`FIELD_MARGIN_M`; the macro step ``run.output_dt_s`` for the terrain
        engine, :data:`GRID_SUBSTEP_S` for the others (the MPC's sample is split into such steps)."""
        if not grid:
            return PlantSetup(self.run.integrator_settings(), self.run.macro_step_s, batch=False)
        settings = grid_integrator(self)
        substep_s = self.run.macro_step_s if settings.method == "grid_fast" else GRID_SUBSTEP_S
        if not 0.0 < substep_s <= 1.0:
            raise ScenarioError(f"grid plant substep_s = {substep_s!r} must be in (0, 1] s")
        s = self.terrain if self.terrain is not None else TerrainSettings()
        if s.passes != 1:
            raise ScenarioError(f"terrain.passes = {s.passes}: an MPC run drives its path once (use --terrain-in "
                                "to continue from a saved terrain)")
        if terrain is None and not s.initial_state and "size_m" not in s.given and "origin_m" not in s.given:
            origin, size = field_from_path(self.build_path())
            s = dataclasses.replace(s, origin_m=origin, size_m=size)
        return PlantSetup(settings, substep_s, s)

    def to_dict(self) -> dict:
        path = dict(self.path_spec)
        if "segments" in path:
            path["segments"] = [
                {"straight_m": s.length_m} if s.kind == "straight" else
                {"arc_radius_m": s.radius_m, "angle_deg": s.angle_deg} for s in path["segments"]]
        return {"name": self.name, "description": self.description,
                "vehicle": {"preset": self.vehicle_preset}, "soil": {"preset": self.soil_preset},
                "parameters": dict(self.params),
                "start": dataclasses.asdict(self.start), "path": path,
                "run": {k: getattr(self.run, k) for k in MPC_RUN_KEYS},
                "mpc": {k: v for k, v in dataclasses.asdict(self.mpc).items() if v is not None},
                **({} if self.terrain is None else {"terrain": self.terrain.to_dict()}),
                **({} if self.surface is None else {"terrain": {"surface": self.surface.to_dict()}}),
                **({} if self.engine is None else {"engine": dataclasses.asdict(self.engine)}),
                **({} if self.model == ModelOptions() else {"model": {
                    k: v for k, v in dataclasses.asdict(self.model).items()
                    if v != getattr(ModelOptions(), k)}})}

    def resolved_dict(self) -> dict:
        """The scenario after presets and overrides, as a scenario document (``scenario.resolved.toml``:
        :func:`load` reads it back to the same scenario): the parameters in [vehicle] and [soil], every
        [model] option in effect (defaults included: the lateral law, the vehicle, ...) and the
        package's version (``symtrack_version``)."""
        d = self.to_dict()
        params = d.pop("parameters")
        d["vehicle"] = {"preset": self.vehicle_preset, **{s.name: params[s.name] for s in vehicle_params(self.model)}}
        d["soil"] = {"preset": self.soil_preset,
                     **{s.name: params[s.name] for s in soil_params(self.model) if s.name in params}}
        d["model"] = {k: getattr(self.model, k) for k in scenario_keys()}
        return with_version(d)


_int = integer
_num = number
_keys = check_keys
_params = parse_params


def _segments(items) -> list[Segment]:
    if not isinstance(items, list) or not items:
        raise ScenarioError("path.segments must be a non-empty list of {straight_m = ...} or "
                            "{arc_radius_m = ..., angle_deg = ...} tables")
    out = []
    for i, it in enumerate(items):
        where = f"path.segments[{i}]"
        if not isinstance(it, dict):
            raise ScenarioError(f"{where} = {it!r} must be a table")
        if "straight_m" in it:
            _keys(where, it, ["straight_m"])
            out.append(Segment("straight", _num(f"{where}.straight_m", it["straight_m"], 0, 1e5, True)))
        elif "arc_radius_m" in it:
            _keys(where, it, ["arc_radius_m", "angle_deg"])
            r = _num(f"{where}.arc_radius_m", it["arc_radius_m"], -1e4, 1e4)
            if abs(r) < 1.0:
                raise ScenarioError(f"{where}.arc_radius_m = {r!r}: |radius| must be at least 1 m")
            if "angle_deg" not in it:
                raise ScenarioError(f"{where}.angle_deg is required for an arc")
            out.append(Segment("arc", radius_m=r, angle_deg=_num(f"{where}.angle_deg", it["angle_deg"], 0, 720, True)))
        else:
            raise ScenarioError(f"{where} = {it!r} must have straight_m or arc_radius_m")
    return out


def _path(t: dict) -> dict:
    allowed = ["x_m", "y_m", "heading_deg", "speed_m_s", "turn_speed_m_s", "kind", "segments", "passes",
               "pass_length_m", "spacing_m", "first_turn"]
    _keys("path", t, allowed)
    kind = t.get("kind", "segments")
    if kind not in ("segments", "field"):
        raise ScenarioError(f"path.kind = {kind!r} is not one of segments, field")
    d = {"kind": kind,
         "x_m": _num("path.x_m", t.get("x_m", 0.0), -1e6, 1e6),
         "y_m": _num("path.y_m", t.get("y_m", 0.0), -1e6, 1e6),
         "heading_deg": _num("path.heading_deg", t.get("heading_deg", 0.0), -360, 360),
         "speed_m_s": _num("path.speed_m_s", t.get("speed_m_s", 2.0), 0.1, 10)}
    if "turn_speed_m_s" in t:
        d["turn_speed_m_s"] = _num("path.turn_speed_m_s", t["turn_speed_m_s"], 0.1, 10)
    if kind == "segments":
        for k in ("passes", "pass_length_m", "spacing_m", "first_turn"):
            if k in t:
                raise ScenarioError(f"path.{k} only applies to path.kind = \"field\"")
        d["segments"] = _segments(t.get("segments"))
    else:
        if "segments" in t:
            raise ScenarioError("path.segments only applies to path.kind = \"segments\"")
        d["passes"] = _int("path.passes", t.get("passes", 4), 1, 100)
        d["pass_length_m"] = _num("path.pass_length_m", t.get("pass_length_m", 40.0), 1, 1e4)
        d["spacing_m"] = _num("path.spacing_m", t.get("spacing_m", 8.0), 2, 100)
        ft = t.get("first_turn", "left")
        if ft not in ("left", "right"):
            raise ScenarioError(f"path.first_turn = {ft!r} is not one of left, right")
        d["first_turn"] = ft
    return d


def _mpc(t: dict) -> MPCSettings:
    names = [f.name for f in dataclasses.fields(MPCSettings)]
    _keys("mpc", t, names)
    try:
        return MPCSettings(**t)
    except (ParameterError, TypeError) as err:
        raise ScenarioError(str(err)) from err


def _model(t: dict) -> ModelOptions:
    _keys("model", t, scenario_keys())
    try:
        return ModelOptions(**t)
    except (ParameterError, TypeError) as err:
        raise ScenarioError(str(err)) from err


def scenario_from_dict(d: dict, default_name="mpc") -> MPCScenario:
    check_document("MPC scenario", d, TOP_KEYS)
    name, desc = d.get("name", default_name), d.get("description", "")
    model = _model(d.get("model", {}))  # its vehicle and soil law declare the [vehicle] and [soil] tables
    vp, veh = _params("vehicle", d.get("vehicle", {}), vehicle_preset, vehicle_params(model), "reference_crawler")
    sp, soil = _params("soil", d.get("soil", {}), soil_preset, soil_params(model), "sandy_loam_15",
                       known_soil_names())
    st = d.get("start", {})
    _keys("start", st, [f.name for f in dataclasses.fields(StartSettings)])
    start = StartSettings(_num("start.x_m", st.get("x_m", 0.0), -1e6, 1e6),
                          _num("start.y_m", st.get("y_m", 0.0), -1e6, 1e6),
                          _num("start.yaw_deg", st.get("yaw_deg", 0.0), -360, 360),
                          _num("start.speed_m_s", st.get("speed_m_s", 2.0), 0.1, 10))
    run = parse_run(d.get("run", {}), MPC_RUN_KEYS, MPC_RUN_DEFAULTS)
    terrain, surface = parse_ground(d.get("terrain"), model, veh,
                                    "the MPC's grid plant: --plant grid or [terrain]")
    mpc = _mpc(d.get("mpc", {}))
    try:  # what no crawler has (symtrack.model.plausibility): refused, or warned in one line
        plausibility.check_vehicle(veh)
        plausibility.check_soil_contact(veh, soil)
        plausibility.check_torque(veh, mpc.torque_max_N_m, "mpc.torque_max_N_m")
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    return MPCScenario(name, desc, vp, sp, {**veh, **soil}, start, _path(d.get("path", {})), run,
                       mpc, terrain, model, parse_engine(d.get("engine")), surface)


def grid_integrator(sc: MPCScenario) -> IntegratorSettings:
    """The grid plant's integrator from ``run.integrator``: the terrain engine (``grid_fast``) by
    default (``cvodes``, the homogeneous plant's default, means the engine here: the grid needs
    the DAE form), IDAS at the tolerances of ``validation_grid`` (``idas``, the reference), or the
    compiled fixed-step grid Rosenbrock (``rosenbrock``)."""
    name = sc.run.integrator
    if name in ("cvodes", "grid_fast"):
        return IntegratorSettings("grid_fast", engine=sc.engine)
    if name == "idas":
        return IntegratorSettings("idas", GRID_RELTOL, GRID_ABSTOL)
    if name == "rosenbrock":
        return IntegratorSettings("rosenbrock", fixed_step_s=MAX_STEP_S)
    raise ScenarioError(f"run.integrator = {name!r}: the grid plant runs grid_fast (the default), idas or rosenbrock")


def field_from_path(path, margin_m: float = FIELD_MARGIN_M) -> tuple[tuple[float, float], tuple[float, float]]:
    """(origin_m, size_m) of a field covering the reference path (without its straight extension
    past the end) with a margin on every side."""
    on = path.segment >= 0
    x, y = path.x[on], path.y[on]
    x0, x1 = float(x.min()) - margin_m, float(x.max()) + margin_m
    y0, y1 = float(y.min()) - margin_m, float(y.max()) + margin_m
    return (x0, y0), (x1 - x0, y1 - y0)


def builtin_names() -> list[str]:
    """The names of the built-in MPC scenarios."""
    return _package_names(SCENARIO_PACKAGE)


def load(name_or_path: str, overrides=None, plant: str | None = None) -> MPCScenario:
    """A built-in scenario by name or a TOML file; overrides as for
    :func:`symtrack.simulation.scenario.load_scenario` (``--set terrain.cell_m=0.25`` adds a
    [terrain] section, so the plant becomes the grid).
    ``plant``: None keeps the scenario's choice; "homogeneous" drops its [terrain] section;
    "grid" adds :data:`GRID_DEFAULT_TERRAIN` as [terrain] if it has none."""
    if plant not in (None, "homogeneous", "grid"):
        raise ScenarioError(f"plant = {plant!r} is not one of homogeneous, grid")
    d, default = read_document(name_or_path, SCENARIO_PACKAGE, "MPC scenario", overrides, paths=TERRAIN_PATH_KEYS)
    if plant == "homogeneous":
        t = d.get("terrain")
        if not (isinstance(t, dict) and set(t) == {"surface"}):  # the 3D vehicle's ground stays
            d.pop("terrain", None)
    elif plant == "grid":
        d.setdefault("terrain", dict(GRID_DEFAULT_TERRAIN))
    return scenario_from_dict(d, default)
