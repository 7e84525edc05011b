"""The terrain engine: vehicle + grid terrain, many macro steps per call, the hot path compiled
(``run.integrator = "grid_fast"``; docs/terrain.md, "The terrain engine").

Scheme (staggered, per macro step of length h, the output step)
---------------------------------------------------------------
1. The world manager's bookkeeping at the step start (footprint at the start pose and at the
   pose predicted for the end, release, sector assignment Cell[i, j] -> CHANNEL[i mod M, j mod M],
   INFO_IN): the rules and expressions of :class:`symtrack.terrain.world.World.before_step`.
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
geometry and law) through the package's compile-and-cache API (``<cache>/engine-<hash>/``).
Without a C compiler (or with ``compiled=False``) :class:`PyKernel` runs the same algorithm, line by line, on CasADi's
interpreter (slow; tests/test_terrain_engine.py checks that both agree).

Interface: :class:`TerrainEngine` is built from a World-like object (``storage``, ``grid``,
``M``, ``params``, ``opts``, ``settings``, ``touched``) and :class:`EngineSettings`;
:meth:`TerrainEngine.begin_pass` sets the vehicle down and settles it, :meth:`TerrainEngine.advance`
runs many macro steps per call and returns the vehicle states and outputs at each output time,
writing the cells back into the storage arrays. The time loop drives it through
:class:`symtrack.simulation.plants.EnginePlant` (it applies the stop-at-distance rule inside its
calls).
"""

from __future__ import annotations

import ctypes
import dataclasses
import logging
import math
import tempfile
import time
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np

from ..build import BuildSpec, build, casadi_tag, compiler, digest
from ..foundations.errors import ScenarioError, SimulationError
from ..native.grid_engine_model import (
    NA,
    NGEO,
    NS,
    NW,
    TRACK_SOIL_PARAMS,
    build_engine_functions,
    cell_constants,
    geo_vector,
    pv_base,
    soil_dispatch_c,
)
from ..terrain import subsoil
from ..terrain.channels import soil_law_values
from ..terrain.world import END_STRIP_CELLS, LIFT_TIME_S, padding_m

log = logging.getLogger("symtrack.terrain")

NV = 12
BUILD_VERSION = 1
SETTLE_STEP_S = 0.01  # the settling steps of World.begin_pass
ERR_FIELD, ERR_COLLISION, ERR_UNCOVERED, ERR_NONFINITE, ERR_NEWTON = 1, 2, 3, 4, 5
SDIRK_GAMMA = 1.0 - 1.0 / math.sqrt(2.0)  # Alexander (1977): L-stable two-stage SDIRK
NEWTON_MAX_ITER = 100
# a Newton step inside the bracket below this fraction of |Z| is the stage's last (grid_engine.c
# NEWTON_ACCEPT): the result is then within about its square (1e-8) of the root, as the law is
# smooth there; at a kink of the law between the iterate and the root, within this fraction
# (docs/terrain.md, "The terrain engine")
NEWTON_ACCEPT_STEP = 1e-4
POWER_MODES = ("step_mean", "instantaneous")
STEADY_METHODS = ("sdirk2", "euler")
CHUNK_STEPS = 100  # macro steps per call from Python (the progress bar moves between calls)


@dataclasses.dataclass(frozen=True)
class EngineSettings:
    """How the engine integrates (docs/terrain.md, "The terrain engine": the measured choices).

    vehicle_substeps: steps of the vehicle's 8-stage Rosenbrock method per macro step, [1, 64].
    cell_substeps: SDIRK substeps of every active cell per macro step, [1, 64].
    entry_substeps: substeps of a cell in its entry window (soil reaction below entry_fraction
        of its load at the step start, or ringing: :func:`ringing`), [1, 256]; not below
        cell_substeps.
    exit_substeps: substeps of a cell in its exit window (leaving a track's contact, its load
        falling, on its unloading line), [1, 256]; not below cell_substeps.
    steady_method: the method of the cells outside the windows: "sdirk2" (Alexander's two-stage
        SDIRK, the windows' method) or "euler" (implicit Euler: one stage a substep).
    entry_fraction: [0, 1].
    ring_tolerance: a cell whose transient about its quasi-static path exceeds this fraction of
        its sinkage at the step start takes an entry window (:func:`ringing`), [0, 1]; 0: never.

    The defaults of the windows (entry 8, exit 8, ring_tolerance 5e-3, steady_method "euler") were
    calibrated against IDAS on validation_grid: every figure of its summary within 0.5 % at the
    fewest cell stages measured (docs/terrain.md, "The cells' ringing", the variants' table).
    power: the compaction power the vehicle and the outputs see: "step_mean" (the work the cells
        absorbed over the last step / its length: energy-consistent) or "instantaneous" (p
        max(dz/dt, 0) at the step end, the channel model's expression).
    compiled: the C hot path (False: the interpreted PyKernel).
    """

    vehicle_substeps: int = 1
    cell_substeps: int = 1
    entry_substeps: int = 8
    exit_substeps: int = 8
    steady_method: str = "euler"
    entry_fraction: float = 0.5
    ring_tolerance: float = 5e-3
    power: str = "step_mean"
    compiled: bool = True

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
        if self.steady_method not in STEADY_METHODS:
            raise ScenarioError(f"engine.steady_method = {self.steady_method!r} is not one of "
                                f"{', '.join(STEADY_METHODS)}")
        if self.power not in POWER_MODES:
            raise ScenarioError(f"engine.power = {self.power!r} is not one of {', '.join(POWER_MODES)}")


def outside_tracks(geo, cx: float, cy: float, a) -> bool:
    """engine.c outside_tracks: the cell centred at (cx, cy) lies wholly outside both contact
    rectangles at the pose and pressure lines a (grown by 0.7072 cell, more than the half cell by
    which the cell geometry's overlap reaches out), so its geometry is exactly zero."""
    length, b, B, e, r = geo[0], geo[1], geo[2], geo[3], 0.7072 * geo[4]
    dx, dy = cx - a[0], cy - a[1]
    xb, yb = a[2] * dx + a[3] * dy, -a[3] * dx + a[2] * dy
    if abs(xb + e) > length / 2 + r:
        return True
    return abs(yb - B / 2) > b / 2 + r and abs(yb + B / 2) > b / 2 + r


