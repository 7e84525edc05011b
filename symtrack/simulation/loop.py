"""The one time loop: any plant, the output grid, the torque programme, the stop rules,
progress, Ctrl-C and the errors, written once.

The output grid is k * output_dt_s (no accumulated round-off), split at the torque changes, up
to ``run.duration_s``. The stop-at-distance rule (``run.stop_after_distance_m``, counted from
the ``run.stop_distance_event``) shortens the last interval so that the run ends at the
distance (three secant refinements, :meth:`Plant.retry`). A plant that advances many intervals
per call (:class:`~symtrack.simulation.plants.BatchPlant`) gets short batches near the stopping
distance, so that little is computed past it.

A ``torque_law`` (``law(t_s, x) -> (left_N_m, right_N_m)``, x the plant's states) replaces the
torque programme by state feedback: it is sampled at the committed state before each plant call
and held over the call's intervals (a digital controller whose sample time is the plant's call:
one output step for the adaptive integrators, ``max_intervals`` steps for the terrain engine);
the run's ``U`` holds the torques applied.

A *sampled* law (:class:`SampledLaw`: a ``sample_time_s`` attribute, e.g. the MPC of
:mod:`symtrack.control.closedloop`) has its own clock instead: the loop samples it every
``sample_time_s`` (the sample times summed, t_k+1 = t_k + sample_time_s), holds its torques over
the sample, cut into equal sub-steps of at most ``substep_s`` (the grid's macro step; None: one
step per sample) handed to the plant in calls of at most ``max_intervals`` sub-steps that never
cross a sample; the run ends when the law returns None (``stopped_by = "controller"``) or at
``run.duration_s`` (the law is then called once more with ``final=True``, to see the last state).
"""

from __future__ import annotations

import bisect
import logging
import math
import time
from typing import NamedTuple, Protocol

import numpy as np

from ..foundations.errors import ImplausibleRunError, SimulationError
from ..foundations.interrupt import raise_if_interrupted, watch_interrupts
from ..foundations.progress import Progress
from ..model import plausibility
from .result import RunResult

__all__ = ["IncompleteRun", "OutputGrid", "SampleGrid", "SampledLaw", "StartPoint", "run"]

log = logging.getLogger("symtrack.simulation")


class IncompleteRun(SimulationError):
    """A run that failed part of the way (the vehicle left the field, the integrator failed):
    ``partial`` is the :class:`RunResult` up to the last completed output step
    (``stopped_by = "error"``), so that what was computed can still be written."""

    def __init__(self, message: str, partial: RunResult):
        super().__init__(message)
        self.partial = partial


class OutputGrid:
    """The output intervals of a scenario: (t0, t1, u) with u the torque commands in force."""

    def __init__(self, scenario):
        run = scenario.run
        self.dt, self.duration = run.output_dt_s, run.duration_s
        self.changes = [e.t_s for e in scenario.torque[1:]]
        self.torque = [np.array([e.left_N_m, e.right_N_m], dtype=float) for e in scenario.torque]
        self.starts = [e.t_s for e in scenario.torque]
        self.scenario = scenario
        self.t = 0.0
        self.cur = 0  # the torque entry in force at self.t (Scenario.torque_at)

    def take(self, n: int) -> list[tuple[float, float, np.ndarray]]:
        """The next n intervals (fewer at the end; none when the grid is exhausted)."""
        out = []
        t, dt = self.t, self.dt
        while len(out) < n and t < self.duration - 1e-12:
            t_next = min(float(np.floor(t / dt + 1e-9) + 1) * dt, self.duration)
            # the first change after t (the entries' times increase strictly, Scenario): the one that can
            # end the interval early; a search, not a scan (a recorded programme has thousands of entries)
            k = bisect.bisect_right(self.changes, t + 1e-12)
            if k < len(self.changes) and self.changes[k] < t_next - 1e-12:
                t_next = self.changes[k]
            while self.cur + 1 < len(self.starts) and self.starts[self.cur + 1] <= t + 1e-12:
                self.cur += 1
            out.append((t, t_next, self.torque[self.cur]))
            t = t_next
        self.t = t
        return out


