"""Closed-loop path tracking: the MPC against a plant.

The loop is the simulation's one time loop (:func:`symtrack.simulation.loop.run`) with the MPC
as its sampled torque law (:class:`TrackingLaw`). The plant is any plant of
:mod:`symtrack.simulation.plants` (the protocol :class:`~symtrack.simulation.plants.Plant`): its
``state_names`` must contain the vehicle states of the model's layout
(``model.layout.vehicle_names``: the 12 of :data:`symtrack.vehicles.planar.VEHICLE_STATES`). Each
sample the loop advances it by the sample time with the commands held (in sub-steps of the
plant's ``macro_step_s`` when it has one: the grid's world-manager step).

The plant is built by the one plant factory (:func:`~symtrack.simulation.plants.make_plant`, with
the MPC's choices of :meth:`~symtrack.control.scenario.MPCScenario.plant_setup`). The default plant,
:class:`~symtrack.simulation.plants.StepPlant`, is the full simulator
(CVODES/IDAS on the SystemModel with its terrain cells), not the MPC's prediction model: the
mismatch (cells frozen in the prediction, collocation error, the plant's tight tolerances) is
real. With a ``[terrain]`` section the plant is the vehicle on the persistent grid terrain
(the field around the path unless the section sizes it): by default the terrain engine
(:class:`~symtrack.simulation.plants.EnginePlant`, ``grid_fast``, 10 ms macro steps), with
``run.integrator = "idas"`` (the reference) or ``"rosenbrock"`` a
:class:`~symtrack.simulation.plants.GridPlant` (:func:`grid_integrator`). A plant whose state
carries the homogeneous terrain's cell states by name gives them to the prediction; another plant
(the grid terrain) leaves the prediction's cells at those of steady straight running.

The loop starts the plant at the trim state of steady straight running at the start speed
(``plant.start(pose, u, state)``; the grid first sets the vehicle down on its cells) and
finishes it after the loop (the grid lifts the vehicle off); the plant's ``figures()`` are
merged into the summary, and the plant's share of the loop's wall time is reported as
``plant_wall_time_s``.
"""

from __future__ import annotations

import io
import json
import logging
import math
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foundations.config import to_toml
from ..foundations.errors import ScenarioError, SimulationError
from ..foundations.progress import Progress, timed_step
from ..model import SystemModel
from ..reports.run_files import TerrainOut, terrain_run, write_folder
from ..simulation import loop
from ..simulation.builder import system_model
from ..simulation.plants import make_plant
from ..vehicles.base import CONTACT_HULL
from .mpc import PathTrackingMPC, realtime_figures
from .scenario import (
    FIELD_MARGIN_M,
    GRID_ABSTOL,
    GRID_RELTOL,
    GRID_SUBSTEP_S,
    MPCScenario,
    field_from_path,
    grid_integrator,
)
from .trim import trim

log = logging.getLogger("symtrack.control.closedloop")

SUMMARY_SCHEMA_VERSION = 1
# the MPC's choices of plant (symtrack.control.scenario: MPCScenario.plant_setup), here as before
__all__ = ["FIELD_MARGIN_M", "GRID_ABSTOL", "GRID_RELTOL", "GRID_SUBSTEP_S", "ClosedLoopResult", "TrackingLaw",
           "closed_loop_files", "field_from_path", "grid_integrator", "initial_state", "make_plant", "run", "summarise",
           "write"]


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

    def state(self, name: str) -> np.ndarray:
        """The plant state ``name`` at the samples (a column of X, by name)."""
        return self.X[:, self.state_names.index(name)]

    def __repr__(self) -> str:
        from ..reports.html import short_repr

        return short_repr("ClosedLoopResult", self.scenario.name, self.summary,
                          ("sim_time_s", "rms_lateral_error_m", "max_lateral_error_m", "failed_solves",
                           "solve_time_median_ms", "wall_time_s"))

    def _repr_html_(self) -> str:
        """The view in a notebook: what ran (scenario, plant and its integrator, solver, machine, soil) and
        the summary's figures with their units."""
        from ..reports.html import machine_facts, notebook_html

        sc = self.scenario
        facts = [("scenario", sc.name), ("plant", sc.plant),
                 ("integrator", self.summary.get("plant_integrator", "")), ("solver", sc.mpc.solver),
                 *machine_facts(sc.vehicle_preset, sc.soil_preset, getattr(sc, "params", None)),
                 ("samples", len(self.t))]
        return notebook_html(f"MPC run {sc.name!r}", self.summary, facts)


