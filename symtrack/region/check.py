"""The fast fidelity against the full one on the same season (docs/region.md, "Fast against full";
``symtrack bench region``).

The full fidelity is a season of :mod:`symtrack.studies.operations` (``symtrack field season_4ha``): each
operation's plan driven by the vehicle on the terrain engine. Its fast twin (:func:`fast_twin`) takes the same
plans (the same :class:`~symtrack.studies.operations.OperationSettings`), the same vehicle as a tracked machine
(:func:`symtrack.region.fleet.track_machine`: its contact length, track width, gauge and mass), the same soil
and the same subsoil depths, on the same cells, with the terrain engine's rule of a trafficked cell (its square
overlaps a track's contact: ``rule = "overlap"``). :func:`compare` puts the two side by side: the share of the
field trafficked, the largest stress and the density change at each depth (means over the field and over the
cells both trafficked), and the cost per hectare-season.
"""

from __future__ import annotations

import time

import numpy as np

from ..model.parameters import SOIL_PARAMS
from .fast import FastOp, build_profiles, density_change, run_season_fast
from .fleet import rut_table_m, stress_profile, track_machine

__all__ = ["CASES", "bench_rows", "bench_table", "compare", "fast_twin", "full_and_fast", "full_season",
           "large_region_row",
           "median_speedup", "run_fast_twin", "soil_of", "workers_rows"]

SOIL_NAMES = frozenset(s.name for s in SOIL_PARAMS)


def soil_of(params: dict) -> dict:
    """The soil's parameters of a scenario's parameter set."""
    return {k: v for k, v in params.items() if k in SOIL_NAMES}


def fast_twin(opspec) -> tuple:
    """(FastOps, soil, depths) of an :class:`~symtrack.studies.operations.OperationSpec` (module doc)."""
    ops = []
    fs0, _, sc0, _ = opspec.operations[0]
    soil = soil_of(sc0.params)
    depths = tuple(sc0.terrain.subsoil_depths_m)
    xi = float(soil["stress_concentration_factor"])
    for fs, _plan, sc, _rows in opspec.operations:
        m = track_machine(sc.params.get("name", "vehicle") if isinstance(sc.params.get("name"), str) else "vehicle",
                          sc.params, fs.working_width_m, fs.turn_radius_m)
        sp = soil_of(sc.params)
        ops.append(FastOp(fs.name, fs, m, 1, None, stress_profile(m, depths, xi), sp,
                          rut_table_m=rut_table_m(m, sp), rut_exponent=float(sp["repeated_loading_exponent"])))
    return ops, soil, depths


def run_fast_twin(opspec, cell_m: float | None = None, rule: str = "overlap"):
    """The fast twin's season on the full fidelity's field (cells of ``cell_m``, default the field's own).
    Returns (SeasonMaps, soil, depths, cell_m, wall time [s], the tables' time [s])."""
    t0 = time.perf_counter()
    ops, soil, depths = fast_twin(opspec)
    for op in ops:  # the turned and pitched profiles too (tables, not the sweep's time)
        build_profiles(op)
    t_tables = time.perf_counter() - t0
    fs0 = opspec.base
    cell = fs0.cell_m if cell_m is None else float(cell_m)
    if cell != fs0.cell_m:
        import dataclasses

        ops = [dataclasses.replace(o, settings=dataclasses.replace(o.settings, cell_m=cell)) for o in ops]
    shape = (int(round(fs0.size_m[0] / cell)), int(round(fs0.size_m[1] / cell)))
    t1 = time.perf_counter()
    maps = run_season_fast(ops, shape, cell, depths, rule=rule)
    return maps, soil, depths, cell, time.perf_counter() - t1, t_tables