class SampleGrid:
    """The intervals of a sampled law (module doc): samples of ``sample_time_s`` from 0 (the
    sample times summed, ``t_s``) until ``duration_s``, each cut into ``n`` equal sub-steps of
    length h = sample_time_s / n <= ``substep_s``, sub-step i from t_s + i h; the torques of each
    sample are given by :meth:`hold` at its start."""

    def __init__(self, sample_time_s: float, substep_s: float | None, duration_s: float):
        self.dt, self.duration = float(sample_time_s), float(duration_s)
        self.n = 1 if substep_s is None else max(1, int(math.ceil(self.dt / substep_s - 1e-9)))
        self.h = self.dt / self.n
        self.t = 0.0  # the time at the current sample boundary: the next sample's start
        self.t0 = 0.0  # the current sample's start
        self.done = self.n  # sub-steps of the current sample handed out (n: at a sample boundary)
        self.u = None

    @property
    def at_sample(self) -> bool:
        """True at a sample boundary (the law is due)."""
        return self.done == self.n

    @property
    def exhausted(self) -> bool:
        """True at a sample boundary at ``duration_s`` (1e-9 s tolerance)."""
        return self.at_sample and self.t >= self.duration - 1e-9

    def hold(self, u) -> None:
        """Start the next sample (from ``t``) with the torques ``u``."""
        self.t0, self.t = self.t, self.t + self.dt
        self.u, self.done = np.asarray(u, dtype=float), 0

    def take(self, n: int) -> list[tuple[float, float, np.ndarray]]:
        """The next at most n sub-steps of the current sample, as (t0_s, t1_s, u); their length is
        ``h`` (exactly: not t1_s - t0_s)."""
        k = min(n, self.n - self.done)
        out = []
        for i in range(self.done, self.done + k):
            t0 = self.t0 + i * self.h
            out.append((t0, t0 + self.h, self.u))
        self.done += k
        return out


class SampledLaw(Protocol):
    """A torque law with its own sample time (module doc)."""

    sample_time_s: float
    substep_s: float | None

    def __call__(self, t_s: float, x: np.ndarray, final: bool = False) -> np.ndarray | None:
        """The torques (left_N_m, right_N_m) to hold over the sample from ``t_s`` at the plant's
        state ``x``, or None to end the run; with ``final`` the run ends (the return is ignored)."""


class StartPoint(NamedTuple):
    """Where the loop starts the plant (``plant.start(x_m, y_m, yaw_rad, u0, state=state)``)
    instead of the scenario's start pose at rest."""

    x_m: float
    y_m: float
    yaw_rad: float
    u0: np.ndarray
    state: np.ndarray | None = None


def _xy_dist(a, b) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))



