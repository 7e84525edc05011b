"""A region study on Dask: one task per field and season, resumable, with progress (docs/region.md, "Running").

    from symtrack.region import load_region, run_region
    res = run_region(load_region("my_region.toml"), out="out/region", workers=2)

The folder::

    DIR/region.json                        the study: its inputs resolved, the fields, the years
    DIR/fields/<field_id>/<year>/maps.npz  the field-season's maps on its own grid (docs/region.md, "Outputs")
    DIR/fields/<field_id>/<year>/*.tif     the same maps as Cloud-Optimized GeoTIFFs on the field's grid, in the
                                           region's CRS ([outputs] field_maps; symtrack.region.outputs.field_cogs)
    DIR/fields/<field_id>/<year>/summary.json
                                           its figures, written last: a field-season whose summary.json is there
                                           is finished, and a rerun into the folder skips it
    DIR/fields.csv, DIR/fields.gpkg        one row per field-season (:func:`symtrack.region.table.TABLE_COLUMNS`;
                                           the GeoPackage with the fields' polygons: symtrack.region.gpkg)
    DIR/maps/<year>/*.tif, DIR/maps/all_years/*.tif
                                           the region's maps (Cloud-Optimized GeoTIFFs)
    DIR/report.html, DIR/summary.json      the report and the region's figures

The client writes every file, from the bytes the tasks return (a cluster needs no shared file system), through
the package's run writer (:func:`symtrack.reports.run_files.write_folder`): each field-season committed once as
it finishes, the study's own files committed together at the end (symtrack.region.outputs). A field's seasons
run in order (each starts from the compression state the one before left); the fields run in parallel. Each
field runs in its fidelity: the fast one (:mod:`symtrack.region.fast`), or the full one on the fields
``[full_fidelity]`` chooses (:mod:`symtrack.region.full`; its tracked machines' operations checked for the
terrain engine before any work, :func:`check_full`). The tables (the machines' stress profiles on each soil, the
soils of each moisture class) are built once, before any task, and sent to the workers once.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foundations.errors import ScenarioError, SymtrackError
from ..foundations.files import check_output_folder, npz_bytes
from ..foundations.progress import Progress
from ..reports.run_files import output_lock, recover, write_folder
from ..studies.operations import OperationSettings, field_mask, headland_mask, plan_operation
from ..studies.traffic_seasons import TRAMLINE_SEED, auto_headland_passes
from .fast import PLAN_DS_M, FastOp, density_change, risk_classes, run_season_fast
from .fleet import rut_table_m, stress_profile
from .full import BASE_SOIL_PRESET, DEFAULT_VEHICLE, check_full_operations, run_season_full
from .inputs import RegionSpec, class_soil, class_suction_kPa, draw_day, field_frame, moisture_class

__all__ = ["Context", "RegionResult", "build_context", "check_full", "check_plans", "check_worker_memory",
           "class_soils", "field_season", "field_season_ops", "run_region", "task_memory_bytes"]

log = logging.getLogger("symtrack.region")

SCHEMA_VERSION = 1
# the full fidelity's cost per hectare-season over the fast one's, for the progress's time left only (measured on
# the demo's fields: 214-260, docs/region.md, "A mixed run")
FULL_COST_RATIO = 240.0
# A fast field-season's memory on a worker (docs/region.md, "Memory"): the worker's resident set once it has run a
# field-season (the package, the context, Dask's own: 134-169 MB measured on a LocalCluster worker after a first
# field-season of the demo's generator) and a season's peak above what the process held before it, per cell and
# depth of the field's grid: a process's first season, the largest (its per-process tables built on the way),
# 94-100 B on 4.1 and 31 ha grids at 0.5 m with four depths (docs/region.md's region-worker-memory table) and 105 B
# on a 12 ha one (tests/test_region_dask.py); a worker's later seasons 60-80 B. Both rounded up
WORKER_BASE_BYTES = 0.17e9
TASK_BYTES_PER_CELL_DEPTH = 120.0


@dataclass
class Context:
    """What every task needs, built once on the client (module doc): the spec, the machines' stress profiles
    by (machine, soil) and the soils by (soil, moisture class)."""

    spec: RegionSpec
    profiles: dict
    class_soils: dict


@dataclass
class RegionResult:
    out: Path
    rows: list
    ran: int
    skipped: int
    wall_time_s: float
    summary: dict
    # the phases' wall times [s]: the plans' check, the cluster's start and the tables, the tasks, the outputs
    phases_s: dict = dataclasses.field(default_factory=dict)


def _settings(spec: RegionSpec, f, op, machine, seed: int) -> OperationSettings:
    hp = op.headland_passes if op.headland_passes is not None else auto_headland_passes(machine,
                                                                                          machine.working_width_m)
    return OperationSettings(name=op.name, size_m=f.size_m, cell_m=spec.cell_m, working_width_m=machine.working_width_m,
                             headland_passes=hp, tracks=op.tracks, random_offset_m=op.random_offset_m, seed=seed,
                             turn="auto", turn_radius_m=machine.turn_radius_m, boundary_file=f"field {f.field_id}",
                             boundary=f.ring)


def _seed(spec: RegionSpec, f, year: int, k: int) -> int:
    return int(np.random.SeedSequence([spec.seed, f.index, year, k]).generate_state(1, dtype=np.uint64)[0] >> 2)


def field_season_plan(spec: RegionSpec, f, year: int) -> list:
    """The operations of a field's season: [(day, calendar index, entry, settings)] in the order worked."""
    series = spec.suction[f.soil][year]
    out, shared, days = [], {}, {}
    for k, op in enumerate(spec.systems[f.system]):
        m = spec.fleet.machines[op.machine]
        if op.same_day_as is not None:
            day = days[op.same_day_as]
        else:
            day = draw_day(series, op.window, spec.workable_suction_kPa,
                           np.random.default_rng(_seed(spec, f, year, k)))
        days[op.name] = day
        if op.same_lines_as is not None:
            fs = _settings(spec, f, op, m, TRAMLINE_SEED + _seed(spec, f, year, 10_000) % 1000)
            if op.same_lines_as in shared:
                first = shared[op.same_lines_as]
                if first.working_width_m != fs.working_width_m:
                    raise ScenarioError(f"systems.{f.system}.operations[{k}].same_lines_as = {op.same_lines_as!r}: "
                                        f"machine {op.machine!r} works {fs.working_width_m:g} m, the first operation "
                                        "on "
                                        f"those lines {first.working_width_m:g} m (one plan needs one width)")
                fs = dataclasses.replace(first, name=op.name)
            else:
                shared[op.same_lines_as] = fs
        else:
            fs = _settings(spec, f, op, m, _seed(spec, f, year, k))
        out.append((day, k, op, fs))
    out.sort(key=lambda r: (r[0], r[1]))
    return out