def compare(full_terrain, full_summary: dict, fast, soil: dict, depths, area_ha: float) -> dict:
    """The two fidelities side by side (module doc). ``fast``: :func:`run_fast_twin`'s result on the same cells.
    Figures ``*_full``, ``*_fast`` and their differences; the cost per hectare-season of each."""
    maps, _, _, cell, fast_s, tables_s = fast
    nd = len(depths)
    shape = maps.counts.shape
    st_full = full_terrain.specific_volume.reshape(-1, nd)
    if st_full.shape[0] != maps.state.shape[0]:
        raise ValueError(f"the full run's field has {st_full.shape[0]} cells, the fast one {maps.state.shape[0]}: "
                         "compare on the same cells")
    run_full = (full_terrain.sigma_max[:, 0] > 0).reshape(shape)
    run_fast = maps.counts > 0
    d_full = density_change(st_full, soil, depths).reshape(*shape, nd)
    d_fast = density_change(maps.state, soil, depths).reshape(*shape, nd)
    sig_full = full_terrain.sigma_max.reshape(*shape, nd).astype(np.float64)
    sig_fast = maps.sigma_max_Pa.astype(np.float64)
    both = run_full & run_fast
    out = {"cells": int(run_full.size), "cell_m": cell, "area_ha": area_ha,
           "trafficked_fraction_full": float(run_full.mean()), "trafficked_fraction_fast": float(run_fast.mean()),
           "trafficked_both_fraction": float(both.mean()),
           "trafficked_either_fraction": float((run_full | run_fast).mean())}
    out["trafficked_difference_points"] = 100 * (out["trafficked_fraction_fast"] - out["trafficked_fraction_full"])
    for k, d in enumerate(depths):
        tag = f"{d:g}m"
        a, b = float(d_full[..., k].mean()), float(d_fast[..., k].mean())
        out[f"density_change_mean_{tag}_full_Mg_per_m3"] = a
        out[f"density_change_mean_{tag}_fast_Mg_per_m3"] = b
        out[f"density_change_ratio_{tag}"] = b / a if a != 0 else float("nan")
        if both.any():
            out[f"stress_mean_trafficked_{tag}_full_kPa"] = 1e-3 * float(sig_full[..., k][both].mean())
            out[f"stress_mean_trafficked_{tag}_fast_kPa"] = 1e-3 * float(sig_fast[..., k][both].mean())
            out[f"stress_ratio_{tag}"] = out[f"stress_mean_trafficked_{tag}_fast_kPa"] / \
                out[f"stress_mean_trafficked_{tag}_full_kPa"]
    full_s = float(full_summary["wall_time_s"])
    out.update(full_wall_time_s=full_s, fast_wall_time_s=fast_s, fast_tables_s=tables_s,
               full_s_per_ha_season=full_s / area_ha, fast_s_per_ha_season=fast_s / area_ha,
               cost_ratio=full_s / fast_s if fast_s > 0 else float("nan"))
    return out


# ---- symtrack bench region -------------------------------------------------------------------------------------
# the fields of the check (module doc): built-in seasons of symtrack field, with overrides
CASES = {
    "operation_small": ("operation_small", []),
    "season_1ha_random": ("season_4ha", ["operation.size_m=[100.0, 100.0]", "season.tracks=\"random\"",
                                         "operation.turn=\"auto\""]),
    "season_4ha": ("season_4ha", []),
}
QUICK_CASES = ("operation_small",)


def full_season(case: str, keep=None):
    """(terrain, summary) of the case's full-fidelity season: run here (one process, minutes), or read back
    from ``keep``/<case> (``field.npz`` and ``summary.json`` of a complete run, as ``symtrack field`` writes
    them) where a run of the same inputs is kept; a run done here is kept there when ``keep`` is given."""
    import json
    from pathlib import Path

    from ..foundations.config import to_toml
    from ..studies.operations import load_operation_spec, run_season
    from ..terrain.storage import Terrain

    name, overrides = CASES[case]
    spec = load_operation_spec(name, overrides)
    folder = Path(keep) / case if keep is not None else None
    if folder is not None and (folder / "summary.json").is_file() and (folder / "field.npz").is_file():
        summary = json.loads((folder / "summary.json").read_text())
        same = (folder / "operation.resolved.toml").is_file() and \
            (folder / "operation.resolved.toml").read_text() == to_toml(spec.document)
        if summary.get("complete") and same:
            return spec, Terrain.load(folder / "field.npz"), summary
    full = run_season(spec, folder, figures=False)
    if not full.summary["complete"]:
        raise RuntimeError(f"{case}: the full fidelity's season failed: {full.summary['error']}")
    return spec, full.terrain, full.summary


