"""The brute-force reference and the terrain benchmark.

- :func:`brute_force_run`: every cell of a (small) field integrated as its own state, the same
  cell equations as the channels, each channel permanently bound to one cell. The same time
  loop, settling and history update as the channel pool; the test of the world manager
  compares the two (tests/test_terrain_world.py).
- :func:`benchmark`: the figures of the issue, measured in one run (see ``examples/bench_terrain.py``).
"""

from __future__ import annotations

import dataclasses
import math
import time

import casadi as ca
import numpy as np

from ..integrators.engine.manager import static_sinkage
from ..integrators.grid_idas import ChannelStepper
from ..integrators.settings import IntegratorSettings
from ..reports import validation
from ..simulation import loop
from ..simulation.passes import RUT_THRESHOLD_M, pass_figures
from ..simulation.plants import make_plant
from ..simulation.result import summarise
from ..simulation.scenario import load_scenario
from ..terrain.channels import HIST_ROWS, NF, NG
from ..terrain.settings import TerrainSettings
from ..terrain.storage import Grid
from ..terrain.world import END_STRIP_CELLS, channel_model

__all__ = ["BruteResult", "GRID_FIXED_STEP_S", "bench_rows", "benchmark", "brute_force_run", "main", "pool_run"]


@dataclasses.dataclass
class BruteResult:
    t: np.ndarray
    X: np.ndarray  # vehicle states per output time (columns: state_names)
    z: np.ndarray  # final sinkage of every cell (nx, ny)
    wall_time_s: float
    n_states: int
    state_names: tuple = ()

    def state(self, name) -> np.ndarray:
        """A vehicle state by name at the output times."""
        return self.X[:, self.state_names.index(name)]


def brute_force_run(scenario, duration_s: float) -> BruteResult:
    """Integrate the scenario for duration_s on its [terrain] field with one channel per cell."""
    s = scenario.terrain
    params = scenario.params
    nx, ny = s.shape
    origin = s.origin_m or (scenario.start.x_m - 0.5 * nx * s.cell_m, scenario.start.y_m - 0.5 * ny * s.cell_m)
    grid = Grid(tuple(float(v) for v in origin), float(s.cell_m), (nx, ny))
    n = grid.n_cells
    model = channel_model(scenario.model, n)
    terrain = model.terrain
    Q = np.zeros(NG + NF * n)
    Q[0], Q[1] = grid.cell_m, END_STRIP_CELLS * grid.cell_m
    qc = Q[NG:].reshape(n, NF)
    ii, jj = np.divmod(np.arange(n), ny)
    qc[:, 0], qc[:, 1] = grid.centres(ii, jj)
    qc[:, 4] = 1.0
    pbase = np.array(model.param_vector(params, Q))[:-len(Q)]
    law = ca.DM(terrain.law.values(params))
    history = terrain.fn["history"].map("history_all", "serial", n, [2], [])
    stepper = ChannelStepper(model, IntegratorSettings("idas", scenario.run.reltol, scenario.run.abstol))

    L = model.layout

    def update(x):
        zc = x[L.cell_field("sinkage")]
        zmax, pmax, _, _, _, _ = (np.array(a).ravel() for a in history(zc, qc[:, HIST_ROWS].T, law))
        qc[:, 2], qc[:, 3] = zmax, pmax

    x = np.zeros(model.nx)
    x[L.pose_index] = scenario.start.x_m, scenario.start.y_m, np.radians(scenario.start.yaw_deg)
    dt = scenario.run.macro_step_s
    # the cells at their static sinkage first (World.begin_pass)
    P0 = np.concatenate([pbase, Q])
    acc = np.array(model.ode(x, np.zeros(2), P0)).ravel()[L.cell_field("rate")]
    p_load = params["cell_areal_mass_kg_per_m2"] * acc
    loaded = np.nonzero(p_load > 0)[0]
    x[L.cell_index(loaded, "sinkage")] = static_sinkage(scenario.model, params, np.zeros(loaded.size),
                                                        qc[loaded][:, HIST_ROWS].T, p_load[loaded])
    for _ in range(int(round(s.settle_s / 0.01))):
        x = stepper.step(x, np.zeros(2), np.concatenate([pbase, Q]), 0.01)
        update(x)
    stepper.reset()
    t = 0.0
    change_times = [e.t_s for e in scenario.torque[1:]]
    vs = L.block("vehicle")
    ts, xs = [t], [x[vs].copy()]
    wall0 = time.perf_counter()
    while t < duration_s - 1e-12:
        t_next = min(t + dt, duration_s)
        for tc in change_times:
            if t + 1e-12 < tc < t_next - 1e-12:
                t_next = tc
        u = np.array(scenario.torque_at(t))
        x = stepper.step(x, u, np.concatenate([pbase, Q]), t_next - t)
        update(x)
        t = t_next
        ts.append(t)
        xs.append(x[vs].copy())
    wall = time.perf_counter() - wall0
    names = tuple(np.asarray(model.state_names, dtype=object)[vs])
    return BruteResult(np.array(ts), np.array(xs), x[L.cell_field("sinkage")].reshape(grid.shape).copy(), wall,
                       model.nx, names)


