"""Running a scenario: the time loop, the stop-at-distance rule and the summary figures."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .errors import SimulationError
from .model import SystemModel
from .progress import Progress
from .scenario import Scenario
from .simulate import FIXED_STEP_INTEGRATORS, IntegratorSettings, Stepper, static_state

SUMMARY_SCHEMA_VERSION = 1
INPUT_COLUMNS = ("torque_cmd_left_N_m", "torque_cmd_right_N_m")


@dataclass
class Result:
    scenario: Scenario
    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    state_names: tuple
    output_names: tuple
    wall_time_s: float
    stopped_by: str
    stats: dict = field(default_factory=dict)
    terrain: dict | None = None  # grid terrain figures of the run (symtrack.terrain.world)

    def state(self, name):
        return self.X[:, self.state_names.index(name)]

    def output(self, name):
        return self.Y[:, self.output_names.index(name)]

    def column(self, name):
        if name in INPUT_COLUMNS:
            return self.U[:, INPUT_COLUMNS.index(name)]
        if name in self.state_names:
            return self.state(name)
        return self.output(name)


def build_model(scenario: Scenario) -> SystemModel:
    return SystemModel(scenario.model)


def run(scenario: Scenario, progress: bool = True, model: SystemModel | None = None, world=None) -> Result:
    """One run (one pass). With a ``[terrain]`` section, or a ``world`` (a
    :class:`symtrack.terrain.world.World`, shared by several passes), the grid terrain's world
    manager assigns channels before and writes the cells back after every macro step."""
    if world is None and "terrain" in scenario.extra:
        from .terrain.study import make_world

        world = make_world(scenario)
    if scenario.run.integrator == "grid_fast":  # issue 9: the terrain engine (symtrack/terrain/engine.py)
        if world is None:
            raise SimulationError('run.integrator = "grid_fast" needs a [terrain] section (the grid terrain engine)')
        from .terrain import engine

        return engine.run(scenario, world, progress)
    model = world.model if world is not None else (model or build_model(scenario))
    params = scenario.params
    p = model.param_vector(params) if world is None else world.param_vector()
    settings = IntegratorSettings(scenario.run.integrator, scenario.run.reltol, scenario.run.abstol,
                                  compiled=scenario.run.compiled, fixed_step_s=scenario.run.fixed_step_s)
    if settings.method in FIXED_STEP_INTEGRATORS and world is None:
        # the same time loop, with the inner loop (many steps per call) in generated C; with a
        # grid world the loop below runs it step by step (simulate.Stepper -> FixedStepper)
        from .compiled import run_fixed_step

        return run_fixed_step(scenario, model, settings, progress)
    stepper = Stepper(model, settings) if world is None else world.stepper(settings)
    st = scenario.start
    if world is None:
        x = static_state(model, params, st.x_m, st.y_m, np.radians(st.yaw_deg))
    else:
        x = world.begin_pass(stepper, st.x_m, st.y_m, np.radians(st.yaw_deg))
        p = world.param_vector()  # the channels the settled start holds

    run_cfg = scenario.run
    dt = run_cfg.output_dt_s
    change_times = [e.t_s for e in scenario.torque[1:]]
    dist_from = None
    if run_cfg.stop_after_distance_m is not None:
        dist_from = scenario.event_time(run_cfg.stop_distance_event) if run_cfg.stop_distance_event else 0.0

    t = 0.0
    u = np.array(scenario.torque_at(0.0))
    ts, xs, us, ys = [t], [x], [u], [np.array(model.outputs(x, u, p)).ravel()]
    dist = 0.0
    stopped_by = "duration"
    bar = Progress(1.0, scenario.name, enabled=progress)
    wall0 = time.perf_counter()
    while t < run_cfg.duration_s - 1e-12:
        # next point of the output grid k dt (no accumulated round-off), or a torque change
        t_next = min(float(np.floor(t / dt + 1e-9) + 1) * dt, run_cfg.duration_s)
        for tc in change_times:
            if t + 1e-12 < tc < t_next - 1e-12:
                t_next = tc
        u = np.array(scenario.torque_at(t))
        if world is not None:
            x, p = world.before_step(x, t_next - t, stepper)
        x_new = stepper.step(x, u, p, t_next - t)
        done = False
        if dist_from is not None and t_next > dist_from + 1e-12:
            d_step = float(np.hypot(x_new[0] - x[0], x_new[1] - x[1]))
            if dist + d_step >= run_cfg.stop_after_distance_m:
                # shorten the last step so the run ends at the distance (three secant refinements)
                h = t_next - t
                for _ in range(3):
                    if d_step <= 0:
                        break
                    h *= (run_cfg.stop_after_distance_m - dist) / d_step
                    x_new = stepper.step(x, u, p, h)
                    d_step = float(np.hypot(x_new[0] - x[0], x_new[1] - x[1]))
                t_next = t + h
                done = True
            dist += d_step
        t, x = t_next, x_new
        if world is not None:
            world.after_step(x)
            world.check_covered(x)
        ts.append(t)
        xs.append(x)
        us.append(u)
        ys.append(np.array(model.outputs(x, u, p)).ravel())
        frac = t / run_cfg.duration_s
        if dist_from is not None:
            frac = max(frac, dist / run_cfg.stop_after_distance_m)
        bar.update(frac, f"t={t:.2f} s" + (f" d={dist:.2f} m" if dist_from is not None else ""))
        if done:
            stopped_by = "distance"
            break
    bar.close()
    wall = time.perf_counter() - wall0
    if world is not None:
        world.end_pass(x)  # lift the vehicle off: the loaded cells unload and go back to storage
    if dist_from is not None and stopped_by != "distance":
        raise SimulationError(
            f"the run reached run.duration_s = {run_cfg.duration_s} s before covering "
            f"run.stop_after_distance_m = {run_cfg.stop_after_distance_m} m (covered {dist:.2f} m); "
            "raise duration_s")
    return Result(scenario, np.array(ts), np.array(xs), np.array(us), np.array(ys),
                  model.state_names, model.output_names, wall, stopped_by,
                  terrain=None if world is None else world.figures())


def summarise(res: Result) -> dict:
    sc = res.scenario
    X0, Y0, psi0 = res.X[0, 0], res.X[0, 1], res.X[0, 2]
    xe, ye, psie = res.X[-1, 0], res.X[-1, 1], res.X[-1, 2]
    lateral = -(xe - X0) * np.sin(psi0) + (ye - Y0) * np.cos(psi0)
    seg = np.hypot(np.diff(res.X[:, 0]), np.diff(res.X[:, 1]))
    out = {
        "schema_version": SUMMARY_SCHEMA_VERSION,
        "scenario": sc.name,
        "integrator": sc.run.integrator,
        "stopped_by": res.stopped_by,
        "distance_m": float(seg.sum()),
    }
    if sc.run.stop_distance_event:
        te = sc.event_time(sc.run.stop_distance_event)
        after = res.t[1:] > te + 1e-12
        out[f"distance_after_{sc.run.stop_distance_event}_m"] = float(seg[after].sum())
    out["lateral_deviation_m"] = float(abs(lateral))
    out["lateral_deviation_signed_m"] = float(lateral)
    out["yaw_final_deg"] = float(np.degrees(psie - psi0))
    ends = {}
    for end in ("sprocket", "idler"):
        mean = 0.5 * (res.column(f"sinkage_{end}_left_m") + res.column(f"sinkage_{end}_right_m"))
        ends[end] = float(mean.max())
        out[f"sinkage_{end}_mm"] = 1e3 * ends[end]
    last = sc.torque[-1]
    jl, jr = res.state("shear_left_m"), res.state("shear_right_m")
    if abs(last.left_N_m) != abs(last.right_N_m) and res.t[-1] >= last.t_s:
        driven, idle = (jr, jl) if abs(last.right_N_m) > abs(last.left_N_m) else (jl, jr)
        since = res.t >= last.t_s
        out["shear_driven_max_m"] = float(driven[since].max())
        out["shear_idle_min_m"] = float(idle[since].min())
    else:
        out["shear_driven_max_m"] = float(max(jl.max(), jr.max()))
        out["shear_idle_min_m"] = None
    out["speed_final_m_s"] = float(res.state("u_m_s")[-1])
    out["nose_up"] = bool(ends["sprocket"] > ends["idler"])
    out["sim_time_s"] = float(res.t[-1])
    out["wall_time_s"] = float(res.wall_time_s)
    out["real_time_factor"] = float(res.t[-1] / res.wall_time_s) if res.wall_time_s > 0 else None
    if res.terrain:
        out.update(res.terrain)
    return out
