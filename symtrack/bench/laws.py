"""Rows of ``symtrack bench``: the cost of the lagged shear law against the creep law on the
million-cell validation (the target: ``validation_grid`` with ``model.lateral_law = "shear"``
at the terrain engine's 10 ms macro step costs at most 1.25 x the same run with the creep law and
stays >= 100 x real time on one core; docs/turning.md section 8).

The two laws' plants are built once each (engine compiled, cached), then the runs alternate
(creep, shear, creep, shear, ...) so that the load of a shared machine falls on both alike; the
ratio is taken between the medians of one session's runs, for wall and for CPU time. ``quick``: one
timed run per law and no warm-up run (the suite's smoke run; the ratio is then noisy).

The density rows: the shear law's plant without the mean normal stress at the four subsoil depths (the
default: the bulk density and the risk take the vertical stress and the soil's own weight) and with it
(``EngineState.compute_mean_stress``, what the kernel would spend on it), alternated the same way; the
figures of the two runs are the same to the last bit (the stress feeds nothing back).
"""

from __future__ import annotations

import statistics

from ..simulation import loop
from ..simulation.plants import make_plant
from ..simulation.scenario import load_scenario

__all__ = ["LAWS", "TARGET_RATIO", "TARGET_REAL_TIME_FACTOR", "bench_rows", "density_rows", "density_runs", "law_runs"]

LAWS = ("creep", "shear")
TARGET_RATIO = 1.25  # the shear law's run at most 1.25 x the creep law's
TARGET_REAL_TIME_FACTOR = 100.0  # >= 100 x real time on one core

FIGURES = ("yaw_final_deg", "lateral_deviation_m", "sinkage_sprocket_mm", "sinkage_idler_mm",
           "shear_driven_max_m", "shear_idle_min_m")


def law_runs(scenario: str = "validation_grid", repeats: int = 3, warm_up: bool = True, overrides=()) -> dict:
    """{law: [(wall_s, cpu_s, sim_s, result), ...]} of ``scenario`` with each law of :data:`LAWS`,
    the runs alternated; the world is cleared before each run (a fresh field every time)."""
    plants = {}
    for law in LAWS:
        sc = load_scenario(scenario, [f"model.lateral_law={law}", *overrides])
        plants[law] = (sc, make_plant(sc))
    out = {law: [] for law in LAWS}
    for k in range(repeats + (1 if warm_up else 0)):
        for law in LAWS:
            sc, plant = plants[law]
            _clear(plant)
            res = loop.run(sc, plant)
            if warm_up and k == 0:
                continue
            out[law].append((float(res.wall_time_s), float(res.cpu_time_s), float(res.t[-1]), res))
    return out


def _clear(plant) -> None:
    world = getattr(plant, "world", None)
    if world is not None:  # a fresh field for every run
        world.clear()


def density_runs(scenario: str = "validation_grid", law: str = "shear", repeats: int = 3, warm_up: bool = True,
                 overrides=()) -> dict:
    """{True: [(wall_s, cpu_s, sim_s, result, ns_subsoil_s), ...], False: [...]} of ``scenario`` on the
    terrain engine with the mean normal stress at the depths (True) and without it (False, the default), one plant,
    the runs alternated; the world is cleared before each run."""
    sc = load_scenario(scenario, [f"model.lateral_law={law}", *overrides])
    plant = make_plant(sc)
    state = plant.engine.state
    out = {True: [], False: []}
    try:
        for k in range(repeats + (1 if warm_up else 0)):
            for on in (True, False):
                state.compute_mean_stress = on
                _clear(plant)
                res = loop.run(sc, plant)
                if warm_up and k == 0:
                    continue
                out[on].append((float(res.wall_time_s), float(res.cpu_time_s), float(res.t[-1]), res,
                                res.stats.get("ns_subsoil", 0) * 1e-9))
    finally:
        state.compute_mean_stress = False
    return out


def density_rows(quick: bool = False) -> list[dict]:
    """One row with and one without the bulk density's mean normal stress (the shear law, median CPU and
    wall time of the alternated runs, the subsoil part's seconds) and their ratio."""
    repeats = 1 if quick else 5
    runs = density_runs(repeats=repeats, warm_up=not quick)
    rows, med = [], {}
    group = "validation_grid: bulk density"
    for on in (True, False):
        rs = runs[on]
        sim = rs[-1][2]
        med[on] = (statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs), sim)
        rows.append({"group": group, "case": "with the mean normal stress (unused)" if on else "without (the default)",
                     "integrator": "grid_fast", "sim_time_s": sim, "wall_time_s": med[on][0],
                     "real_time_factor": sim / med[on][0], "cpu_time_s": med[on][1],
                     "real_time_factor_cpu": sim / med[on][1], "cpus_s": [r[1] for r in rs],
                     "subsoil_s": statistics.median(r[4] for r in rs),
                     "note": f"median of {repeats} alternated run(s); {sim / med[on][1]:.0f} x real time in CPU time "
                             f"(target >= {TARGET_REAL_TIME_FACTOR:g} x with the bulk density)"})
    same = bool(all((runs[True][-1][3].X == r[3].X).all() for r in runs[False]))
    ratio = med[True][1] / med[False][1]
    rows.append({"group": group, "case": "with / without", "integrator": "grid_fast", "cpu_ratio": ratio,
                 "wall_ratio": med[True][0] / med[False][0], "identical_states": same,
                 "note": f"CPU {ratio:.2f} x; the vehicle's states identical with and without: {same}"})
    return rows


def bench_rows(quick: bool = False) -> list[dict]:
    """One row per law (median wall and CPU time of the alternated runs) and the ratio row, then
    :func:`density_rows`."""
    from ..simulation.result import summarise

    repeats = 1 if quick else 5
    runs = law_runs(repeats=repeats, warm_up=not quick)
    rows, med = [], {}
    for law in LAWS:
        walls = [r[0] for r in runs[law]]
        cpus = [r[1] for r in runs[law]]
        sim = runs[law][-1][2]
        med[law] = (statistics.median(walls), statistics.median(cpus), sim)
        summ = summarise(runs[law][-1][3])
        rows.append({"group": "validation_grid: lateral law", "case": f"lateral_law = {law}", "integrator": "grid_fast",
                     "sim_time_s": sim, "wall_time_s": med[law][0], "real_time_factor": sim / med[law][0],
                     "cpu_time_s": med[law][1], "real_time_factor_cpu": sim / med[law][1],
                     "walls_s": walls, "cpus_s": cpus, "figures": {k: summ[k] for k in FIGURES},
                     "note": f"median of {repeats} alternated run(s); {sim / med[law][1]:.0f} x real time in CPU "
                             "time"})
    wall_ratio = med["shear"][0] / med["creep"][0]
    cpu_ratio = med["shear"][1] / med["creep"][1]
    rows.append({"group": "validation_grid: lateral law", "case": "shear / creep", "integrator": "grid_fast",
                 "wall_ratio": wall_ratio, "cpu_ratio": cpu_ratio, "target_ratio": TARGET_RATIO,
                 "note": f"wall {wall_ratio:.2f} x, CPU {cpu_ratio:.2f} x (target <= {TARGET_RATIO:g} x; "
                         f"shear law {med['shear'][2] / med['shear'][1]:.0f} x real time in CPU time, "
                         f"target >= {TARGET_REAL_TIME_FACTOR:g} x)"})
    return rows + density_rows(quick)
