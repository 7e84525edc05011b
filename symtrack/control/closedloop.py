"""Closed-loop path tracking: the MPC against a plant.

The plant is any object with

- ``state_names``: names of its state vector (it must contain the 12 vehicle states of
  :data:`symtrack.model.vehicle.VEHICLE_STATES`);
- ``step(x, u, dt) -> x``: advance the state over dt [s] with the commanded torques u held.

The default plant, :class:`~symtrack.control.plants.HomogeneousPlant`, is the full simulator
(CVODES/IDAS on the SystemModel with its terrain cells), not the MPC's prediction model: the
mismatch (cells frozen in the prediction, collocation error, the plant's tight tolerances) is
real. With a ``[terrain]`` section the plant is :class:`~symtrack.control.plants.GridPlant`, the
vehicle on the persistent grid terrain. A plant whose state carries the homogeneous terrain's
cell states by name gives them to the prediction; another plant (the grid terrain) leaves the
prediction's cells at the static equilibrium on the scenario's soil.

Optional plant hooks: ``start(x_vehicle) -> x`` (the loop's initial plant state from the
vehicle's trim state), ``finish(x)`` (after the loop, e.g. lift the vehicle off the grid),
``figures() -> dict`` (merged into the summary) and ``wall_time_s`` (the plant's share of the
loop's wall time, reported as ``plant_wall_time_s``).
"""

from __future__ import annotations

import io
import json
import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from ..model import SystemModel
from ..model.vehicle import VEHICLE_STATES
from ..output import atomic_write_bytes, atomic_write_text
from ..progress import Progress
from .mpc import PathTrackingMPC, realtime_figures
from .plants import HomogeneousPlant, make_grid_plant
from .scenario import MPCScenario
from .trim import trim

log = logging.getLogger("symtrack.control.closedloop")

SUMMARY_SCHEMA_VERSION = 1
__all__ = ["HomogeneousPlant", "ClosedLoopResult", "initial_state", "make_plant", "run", "summarise", "write"]


@dataclass
class ClosedLoopResult:
    scenario: MPCScenario
    t: np.ndarray
    X: np.ndarray  # plant states
    U: np.ndarray  # commands applied from t_k to t_k+1 (last row repeats)
    ref: np.ndarray  # reference point (x, y, yaw, speed, curvature) at each sample
    s: np.ndarray  # path arc length of the projection
    e_lat: np.ndarray
    e_psi: np.ndarray
    straight: np.ndarray
    solve_ms: np.ndarray
    solve_ok: np.ndarray
    solve_iter: np.ndarray
    state_names: tuple
    summary: dict
    path: object
    plant: object = None


def initial_state(model: SystemModel, sc: MPCScenario) -> np.ndarray:
    """Steady straight running at the start speed (trim), placed at the start pose."""
    tp = trim(model, sc.params, sc.start.speed_m_s)
    x = tp.x.copy()
    x[model.state_index("x_m")] = sc.start.x_m
    x[model.state_index("y_m")] = sc.start.y_m
    x[model.state_index("yaw_rad")] = math.radians(sc.start.yaw_deg)
    return x, tp.u.copy()


def make_plant(sc: MPCScenario, model: SystemModel, terrain_in: str | None = None):
    """The scenario's plant: the grid terrain with a [terrain] section, else the homogeneous one."""
    if sc.terrain is not None or terrain_in:
        if sc.terrain is None:
            import dataclasses

            sc = dataclasses.replace(sc, terrain={})
        return make_grid_plant(sc, terrain_in)
    return HomogeneousPlant(model, sc.params, sc.run.integrator)


def cidx_missing(plant, mpc) -> bool:
    """True when the prediction has cells the plant's state does not carry (e.g. the grid plant)."""
    return bool(mpc.cell_names) and not all(n in plant.state_names for n in mpc.cell_names)


