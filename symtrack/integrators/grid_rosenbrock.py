"""The compiled fixed-step Rosenbrock integrator for the grid terrain (``run.integrator =
"rosenbrock"`` with a ``[terrain]`` section).

The step is :mod:`symtrack.native.grid_rosenbrock` (8-stage L-stable Rosenbrock on the DAE form, the
channels eliminated through the arrowhead's Schur complement, ``map`` over the channels). Its C
source is generated on first use for the pool size and the number of steps per call, compiled
into ``<cache>/grid-<hash>/`` through :func:`symtrack.toolchain.build` (the key hashes the
serialised Function) and loaded with ``casadi.external``. The sources are not committed: they
depend on the pool size M^2. Without a C compiler the same Function runs on CasADi's
interpreter (slow; an error with ``--require-compiled``).

Every macro step of the world manager (one output step) is one call: n equal steps of at most
``run.fixed_step_s``, the algebraic state first made consistent for the (possibly reset) channels.

Error control (``run.fixed_step_tolerance``, as the homogeneous terrain's compiled Rosenbrock,
:mod:`symtrack.integrators.fixed_step`): the call returns the largest error ratio of its steps (the
last stage's increment, the method's embedded error estimate, over FIXED_STEP_TOLERANCE max(|y0|, |y1|) +
FIXED_STEP_ATOL in the vehicle's differential states and the channels' sinkage:
:mod:`symtrack.native.grid_rosenbrock`, which says why not the channels' rate). A macro step whose
ratio exceeds 1, or whose state is not finite, is taken again in steps of half the length (two calls of
the same compiled code), down to 2^-GRID_MAX_HALVINGS of the step. A macro step still above its
tolerance there is kept with a warning (once per run); ``fixed_step_error_max`` in summary.json is the
largest ratio kept. ``run.fixed_step_tolerance = 0``: no step halved, the ratios measured.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from ..foundations.errors import SimulationError
from ..native.grid_rosenbrock import step_functions
from ..terrain.channels import NF, NG
from ..toolchain import BuildSpec, build, casadi_tag, compiler, digest
from ..vehicles.planar import codegen_options
from .settings import FIXED_STEP_TOLERANCE, substeps

__all__ = ["MAX_STEP_S", "PACK_SLOTS", "GridRosenbrockStepper", "grid_library"]

log = logging.getLogger("symtrack.terrain")
# how many times a macro step is halved at most (to 1/64 of it, as the terrain engine's vehicle step,
# VEHICLE_MAX_HALVINGS): each level takes the whole macro step again in uniform steps (2^level calls), so the
# homogeneous chunks' deeper limit (symtrack.native.rosenbrock.FIXED_STEP_MAX_HALVINGS, halving one step
# where it is needed) is not taken here
GRID_MAX_HALVINGS = 6

BUILD_VERSION = 1
# the active channels are packed into calls of a multiple of PACK_SLOTS slots (one compiled library
# per size met: at most 64 - 1 idle slots evaluated)
PACK_SLOTS = 64
# The largest step measured to work on the grid (docs/terrain.md, "Speed"): at 1.25 ms the
# validation on the million-cell field diverged (a linearly-implicit step freezes the Jacobian,
# and the regularised Bekker slope of a cell that starts loading from z = 0 is very steep and
# falls fast); at 0.625 ms every figure agrees with IDAS.
MAX_STEP_S = 0.000625


def grid_library(opts, n_channels: int, n_steps: int, compiled: bool = True):
    """(Function, compiled?) of ``grid_rosenbrock`` for n_channels channels and n_steps steps per call."""
    cc = compiler() if compiled else None
    if cc is None:
        return step_functions(opts, n_channels, n_steps)["multi"], False
    # generated C: a large track quadrature as one call node (symtrack.vehicles.planar.codegen_options)
    f = step_functions(codegen_options(opts), n_channels, n_steps)["multi"]

    def sources():
        with tempfile.TemporaryDirectory(prefix="symtrack-gridgen-") as scratch:
            cg = ca.CodeGenerator("grid_rosenbrock.c", {"with_header": True})
            cg.add(f)
            cg.generate(str(Path(scratch)) + "/")
            files = {n: (Path(scratch) / n).read_bytes() for n in ("grid_rosenbrock.c", "grid_rosenbrock.h")}
        if b"#error" in files["grid_rosenbrock.c"]:
            raise SimulationError("the generated grid integrator is not exportable (#error in grid_rosenbrock.c)")
        return files

    so = build(BuildSpec(kind="grid", key=digest(f.serialize(), casadi_tag(BUILD_VERSION)),
                         output="libgrid_rosenbrock.so", sources=sources,
                         what=f"the grid integrator ({n_channels} channels, {n_steps} steps per call)"), cc)
    return ca.external(f.name(), str(so)), True


class GridRosenbrockStepper:
    """The :class:`~symtrack.integrators.settings.Stepper` interface for the world of the grid
    terrain (one macro step per call)."""

    def __init__(self, model, settings, n_channels: int, compiled: bool = True):
        self.model, self.settings, self.n = model, settings, n_channels
        self.want_compiled = compiled
        self._f: dict[tuple[int, int], ca.Function] = {}
        self.compiled = None
        self.z = None
        self.nsteps = 0
        self.ncalls = 0
        # the error control (module doc): the relative tolerance, 0 for off (the ratios are then measured
        # against FIXED_STEP_TOLERANCE and no step is halved)
        self.tolerance = float(getattr(settings, "fixed_step_tolerance", FIXED_STEP_TOLERANCE))
        self.rtol = self.tolerance if self.tolerance > 0 else FIXED_STEP_TOLERANCE
        self.error_max = 0.0
        self.n_halved = 0
        self.warned = False

    def function(self, slots: int, n_steps: int) -> ca.Function:
        f = self._f.get((slots, n_steps))
        if f is None:
            f, self.compiled = grid_library(self.model.opts, slots, n_steps, self.want_compiled)
            self._f[(slots, n_steps)] = f
        return f

    def reset(self):
        """Nothing to forget: each call makes the algebraic state consistent first."""

    def stats(self) -> dict:
        return {"nsteps": self.nsteps, "n_calls": self.ncalls, "compiled": bool(self.compiled),
                "fixed_step_tolerance": self.tolerance, "fixed_step_error_max": self.error_max,
                "fixed_step_steps_halved": self.n_halved}

    def step(self, x, u, p, dt: float):
        """One macro step. Only the active channels are integrated (an idle channel is inert: its
        derivatives are zero), packed in channel order into a call with the next multiple
        of PACK_SLOTS slots (the spare slots idle); the channel identity is kept."""
        x, p = np.asarray(x, dtype=float), np.asarray(p, dtype=float)
        n = substeps(dt, self.settings.fixed_step_s)
        npv = p.size - NG - NF * self.n
        qc = p[npv + NG:].reshape(self.n, NF)
        act = np.nonzero(qc[:, 4] != 0.0)[0]
        cap = min(PACK_SLOTS * max(1, -(-act.size // PACK_SLOTS)), self.n)
        f = self.function(cap, n)
        lay = self.model.layout
        vs = lay.block("vehicle")
        xc = x[lay.block("cells")].reshape(self.n, lay.cell_width)
        xc_p = np.zeros((cap, 2))
        xc_p[:act.size] = xc[act]
        q_p = np.zeros((cap, NF))
        q_p[:act.size] = qc[act]
        z0 = self.z if self.z is not None else np.array(self.model.accel(x, u, p)).ravel()
        w_start, p_call = np.concatenate([x[vs], z0]), np.concatenate([p[:npv + NG], q_p.ravel()])
        on = self.tolerance > 0
        for level in range(GRID_MAX_HALVINGS + 1 if on else 1):
            # 2^level calls of n steps of dt / (n 2^level): the same compiled code (module doc)
            xc1, w1, ratio = xc_p.ravel(), w_start, 0.0
            for _ in range(2 ** level):
                xc1, w1, r = f(xc1, w1, u, p_call, dt / (n * 2 ** level), self.rtol)
                ratio = max(ratio, float(r))
            self.nsteps += n * 2 ** level
            self.ncalls += 2 ** level
            xc1, w1 = np.array(xc1).ravel(), np.array(w1).ravel()
            finite = np.all(np.isfinite(xc1)) and np.all(np.isfinite(w1)) and np.isfinite(ratio)
            if finite and ratio <= 1.0:
                break
            if level < GRID_MAX_HALVINGS and on:
                self.n_halved += n * 2 ** level  # each of these steps is taken again as two halves
        if not finite:
            raise SimulationError("the grid rosenbrock integrator returned a non-finite state (steps of "
                                  f"{dt / (n * 2 ** level):.3g} s): run it with --integrator idas")
        if on and ratio > 1.0 and not self.warned:
            log.warning("the grid Rosenbrock's error estimate stays %.3g x its tolerance in steps of %.3g s (%d "
                        "halvings of the %g s step); the step was kept: compare with --integrator idas "
                        "(summary.json: fixed_step_error_max)", ratio, dt / (n * 2 ** level), level, dt / n)
            self.warned = True
        self.error_max = max(self.error_max, ratio)
        xc_new = xc.copy()
        xc_new[act] = xc1.reshape(cap, 2)[:act.size]
        out = np.concatenate([w1[vs], xc_new.ravel()])
        self.z = w1[vs.stop:]  # w1 = (vehicle states, accelerations)
        return out
