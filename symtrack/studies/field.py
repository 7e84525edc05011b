"""The whole-field traffic study (docs/studies.md, "Whole-field traffic study").

A field of the persistent grid terrain worked in parallel straight passes, in two patterns:

- ``random``: the passes' lateral positions drawn uniformly over the usable width of the field by
  numpy's default generator seeded with ``field.seed`` (uncoordinated traffic);
- ``controlled``: controlled traffic farming (CTF): every pass on one of a fixed set of permanent
  lanes ``field.lane_spacing_m`` apart, centred on the field; pass k on lane k mod n_lanes.

The path is prescribed, the simplest honest one: each pass is a straight run along x from one
headland to the other (the CG covers ``field.pass_length_m``), the same torque on both sprockets:
held at ``field.speed_m_s`` by a speed governor (:class:`SpeedGovernor`, a PI law sampled per plant
call, the torque limited to ``field.torque_N_m``), or ``field.torque_N_m`` throughout with
``speed_m_s = "none"``; the passes alternate direction. The headland turn is **not driven**: at
the end of a pass the vehicle is lifted off (the terrain's ``end_pass``) and set down at rest at
the next pass's start (``begin_pass``), so the headlands carry no traffic in this study.

A spec is a scenario-like TOML document: ``[run]``, ``[model]``, ``[vehicle]``, ``[soil]`` as a
simulation scenario (``[run]`` without the stop rule, which the field sets), an optional
``[terrain]`` with the pool's keys (not size_m, cell_m, origin_m, passes, initial_state: the field
sets those) and the ``[field]`` section (:data:`FIELD_KEYS`; the built-in
``symtrack/studies/fields/field_traffic.toml`` documents every key). The field spans
[0, size_x] x [0, size_y] in world coordinates.

Passes per cell are counted from per-pass masks of the cells the pass loaded: a cell counts once
per pass when a track's contact overlapped it at the end of some macro step (the terrain
engine's per-pass subsoil stress is non-zero exactly there, ``World.pass_sigma``). Without the
subsoil stress (``terrain.subsoil_depths_m = []`` or an integrator other than the engine) the
mask is the cells whose sinkage changed during the pass. ``Terrain.cycles`` (the soil's count of
plastic load cycles) is reported beside it, but is not the pass count: a reload that peaks below
half the cell's previous largest pressure does not count as a cycle (docs/terrain.md, "Soil
memory"), so cells under a track's edge of a later pass are missing from it.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..foundations.config import check_document, check_keys, integer, list_hint, number, read_document, to_toml
from ..foundations.errors import ScenarioError, SimulationError
from ..foundations.files import check_output_folder, npz_bytes
from ..foundations.interrupt import defer_interrupts
from ..foundations.progress import Progress, timed_step
from ..integrators import registry
from ..reports.run_files import TerrainOut, clear_previous_run, recover, terrain_run, write_folder
from ..simulation import loop
from ..simulation.plants import make_plant
from ..simulation.scenario import SIMULATION_RUN_KEYS, Scenario, Start, scenario_from_dict
from ..soil import density, subsoil
from ..terrain.settings import PATH_KEYS as TERRAIN_PATH_KEYS
from ..terrain.storage import Terrain
from ..terrain.world import padding_m
from ..vehicles.wheeled import terrain_soils

__all__ = ["FIELD_KEYS", "FIELD_PACKAGE", "PATTERNS", "SCHEMA_VERSION", "FieldSettings", "FieldSpec",
           "FieldStudyResult", "IncompleteFieldStudy", "PassLine", "PatternResult", "SpeedGovernor",
           "clear_previous_study", "field_figures", "field_spec_from_dict", "flat_figures", "lane_positions",
           "load_field_spec", "plan_passes", "run_field_study", "usable_band_m"]

log = logging.getLogger("symtrack.studies")

SCHEMA_VERSION = 1
FIELD_PACKAGE = "symtrack.studies.fields"
PATTERNS = ("random", "controlled")
# the longest stretch of a pattern's passes between two checkpoints of its folder (field.npz,
# passes.csv, passes_per_cell.npz of the whole passes done): a study killed (SIGKILL, a lost machine)
# redoes at most this much when it is run again into the same folder. A checkpoint's field.npz of the
# million-cell field after a 20 m rut: 0.12 MB compressed in 0.26 s (storage.file_bytes, measured
# on a quiet 2-core machine); a pass takes seconds to a minute.
CHECKPOINT_EVERY_S = 60.0
PATTERN_CHOICES = (*PATTERNS, "both")
TOP_KEYS = ("name", "description", "run", "model", "vehicle", "soil", "terrain", "field")
FIELD_KEYS = ("size_m", "cell_m", "pattern", "passes", "seed", "lane_spacing_m", "lanes", "headland_m",
              "pass_length_m", "speed_m_s", "torque_N_m")
# [run] keys of a field spec: a simulation's, without the stop rule (the field sets it) and
# the run folder's figures (a field study draws its own figures, none per pass)
FIELD_RUN_KEYS = tuple(k for k in SIMULATION_RUN_KEYS
                       if k not in ("stop_after_distance_m", "stop_distance_event", "all_figures", "figures"))
# [terrain] keys the [field] section sets
TERRAIN_KEYS_OF_FIELD = ("size_m", "cell_m", "origin_m", "passes", "initial_state")
DEFAULT_PASS_LIMIT_S = 300.0
# the lateral room kept beyond the vehicle's half width and the footprint's padding (a pass that
# drifts sideways stays in the field)
LATERAL_ALLOWANCE_M = 0.25
# the longitudinal room kept at each end beyond half the contact length and the padding (the
# footprint predicted one macro step ahead)
END_ALLOWANCE_M = 0.5
MAX_PASSES = 1000


@dataclass(frozen=True)
class FieldSettings:
    """The ``[field]`` section, validated by :func:`field_spec_from_dict` (module doc)."""

    size_m: tuple[float, float] = (100.0, 100.0)
    cell_m: float = 0.1
    pattern: str = "both"
    passes: int = 20
    seed: int = 1
    lane_spacing_m: float = 10.0
    lanes: int | str = "auto"
    headland_m: float = 7.5
    pass_length_m: float | None = None  # None: size_m[0] - 2 headland_m
    speed_m_s: float | None = 2.5  # None: torque_N_m on both sprockets for the whole pass
    torque_N_m: float = 2000.0

    @property
    def patterns(self) -> tuple[str, ...]:
        return PATTERNS if self.pattern == "both" else (self.pattern,)

    @property
    def length_m(self) -> float:
        return self.pass_length_m if self.pass_length_m is not None else self.size_m[0] - 2 * self.headland_m


@dataclass(frozen=True)
class FieldSpec:
    """A validated field study: the ``[field]`` settings and the scenario of one pass (its
    ``[terrain]`` is the field, its torque programme and stop rule the pass's; ``start`` is
    replaced per pass); ``document`` is the resolved spec (written as ``field.resolved.toml``)."""

    name: str
    description: str
    field: FieldSettings
    scenario: Scenario
    document: dict

    @property
    def params(self) -> dict:
        return self.scenario.params


@dataclass(frozen=True)
class PassLine:
    """One planned pass: its number (0-based), lane (controlled traffic; None for random), the
    lateral position of the CG y_m, the start of the CG x_start_m and the heading (0 or 180 deg)."""

    index: int
    lane: int | None
    y_m: float
    x_start_m: float
    yaw_deg: float

    @property
    def direction(self) -> int:
        return 1 if self.yaw_deg == 0.0 else -1


class SpeedGovernor:
    """The torque law of a pass at ``field.speed_m_s``: the same torque on both sprockets,
    u = clip(u_r + Kp e, -T, T) with the speed error e = v_ref - u_m_s, sampled and held over each
    plant call (:func:`symtrack.simulation.loop.run`'s ``torque_law``; a call of the terrain engine
    is ``hold_s`` = 1 s). Kp = r m / (4 hold) halves the speed error per hold (both tracks' force
    2 u / r on the mass m, the sprocket radius r). u_r, the torque that balances the soil's
    resistance, is estimated from the last hold: u_r = u_prev - (r m / 2) (v - v_prev) / h (the
    mean of the new and the previous estimate; 0 before the first hold), so the speed settles
    without the overshoot of an integral's wind-up. T = ``field.torque_N_m``."""

    def __init__(self, speed_m_s: float, torque_limit_N_m: float, mass_kg: float, sprocket_radius_m: float,
                 hold_s: float, speed_index: int):
        self.v_ref, self.limit, self.iu = speed_m_s, torque_limit_N_m, speed_index
        self.kp = sprocket_radius_m * mass_kg / (4.0 * hold_s)
        self.half_rm = 0.5 * sprocket_radius_m * mass_kg
        self.resistance = None
        self.prev = None

    def __call__(self, t_s: float, x) -> tuple[float, float]:
        v = float(x[self.iu])
        if self.prev is not None and t_s > self.prev[2]:
            u_prev, v_prev, t_prev = self.prev
            est = u_prev - self.half_rm * (v - v_prev) / (t_s - t_prev)
            self.resistance = est if self.resistance is None else 0.5 * (self.resistance + est)
        u = (self.resistance or 0.0) + self.kp * (self.v_ref - v)
        u = min(max(u, -self.limit), self.limit)
        self.prev = (u, v, t_s)
        return u, u