def pool_run(scenario, duration_s: float):
    """The same run through the channel pool (the time loop with the grid plant)."""
    sc = dataclasses.replace(scenario, run=dataclasses.replace(
        scenario.run, duration_s=duration_s, stop_after_distance_m=None, stop_distance_event=None))
    plant = make_plant(sc)
    res = loop.run(sc, plant)
    return plant.world, res


def _field_scenario(base, size_m, cell_m, extra=()):
    return load_scenario(base, ["run.integrator=idas", f"terrain.size_m={list(size_m)}",
                                f"terrain.cell_m={cell_m}", *extra])


def benchmark(big_size_m=(100.0, 100.0), big_cell_m=0.1, small_size_m=(12.0, 4.0), small_cell_m=0.25,
              small_duration_s=1.0, big_duration_s=None) -> dict:
    """All figures of the issue's benchmark, measured in one process.

    1. The validation run (validation_grid) on the big field: wall time per simulated second,
       peak active cells, channels, storage memory.
    2. On the small field, ``small_duration_s`` of the validation's torque programme through the
       channel pool and with every cell integrated as its own state: the speed ratio.
    """
    out = {}
    sc = _field_scenario("validation_grid", big_size_m, big_cell_m)
    if big_duration_s is not None:  # a shortened run (the example's test), not the validation
        sc = dataclasses.replace(sc, run=dataclasses.replace(
            sc.run, duration_s=big_duration_s, stop_after_distance_m=None, stop_distance_event=None))
    t0 = time.perf_counter()
    plant = make_plant(sc)
    world = plant.world
    out["big_build_s"] = time.perf_counter() - t0
    res = loop.run(sc, plant)
    out["big_field_cells"] = world.grid.n_cells
    out["big_cell_m"] = big_cell_m
    out["big_sim_time_s"] = float(res.t[-1])
    out["big_wall_time_s"] = float(res.wall_time_s)
    out["big_wall_s_per_sim_s"] = float(res.wall_time_s / res.t[-1])
    out["big_peak_active_cells"] = res.terrain["terrain_peak_active_cells"]
    out["big_channels"] = world.n_channels
    out["big_storage_MB"] = world.storage.nbytes / 1e6
    if big_duration_s is None:
        summ = summarise(res)
        out["big_validation_all_within"] = all(ok for *_, ok in validation.check(summ))
        out["big_validation"] = {k: v for k, _, v, _ in validation.check(summ)}

    sc2 = _field_scenario("validation_grid", small_size_m, small_cell_m)
    if (tuple(small_size_m), small_cell_m, small_duration_s) == (tuple(big_size_m), big_cell_m, big_duration_s):
        pres = res  # the big run was this pool run (the quick smoke run): not run and built twice
    else:
        _, pres = pool_run(sc2, small_duration_s)
    b = brute_force_run(sc2, small_duration_s)
    out["small_field_cells"] = int(np.prod(TerrainSettings(size_m=tuple(small_size_m), cell_m=small_cell_m).shape))
    out["small_pool_wall_s"] = float(pres.wall_time_s)
    out["small_brute_wall_s"] = float(b.wall_time_s)
    out["small_speed_ratio_brute_over_pool"] = float(b.wall_time_s / pres.wall_time_s)
    out["small_pose_difference_m"] = float(max(np.max(np.abs(pres.state(n) - b.state(n))) for n in ("x_m", "y_m")))
    return out


# ---- rows of `symtrack bench` (symtrack/bench/homogeneous.py) ----------------------------------------
GRID_FIXED_STEP_S = 0.000625  # the grid rosenbrock's step (docs/terrain.md, "Speed": accuracy against IDAS)


