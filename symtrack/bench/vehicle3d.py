"""Rows of ``symtrack bench``: the 3D vehicle's cost against the planar one on the homogeneous
validation with the compiled Rosenbrock (the target: at most 2 x; docs/vehicle3d.md), and on
``validation_grid`` through the terrain engine (the million-cell field; the target: at most
1.5 x the planar run and at least 100 x real time, :data:`GRID_TARGET_RATIO`, :data:`GRID_TARGET_RTF`).

Both plants are built once (compiled, cached), then the runs alternate (planar, 3d, planar, ...) so
that a shared machine's load falls on both alike; the ratio is taken between the medians of one
session's CPU times (and wall times). ``quick``: one timed run each, no warm-up (the suite's smoke run).
"""

from __future__ import annotations

import statistics

from ..simulation import loop
from ..simulation.plants import make_plant
from ..simulation.scenario import load_scenario

__all__ = ["GRID_TARGET_RATIO", "GRID_TARGET_RTF", "TARGET_RATIO", "VEHICLES", "bench_rows", "grid_rows",
           "vehicle_runs"]

VEHICLES = ("planar", "3d")
TARGET_RATIO = 2.0  # the homogeneous 3D validation at most 2 x the planar one (compiled Rosenbrock)
GRID_TARGET_RATIO = 1.5  # validation_grid with the 3D vehicle at most 1.5 x the planar run ...
GRID_TARGET_RTF = 100.0  # ... and at least 100 x real time (CPU, one core)
FIGURES = ("yaw_final_deg", "lateral_deviation_m", "sinkage_sprocket_mm", "sinkage_idler_mm")


def vehicle_runs(scenario: str = "validation", repeats: int = 7, warm_up: bool = True, overrides=(),
                 integrator: str | None = "rosenbrock") -> dict:
    """{vehicle: [(wall_s, cpu_s, sim_s, result), ...]} of ``scenario`` with each vehicle of
    :data:`VEHICLES` on ``integrator`` (None: the scenario's own), the runs alternated. A grid plant's
    field is cleared before each run (every run the first pass on virgin soil; outside the timed loop)."""
    plants = {}
    for v in VEHICLES:
        sets = [f"model.vehicle={v}", *([f"run.integrator={integrator}"] if integrator else []), *overrides]
        sc = load_scenario(scenario, sets)
        plants[v] = (sc, make_plant(sc))
    out = {v: [] for v in VEHICLES}
    for k in range(repeats + (1 if warm_up else 0)):
        for v in VEHICLES:
            sc, plant = plants[v]
            if getattr(plant, "world", None) is not None:
                plant.world.clear()
            res = loop.run(sc, plant)
            if warm_up and k == 0:
                continue
            out[v].append((float(res.wall_time_s), float(res.cpu_time_s), float(res.t[-1]), res))
    return out


def bench_rows(quick: bool = False, grid: bool = True) -> list[dict]:
    """One row per vehicle (median wall and CPU time of the alternated runs, the run's figures) and the
    ratio row, on the homogeneous validation; with ``grid``, the same on validation_grid (:func:`grid_rows`)."""
    rows = _rows(vehicle_runs(repeats=1 if quick else 7, warm_up=not quick), "validation: 3D vehicle",
                 "rosenbrock", TARGET_RATIO, 1 if quick else 7)
    return rows + (grid_rows(quick) if grid else [])


def grid_rows(quick: bool = False) -> list[dict]:
    """validation_grid (the million-cell field, the terrain engine) with each vehicle, alternated:
    the rows of :func:`bench_rows` and the ratio against :data:`GRID_TARGET_RATIO`, the 3D run's
    real-time factor against :data:`GRID_TARGET_RTF`."""
    repeats = 1 if quick else 7
    rows = _rows(vehicle_runs("validation_grid", repeats=repeats, warm_up=not quick, integrator=None),
                 "validation_grid: 3D vehicle", "grid_fast", GRID_TARGET_RATIO, repeats)
    rtf = rows[1]["real_time_factor_cpu"]
    rows[2]["real_time_factor_cpu_3d"] = rtf
    rows[2]["target_real_time_factor"] = GRID_TARGET_RTF
    rows[2]["note"] += f"; 3d {rtf:.0f} x real time in CPU time (target >= {GRID_TARGET_RTF:g} x)"
    return rows


def _rows(runs: dict, group: str, integrator: str, target: float, repeats: int) -> list[dict]:
    from ..simulation.result import summarise

    rows, med = [], {}
    for v in VEHICLES:
        rs = runs[v]
        sim = rs[-1][2]
        med[v] = (statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs), sim)
        summ = summarise(rs[-1][3])
        rows.append({"group": group, "case": f"vehicle = {v}", "integrator": integrator, "sim_time_s": sim,
                     "wall_time_s": med[v][0], "real_time_factor": sim / med[v][0], "cpu_time_s": med[v][1],
                     "real_time_factor_cpu": sim / med[v][1], "cpus_s": [r[1] for r in rs],
                     "figures": {k: summ[k] for k in FIGURES},
                     "note": f"median of {repeats} alternated run(s); {sim / med[v][1]:.0f} x real time in CPU time"})
    cpu_ratio = med["3d"][1] / med["planar"][1]
    wall_ratio = med["3d"][0] / med["planar"][0]
    pair = statistics.median(a[1] / b[1] for a, b in zip(runs["3d"], runs["planar"], strict=True))
    rows.append({"group": group, "case": "3d / planar", "integrator": integrator, "cpu_ratio": cpu_ratio,
                 "wall_ratio": wall_ratio, "paired_cpu_ratio": pair, "target_ratio": target,
                 "note": f"CPU {cpu_ratio:.2f} x (median paired {pair:.2f} x), wall {wall_ratio:.2f} x "
                         f"(target <= {target:g} x)"})
    return rows