def _plan_error(spec: RegionSpec, f) -> str | None:
    """The first refusal of a plan of the field's seasons, or None."""
    for y in spec.years:
        for _day, _k, op, fs in field_season_plan(spec, f, y):
            try:
                plan_operation(fs, ds_m=PLAN_DS_M)
            except ScenarioError as err:
                return f"{y}, operation {op.name!r} with machine {op.machine!r}: {err}"
    return None


def check_plans(spec: RegionSpec, progress: bool = False) -> None:
    """Plan every operation of every field's seasons before any work. The track lines run along the field's
    longer side (its minimum rotated rectangle's); where a machine's plan does not fit that way (the polygon
    planner refuses a headland round or a line), across it, then along each of the field's edges in turn (the
    first direction every plan fits is kept: ``lines_direction_deg`` in the field's summary). A field no
    direction fits is refused naming the field and the reason, or, with ``unplannable_fields = "skip"``, left
    out of the study and listed in ``spec.skipped`` (the study's region.json and report)."""
    bar = Progress(len(spec.fields), "checking the fields' plans", enabled=progress)
    kept = []
    for i, f in enumerate(spec.fields):
        err = _plan_error(spec, f)
        if err is not None:
            ring = np.array(f.world_ring)
            edges = np.diff(np.vstack([ring, ring[:1]]), axis=0)
            candidates = [f.theta_rad + 0.5 * math.pi] + [math.atan2(e[1], e[0]) for e in edges]
            for theta in candidates:
                g = dataclasses.replace(f, **field_frame(ring, theta, spec.margin_m))
                if _plan_error(spec, g) is None:
                    f, err = g, None
                    break
        if err is None:
            kept.append(f)
        elif spec.unplannable_fields == "skip":
            spec.skipped.append({"field_id": f.field_id, "reason": f"no direction of the track lines fits every "
                                 f"plan; along its longer side: {err}"})
        else:
            raise ScenarioError(f"field {f.field_id!r} (system {f.system!r}): no direction of the track lines fits "
                                f"every plan; along its longer side: {err} (unplannable_fields = \"skip\" leaves such "
                                "fields out)")
        bar.update(i + 1)
    bar.close()
    if not kept:
        raise ScenarioError("no field of the region can be planned (unplannable_fields = \"skip\" left out all of "
                            "them)")
    spec.fields[:] = kept


