"""Plants: what the time loop (and the closed loop of :mod:`symtrack.control`) drives.

A plant is the vehicle on a terrain with an integrator. Every plant has the same protocol
(:class:`Plant`), with two phases per step as Chrono::Vehicle's subsystems have
(Synchronize, then Advance):

1. :meth:`Plant.synchronize` hands the plant the coming output intervals (start time, length
   and the sprocket torque commands of each). The grid terrain's world manager does its per-step work here:
   footprint, release, channel assignment, INFO_IN.
2. :meth:`Plant.advance` integrates over them tentatively and returns the states at their
   ends; :meth:`Plant.retry` integrates one of them again with another length (the stop rule's
   secant refinement); :meth:`Plant.commit` accepts the first k intervals and returns their
   outputs (the grid: INFO_OUT, the coverage check).

A plant reports ``state_names`` (the states it exposes: the homogeneous model's full state, or
the 12 vehicle states of the grid, whose channel slots stay inside) and ``output_names``.
``max_intervals`` is how many output intervals one :meth:`advance` may cover: 1 for the
adaptive integrators and the grid, many for the compiled fixed-step batch (256 steps per call
of the generated C).

- :class:`StepPlant`: the homogeneous terrain with a per-step integrator (CVODES, IDAS);
- :class:`BatchPlant`: the homogeneous terrain with a batch stepper (compiled Rosenbrock);
- :class:`GridPlant`: the persistent grid terrain (a :class:`~symtrack.terrain.world.World`)
  with its integrator (IDAS, compiled Rosenbrock);
- :class:`EnginePlant`: the persistent grid terrain through the compiled terrain engine
  (``grid_fast``; many macro steps per call, the stop rule inside, start from a state, retry
  from checkpoints);
- :func:`make_plant`: the plant a scenario of any kind asks for (the integrator from the registry, the
  kind's choices from its scenario's ``plant_setup``).
"""

from __future__ import annotations

import logging
import math
from typing import Protocol

import numpy as np

from ..foundations.errors import SimulationError
from ..foundations.progress import timed_step
from ..integrators import registry
from ..integrators.engine import ChannelManager
from ..integrators.settings import IntegratorSettings, substeps
from ..model import SystemModel
from ..model.static import static_state
from ..terrain.settings import TerrainSettings
from ..terrain.world import World, open_world
from ..vehicles import registry as vehicle_registry
from ..vehicles.vehicle3d import RasterGuard

__all__ = ["BatchPlant", "EnginePlant", "GridPlant", "Plant", "StepPlant", "advance_plant", "make_grid_plant",
           "make_plant"]

log = logging.getLogger("symtrack.simulation")


class Plant(Protocol):
    """The protocol of every plant (module doc). ``intervals`` are (t0_s, length_s, u) triples,
    consecutive from the committed state."""

    kind: str
    model: SystemModel
    state_names: tuple
    output_names: tuple
    max_intervals: int
    short_intervals: int

    def start(self, x_m: float, y_m: float, yaw_rad: float, u0, state=None) -> tuple[np.ndarray, np.ndarray]:
        """Set the vehicle down at rest at the pose (cells settled); with ``state`` (values of
        ``state_names``), continue from that state instead. Returns (state, outputs at u0)."""

    def synchronize(self, intervals) -> None:
        """Phase 1: the coming intervals, consecutive from the committed state."""

    def advance(self) -> np.ndarray:
        """Phase 2: the states at the ends of the synchronized intervals (tentative), (n, nx)."""

    def retry(self, k: int, length_s: float) -> np.ndarray:
        """Interval k again, from the end of interval k - 1, with another length; returns its end state."""

    def commit(self, k: int) -> np.ndarray:
        """Accept the first k intervals (the last as advanced or retried); their outputs, (k, ny)."""

    def finish(self) -> None:
        """The end of a run (the grid lifts the vehicle off)."""

    def figures(self) -> dict:
        """Figures of the terrain for the summary ({} for the homogeneous terrain)."""

    def stats(self) -> dict:
        """Integrator counters."""


