"""The full fidelity of a region study (docs/region.md, "A mixed run"): a field's season with each operation's
plan driven over the field's own terrain, the way ``symtrack field`` drives a season, instead of swept by the
machine's quasi-static footprint (:mod:`symtrack.region.fast`).

The field is a :class:`~symtrack.terrain.storage.Terrain` on the field's grid (its frame, the study's cells and
depths), starting the season from the compression state the season before left (the same state the fast
fidelity carries: tillage and the seasons as there). Each operation, in the order of the days worked, with the
soil of its day (its moisture class):

- a **tracked machine** is the package's vehicle (``[full_fidelity] vehicle``, a vehicle preset; default the
  reference crawler) with the machine's contact length, track width, gauge and mass (its other parameters, the
  inertia among them, the preset's: ASSUMED), driven along the plan by the path follower on the terrain engine
  (:func:`symtrack.studies.operations.run_operation`: its turns driven on the soil, the engine's sinkage, rut,
  stress under the moving, pitching tracks, each cell's compression bounded by its rut). The engine needs cells
  narrower than the track (``cell_m`` below the track width) and a turn the vehicle holds on the soil (a trim):
  both are checked before any work. Passes per cell are the engine's (a cell re-entered after 1 s out of every
  contact), its trafficked cells those a track's contact overlapped;
- a **wheeled machine** is driven along the same plan as the package's wheeled pass
  (:func:`symtrack.vehicles.wheeled.wheeled_pass`): every wheel's Keller contact at every pose of the path
  (sampled every quarter cell), the stress of all the wheels summed at each cell within 1.5 m (beside the tyres
  too, not only under them), no rut. Passes per cell: one per segment of the plan whose wheels' swept strips
  (the wheel centres' paths widened by the tyre widths) hold the cell's centre.

As the terrain engine folds a drive, each drive of an operation (its ``repeat`` drives) folds every cell's
compression once, at the largest stress the drive gave it (:func:`symtrack.soil.density.pass_update`); the risk
ratio is graded against the day's precompression stress as in the fast fidelity. The outputs (the maps, the
summary) have the fast fidelity's schema; ``fidelity`` says which produced them.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ParameterError, ScenarioError, SymtrackError
from ..presets import vehicle_preset
from ..simulation.plants import make_plant
from ..soil import density
from ..studies.operations import operation_of, plan_operation, run_operation
from ..terrain.storage import Grid, Terrain
from ..vehicles import wheeled
from .fast import SeasonMaps
from .fleet import TYRE_ELEMENT_M, footprint_table_cached

__all__ = ["DEFAULT_VEHICLE", "FULL_KEYS", "FullFidelity", "check_full_operations", "engine_operation",
           "parse_full_fidelity", "run_season_full"]

FULL_KEYS = ("fields", "share", "vehicle")
DEFAULT_VEHICLE = "reference_crawler"
# the preset under a region soil described without one (the day's soil gives every soil parameter over it; the
# preset only brings the coefficients of other soil laws, which the engine's law does not read)
BASE_SOIL_PRESET = "sandy_loam_15"
# the engine's scenario of a tracked machine's drive (the built-in seasons' settings: symtrack/studies/fields)
ENGINE_RUN = {"integrator": "grid_fast", "output_dt_s": 0.01}
ENGINE_MODEL = {"lateral_law": "shear"}
# who drives the plan: the path-following torque law (symtrack.studies.operations.PathFollower). The MPC follower
# ("rti", the operations' default) left the path of a generated polygon field's headland rounds (1 m lateral
# error) where the law held it
ENGINE_FOLLOWER = "law"
# the wheeled pass's stress tables (symtrack.vehicles.tyre.footprint_table): 2 cm steps out to the wheel pass's
# reach beyond the contact (the tables' own default, 1 cm, has four times the points to sum the contact over; the
# fast fidelity's profiles are tabulated at 3 cm, within 0.6 % of 1 cm at 0.1 m depth: symtrack/region/fleet.py)
TABLE_STEP_M = 0.02


@dataclasses.dataclass(frozen=True)
class FullFidelity:
    """``[full_fidelity]``: the fields named, the share of the others drawn, the vehicle preset of the tracked
    machines."""

    fields: tuple = ()
    share: float = 0.0
    vehicle: str = DEFAULT_VEHICLE

    def choose(self, field_ids: list, seed: int) -> set:
        """The fields run in the full fidelity: those named, and ``share`` of the others (rounded to the nearest
        count) drawn with the study's seed."""
        named = set(self.fields)
        others = [f for f in field_ids if f not in named]
        k = int(round(self.share * len(others)))
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xF0F1]))
        drawn = {others[int(i)] for i in rng.choice(len(others), size=k, replace=False)} if k else set()
        return named | drawn