def class_soils(spec: RegionSpec) -> dict:
    """The soils of each (soil, moisture class) the study's suction series reach, as parameter dicts."""
    out = {}
    for sname, years in spec.suction.items():
        for s in years.values():
            for k in sorted({moisture_class(x, spec.moisture_class_pF) for x in s}):
                if (sname, k) not in out:
                    out[(sname, k)] = dict(class_soil(spec.soils[sname], class_suction_kPa(k, spec.moisture_class_pF),
                                                      f"soils.{sname}"))
    return out


def _vehicle(spec: RegionSpec) -> str:
    return spec.full_fidelity.vehicle if spec.full_fidelity is not None else DEFAULT_VEHICLE


def _soil_preset(spec: RegionSpec, soil: str) -> str:
    t = spec.document.get("soils", {}).get(soil, {})
    return t.get("preset", BASE_SOIL_PRESET) if isinstance(t, dict) else BASE_SOIL_PRESET


def check_full(spec: RegionSpec, soils_by_class: dict | None = None) -> None:
    """The full fidelity's fields checked before any work (symtrack.region.full): every tracked machine's
    operation of their seasons planned for the terrain engine (its cells narrower than the track, the turn
    held on the day's soil); a refusal names the field, the year and the operation."""
    full = [f for f in spec.fields if f.fidelity == "full"]
    if not full:
        return
    ctx = Context(spec, {}, soils_by_class if soils_by_class is not None else class_soils(spec))
    vehicle = _vehicle(spec)
    for f in full:
        for y in spec.years:
            ops = field_season_ops(ctx, f, y)
            check_full_operations(ops, vehicle, spec.depths_m, _shape(spec, f), spec.cell_m,
                                  f"field {f.field_id!r}, {y}", _soil_preset(spec, f.soil))


def build_context(spec: RegionSpec, client=None) -> Context:
    """The tables, once (module doc): the stress profiles on the client's workers when a client is given."""
    keys, jobs = [], []
    for sname, soil in spec.soils.items():
        xi = float(soil["stress_concentration_factor"])
        used = {op.machine for f in spec.fields if f.soil == sname for op in spec.systems[f.system]}
        for mname in sorted(used):
            keys.append((mname, sname))
            jobs.append((spec.fleet.machines[mname], spec.depths_m, xi))
    if client is not None and jobs:
        futs = [client.submit(stress_profile, *j, pure=False) for j in jobs]
        profiles = dict(zip(keys, client.gather(futs), strict=True))
    else:
        profiles = {k: stress_profile(*j) for k, j in zip(keys, jobs, strict=True)}
    return Context(spec, profiles, class_soils(spec))


def field_season_ops(ctx: Context, f, year: int) -> list:
    """The field-season's :class:`~symtrack.region.fast.FastOp` list in the order worked."""
    spec = ctx.spec
    series = spec.suction[f.soil][year]
    ops = []
    for day, _k, op, fs in field_season_plan(spec, f, year):
        cls = moisture_class(float(series[day - 1]), spec.moisture_class_pF)
        machine, soil_day = spec.fleet.machines[op.machine], ctx.class_soils[(f.soil, cls)]
        # a tracked machine's rut bounds the compression below it (docs/region.md, step 4), as in the fast twin of
        # the check (check.fast_twin) and the terrain engine: the first-pass rut on the day's soil, times N^beta
        ops.append(FastOp(op.name, fs, machine, op.repeat, op.loosens_to_m, ctx.profiles.get((op.machine, f.soil)),
                          soil_day, day, rut_table_m=rut_table_m(machine, soil_day),
                          rut_exponent=float(soil_day["repeated_loading_exponent"])))
    return ops


def _shape(spec: RegionSpec, f) -> tuple:
    return (int(math.ceil(f.size_m[0] / spec.cell_m)), int(math.ceil(f.size_m[1] / spec.cell_m)))