class _Timed:
    """Wall time spent in named methods of an object (wrapped on the instance)."""

    def __init__(self, obj, names):
        self.total = dict.fromkeys(names, 0.0)
        for n in names:
            fn = getattr(obj, n)

            def wrapped(*a, _fn=fn, _n=n, **k):
                t0 = time.perf_counter()
                try:
                    return _fn(*a, **k)
                finally:
                    self.total[_n] += time.perf_counter() - t0
            setattr(obj, n, wrapped)


def _grid_row(integrator, duration_s=None, channels=None, note=""):
    """One validation run on the million-cell field; the world manager's and the integrator's
    shares of the wall time of the time loop (model construction and compilation excluded: a
    warm-up macro step compiles what the run needs first)."""
    extra = [f"run.integrator={integrator}", f"run.fixed_step_s={GRID_FIXED_STEP_S}"]
    if channels is not None:
        extra.append(f"terrain.channels={channels}")
    sc = _field_scenario("validation_grid", (100.0, 100.0), 0.1, extra)
    if duration_s is not None:
        sc = dataclasses.replace(sc, run=dataclasses.replace(
            sc.run, duration_s=duration_s, stop_after_distance_m=None, stop_distance_event=None))
    t0 = time.perf_counter()
    plant = make_plant(sc)
    world, stepper = plant.world, plant.stepper
    if integrator == "rosenbrock":  # compile the packed sizes the validation meets (up to 448 slots)
        from ..integrators.grid_rosenbrock import PACK_SLOTS

        n_sub = int(round(sc.run.macro_step_s / sc.run.fixed_step_s))
        for slots in range(PACK_SLOTS, 512, PACK_SLOTS):
            stepper.function(min(slots, world.n_channels), n_sub)
    build_s = time.perf_counter() - t0
    st = _Timed(stepper, ("step",))
    mgr = plant.manager  # the world manager of the IDAS reference path (grid_engine.c's rules)
    wt = _Timed(mgr, ("before_step", "after_step", "check_covered"))
    begin = mgr.begin_pass
    in_begin = {}

    def timed_begin(*a, **k):  # the settling before the time loop is not in the run's wall time
        s0, w0 = dict(st.total), dict(wt.total)
        try:
            return begin(*a, **k)
        finally:
            in_begin.update({k: st.total[k] - s0[k] for k in s0})
            in_begin.update({k: wt.total[k] - w0[k] for k in w0})
    mgr.begin_pass = timed_begin
    res = loop.run(sc, plant)
    integration = st.total["step"] - in_begin.get("step", 0.0)
    wall = float(res.wall_time_s)
    manager = sum(wt.total[k] - in_begin.get(k, 0.0) for k in ("before_step", "after_step", "check_covered"))
    other = wall - manager - integration
    row = {"group": "grid validation (1e6 cells)", "case": f"M = {world.M}", "integrator": integrator,
           "sim_time_s": float(res.t[-1]), "wall_time_s": wall, "real_time_factor": float(res.t[-1]) / wall,
           "build_s": build_s, "channels": world.n_channels, "peak_active_cells": world.peak_active,
           "world_manager_s": manager, "integration_s": integration, "other_s": other,
           "world_manager_share": manager / wall, "integration_share": integration / wall}
    if duration_s is None:
        summ = summarise(res)
        row["validation"] = {k: v for k, _, v, _ in validation.check(summ)}
        row["validation_all_within"] = all(ok for *_, ok in validation.check(summ))
    row["note"] = (note + f"; {float(res.t[-1]) / wall:.3g} x real time; wall: integration "
                   f"{100 * integration / wall:.0f} %, world manager {100 * manager / wall:.0f} %, outputs and loop "
                   f"{100 * other / wall:.0f} %").lstrip("; ")
    return row


# ---- the terrain engine (run.integrator = "grid_fast", symtrack/integrators/engine/) -------------
ENGINE_FIGURES = ("lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm", "sinkage_idler_mm",
                  "shear_driven_max_m", "shear_idle_min_m", "rut_max_depth_mm", "rut_mean_depth_mm",
                  "compaction_resistance_mean_N", "compaction_resistance_time_mean_N")