# ---- the spec -------------------------------------------------------------------------------------
def _num(key, value, low, high, low_open=False):
    return number(f"field.{key}", value, low, high, low_open)


def _none(value) -> bool:
    return value is None or (isinstance(value, str) and value.lower() == "none")


def _parse_field(t: dict) -> FieldSettings:
    """The [field] values on their own (the checks against the vehicle follow in :func:`_check_geometry`)."""
    check_keys("field", t, FIELD_KEYS)
    d = FieldSettings()
    size = t.get("size_m", list(d.size_m))
    if not isinstance(size, (list, tuple)) or len(size) != 2:
        raise ScenarioError(f"field.size_m = {size!r} must be a pair [x, y] of lengths in m"
                            f"{list_hint('field.size_m', size)}")
    size = tuple(_num(f"size_m[{i}]", v, 1.0, 1e4) for i, v in enumerate(size))
    cell = _num("cell_m", t.get("cell_m", d.cell_m), 0.01, 5.0)
    pattern = t.get("pattern", d.pattern)
    if pattern not in PATTERN_CHOICES:
        raise ScenarioError(f"field.pattern = {pattern!r} is not one of {', '.join(PATTERN_CHOICES)}")
    passes = integer("field.passes", t.get("passes", d.passes), 1, MAX_PASSES)
    seed = t.get("seed", d.seed)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 63:
        raise ScenarioError(f"field.seed = {seed!r} must be an integer in [0, 2^63)")
    spacing = _num("lane_spacing_m", t.get("lane_spacing_m", d.lane_spacing_m), 0.0, 1e4, low_open=True)
    lanes = t.get("lanes", d.lanes)
    if lanes != "auto":
        lanes = integer("field.lanes", lanes, 1, 10_000)
    headland = _num("headland_m", t.get("headland_m", d.headland_m), 0.0, 5e3, low_open=True)
    length = t.get("pass_length_m", d.pass_length_m)
    length = None if _none(length) else _num("pass_length_m", length, 0.0, 1e4, low_open=True)
    speed = t.get("speed_m_s", d.speed_m_s)
    speed = None if _none(speed) else _num("speed_m_s", speed, 0.0, 10.0, low_open=True)
    torque = _num("torque_N_m", t.get("torque_N_m", d.torque_N_m), 0.0, 1e6, low_open=True)
    return FieldSettings(size, cell, pattern, passes, seed, spacing, lanes, headland, length, speed, torque)


def usable_band_m(fs: FieldSettings, params: dict) -> tuple[float, float]:
    """The lateral positions (world y of the CG) a pass may take: the vehicle, the footprint's
    padding, one cell and :data:`LATERAL_ALLOWANCE_M` inside the field on both sides."""
    margin = (0.5 * (params["track_gauge_m"] + params["track_width_m"]) + padding_m(fs.cell_m) + fs.cell_m
              + LATERAL_ALLOWANCE_M)
    return margin, fs.size_m[1] - margin


def _min_headland_m(fs: FieldSettings, params: dict) -> float:
    return (0.5 * params["contact_length_m"] + abs(params["cg_ahead_of_contact_centre_m"]) + padding_m(fs.cell_m)
            + fs.cell_m + END_ALLOWANCE_M)


def lane_positions(fs: FieldSettings, params: dict) -> np.ndarray:
    """The controlled-traffic lanes (world y of the CG), centred across the field, lane_spacing_m
    apart; "auto": as many as fit in :func:`usable_band_m`."""
    lo, hi = usable_band_m(fs, params)
    n = int(math.floor((hi - lo) / fs.lane_spacing_m + 1e-9)) + 1 if fs.lanes == "auto" else fs.lanes
    centre = 0.5 * fs.size_m[1]
    return centre + (np.arange(n) - 0.5 * (n - 1)) * fs.lane_spacing_m