def task_memory_bytes(spec: RegionSpec, f) -> float:
    """A worker's peak resident set [bytes] while it runs a fast field-season of field ``f``
    (:data:`WORKER_BASE_BYTES` plus :data:`TASK_BYTES_PER_CELL_DEPTH` per cell and depth of its grid)."""
    nx, ny = _shape(spec, f)
    return WORKER_BASE_BYTES + TASK_BYTES_PER_CELL_DEPTH * nx * ny * len(spec.depths_m)


def check_worker_memory(spec: RegionSpec, client) -> None:
    """Refuse, before any task, a fast field whose field-season would take a worker past the memory at which Dask
    terminates it (``distributed.worker.memory.terminate`` of its ``memory_limit``: it would be restarted and the
    field tried again until Dask gives up). Workers without a limit, or none connected yet (an existing
    scheduler), are not checked. A full fidelity's field is checked in its task (the terrain world's estimate against
    the worker machine's available memory)."""
    import dask

    try:  # every worker (some versions of distributed list only the first five unless asked)
        info = client.scheduler_info(n_workers=-1)
    except TypeError:  # a distributed without the argument lists them all
        info = client.scheduler_info()
    limits = [w.get("memory_limit") or 0 for w in info.get("workers", {}).values()]
    limits = [x for x in limits if x > 0]
    frac = dask.config.get("distributed.worker.memory.terminate", 0.95)
    if not limits or not frac:
        log.debug("the workers' memory is not checked: %s", "no limit or no worker" if not limits else
                  "Dask's terminate threshold is off")
        return
    limit = min(limits) * float(frac)
    fast = [f for f in spec.fields if f.fidelity == "fast"]
    if not fast:
        return
    need, worst = max(((task_memory_bytes(spec, f), f) for f in fast), key=lambda t: t[0])
    if need > limit:
        nx, ny = _shape(spec, worst)
        raise ScenarioError(
            f"field {worst.field_id!r}: a season on its grid of {nx} x {ny} cells of cell_m = {spec.cell_m:g} m "
            f"({nx * ny * spec.cell_m ** 2 / 1e4:.1f} ha, {len(spec.depths_m)} depths) needs about {need / 1e9:.2f} GB "
            f"on a worker, more than the {limit / 1e9:.2f} GB at which Dask stops a worker ({float(frac):g} of the "
            f"smallest worker's memory_limit {min(limits) / 1e9:.2f} GB): give the workers more memory (fewer local "
            f"--workers share the machine's memory among fewer), raise cell_m (half as many cells at sqrt(2) x), "
            f"or split the field in the fields file")


def field_season(ctx: Context, field_index: int, year: int, prev) -> dict:
    """One task: a field's season in its fidelity (the fast one, or the full one: symtrack.region.full).
    ``prev``: the previous season's result (its ``state``), or the state itself (a rerun's, read back from its
    maps.npz), or None (the first season). Returns {"files": {name: bytes}, "state": float32 array, "summary":
    dict}."""
    t0, c0 = time.perf_counter(), time.process_time()
    spec = ctx.spec
    f = spec.fields[field_index]
    shape = _shape(spec, f)
    state = prev["state"] if isinstance(prev, dict) else prev
    ops = field_season_ops(ctx, f, year)
    fs0 = ops[0].settings
    fmask = field_mask(fs0, shape, spec.cell_m)
    soil0 = spec.soils[f.soil]
    if f.fidelity == "full":
        maps = run_season_full(ops, shape, spec.cell_m, spec.depths_m, float(soil0["stress_concentration_factor"]),
                               _vehicle(spec), state=state, field_mask=fmask,
                               soil_preset=_soil_preset(spec, f.soil))
    else:
        maps = run_season_fast(ops, shape, spec.cell_m, spec.depths_m, state=state, field_mask=fmask,
                               rule=spec.rule)
    drho = density_change(maps.state, soil0, spec.depths_m).reshape(*shape, len(spec.depths_m)).astype(np.float32)
    risk = risk_classes(maps.risk_ratio_max)
    widest = max(ops, key=lambda o: o.settings.headland_m).settings
    head = headland_mask(widest, shape, spec.cell_m) & fmask
    summary = field_summary(spec, f, year, ops, maps, drho, risk, fmask, head)
    sigma_kPa = (1e-3 * maps.sigma_max_Pa).astype(np.float32)
    files = {"maps.npz": npz_bytes(counts=maps.counts, sigma_max_kPa=sigma_kPa,
                                   risk_ratio=maps.risk_ratio_max, risk_class=risk, density_change_Mg_per_m3=drho,
                                   field_mask=fmask, headland_mask=head, state=maps.state,
                                   depths_m=np.asarray(spec.depths_m), cell_m=np.float64(spec.cell_m))}
    if spec.field_maps:  # the same maps as COGs on the field's grid, committed with maps.npz (docs/region.md)
        from .outputs import field_cogs

        files.update(field_cogs(spec, f, {"counts": maps.counts, "sigma_max_kPa": sigma_kPa,
                                          "density_change_Mg_per_m3": drho, "risk_class": risk}))
    summary["wall_time_s"] = time.perf_counter() - t0  # the task's, its files included
    summary["cpu_time_s"] = time.process_time() - c0
    files["summary.json"] = (json.dumps(summary, indent=2) + "\n").encode()
    return {"files": files, "state": maps.state, "summary": summary}


