"""Plants for the closed loop: the homogeneous-terrain simulator and the persistent grid terrain.

A plant has ``state_names`` (containing the 12 vehicle states by name) and
``step(x, u, dt) -> x``. The closed loop measures the plant's state; the MPC predicts with the
homogeneous-terrain model whatever the plant is, so the mismatch is honest.

:class:`GridPlant` is the vehicle on the persistent grid terrain (``symtrack/terrain``): a
:class:`~symtrack.terrain.world.World` and its IDAS stepper driven exactly as
:func:`symtrack.runner.run` drives them, per plant sub-step: ``world.before_step`` (footprint,
release, channel assignment, INFO_IN), ``stepper.step``, ``world.after_step`` (INFO_OUT: the cells
written back) and ``world.check_covered``. Its ``state_names`` are the 12 vehicle states only:
the channel states stay inside the plant (they are channel slots, not cells; the cells live in
the world's storage). :meth:`GridPlant.start` sets the vehicle down at its start pose (the cells
under it settle at rest, :meth:`World.begin_pass`) and then gives it the running state the loop
starts from; :meth:`GridPlant.finish` lifts it off (:meth:`World.end_pass`) so the final terrain
holds the elastic rebound, as a terrain run's does.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ..errors import ScenarioError, SimulationError
from ..model import SystemModel
from ..model.vehicle import VEHICLE_STATES
from ..simulate import IntegratorSettings, Stepper

log = logging.getLogger("symtrack.control.plants")

NV = len(VEHICLE_STATES)
# IDAS tolerances of the grid plant: those of `symtrack simulate validation_grid` (docs/terrain.md:
# every validation figure equal to 3 digits against 1e-7 / 1e-9, in half the time)
GRID_RELTOL = 1e-5
GRID_ABSTOL = 1e-8
# plant sub-step: the world manager's macro step (footprint prediction, release); the MPC's sample
# is split into sub-steps no longer than this
GRID_SUBSTEP_S = 0.02
GRID_INTEGRATORS = ("idas", "rosenbrock")
# margin around the reference path when the field is sized from it
FIELD_MARGIN_M = 4.0


class _Timed:
    """Wall time spent in ``step`` (the plant's share of the loop's wall time)."""

    wall_time_s = 0.0
    steps = 0

    def _timed(self, fn, *args):
        t0 = time.perf_counter()
        try:
            return fn(*args)
        finally:
            self.wall_time_s += time.perf_counter() - t0
            self.steps += 1


class HomogeneousPlant(_Timed):
    """The full simulator on homogeneous soil: Stepper (CVODES or IDAS) on a SystemModel."""

    kind = "homogeneous"

    def __init__(self, model: SystemModel, params: dict, integrator: str = "cvodes"):
        self.model = model
        self.p = model.param_vector(params)
        self.stepper = Stepper(model, IntegratorSettings(integrator))
        self.state_names = tuple(model.state_names)

    def step(self, x, u, dt):
        return self._timed(self.stepper.step, x, u, self.p, dt)


class GridPlant(_Timed):
    """The vehicle on the persistent grid terrain (see the module doc).

    ``world``: a :class:`symtrack.terrain.world.World`; its M must have been derived for a macro
    step of at most ``substep_s``. ``integrator``: "idas" (default; tolerances ``reltol``,
    ``abstol``) or "rosenbrock" (the compiled fixed-step integrator of
    symtrack/terrain/compiled_grid.py at its largest measured step).
    """

    kind = "grid"

    def __init__(self, world, substep_s: float = GRID_SUBSTEP_S, reltol: float = GRID_RELTOL,
                 abstol: float = GRID_ABSTOL, integrator: str = "idas"):
        if not 0.0 < substep_s <= 1.0:
            raise ScenarioError(f"grid plant substep_s = {substep_s!r} must be in (0, 1] s")
        if integrator not in GRID_INTEGRATORS:
            raise ScenarioError(f"grid plant integrator = {integrator!r} is not one of {', '.join(GRID_INTEGRATORS)}")
        self.world = world
        self.substep_s = float(substep_s)
        self.integrator = integrator
        if integrator == "rosenbrock":
            from ..terrain.compiled_grid import MAX_STEP_S

            settings = IntegratorSettings("rosenbrock", fixed_step_s=MAX_STEP_S)
        else:
            settings = IntegratorSettings("idas", reltol, abstol)
        self.stepper = world.stepper(settings)
        self.state_names = tuple(VEHICLE_STATES)
        self._x = None  # the full state (vehicle + channel slots) after the last step
        self.finished = False

    def start(self, x_vehicle) -> np.ndarray:
        """Set the vehicle down at the pose of ``x_vehicle`` (the cells under it settle at rest for
        the world's ``settle_s``), then give it the rest of ``x_vehicle`` (speeds, shears,
        torques: e.g. the trim of steady running) as the state the loop starts from. Returns the
        vehicle state."""
        xv = np.asarray(x_vehicle, dtype=float)
        if xv.shape != (NV,):
            raise SimulationError(f"GridPlant.start: expected the {NV} vehicle states, got shape {xv.shape}")
        x = self.world.begin_pass(self.stepper, float(xv[0]), float(xv[1]), float(xv[2]))
        x[:NV] = xv
        self.stepper.reset()
        self._x = x
        self.finished = False
        return x[:NV].copy()

    def _step(self, xv, u, dt):
        if self._x is None:
            raise SimulationError("GridPlant.step before GridPlant.start: set the vehicle down first")
        if self.finished:
            raise SimulationError("GridPlant.step after GridPlant.finish: the vehicle was lifted off")
        x = self._x.copy()
        x[:NV] = xv
        u = np.asarray(u, dtype=float)
        n = max(1, int(math.ceil(dt / self.substep_s - 1e-9)))
        h = dt / n
        w = self.world
        for _ in range(n):
            x, p = w.before_step(x, h, self.stepper)
            x = self.stepper.step(x, u, p, h)
            w.after_step(x)
            w.check_covered(x)
        self._x = x
        return x[:NV].copy()

    def step(self, x, u, dt):
        return self._timed(self._step, np.asarray(x, dtype=float), u, dt)

    def finish(self, x=None) -> None:
        """Lift the vehicle off (the loaded cells unload and go back to storage)."""
        if self._x is None or self.finished:
            return
        full = self._x.copy()
        if x is not None:
            full[:NV] = np.asarray(x, dtype=float)
        self.world.end_pass(full)
        self.finished = True

    def figures(self) -> dict:
        return self.world.figures()


def field_from_path(path, margin_m: float = FIELD_MARGIN_M) -> tuple[tuple[float, float], tuple[float, float]]:
    """(origin_m, size_m) of a field covering the reference path (without its straight extension
    past the end) with a margin on every side."""
    on = path.segment >= 0
    x, y = path.x[on], path.y[on]
    x0, x1 = float(x.min()) - margin_m, float(x.max()) + margin_m
    y0, y1 = float(y.min()) - margin_m, float(y.max()) + margin_m
    return (x0, y0), (x1 - x0, y1 - y0)


def make_grid_plant(sc, terrain_in: str | None = None, substep_s: float = GRID_SUBSTEP_S) -> GridPlant:
    """The grid plant of an MPC scenario with a ``[terrain]`` section. Without ``size_m`` and
    ``origin_m`` (and no terrain file) the field covers the reference path plus
    :data:`FIELD_MARGIN_M` on every side. The plant integrates with IDAS, or with the compiled
    Rosenbrock integrator when ``run.integrator = "rosenbrock"`` (``cvodes``, the homogeneous
    plant's default, means IDAS here: the grid needs the DAE form)."""
    import dataclasses

    from ..model.options import ModelOptions
    from ..terrain import persist
    from ..terrain.config import settings_from_dict
    from ..terrain.world import World

    t = sc.terrain
    if t is None:
        raise ScenarioError("the MPC scenario has no [terrain] section: the grid plant needs one")
    s = settings_from_dict(t)
    if s.passes != 1:
        raise ScenarioError(f"terrain.passes = {s.passes}: an MPC run drives its path once (use --terrain-in "
                            "to continue from a saved terrain)")
    path_in = terrain_in or s.initial_state
    storage = None
    if path_in:
        storage = persist.load(path_in, sc.params)
        g = storage.grid
        if "cell_m" in t and abs(g.cell_m - s.cell_m) > 1e-12:
            raise ScenarioError(f"{path_in}: the terrain file has cells of {g.cell_m} m, the scenario's [terrain] "
                                f"asks for terrain.cell_m = {s.cell_m}; make them agree")
        # the file's geometry (M is derived from the cell size)
        s = dataclasses.replace(s, cell_m=g.cell_m, size_m=(g.shape[0] * g.cell_m, g.shape[1] * g.cell_m))
    elif "size_m" not in t and "origin_m" not in t:
        origin, size = field_from_path(sc.build_path())
        s = dataclasses.replace(s, origin_m=origin, size_m=size)
    world = World(s, sc.params, ModelOptions(), substep_s, start_xy=(sc.start.x_m, sc.start.y_m), storage=storage)
    log.info("grid plant: %d x %d cells of %g m, M = %d (%d channels)", *world.grid.shape, world.grid.cell_m,
             world.M, world.n_channels)
    return GridPlant(world, substep_s, integrator="rosenbrock" if sc.run.integrator == "rosenbrock" else "idas")