def _check_geometry(fs: FieldSettings, params: dict) -> None:
    """The field against the vehicle: room for the passes, headlands, lanes (errors name the key)."""
    width = params["track_gauge_m"] + params["track_width_m"]
    lo, hi = usable_band_m(fs, params)
    if not hi > lo:
        raise ScenarioError(f"field.size_m = {list(fs.size_m)}: the field is too narrow for the vehicle "
                            f"({width:g} m wide; size_m[1] must exceed {2 * lo:g} m)")
    if not fs.cell_m < params["track_width_m"]:
        raise ScenarioError(f"field.cell_m = {fs.cell_m!r} must be smaller than the track width "
                            f"{params['track_width_m']!r} m (cells resolve the contact patch)")
    hmin = _min_headland_m(fs, params)
    if fs.headland_m < hmin:
        raise ScenarioError(f"field.headland_m = {fs.headland_m!r} is outside the allowed range [{hmin:.3g}, "
                            f"{0.5 * fs.size_m[0]:g}] m (half the contact length, the footprint's padding and "
                            f"{END_ALLOWANCE_M} m for the set-down and the stop)")
    room = fs.size_m[0] - 2 * fs.headland_m
    if not room > 0:
        raise ScenarioError(f"field.size_m = {list(fs.size_m)}: a field {fs.size_m[0]:g} m long leaves no room for a "
                            f"pass between its two headlands of field.headland_m = {fs.headland_m:g} m; the smallest "
                            f"that fits has size_m[0] > {2 * fs.headland_m:g} m (2 headland_m; headland_m may go down "
                            f"to {hmin:.3g} m: a field longer than {2 * hmin:.3g} m)")
    if fs.pass_length_m is not None and fs.pass_length_m > room + 1e-9:
        raise ScenarioError(f"field.pass_length_m = {fs.pass_length_m!r} is outside the allowed range (0, {room:g}] "
                            f"m (size_m[0] - 2 headland_m)")
    if "controlled" in fs.patterns:
        if fs.lane_spacing_m < width:
            raise ScenarioError(f"field.lane_spacing_m = {fs.lane_spacing_m!r} is outside the allowed range "
                                f"[{width:g}, 1e4] m: lanes closer than the vehicle's width ({width:g} m) overlap")
        y = lane_positions(fs, params)
        if y[0] < lo - 1e-9 or y[-1] > hi + 1e-9:
            most = int(math.floor((hi - lo) / fs.lane_spacing_m + 1e-9)) + 1
            raise ScenarioError(f"field.lanes = {fs.lanes!r}: {y.size} lanes {fs.lane_spacing_m:g} m apart do not fit "
                                f"across the field; at most {most} fit (lateral positions {lo:g} to {hi:g} m)")


def _pass_scenario_doc(doc: dict, fs: FieldSettings) -> dict:
    """The simulation scenario of one pass from the field spec's document."""
    run = dict(doc.get("run", {}))
    check_keys("run", run, FIELD_RUN_KEYS)
    terrain = dict(doc.get("terrain", {}))
    if not isinstance(terrain, dict):
        raise ScenarioError(f"[terrain] must be a table, got {terrain!r}")
    for k in TERRAIN_KEYS_OF_FIELD:
        if k in terrain:
            raise ScenarioError(f"terrain.{k} = {terrain[k]!r}: the [field] section sets the field "
                                "(field.size_m, field.cell_m, field.passes); leave it out of [terrain]")
    run.setdefault("duration_s", DEFAULT_PASS_LIMIT_S)
    run.setdefault("integrator", "grid_fast")
    run["stop_after_distance_m"] = fs.length_m
    run["stop_distance_event"] = "go"
    # the programme of a constant-torque pass (with field.speed_m_s the governor replaces it)
    torque = [{"t_s": 0.0, "left_N_m": fs.torque_N_m, "right_N_m": fs.torque_N_m, "event": "go"}]
    terrain.update(size_m=list(fs.size_m), cell_m=fs.cell_m, origin_m=[0.0, 0.0])
    out = {k: doc[k] for k in ("model", "vehicle", "soil") if k in doc}
    return {"name": doc.get("name", "field"), "description": doc.get("description", ""), "run": run, **out,
            "terrain": terrain, "torque": torque}


def field_spec_from_dict(doc: dict, default_name: str = "field") -> FieldSpec:
    """A field spec document (already read) -> :class:`FieldSpec`, every section checked before
    any work: errors name the key, the value and the allowed range."""
    check_document("field spec", doc, TOP_KEYS)
    if "field" not in doc:
        raise ScenarioError("a field study needs a [field] section (docs/studies.md, \"Whole-field traffic study\"),"
                            " or a field operation an [operation] section (docs/studies.md, \"Field operations\")")
    name = doc.get("name", default_name)
    desc = doc.get("description", "")
    fs = _parse_field(doc["field"])
    sdoc = _pass_scenario_doc(doc, fs)
    sdoc["name"] = name
    if fs.length_m <= 0:  # no room for a pass: _check_geometry names the field's size, not the pass's stop rule
        sdoc["run"]["stop_after_distance_m"] = fs.size_m[0]
    sc = scenario_from_dict(sdoc, name)
    registry.get(sc.run.integrator).check("grid", sc.run.integrator_settings())
    _check_geometry(fs, sc.params)
    if fs.speed_m_s is not None and fs.speed_m_s > sc.terrain.max_speed_m_s:
        raise ScenarioError(f"field.speed_m_s = {fs.speed_m_s!r} is outside the allowed range (0, "
                            f"{sc.terrain.max_speed_m_s:g}] m/s (terrain.max_speed_m_s, the speed the channel pool "
                            "is sized for)")
    resolved = {"name": name, "description": desc, **{k: doc[k] for k in ("run", "model", "terrain") if k in doc}}
    # the vehicle and the soil with every value after the presets, the files and the overrides (as simulate's
    # scenario.resolved.toml: a preset file's values are in the record, not only its path)
    resolved["vehicle"] = {"preset": sc.vehicle_preset, **sc.vehicle}
    resolved["soil"] = {"preset": sc.soil_preset, **sc.soil}
    resolved["field"] = {k: (list(v) if isinstance(v, tuple) else ("none" if v is None else v))
                         for k, v in dataclasses.asdict(fs).items()}
    return FieldSpec(name, desc, fs, sc, resolved)


def load_field_spec(name_or_path, overrides=None) -> FieldSpec:
    """Load a built-in field study (``symtrack/studies/fields/``) or a TOML file, apply the
    overrides (``["field.passes=4", ...]`` as ``--set`` takes them, or a dict), validate."""
    doc, default_name = read_document(name_or_path, FIELD_PACKAGE, "field study", overrides, paths=TERRAIN_PATH_KEYS)
    return field_spec_from_dict(doc, default_name)


def plan_passes(spec: FieldSpec, pattern: str) -> list[PassLine]:
    """The passes of a pattern, in order (module doc)."""
    fs = spec.field
    if pattern not in PATTERNS:
        raise ScenarioError(f"pattern = {pattern!r} is not one of {', '.join(PATTERNS)}")
    if pattern == "random":
        lo, hi = usable_band_m(fs, spec.params)
        ys = np.random.default_rng(fs.seed).uniform(lo, hi, fs.passes)
        lanes = [None] * fs.passes
    else:
        lane_y = lane_positions(fs, spec.params)
        lanes = [k % lane_y.size for k in range(fs.passes)]
        ys = lane_y[lanes]
    out = []
    for k in range(fs.passes):
        forward = k % 2 == 0
        x0 = fs.headland_m if forward else fs.size_m[0] - fs.headland_m
        out.append(PassLine(k, lanes[k], float(ys[k]), float(x0), 0.0 if forward else 180.0))
    return out