def field_summary(spec, f, year, ops, maps, drho, risk, fmask, head) -> dict:
    """A field-season's figures (a row of fields.csv: docs/region.md, "Outputs")."""
    counts = maps.counts
    run = counts > 0
    area = spec.cell_m ** 2
    n_field = int(fmask.sum())
    inner = fmask & ~head
    out = {"schema_version": SCHEMA_VERSION, "kind": "symtrack-region-field-season", "field_id": f.field_id,
           "soil": f.soil, "soil_from": f.soil_from, "soil_share": f.soil_share, "system": f.system, "year": year,
           "fidelity": f.fidelity, "area_ha": f.area_m2 / 1e4,
           "lines_direction_deg": math.degrees(f.theta_rad),
           "grid_area_ha": n_field * area / 1e4, "cell_m": spec.cell_m,
           "rule": spec.rule if f.fidelity == "fast" else "full: the wheels' strips' centre rule, the engine's overlap",
           "days_worked": {o.name: o.day for o in ops},
           "trafficked_fraction": float(run[fmask].mean()),
           "headland_share": float(head.sum() / max(n_field, 1)),
           "headland_trafficked_fraction": float(run[head].mean()) if head.any() else 0.0,
           "infield_trafficked_fraction": float(run[inner].mean()) if inner.any() else 0.0,
           "repeated_coverage_fraction": float(counts[fmask].astype(np.int64).sum() / max(n_field, 1)),
           "passes_max": int(counts[fmask].max(initial=0)),
           "outside_field_trafficked_m2": float((run & ~fmask).sum() * area),
           "depths_m": list(spec.depths_m)}
    for k, d in enumerate(spec.depths_m):
        tag = f"{d:g}m"
        rk = risk[..., k][fmask]
        for c, nm in enumerate(("low", "medium", "high")):
            # the field's share in each class; "low" includes the cells no machine passed
            out[f"risk_{nm}_fraction_{tag}"] = float((rk == c).mean())
        dk = drho[..., k][fmask]
        out[f"density_change_mean_{tag}_Mg_per_m3"] = float(dk.mean())
        out[f"density_change_trafficked_mean_{tag}_Mg_per_m3"] = float(dk[run[fmask]].mean()) if run[fmask].any() \
            else 0.0
        out[f"density_change_max_{tag}_Mg_per_m3"] = float(dk.max(initial=0.0))
        sk = maps.sigma_max_Pa[..., k][fmask]
        out[f"stress_max_{tag}_kPa"] = float(1e-3 * sk.max(initial=0.0))
    out["operations"] = maps.operations
    return out


# ---- running -------------------------------------------------------------------------------------------------
def _season_dir(out: Path, f, year: int) -> Path:
    return out / "fields" / f.field_id / str(year)


def _done(out: Path, f, year: int) -> bool:
    """The field-season is committed: its summary.json is in place, or a run killed past its commit point
    left it (its journal; completed here, not run again)."""
    d = _season_dir(out, f, year)
    if d.is_dir():
        recover(d)
    return (d / "summary.json").is_file()


def _commit(out: Path, f, year: int, res: dict) -> None:
    """A finished field-season's files committed once (:func:`symtrack.reports.run_files.write_folder`: a kill
    leaves the field-season as it was or whole; summary.json, written last, marks it finished)."""
    write_folder(_season_dir(out, f, year), res["files"])  # staged, then in place with summary.json last


