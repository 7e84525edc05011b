"""The settings every integrator takes (and the terrain engine's scheme), and the stepper interface they share.

Low in the package: the scenario reads :class:`EngineSettings` from here without importing the engine's
kernel (:mod:`symtrack.integrators.engine`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..foundations.errors import ScenarioError

__all__ = ["EngineSettings", "FIXED_STEP_TOLERANCE", "IntegratorSettings", "POWER_MODES", "STEADY_METHODS", "Stepper",
           "VEHICLE_ATOL", "VEHICLE_MAX_HALVINGS", "substeps", "window_substeps"]


# The relative tolerance of the compiled Rosenbrock's error control (IntegratorSettings.fixed_step_tolerance,
# run.fixed_step_tolerance): a step whose local error estimate exceeds
# FIXED_STEP_TOLERANCE max(|x0|, |x1|) + FIXED_STEP_ATOL in any differential state is halved.
# Calibrated on examples/scenarios/drive_and_coast.toml (every summary figure within 2 % of CVODES) and
# the validation scenario (its figures and wall time unchanged): docs/scenarios.md, "Error control of the fixed step".
FIXED_STEP_TOLERANCE = 1e-3
# (its absolute part FIXED_STEP_ATOL and the halvings' limit FIXED_STEP_MAX_HALVINGS are in the generated C:
# symtrack.native.rosenbrock)


@dataclass(frozen=True)
class IntegratorSettings:
    """How to integrate: the method (a name of :mod:`symtrack.integrators.registry`) and its
    options. ``reltol``/``abstol``/``max_num_steps``: the adaptive integrators; ``compiled``:
    CVODES/IDAS on the compiled dynamics; ``fixed_step_s``: the step bound of the fixed-step
    integrators (each requested length is cut into equal steps no longer than this);
    ``fixed_step_tolerance``: the homogeneous terrain's compiled Rosenbrock halves a step whose
    error estimate exceeds it (:class:`~symtrack.integrators.fixed_step.FixedStepper`; 0: off)."""

    method: str = "cvodes"
    reltol: float = 1e-7
    abstol: float = 1e-9
    max_num_steps: int = 200000
    compiled: bool = False
    fixed_step_s: float = 0.01
    fixed_step_tolerance: float = FIXED_STEP_TOLERANCE
    engine: object = None  # the terrain engine's settings (EngineSettings; None: its defaults)


class Stepper(Protocol):
    """What a plant needs of an integrator: advance a state over one step with inputs u and
    parameter vector p held fixed, forget what depends on continuity after a jump, report
    counters."""

    def step(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, dt: float) -> np.ndarray: ...

    def reset(self) -> None: ...

    def stats(self) -> dict: ...


def substeps(length_s: float, fixed_step_s: float) -> int:
    """Number of equal steps of at most fixed_step_s that cover length_s (the C driver mirrors it)."""
    return max(1, math.ceil(length_s / fixed_step_s - 1e-9))


POWER_MODES = ("step_mean", "instantaneous")
STEADY_METHODS = ("sdirk2", "euler")


# the absolute part of the vehicle step's error control (EngineSettings.vehicle_tolerance), in the SI unit of
# each state (m, rad, m/s, rad/s, N m): 1 um or 1 urad, below every figure the validation reports
VEHICLE_ATOL = 1e-6
# the error control halves a vehicle step at most this many times (1/64 of the macro step)
VEHICLE_MAX_HALVINGS = 6


@dataclass(frozen=True)
class EngineSettings:
    """How the engine integrates (docs/terrain.md, "The terrain engine": the measured choices).

    vehicle_substeps: steps of the vehicle's 8-stage Rosenbrock method per macro step, [1, 64].
    cell_substeps: SDIRK substeps of every active cell per macro step, [1, 64].
    entry_substeps: substeps of a cell in its entry window (soil reaction below entry_fraction
        of its load at the step start, or ringing), [1, 256]; not below
        cell_substeps.
    exit_substeps: substeps of a cell in its exit window (leaving a track's contact, its load
        falling, on its unloading line), [1, 256]; not below cell_substeps.
    steady_method: the method of the cells outside the windows: "sdirk2" (Alexander's two-stage
        SDIRK, the windows' method) or "euler" (implicit Euler: one stage a substep).
    entry_fraction: [0, 1].
    ring_tolerance: a cell whose transient about its quasi-static path exceeds this fraction of
        its sinkage at the step start takes an entry window (grid_engine.c ``ringing``), [0, 1]; 0: never.

    The defaults of the windows (entry 8, exit 8, ring_tolerance 5e-3, steady_method "euler") were
    calibrated against IDAS on validation_grid: every figure of its summary within 0.5 % at the
    fewest cell stages measured (docs/terrain.md, "The cells' ringing", the variants' table).
    vehicle_tolerance: the vehicle step's error control (grid_engine.c ``vehicle_step_controlled``): a
        vehicle step whose error estimate (the embedded solution of the stiffly accurate Rosenbrock
        method) exceeds vehicle_tolerance |w| + VEHICLE_ATOL in any differential state is replaced by
        two half steps, each controlled the same way (down to 1/64 of the step), [0, 0.1]; 0: off.
        The default 1e-3 halves 5 of the 688 steps of validation_grid on the shear law and carries the
        replayed field-operation input of tests/test_vehicle_step_replay.py that diverged without it
        (docs/terrain.md, "The vehicle step's error control").
    power: the compaction power the vehicle and the outputs see: "step_mean" (the work the cells
        absorbed over the last step / its length: energy-consistent) or "instantaneous" (p
        max(dz/dt, 0) at the step end, the channel model's expression).
    """

    vehicle_substeps: int = 1
    cell_substeps: int = 1
    entry_substeps: int = 8
    exit_substeps: int = 8
    steady_method: str = "euler"
    entry_fraction: float = 0.5
    ring_tolerance: float = 5e-3
    vehicle_tolerance: float = 1e-3
    power: str = "step_mean"

    def __post_init__(self):
        for name, hi in (("vehicle_substeps", 64), ("cell_substeps", 64), ("entry_substeps", 256),
                         ("exit_substeps", 256)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= hi:
                raise ScenarioError(f"engine.{name} = {v!r} must be an integer in [1, {hi}]")
        if not (isinstance(self.entry_fraction, (int, float)) and 0.0 <= self.entry_fraction <= 1.0):
            raise ScenarioError(f"engine.entry_fraction = {self.entry_fraction!r} must be a number in [0, 1]")
        if not (isinstance(self.ring_tolerance, (int, float)) and not isinstance(self.ring_tolerance, bool)
                and 0.0 <= self.ring_tolerance <= 1.0):
            raise ScenarioError(f"engine.ring_tolerance = {self.ring_tolerance!r} must be a number in [0, 1]")
        if not (isinstance(self.vehicle_tolerance, (int, float)) and not isinstance(self.vehicle_tolerance, bool)
                and 0.0 <= self.vehicle_tolerance <= 0.1):
            raise ScenarioError(f"engine.vehicle_tolerance = {self.vehicle_tolerance!r} must be a number in [0, 0.1]"
                                " (0: no error control)")
        if self.steady_method not in STEADY_METHODS:
            raise ScenarioError(f"engine.steady_method = {self.steady_method!r} is not one of "
                                f"{', '.join(STEADY_METHODS)}")
        if self.power not in POWER_MODES:
            raise ScenarioError(f"engine.power = {self.power!r} is not one of {', '.join(POWER_MODES)}")


def window_substeps(settings: EngineSettings) -> tuple[int, int]:
    """The substeps of the entry and of the exit windows (neither below cell_substeps)."""
    return (max(settings.entry_substeps, settings.cell_substeps), max(settings.exit_substeps, settings.cell_substeps))