# ---- the figures -----------------------------------------------------------------------------------
def _copy_terrain(st: Terrain) -> Terrain:
    t = Terrain(st.grid, st.soil, st.subsoil_depths_m)
    t.soil_law = st.soil_law
    _copy_into(t, st)
    return t


def _copy_into(dst: Terrain, src: Terrain) -> None:
    """The cell state of ``src`` into ``dst`` (same grid and depths)."""
    for name, a in src.arrays().items():
        dst.arrays()[name][...] = a


def _with_own_weight(terrain: Terrain) -> np.ndarray:
    """The terrain's largest vertical stress plus the soil's own weight where traffic loaded it: the
    stress the risk grades (soil/density.py)."""
    sm = terrain.sigma_max.astype(np.float64)
    geo = density.geostatic_table(terrain_soils(terrain), terrain.subsoil_depths_m)[terrain.soil_index]
    return np.where(sm > 0, sm + geo, sm)


def precompression_cells_Pa(terrain: Terrain, soils=None) -> np.ndarray:
    """(n_cells, n_depths): each cell's precompression stress at each subsoil depth [Pa], its soil's
    layer's (``soils``: the field's soils by soil index, e.g. a world's with the day's moisture;
    default the terrain's own)."""
    soils = terrain_soils(terrain) if soils is None else soils
    return density.precompression_table(soils, terrain.subsoil_depths_m)[terrain.soil_index]


def field_figures(terrain: Terrain, counts: np.ndarray, precompression_stress_Pa) -> dict:
    """The figures of one pattern's field (docs/studies.md): from the terrain after the passes and
    the passes-per-cell counts (n_cells,); ``precompression_stress_Pa``: a strength the risk grades
    against, broadcast against (n_cells, n_depths) (:func:`precompression_cells_Pa`)."""
    g = terrain.grid
    area = g.cell_m ** 2
    counts = np.asarray(counts).ravel()
    traff = counts > 0
    n_t = int(traff.sum())
    z = terrain.z
    out = {
        "field_cells": g.n_cells,
        "trafficked_cells": n_t,
        "trafficked_area_m2": n_t * area,
        "trafficked_area_fraction": n_t / g.n_cells,
        "passes_per_cell_max": int(counts.max()) if counts.size else 0,
        "passes_per_cell_mean_trafficked": float(counts[traff].mean()) if n_t else 0.0,
        "passes_per_cell_histogram": [int(v) for v in np.bincount(counts.astype(np.int64), minlength=1)],
        "load_cycles_histogram": [int(v) for v in np.bincount(terrain.cycles.astype(np.int64), minlength=1)],
        "rut_mean_depth_mm": 1e3 * float(z[traff].mean()) if n_t else 0.0,
        "rut_max_depth_mm": 1e3 * float(z.max()) if z.size else 0.0,
        "sinkage_volume_m3": float(z.sum() * area),
    }
    depths = list(terrain.subsoil_depths_m)
    if depths:
        sm = terrain.sigma_max
        fr = subsoil.risk_area_fractions(_with_own_weight(terrain), precompression_stress_Pa, traff, area)
        pc = np.broadcast_to(np.asarray(precompression_stress_Pa, dtype=np.float64), sm.shape)
        out["subsoil_depths_m"] = depths
        # the weakest cell's at any depth (named so: a two-layer soil's depths differ), and at each depth
        out["subsoil_precompression_stress_min_kPa"] = 1e-3 * float(pc.min())
        out["subsoil_precompression_stress_by_depth_kPa"] = [1e-3 * float(v) for v in pc.min(axis=0)]
        out["subsoil_sigma_z_max_kPa"] = [1e-3 * float(v) for v in (sm[traff].max(axis=0) if n_t
                                                                     else np.zeros(len(depths)))]
        field_area = g.n_cells * area
        for name in subsoil.RISK_NAMES:
            out[f"risk_fraction_of_trafficked_{name}"] = [float(v) for v in fr[f"fraction_{name}"]]
            out[f"risk_area_m2_{name}"] = [float(v) for v in fr[f"area_{name}_m2"]]
            out[f"risk_fraction_of_field_{name}"] = [float(v) / field_area for v in fr[f"area_{name}_m2"]]
    return out


# a pattern's figures that are lists by subsoil depth (subsoil_depths_m): the report's rows by depth
FIGURES_BY_DEPTH = ("subsoil_precompression_stress_by_depth_kPa", "subsoil_sigma_z_max_kPa",
                    "bulk_density_initial_Mg_per_m3",
                    *(f"{kind}_{name}" for name in subsoil.RISK_NAMES
                      for kind in ("risk_fraction_of_trafficked", "risk_area_m2", "risk_fraction_of_field")))


def flat_figures(pattern: str, figures: dict) -> dict:
    """The scalar figures of a pattern under ``<pattern>_<name>`` (the per-depth risk fractions of
    the field as ``<pattern>_risk_fraction_of_field_<class>_at_<depth>m``, the precompression stress as
    ``<pattern>_subsoil_precompression_stress_at_<depth>m_kPa``, the largest vertical stress of the trafficked
    cells as ``<pattern>_subsoil_sigma_z_max_at_<depth>m_kPa``): the top-level keys of summary.json that a
    sweep's results.csv takes."""
    out = {}
    for k, v in figures.items():
        if isinstance(v, (bool, int, float, str)) or v is None:
            out[f"{pattern}_{k}"] = v
    for name in subsoil.RISK_NAMES:
        for d, v in zip(figures.get("subsoil_depths_m", []), figures.get(f"risk_fraction_of_field_{name}", []),
                        strict=True):
            out[f"{pattern}_risk_fraction_of_field_{name}_at_{d:g}m"] = v
    for d, v in zip(figures.get("subsoil_depths_m", []), figures.get("subsoil_precompression_stress_by_depth_kPa", []),
                    strict=True):
        out[f"{pattern}_subsoil_precompression_stress_at_{d:g}m_kPa"] = v
    for d, v in zip(figures.get("subsoil_depths_m", []), figures.get("subsoil_sigma_z_max_kPa", []), strict=True):
        out[f"{pattern}_subsoil_sigma_z_max_at_{d:g}m_kPa"] = v
    return out


# ---- running it --------------------------------------------------------------------------------------
@dataclass
class PatternResult:
    """One pattern's study: the planned passes, a record per pass run, the passes-per-cell counts
    (n_cells,) uint16, the terrain after it (a copy), its figures, and whether all passes ran."""

    pattern: str
    lines: list
    records: list = field(default_factory=list)
    counts: np.ndarray | None = None
    terrain: Terrain | None = None
    figures: dict = field(default_factory=dict)
    complete: bool = False
    error: str | None = None
    wall_time_s: float = 0.0
    sim_time_s: float = 0.0
    count_source: str = ""
    soils: list = field(default_factory=list)  # the field's soil parameter sets (its soil_index's)
    # the bulk density (docs/subsoil.md "Bulk density"): the field's largest by depth before the passes
    density0: list | None = None

    def __repr__(self) -> str:
        from ..reports.html import short_repr

        figures = {**self.figures, "passes_done": len(self.records), "complete": self.complete,
                   "wall_time_s": self.wall_time_s}
        return short_repr("PatternResult", self.pattern, figures,
                          ("passes_done", "trafficked_area_fraction", "rut_max_depth_mm", "wall_time_s"))