def _state_on_disk(out: Path, f, year: int) -> np.ndarray:
    with np.load(_season_dir(out, f, year) / "maps.npz") as z:
        return z["state"]


def _describe(spec: RegionSpec) -> dict:
    return {"schema_version": SCHEMA_VERSION, "kind": "symtrack-region", "name": spec.name,
            "description": spec.description, "years": list(spec.years), "seed": spec.seed, "cell_m": spec.cell_m,
            "map_cell_m": spec.map_cell_m, "depths_m": list(spec.depths_m), "rule": spec.rule,
            "workable_suction_kPa": spec.workable_suction_kPa, "moisture_class_pF": spec.moisture_class_pF,
            "fleet": spec.fleet.label, "soils": sorted(spec.soils), "systems": sorted(spec.systems),
            "fields": [{"field_id": f.field_id, "soil": f.soil, "system": f.system, "area_ha": f.area_m2 / 1e4,
                        **({"soil_from": f.soil_from, "soil_share": f.soil_share} if f.soil_from != "fields_file"
                           else {}), **({"fidelity": "full"} if f.fidelity == "full" else {})}
                       for f in spec.fields],
            "fields_left_out": spec.skipped,
            **({"fields_full_fidelity": [f.field_id for f in spec.fields if f.fidelity == "full"],
                "full_fidelity_vehicle": spec.full_fidelity.vehicle} if spec.full_fidelity is not None else {}),
            "document": spec.document}


def _check_same_study(out: Path, spec: RegionSpec) -> None:
    try:
        old = json.loads((out / "region.json").read_text())
    except FileNotFoundError:
        return
    except (OSError, ValueError) as err:
        raise ScenarioError(f"--out {str(out)!r}: its region.json cannot be read ({err}); give another "
                            "folder") from None
    new = json.loads(json.dumps(_describe(spec), default=str))
    keys = ("years", "seed", "cell_m", "depths_m", "rule", "fields", "document")
    if any(old.get(k) != new.get(k) for k in keys):
        raise ScenarioError(f"--out {str(out)!r} holds another region study ({old.get('name')!r}); a rerun resumes "
                            "only "
                            "the same study (the same inputs): give another --out")


def run_region(spec: RegionSpec, out, *, workers: int = 2, scheduler: str | None = None, progress: bool = True,
               outputs: bool = True) -> RegionResult:
    """Run the study on Dask and write its folder (module doc). A rerun into the same folder skips the
    finished field-seasons. Ctrl-C cancels the tasks in flight; what was committed stays."""
    from ..studies.engine import check_scheduler_address, dask_client

    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 1024:
        raise ScenarioError(f"--workers {workers!r} must be an integer in [1, 1024]")
    if scheduler:
        check_scheduler_address(scheduler)
    out = check_output_folder(str(out))
    t0 = time.perf_counter()
    check_plans(spec, progress=False)
    check_full(spec)
    phases = {"plans_s": time.perf_counter() - t0}
    _check_same_study(out, spec)
    todo = [(fi, y) for fi, f in enumerate(spec.fields) for y in spec.years if not _done(out, f, y)]
    n_all = len(spec.fields) * len(spec.years)
    skipped = n_all - len(todo)
    say = log.info if progress else log.debug
    say("region %s: %d fields, %.1f ha, %d seasons: %d field-seasons to run, %d finished before; %s", spec.name,
        len(spec.fields), spec.area_ha, len(spec.years), len(todo), skipped,
        f"scheduler {scheduler}" if scheduler else f"{workers} local workers")
    # the folder's lock from before the first write: a second study into it is refused at once (the holder's pid)
    with output_lock(out):
        out.mkdir(parents=True, exist_ok=True)
        region_json = json.dumps(_describe(spec), indent=2, default=str) + "\n"
        # the study's identity first (a rerun into the folder resumes only the same study); the outputs at the end
        # are committed together with it, once (write_outputs)
        write_folder(out, {"region.json": region_json}, clear=False)
        if todo:
            t1 = time.perf_counter()
            with dask_client("region", workers, scheduler) as client:
                check_worker_memory(spec, client)
                t_tables = time.perf_counter()
                ctx = build_context(spec, client)
                say("the tables (%d stress profiles, %d soils by moisture class) in %.1f s", len(ctx.profiles),
                    len(ctx.class_soils), time.perf_counter() - t_tables)
                t2 = time.perf_counter()
                _run_all(out, spec, ctx, todo, client, progress)
                t3 = time.perf_counter()
            phases.update(cluster_s=t_tables - t1, tables_s=t2 - t_tables, tasks_s=t3 - t2)
        rows = [json.loads((_season_dir(out, f, y) / "summary.json").read_text())
                for f in spec.fields for y in spec.years]
        summary = {}
        if outputs:
            from .outputs import write_outputs

            t4 = time.perf_counter()
            summary = write_outputs(spec, out, rows, region_json)
            phases["outputs_s"] = time.perf_counter() - t4
    return RegionResult(out, rows, len(todo), skipped, time.perf_counter() - t0, summary, phases)