def full_and_fast(case: str, keep=None) -> list:
    """One case: the full fidelity's season (:func:`full_season`), then its fast twin on the same cells (the
    overlap and centre rules) and on the region's 0.25 m and 0.5 m cells; the comparison rows."""
    spec, terrain, summary = full_season(case, keep)
    fs0 = spec.base
    area_ha = fs0.size_m[0] * fs0.size_m[1] / 1e4
    rows = []
    for rule in ("overlap", "centre"):
        fast = run_fast_twin(spec, rule=rule)
        rows.append({"case": case, "rule": rule, **compare(terrain, summary, fast, fast[1], fast[2], area_ha)})
    for coarse in (0.25, 0.5):  # the cost on the region's cells, and what the coarser cells change
        fast = run_fast_twin(spec, cell_m=coarse, rule="centre")
        maps, soil, depths = fast[0], fast[1], fast[2]
        d = density_change(maps.state, soil, depths).mean(axis=0)
        row = {"case": case, "rule": "centre", "cell_m": coarse, "area_ha": area_ha,
               "trafficked_fraction_full": rows[0]["trafficked_fraction_full"],
               "trafficked_fraction_fast": float((maps.counts > 0).mean()),
               "full_wall_time_s": rows[0]["full_wall_time_s"], "fast_wall_time_s": fast[4],
               "cost_ratio": rows[0]["full_wall_time_s"] / fast[4]}
        row["trafficked_difference_points"] = 100 * (row["trafficked_fraction_fast"] - row["trafficked_fraction_full"])
        for k, dep in enumerate(depths):
            tag = f"{dep:g}m"
            a = rows[0][f"density_change_mean_{tag}_full_Mg_per_m3"]
            row[f"density_change_mean_{tag}_fast_Mg_per_m3"] = float(d[k])
            row[f"density_change_ratio_{tag}"] = float(d[k]) / a if a else float("nan")
        rows.append(row)
    return rows


def workers_rows(n_fields: int = 24, seed: int = 11, folder=None, repeats: int = 1) -> list:
    """The same generated region (one season) on 1 and on 2 workers of a local cluster, the two alternated
    ``repeats`` times (a noisy machine moves both of a pair alike): the phases' times and the tasks' throughput
    (hectare-seasons per second). Each 2-worker row carries ``speedup_vs_1_worker``, the ratio of its pair's task
    times, and its ``repeat``; :func:`median_speedup` is the median over the pairs."""
    import tempfile
    from pathlib import Path

    from . import demo
    from .inputs import load_region
    from .study import run_region

    if repeats < 1:
        raise ValueError(f"repeats = {repeats} must be >= 1")
    rows = []
    with tempfile.TemporaryDirectory(prefix="symtrack-bench-region-", dir=folder) as tmp:
        path = demo.write_region(Path(tmp) / "in", n_fields=n_fields, seed=seed, years={2021: -0.4})
        for k in range(repeats):
            pair = []
            for w in (1, 2):
                spec = load_region(path)
                res = run_region(spec, Path(tmp) / f"out{k}_{w}", workers=w, progress=False, outputs=False)
                ph = res.phases_s
                cpu = sum(r.get("cpu_time_s", 0.0) for r in res.rows)
                pair.append({"case": f"region_{n_fields}_fields", "workers": w, "repeat": k, "area_ha": spec.area_ha,
                             "field_seasons": res.ran, "wall_time_s": res.wall_time_s, **ph,
                             "ha_seasons_per_s": spec.area_ha / ph["tasks_s"],
                             "s_per_ha_season_per_core": w * ph["tasks_s"] / spec.area_ha,
                             # the tasks' own CPU time: on a machine shared with other work, the cores the workers
                             # got (tasks_cpu_s / tasks_s) tell a lack of cores from a lack of parallelism
                             "tasks_cpu_s": cpu, "cpu_s_per_ha_season": cpu / spec.area_ha,
                             "cores_used": cpu / ph["tasks_s"]})
            pair[1]["speedup_vs_1_worker"] = pair[0]["tasks_s"] / pair[1]["tasks_s"]
            rows += pair
    return rows


def median_speedup(rows: list) -> float:
    """The median of :func:`workers_rows`' pairs' 1 -> 2 worker throughput ratios."""
    return float(np.median([r["speedup_vs_1_worker"] for r in rows if "speedup_vs_1_worker" in r]))