@dataclass
class FieldStudyResult:
    """What :func:`run_field_study` returns: per pattern a :class:`PatternResult`, the summary
    (summary.json) and the files written (when ``out`` was given)."""

    spec: FieldSpec
    patterns: dict
    summary: dict
    written: list = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return bool(self.summary.get("complete"))

    def _figure_keys(self) -> list[str]:
        s = self.summary
        keys = []
        for p in s.get("patterns_run") or ():
            keys += [f"{p}_{k}" for k in ("passes_done", "trafficked_area_fraction", "passes_per_cell_max",
                                          "rut_mean_depth_mm", "rut_max_depth_mm")]
            keys += [k for k in s if k.startswith(f"{p}_risk_fraction_of_field_high_at_")]
        return keys + ["sim_time_s", "build_s", "wall_time_s"]

    def __repr__(self) -> str:
        from ..reports.html import short_repr

        keys = [k for k in self._figure_keys() if k.endswith(("_trafficked_area_fraction", "wall_time_s"))]
        return short_repr("FieldStudyResult", self.spec.name, self.summary, tuple(keys))

    def _repr_html_(self) -> str:
        """The view in a notebook: what ran (the study, its field, patterns and passes, the integrator, the
        machine and soil), each pattern's figures with their units (the share of the field trafficked, the
        rut, the area at high compaction risk by depth) and the run time."""
        from ..reports.html import machine_facts, notebook_html

        s, sc = self.summary, self.spec.scenario
        size = s.get("field_size_m") or list(self.spec.field.size_m)
        facts = [("field study", self.spec.name),
                 ("field", f"{size[0]:g} m x {size[1]:g} m, {s.get('field_cell_m', self.spec.field.cell_m):g} m cells"),
                 ("patterns", ", ".join(map(str, s.get("patterns_run") or ()))),
                 ("passes per pattern", s.get("passes_per_pattern", "")), ("integrator", sc.run.integrator),
                 *machine_facts(sc.vehicle_preset, sc.soil_preset, sc.params)]
        return notebook_html(f"field study {self.spec.name!r}", s, facts, keys=tuple(self._figure_keys()))


class IncompleteFieldStudy(SimulationError):
    """A field study in which a pass failed; ``result`` holds (and ``out`` has) what was computed."""

    def __init__(self, message: str, result: FieldStudyResult):
        super().__init__(message)
        self.result = result


def _engine_stress(plant) -> bool:
    """Whether the plant's engine records each pass's stress (then a pass's cells are those it stressed)."""
    return bool(plant.world.storage.subsoil_depths_m) and hasattr(plant, "engine")


def _count_source(plant) -> str:
    return ("cells a track's contact overlapped at a macro step's end (World.pass_sigma > 0)"
            if _engine_stress(plant) else "cells whose sinkage changed during the pass")


def _pass_mask(world, engine_stress: bool, z_before: np.ndarray | None) -> np.ndarray:
    if engine_stress:
        return world.pass_sigma[:, 0] > 0
    return world.touched & (world.storage.z != z_before)


def _run_pattern(spec: FieldSpec, plant, pr: PatternResult, bar: Progress, done_before: int,
                 checkpoint=None) -> None:
    """Run the passes of ``pr.lines`` after those of ``pr.records`` (a resumed pattern: its
    terrain is in the plant's world, its counts in ``pr.counts``) on the plant's world, filling
    ``pr`` (also when a pass fails or Ctrl-C stops it: its figures are those of the passes done;
    a pass that Ctrl-C stopped is not among them: the terrain is the one after the last whole
    pass). ``checkpoint(pr)``, when given, is called after a pass at most every
    :data:`CHECKPOINT_EVERY_S`, with ``pr.terrain`` the terrain after it."""
    world = plant.world
    sc = spec.scenario
    pattern, lines = pr.pattern, pr.lines
    if pr.counts is None:
        pr.counts = np.zeros(world.grid.n_cells, dtype=np.uint16)
    counts = pr.counts
    whole = _copy_terrain(world.storage)  # the terrain after the last whole pass
    in_pass = False
    last_checkpoint = time.perf_counter()
    engine_stress = _engine_stress(plant)
    pr.count_source = _count_source(plant)
    iu = plant.state_names.index("u_m_s")
    pr.soils = list(world.soils)
    t_pat = time.perf_counter()
    try:
        for line in lines[len(pr.records):]:
            in_pass = True
            sck = dataclasses.replace(sc, start=Start(line.x_start_m, line.y_m, line.yaw_deg))
            z0 = None if engine_stress else world.storage.z.copy()
            t0 = time.perf_counter()
            failure = None
            try:
                law = None
                if spec.field.speed_m_s is not None:
                    law = SpeedGovernor(spec.field.speed_m_s, spec.field.torque_N_m, sc.params["mass_kg"],
                                        sc.params["sprocket_radius_m"], plant.max_intervals * sc.run.macro_step_s, iu)
                res = loop.run(sck, plant, torque_law=law)
            except loop.IncompleteRun as err:
                res, failure = err.partial, err
            wall = time.perf_counter() - t0
            mask = _pass_mask(world, engine_stress, z0)
            record = {"pass": line.index + 1, "lane": line.lane, "y_m": line.y_m, "x_start_m": line.x_start_m,
                      "direction": line.direction, "distance_m": float(np.sum(np.hypot(
                          np.diff(res.state("x_m")), np.diff(res.state("y_m"))))),
                      "sim_time_s": float(res.t[-1]), "wall_time_s": wall,
                      "speed_end_m_s": float(res.X[-1, iu]), "cells_loaded": int(mask.sum()),
                      "stopped_by": res.stopped_by}
            if engine_stress:
                record[DENSITY_COLUMN] = world.bulk_density_max()
            # the pass is counted whole (its record, counts, time and terrain) or not at all: a Ctrl-C
            # in these lines is raised after them
            with defer_interrupts():
                counts += mask
                pr.records.append(record)
                pr.sim_time_s += float(res.t[-1])
                _copy_into(whole, world.storage)
                in_pass = False
            bar.update(done_before + line.index + 1, f"{pattern} pass {line.index + 1}/{len(lines)}")
            if checkpoint is not None and time.perf_counter() - last_checkpoint >= CHECKPOINT_EVERY_S \
                    and len(pr.records) < len(lines):
                pr.terrain = whole
                checkpoint(pr)
                last_checkpoint = time.perf_counter()
            if failure is None and res.stopped_by != "distance":
                failure = SimulationError(f"run.duration_s = {sc.run.duration_s:g} s ended the pass before it "
                                          f"covered field.pass_length_m = {spec.field.length_m:g} m (it covered "
                                          f"{pr.records[-1]['distance_m']:.2f} m); raise run.duration_s")
            if failure is not None:
                pr.error = f"{pattern} pass {line.index + 1}: {failure}"
                break
        else:
            pr.complete = True
    finally:  # also on Ctrl-C: the whole passes done are kept
        pr.wall_time_s += time.perf_counter() - t_pat
        pr.terrain = whole if in_pass else _copy_terrain(world.storage)
        pr.figures = _pattern_figures(spec, pr)