def ringing(tol: float, z: float, v: float, p: float, dp: float, plA: float, plB: float, h: float,
            areal_mass: float, damping: float) -> bool:
    """engine.c ringing: the cell (sinkage z, rate v, reaction p, dp/dz = dp at its state) rings at
    the step start, its load going from plA to plB over h: its motion about the quasi-static path
    (p following the load, at the rate (plB - plA) / (h dp)) has an amplitude sqrt(d^2 + e^2 m / dp)
    above tol |z|, d = (plA - p - c v) / dp its displacement from that path and e its excess rate
    (docs/terrain.md, "The cells' ringing")."""
    if not (tol > 0.0 and dp > 0.0 and h > 0.0):
        return False
    ik, ih = 1.0 / dp, 1.0 / h  # as engine.c: the reciprocals, then products
    d = (plA - p - damping * v) * ik
    ev = v - (plB - plA) * ih * ik
    tz = tol * z
    return d * d + areal_mass * ev * ev * ik > tz * tz


def window_substeps(settings: EngineSettings) -> tuple[int, int]:
    """The substeps of the entry and of the exit windows (neither below cell_substeps)."""
    return (max(settings.entry_substeps, settings.cell_substeps), max(settings.exit_substeps, settings.cell_substeps))


# ---- the compiled library ---------------------------------------------------------------------------------
class _Eng(ctypes.Structure):
    _fields_ = ([(n, ctypes.c_longlong) for n in ("nx", "ny", "M", "n_ch")]
                + [(n, ctypes.c_double) for n in ("x0", "y0", "dx")]
                + [(n, ctypes.c_void_p) for n in ("z", "zdot", "zmax", "pmax", "phase", "touched",
                                                  "ch_cell", "ch_foot", "ch_new_stamp", "ch_new_cell",
                                                  "ch_z", "ch_v", "ch_zmax", "ch_pmax", "ch_p", "ch_cx", "ch_cy",
                                                  "ch_g", "ch_dp", "ch_pw", "ch_vr", "ch_new", "act", "new_list")]
                + [(n, ctypes.c_longlong) for n in ("n_act", "n_new", "peak_active", "stamp")]
                + [(n, ctypes.c_void_p) for n in ("pv", "geo", "wv", "a", "work", "agrid", "plbuf", "frbuf")]
                + [(n, ctypes.c_longlong) for n in ("n_pv", "ny_out", "cell_substeps", "entry_substeps", "power_mode")]
                + [(n, ctypes.c_double) for n in ("pad", "release_rate", "areal_mass", "damping", "gamma",
                                                  "entry_fraction")]
                + [(n, ctypes.c_longlong) for n in ("err_code", "err_a", "err_b", "err_ch")]
                + [("err_x", ctypes.c_double * 2)]
                + [(n, ctypes.c_longlong) for n in ("n_newton", "n_cell_stages", "n_vehicle_steps", "ns_manager",
                                                    "ns_vehicle", "ns_cells", "ns_outputs")]
                + [(n, ctypes.c_void_p) for n in ("zoff", "cycles", "ch_zoff", "ch_delta", "ch_dc", "ch_counted",
                                                  "subsoil", "sig_pass")]
                + [(n, ctypes.c_longlong) for n in ("n_depths", "ns_subsoil")]
                + [(n, ctypes.c_void_p) for n in ("soil_index", "ch_soil", "soil_veh")]
                + [("n_sums", ctypes.c_longlong), ("exit_substeps", ctypes.c_longlong),
                   ("agrid_entry", ctypes.c_void_p), ("steady_euler", ctypes.c_longlong),
                   ("ring_tol", ctypes.c_double)])


def _check_no_work(fns):
    for f in fns:
        if f.sz_iw() or f.sz_arg() != f.n_in() or f.sz_res() != f.n_out():
            raise SimulationError(f"{f.name()} needs integer work or extra arguments; engine.c passes neither")


def library(fns, compiled: bool = True):
    """The loaded engine library (ctypes.CDLL) for these Functions, or None (no compiler / not wanted)."""
    if not compiled:
        return None
    cc = compiler()
    if cc is None:
        return None
    _check_no_work(fns.all())
    csrc = resources.files("symtrack.native").joinpath("grid_engine.c").read_bytes()
    hsrc = resources.files("symtrack.native").joinpath("subsoil.h").read_bytes()
    dsrc = soil_dispatch_c(fns.n_soils).encode()
    key = digest(*(f.serialize() for f in fns.all()), csrc, hsrc, dsrc, casadi_tag(BUILD_VERSION))

    def sources():
        with tempfile.TemporaryDirectory(prefix="symtrack-enginegen-") as scratch:
            cg = ca.CodeGenerator("engine_gen.c", {"with_header": False})
            for f in fns.all():
                cg.add(f)
            cg.generate(str(Path(scratch)) + "/")
            gen = (Path(scratch) / "engine_gen.c").read_bytes()
        if b"#error" in gen:
            raise SimulationError("the generated engine functions are not exportable (#error in engine_gen.c)")
        return {"engine.c": csrc, "engine_gen.inc": gen, "subsoil.h": hsrc, "engine_soils.inc": dsrc}

    so = build(BuildSpec(kind="engine", key=key, output="libsymtrack_engine.so", sources=sources,
                         what="the terrain engine"), cc)
    lib = ctypes.CDLL(str(so))
    P = ctypes.POINTER(_Eng)
    dp, ll = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_longlong)
    lib.eng_assign.argtypes = [P, ctypes.c_double]
    lib.eng_assign.restype = ctypes.c_int
    lib.eng_sums.argtypes = [P]
    lib.eng_sums.restype = None
    lib.eng_run.argtypes = [P, ctypes.c_longlong, ctypes.c_double, dp, dp, dp, ctypes.c_int, dp, dp, dp, ll]
    lib.eng_run.restype = ctypes.c_int
    lib.eng_lift.argtypes = [P, dp, ctypes.c_double, ctypes.c_double, ctypes.c_longlong, ctypes.c_longlong,
                             ctypes.POINTER(ctypes.c_int)]
    lib.eng_lift.restype = ctypes.c_longlong
    lib.eng_static.argtypes = [P]
    lib.eng_static.restype = None
    return lib


def _address(a: np.ndarray) -> int:
    """The address of a C-contiguous array's data (without building a ctypes object)."""
    if not a.flags.c_contiguous:
        raise SimulationError("the engine's arrays must be C-contiguous")
    return a.__array_interface__["data"][0]


def _dptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