def _scheduler_lost(client, err: BaseException) -> bool:
    """Whether a task's error is the loss of the scheduler (Dask cancels every future with the reason
    "scheduler-connection-lost" and the client leaves its running state), not the task's own."""
    return "scheduler-connection-lost" in str(err) or \
        getattr(client, "status", "running") not in ("running", "newly-created")


def _run_all(out: Path, spec: RegionSpec, ctx: Context, todo: list, client, progress: bool) -> None:
    """Submit a field's seasons as a chain (each on the one before) and the fields side by side; commit each
    field-season as it finishes; progress in field-seasons, hectares and the time left."""
    from distributed import as_completed

    from ..studies.engine import SchedulerLost

    ha_total = sum(spec.fields[fi].area_m2 for fi, _ in todo) / 1e4

    def work(f) -> float:  # the time left from the work done: a full field's hectare costs FULL_COST_RATIO fast ones
        return f.area_m2 / 1e4 * (FULL_COST_RATIO if f.fidelity == "full" else 1.0)

    work_total = sum(work(spec.fields[fi]) for fi, _ in todo)
    work_done = 0.0
    bar = Progress(ha_total, f"region {spec.name}", enabled=progress)
    futures = {}
    t0 = time.perf_counter()
    try:
        [cfut] = client.scatter([ctx], broadcast=True)
        by_field: dict = {}
        for fi, y in todo:
            by_field.setdefault(fi, []).append(y)
        for fi, years in by_field.items():
            f = spec.fields[fi]
            k = spec.years.index(years[0])
            prev = _state_on_disk(out, f, spec.years[k - 1]) if k > 0 else None
            for y in years:
                # the largest fields first (the longest tasks first: no worker is left with a large field at the
                # end while the others idle; the outputs do not depend on the order)
                fut = client.submit(field_season, cfut, fi, y, prev, key=f"symtrack-region-{f.field_id}-{y}-"
                                    f"{time.time_ns()}", pure=False, priority=int(round(work(f) * 1000)))
                futures[fut] = (fi, y)
                prev = fut
        done, ha_done = 0, 0.0
        for fut in as_completed(list(futures)):
            fi, y = futures[fut]
            f = spec.fields[fi]
            try:
                res = fut.result()
            except Exception as err:
                if _scheduler_lost(client, err):
                    raise SchedulerLost(done, len(todo)) from err
                raise SymtrackError(f"field {f.field_id!r}, {y}: {type(err).__name__}: {err}") from err
            _commit(out, f, y, res)
            task_s = res["summary"]["wall_time_s"]
            # the client lets go of the committed result: the workers drop it once the field's next season (a
            # task that takes it as its input) has run, so that a worker holds a field-season's result only as
            # long as something needs it, whatever the region's size
            del futures[fut], res
            done += 1
            ha_done += f.area_m2 / 1e4
            work_done += work(f)
            el = time.perf_counter() - t0
            left = el / work_done * (work_total - work_done) if work_done > 0 else float("nan")
            bar.update(ha_done, f"{done}/{len(todo)} field-seasons, {ha_done:.1f}/{ha_total:.1f} ha, about "
                                f"{left:.0f} s left")
            if progress and not bar.enabled:
                log.info("[%d/%d] field %s %d in %.1f s", done, len(todo), f.field_id, y, task_s)
    except KeyboardInterrupt:
        client.cancel(list(futures), force=True)
        raise
    except SchedulerLost as lost:
        raise SymtrackError(f"the Dask scheduler was lost after {lost.done} of {lost.total} field-seasons; the "
                            "finished "
                            f"ones are kept in {out}: start the scheduler and its workers again and rerun the same "
                            "command to do the rest") from None
    finally:
        bar.close()