def _engine_validation(plant, sc, repeats=2):
    """The scenario through the engine plant on its world (cleared before each run); the best of repeats."""
    world = plant.world
    best = None
    for _ in range(repeats):
        world.clear()
        z0 = world.storage.z.copy()
        res = loop.run(sc, plant)
        if best is None or res.wall_time_s < best[0].wall_time_s:
            summ = summarise(res)
            summ.update(pass_figures(world, z0, res, world.touched.copy()))
            best = (res, summ)
    return best


def _engine_row(group, case, res, note=""):
    st = res.stats
    wall, sim = float(res.wall_time_s), float(res.t[-1])
    parts = {k: st.get(k, 0) * 1e-9 for k in ("ns_manager", "ns_vehicle", "ns_cells", "ns_subsoil", "ns_outputs")}
    loop = max(0.0, wall - sum(parts.values()))
    row = {"group": group, "case": case, "integrator": "grid_fast", "sim_time_s": sim, "wall_time_s": wall,
           "real_time_factor": sim / wall, "cpu_time_s": res.cpu_time_s, "real_time_factor_cpu": sim / res.cpu_time_s,
           "world_manager_s": parts["ns_manager"], "vehicle_s": parts["ns_vehicle"], "cells_s": parts["ns_cells"],
           "subsoil_s": parts["ns_subsoil"], "outputs_s": parts["ns_outputs"], "python_loop_s": loop,
           "peak_active_cells": res.terrain["terrain_peak_active_cells"], "cell_stages": st["n_cell_stages"],
           "newton_iterations": st["n_newton"]}
    shares = ", ".join(f"{n} {100 * v / wall:.0f} %" for n, v in (
        ("world manager", parts["ns_manager"]), ("vehicle", parts["ns_vehicle"]), ("cells", parts["ns_cells"]),
        ("subsoil stress", parts["ns_subsoil"]), ("outputs", parts["ns_outputs"]), ("python", loop)))
    row["note"] = (note + f"; {sim / wall:.3g} x real time (CPU time: {sim / res.cpu_time_s:.3g} x); "
                   f"{shares}").lstrip("; ")
    return row


def engine_field_rows(sizes_cells=(1e4, 1e6, 1.6e7), duration_s=2.0) -> list[dict]:
    """Cost against field size: duration_s of the validation's torque programme on square fields of
    about sizes_cells cells at 0.1 m, the vehicle starting at the centre (the same run on each)."""
    rows = []
    base = None
    for n in sizes_cells:
        side = round(math.sqrt(n) * 0.1, 1)
        sc = _field_scenario("validation_grid", (side, side), 0.1, ["run.integrator=grid_fast"])
        sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=duration_s, stop_after_distance_m=None,
                                                             stop_distance_event=None))
        plant = make_plant(sc)
        world = plant.world
        res, _ = _engine_validation(plant, sc, repeats=2)
        per = res.cpu_time_s / float(res.t[-1])
        base = base if base is not None else per
        r = _engine_row("grid_fast: cost vs field size", f"{world.grid.n_cells:.3g} cells", res,
                        note=f"{world.storage.nbytes / world.grid.n_cells:.0f} B per cell in storage; CPU s per "
                             f"simulated s {per:.4f} ({per / base:.2f} x the smallest field)")
        r["cells"] = world.grid.n_cells
        r["storage_MB"] = world.storage.nbytes / 1e6
        r["cpu_s_per_sim_s"] = per
        rows.append(r)
        del world, plant
    return rows


