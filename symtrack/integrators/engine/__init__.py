"""The terrain engine: vehicle + grid terrain, many macro steps per call, the hot path compiled
(``run.integrator = "grid_fast"``; docs/terrain.md, "The terrain engine").

Scheme (staggered, per macro step of length h, the output step)
---------------------------------------------------------------
1. The world manager's bookkeeping at the step start (footprint at the start pose and at the
   pose predicted for the end, release, sector assignment Cell[i, j] -> CHANNEL[i mod M, j mod M],
   INFO_IN; grid_engine.c, the rules' one home, also run for the IDAS path by :class:`ChannelManager`).
2. The vehicle (12 states, 2 algebraic accelerations) over h with the channel sums (compaction
   power per track, the end-strip sinkages) held at their values at the step start: the 8-stage,
   order-5, L-stable Rosenbrock method of CasADi's plugin with the exact Jacobian,
   ``vehicle_substeps`` steps.
3. Every active cell on its own over h, its load p_load linear in time between the geometry at
   the step's start pose and at its end pose: Alexander's two-stage SDIRK (L-stable, order 2,
   stiffly accurate; or implicit Euler, ``steady_method``), each implicit stage one monotone
   scalar equation in z solved by Newton in a bracket (exact derivative of the cell's unchanged
   law, bisection when a step leaves the bracket). ``cell_substeps`` equal substeps; transient
   windows with the geometry at every substep end: ``exit_substeps`` for a cell leaving a track on
   its unloading line, ``entry_substeps`` for a cell whose soil reaction at the step start is
   below ``entry_fraction`` of its load (the entry from z = 0, where the stiffness is
   discontinuous and falls 40 x within a step) or that rings (:func:`ringing`: the lightly damped
   oscillation on the elastic line that the end of the entry ramp excites).
4. INFO_OUT for the active channels only (z, dz/dt, z_max, p_max, phase into storage), the
   channel sums at the end state, the outputs, the coverage check (every cell the tracks load
   holds a channel).

The hot path is ``symtrack/native/grid_engine.c`` (bookkeeping, cell solves) compiled with the
CasADi-generated C of :mod:`symtrack.native.grid_engine_model` (vehicle step, outputs, cell
geometry and law) through the package's compile-and-cache API (``<cache>/engine-<hash>/``);
it needs a C compiler (:data:`~.kernel.NO_COMPILER` says what to install). The same algorithm,
line by line, on CasADi's interpreter is the tests' oracle (tests/engine_oracle.py,
tests/test_terrain_engine.py checks that both agree).

Modules: :mod:`.state` (the channel tables and the C struct), :mod:`.kernel` (the library and its
ctypes calls), :mod:`.engine` (:class:`TerrainEngine`), :mod:`.manager` (:class:`ChannelManager`:
the same world-manager rules, grid_engine.c's, on a World's channel tables for the IDAS reference
path); the settings are :class:`symtrack.integrators.settings.EngineSettings`.

Interface: :class:`TerrainEngine` is built from a World-like object (``storage``, ``grid``,
``M``, ``params``, ``opts``, ``settings``, ``touched``) and :class:`EngineSettings`;
:meth:`TerrainEngine.begin_pass` sets the vehicle down and settles it, :meth:`TerrainEngine.advance`
runs many macro steps per call and returns the vehicle states and outputs at each output time,
writing the cells back into the storage arrays. The time loop drives it through
:class:`symtrack.simulation.plants.EnginePlant` (it applies the stop-at-distance rule inside its
calls), which uses the engine's public methods only.
"""

from __future__ import annotations

from ..settings import POWER_MODES, EngineSettings, window_substeps
from .engine import SETTLE_STEP_S, TerrainEngine, engine_functions
from .kernel import CKernel, library
from .manager import ChannelManager
from .state import SDIRK_GAMMA, EngineState, subsoil_tables

__all__ = ["CKernel", "ChannelManager", "EngineSettings", "EngineState", "POWER_MODES", "SDIRK_GAMMA",
           "SETTLE_STEP_S", "TerrainEngine", "engine_functions", "library", "subsoil_tables", "window_substeps"]
