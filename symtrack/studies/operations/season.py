"""The season runner: one operation on the terrain engine (:func:`run_operation`), a season of operations on one
field (:func:`run_season`) and the comparison of traffic systems (:func:`traffic_comparison`).

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass

import numpy as np

from ...foundations.config import to_toml
from ...foundations.files import check_output_folder
from ...simulation import loop
from ...simulation.plants import make_plant
from ...terrain.storage import Terrain
from .followers import PathFollower, follower_of, mpc_follower
from .footprints import count_passes_and_times, field_shares
from .outputs import (
    OperationResult,
    TrafficComparison,
    animation,
    counts_npz,
    map_pngs,
    season_animation,
    traffic_files,
    traffic_row,
)
from .plans import OperationPlan
from .settings import COUNT_SAMPLE_S, SCHEMA_VERSION
from .spec import OperationSpec, operation_spec_from_dict


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
        law, start, mpc = mpc_follower(plan, sc, plant, fs, limit)
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

    FIGURES = ("trafficked_fraction", "headland_trafficked_fraction", "infield_trafficked_fraction",
               "rut_max_depth_mm", "distance_m", "turns_driven", "rms_lateral_error_lines_m",
               "energy_sprockets_J", "energy_compaction_J", "sim_time_s", "build_s", "wall_time_s")

    def __repr__(self) -> str:
        from ...reports.html import short_repr

        return short_repr("SeasonResult", self.spec.name, self.summary,
                          ("trafficked_fraction", "rut_max_depth_mm", "sim_time_s", "wall_time_s"))

    def _repr_html_(self) -> str:
        """The view in a notebook: what ran (the operations in order, each with its machine; the field, the
        soil, the integrator), the season's figures with their units and the run time, then one row of
        figures per operation."""
        from ...reports.html import machine_facts, notebook_html

        s = self.summary
        size = s.get("field_size_m") or list(self.spec.base.size_m)
        ops = []
        for fs, _plan, sc, _rows in self.spec.operations:
            vehicle = machine_facts(sc.vehicle_preset, sc.soil_preset, sc.params)[0][1]
            ops.append(f"{fs.name} ({vehicle})")
        sc0 = self.spec.operations[0][2] if self.spec.operations else None
        facts = [("season", self.spec.name), ("operations", "; ".join(ops)),
                 ("field", f"{size[0]:g} m x {size[1]:g} m, {s.get('field_cell_m', self.spec.base.cell_m):g} m cells")]
        if sc0 is not None:
            facts += [("soil", machine_facts(sc0.vehicle_preset, sc0.soil_preset)[1][1]),
                      ("integrator", sc0.run.integrator)]
        per_op = ("distance_m", "rut_max_depth_mm", "sim_time_s", "wall_time_s")
        rows = [[r.name, *(r.figures.get(k) for k in per_op)] for r in self.operations]
        return notebook_html(f"season {self.spec.name!r}", s, facts, keys=self.FIGURES, rows=rows or None,
                             row_header=["operation", *per_op])


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
                            f"{sub}/passes_per_cell.npz": counts_npz(r.counts, fs.cell_m)}
                if figures:
                    op_files |= {f"{sub}/{n}": b for n, b in
                                 map_pngs(r.counts, terrain.z.reshape(r.counts.shape), fs, label).items()}
                    op_files[f"{sub}/animation.gif"] = animation(r, terrain, fs, label, progress)
                    if k == 0:  # the season's own, of every operation, replaces it below when there are more
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
    if folder is not None and figures and len(results) > 1:
        files["animation.gif"] = season_animation(results, terrain, fs0, [r.name for r in results], spec.name,
                                                  progress)
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
        files["passes_per_cell.npz"] = counts_npz(counts, fs0.cell_m)
        if figures:
            files |= map_pngs(counts, terrain.z.reshape(counts.shape), fs0, f"{spec.name}, {len(results)} operations")
        files["report.html"] = _season_report(spec, summary, files, results).encode()
        files["summary.json"] = json.dumps(summary, indent=2) + "\n"
        from ...reports.run_files import write_folder

        written = write_folder(folder, files, clear=False)
        terrain.save(folder / "field.npz")
        written.append(folder / "field.npz")
    return SeasonResult(spec, results, summary, counts, terrain, written)


def _season_report(spec, summary: dict, files: dict, results) -> str:
    """report.html of an operation or a season: what ran, each operation's scalar figures, the season's
    maps (the animation is its own file), the resolved run file."""
    from ...reports.html import report_html

    images = {n: d for n, d in files.items() if n.endswith(".png") and "/" not in n}
    names = [r.figures.get("name", f"operation {k + 1}") for k, r in enumerate(results)]
    keys = [k for k, v in results[0].figures.items() if isinstance(v, (bool, int, float, str))] if results else []
    rows = [[k, *(r.figures.get(k) for r in results)] for k in keys]
    note = (f"'{spec.name}': {len(results)} operation(s), {summary.get('turns_driven', 0)} turns driven; "
            f"{'complete' if summary.get('complete') else 'incomplete: ' + str(summary.get('error'))}."
            + (f" The animation: {summary['animation_gif']}." if summary.get("animation_gif") else ""))
    if spec.operations:
        from ...reports.html import machine_facts

        machines = "; ".join(f"{fs.name}: {machine_facts(sc.vehicle_preset, sc.soil_preset, sc.params)[0][1]}"
                             for fs, _plan, sc, _rows in spec.operations)
        sc0 = spec.operations[0][2]
        note += (f" Ran: {machines}; on {machine_facts(sc0.vehicle_preset, sc0.soil_preset)[1][1]}, "
                 f"integrator {sc0.run.integrator}.")
    return report_html(f"symtrack field: {spec.name}", summary, images, files["operation.resolved.toml"], note=note,
                       tables={"Operations": (["figure", *map(str, names)], rows)} if results else None)


def _rms_of(results, role: int):
    parts = [r.log[r.log[:, 4] == role, 2] for r in results if r.log.size]
    e = np.concatenate(parts) if parts else np.zeros(0)
    return float(np.sqrt(np.mean(e ** 2))) if e.size else None


def Path_(p):
    from pathlib import Path as _P

    return _P(p)


def traffic_comparison(doc: dict, systems, out=None, progress: bool = False,
                       name: str = "operation") -> TrafficComparison:
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
        from ...reports.run_files import write_folder

        write_folder(folder, traffic_files(rows), clear=False)
    return TrafficComparison(name, rows)