# ---- the state both kernels work on -----------------------------------------------------------------------
class EngineState:
    """Channel tables, the vehicle state and the constants (numpy arrays shared with the C struct)."""

    def __init__(self, world, settings: EngineSettings, fns):
        g = world.grid
        self.grid, self.M = g, int(world.M)
        n = self.M * self.M
        self.n_ch = n
        self.storage = world.storage
        self.touched = world.touched  # bool array: 1 byte per cell
        self.ch_cell = np.full(n, -1, dtype=np.int64)
        self.ch_foot = np.zeros(n, dtype=np.int64)
        self.ch_new_stamp = np.zeros(n, dtype=np.int64)
        self.ch_new_cell = np.full(n, -1, dtype=np.int64)
        for name in ("ch_z", "ch_v", "ch_zmax", "ch_pmax", "ch_p", "ch_cx", "ch_cy", "ch_zoff", "ch_delta", "ch_dc"):
            setattr(self, name, np.zeros(n))
        self.ch_counted = np.zeros(n, dtype=np.uint8)
        self.ch_g = np.zeros((n, NGEO))
        self.ch_dp = np.zeros(n)
        self.ch_pw = np.zeros((n, 2))
        self.ch_vr = np.zeros(n)
        self.ch_new = np.zeros(n, dtype=np.uint8)
        self.act = np.zeros(n, dtype=np.int64)
        self.new_list = np.zeros(4 * n + 16, dtype=np.int64)
        self.n_act = 0
        self.peak_active = 0
        self.stamp = 0
        strip = END_STRIP_CELLS * g.cell_m
        self.n_sums = fns.n_sums
        self.pv = np.array(pv_base(world.params, g.cell_m, strip) + [0.0] * self.n_sums)
        # the soil map: each channel's soil, per soil what the traction uses
        self.soil_index = world.storage.soil_index
        self.ch_soil = np.zeros(n, dtype=np.uint8)
        self.soil_veh = np.array([[float(sp[k]) for k in TRACK_SOIL_PARAMS] for sp in world.soils]).ravel()
        self.geo = np.array(geo_vector(world.params, g.cell_m, strip))
        self.wv = np.zeros(NW)
        self.a = np.zeros(NA)
        self.work = np.zeros(max(f.sz_w() for f in fns.all()) + 1)
        n_entry, n_exit = window_substeps(settings)
        nmax = max(n_entry, n_exit)
        self.agrid, self.agrid_entry = np.zeros(NA * (n_exit + 1)), np.zeros(NA * (n_entry + 1))
        self.plbuf, self.frbuf = np.zeros(nmax + 1), np.zeros(2 * (nmax + 1))
        self.pad = padding_m(g.cell_m)
        self.release_rate = float(world.settings.release_rate_m_s)
        self.areal_mass, self.damping = cell_constants(world.params)
        self.settings = settings
        self.ny_out = len(fns.output_names)
        self.stats = {"n_newton": 0, "n_cell_stages": 0, "n_vehicle_steps": 0, "ns_manager": 0, "ns_vehicle": 0,
                      "ns_cells": 0, "ns_outputs": 0, "ns_subsoil": 0}  # ns_*: the C kernel's parts (0: interpreted)
        # the subsoil stress (docs/subsoil.md): tables for the vehicle and soil, this pass's maxima
        self.sig_pass = world.pass_sigma
        self._addresses = None  # struct(): the arrays and their addresses
        self.subsoil = subsoil_tables(world.params, world.storage.subsoil_depths_m)
        self._subsoil_c = self.subsoil.c_struct() if self.subsoil is not None else None

    def struct(self) -> _Eng:
        g, st, s = self.grid, self.storage, self.settings
        e = _Eng()
        e.nx, e.ny, e.M, e.n_ch = g.shape[0], g.shape[1], self.M, self.n_ch
        e.x0, e.y0, e.dx = g.origin_m[0], g.origin_m[1], g.cell_m
        arrays = [("z", st.z), ("zdot", st.zdot), ("zmax", st.zmax), ("pmax", st.pmax), ("phase", st.phase),
                  ("touched", self.touched), ("zoff", st.zoff), ("cycles", st.cycles), ("sig_pass", self.sig_pass),
                  ("soil_index", self.soil_index)]
        arrays += [(name, getattr(self, name)) for name in (
            "ch_cell", "ch_foot", "ch_new_stamp", "ch_new_cell", "ch_z", "ch_v", "ch_zmax", "ch_pmax", "ch_p", "ch_cx",
            "ch_cy", "ch_g", "ch_dp", "ch_pw", "ch_vr", "ch_new", "act", "new_list", "pv", "geo", "wv", "a", "work",
            "agrid", "agrid_entry", "plbuf", "frbuf", "ch_zoff", "ch_delta", "ch_dc", "ch_counted", "ch_soil",
            "soil_veh")]
        # the addresses, taken again only when an array was replaced (a call runs 100 macro steps:
        # ctypes' data_as for the 43 arrays was a few percent of a call)
        cached = self._addresses
        if cached is None or len(cached[0]) != len(arrays) or any(
                a is not b for (_, a), b in zip(arrays, cached[0], strict=True)):
            cached = self._addresses = ([a for _, a in arrays], [_address(a) for _, a in arrays])
        for (name, _), addr in zip(arrays, cached[1], strict=True):
            setattr(e, name, addr)
        e.n_act, e.n_new, e.peak_active, e.stamp = self.n_act, 0, self.peak_active, self.stamp
        e.n_pv, e.ny_out = self.pv.size, self.ny_out
        e.cell_substeps = s.cell_substeps
        e.entry_substeps, e.exit_substeps = window_substeps(s)
        e.steady_euler = int(s.steady_method == "euler")
        e.power_mode = POWER_MODES.index(s.power)
        e.pad, e.release_rate, e.areal_mass, e.damping = self.pad, self.release_rate, self.areal_mass, self.damping
        e.gamma, e.entry_fraction = SDIRK_GAMMA, float(s.entry_fraction)
        e.ring_tol = float(s.ring_tolerance)
        for k, v in self.stats.items():
            setattr(e, k, v)
        e.n_depths = self.sig_pass.shape[1] if self.subsoil is not None else 0
        e.subsoil = ctypes.addressof(self._subsoil_c) if self._subsoil_c is not None else None
        e.n_sums = self.n_sums
        return e

    def absorb(self, e: _Eng) -> None:
        """The scalar fields the C kernel changed."""
        self.n_act, self.peak_active, self.stamp = int(e.n_act), int(e.peak_active), int(e.stamp)
        for k in self.stats:
            self.stats[k] = int(getattr(e, k))

    def active_channels(self) -> np.ndarray:
        return self.act[:self.n_act]


