"""Rows of ``symtrack bench``: the 3D vehicle's cost against the planar one on the homogeneous
validation with the compiled Rosenbrock (issue 22's target: at most 2 x; docs/vehicle3d.md).

Both plants are built once (compiled, cached), then the runs alternate (planar, 3d, planar, ...) so
that a shared machine's load falls on both alike; the ratio is taken between the medians of one
session's CPU times (and wall times). ``quick``: one timed run each, no warm-up (the suite's smoke run).
"""

from __future__ import annotations

import statistics

from ..simulation import loop
from ..simulation.plants import make_plant
from ..simulation.scenario import load_scenario

__all__ = ["TARGET_RATIO", "VEHICLES", "bench_rows", "vehicle_runs"]

VEHICLES = ("planar", "3d")
TARGET_RATIO = 2.0  # issue 22: the homogeneous 3D validation at most 2 x the planar one (compiled Rosenbrock)
FIGURES = ("yaw_final_deg", "lateral_deviation_m", "sinkage_sprocket_mm", "sinkage_idler_mm")


def vehicle_runs(scenario: str = "validation", repeats: int = 7, warm_up: bool = True, overrides=()) -> dict:
    """{vehicle: [(wall_s, cpu_s, sim_s, result), ...]} of ``scenario`` with each vehicle of
    :data:`VEHICLES` on the compiled Rosenbrock, the runs alternated."""
    plants = {}
    for v in VEHICLES:
        sc = load_scenario(scenario, [f"model.vehicle={v}", "run.integrator=rosenbrock", *overrides])
        plants[v] = (sc, make_plant(sc))
    out = {v: [] for v in VEHICLES}
    for k in range(repeats + (1 if warm_up else 0)):
        for v in VEHICLES:
            sc, plant = plants[v]
            res = loop.run(sc, plant)
            if warm_up and k == 0:
                continue
            out[v].append((float(res.wall_time_s), float(res.cpu_time_s), float(res.t[-1]), res))
    return out


def bench_rows(quick: bool = False) -> list[dict]:
    """One row per vehicle (median wall and CPU time of the alternated runs, the run's figures) and the
    ratio row."""
    from ..simulation.result import summarise

    repeats = 1 if quick else 7
    runs = vehicle_runs(repeats=repeats, warm_up=not quick)
    rows, med = [], {}
    group = "validation: 3D vehicle"
    for v in VEHICLES:
        rs = runs[v]
        sim = rs[-1][2]
        med[v] = (statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs), sim)
        summ = summarise(rs[-1][3])
        rows.append({"group": group, "case": f"vehicle = {v}", "integrator": "rosenbrock", "sim_time_s": sim,
                     "wall_time_s": med[v][0], "real_time_factor": sim / med[v][0], "cpu_time_s": med[v][1],
                     "real_time_factor_cpu": sim / med[v][1], "cpus_s": [r[1] for r in rs],
                     "figures": {k: summ[k] for k in FIGURES},
                     "note": f"median of {repeats} alternated run(s); {sim / med[v][1]:.0f} x real time in CPU time"})
    cpu_ratio = med["3d"][1] / med["planar"][1]
    wall_ratio = med["3d"][0] / med["planar"][0]
    rows.append({"group": group, "case": "3d / planar", "integrator": "rosenbrock", "cpu_ratio": cpu_ratio,
                 "wall_ratio": wall_ratio, "target_ratio": TARGET_RATIO,
                 "note": f"CPU {cpu_ratio:.2f} x, wall {wall_ratio:.2f} x (target <= {TARGET_RATIO:g} x)"})
    return rows