def parse_full_fidelity(t, field_ids) -> FullFidelity:
    """``[full_fidelity]`` -> :class:`FullFidelity`, its field ids checked against the fields file's."""
    if not isinstance(t, dict):
        raise ScenarioError("[full_fidelity] must be a table: fields (field ids), share (of the other fields), "
                            "vehicle (a vehicle preset)")
    check_keys("full_fidelity", t, FULL_KEYS)
    names = t.get("fields", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ScenarioError(f"full_fidelity.fields = {names!r} must be a list of field ids")
    known = set(field_ids)
    for i, n in enumerate(names):
        if n not in known:
            some = ", ".join(list(field_ids)[:8]) + (" ..." if len(field_ids) > 8 else "")
            raise ScenarioError(f"full_fidelity.fields[{i}] = {n!r} is not a field of fields_file (its fields: "
                                f"{some})")
    if len(set(names)) != len(names):
        raise ScenarioError(f"full_fidelity.fields = {names!r}: a field is named twice")
    share = number("full_fidelity.share", t.get("share", 0.0), 0.0, 1.0)
    vehicle = t.get("vehicle", DEFAULT_VEHICLE)
    try:
        vehicle_preset(vehicle)
    except (ParameterError, ScenarioError, KeyError, TypeError) as err:
        raise ScenarioError(f"full_fidelity.vehicle = {vehicle!r}: {err}") from None
    return FullFidelity(tuple(names), share, vehicle)


# ---- a tracked machine on the terrain engine ---------------------------------------------------------------------
def _grid_settings(fs, shape, cell_m: float):
    """The operation's settings on the grid's exact extent (the engine's field is the grid; the plan is the
    polygon's)."""
    return dataclasses.replace(fs, size_m=(shape[0] * cell_m, shape[1] * cell_m))


def engine_operation(op, vehicle: str, depths_m, shape, cell_m: float, soil_preset: str = BASE_SOIL_PRESET):
    """(settings, plan, scenario, steering rows) of a tracked machine's operation on the terrain engine (module
    doc), planned and checked (the footprint in the field, the turn held on the day's soil: every soil parameter
    of the day given over ``soil_preset``, the region soil's preset)."""
    t = op.machine.tracks
    if not cell_m < t.track_width_m:
        raise ScenarioError(f"cell_m = {cell_m:g}: the full fidelity drives machine {op.machine.name!r} on the terrain "
                            f"engine, whose cells must be narrower than its track ({t.track_width_m:g} m): the allowed "
                            f"range is (0, {t.track_width_m:g}) m")
    soil = {k: float(v) for k, v in op.soil_day.items()}
    doc = {"name": op.name, "run": dict(ENGINE_RUN), "model": dict(ENGINE_MODEL),
           "vehicle": {"preset": vehicle, "contact_length_m": t.contact_length_m, "track_width_m": t.track_width_m,
                       "track_gauge_m": t.track_gauge_m, "mass_kg": t.mass_kg},
           "soil": {"preset": soil_preset, **soil}, "terrain": {"subsoil_depths_m": [float(d) for d in depths_m]}}
    return operation_of(doc, dataclasses.replace(_grid_settings(op.settings, shape, cell_m), follower=ENGINE_FOLLOWER))


def check_full_operations(ops, vehicle: str, depths_m, shape, cell_m: float, where: str,
                          soil_preset: str = BASE_SOIL_PRESET) -> None:
    """Every tracked machine's operation of a full field-season planned for the engine and checked (module doc)
    before any work; a refusal names ``where`` (the field and the year)."""
    for op in ops:
        if op.machine.tracks is not None:
            try:
                engine_operation(op, vehicle, depths_m, shape, cell_m, soil_preset)
            except ScenarioError as err:
                raise ScenarioError(f"{where}, operation {op.name!r} in the full fidelity: {err}") from None


def _engine_drive(op, terrain: Terrain, vehicle: str, depths_m, soil_preset: str) -> tuple:
    """One drive of the operation's plan on the engine (module doc): (passes per cell, its figures)."""
    eop = engine_operation(op, vehicle, depths_m, terrain.grid.shape, terrain.grid.cell_m, soil_preset)
    terrain.soil = None  # the day's soil, written in by the world (the soil changes with the day's moisture)
    plant = make_plant(eop[2], terrain=terrain)
    r = run_operation(eop, plant)
    if plant.world.storage is not terrain:  # (the world works on the field's own terrain, in place)
        raise SymtrackError("the terrain engine did not drive on the field's terrain")
    if r.error:
        raise SymtrackError(f"operation {op.name!r} (machine {op.machine.name!r}) in the full fidelity: {r.error}")
    keep = ("complete", "turns_driven", "path_length_m", "distance_m", "sim_time_s", "rut_max_depth_mm",
            "rms_lateral_error_lines_m", "max_lateral_error_lines_m", "follower", "cpu_time_s")
    return r.counts.astype(np.int32), {"carrier": "tracks on the terrain engine",
                                       **{k: r.figures.get(k) for k in keep}}


# ---- a wheeled machine: the package's wheeled pass ---------------------------------------------------------------
def _wheeled_drive(op, terrain: Terrain, xi: float) -> tuple:
    """One drive of the operation's plan as the wheeled pass (module doc): (passes per cell, its figures)."""
    import shapely
    from shapely.geometry import LineString


    g = terrain.grid
    cell = g.cell_m
    depths = tuple(terrain.subsoil_depths_m)
    plan = plan_operation(op.settings, ds_m=0.25 * cell)
    p = plan.path
    end = int(np.nonzero(p.segment == -1)[0][0]) + 1  # the path's end (the extension after it left out)
    poses = np.column_stack([p.x[:end], p.y[:end], p.psi[:end]])
    wheels, tables = [], []
    for w in op.machine.wheels:  # (each tyre, load and soil's table computed once into the cache)
        c, tb = footprint_table_cached(w.tyre, w.load_kN, w.inflation_kPa, TYRE_ELEMENT_M, depths, xi,
                                wheeled.DEFAULT_REACH_M + 0.5 * w.tyre.diameter_m, TABLE_STEP_M)
        wheels.append(wheeled.Wheel(c, w.x_m, w.y_m))
        tables.append(tb)
    figs = wheeled.wheeled_pass(terrain, wheels, poses, xi, soils=[dict(op.soil_day)], tables=tables)
    # passes per cell: per segment, the cells whose centre is under a wheel's swept strip
    nx, ny = g.shape
    counts = np.zeros(g.shape, dtype=np.int32)
    seg = p.segment[:end]
    for k in range(len(p.segments)):
        idx = np.nonzero(seg == k)[0]
        if idx.size == 0:
            continue
        idx = np.append(idx, min(idx[-1] + 1, end - 1))  # the segment's end point
        X, Y, P = poses[idx, 0], poses[idx, 1], poses[idx, 2]
        c, s = np.cos(P), np.sin(P)
        hit = None
        for w in op.machine.wheels:
            wx, wy = X + c * w.x_m - s * w.y_m, Y + s * w.x_m + c * w.y_m
            if wx.size < 2 or np.hypot(np.diff(wx), np.diff(wy)).sum() <= 0:
                continue
            strip = LineString(np.column_stack([wx, wy])).buffer(0.5 * w.width_m, cap_style="flat")
            x0, y0, x1, y1 = strip.bounds
            i0, i1 = max(int(math.floor(x0 / cell)), 0), min(int(math.ceil(x1 / cell)) + 1, nx)
            j0, j1 = max(int(math.floor(y0 / cell)), 0), min(int(math.ceil(y1 / cell)) + 1, ny)
            if i1 <= i0 or j1 <= j0:
                continue
            xc, yc = np.meshgrid((np.arange(i0, i1) + 0.5) * cell, (np.arange(j0, j1) + 0.5) * cell, indexing="ij")
            inside = np.zeros(g.shape, dtype=bool)
            inside[i0:i1, j0:j1] = shapely.contains_xy(strip, xc, yc)
            hit = inside if hit is None else hit | inside
        if hit is not None:
            counts += hit
    return counts, {"carrier": "wheels (the wheeled pass)", "path_length_m": float(p.s[end - 1]),
                    "poses": int(poses.shape[0]), "cells_loaded": figs["cells_loaded"]}


# ---- the season --------------------------------------------------------------------------------------------------
def run_season_full(ops, shape, cell_m: float, depths_m, xi: float, vehicle: str = DEFAULT_VEHICLE,
                    state: np.ndarray | None = None, field_mask: np.ndarray | None = None,
                    soil_preset: str = BASE_SOIL_PRESET) -> SeasonMaps:
    """A field's season in the full fidelity (module doc): ``ops`` (:class:`~symtrack.region.fast.FastOp`, the
    same list the fast fidelity takes) in the order worked, on a grid of ``shape`` cells of ``cell_m`` in the
    field's frame; ``state`` the compression state it starts from (None: initial); ``xi`` the soil's stress
    concentration factor (the wheeled pass's); ``soil_preset`` the region soil's preset (the engine's scenario).
    Returns the fast fidelity's :class:`SeasonMaps`."""
    nx, ny = shape
    nd = len(depths_m)
    depths = np.asarray(depths_m, dtype=float)
    terrain = Terrain(Grid((0.0, 0.0), float(cell_m), (int(nx), int(ny))), None, tuple(depths_m))
    if state is not None:
        terrain.specific_volume[:] = state
    counts = np.zeros(shape, dtype=np.int64)
    sig_max = np.zeros((nx, ny, nd), dtype=np.float32)
    ratio_max = np.zeros((nx, ny, nd), dtype=np.float32)
    cells_field = np.flatnonzero(field_mask.ravel()) if field_mask is not None else np.arange(nx * ny)
    figs = []
    for op in ops:
        t0 = time.perf_counter()
        arrays = density.soil_arrays([op.soil_day], list(depths_m))
        geo = density.geostatic_table([op.soil_day], list(depths_m))
        terrain.sigma_max[:] = 0.0  # the operation's own stress (its drives' largest)
        c_op = np.zeros(shape, dtype=np.int64)
        drives = []
        for _ in range(op.repeat):
            if op.machine.tracks is not None:
                c1, fig = _engine_drive(op, terrain, vehicle, depths_m, soil_preset)
            else:
                c1, fig = _wheeled_drive(op, terrain, xi)
            c_op += c1
            drives.append(fig)
        s_op = terrain.sigma_max.reshape(-1, nd)
        ratio = np.where(s_op > 0, (s_op + geo[0]) / arrays["pc"][0], 0.0).astype(np.float32)
        rm, sm = ratio_max.reshape(-1, nd), sig_max.reshape(-1, nd)
        np.maximum(rm, ratio, out=rm)
        np.maximum(sm, s_op, out=sm)
        counts += c_op
        if op.loosens_to_m is not None:  # tillage: the layer loosened, the ruts levelled (the surface as new)
            above = depths < op.loosens_to_m
            sub = terrain.specific_volume[cells_field]
            sub[:, above] = 0.0
            terrain.specific_volume[cells_field] = sub
            for a in (terrain.z, terrain.zdot, terrain.zmax, terrain.pmax, terrain.phase, terrain.zoff,
                      terrain.cycles):
                a[cells_field] = 0
        figs.append({"name": op.name, "machine": op.machine.name, "day": op.day, "repeat": op.repeat,
                     "matric_suction_kPa": float(op.soil_day["matric_suction_kPa"]),
                     "precompression_stress_topsoil_kPa": 1e-3 * float(arrays["pc"][0, 0]),
                     "cells_passed": int(np.count_nonzero(c_op)), "loosens_to_m": op.loosens_to_m,
                     "drives": drives, "wall_time_s": time.perf_counter() - t0})
    return SeasonMaps(np.minimum(counts, np.iinfo(np.uint16).max).astype(np.uint16), sig_max, ratio_max,
                      terrain.specific_volume.copy(), figs)