def engine_rows(quick: bool = False, rosenbrock_row: dict | None = None, reference_summary: dict | None = None):
    """Rows of the terrain engine: the validation on the million-cell field (real-time factor, the
    shares of its parts, the gain over the compiled grid rosenbrock of the same run, the figures
    against a reference summary if given), the cost against field size, the pool against one
    channel per cell on the small field."""
    ref = None if reference_summary is None else {**reference_summary, **reference_summary.get("passes", [{}])[0]}

    def validation_row(extra, case):
        sc = _field_scenario("validation_grid", (100.0, 100.0), 0.1, ["run.integrator=grid_fast", *extra])
        t0 = time.perf_counter()
        plant = make_plant(sc)  # builds and compiles the engine (cached)
        build_s = time.perf_counter() - t0
        res, summ = _engine_validation(plant, sc, repeats=5)
        row = _engine_row("grid validation (1e6 cells)", f"M = {plant.world.M}{case}", res,
                          note="the whole validation")
        row["build_s"] = build_s
        row["validation"] = {k: summ[k] for k in ENGINE_FIGURES}
        if ref is not None:
            row["relative_difference_to_reference"] = {k: summ[k] / ref[k] - 1 for k in ENGINE_FIGURES if ref.get(k)}
        return row

    row = validation_row([], "")
    if rosenbrock_row is not None:
        gain = row["real_time_factor"] / rosenbrock_row["real_time_factor"]
        row["gain_over_rosenbrock"] = gain
        row["note"] += f"; {gain:.0f} x the compiled grid rosenbrock of this run"
    # the two-stage SDIRK for the cells outside the windows (EngineSettings.steady_method): the same run
    row_e = validation_row(["engine.steady_method='sdirk2'"], ", steady_method sdirk2")
    row_e["note"] += f"; {row_e['real_time_factor'] / row['real_time_factor']:.2f} x the default's speed"
    rows = [row, row_e]
    rows += engine_field_rows((1e4, 1e6) if quick else (1e4, 1e6, 1.6e7))
    # the small field: the pool (sector rule) against one channel per cell (bit for bit)
    sc2 = _field_scenario("validation_grid", (12.0, 4.0), 0.25, ["run.integrator=grid_fast"])
    sc2 = dataclasses.replace(sc2, run=dataclasses.replace(sc2.run, duration_s=1.0, stop_after_distance_m=None,
                                                           stop_distance_event=None))
    p_pool = make_plant(sc2)
    w_pool = p_pool.world
    r_pool, _ = _engine_validation(p_pool, sc2)
    nx, ny = w_pool.grid.shape
    sc3 = dataclasses.replace(sc2, terrain=dataclasses.replace(sc2.terrain, channels=max(nx, ny)))
    p_all = make_plant(sc3)
    w_all = p_all.world
    r_all, _ = _engine_validation(p_all, sc3)
    same = bool((r_pool.X == r_all.X).all() and (w_pool.z_at_pass_end == w_all.z_at_pass_end).all())
    for case, r, w in (("channel pool", r_pool, w_pool), ("one channel per cell", r_all, w_all)):
        rr = _engine_row("small field 12 m x 4 m at 0.25 m", case, r,
                         note=f"M = {w.M}, {w.n_channels} channels" + ("; identical to the pool to the last bit"
                                                                        if case != "channel pool" and same else ""))
        rr["identical_to_pool"] = same
        rows.append(rr)
    return rows


def engine_field_pattern(passes: int = 20, length_m: float = 85.0, spacing_m: float = 4.0) -> dict:
    """A whole-field study: ``passes`` straight passes of length_m (2000 N m on both sprockets) on
    parallel lines spacing_m apart, alternating direction, over one 100 m x 100 m field at 0.1 m
    (1e6 cells) through the engine; the wall time of everything (the World's construction, the
    compilation if not cached, every pass with its settling and lift-off)."""
    t0 = time.perf_counter()
    sc = _field_scenario("validation_grid", (100.0, 100.0), 0.1,
                         ["run.integrator=grid_fast", "terrain.origin_m=[-50.0, -50.0]"])
    torque = (dataclasses.replace(sc.torque[0], left_N_m=2000.0, right_N_m=2000.0, event="go"),)
    run = dataclasses.replace(sc.run, duration_s=200.0, stop_after_distance_m=length_m, stop_distance_event="go")
    plant = make_plant(sc)
    world = plant.world
    loop_s, sim_s, figs = 0.0, 0.0, []
    for k in range(passes):
        y = -0.5 * (passes - 1) * spacing_m + k * spacing_m
        x, yaw = (-0.5 * length_m - 2.0, 0.0) if k % 2 == 0 else (0.5 * length_m + 2.0, 180.0)
        sck = dataclasses.replace(sc, run=run, torque=torque, start=dataclasses.replace(sc.start, x_m=x, y_m=y,
                                                                                         yaw_deg=yaw))
        z0 = world.storage.z.copy()
        res = loop.run(sck, plant)
        figs.append(pass_figures(world, z0, res, world.touched.copy()))
        loop_s += res.wall_time_s
        sim_s += float(res.t[-1])
    total = time.perf_counter() - t0
    cells = int((world.storage.zmax > RUT_THRESHOLD_M).sum())
    return {"group": "grid_fast: field pattern", "case": f"{passes} passes x {length_m:g} m, 1e6 cells",
            "integrator": "grid_fast", "sim_time_s": sim_s, "wall_time_s": total, "real_time_factor": sim_s / total,
            "time_loop_s": loop_s, "cells_rutted": cells,
            "note": f"{sim_s:.0f} s simulated; wall {total:.1f} s in all (time loops {loop_s:.2f} s: "
                    f"{sim_s / loop_s:.0f} x real time); {cells} cells rutted; mean compaction resistance "
                    f"{np.mean([f['compaction_resistance_mean_N'] for f in figs]):.1f} N"}




