"""The integrator menu: one registry, each entry declaring what it supports (as PyBaMM's solvers do).

An entry is an :class:`IntegratorSpec`: its name (the value of ``run.integrator``), which
terrains it integrates (``homogeneous``: the vehicle with its four travelling cells; ``grid``:
the vehicle on the channel pool of the persistent terrain), whether it takes fixed steps or
adapts them, whether it wants a C compiler (it falls back to CasADi's interpreter without one,
or fails with ``--require-compiled``), whether it accepts ``run.compiled = true`` (the adaptive
integrators on the compiled dynamics), and factories that build its stepper.

A stepper has the interface of :class:`~symtrack.integrators.settings.Stepper`:
``step(x, u, p, dt) -> x``, ``reset()``, ``stats()``. A *batch* stepper (its terrain in ``batch``)
also has ``run_chunk`` and ``consistent_z`` and advances many output steps per call
(:class:`~symtrack.simulation.plants.BatchPlant`).

Adding an integrator is one class and one :func:`register` call::

    register(IntegratorSpec("euler", "explicit Euler (a toy)", terrains=frozenset({"homogeneous"}),
                            fixed_step=True, homogeneous=lambda model, settings: EulerStepper(model, settings)))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..foundations.errors import ScenarioError
from ..foundations.registry import Registry
from .engine import TerrainEngine
from .fixed_step import FixedStepper
from .grid_idas import ChannelStepper
from .grid_rosenbrock import MAX_STEP_S, GridRosenbrockStepper
from .settings import EngineSettings, IntegratorSettings
from .sundials import SundialsStepper

__all__ = ["IntegratorSpec", "get", "names", "register", "REGISTRY", "TERRAINS"]

TERRAINS = ("homogeneous", "grid")


@dataclass(frozen=True)
class IntegratorSpec:
    """One integrator and its capabilities (module doc)."""

    name: str
    description: str
    terrains: frozenset
    fixed_step: bool = False
    needs_compiler: bool = False
    compiled_dynamics: bool = False
    batch: frozenset = frozenset()  # terrains on which its stepper advances many output steps per call
    max_fixed_step_s: dict | None = None  # terrain -> largest allowed run.fixed_step_s (None: no bound)
    homogeneous: Callable | None = None  # (model, settings) -> stepper
    grid: Callable | None = None  # (model, settings, n_channels) -> stepper
    # (world, settings) -> an engine that runs the world manager's per-step work itself, many macro
    # steps per call (symtrack.simulation.plants.EnginePlant drives it)
    grid_engine: Callable | None = None

    def __post_init__(self):
        unknown = set(self.terrains) - set(TERRAINS)
        if unknown or not self.terrains:
            raise ValueError(f"integrator {self.name!r}: terrains must be a non-empty subset of {TERRAINS}")
        for t in self.terrains:
            if getattr(self, t) is None and not (t == "grid" and self.grid_engine is not None):
                raise ValueError(f"integrator {self.name!r} supports the {t} terrain but has no {t} factory")

    def check(self, terrain: str, settings: IntegratorSettings, where: str = "run.integrator") -> None:
        """Raise a :class:`ScenarioError` when this integrator cannot run ``settings`` on ``terrain``."""
        if terrain not in self.terrains:
            others = [s.name for s in REGISTRY.values() if terrain in s.terrains]
            raise ScenarioError(f"{where} = {self.name!r} does not integrate the {terrain} terrain; "
                                f"for it use one of {', '.join(others)}")
        if settings.compiled and not self.compiled_dynamics:
            raise ScenarioError(f"run.compiled = true is not available with {where} = {self.name!r} on the "
                                f"{terrain} terrain")
        bound = (self.max_fixed_step_s or {}).get(terrain)
        if self.fixed_step and bound is not None and settings.fixed_step_s > bound * (1 + 1e-9):
            raise ScenarioError(f"run.fixed_step_s = {settings.fixed_step_s!r} s is above {bound} s, the largest "
                                f"step of {self.name} on the {terrain} terrain that was measured stable and accurate "
                                f"(docs/terrain.md, \"Speed\"); set run.fixed_step_s <= {bound}")

    def stepper(self, terrain: str, model, settings: IntegratorSettings, n_channels: int | None = None):
        """Build the stepper for ``terrain`` (checked first)."""
        self.check(terrain, settings)
        if terrain == "grid":
            return self.grid(model, settings, n_channels)
        return self.homogeneous(model, settings)


_MENU: Registry[IntegratorSpec] = Registry("an integrator", "run.integrator", ScenarioError)
REGISTRY = _MENU.entries


def register(spec: IntegratorSpec, replace: bool = False) -> IntegratorSpec:
    """Add an integrator to the menu (``run.integrator`` accepts its name from then on)."""
    return _MENU.add(spec.name, spec, replace)


def unregister(name: str) -> None:
    """Remove an integrator from the menu."""
    _MENU.remove(name)


def names(terrain: str | None = None) -> tuple[str, ...]:
    """The registered names (those that integrate ``terrain`` when it is given)."""
    return tuple(n for n, s in REGISTRY.items() if terrain is None or terrain in s.terrains)


def get(name: str, where: str = "run.integrator") -> IntegratorSpec:
    """The entry of ``name``; an unknown name is a :class:`ScenarioError` listing the menu."""
    return _MENU.get(name, where)


register(IntegratorSpec(
    "cvodes", "CVODES (BDF, adaptive) on the ODE form, exact sparse Jacobian",
    terrains=frozenset({"homogeneous"}), compiled_dynamics=True,
    homogeneous=SundialsStepper))
register(IntegratorSpec(
    "idas", "IDAS (BDF, adaptive) on the DAE form, exact Jacobian; the grid with its channels first",
    terrains=frozenset({"homogeneous", "grid"}), compiled_dynamics=True,
    homogeneous=SundialsStepper, grid=lambda model, settings, n: ChannelStepper(model, settings)))
register(IntegratorSpec(
    "rosenbrock", "compiled fixed-step 8-stage L-stable Rosenbrock (generated C)",
    terrains=frozenset({"homogeneous", "grid"}), fixed_step=True, needs_compiler=True, batch=frozenset({"homogeneous"}),
    max_fixed_step_s={"grid": MAX_STEP_S},
    homogeneous=FixedStepper, grid=GridRosenbrockStepper))
register(IntegratorSpec(
    "grid_fast", "the compiled terrain engine: vehicle Rosenbrock with frozen channel sums, each cell by SDIRK, "
    "the world manager in C, 100 macro steps per call (docs/terrain.md)",
    terrains=frozenset({"grid"}), fixed_step=True, needs_compiler=True,
    grid_engine=lambda world, settings: TerrainEngine(world, settings.engine or EngineSettings())))