class StepPlant:
    """The homogeneous terrain with a per-step integrator (one interval per advance)."""

    kind = "homogeneous"
    max_intervals = short_intervals = 1

    def __init__(self, model: SystemModel, params: dict, stepper):
        self.model, self.params, self.stepper = model, dict(params), stepper
        self.p = model.param_vector(params)
        self.guard = RasterGuard.of(model, params)  # the 3D vehicle on an elevation raster: stay on it
        self.state_names = tuple(model.state_names)
        self.output_names = tuple(model.output_names)
        self.x = None

    def _outputs(self, x, u):
        return np.array(self.model.outputs(x, u, self.p)).ravel()

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        if state is None:
            x = static_state(self.model, self.params, x_m, y_m, yaw_rad)
        else:
            x = np.array(state, dtype=float)
            if x.shape != (self.model.nx,):
                raise SimulationError(f"{type(self).__name__}.start: expected {self.model.nx} states, got {x.shape}")
        self.stepper.reset()
        self.x = x
        return x, self._outputs(x, np.asarray(u0, dtype=float))

    def synchronize(self, intervals):
        if len(intervals) != 1:
            raise SimulationError(f"{type(self).__name__} advances one interval at a time, got {len(intervals)}")
        if self.x is None:
            raise SimulationError(f"{type(self).__name__}: start the plant before stepping it")
        (_, self.h, u), = intervals
        self.u = np.asarray(u, dtype=float)

    def advance(self):
        self.x_new = self.stepper.step(self.x, self.u, self.p, self.h)
        if self.guard is not None:
            self.guard(self.x_new[None, :])
        return self.x_new[None, :]

    def retry(self, k, length_s):
        self.x_new = self.stepper.step(self.x, self.u, self.p, length_s)
        return self.x_new

    def commit(self, k):
        self.x = self.x_new
        return self._outputs(self.x, self.u)[None, :]

    def finish(self):
        pass

    def figures(self):
        return {}

    def stats(self):
        return self.stepper.stats()