def run(sc: MPCScenario, plant=None, model: SystemModel | None = None, mpc: PathTrackingMPC | None = None,
        x0=None, progress: bool = False, max_steps: int | None = None, finish: bool = True) -> ClosedLoopResult:
    """The closed loop until the path's end, ``run.duration_s`` or ``max_steps``. A plant with
    ``start`` gets the vehicle's trim state there (unless x0 is given); with ``finish`` (default)
    the plant's ``finish`` hook runs after the loop."""
    model = model or SystemModel()
    mpc = mpc or PathTrackingMPC(model, sc.params, sc.mpc)
    plant = plant or make_plant(sc, model)
    path = sc.build_path()
    dt, N = sc.mpc.sample_time_s, sc.mpc.horizon_steps
    if x0 is None and hasattr(plant, "start"):
        xt, _ = initial_state(model, sc)
        x0 = plant.start(xt[:len(VEHICLE_STATES)])
    if x0 is None:
        if tuple(plant.state_names) != tuple(model.state_names):
            from ..errors import SimulationError

            raise SimulationError("the plant's state differs from the model's: give x0 (the plant's initial "
                                  "state, e.g. the vehicle states of initial_state() placed into it)")
        x, u_prev = initial_state(model, sc)
    else:
        x = np.asarray(x0, float)
        # the command that holds the actual torques where they are
        u_prev = np.array([x[plant.state_names.index(f"torque_{k}_N_m")] for k in ("left", "right")])
    pidx = [plant.state_names.index(n) for n in mpc.pred_names if n in plant.state_names]
    if len(pidx) != len(mpc.pred_names):
        missing = [n for n in mpc.pred_names if n not in plant.state_names]
        if mpc.cell_names or any(n in VEHICLE_STATES for n in missing):
            from ..errors import SimulationError

            raise SimulationError(f"the plant's state has no {', '.join(missing)}: the MPC cannot read it")
    # a plant without the homogeneous cells (the grid): the prediction freezes its cells at those
    # of steady straight running at the start speed (trim), as the homogeneous plant starts
    cell_default = initial_state(model, sc)[0][len(VEHICLE_STATES):] if cidx_missing(plant, mpc) else None
    cidx = [plant.state_names.index(n) for n in mpc.cell_names] if all(
        n in plant.state_names for n in mpc.cell_names) else None
    ts, xs, us, refs, ss, elat, epsi, strt, sms, sok, sit = ([] for _ in range(11))
    s_hint = path.project(x[plant.state_names.index("x_m")], x[plant.state_names.index("y_m")])
    ix, iy, ipsi = (plant.state_names.index(n) for n in ("x_m", "y_m", "yaw_rad"))
    # cold start before the loop engages (reported separately, not in the per-step statistics)
    ref0 = path.reference(s_hint, N, dt, x[ipsi])
    xc0 = (x[cidx] if cidx is not None else cell_default) if mpc.cell_names else None
    cold = mpc.prepare(x[pidx], xc0, u_prev, ref0)
    bar = Progress(path.length_m, sc.name, enabled=progress)
    t = 0.0
    k = 0
    wall0 = time.perf_counter()
    while True:
        s_hint = path.project(x[ix], x[iy], s_hint)
        e_l, e_p = path.errors(x[ix], x[iy], x[ipsi], s_hint)
        here = path.at(s_hint)
        ts.append(t)
        xs.append(x.copy())
        ss.append(s_hint)
        elat.append(e_l)
        epsi.append(e_p)
        strt.append(here["straight"] and here["segment"] >= 0)
        refs.append([here["x_m"], here["y_m"], here["yaw_rad"], here["speed_m_s"], here["curvature_1_per_m"]])
        if s_hint >= path.length_m or t >= sc.run.duration_s - 1e-9 or (max_steps is not None and k >= max_steps):
            us.append(u_prev.copy())
            break
        ref = path.reference(s_hint, N, dt, x[ipsi])
        xp = x[pidx]
        xc = (x[cidx] if cidx is not None else cell_default) if mpc.cell_names else None
        u, info = mpc.step(xp, xc, u_prev, ref)
        sms.append(1e3 * info.solve_time_s)
        sok.append(info.success)
        sit.append(info.iterations)
        us.append(u.copy())
        x = plant.step(x, u, dt)
        u_prev = u
        t += dt
        k += 1
        bar.update(s_hint, f"t={t:.1f} s e_lat={100 * e_l:+.1f} cm")
    bar.close()
    wall = time.perf_counter() - wall0
    plant_wall = float(getattr(plant, "wall_time_s", float("nan")))
    if finish and hasattr(plant, "finish"):
        plant.finish(x)
    res = ClosedLoopResult(sc, np.array(ts), np.array(xs), np.array(us), np.array(refs), np.array(ss),
                           np.array(elat), np.array(epsi), np.array(strt, bool), np.array(sms),
                           np.array(sok, bool), np.array(sit), tuple(plant.state_names), {}, path, plant)
    res.summary = summarise(res, wall, mpc)
    res.summary["initial_solve_ms"] = 1e3 * cold.solve_time_s
    res.summary["initial_solve_success"] = cold.success
    res.summary["plant"] = getattr(plant, "kind", type(plant).__name__)
    res.summary["plant_wall_time_s"] = plant_wall
    res.summary["solver_wall_time_s"] = float(np.sum(res.solve_ms) / 1e3)
    res.summary["plant_wall_time_per_sim_s"] = plant_wall / res.summary["sim_time_s"] if res.summary[
        "sim_time_s"] > 0 else None
    if hasattr(plant, "figures"):
        res.summary.update(plant.figures())
    if getattr(plant, "kind", None) == "grid":
        res.summary.update(rut_figures(plant))
    return res