class CKernel:
    """engine.c through ctypes (the arrays are shared; the struct's scalars are copied in and out)."""

    compiled = True

    def __init__(self, lib, state: EngineState):
        self.lib, self.s = lib, state

    def assign(self, h: float) -> tuple[int, _Eng]:
        e = self.s.struct()
        rc = self.lib.eng_assign(ctypes.byref(e), float(h))
        self.s.absorb(e)
        return (-rc if rc > 0 else 0), e

    def sums(self) -> None:
        e = self.s.struct()
        self.lib.eng_sums(ctypes.byref(e))

    def run(self, t0, T, U, dist, check_covered, T_out, X, Y):
        e = self.s.struct()
        n_done = ctypes.c_longlong(0)
        rc = self.lib.eng_run(ctypes.byref(e), T.size, float(t0), _dptr(T), _dptr(U), _dptr(dist),
                              int(bool(check_covered)), _dptr(T_out), _dptr(X), _dptr(Y), ctypes.byref(n_done))
        self.s.absorb(e)
        return rc, int(n_done.value), e

    def static(self) -> None:
        e = self.s.struct()
        self.lib.eng_static(ctypes.byref(e))

    def lift(self, p_end, h, T, n, max_steps):
        e = self.s.struct()
        settled = ctypes.c_int(0)
        rc = self.lib.eng_lift(ctypes.byref(e), _dptr(p_end), float(h), float(T), int(n), int(max_steps),
                               ctypes.byref(settled))
        self.s.absorb(e)
        return int(rc), bool(settled.value), e


class _PyErr:
    """The error fields of the C struct, for the interpreted kernel."""

    def __init__(self):
        self.err_code, self.err_a, self.err_b, self.err_ch = 0, -1, -1, -1
        self.err_x = [0.0, 0.0]
        self.n_new = 0


