"""Scenarios on the grid terrain: the world of a scenario, passes, per-pass figures, outputs.

``symtrack simulate SCENARIO`` comes here when the scenario has a ``[terrain]`` section (or
``--terrain-in`` / ``--terrain-out`` is given). Output folder:

- one pass: the files of an ordinary run (``trajectory.csv`` with the vehicle states and the
  outputs, no channel columns; ``scenario.resolved.toml``; plots; ``summary.json`` with the
  terrain figures) plus ``sinkage_map.png`` and ``rut_section.png``;
- several passes: ``pass_1/``, ``pass_2/``, ... each with the files of one run, and at the top
  ``sinkage_map_pass_<k>.png``, ``rut_section.png`` and ``summary.json`` (schema below).

summary.json of a terrain study (``schema_version`` 1): the runner's summary keys of the last
pass, the terrain figures (``terrain_*``), and ``passes``: a list with, per pass,
``rut_max_depth_mm``, ``rut_mean_depth_mm`` (mean sinkage over the rut: the cells loaded in
the pass, z_max > 1 um), ``new_sinkage_mean_mm`` (mean sinkage added by the pass over the rut),
``new_sinkage_volume_m3``, ``compaction_resistance_mean_N`` (time mean of the sum of both
tracks' compaction resistance), ``distance_m``, ``sim_time_s``, ``wall_time_s``; with several
passes also ``later_passes_add_less_sinkage`` and ``later_passes_meet_less_resistance``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from ..errors import ScenarioError
from .config import settings_from_dict, validate_section
from .world import NV, World

RUT_THRESHOLD_M = 1e-6
GRID_INTEGRATORS = ("idas", "rosenbrock", "grid_fast")  # rosenbrock: compiled_grid.py; grid_fast: engine.py


def make_world(scenario, terrain_in: str | None = None) -> World:
    from . import persist

    t = scenario.extra.get("terrain")
    if t is None:
        raise ScenarioError("the scenario has no [terrain] section")
    s = settings_from_dict(t)
    if scenario.run.integrator not in GRID_INTEGRATORS:
        raise ScenarioError(
            f"run.integrator = {scenario.run.integrator!r}: the grid terrain runs with run.integrator = \"idas\", "
            "\"rosenbrock\" (the DAE form keeps the Jacobian an arrowhead; see symtrack/terrain/channels.py) or "
            "\"grid_fast\" (the terrain engine, symtrack/terrain/engine.py)")
    if scenario.run.compiled:
        raise ScenarioError("run.compiled = true is not available with the grid terrain")
    path = terrain_in or s.initial_state
    storage = None
    if path:
        storage = persist.load(path, scenario.soil)
        g = storage.grid
        explicit = "cell_m" in t or "size_m" in t
        if explicit and (abs(g.cell_m - s.cell_m) > 1e-12 or tuple(g.shape) != tuple(s.shape)):
            raise ScenarioError(
                f"{path}: the terrain file has {g.shape[0]} x {g.shape[1]} cells of {g.cell_m} m, the scenario's "
                f"[terrain] asks for {s.shape[0]} x {s.shape[1]} cells of {s.cell_m} m (size_m = {list(s.size_m)}); "
                "make them agree")
        s = dataclasses.replace(s, cell_m=g.cell_m, size_m=(g.shape[0] * g.cell_m, g.shape[1] * g.cell_m))
    return World(s, scenario.params, scenario.model, scenario.run.output_dt_s,
                 start_xy=(scenario.start.x_m, scenario.start.y_m), storage=storage)


def vehicle_only(res):
    """The run's result without the channel states (the trajectory file stays small)."""
    return dataclasses.replace(res, X=res.X[:, :NV], state_names=res.state_names[:NV])


def pass_figures(world: World, z_before: np.ndarray, res, touched: np.ndarray) -> dict:
    st = world.storage
    z = st.z
    rut = touched & (st.zmax > RUT_THRESHOLD_M)
    dz = z - z_before
    area = world.grid.cell_m ** 2
    rc = res.output("compaction_resistance_left_N") + res.output("compaction_resistance_right_N")
    tt = res.t
    rc_mean = float(np.sum(0.5 * (rc[1:] + rc[:-1]) * np.diff(tt)) / (tt[-1] - tt[0])) if tt[-1] > tt[0] else 0.0
    seg = np.hypot(np.diff(res.X[:, 0]), np.diff(res.X[:, 1]))
    return {
        "rut_max_depth_mm": 1e3 * float(z[rut].max()) if rut.any() else 0.0,
        "rut_mean_depth_mm": 1e3 * float(z[rut].mean()) if rut.any() else 0.0,
        "new_sinkage_mean_mm": 1e3 * float(dz[rut].mean()) if rut.any() else 0.0,
        "new_sinkage_volume_m3": float(dz.sum() * area),
        "compaction_resistance_mean_N": rc_mean,
        "rut_cells": int(rut.sum()),
        "distance_m": float(seg.sum()),
        "sim_time_s": float(res.t[-1]),
        "wall_time_s": float(res.wall_time_s),
    }