def summarise(res: ClosedLoopResult, wall_s: float, mpc: PathTrackingMPC) -> dict:
    sc = res.scenario
    keep = res.straight & (res.s >= sc.run.rms_exclude_first_m)
    e = res.e_lat
    ms = res.solve_ms if res.solve_ms.size else np.array([np.nan])
    on_path = res.s < res.path.length_m
    out = {
        "schema_version": SUMMARY_SCHEMA_VERSION,
        "scenario": sc.name,
        "solver": sc.mpc.solver,
        "jit": sc.mpc.jit,
        "prediction": sc.mpc.prediction,
        "horizon_s": sc.mpc.horizon_s,
        "horizon_steps": sc.mpc.horizon_steps,
        "sample_time_s": sc.mpc.sample_time_s,
        "rms_lateral_error_m": float(np.sqrt(np.mean(e[keep] ** 2))) if keep.any() else None,
        "rms_lateral_error_note": (f"straight segments, from s = {sc.run.rms_exclude_first_m:g} m of path on"),
        "max_lateral_error_m": float(np.max(np.abs(e[on_path]))) if on_path.any() else float(np.max(np.abs(e))),
        "max_lateral_error_straights_m": float(np.max(np.abs(e[keep]))) if keep.any() else None,
        "rms_lateral_error_all_m": float(np.sqrt(np.mean(e ** 2))),
        "max_heading_error_deg": float(np.degrees(np.max(np.abs(res.e_psi)))),
        "solve_time_median_ms": float(np.median(ms)),
        "solve_time_p95_ms": float(np.percentile(ms, 95)),
        "solve_time_max_ms": float(np.max(ms)),
        "solve_iterations_median": float(np.median(res.solve_iter)) if res.solve_iter.size else None,
        "solves": int(res.solve_ms.size),
        "failed_solves": int(mpc.stats.failed),
        "fallback_solves": int(getattr(mpc.stats, "fallbacks", 0)),
        "path_length_m": float(res.path.length_m),
        "path_completed": bool(res.s[-1] >= res.path.length_m),
        "sim_time_s": float(res.t[-1]),
        "wall_time_s": float(wall_s),
        "torque_cmd_max_abs_N_m": float(np.max(np.abs(res.U))),
        "torque_cmd_rate_max_abs_N_m_s": float(np.max(np.abs(np.diff(res.U, axis=0))) / sc.mpc.sample_time_s)
        if len(res.U) > 1 else 0.0,
        "machine_note": "solve times measured on this machine in this run (wall clock of the solver call)",
    }
    # issue 13 (real-time honesty): overruns of the sample time, RTI preparation times
    out.update(realtime_figures(mpc.stats, sc.mpc.sample_time_s))
    return out