def _strength(spec: FieldSpec, pr: PatternResult):
    """The strength the risk grades a pattern's field against: each cell's at each depth from the
    field's soils (the world's, with the day's moisture), or the study's soil's where none are known."""
    if not pr.terrain.subsoil_depths_m:
        return float(spec.params["precompression_stress_Pa"])
    if pr.soils:
        return precompression_cells_Pa(pr.terrain, pr.soils)
    return density.precompression_table([spec.params], pr.terrain.subsoil_depths_m)[0]


def _pattern_figures(spec: FieldSpec, pr: PatternResult) -> dict:
    """The figures of a pattern's passes done (its terrain, counts and records)."""
    f = field_figures(pr.terrain, pr.counts, _strength(spec, pr))
    f.update(passes_done=len(pr.records), wall_time_s=pr.wall_time_s, sim_time_s=pr.sim_time_s,
             lateral_positions_m=[ln.y_m for ln in pr.lines[:len(pr.records)]])
    if pr.density0 is not None:
        f["bulk_density_initial_Mg_per_m3"] = pr.density0
    if pr.pattern == "controlled":
        f["lanes"] = int(lane_positions(spec.field, spec.params).size)
    else:
        f["seed"] = spec.field.seed
    return f


PASS_COLUMNS = ("pass", "lane", "y_m", "x_start_m", "direction", "distance_m", "sim_time_s", "wall_time_s",
                "speed_end_m_s", "cells_loaded", "stopped_by")


# a pass's largest bulk density by depth (with the engine's stress; the order of subsoil_depths_m):
# one column, a JSON list (passes.csv is also what a resumed study reads its passes from)
DENSITY_COLUMN = "bulk_density_max_Mg_per_m3"


def _passes_csv(records) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = PASS_COLUMNS + ((DENSITY_COLUMN,) if records and DENSITY_COLUMN in records[0] else ())
    w.writerow(cols)
    for r in records:
        w.writerow(["" if r[c] is None else (repr(r[c]) if isinstance(r[c], float) else
                                             json.dumps(r[c]) if isinstance(r[c], list) else r[c]) for c in cols])
    return buf.getvalue()


def _pattern_files(spec: FieldSpec, pr: PatternResult, figures: bool = True) -> dict[str, bytes]:
    """The files of one pattern's folder (besides field.npz); without ``figures`` its data files only
    (a checkpoint)."""
    files = {"passes_per_cell.npz": passes_per_cell_npz(pr), "passes.csv": _passes_csv(pr.records).encode()}
    if not figures:
        return files
    from ..reports.subsoil_plots import density_map_png, risk_map_png  # matplotlib: imported when drawn
    from . import field_plots

    g = pr.terrain.grid
    x0, x1, y0, y1 = g.bounds()
    ext = (x0, x1, y0, y1)
    shape = g.shape
    label = f"{pr.pattern} traffic, {len(pr.records)} passes"
    files |= {"sinkage_map.png": field_plots.sinkage_map_png(pr.terrain.z.reshape(shape), ext, label),
              "passes_map.png": field_plots.passes_map_png(pr.counts.reshape(shape), ext, label)}
    depths = pr.terrain.subsoil_depths_m
    if depths:
        pc = _strength(spec, pr)
        # a field of many cells in blocks, each its highest class (a rut of a few cells stays visible)
        risk = subsoil.risk_class(_with_own_weight(pr.terrain), pc).reshape(*shape, len(depths))
        risk, f = field_plots.block_max(risk, field_plots.RISK_MAP_BLOCKS)
        touched, _ = field_plots.block_max((pr.counts > 0).reshape(shape), field_plots.RISK_MAP_BLOCKS)
        blocks = f"\n(blocks of {f * g.cell_m:g} m: the highest class)" if f > 1 else ""
        files["risk_map.png"] = risk_map_png(risk, touched, depths, (x0, x0 + risk.shape[0] * f * g.cell_m, y0,
                                                                     y0 + risk.shape[1] * f * g.cell_m),
                                             title=f"compaction risk: {label}{blocks}")
        if pr.soils and "bulk_density_initial_Mg_per_m3" in pr.figures:
            rho = density.bulk_density(pr.terrain.specific_volume, pr.terrain.soil_index, pr.soils, depths)
            rho0 = density.bulk_density(np.zeros_like(pr.terrain.specific_volume), pr.terrain.soil_index, pr.soils,
                                        depths)
            # the change from the initial density, blocks their largest (a 1.35 topsoil's compaction shows
            # beside a 1.55 subsoil's)
            change, f = field_plots.block_max((rho - rho0).reshape(*shape, len(depths)), field_plots.RISK_MAP_BLOCKS)
            rho, _ = field_plots.block_max(rho.reshape(*shape, len(depths)), field_plots.RISK_MAP_BLOCKS)
            blocks = f"\n(blocks of {f * g.cell_m:g} m: the largest)" if f > 1 else ""
            files["density_map.png"] = density_map_png(
                rho, depths, (x0, x0 + rho.shape[0] * f * g.cell_m, y0, y0 + rho.shape[1] * f * g.cell_m),
                title=f"dry bulk density, increase over the initial: {label}{blocks}", initial_Mg_per_m3=rho - change)
    return files


def _summary(spec: FieldSpec, results: dict, build_s: float, t_start: float, error: str | None,
             interrupted: bool, world) -> dict:
    fs = spec.field
    g = next(iter(results.values())).terrain.grid if results else None
    complete = (not interrupted and error is None and set(results) == set(fs.patterns)
                and all(r.complete for r in results.values()))
    s = {"schema_version": SCHEMA_VERSION, "kind": "symtrack-field-study", "name": spec.name,
         "description": spec.description, "complete": complete, "error": error,
         "interrupted": interrupted, "patterns_run": list(results), "passes_per_pattern": fs.passes,
         "field_size_m": list(fs.size_m), "field_cell_m": fs.cell_m,
         "field_cells": g.n_cells if g is not None else None, "field_area_m2": fs.size_m[0] * fs.size_m[1],
         "pass_length_m": fs.length_m, "terrain_channel_modulus_M": world.M, "terrain_channels": world.n_channels,
         "build_s": build_s,
         "passes_wall_time_s": sum(r.wall_time_s for r in results.values()),
         "sim_time_s": sum(r.sim_time_s for r in results.values()),
         "wall_time_s": time.perf_counter() - t_start,
         "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
         "path_note": "prescribed straight passes along x between the headlands; the headland turn is not "
                      "driven: the vehicle is lifted off at a pass's end and set down at rest at the next start",
         "passes_count_source": next(iter(results.values())).count_source if results else ""}
    for name, r in results.items():
        s.update(flat_figures(name, r.figures))
    s["patterns"] = {name: {**r.figures, "complete": r.complete, "error": r.error, "passes": r.records}
                     for name, r in results.items()}
    return s