def large_region_row(target_ha: float = 1000.0, workers: int = 2, seed: int = 13, folder=None) -> dict:
    """A generated region of about ``target_ha`` hectares, one season, the fast fidelity on ``workers`` local
    workers, outputs included: the wall time of the whole study."""
    import tempfile
    from pathlib import Path

    from . import demo
    from .inputs import load_region
    from .study import run_region

    n = max(1, int(round(target_ha / 3.8)))  # the generator's fields average about 3.8 ha
    with tempfile.TemporaryDirectory(prefix="symtrack-bench-region-", dir=folder) as tmp:
        path = demo.write_region(Path(tmp) / "in", n_fields=n, seed=seed, years={2022: 0.3})
        spec = load_region(path)
        res = run_region(spec, Path(tmp) / "out", workers=workers, progress=False)
        return {"case": f"region_{n}_fields", "workers": workers, "area_ha": spec.area_ha, "fields": n,
                "wall_time_s": res.wall_time_s, **res.phases_s,
                "s_per_ha_season_per_core": workers * res.phases_s["tasks_s"] / spec.area_ha}


def bench_rows(quick: bool = False, large: bool = False, cases=None, keep=None, workers_only: bool = False,
               repeats: int = 1) -> dict:
    """``symtrack bench region``: the cases' comparisons, 1 against 2 workers, and with ``large`` the 1,000 ha
    region; ``quick``: the smallest case only; ``keep``: a folder of the full fidelity's runs (reused, or
    written there: :func:`full_season`); ``workers_only``: only 1 against 2 workers, ``repeats`` alternated pairs
    (:func:`workers_rows`)."""
    if workers_only:
        rows = workers_rows(repeats=repeats)
        return {"workers": rows, "speedup_median": median_speedup(rows)}
    cases = cases or (QUICK_CASES if quick else tuple(CASES))
    out = {"fast_vs_full": [r for c in cases for r in full_and_fast(c, keep)]}
    if not quick:
        out["workers"] = workers_rows()
    if large:
        out["large_region"] = large_region_row()
    return out


def bench_table(rep: dict) -> str:
    lines = ["| case | rule | cell m | trafficked full % | fast % | diff points | drho ratio 0.1 / 0.3 / 0.5 m | "
             "full s | fast s | cost ratio |", "|---|---|---|---|---|---|---|---|---|---|"] \
        if rep.get("fast_vs_full") else []
    for r in rep.get("fast_vs_full", []):
        ratios = " / ".join(f"{r.get(f'density_change_ratio_{d}m', float('nan')):.3f}" for d in ("0.1", "0.3", "0.5"))
        lines.append(f"| {r['case']} | {r['rule']} | {r.get('cell_m', 0.1):g} | "
                     f"{100 * r['trafficked_fraction_full']:.2f} | {100 * r['trafficked_fraction_fast']:.2f} | "
                     f"{r['trafficked_difference_points']:+.2f} | {ratios} | {r['full_wall_time_s']:.1f} | "
                     f"{r['fast_wall_time_s']:.2f} | {r['cost_ratio']:.0f} |")
    for r in rep.get("workers", []):
        lines.append(f"region {r['area_ha']:.1f} ha on {r['workers']} worker(s): tasks {r['tasks_s']:.1f} s "
                     f"({r['ha_seasons_per_s']:.2f} ha-seasons/s, {r['s_per_ha_season_per_core']:.2f} s per ha-season "
                     f"per core), whole study {r['wall_time_s']:.1f} s"
                     + (f"; {r['speedup_vs_1_worker']:.2f} x the 1-worker throughput" if "speedup_vs_1_worker" in r
                        else ""))
    if "speedup_median" in rep:
        lines.append(f"1 -> 2 workers, median of {len(rep['workers']) // 2} alternated pairs: "
                     f"{rep['speedup_median']:.2f} x the throughput")
    if "large_region" in rep:
        r = rep["large_region"]
        lines.append(f"{r['area_ha']:.0f} ha ({r['fields']} fields), one season, {r['workers']} workers: "
                     f"{r['wall_time_s']:.0f} s in all (tasks {r['tasks_s']:.0f} s)")
    return "\n".join(lines)