def trajectory_csv(res: ClosedLoopResult) -> str:
    n = len(res.t)
    sm = np.full(n, np.nan)
    ok = np.full(n, np.nan)
    sm[:len(res.solve_ms)] = res.solve_ms
    ok[:len(res.solve_ok)] = res.solve_ok
    names = (["t_s"] + list(res.state_names) + ["torque_cmd_left_N_m", "torque_cmd_right_N_m"]
             + ["ref_x_m", "ref_y_m", "ref_yaw_rad", "ref_speed_m_s", "ref_curvature_1_per_m", "path_s_m",
                "lateral_error_m", "heading_error_rad", "on_straight", "solve_time_ms", "solve_ok"])
    data = np.hstack([res.t[:, None], res.X, res.U, res.ref, res.s[:, None], res.e_lat[:, None],
                      res.e_psi[:, None], res.straight[:, None].astype(float), sm[:, None], ok[:, None]])
    buf = io.StringIO()
    np.savetxt(buf, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    return buf.getvalue()


def path_csv(res: ClosedLoopResult) -> str:
    p = res.path
    buf = io.StringIO()
    data = np.column_stack([p.s, p.x, p.y, p.psi, p.kappa, p.speed, p.segment, p.straight.astype(float)])
    np.savetxt(buf, data, delimiter=",", comments="", fmt="%.10g",
               header="s_m,x_m,y_m,yaw_rad,curvature_1_per_m,speed_m_s,segment,straight")
    return buf.getvalue()


def plots(res: ClosedLoopResult) -> dict[str, bytes]:
    from ..plots import _png, plt

    out = {}
    p = res.path
    ix, iy = res.state_names.index("x_m"), res.state_names.index("y_m")
    fig, ax = plt.subplots(figsize=(8, 6))
    on = p.segment >= 0
    ax.plot(p.x[on], p.y[on], "k--", lw=1, label="reference path")
    ax.plot(res.X[:, ix], res.X[:, iy], "C0", lw=1.5, label="vehicle (CG)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend()
    ax.set_title(f"{res.scenario.name}: path")
    out["path.png"] = _png(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    a1.plot(res.s, 100 * res.e_lat)
    a1.set_ylabel("lateral error [cm]")
    a1.grid(True)
    a2.plot(res.s, np.degrees(res.e_psi))
    a2.set_ylabel("heading error [deg]")
    a2.set_xlabel("path length s [m]")
    a2.grid(True)
    for a in (a1, a2):
        lo, hi = a.get_ylim()
        a.fill_between(res.s, lo, hi, where=~res.straight, color="0.9", step="mid", label="turn")
        a.set_ylim(lo, hi)
    a1.set_title("tracking errors (grey: turns)")
    out["errors.png"] = _png(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    for k, name in enumerate(("left", "right")):
        ax.step(res.t, res.U[:, k], where="post", label=f"{name} command")
        ax.plot(res.t, res.X[:, res.state_names.index(f"torque_{name}_N_m")], "--", label=f"{name} actual")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("torque [N m]")
    ax.grid(True)
    ax.legend()
    out["torques.png"] = _png(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(res.t[:len(res.solve_ms)], res.solve_ms, ".", ms=3)
    bad = ~res.solve_ok
    ax.plot(res.t[:len(res.solve_ms)][bad], res.solve_ms[bad], "rx", label="failed")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("solve time [ms]")
    ax.set_title(f"solver {res.scenario.mpc.solver}{' (jit)' if res.scenario.mpc.jit else ''}")
    ax.grid(True)
    out["solve_times.png"] = _png(fig)
    return out


def rut_figures(plant) -> dict:
    """Figures of the final terrain of a grid plant: the rut (cells loaded in the run, z_max > 1 um)."""
    world = plant.world
    st = world.storage
    rut = world.touched & (st.zmax > 1e-6)
    return {
        "rut_cells": int(rut.sum()),
        "rut_area_m2": float(rut.sum() * world.grid.cell_m ** 2),
        "rut_max_depth_mm": 1e3 * float(st.z[rut].max()) if rut.any() else 0.0,
        "rut_mean_depth_mm": 1e3 * float(st.z[rut].mean()) if rut.any() else 0.0,
        "rut_volume_m3": float(st.z[rut].sum() * world.grid.cell_m ** 2),
    }


def terrain_plots(res: ClosedLoopResult) -> dict[str, bytes]:
    """The final terrain of a grid plant: ``sinkage_map.png`` (top view, symtrack/terrain/plots.py)."""
    plant = res.plant
    if getattr(plant, "kind", None) != "grid":
        return {}
    from ..terrain.plots import sinkage_map_png

    return {"sinkage_map.png": sinkage_map_png(plant.world, plant.world.storage.copy_z(), 1)}


def write(out_dir, res: ClosedLoopResult) -> None:
    """trajectory.csv, path.csv, scenario.resolved.json, the plots, then summary.json (last)."""
    from pathlib import Path

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "trajectory.csv", trajectory_csv(res))
    atomic_write_text(out_dir / "path.csv", path_csv(res))
    atomic_write_text(out_dir / "scenario.resolved.json",
                      json.dumps({"schema_version": SUMMARY_SCHEMA_VERSION, **res.scenario.to_dict()}, indent=2) + "\n")
    for name, data in plots(res).items():
        atomic_write_bytes(out_dir / name, data)
    for name, data in terrain_plots(res).items():
        atomic_write_bytes(out_dir / name, data)
    atomic_write_text(out_dir / "summary.json", json.dumps(res.summary, indent=2) + "\n")