def run_field_study(spec, out=None, *, overrides=None, progress: bool = False, plant=None) -> FieldStudyResult:
    """Run a field study: every pattern of ``field.pattern`` on a field of its own (one plant,
    the field cleared between the patterns), and write its folder.

    Parameters
    ----------
    spec : FieldSpec or str
        A loaded spec, or a built-in name / TOML path (loaded with ``overrides``).
    out : path, optional
        The output folder (docs/studies.md): ``summary.json`` (last), ``field.resolved.toml``,
        ``<pattern>/field.npz``, ``<pattern>/passes.csv``, ``<pattern>/*.png``, ``comparison.png``
        with both patterns. Checked before any work.
    overrides : list of str or dict, optional
        With a name or path: ``--set`` overrides.
    progress : bool
        A progress bar over the passes on stderr.
    plant : optional
        The grid plant to run on (``make_plant(spec.scenario)``, e.g. instrumented by a benchmark);
        built here by default. Its field is cleared first.

    Returns
    -------
    FieldStudyResult

    Raises
    ------
    IncompleteFieldStudy
        A pass failed; what was computed is in ``result`` (and written to ``out``).
    KeyboardInterrupt
        On Ctrl-C, after writing the passes done (``summary.json``: ``complete = false``).
    """
    if not isinstance(spec, FieldSpec):
        spec = load_field_spec(spec, overrides)
    elif overrides:
        raise ScenarioError("overrides apply to a spec given by name or path; this spec is loaded already")
    folder = check_output_folder(str(out)) if out is not None else None
    t_start = time.perf_counter()
    fs = spec.field
    if folder is not None:
        recover(folder)  # a killed write's commit completed (or undone) before the folder is read
    done = _resumable(folder, spec) if folder is not None else {}
    if folder is not None and not done:
        clear_previous_study(folder)
        # first: a folder interrupted later is known by it as this study's (a rerun resumes it)
        write_folder(folder, {"field.resolved.toml": to_toml(spec.document)}, clear=False)
    elif done:
        log.info("field %s: resuming the study in %s (%s)", spec.name, folder, ", ".join(
            f"{p}: {len(r.records)} of {fs.passes} passes done" for p, r in done.items()))
    if plant is None:
        plant = make_plant(spec.scenario)
    else:
        plant.world.clear()
    build_s = time.perf_counter() - t_start
    results: dict[str, PatternResult] = {}
    bar = Progress(fs.passes * len(fs.patterns), f"field {spec.name}", enabled=progress)
    error, interrupted, pending = None, False, None
    checkpoint = None if folder is None else (lambda pr: _write_checkpoint(folder, spec, pr))
    try:
        for k, pattern in enumerate(fs.patterns):
            plant.world.clear()
            pr = done.get(pattern) or PatternResult(pattern, plan_passes(spec, pattern))
            pending = results[pattern] = pr
            pr.density0 = plant.world.bulk_density_max() if _engine_stress(plant) else None  # of the new field
            if pr.complete:  # finished before: its folder is whole
                pr.count_source = _count_source(plant)
                pr.soils = list(plant.world.soils)
                pr.figures = _pattern_figures(spec, pr)
                pending = None
                continue
            if pr.records:  # resumed: the terrain after its last checkpointed pass
                _copy_into(plant.world.storage, pr.terrain)
            _run_pattern(spec, plant, pr, bar, k * fs.passes + len(pr.records), checkpoint)
            if folder is not None:
                bar.say(f"writing the {pattern} pattern's field and drawing its maps")
                _write_pattern(folder, spec, pr)
            pending = None
            if not pr.complete:
                error = pr.error
                break
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        bar.close(complete=error is None and not interrupted)
        if folder is not None and pending is not None and pending.terrain is not None:
            _write_pattern(folder, spec, pending)  # the pattern Ctrl-C stopped: its passes done
        summary = _summary(spec, results, build_s, t_start, error, interrupted, plant.world)
        written = []
        if folder is not None:
            with timed_step(f"drawing the comparison and writing the report into {folder}"):
                written = _write_top(folder, spec, results, summary)
        result = FieldStudyResult(spec, results, summary, written)
    if error is not None:
        raise IncompleteFieldStudy(error, result)
    return result


PATTERN_FILES = ("field.npz", "passes_per_cell.npz", "passes.csv", "sinkage_map.png", "passes_map.png",
                 "risk_map.png")


def passes_per_cell_npz(pr: PatternResult) -> bytes:
    """``passes_per_cell.npz``: ``kind`` "symtrack-field-passes", ``schema_version``, ``origin_m``,
    ``cell_m``, ``shape`` (as the terrain file) and ``passes`` uint16 (nx, ny): the passes that
    loaded each cell (the counts of docs/studies.md)."""
    g = pr.terrain.grid
    return npz_bytes(kind=np.array("symtrack-field-passes"), schema_version=np.array(SCHEMA_VERSION),
                     origin_m=np.array(g.origin_m, dtype=float), cell_m=np.array(g.cell_m), shape=np.array(g.shape),
                     passes=pr.counts.reshape(g.shape))
TOP_FILES = ("summary.json", "field.resolved.toml", "comparison.png", "report.html")


def clear_previous_study(folder) -> list:
    """Remove the files of a previous field study from ``folder`` (one whose summary.json is a
    field study's): :data:`TOP_FILES` and each pattern folder's :data:`PATTERN_FILES`, so that a
    reused ``--out`` never mixes two studies' files (the one clean-up,
    :func:`~symtrack.reports.run_files.clear_previous_run`). Anything else is left alone."""
    names = [f"{p}/{n}" for p in PATTERNS for n in PATTERN_FILES] + list(TOP_FILES)
    return clear_previous_run(folder, names, kind="symtrack-field-study")


def _write_checkpoint(folder, spec: FieldSpec, pr: PatternResult) -> None:
    """The pattern's data files of the whole passes done (no figures): what a rerun resumes from."""
    _write_pattern(folder, spec, pr, figures=False)


def _read_records(text: str) -> list[dict]:
    """passes.csv -> the records of :func:`_run_pattern` (the types of :data:`PASS_COLUMNS`)."""
    out = []
    for row in csv.DictReader(io.StringIO(text)):
        r = {}
        for k in PASS_COLUMNS:
            v = row[k]
            r[k] = (None if v == "" else int(v) if k in ("pass", "lane", "cells_loaded")
                    else v if k in ("direction", "stopped_by") else float(v))
        if row.get(DENSITY_COLUMN):
            r[DENSITY_COLUMN] = [float(x) for x in json.loads(row[DENSITY_COLUMN])]
        out.append(r)
    return out