def run(scenario, plant, progress: bool | None = False, label: str | None = None, torque_law=None,
        start: StartPoint | None = None, finish: bool = True) -> RunResult:
    """Drive ``plant`` through ``scenario``'s torque programme until its stop rule.

    Parameters
    ----------
    scenario : symtrack.simulation.scenario.Scenario
        (An MPC scenario with a sampled ``torque_law``: its ``run`` and ``name`` are read.)
    plant : symtrack.simulation.plants.Plant
        A plant not yet started; the loop starts it at the scenario's start pose and finishes
        it at the end (the grid lifts the vehicle off), also when the run fails.
    progress : bool or None
        Show a progress bar (or log lines when stderr is no terminal); None: once the run has taken 2 s.
    torque_law : callable or SampledLaw, optional
        ``law(t_s, x) -> (left_N_m, right_N_m)`` in place of the torque programme, sampled at
        each plant call, or a :class:`SampledLaw` on its own clock (module doc).
    start : StartPoint, optional
        The pose, first torques and state to start the plant at (default: the scenario's start
        pose, at rest, with the programme's first torques).
    finish : bool
        Finish the plant at the end (default); False leaves it started (the grid's vehicle stays
        down, e.g. to continue).

    Returns
    -------
    RunResult
        ``stopped_by`` is "distance", "controller" (a sampled law ended the run), or "duration"
        (when a distance stop was set but not reached in ``run.duration_s``, a warning says so).

    Raises
    ------
    IncompleteRun
        When the plant fails part of the way; it carries the partial result.
    """
    run_cfg = scenario.run
    dt = run_cfg.output_dt_s
    dist_from = target = None
    if run_cfg.stop_after_distance_m is not None:
        target = run_cfg.stop_after_distance_m
        dist_from = scenario.event_time(run_cfg.stop_distance_event) if run_cfg.stop_distance_event else 0.0
    names = plant.state_names
    iu, iv = names.index("u_m_s"), names.index("v_m_s")
    ixy = [names.index("x_m"), names.index("y_m")]
    # the sprockets' tread speed r |omega| (a vehicle with sprockets: the tracks' spin is stopped too)
    iw = [names.index(n) for n in ("omega_left_rad_s", "omega_right_rad_s") if n in names]
    r_sprocket = float(scenario.params.get("sprocket_radius_m", 0.0)) if iw else 0.0
    # the track ends' sinkages (the hull in the soil is out of the model's domain)
    sk_from, isk = plausibility.sinkage_columns(names, getattr(plant, "output_names", ()))
    cg_height = float(scenario.params.get("cg_height_m", 0.0)) if isk else 0.0
    # the 3D hull's pitch and roll (a hull turned over is out of the model's domain)
    itilt = [names.index(n) for n in ("pitch_rad", "roll_rad")] if {"pitch_rad", "roll_rad"} <= set(names) else []
    sampled = torque_law is not None and hasattr(torque_law, "sample_time_s")
    if start is None:
        st = scenario.start
        start = StartPoint(st.x_m, st.y_m, math.radians(st.yaw_deg), np.array(scenario.torque_at(0.0)))
    u0 = np.asarray(start.u0, dtype=float)
    if sampled:
        grid = SampleGrid(torque_law.sample_time_s, torque_law.substep_s, run_cfg.duration_s)
    else:
        grid = OutputGrid(scenario)
    bar = Progress(1.0, label or scenario.name, enabled=progress)
    own_stop = getattr(plant, "applies_stop_rule", False)  # the plant applies the distance rule in its calls
    if own_stop:
        plant.set_stop_rule(target, dist_from or 0.0)
    with watch_interrupts():
        if start.state is None:
            x, y = plant.start(start.x_m, start.y_m, start.yaw_rad, u0)
        else:
            x, y = plant.start(start.x_m, start.y_m, start.yaw_rad, u0, state=start.state)
        ts, xs, us, ys = [np.zeros(1)], [x[None, :]], [u0[None, :]], [y[None, :]]
        t, dist, stopped_by = 0.0, 0.0, "duration"
        wall0, cpu0 = time.perf_counter(), time.process_time()
        failure, finished = None, False
        try:
            while True:
                n = plant.max_intervals
                if dist_from is not None and t >= dist_from and plant.short_intervals < n:
                    speed = float(np.hypot(x[iu], x[iv]))
                    if (target - dist) / max(speed, 1e-3) / dt <= 1.2 * n:
                        n = plant.short_intervals
                if sampled and grid.at_sample:
                    if grid.exhausted:
                        torque_law(grid.t, x, final=True)
                        break
                    u_law = torque_law(grid.t, x)
                    if u_law is None:
                        stopped_by = "controller"
                        break
                    grid.hold(np.asarray(u_law, dtype=float).reshape(2))
                # (t0_s, t1_s, length_s, u): a sampled law's sub-steps have the length h exactly
                ivs = [(t0, t1, grid.h if sampled else t1 - t0, u) for t0, t1, u in grid.take(n)]
                if not ivs:
                    break
                if torque_law is not None and not sampled:
                    u_law = np.asarray(torque_law(t, x), dtype=float).reshape(2)
                    ivs = [(t0, t1, h, u_law) for t0, t1, h, _ in ivs]
                try:
                    plant.synchronize([(t0, h, u) for t0, _, h, u in ivs])
                    X = plant.advance()
                    raise_if_interrupted()  # a solver may have swallowed the interrupt and returned
                    hit = None
                    if own_stop:
                        k = len(X)
                        Y = plant.commit(k)
                        times = np.asarray(plant.end_times, dtype=float)
                        dist = plant.distance_m
                        if plant.stopped:
                            stopped_by = "distance"
                    elif dist_from is not None:
                        t1s = np.array([t1 for _, t1, _, _ in ivs])
                        xy = X[:, ixy]
                        xy_prev = np.vstack([np.asarray(x)[ixy][None, :], xy[:-1]])
                        d = np.hypot(xy[:, 0] - xy_prev[:, 0], xy[:, 1] - xy_prev[:, 1])
                        active = t1s > dist_from + 1e-12
                        # the sequential sums dist_k = dist_(k-1) + d_k (np.cumsum adds in order)
                        cum = np.cumsum(np.concatenate(([dist], np.where(active, d, 0.0))))[1:]
                        reached = np.flatnonzero(active & (cum >= target))
                        if reached.size:
                            hit = int(reached[0])
                            dist = float(cum[hit - 1]) if hit > 0 else dist
                        else:
                            dist = float(cum[-1])
                    if own_stop:
                        pass
                    elif hit is None:
                        Y = plant.commit(len(ivs))
                        times = np.array([t1 for _, t1, _, _ in ivs])
                    else:
                        # shorten the last interval so the run ends at the distance (three secant refinements)
                        t0, t1, _, _ = ivs[hit]
                        prev = x if hit == 0 else X[hit - 1]
                        d_step = _xy_dist(X[hit], prev)
                        h = t1 - t0
                        for _ in range(3):
                            if d_step <= 0:
                                break
                            h *= (target - dist) / d_step
                            X[hit] = plant.retry(hit, h)
                            d_step = _xy_dist(X[hit], prev)
                        dist += d_step
                        Y = plant.commit(hit + 1)
                        X = X[:hit + 1]
                        times = np.array([t1 for _, t1, _, _ in ivs[:hit]] + [t0 + h])
                        stopped_by = "distance"
                except SimulationError as err:
                    raise_if_interrupted()
                    failure = err
                    done = int(getattr(err, "intervals_done", 0))  # intervals a batch plant finished before it
                    if done > 0:
                        Y = plant.commit(done)
                        ts.append(np.array([t1 for _, t1, _, _ in ivs[:done]]))
                        xs.append(np.array(plant.Xe[:done]))
                        us.append(np.array([u for _, _, _, u in ivs[:done]]))
                        ys.append(np.array(Y[:done]))
                        t, x = float(ts[-1][-1]), xs[-1][-1]
                    break
                k = len(times)
                ts.append(times)
                xs.append(np.array(X[:k]))
                us.append(np.array([u for _, _, _, u in ivs[:k]]))
                ys.append(np.array(Y[:k]))
                t, x = float(times[-1]), xs[-1][-1]
                speeds = np.hypot(xs[-1][:, iu], xs[-1][:, iv])
                treads = r_sprocket * np.max(np.abs(xs[-1][:, iw]), axis=1) if iw else np.zeros(len(times))
                sinks = (np.max((xs if sk_from == "x" else ys)[-1][:, isk], axis=1) if isk
                         else np.zeros(len(times)))
                tilts = (plausibility.tilt_over_tipping(xs[-1][:, itilt[0]], xs[-1][:, itilt[1]], scenario.params)
                         if itilt else np.zeros(len(times)))
                # the samples over each limit (the sinkage's only with a CG height)
                over = {"speed": speeds > plausibility.MAX_SPEED_M_S,
                        "tread": treads > plausibility.MAX_TREAD_SPEED_M_S,
                        "sinkage": (cg_height > 0) & (sinks > plausibility.SINKAGE_OVER_CG_HEIGHT_MAX * cg_height),
                        "tilt": tilts > 1.0}
                # the limit passed first is the one the run is cut at and the message names, at the sample where it
                # was passed (several may be passed in one chunk: a hull that turns over, then sinks)
                passed = {k: int(np.flatnonzero(v)[0]) for k, v in over.items() if v.any()}
                try:  # faster than any crawler, or the hull in the soil: stopped (symtrack.model.plausibility)
                    if passed:
                        k = min(passed, key=passed.get)
                        i = passed[k]
                        if k == "speed":
                            plausibility.check_speed(float(speeds[i]), float(times[i]))
                        elif k == "tread":
                            plausibility.check_tread_speed(float(treads[i]), float(times[i]))
                        elif k == "sinkage":
                            plausibility.check_sinkage(float(sinks[i]), cg_height, float(times[i]))
                        else:
                            plausibility.check_tilt(float(xs[-1][i, itilt[0]]), float(xs[-1][i, itilt[1]]),
                                                    scenario.params, float(times[i]))
                except ImplausibleRunError as err:
                    err_max = float((plant.stats() or {}).get("fixed_step_error_max", 0.0) or 0.0)
                    if err_max > 1.0:  # the fixed step kept steps above its tolerance: perhaps a numerical divergence
                        # the reference integrator of the plant's terrain (the grid's channel pool: IDAS)
                        ref = "idas" if getattr(plant, "kind", "") == "grid" else "cvodes"
                        err = ImplausibleRunError(
                            f"{err}; the fixed step's error estimate had reached {err_max:.3g} x its tolerance "
                            f"(steps kept above it: summary.json fixed_step_error_max), so the run may have "
                            f"diverged numerically: compare with --integrator {ref} or a smaller run.fixed_step_s",
                            err.quantity)
                    # the run is kept up to the last sample within the limits
                    bad = min(passed.values())
                    ts[-1], xs[-1], us[-1], ys[-1] = ts[-1][:bad], xs[-1][:bad], us[-1][:bad], ys[-1][:bad]
                    if bad > 0:
                        t = float(ts[-1][-1])
                    elif len(ts) > 1:
                        t = float(ts[-2][-1])
                    failure = err
                    break
                frac = t / run_cfg.duration_s
                # a law that knows how far it is (a path follower: the arc length driven) says so
                frac = max(frac, float(getattr(torque_law, "progress_fraction", 0.0) or 0.0))
                if dist_from is not None:
                    frac = max(frac, dist / target)
                bar.update(frac, f"t={t:.2f} s" + (f" d={dist:.2f} m" if dist_from is not None else ""))
                if stopped_by == "distance":
                    break
            finished = failure is None
        finally:
            bar.close(complete=finished)
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            if finish:
                plant.finish()
    res = RunResult(scenario, np.concatenate(ts), np.vstack(xs), np.vstack(us), np.vstack(ys),
                    tuple(plant.state_names), tuple(plant.output_names), wall,
                    "error" if failure is not None else stopped_by, plant.stats(), plant.figures() or None, cpu)
    if failure is not None:
        raise IncompleteRun(f"{failure} (the run is kept up to t = {t:.3f} s)", res) from failure
    if dist_from is not None and stopped_by != "distance":
        log.warning("%s: the run reached run.duration_s = %g s before covering run.stop_after_distance_m = %g m "
                    "(covered %.2f m); it ended by duration", scenario.name, run_cfg.duration_s, target, dist)
    return res