class BatchPlant:
    """The homogeneous terrain with a batch stepper (:class:`~symtrack.integrators.fixed_step.FixedStepper`):
    many output intervals per advance, their equal steps of at most ``fixed_step_s`` packed into
    calls of the generated C (256 steps per call, 16 for a short batch), each step error-controlled
    (:mod:`symtrack.integrators.fixed_step`)."""

    kind = "homogeneous"

    def __init__(self, model: SystemModel, params: dict, stepper, output_dt_s: float):
        self.model, self.params, self.stepper = model, dict(params), stepper
        self.p = np.array(model.param_vector(params), dtype=float)
        self.guard = RasterGuard.of(model, params)  # the 3D vehicle on an elevation raster: stay on it
        self.state_names = tuple(model.state_names)
        self.output_names = tuple(model.output_names)
        self.big, self.short = max(stepper.sizes), min(stepper.sizes)
        per = substeps(output_dt_s, stepper.settings.fixed_step_s)
        self.max_intervals = max(1, self.big // per)
        self.short_intervals = max(1, self.short // per)
        self.outputs_f = stepper.lib.f("outputs")
        self.x = self.z = None

    def _outputs(self, x, u):
        return np.array(self.outputs_f(x, u, self.p)).ravel()

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        u0 = np.asarray(u0, dtype=float)
        x = static_state(self.model, self.params, x_m, y_m, yaw_rad) if state is None else np.array(state, float)
        self.x, self.z = x, self.stepper.consistent_z(x, u0, self.p)
        return x, self._outputs(x, u0)

    def synchronize(self, intervals):
        if self.x is None:
            raise SimulationError("BatchPlant: start the plant before stepping it")
        self.t0 = float(intervals[0][0])
        self.lengths = np.array([h for _, h, _ in intervals], dtype=float)
        self.inputs = np.array([u for _, _, u in intervals], dtype=float)

    def advance(self):
        fs = self.stepper.settings.fixed_step_s
        n = np.maximum(1, np.ceil(self.lengths / fs - 1e-9)).astype(int)  # substeps() of each interval
        H_all = np.repeat(self.lengths / n, n)
        U_all = np.repeat(self.inputs, n, axis=0)
        ends = np.cumsum(n) - 1  # the column that ends each interval
        total = int(ends[-1]) + 1
        n_cols = self.short if total <= self.short else self.big
        m = len(ends)
        self.Xe = np.empty((m, self.model.nx))
        self.Ze = np.empty((m, self.model.z.numel()))
        self.Ye = np.empty((m, len(self.output_names)))
        x, z = self.x, self.z
        t0 = np.concatenate([[self.t0], self.t0 + np.cumsum(H_all)])
        for c0 in range(0, total, n_cols):
            c1 = min(c0 + n_cols, total)
            try:
                X, Z, Y = self.stepper.run_chunk(n_cols, x, z, U_all[c0:c1], H_all[c0:c1], self.p, t0[c0])
            except SimulationError as err:
                # the intervals that ended before the chunk's first non-finite step are kept: the error
                # says how many (intervals_done), the loop commits them (nothing computed is lost)
                c = self.stepper.chunk[n_cols]
                i0, done = np.searchsorted(ends, c0), np.searchsorted(ends, c0 + int(getattr(err, "steps_done", 0)))
                rows = ends[i0:done] - c0
                self.Xe[i0:done], self.Ze[i0:done], self.Ye[i0:done] = c.X[rows], c.Z[rows], c.Y[rows]
                err.intervals_done = int(done)
                raise
            k = c1 - c0
            x, z = X[k - 1].copy(), Z[k - 1].copy()
            i0, i1 = np.searchsorted(ends, c0), np.searchsorted(ends, c1)
            rows = ends[i0:i1] - c0
            self.Xe[i0:i1], self.Ze[i0:i1], self.Ye[i0:i1] = X[rows], Z[rows], Y[rows]
        if self.guard is not None:
            self.guard(self.Xe)
        return self.Xe

    def retry(self, k, length_s):
        x0, z0 = (self.x, self.z) if k == 0 else (self.Xe[k - 1], self.Ze[k - 1])
        u = self.inputs[k]
        x_new, z_new = self.stepper.advance(x0, z0, u, self.p, length_s)
        self.Xe[k], self.Ze[k] = x_new, z_new
        self.Ye[k] = self._outputs(x_new, u)
        return x_new

    def commit(self, k):
        self.x, self.z = self.Xe[k - 1].copy(), self.Ze[k - 1].copy()
        return self.Ye[:k]

    def finish(self):
        pass

    def figures(self):
        return {}

    def stats(self):
        return self.stepper.stats()


class GridPlant:
    """The vehicle on the persistent grid terrain: a :class:`~symtrack.terrain.world.World` and
    its integrator, one macro step per interval; the world manager's rules are grid_engine.c's, run on
    the World's channel tables by a :class:`~symtrack.integrators.engine.ChannelManager`
    (``before_step`` in :meth:`synchronize`, ``after_step`` and ``check_covered`` in :meth:`commit`).
    ``state_names`` are the 12 vehicle states: the channel slots stay inside (the cells live in the
    world's storage). :meth:`start` sets the vehicle down (the cells under it settle,
    ``ChannelManager.begin_pass``); :meth:`finish` lifts it off (``ChannelManager.end_pass``), so the
    terrain holds the rebound."""

    kind = "grid"
    max_intervals = short_intervals = 1

    def __init__(self, world: World, stepper, record_every_s: float | None = None):
        """``record_every_s``: keep a snapshot of the loaded cells' sinkage and the pose this
        often (``snapshots``: (t_s, pose, cells, z_m) per snapshot, reset at every start), for an
        animation of the pass; None records nothing."""
        self.world, self.stepper = world, stepper
        self.manager = ChannelManager(world)
        self.record_every_s = record_every_s
        self.snapshots: list = []
        self._t = self._t_snap = 0.0
        self.model = world.model
        self._vs = world.layout.block("vehicle")
        self.state_names = world.layout.vehicle_names
        self.output_names = tuple(world.model.output_names)
        self._x = None  # the full state (vehicle + channel slots)
        self.finished = True

    @property
    def full_state(self) -> np.ndarray:
        return self._x

    def _outputs(self, x, u, p):
        return np.array(self.model.outputs(x, u, p)).ravel()

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        x = self.manager.begin_pass(self.stepper, float(x_m), float(y_m), float(yaw_rad))
        if state is not None:
            xv = np.asarray(state, dtype=float)
            if xv.shape != (len(self.state_names),):
                raise SimulationError(f"GridPlant.start: expected the {len(self.state_names)} vehicle states, got "
                                      f"shape {xv.shape}")
            x[self._vs] = xv
            self.stepper.reset()
        self._x = x
        self.finished = False
        self._t = 0.0
        self.snapshots = []
        self._t_snap = -np.inf
        self._record(x)
        return x[self._vs].copy(), self._outputs(x, np.asarray(u0, dtype=float), self.world.param_vector())

    def _record(self, x):
        if self.record_every_s is None or self._t < self._t_snap + self.record_every_s - 1e-9:
            return
        self._t_snap = self._t
        cells = self.world.active_cells()
        self.snapshots.append((self._t, x[self.model.layout.pose_index], cells.copy(),
                               self.world.storage.z[cells].copy()))

    def synchronize(self, intervals):
        if self._x is None or self.finished:
            raise SimulationError("GridPlant: start the plant (set the vehicle down) before stepping it")
        if len(intervals) != 1:
            raise SimulationError(f"GridPlant advances one interval at a time, got {len(intervals)}")
        (_, self.h, u), = intervals
        self.u = np.asarray(u, dtype=float)
        self.x_pre, self.p = self.manager.before_step(self._x, self.h, self.stepper)

    def advance(self):
        self.x_new = self.stepper.step(self.x_pre, self.u, self.p, self.h)
        self.h_done = self.h
        return self.x_new[None, self._vs]

    def retry(self, k, length_s):
        self.x_new = self.stepper.step(self.x_pre, self.u, self.p, length_s)
        self.h_done = length_s
        return self.x_new[self._vs]

    def commit(self, k):
        x = self._x = self.x_new
        self.manager.after_step(x)
        self.manager.check_covered(x)
        self._t += self.h_done
        self._record(x)
        return self._outputs(x, self.u, self.p)[None, :]

    def finish(self):
        if self._x is None or self.finished:
            return
        self.manager.end_pass(self._x)
        self.finished = True

    def figures(self):
        return self.world.figures()

    def stats(self):
        return self.stepper.stats()


class EnginePlant:
    """The vehicle on the grid terrain through the compiled terrain engine
    (:class:`~symtrack.integrators.engine.TerrainEngine`, ``run.integrator = "grid_fast"``):
    the world manager's per-step work, the vehicle and the cells in C, up to ``max_intervals``
    macro steps per call. It applies the stop-at-distance rule inside its calls
    (``applies_stop_rule``: :meth:`set_stop_rule`; after :meth:`advance`, ``end_times`` holds the
    steps' end times, the last one shortened when ``stopped``), so the time loop needs no
    :meth:`retry`.
    ``record_every_s``: snapshots for the animation, one per call (calls of 25 macro steps then).

    :meth:`start` with ``state`` (the 12 vehicle states, e.g. the trim of the closed loop) sets
    the vehicle down at rest first (:meth:`TerrainEngine.begin_pass`: the cells under it at their
    static sinkage, then settled), then gives it that state: the accelerations of the DAE form
    and the tracks' pressure lines made consistent with it (a vehicle step of length 0), the
    active cells' geometry re-evaluated for those pressure lines, the channel sums recomputed.

    Retry: the engine advances its state in place (the World's storage arrays and its channel
    tables). With ``checkpoints = True`` :meth:`synchronize` saves that state (the storage arrays
    of the whole field, the channel tables, the vehicle; :meth:`checkpoint`), so :meth:`retry` and
    a :meth:`commit` of fewer intervals than were advanced restore it and re-run the intervals
    (bit for bit the same, the engine being deterministic). Off by default: the saved field costs
    about 40 bytes per cell per synchronize, and neither the time loop nor the closed loop needs
    it (they commit every interval they advance)."""

    kind = "grid"
    applies_stop_rule = True
    CALL_STEPS = 100  # macro steps per call
    RECORD_CALL_STEPS = 25  # ... when recording snapshots

    def __init__(self, world: World, engine, record_every_s: float | None = None, checkpoints: bool = False):
        self.world, self.engine = world, engine
        self._layout = world.layout  # the engine's wv: the vehicle's states, then its accelerations
        self.state_names = self._layout.vehicle_names
        self.output_names = tuple(engine.output_names)
        self.record_every_s = record_every_s
        self.checkpoints = checkpoints
        self.snapshots: list = []
        self.dist = np.array([0.0, -1.0, 0.0])  # distance so far, stop distance (< 0: none), counted from
        self._saved = None
        self.finished = True

    @property
    def max_intervals(self) -> int:
        return self.CALL_STEPS if self.record_every_s is None else self.RECORD_CALL_STEPS

    short_intervals = max_intervals

    @property
    def distance_m(self) -> float:
        return float(self.dist[0])

    def set_stop_rule(self, target_m: float | None, from_s: float = 0.0) -> None:
        self.dist[:] = [0.0, -1.0 if target_m is None else target_m, from_s]

    def _record(self, t):
        if self.record_every_s is not None:
            cells = self.world.storage  # the engine writes the active cells' state into the storage
            act = self.engine.active_cells()
            self.snapshots.append((t, self.engine.vehicle_state()[self._layout.pose_index], act, cells.z[act].copy()))

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        u0 = np.asarray(u0, dtype=float)
        x = self.engine.begin_pass(float(x_m), float(y_m), float(yaw_rad))
        self.engine.reset_stats()  # the statistics of the time loop (the settling excluded)
        if state is not None:
            x = self.engine.set_vehicle_state(state, u0)
        self.dist[0] = 0.0
        self.finished = False
        self.snapshots = []
        self._saved = None
        self._record(0.0)
        return x, self.engine.outputs_now(u0)

    # -- checkpoints (retry) ----------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        """The engine's whole state (:meth:`TerrainEngine.checkpoint`: its arrays and scalars, the World's
        storage arrays) and the stop rule's distance."""
        return {"engine": self.engine.checkpoint(), "dist": self.dist.copy()}

    def restore(self, saved: dict) -> None:
        """Back to a :meth:`checkpoint` (in place: the C kernel and the World share these arrays)."""
        self.engine.restore(saved["engine"])
        self.dist[:] = saved["dist"]

    def _rerun(self, k: int, last_length_s: float | None = None) -> None:
        """From the checkpoint, intervals 0 .. k-1 as synchronized (the last one with ``last_length_s``)."""
        if self._saved is None:
            raise SimulationError("EnginePlant: retry / a partial commit needs checkpoints (EnginePlant(..., "
                                  "checkpoints=True)): the engine advances the terrain in place")
        self.restore(self._saved)
        T = self.T[:k].copy()
        if last_length_s is not None:
            T[k - 1] = (self.T[k - 2] if k >= 2 else self.t0) + float(last_length_s)
        self.stopped, self.end_times, X, Y = self.engine.advance(self.t0, T, self.U[:k], self.dist)
        if len(self.end_times) != k:
            raise SimulationError("EnginePlant: the stop rule ended the re-run early; retry is for runs without it")
        self.X, self.Y = X, Y
        self._done = k

    def synchronize(self, intervals):
        if self.finished:
            raise SimulationError("EnginePlant: start the plant (set the vehicle down) before stepping it")
        self.t0 = intervals[0][0]
        self.T = np.array([t0 + h for t0, h, _ in intervals], dtype=float)
        self.U = np.array([u for _, _, u in intervals], dtype=float)
        self._saved = self.checkpoint() if self.checkpoints else None

    def advance(self):
        self.stopped, self.end_times, X, self.Y = self.engine.advance(self.t0, self.T, self.U, self.dist)
        self.X = X
        self._done = len(self.end_times)
        self._record(float(self.end_times[-1]) if len(self.end_times) else self.t0)
        return X

    def retry(self, k, length_s):
        """Interval k again with another length, from the end of interval k - 1 (needs ``checkpoints``)."""
        self._rerun(k + 1, length_s)
        return self.X[k].copy()

    def commit(self, k):
        if k != self._done:
            self._rerun(k)
        return self.Y[:k]

    def finish(self):
        if self.finished:
            return
        self.engine.end_pass()  # the lift-off in the engine (World.end_pass's rules)
        self.finished = True

    def figures(self):
        return self.world.figures()

    def stats(self):
        return {"engine_compiled": self.engine.compiled, **self.engine.stats}


def advance_plant(plant, u, length_s: float, substep_s: float | None = None,
                  t0_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Advance a started plant from time ``t0_s`` by ``length_s`` with input ``u`` (in equal
    sub-steps of at most ``substep_s``, the grid's macro step); returns its state and outputs at
    the end."""
    n = 1 if substep_s is None else max(1, int(math.ceil(length_s / substep_s - 1e-9)))
    h = length_s / n
    u = np.asarray(u, dtype=float)
    done = 0
    x = y = None
    while done < n:
        k = min(plant.max_intervals, n - done)
        plant.synchronize([(t0_s + (done + i) * h, h, u) for i in range(k)])
        X = plant.advance()
        Y = plant.commit(k)
        x, y = X[k - 1], Y[k - 1]
        done += k
    return x, y


def make_grid_plant(world: World, settings: IntegratorSettings, spec: registry.IntegratorSpec | None = None):
    """The grid plant of a world with the integrator of ``settings`` (``spec``: its registry entry,
    looked up when None): an :class:`EnginePlant` for an engine, else a :class:`GridPlant` with its
    stepper."""
    spec = spec or registry.get(settings.method)
    if spec.grid_engine is not None:
        spec.check("grid", settings)
        return EnginePlant(world, spec.grid_engine(world, settings))
    return GridPlant(world, spec.stepper("grid", world.model, settings, world.n_channels))


def make_plant(scenario, model: SystemModel | None = None, terrain=None, *, world: World | None = None,
               spec: registry.IntegratorSpec | None = None):
    """The plant a scenario asks for, of every kind of run (a simulation, an MPC run, a field study's
    passes): the grid terrain when it has a ``[terrain]`` section (or a ``world`` / ``terrain`` is
    given: a :class:`~symtrack.terrain.storage.Terrain` or a terrain file to continue from), else the
    homogeneous terrain (on ``model`` when given). What the run's kind chooses (the integrator, the
    grid's section and macro step, a batch stepper or not) is its scenario's
    ``plant_setup(grid, terrain)`` (:class:`~symtrack.simulation.scenario.PlantSetup`); ``spec``: the
    integrator's registry entry, as :class:`~symtrack.simulation.builder.Built` holds it (looked up
    when None). A grid plant on a world opened here has the world's ``macro_step_s``."""
    grid = world is not None or scenario.terrain is not None or terrain is not None
    setup = scenario.plant_setup(grid, terrain)
    settings = setup.integrator
    spec = spec or registry.get(settings.method)
    surface = getattr(scenario, "surface", None)
    vehicle = model.vehicle if model is not None else vehicle_registry.for_options(scenario.model, surface=surface)
    if grid:
        vehicle_registry.check_plant(vehicle, "engine" if spec.grid_engine is not None else "grid", settings.method)
        with timed_step("building the grid terrain's model and its integrator", log):
            if world is not None:
                return make_grid_plant(world, settings, spec)
            spec.check("grid", settings)
            st = scenario.start
            world = open_world(setup.terrain or TerrainSettings(), scenario.params, scenario.model,
                               setup.macro_step_s, start_xy=(st.x_m, st.y_m), terrain=terrain)
            plant = make_grid_plant(world, settings, spec)
        plant.macro_step_s = setup.macro_step_s
        return plant
    vehicle_registry.check_plant(vehicle, "homogeneous", settings.method)
    with timed_step("building the model and its integrator", log):
        model = model or SystemModel(scenario.model, vehicle=vehicle)
        stepper = spec.stepper("homogeneous", model, settings)
    if setup.batch and "homogeneous" in spec.batch:
        return BatchPlant(model, scenario.params, stepper, scenario.run.output_dt_s)
    return StepPlant(model, scenario.params, stepper)