def initial_state(model: SystemModel, sc: MPCScenario) -> np.ndarray:
    """Steady straight running at the start speed (trim), placed at the start pose. The 3D
    vehicle's trim is taken at the start pose (its hull settled on the ground there)."""
    if model.vehicle.contact == CONTACT_HULL:  # a hull settles on the ground at the start pose
        tp = trim(model, sc.params, sc.start.speed_m_s,
                  pose=(sc.start.x_m, sc.start.y_m, math.radians(sc.start.yaw_deg)))
    else:
        tp = trim(model, sc.params, sc.start.speed_m_s)
    x = tp.x.copy()
    x[model.state_index("x_m")] = sc.start.x_m
    x[model.state_index("y_m")] = sc.start.y_m
    x[model.state_index("yaw_rad")] = math.radians(sc.start.yaw_deg)
    return x, tp.u.copy()


def plant_integrator(plant) -> str | None:
    """The integrator a plant runs: "grid_fast" for the terrain engine, else its stepper's method."""
    if getattr(plant, "engine", None) is not None:
        return "grid_fast"
    settings = getattr(getattr(plant, "stepper", None), "settings", None)
    return getattr(settings, "method", None)


def cidx_missing(plant, mpc) -> bool:
    """True when the prediction has cells the plant's state does not carry (e.g. the grid plant)."""
    return bool(mpc.cell_names) and not all(n in plant.state_names for n in mpc.cell_names)


class TrackingLaw:
    """The MPC as a sampled torque law of the one time loop (:class:`~symtrack.simulation.loop.SampledLaw`):
    every ``sample_time_s`` it projects the plant's state on the path, records the sample (time,
    state, reference, errors) and returns the MPC's torques, or None at the path's end or after
    ``max_steps`` samples. Its first call solves the cold start (:meth:`PathTrackingMPC.prepare`,
    reported apart from the per-sample statistics). The records are the rows of the
    :class:`ClosedLoopResult` (:meth:`result`)."""

    def __init__(self, sc: MPCScenario, mpc, path, state_names, u_prev, cell_default, substep_s: float | None,
                 max_steps: int | None = None):
        self.sc, self.mpc, self.path, self.max_steps = sc, mpc, path, max_steps
        self.sample_time_s, self.substep_s = sc.mpc.sample_time_s, substep_s
        names = tuple(state_names)
        self.pidx = [names.index(n) for n in mpc.pred_names if n in names]
        if len(self.pidx) != len(mpc.pred_names):
            missing = [n for n in mpc.pred_names if n not in names]
            if mpc.cell_names or any(n in mpc.model.layout.vehicle_names for n in missing):
                raise SimulationError(f"the plant's state has no {', '.join(missing)}: the MPC cannot read it")
        self.cell_default = cell_default
        self.cidx = [names.index(n) for n in mpc.cell_names] if all(n in names for n in mpc.cell_names) else None
        self.ix, self.iy, self.ipsi = (names.index(n) for n in ("x_m", "y_m", "yaw_rad"))
        self.u_prev = np.asarray(u_prev, dtype=float).copy()
        self.s_hint = self.cold = None
        self.k = 0
        self.law_wall_s = 0.0  # wall time in the law (the solver, the path), for the plant's share
        self.cold_wall_s = 0.0  # ... of it the cold start's (not in the loop's wall time, as before the loop)
        self.rows = {n: [] for n in ("t", "x", "u", "ref", "s", "e_lat", "e_psi", "straight", "solve_ms",
                                     "solve_ok", "solve_iter")}
        self.bar = None

    def _cells(self, x):
        if not self.mpc.cell_names:
            return None
        return x[self.cidx] if self.cidx is not None else self.cell_default

    def __call__(self, t_s: float, x: np.ndarray, final: bool = False):
        w0 = time.perf_counter()
        try:
            return self._sample(t_s, x, final)
        finally:
            self.law_wall_s += time.perf_counter() - w0

    def _sample(self, t_s, x, final):
        path, mpc, r = self.path, self.mpc, self.rows
        N, dt = self.sc.mpc.horizon_steps, self.sc.mpc.sample_time_s
        if self.cold is None:  # the cold start before the loop engages
            w0 = time.perf_counter()
            self.s_hint = path.project(x[self.ix], x[self.iy])
            ref0 = path.reference(self.s_hint, N, dt, x[self.ipsi])
            self.cold = mpc.prepare(x[self.pidx], self._cells(x), self.u_prev, ref0)
            self.cold_wall_s = time.perf_counter() - w0
        self.s_hint = s_hint = path.project(x[self.ix], x[self.iy], self.s_hint)
        e_l, e_p = path.errors(x[self.ix], x[self.iy], x[self.ipsi], s_hint)
        here = path.at(s_hint)
        r["t"].append(t_s)
        r["x"].append(x.copy())
        r["s"].append(s_hint)
        r["e_lat"].append(e_l)
        r["e_psi"].append(e_p)
        r["straight"].append(here["straight"] and here["segment"] >= 0)
        r["ref"].append([here["x_m"], here["y_m"], here["yaw_rad"], here["speed_m_s"], here["curvature_1_per_m"]])
        if self.bar is not None:
            self.bar.update(s_hint, f"t={t_s:.1f} s e_lat={100 * e_l:+.1f} cm")
        if (final or s_hint >= path.length_m or t_s >= self.sc.run.duration_s - 1e-9
                or (self.max_steps is not None and self.k >= self.max_steps)):
            r["u"].append(self.u_prev.copy())
            return None
        ref = path.reference(s_hint, N, dt, x[self.ipsi])
        u, info = mpc.step(x[self.pidx], self._cells(x), self.u_prev, ref)
        r["solve_ms"].append(1e3 * info.solve_time_s)
        r["solve_ok"].append(info.success)
        r["solve_iter"].append(info.iterations)
        r["u"].append(u.copy())
        self.u_prev = u
        self.k += 1
        return u

    def result(self, plant) -> ClosedLoopResult:
        """The closed loop's rows (one per sample) as a :class:`ClosedLoopResult` (summary empty)."""
        r = self.rows
        return ClosedLoopResult(self.sc, np.array(r["t"]), np.array(r["x"]), np.array(r["u"]), np.array(r["ref"]),
                                np.array(r["s"]), np.array(r["e_lat"]), np.array(r["e_psi"]),
                                np.array(r["straight"], bool), np.array(r["solve_ms"]), np.array(r["solve_ok"], bool),
                                np.array(r["solve_iter"]), tuple(plant.state_names), {}, self.path, plant)