def run_passes(scenario, world: World | None = None, progress: bool = False):
    """All passes of the scenario on one world. Returns (world, results, per-pass figures, maps)."""
    from .. import runner
    from .config import settings_of

    world = world or make_world(scenario)
    n = settings_of(scenario).passes
    results, figures, maps = [], [], []
    for _ in range(n):
        z0 = world.storage.z.copy()
        res = runner.run(scenario, progress=progress, world=world)
        figures.append(pass_figures(world, z0, res, world.touched.copy()))
        maps.append(world.storage.copy_z())
        results.append(res)
    return world, results, figures, maps


def simulate_cli(args, sc) -> int:
    """``symtrack simulate`` for a scenario on the grid terrain."""
    from .. import output, plots, runner, validation
    from . import persist
    from .plots import rut_section_png, sinkage_map_png

    terrain_in = getattr(args, "terrain_in", None)
    terrain_out = getattr(args, "terrain_out", None)
    if "terrain" not in sc.extra:
        sc = dataclasses.replace(sc, extra={**sc.extra, "terrain": validate_section({})})
    world = make_world(sc, terrain_in)
    world, results, figures, maps = run_passes(sc, world, progress=not args.quiet)
    out = Path(args.out)
    if terrain_out:
        persist.save(terrain_out, world.storage, sc.soil)
    summaries = []
    multi = len(results) > 1
    for k, res in enumerate(results):
        summary = runner.summarise(res)
        summary.update(figures[k])
        summaries.append(summary)
        folder = out / f"pass_{k + 1}"
        if multi:
            trimmed = vehicle_only(res)
            output.write_run(folder, trimmed, summary, plots.all_plots(trimmed))
    top = dict(summaries[-1])
    top["passes"] = figures
    if multi:
        pairs = list(zip(figures[:-1], figures[1:], strict=True))
        top["later_passes_add_less_sinkage"] = all(
            b["new_sinkage_mean_mm"] < a["new_sinkage_mean_mm"] for a, b in pairs)
        top["later_passes_meet_less_resistance"] = all(
            b["compaction_resistance_mean_N"] < a["compaction_resistance_mean_N"] for a, b in pairs)
    if terrain_in:
        top["terrain_in"] = str(terrain_in)
    if terrain_out:
        top["terrain_out"] = str(terrain_out)
    pngs = {}
    line = (sc.start.x_m, sc.start.y_m, np.radians(sc.start.yaw_deg))
    for k, z in enumerate(maps):
        pngs[f"sinkage_map_pass_{k + 1}.png" if multi else "sinkage_map.png"] = sinkage_map_png(world, z, k + 1)
    pngs["rut_section.png"] = rut_section_png(world, maps, results, line)
    if multi:
        for name, data in pngs.items():
            output.atomic_write_bytes(out / name, data)
        output.atomic_write_text(out / "summary.json", json.dumps(top, indent=2) + "\n")
    else:
        trimmed = vehicle_only(results[0])
        pngs.update(plots.all_plots(trimmed))
        output.write_run(out, trimmed, top, pngs)
    if sc.run.stop_distance_event == "idle" and "validation" in sc.name:
        table = validation.table_markdown(top)
        output.atomic_write_text(out / "validation_table.md", table)
        print(table)
    for k, f in enumerate(figures):
        print(f"pass {k + 1}: rut max {f['rut_max_depth_mm']:.3f} mm, mean {f['rut_mean_depth_mm']:.3f} mm, "
              f"new sinkage {f['new_sinkage_mean_mm']:.4f} mm, compaction resistance "
              f"{f['compaction_resistance_mean_N']:.1f} N")
    print(f"{sc.name}: {sum(r.t[-1] for r in results):.2f} s simulated in "
          f"{sum(r.wall_time_s for r in results):.2f} s on {world.grid.n_cells} cells through {world.n_channels} "
          f"channels (peak {max(r.terrain['terrain_peak_active_cells'] for r in results)} active); results in {out}")
    return 0
