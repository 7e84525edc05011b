"""The settings every integrator takes, and the stepper interface they share."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["IntegratorSettings", "Stepper", "substeps"]


@dataclass(frozen=True)
class IntegratorSettings:
    """How to integrate: the method (a name of :mod:`symtrack.integrators.registry`) and its
    options. ``reltol``/``abstol``/``max_num_steps``: the adaptive integrators; ``compiled``:
    CVODES/IDAS on the compiled dynamics; ``fixed_step_s``: the step bound of the fixed-step
    integrators (each requested length is cut into equal steps no longer than this)."""

    method: str = "cvodes"
    reltol: float = 1e-7
    abstol: float = 1e-9
    max_num_steps: int = 200000
    compiled: bool = False
    fixed_step_s: float = 0.01
    engine: object = None  # the terrain engine's settings (grid_engine.EngineSettings; None: its defaults)


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