def _resumable(folder, spec: FieldSpec) -> dict:
    """The patterns of an interrupted run of this same study in ``folder`` (its field.resolved.toml
    is this spec's, its summary.json absent (killed) or interrupted, not failed): per pattern whose
    data files are there, a :class:`PatternResult` with its passes done, counts and terrain (complete
    when every pass is done). Empty when there is nothing to resume."""
    try:
        if (folder / "field.resolved.toml").read_text() != to_toml(spec.document):
            return {}
    except (OSError, ValueError):  # gone, unreadable, not UTF-8: nothing to resume
        return {}
    try:
        summary = json.loads((folder / "summary.json").read_text())
    except FileNotFoundError:
        summary = None
    except (OSError, ValueError):
        return {}
    if summary is not None and (summary.get("complete") or summary.get("error") is not None):
        return {}
    done = {}
    for pattern in spec.field.patterns:
        sub = folder / pattern
        try:
            records = _read_records((sub / "passes.csv").read_text())
            with np.load(sub / "passes_per_cell.npz") as z:
                counts = np.asarray(z["passes"], dtype=np.uint16).ravel()
            terrain = Terrain.load(sub / "field.npz", spec.params)
        except (OSError, KeyError, ValueError, ScenarioError) as err:
            log.info("field %s: %s is not resumable (%s); it runs again", spec.name, sub, err)
            continue
        lines = plan_passes(spec, pattern)
        ran = terrain.history[-1].get("passes") if terrain.history else None  # the passes its writer ran
        if len(records) > len(lines) or ran != len(records) or counts.size != terrain.grid.n_cells:
            continue
        pr = PatternResult(pattern, lines, records=records, counts=counts, terrain=terrain,
                           complete=len(records) == len(lines) and (sub / "sinkage_map.png").is_file(),
                           sim_time_s=sum(r["sim_time_s"] for r in records),
                           wall_time_s=sum(r["wall_time_s"] for r in records))
        done[pattern] = pr
    return done


def _write_pattern(folder, spec: FieldSpec, pr: PatternResult, figures: bool = True) -> list:
    sub = folder / pr.pattern
    files = _pattern_files(spec, pr, figures)
    # field.npz with the pattern's files, through the one writer (its history: this study's passes)
    field = TerrainOut(sub / "field.npz", pr.terrain, spec.scenario.soil, terrain_run(spec.scenario, len(pr.records)),
                       lock=False)
    # written as the study folder's files (its manifest records them: symtrack.reports.run_files)
    write_folder(folder, {f"{pr.pattern}/{n}": d for n, d in files.items()}, clear=False, terrain=field)
    return [sub / "field.npz", *(sub / n for n in files)]


def _write_top(folder, spec: FieldSpec, results: dict, summary: dict) -> list:
    written = [folder / "field.resolved.toml"]
    files = {"field.resolved.toml": to_toml(spec.document)}
    for pr in results.values():
        written += [folder / pr.pattern / n for n in PATTERN_FILES if (folder / pr.pattern / n).is_file()]
    if len(results) == 2:
        from . import field_plots

        files["comparison.png"] = field_plots.comparison_png({k: r.figures for k, r in results.items()})
        written.append(folder / "comparison.png")
    files["report.html"] = _report(folder, spec, results, summary, files).encode()
    written.append(folder / "report.html")
    files["summary.json"] = json.dumps(summary, indent=2) + "\n"
    write_folder(folder, files, clear=False)  # summary.json last
    written.append(folder / "summary.json")
    return written


def _report(folder, spec: FieldSpec, results: dict, summary: dict, files: dict) -> str:
    """report.html of a field study: what ran, each pattern's scalar figures side by side, the maps of
    every pattern (read from its folder, written before) and the comparison, the resolved study."""
    from ..reports.html import report_html

    images = {"comparison.png": files["comparison.png"]} if "comparison.png" in files else {}
    for pr in results.values():
        for n in ("sinkage_map.png", "passes_map.png", "risk_map.png", "density_map.png"):
            if (folder / pr.pattern / n).is_file():
                images[f"{pr.pattern}/{n}"] = (folder / pr.pattern / n).read_bytes()
    names = list(results)
    keys = [k for k, v in results[names[0]].figures.items() if isinstance(v, (bool, int, float, str))] if names else []
    rows = [[k, *(results[n].figures.get(k) for n in names)] for k in keys]
    # the figures by depth, a row per depth (the strength, the stress, the risk; not the other lists, such as
    # the passes' lateral positions, whatever their length)
    depths = results[names[0]].figures.get("subsoil_depths_m", []) if names else []
    for k, v in (results[names[0]].figures.items() if names else ()):
        if k in FIGURES_BY_DEPTH and isinstance(v, list) and len(v) == len(depths):
            rows += [[f"{k} at {d:g} m", *(_at(results[n].figures.get(k), j) for n in names)]
                     for j, d in enumerate(depths)]
    tables = {"Soil": soil_table(spec.scenario.soil, depths, spec.scenario.soil_preset)}
    if names:
        tables["Patterns"] = (["figure", *names], rows)
    done = ", ".join(f"{n}: {len(results[n].records)} passes" for n in names)
    from ..reports.run_files import what_ran

    note = (f"Field study '{spec.name}': the patterns {done}; "
            f"{'complete' if summary.get('complete', True) else 'incomplete'}. {what_ran(spec.scenario, {})}")
    return report_html(f"symtrack field: {spec.name}", summary, images, files["field.resolved.toml"], note=note,
                       tables=tables)


def _at(v, j):
    return v[j] if isinstance(v, list) and j < len(v) else None


def soil_table(soil: dict, depths_m, preset: str = "") -> tuple[list, list]:
    """The report's description of the soil (``preset``: what it was made from): per layer its texture, initial
    dry bulk density and matric suction, and at each subsoil depth the precompression stress (header, rows)."""
    from ..soil.pedotransfer import is_layered, subsoil_set

    layers = [("topsoil" if is_layered(soil) else "the soil", soil)]
    if is_layered(soil):
        layers.append((f"subsoil (from {float(soil['subsoil_top_m']):g} m)", subsoil_set(soil)))
    rows = [["preset", preset]] if preset else []
    rows += [[f"{name}: clay / silt / sand [kg/kg]", f"{sp['clay_kg_per_kg']:.3g} / {sp['silt_kg_per_kg']:.3g} / "
             f"{sp['sand_kg_per_kg']:.3g}"] for name, sp in layers]
    rows += [[f"{name}: initial dry bulk density [Mg/m^3]", f"{sp['bulk_density_initial_Mg_per_m3']:.4g}"]
             for name, sp in layers]
    rows += [[f"{name}: matric suction [kPa]", f"{sp['matric_suction_kPa']:.4g}"] for name, sp in layers]
    if depths_m:
        pc = density.precompression_table([soil], list(depths_m))[0]
        rows += [[f"precompression stress at {d:g} m [kPa]", f"{1e-3 * float(v):.4g}"] for d, v in zip(
            depths_m, pc, strict=True)]
    return ["soil", "value"], rows