class PyKernel:
    """engine.c in Python on CasADi's interpreter: the same algorithm, expression by expression."""

    compiled = False

    def __init__(self, fns, state: EngineState):
        self.f, self.s = fns, state
        self.e = _PyErr()

    # the generated Functions
    def _law(self, z, hist, soil):
        p, dp = self.f.cell_law[soil](z, hist)
        return float(p), float(dp)

    def _hist(self, ch):
        s = self.s
        return [float(s.ch_zmax[ch]), float(s.ch_pmax[ch]), float(s.ch_zoff[ch]), float(s.ch_delta[ch]),
                float(s.ch_dc[ch])]

    def _geo(self, cx, cy, a):
        return np.array(self.f.cell_geo(ca.DM([cx, cy]), ca.DM(a), ca.DM(self.s.geo))).ravel()

    def _scan(self, X, Y, psi, pad, check_field, fn):
        s = self.s
        g = s.grid
        l, b, B, e = (float(v) for v in s.geo[:4])
        c, sn = math.cos(psi), math.sin(psi)
        dx, x0, y0 = g.cell_m, g.origin_m[0], g.origin_m[1]
        nx, ny = g.shape
        x1, y1 = x0 + nx * dx, y0 + ny * dx
        for sg in (1.0, -1.0):
            bx, by = -e, sg * B / 2
            cx, cy = X + c * bx - sn * by, Y + sn * bx + c * by
            hl, hw = l / 2 + pad, b / 2 + pad
            ex = abs(c) * hl + abs(sn) * hw
            ey = abs(sn) * hl + abs(c) * hw
            if check_field:
                exu, eyu = ex - pad * (abs(c) + abs(sn)), ey - pad * (abs(c) + abs(sn))
                if cx - exu < x0 or cx + exu > x1 or cy - eyu < y0 or cy + eyu > y1:
                    self.e.err_code, self.e.err_x = ERR_FIELD, [cx, cy]
                    return 1
            i0, i1 = max(math.floor((cx - ex - x0) / dx), 0), min(math.ceil((cx + ex - x0) / dx), nx - 1)
            j0, j1 = max(math.floor((cy - ey - y0) / dx), 0), min(math.ceil((cy + ey - y0) / dx), ny - 1)
            for i in range(i0, i1 + 1):
                px = x0 + (i + 0.5) * dx
                for j in range(j0, j1 + 1):
                    py = y0 + (j + 0.5) * dx
                    along = (px - cx) * c + (py - cy) * sn
                    across = -(px - cx) * sn + (py - cy) * c
                    if abs(along) <= hl and abs(across) <= hw:
                        fn(i * ny + j)
        return 0

    def _channel_of(self, cell):
        i, j = divmod(cell, self.s.grid.shape[1])
        return (i % self.s.M) * self.s.M + (j % self.s.M)

    def assign(self, h: float):
        s, e = self.s, self.e
        w = s.wv
        X, Y, psi, u, v, r = (float(w[i]) for i in range(6))
        c, sn = math.cos(psi), math.sin(psi)
        X1, Y1, psi1 = X + h * (u * c - v * sn), Y + h * (u * sn + v * c), psi + h * r
        s.stamp += 1
        new = []

        def mark(cell):
            if e.err_code:
                return
            ch = self._channel_of(cell)
            if s.ch_cell[ch] == cell:
                s.ch_foot[ch] = s.stamp
            elif s.ch_new_stamp[ch] == s.stamp:
                if s.ch_new_cell[ch] != cell:
                    e.err_code, e.err_a, e.err_b, e.err_ch = ERR_COLLISION, int(s.ch_new_cell[ch]), cell, ch
            else:
                s.ch_new_stamp[ch] = s.stamp
                s.ch_new_cell[ch] = cell
                new.append(cell)

        e.n_new = 0
        if self._scan(X, Y, psi, s.pad, True, mark) or self._scan(X1, Y1, psi1, s.pad, True, mark) or e.err_code:
            s.new_list[:len(new)] = new
            e.n_new = len(new)
            return e.err_code, e
        keep = []
        for ch in s.act[:s.n_act]:
            if s.ch_foot[ch] != s.stamp and s.ch_p[ch] <= 0.0 and abs(s.ch_v[ch]) <= s.release_rate:
                s.ch_cell[ch] = -1
                s.ch_z[ch] = s.ch_v[ch] = s.ch_p[ch] = 0.0
            else:
                keep.append(ch)
        s.n_act = len(keep)
        s.act[:s.n_act] = keep
        s.new_list[:len(new)] = new
        e.n_new = len(new)
        for cell in new:
            ch = self._channel_of(cell)
            if s.ch_cell[ch] >= 0:
                e.err_code, e.err_a, e.err_b, e.err_ch = ERR_COLLISION, cell, int(s.ch_cell[ch]), ch
                return e.err_code, e
        g = s.grid
        st = s.storage
        for cell in new:
            ch = self._channel_of(cell)
            i, j = divmod(cell, g.shape[1])
            s.ch_cell[ch] = cell
            s.ch_cx[ch] = g.origin_m[0] + (i + 0.5) * g.cell_m
            s.ch_cy[ch] = g.origin_m[1] + (j + 0.5) * g.cell_m
            s.ch_z[ch], s.ch_v[ch] = st.z[cell], st.zdot[cell]
            s.ch_zmax[ch], s.ch_pmax[ch] = st.zmax[cell], st.pmax[cell]
            s.ch_zoff[ch], s.ch_delta[ch], s.ch_dc[ch], s.ch_counted[ch] = st.zoff[cell], 0.0, 0.0, 0
            s.ch_soil[ch] = st.soil_index[cell]
            soil = int(s.ch_soil[ch])
            s.ch_delta[ch] = float(self.f.cell_entry[soil](float(s.ch_z[ch]), self._hist(ch), float(st.cycles[cell])))
            s.ch_p[ch] = 0.0
            s.ch_pw[ch] = 0.0
            s.ch_vr[ch] = s.ch_v[ch]
            s.ch_p[ch], s.ch_dp[ch] = self._law(s.ch_z[ch], self._hist(ch), soil)
            s.touched[cell] = True
            s.ch_g[ch] = self._geo(s.ch_cx[ch], s.ch_cy[ch], s.a)
            s.act[s.n_act] = ch
            s.n_act += 1
        s.peak_active = max(s.peak_active, s.n_act)
        return 0, e

    def _coefficients(self, gh):
        """engine.c stage_coefficients: (a, 1 / a, g) of a stage of length gh."""
        m, cd = self.s.areal_mass, self.s.damping
        a = (1.0 + gh * cd / m) / gh
        return a, 1.0 / a, gh / m

    def _stage(self, zeta, omega, pl, a, ia, g, hist, soil, zs, ps, dps):
        s = self.s
        hi = zeta + (omega + g * pl) * ia
        lo = -math.inf
        x = (a * zeta + omega + g * (pl - ps + dps * zs)) / (a + g * dps)
        if not x < hi:
            x = hi
        for _ in range(NEWTON_MAX_ITER):
            s.stats["n_newton"] += 1
            p, dp = self._law(x, hist, soil)
            F = a * (x - zeta) + g * p - omega - g * pl
            if F > 0.0:
                hi = x
            elif F < 0.0:
                lo = x
            else:
                break
            xn = x - F / (a + g * dp)
            if abs(xn - x) <= 1e-13 * abs(xn) + 1e-18:
                break
            if abs(xn - x) <= NEWTON_ACCEPT_STEP * abs(xn) and lo < xn < hi:
                p = max(0.0, p + dp * (xn - x))
                x = xn
                break
            if not (lo < xn < hi):
                if lo == -math.inf:
                    ph, _ = self._law(hi, hist, soil)
                    lo = hi - g * ph * ia
                if not (lo < xn < hi):
                    xn = 0.5 * (lo + hi)
            x = xn
        if not abs(a * (x - zeta) + g * p - omega - g * pl) <= (1e-6 * abs(x) + 1e-18) * (a + g * dp):
            return None  # the Newton step from x, F / F', not below 1e-6 |x| + 1e-18 m
        return x, p, dp

    def _cell_step(self, z0, v0, pz, dpz, pl, f, hist, soil, h, n, work, euler=False):
        gam = SDIRK_GAMMA
        hs = h / n
        gh = gam * hs
        if euler:
            vr = v0
            ae, iae, ge = self._coefficients(hs)
            ihs = 1.0 / hs
            for k in range(n):
                p0 = pz
                r1 = self._stage(z0, v0, pl[k + 1], ae, iae, ge, hist, soil, z0, pz, dpz)
                if r1 is None:
                    return None
                Z1, pz, dpz = r1
                w1 = 0.5 * (p0 + pz) * max(Z1 - z0, 0.0)
                for t in range(2):
                    work[t] += 0.5 * (f[2 * k + t] + f[2 * k + 2 + t]) * w1
                v0 = (Z1 - z0) * ihs
                vr = v0
                z0 = Z1
                self.s.stats["n_cell_stages"] += 1
            return z0, v0, pz, dpz, vr
        a, ia, g = self._coefficients(gh)
        igh, ihs = 1.0 / gh, 1.0 / hs
        q0, q1, q2 = (1.0 - gam) / gam * ihs, ihs / (gam * (gam - 1.0)), (2.0 - gam) / (1.0 - gam) * ihs
        for k in range(n):
            p0 = pz
            plA, plB = pl[k], pl[k + 1]
            r1 = self._stage(z0, v0, plA + (plB - plA) * gam, a, ia, g, hist, soil, z0, pz, dpz)
            if r1 is None:
                return None
            Z1, pz, dpz = r1
            p1 = pz
            V1 = (Z1 - z0) * igh
            A1 = (V1 - v0) * igh
            zeta, omega = z0 + hs * (1.0 - gam) * V1, v0 + hs * (1.0 - gam) * A1
            r2 = self._stage(zeta, omega, plB, a, ia, g, hist, soil, Z1, pz, dpz)
            if r2 is None:
                return None
            Z2, pz, dpz = r2
            m1, m2 = 0.5 * gam, 0.5 * (gam + 1.0)
            w1, w2 = 0.5 * (p0 + p1) * max(Z1 - z0, 0.0), 0.5 * (p1 + pz) * max(Z2 - Z1, 0.0)
            for t in range(2):
                fa, fb = f[2 * k + t], f[2 * k + 2 + t]
                work[t] += (fa + (fb - fa) * m1) * w1 + (fa + (fb - fa) * m2) * w2
            v0 = (Z2 - zeta) * igh
            vr = z0 * q0 + Z1 * q1 + Z2 * q2  # the quadratic through (0, z0), (gamma, Z1), (1, Z2)
            z0 = Z2
            self.s.stats["n_cell_stages"] += 2
        return z0, v0, pz, dpz, vr

    def _info_out(self, ch, hist, soil):
        s, st = self.s, self.s.storage
        zc, p = float(s.ch_z[ch]), float(s.ch_p[ch])
        zm1, pm1, dc1, plastic, phase = np.array(self.f.cell_history[soil](zc, p, hist)).ravel()
        cell = int(s.ch_cell[ch])
        st.z[cell], st.zdot[cell], st.zmax[cell], st.pmax[cell] = zc, s.ch_v[ch], zm1, pm1
        st.phase[cell] = int(phase) if zm1 > 0 else 0
        st.zoff[cell] = s.ch_zoff[ch] + dc1
        if plastic > 0 and not s.ch_counted[ch]:
            s.ch_counted[ch] = 1
            st.cycles[cell] = min(int(st.cycles[cell]) + 1, 65535)
        s.ch_zmax[ch], s.ch_pmax[ch], s.ch_dc[ch] = zm1, pm1, dc1

    def static(self) -> None:
        s = self.s
        for ch in s.act[:s.n_act]:
            soil, hist = int(s.ch_soil[ch]), self._hist(ch)
            z0, pl = float(s.ch_z[ch]), float(s.ch_g[ch, 0])
            p, _ = self._law(z0, hist, soil)
            if pl != p:
                up = pl > p
                lo = hi = z0
                step = 1e-4
                for _ in range(60):
                    if up:
                        hi = lo + step
                    else:
                        lo = hi - step
                    p, _ = self._law(hi if up else lo, hist, soil)
                    if (not p < pl) if up else (not p > pl):
                        break
                    step *= 2.0
                for _ in range(200):
                    if not hi - lo > 1e-15:
                        break
                    mid = 0.5 * (lo + hi)
                    p, _ = self._law(mid, hist, soil)
                    if p <= pl:
                        lo = mid
                    else:
                        hi = mid
                s.ch_z[ch] = 0.5 * (lo + hi)
            s.ch_v[ch] = s.ch_vr[ch] = 0.0
            s.ch_p[ch], s.ch_dp[ch] = self._law(float(s.ch_z[ch]), hist, soil)

    def lift(self, p_end, h, T, n, max_steps):
        s, e = self.s, self.e
        fr = [0.0] * (2 * (n + 1))
        for k in range(max_steps):
            t0 = k * h
            act = s.act[:s.n_act]
            if t0 >= T and all(s.ch_p[ch] <= 0.0 and abs(s.ch_v[ch]) <= s.release_rate for ch in act):
                return k, True, e
            for ch in act:
                pe = float(p_end[ch])
                if s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and pe == 0.0:
                    continue
                pl = [pe * max(0.0, 1.0 - (t0 + h * j / n) / T) for j in range(n + 1)]
                hist = self._hist(ch)
                soil = int(s.ch_soil[ch])
                out = self._cell_step(float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]), float(s.ch_dp[ch]),
                                      pl, fr, hist, soil, h, n, [0.0, 0.0])
                if out is None:
                    e.err_code, e.err_a = ERR_NEWTON, int(s.ch_cell[ch])
                    return -ERR_NEWTON, False, e
                s.ch_z[ch], s.ch_v[ch], s.ch_p[ch], s.ch_dp[ch], _ = out
                self._info_out(ch, hist, soil)
        return max_steps, False, e

    def sums(self):
        s = self.s
        S = [0.0] * s.n_sums
        for ch in s.act[:s.n_act]:
            g = s.ch_g[ch]
            zc = float(s.ch_z[ch])
            if s.settings.power == "step_mean":
                S[0] += s.ch_pw[ch, 0]
                S[1] += s.ch_pw[ch, 1]
            else:
                pw = float(s.ch_p[ch]) * max(float(s.ch_vr[ch]), 0.0)
                S[0] += g[1] * pw
                S[1] += g[2] * pw
            for r in range(4):
                S[2 + r] += g[3 + r] * zc
                S[6 + r] += g[3 + r]
            if s.n_sums > NS:
                sv = s.soil_veh[3 * int(s.ch_soil[ch]):3 * int(s.ch_soil[ch]) + 3]
                for t in range(2):
                    S[NS + t] += g[1 + t]
                    for i in range(3):
                        S[NS + 2 + 3 * t + i] += g[1 + t] * sv[i]
        s.pv[-s.n_sums:] = S

    def _uncovered(self, w1):
        s = self.s
        missing = []

        def check(cell):
            if s.ch_cell[self._channel_of(cell)] != cell:
                missing.append(cell)
        self._scan(w1[0], w1[1], w1[2], 0.5 * s.grid.cell_m, False, check)
        return missing

    def _vehicle_step(self, u, h):
        w1, a1 = self.f.vehicle_step(self.s.wv, u, self.s.pv, h)
        self.s.stats["n_vehicle_steps"] += 1
        return np.array(w1).ravel(), np.array(a1).ravel()

    def _pose_grid(self, a1, psi1, n):
        """engine.c pose_grid: the pose and pressure lines at the ends of n equal substeps."""
        s = self.s
        grid = [s.a.copy()]
        for j in range(1, n):
            th = j / n
            psi = s.wv[2] + (psi1 - s.wv[2]) * th
            aj = s.a + (a1 - s.a) * th
            aj[2], aj[3] = math.cos(psi), math.sin(psi)
            grid.append(aj)
        grid.append(a1.copy())
        return grid

    def run(self, t0, T, U, dist, check_covered, T_out, X, Y):
        s, e = self.s, self.e
        t = t0
        n_done = 0
        sset = s.settings
        nsub = sset.cell_substeps
        nentry, nexit = window_substeps(sset)
        for k in range(T.size):
            t_next = float(T[k])
            h = t_next - t
            u = U[k]
            done = False
            rc, _ = self.assign(h)
            if rc:
                return -rc, n_done, e
            w1, a1 = self._vehicle_step(u, h)
            if dist[1] >= 0.0 and t_next > dist[2] + 1e-12:
                d_step = math.hypot(w1[0] - s.wv[0], w1[1] - s.wv[1])
                if dist[0] + d_step >= dist[1]:
                    for _ in range(3):
                        if d_step <= 0:
                            break
                        h *= (dist[1] - dist[0]) / d_step
                        w1, a1 = self._vehicle_step(u, h)
                        d_step = math.hypot(w1[0] - s.wv[0], w1[1] - s.wv[1])
                    t_next = t + h
                    done = True
                dist[0] += d_step
            if not np.all(np.isfinite(w1)):
                e.err_code = ERR_NONFINITE
                return -ERR_NONFINITE, n_done, e
            grid_exit = self._pose_grid(a1, w1[2], nexit)
            grid_entry = grid_exit if nentry == nexit else self._pose_grid(a1, w1[2], nentry)
            ih = 1.0 / h if h > 0.0 else 0.0  # engine.c: the step's reciprocal
            for ch in s.act[:s.n_act]:
                if (s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and s.ch_g[ch][0] == 0.0
                        and outside_tracks(s.geo, s.ch_cx[ch], s.ch_cy[ch], a1)):
                    s.ch_g[ch] = 0.0
                    s.ch_pw[ch] = 0.0
                    s.ch_p[ch] = 0.0
                    s.ch_vr[ch] = 0.0
                    continue
                gB = self._geo(s.ch_cx[ch], s.ch_cy[ch], a1)
                gA = s.ch_g[ch]
                plA, plB = float(gA[0]), float(gB[0])
                s.ch_pw[ch] = 0.0
                if s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and plA == 0.0 and plB == 0.0:
                    s.ch_g[ch] = gB
                    s.ch_p[ch] = 0.0
                    s.ch_vr[ch] = 0.0
                    continue
                ns = nsub
                wgrid = None
                if (plB < plA and gB[1] + gB[2] < gA[1] + gA[2]
                        and s.ch_z[ch] < s.ch_zmax[ch] + s.ch_zoff[ch] + s.ch_dc[ch]):
                    if nexit > ns:
                        ns, wgrid = nexit, grid_exit
                elif (s.ch_p[ch] < sset.entry_fraction * max(plA, plB)
                      or ringing(sset.ring_tolerance, float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]),
                                 float(s.ch_dp[ch]), plA, plB, h, s.areal_mass, s.damping)):
                    if nentry > ns:
                        ns, wgrid = nentry, grid_entry
                pl, fr = [plA], [float(gA[1]), float(gA[2])]
                for j in range(1, ns):
                    if wgrid is not None:
                        gj = self._geo(s.ch_cx[ch], s.ch_cy[ch], wgrid[j])
                        pl.append(float(gj[0]))
                        fr += [float(gj[1]), float(gj[2])]
                    else:
                        th = j / ns
                        pl.append(plA + (plB - plA) * th)
                        fr += [float(gA[1] + (gB[1] - gA[1]) * th), float(gA[2] + (gB[2] - gA[2]) * th)]
                pl.append(plB)
                fr += [float(gB[1]), float(gB[2])]
                work = [0.0, 0.0]
                hist = self._hist(ch)
                soil = int(s.ch_soil[ch])
                out = self._cell_step(float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]), float(s.ch_dp[ch]),
                                      pl, fr, hist, soil, h, ns, work,
                                      wgrid is None and sset.steady_method == "euler")
                if out is None:
                    e.err_code, e.err_a = ERR_NEWTON, int(s.ch_cell[ch])
                    return -ERR_NEWTON, n_done, e
                s.ch_z[ch], s.ch_v[ch], s.ch_p[ch], s.ch_dp[ch], s.ch_vr[ch] = out
                s.ch_pw[ch] = (work[0] * ih, work[1] * ih)
                s.ch_g[ch] = gB
                self._info_out(ch, hist, soil)
            if s.subsoil is not None:
                act = s.act[:s.n_act]
                act = act[s.ch_g[act, 0] > 0.0]
                if act.size:
                    sig = subsoil.stress_at(s.subsoil, s.ch_cx[act], s.ch_cy[act], a1, s.geo).astype(np.float32)
                    cells = s.ch_cell[act]
                    s.sig_pass[cells] = np.maximum(s.sig_pass[cells], sig)
            s.wv[:] = w1
            s.a[:] = a1
            self.sums()
            t = t_next
            T_out[k] = t
            X[k] = w1[:NV]
            Y[k] = np.array(self.f.outputs(w1[:NV], u, s.pv)).ravel()
            n_done = k + 1
            if check_covered:
                missing = self._uncovered(w1)
                if missing:
                    e.err_code, e.err_a, e.err_b = ERR_UNCOVERED, missing[0], len(missing)
                    return -ERR_UNCOVERED, n_done, e
            if done:
                return 1, n_done, e
        return 0, n_done, e


