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
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ..foundations.errors import SimulationError
from ..foundations.interrupt import raise_if_interrupted, watch_interrupts
from ..foundations.progress import Progress
from .result import RunResult

__all__ = ["IncompleteRun", "OutputGrid", "run"]

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
            for tc in self.changes:
                if t + 1e-12 < tc < t_next - 1e-12:
                    t_next = tc
            while self.cur + 1 < len(self.starts) and self.starts[self.cur + 1] <= t + 1e-12:
                self.cur += 1
            out.append((t, t_next, self.torque[self.cur]))
            t = t_next
        self.t = t
        return out


def _xy_dist(a, b) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))



def run(scenario, plant, progress: bool = False, label: str | None = None, torque_law=None) -> RunResult:
    """Drive ``plant`` through ``scenario``'s torque programme until its stop rule.

    Parameters
    ----------
    scenario : symtrack.simulation.scenario.Scenario
    plant : symtrack.simulation.plants.Plant
        A plant not yet started; the loop starts it at the scenario's start pose and finishes
        it at the end (the grid lifts the vehicle off), also when the run fails.
    progress : bool
        Show a progress bar (or log lines when stderr is no terminal).
    torque_law : callable, optional
        ``law(t_s, x) -> (left_N_m, right_N_m)`` in place of the torque programme (module doc).

    Returns
    -------
    RunResult
        ``stopped_by`` is "distance", or "duration" (when a distance stop was set but not
        reached in ``run.duration_s``, a warning says so).

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
    st = scenario.start
    u0 = np.array(scenario.torque_at(0.0))
    grid = OutputGrid(scenario)
    bar = Progress(1.0, label or scenario.name, enabled=progress)
    own_stop = getattr(plant, "applies_stop_rule", False)  # the plant applies the distance rule in its calls
    if own_stop:
        plant.set_stop_rule(target, dist_from or 0.0)
    with watch_interrupts():
        x, y = plant.start(st.x_m, st.y_m, math.radians(st.yaw_deg), u0)
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
                ivs = grid.take(n)
                if not ivs:
                    break
                if torque_law is not None:
                    u_law = np.asarray(torque_law(t, x), dtype=float).reshape(2)
                    ivs = [(t0, t1, u_law) for t0, t1, _ in ivs]
                try:
                    plant.synchronize([(t0, t1 - t0, u) for t0, t1, u in ivs])
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
                        t1s = np.array([t1 for _, t1, _ in ivs])
                        prev = np.vstack([x[None, :2], X[:-1, :2]])
                        d = np.hypot(X[:, 0] - prev[:, 0], X[:, 1] - prev[:, 1])
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
                        times = np.array([t1 for _, t1, _ in ivs])
                    else:
                        # shorten the last interval so the run ends at the distance (three secant refinements)
                        t0, t1, _ = ivs[hit]
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
                        times = np.array([t1 for _, t1, _ in ivs[:hit]] + [t0 + h])
                        stopped_by = "distance"
                except SimulationError as err:
                    raise_if_interrupted()
                    failure = err
                    break
                k = len(times)
                ts.append(times)
                xs.append(np.array(X[:k]))
                us.append(np.array([u for _, _, u in ivs[:k]]))
                ys.append(np.array(Y[:k]))
                t, x = float(times[-1]), xs[-1][-1]
                frac = t / run_cfg.duration_s
                if dist_from is not None:
                    frac = max(frac, dist / target)
                bar.update(frac, f"t={t:.2f} s" + (f" d={dist:.2f} m" if dist_from is not None else ""))
                if stopped_by == "distance":
                    break
            finished = failure is None
        finally:
            bar.close(complete=finished)
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            plant.finish()
    res = RunResult(scenario, np.concatenate(ts), np.vstack(xs), np.vstack(us), np.vstack(ys),
                    tuple(plant.state_names), tuple(plant.output_names), wall,
                    "error" if failure is not None else stopped_by, plant.stats(), plant.figures() or None, cpu)
    if failure is not None:
        raise IncompleteRun(f"{failure} (at t = {t:.3f} s; the run up to there is kept)", res) from failure
    if dist_from is not None and stopped_by != "distance":
        log.warning("%s: the run reached run.duration_s = %g s before covering run.stop_after_distance_m = %g m "
                    "(covered %.2f m); it ended by duration", scenario.name, run_cfg.duration_s, target, dist)
    return res