def run(sc: MPCScenario, plant=None, model: SystemModel | None = None, mpc: PathTrackingMPC | None = None,
        x0=None, progress: bool = False, max_steps: int | None = None, finish: bool = True) -> ClosedLoopResult:
    """The closed loop until the path's end, ``run.duration_s`` or ``max_steps``: the MPC
    (:class:`TrackingLaw`) as the sampled torque law of the one time loop
    (:func:`symtrack.simulation.loop.run`). The plant is started at the vehicle's trim state of
    straight running (or at ``x0``, values of the plant's ``state_names``); with ``finish``
    (default) the plant is finished after the loop (the grid lifts the vehicle off)."""
    with timed_step("building the vehicle model", log):
        model = model or system_model(sc.model, sc.surface)
    if model.opts != sc.model:
        raise ScenarioError(f"the model's options ({model.opts}) differ from the scenario's [model] section "
                            f"({sc.model}): build the model as SystemModel(scenario.model)")
    if mpc is None:
        with timed_step(f"building the MPC's solver ({sc.mpc.solver}, {sc.mpc.horizon_steps} steps)", log):
            mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    with timed_step("building the plant", log):
        plant = plant or make_plant(sc, model)
    world = getattr(plant, "world", None)
    if world is not None:
        log.info("grid plant (%s): %d x %d cells of %g m, M = %d (%d channels)", plant_integrator(plant),
                 *world.grid.shape, world.grid.cell_m, world.M, world.n_channels)
    path = sc.build_path()
    xt, ut = initial_state(model, sc)
    if x0 is None:
        if tuple(plant.state_names) == tuple(model.state_names):
            x0 = xt
        elif tuple(plant.state_names) == model.layout.vehicle_names:
            x0 = xt[model.layout.block("vehicle")]
        else:
            raise SimulationError("the plant's state differs from the model's: give x0 (the plant's initial "
                                  "state, e.g. the vehicle states of initial_state() placed into it)")
    x0 = np.asarray(x0, float)
    names0 = plant.state_names
    if x0 is xt:
        u_prev = ut.copy()
    else:
        # the command that holds the actual torques where they are
        u_prev = np.array([x0[names0.index(f"torque_{k}_N_m")] for k in ("left", "right")])
    ix0, iy0, ipsi0 = (names0.index(n) for n in ("x_m", "y_m", "yaw_rad"))
    # a plant without the homogeneous cells (the grid): the prediction freezes its cells at those
    # of steady straight running at the start speed (trim), as the homogeneous plant starts
    cell_default = xt[model.layout.block("cells")] if cidx_missing(plant, mpc) else None
    law = TrackingLaw(sc, mpc, path, names0, u_prev, cell_default, getattr(plant, "macro_step_s", None), max_steps)
    law.bar = Progress(path.length_m, sc.name, enabled=progress)
    try:
        run_res = loop.run(sc, plant, torque_law=law, finish=finish,
                           start=loop.StartPoint(x0[ix0], x0[iy0], x0[ipsi0], u_prev, x0))
    except loop.IncompleteRun as err:  # the plant failed: the closed loop reports the plant's error
        raise err.__cause__ from None
    finally:
        law.bar.close()
    res = law.result(plant)
    wall = run_res.wall_time_s - law.cold_wall_s  # the loop's wall time after the cold start
    plant_wall = max(0.0, wall - (law.law_wall_s - law.cold_wall_s))
    cold = law.cold
    res.summary = summarise(res, wall, mpc)
    res.summary["initial_solve_ms"] = 1e3 * cold.solve_time_s
    res.summary["initial_solve_success"] = cold.success
    res.summary["plant"] = getattr(plant, "kind", type(plant).__name__)
    res.summary["plant_integrator"] = plant_integrator(plant)
    res.summary["plant_wall_time_s"] = plant_wall
    res.summary["solver_wall_time_s"] = float(np.sum(res.solve_ms) / 1e3)
    res.summary["plant_wall_time_per_sim_s"] = plant_wall / res.summary["sim_time_s"] if res.summary[
        "sim_time_s"] > 0 else None
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
        "jit": sc.mpc.uses_jit,
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
        "solve_time_mean_ms": float(np.mean(ms)),
        "solve_time_p95_ms": float(np.percentile(ms, 95)),
        "solve_time_max_ms": float(np.max(ms)),
        "solve_iterations_median": float(np.median(res.solve_iter)) if res.solve_iter.size else None,
        "solves": int(res.solve_ms.size),
        "failed_solves": int(mpc.stats.failed),
        "fallback_solves": int(getattr(mpc.stats, "fallbacks", 0)),
        "solve_status_counts": dict(Counter(str(i.status) for i in mpc.stats.solves)),
        "path_length_m": float(res.path.length_m),
        "path_completed": bool(res.s[-1] >= res.path.length_m),
        "sim_time_s": float(res.t[-1]),
        "wall_time_s": float(wall_s),
        "torque_cmd_max_abs_N_m": float(np.max(np.abs(res.U))),
        "torque_cmd_rate_max_abs_N_m_s": float(np.max(np.abs(np.diff(res.U, axis=0))) / sc.mpc.sample_time_s)
        if len(res.U) > 1 else 0.0,
        "machine_note": "solve times measured on this machine in this run (wall clock of the solver call)",
    }
    # overruns of the sample time, RTI preparation times
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