# ---- the engine -------------------------------------------------------------------------------------------
_FUNCTIONS: dict = {}
_TABLES: dict = {}


def subsoil_tables(params: dict, depths_m) -> subsoil.SubsoilTables | None:
    """The subsoil stress tables of the vehicle's tracks and the soil's concentration factor at the
    depths (None for no depths), cached per (geometry, xi, depths) in this process."""
    if not depths_m:
        return None
    key = (tuple(depths_m), float(params["stress_concentration_factor"]), float(params["contact_length_m"]),
           float(params["track_width_m"]), float(params["track_gauge_m"]))
    if key not in _TABLES:
        _TABLES[key] = subsoil.build_tables(key[0], key[1], key[2], key[3], key[4])
    return _TABLES[key]


def engine_functions(opts, params: dict, vehicle_substeps: int, soils: tuple = ()):
    """build_engine_functions, cached per (options, soil laws, substeps) in this process;
    ``soils``: the parameter dicts of a soil map's soils (index 0 the scenario's)."""
    soils = tuple(soils) or (params,)
    key = (opts, vehicle_substeps, tuple(
        (tuple(soil_law_values(sp, opts.bekker_regularisation_m)), float(sp["repeated_loading_exponent"]),
         tuple(float(sp[k]) for k in TRACK_SOIL_PARAMS)) for sp in soils))
    if key not in _FUNCTIONS:
        _FUNCTIONS[key] = build_engine_functions(opts, params, vehicle_substeps, soils if len(soils) > 1 else ())
    return _FUNCTIONS[key]


