"""An operation's run file (:class:`OperationSpec`): read, checked and planned before anything runs.

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ...foundations.config import check_document, check_keys, read_document
from ...foundations.errors import ScenarioError
from ...simulation.scenario import scenario_from_dict
from ...terrain.settings import PATH_KEYS as TERRAIN_PATH_KEYS
from .followers import steering_map
from .footprints import check_plan
from .plans import plan_operation
from .settings import (
    FIELD_PACKAGE,
    OPERATION_RUN_KEYS,
    SEASON_KEYS,
    TERRAIN_KEYS_OF_OPERATION,
    TOP_KEYS,
    TRACKS,
    OperationSettings,
    parse_operation,
)


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


def operation_of(doc: dict, fs: OperationSettings) -> tuple:
    """One operation of a run file's document (its [run], [model], [vehicle], [soil], [terrain], [engine]) on
    the settings ``fs``: (settings, plan, scenario, steering rows), planned and checked as every operation of
    :func:`operation_spec_from_dict` is (the footprint in the field, the turn held on the soil). A region
    study's full fidelity builds its tracked machines' operations with it (symtrack/region/full.py)."""
    return _operation(doc, fs)


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