def closed_loop_files(res: ClosedLoopResult) -> dict[str, str | bytes]:
    """The folder of a closed loop: trajectory.csv, path.csv, scenario.resolved.toml (as
    ``symtrack simulate``'s: a scenario file that loads back to the scenario as run), the
    ``control`` figures of :mod:`symtrack.reports.figures`, report.html (what ran, the summary, the
    figures and the scenario on one page), summary.json."""
    from ..reports.figures import figures  # matplotlib: imported when a run draws
    from ..reports.html import report_html
    from ..reports.run_files import what_ran

    scenario_toml = to_toml(res.scenario.resolved_dict())
    images = figures("control", res)
    sm = res.summary
    note = (f"The {sm.get('solver')} MPC ({sm.get('horizon_steps')} steps of {sm.get('sample_time_s')} s) tracking "
            f"the path of scenario '{sm.get('scenario')}': {sm.get('solves')} solves, {sm.get('failed_solves')} "
            f"failed, median {sm.get('solve_time_median_ms', float('nan')):.3g} ms.")
    sc = res.scenario
    note += " " + what_ran(sc, sm, ground=f"the {sm.get('plant', sc.plant)} plant",
                           integrator=sm.get("plant_integrator") or "")
    return {"trajectory.csv": trajectory_csv(res), "path.csv": path_csv(res), "scenario.resolved.toml": scenario_toml,
            **images, "report.html": report_html(f"symtrack mpc: {sm.get('scenario')}", sm, images, scenario_toml,
                                                 note=note).encode(),
            "summary.json": json.dumps(sm, indent=2) + "\n"}


def write(out_dir, res: ClosedLoopResult, terrain_out=None, plant=None) -> list:
    """Write the closed loop's folder (:func:`closed_loop_files`) with the one writer
    (:func:`~symtrack.reports.run_files.write_folder`: a previous run's files removed first,
    summary.json last, all or nothing); with ``terrain_out`` the grid ``plant``'s terrain file
    with them, this run in its history (``summary["terrain_run_id"]``). Returns the paths written."""
    terrain = None
    if terrain_out is not None:
        run = terrain_run(res.scenario, 1)
        terrain = TerrainOut(Path(terrain_out), plant.world.storage, res.scenario.params, run)
        res.summary["terrain_out"] = str(terrain_out)
        res.summary["terrain_run_id"] = run["run_id"]
    return write_folder(out_dir, closed_loop_files(res), terrain=terrain)