class TerrainEngine:
    """Vehicle + grid terrain (module doc). ``world``: a :class:`~symtrack.terrain.world.World` (or
    an object with its ``storage``, ``grid``, ``M``, ``params``, ``opts``, ``settings``, ``touched``)."""

    def __init__(self, world, settings: EngineSettings | None = None):
        self.world = world
        self.settings = settings or EngineSettings()
        self.fns = engine_functions(world.opts, world.params, self.settings.vehicle_substeps, world.soils)
        # the channel model's outputs, when it was built (World.model is built on first use)
        names = getattr(vars(world).get("model"), "output_names", None)
        if names is not None and tuple(names) != tuple(self.fns.output_names):
            raise SimulationError("the engine's outputs differ from the channel model's")
        self.output_names = self.fns.output_names
        self.state = EngineState(world, self.settings, self.fns)
        lib = library(self.fns, self.settings.compiled)
        self.kernel = CKernel(lib, self.state) if lib is not None else PyKernel(self.fns, self.state)
        self.compiled = self.kernel.compiled
        self.timing = {"kernel_s": 0.0, "kernel_cpu_s": 0.0, "calls": 0}

    # -- errors ---------------------------------------------------------------------------------------------
    def _raise(self, code: int, e) -> None:
        s = self.state
        g = s.grid

        def ij(cell):
            return tuple(int(v) for v in divmod(int(cell), g.shape[1]))
        if code == ERR_FIELD:
            x0, x1 = g.origin_m[0], g.origin_m[0] + g.shape[0] * g.cell_m
            y0, y1 = g.origin_m[1], g.origin_m[1] + g.shape[1] * g.cell_m
            raise SimulationError(
                f"the vehicle left the terrain field: a track's contact around ({e.err_x[0]:.2f}, {e.err_x[1]:.2f}) m "
                f"is outside x in [{x0:g}, {x1:g}] m, y in [{y0:g}, {y1:g}] m; enlarge terrain.size_m "
                "or move terrain.origin_m")
        if code == ERR_COLLISION:
            held = s.ch_cell[s.ch_cell >= 0]
            new = s.new_list[:int(e.n_new)]
            cells = np.unique(np.concatenate([held, new, [e.err_a, e.err_b]]).astype(np.int64))
            i, j = np.divmod(cells, g.shape[1])
            need = int(max(np.ptp(i), np.ptp(j))) + 1
            raise SimulationError(
                f"channel collision: cells {ij(e.err_a)} and {ij(e.err_b)} (i, j) are both active and both map to "
                f"channel {int(e.err_ch)} with M = {s.M} (Cell[i, j] -> CHANNEL[i mod M, j mod M]); the active set "
                f"spans {np.ptp(i) + 1} x {np.ptp(j) + 1} cells and needs M >= {need}. "
                "Raise terrain.channels, terrain.max_speed_m_s or terrain.release_time_s")
        if code == ERR_UNCOVERED:
            raise SimulationError(
                f"cell {ij(e.err_a)} came under a track without a channel ({int(e.err_b)} cells): "
                "the footprint prediction missed it; reduce run.output_dt_s")
        if code == ERR_NONFINITE:
            raise SimulationError("the terrain engine's vehicle step returned a non-finite state "
                                  "(raise engine vehicle_substeps)")
        if code == ERR_NEWTON:
            raise SimulationError(f"the implicit stage of cell {ij(e.err_a)} did not converge in "
                                  f"{NEWTON_MAX_ITER} iterations")
        raise SimulationError(f"terrain engine error {code}")

    # -- passes ---------------------------------------------------------------------------------------------
    def release_all(self) -> None:
        s = self.state
        s.ch_cell[:] = -1
        for name in ("ch_z", "ch_v", "ch_p", "ch_zmax", "ch_pmax", "ch_cx", "ch_cy", "ch_zoff", "ch_delta", "ch_dc"):
            getattr(s, name)[:] = 0.0
        s.ch_counted[:] = 0
        s.ch_g[:] = 0.0
        s.n_act = 0
        s.pv[-s.n_sums:] = 0.0

    def begin_pass(self, x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
        """World.begin_pass: the vehicle at rest at the pose, the cells under it settled for
        settle_s with zero torque; returns the vehicle's 12 states."""
        s = self.state
        self.release_all()
        s.peak_active = 0
        s.touched[:] = False
        s.sig_pass[:] = 0.0
        s.wv[:] = 0.0
        s.wv[0], s.wv[1], s.wv[2] = x_m, y_m, yaw_rad
        s.a[:] = np.array(self.fns.vehicle_a(s.wv, s.pv)).ravel()
        # the cells under the vehicle at their static sinkage first (World.begin_pass)
        rc, e = self.kernel.assign(0.0)
        if rc:
            self._raise(abs(rc), e)
        self.kernel.static()
        n = int(round(self.world.settings.settle_s / SETTLE_STEP_S))
        if n:
            T = SETTLE_STEP_S * np.arange(1, n + 1)
            self._call(0.0, T, np.zeros((n, 2)), np.array([0.0, -1.0, 0.0]), False)
        rc, e = self.kernel.assign(0.0)
        if rc:
            self._raise(abs(rc), e)
        return s.wv[:NV].copy()

    def end_pass(self, dt_s: float = SETTLE_STEP_S, max_steps: int = 300) -> None:
        """World.end_pass in the engine: the vehicle lifted off (each active cell's load falls from its
        reaction at the pass end to zero over LIFT_TIME_S), the cells settle until released (or
        max_steps, with a warning), every channel freed; the pass's subsoil maxima folded into the
        terrain's record. The cells are integrated by the engine's own cell step (SDIRK, the exit
        windows' substep count per step): the same as CVODES over the pool to the tolerance tested."""
        w, s = self.world, self.state
        w.z_at_pass_end = w.storage.z.copy()
        w.peak_active = s.peak_active  # the World's figures report it
        if s.n_act:
            n = window_substeps(self.settings)[1]
            rc, settled, e = self.kernel.lift(s.ch_p.copy(), dt_s, LIFT_TIME_S, n, max_steps)
            if rc < 0:
                self._raise(-rc, e)
            if not settled:
                log.warning("%d cells had not unloaded %g s after the vehicle was lifted; their state is stored",
                            s.n_act, max_steps * dt_s)
        self.release_all()
        w.release_all()
        np.maximum(w.storage.sigma_max, w.pass_sigma, out=w.storage.sigma_max)

    def _call(self, t0, T, U, dist, check_covered):
        n = T.size
        T_out, X, Y = np.zeros(n), np.zeros((n, NV)), np.zeros((n, self.state.ny_out))
        T, U = np.ascontiguousarray(T, dtype=float), np.ascontiguousarray(U, dtype=float)
        w0, c0 = time.perf_counter(), time.process_time()
        rc, n_done, e = self.kernel.run(t0, T, U, dist, check_covered, T_out, X, Y)
        self.timing["kernel_s"] += time.perf_counter() - w0
        self.timing["kernel_cpu_s"] += time.process_time() - c0
        self.timing["calls"] += 1
        if rc < 0:
            self._raise(-rc, e)
        return rc == 1, T_out[:n_done], X[:n_done], Y[:n_done]

    def advance(self, t0: float, T: np.ndarray, U: np.ndarray, dist: np.ndarray, check_covered: bool = True):
        """Macro steps from t0 to T[0], T[1], ... with the inputs U[k] (commanded torques) over step k.
        dist = [distance so far, stop distance (< 0: none), time from which it counts] is updated.
        Returns (stopped by distance?, end times, vehicle states, outputs) of the steps done."""
        return self._call(t0, T, U, dist, check_covered)

    def outputs_now(self, u) -> np.ndarray:
        s = self.state
        self.kernel.sums()
        return np.array(self.fns.outputs(s.wv[:NV], u, s.pv)).ravel()

    def sync_world(self) -> np.ndarray:
        """Hand the active channels to the World (channel_cell, Q, p_soil) for World.end_pass; returns
        the channel model's state vector x (vehicle states, then the channels' z, dz/dt)."""
        w, s = self.world, self.state
        w.release_all()
        act = s.active_channels()
        w.channel_cell[act] = s.ch_cell[act]
        w.qc[act, 0], w.qc[act, 1] = s.ch_cx[act], s.ch_cy[act]
        w.qc[act, 2], w.qc[act, 3], w.qc[act, 4] = s.ch_zmax[act], s.ch_pmax[act], 1.0
        w.qc[act, 5], w.qc[act, 6], w.qc[act, 7] = s.ch_zoff[act], s.ch_delta[act], s.ch_dc[act]
        w.counted[act] = s.ch_counted[act] > 0
        w.ch_soil[act] = s.ch_soil[act]
        w.p_soil[act] = s.ch_p[act]
        w.peak_active = s.peak_active
        x = np.zeros(NV + 2 * w.n_channels)
        x[:NV] = s.wv[:NV]
        x[NV::2][act] = s.ch_z[act]
        x[NV + 1::2][act] = s.ch_v[act]
        return x