def bench_rows(quick: bool = False) -> list[dict]:
    """Rows of ``symtrack bench``: the validation on the million-cell field (IDAS interpreted, the
    compiled grid rosenbrock), the channel-pool size M against cost, the pool against brute force
    on the small field. ``quick``: the IDAS row and the M sweep over 0.5 s of the run only."""
    rows = []
    short = 0.5 if quick else None
    rows.append(_grid_row("idas", duration_s=0.5 if quick else None,
                          note="first 0.5 s only" if quick else "the whole validation"))
    rows.append(_grid_row("rosenbrock", note=f"compiled, step {GRID_FIXED_STEP_S * 1e3:g} ms"))
    rows += engine_rows(quick, rosenbrock_row=rows[-1])
    for M in (48, 64):
        r = _grid_row("rosenbrock", duration_s=short, channels=M,
                      note="M sweep" + ("; first 0.5 s only" if quick else ""))
        r["group"] = "grid: pool size M vs cost"
        rows.append(r)
    sc2 = _field_scenario("validation_grid", (12.0, 4.0), 0.25, [f"run.fixed_step_s={GRID_FIXED_STEP_S}"])
    _, pres = pool_run(sc2, 1.0)
    b = brute_force_run(sc2, 1.0)
    sc3 = dataclasses.replace(sc2, run=dataclasses.replace(sc2.run, integrator="rosenbrock"))
    pool_run(sc3, 0.05)  # compile
    _, rres = pool_run(sc3, 1.0)
    for case, integ, wall in (("brute force (768 cells as states)", "idas", b.wall_time_s),
                              ("channel pool", "idas", pres.wall_time_s),
                              ("channel pool", "rosenbrock", rres.wall_time_s)):
        rows.append({"group": "small field 12 m x 4 m at 0.25 m", "case": case, "integrator": integ,
                     "sim_time_s": 1.0, "wall_time_s": float(wall), "real_time_factor": 1.0 / float(wall),
                     "note": f"{1.0 / float(wall):.3g} x real time"
                     + (f"; brute / pool (idas) = {b.wall_time_s / pres.wall_time_s:.1f}"
                        if case == "channel pool" and integ == "idas" else "")})
    return rows


def main(argv=None) -> int:
    """``python -m symtrack.bench.terrain [--quick] [--out FILE]``: the grid rows of ``symtrack bench``
    alone, printed as its table and written as its JSON."""
    import argparse
    import json
    from pathlib import Path

    from ..foundations.files import atomic_write_text
    from .homogeneous import report, table

    ap = argparse.ArgumentParser(prog="python -m symtrack.bench.terrain")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="out/bench_terrain.json")
    ap.add_argument("--engine", action="store_true",
                    help="only the terrain engine's rows, with the compiled grid rosenbrock for the gain")
    ap.add_argument("--pattern", action="store_true", help="only the 20-pass field pattern through the engine")
    ap.add_argument("--reference", help="summary.json of `symtrack simulate validation_grid --integrator idas`: "
                                        "the engine's figures relative to it")
    args = ap.parse_args(argv)
    if args.pattern:
        rows = [engine_field_pattern()]
    elif args.engine:
        ref = json.loads(Path(args.reference).read_text()) if args.reference else None
        rb = _grid_row("rosenbrock", note=f"compiled, step {GRID_FIXED_STEP_S * 1e3:g} ms")
        rows = [rb, *engine_rows(args.quick, rosenbrock_row=rb, reference_summary=ref)]
    else:
        rows = bench_rows(args.quick)
    rep = report(rows)
    atomic_write_text(Path(args.out), json.dumps(rep, indent=2, default=str) + "\n")
    print(table(rows))
    print(f"load average {rep['load_average'][0]:.2f} on {rep['cpus']} CPUs; JSON in {args.out}")
    return 0


if __name__ == "__main__":
    import logging
    import sys

    logging.basicConfig(level=logging.WARNING)
    sys.exit(main())
