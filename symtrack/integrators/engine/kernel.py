"""The compiled kernel of the terrain engine: symtrack/native/grid_engine.c with the CasADi-generated
C of :mod:`symtrack.native.grid_engine_model`, built through the package's compile-and-cache API
(``<cache>/engine-<hash>/``) and called through ctypes on the :class:`~.state.EngineState` arrays.

The engine needs a C compiler: without one :func:`library` raises a
:class:`~symtrack.foundations.errors.SimulationError` that says what to install. (The same
algorithm in Python, on CasADi's interpreter, is the tests' oracle: tests/engine_oracle.py.)"""

from __future__ import annotations

import ctypes
import logging
import tempfile
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np

from ...foundations.errors import SimulationError
from ...native.grid_engine_model import soil_dispatch_c
from ...toolchain import BuildSpec, build, casadi_tag, compiler, digest, native_cflags
from .state import EngineState, EngineStruct, vehicle_work_sizes

__all__ = ["BUILD_VERSION", "CKernel", "NO_COMPILER", "check_no_work", "check_struct", "dptr", "library",
           "static_sinkage_cells"]

log = logging.getLogger("symtrack.terrain")

BUILD_VERSION = 1
NO_COMPILER = ("the terrain engine (run.integrator = \"grid_fast\") is compiled C and no C compiler was found "
               "(looked for $CC, cc, gcc): install one (e.g. apt-get install gcc, or set CC), or run the grid "
               "terrain with run.integrator = \"idas\"")


def check_no_work(fns):
    """Raise when a Function needs integer work or extra arguments (engine.c passes neither to the
    cells' Functions)."""
    for f in fns:
        if f.sz_iw() or f.sz_arg() != f.n_in() or f.sz_res() != f.n_out():
            raise SimulationError(f"{f.name()} needs integer work or extra arguments; engine.c passes neither")


# grid_engine.c's field types (eng_field_type) -> the ctypes type the binding must give them (every
# pointer an address)
_C_SCALARS = {"double": ctypes.c_double, "long long": ctypes.c_longlong}


def _ctype_of(c_type: str):
    """The ctypes type of an eng_t field of C type ``c_type`` ("double", "long long", a pointer, "double[2]")."""
    base, _, n = c_type.partition("[")
    base = base.strip()
    t = ctypes.c_void_p if base.endswith("*") else _C_SCALARS.get(base)
    if t is None:
        return None
    return t * int(n.rstrip("]")) if n else t  # (ctypes makes one class per element type and length)


def check_struct(lib, struct=EngineStruct) -> None:
    """Compare the ctypes binding ``struct`` with the eng_t that ``lib`` was compiled with (the table the
    library exports: eng_struct_size, eng_field_count, eng_field_name, eng_field_type, eng_field_offset,
    eng_field_size): field by field the name, the type, the offset and the size, then the struct's size.
    A :class:`SimulationError` naming the first field that differs."""
    for name, res in (("eng_struct_size", ctypes.c_longlong), ("eng_field_count", ctypes.c_longlong),
                      ("eng_field_offset", ctypes.c_longlong), ("eng_field_size", ctypes.c_longlong),
                      ("eng_field_name", ctypes.c_char_p), ("eng_field_type", ctypes.c_char_p)):
        getattr(lib, name).restype = res
        getattr(lib, name).argtypes = [] if name in ("eng_struct_size", "eng_field_count") else [ctypes.c_longlong]
    py = struct._fields_
    n_c = int(lib.eng_field_count())
    for i in range(max(n_c, len(py))):
        if i >= n_c:
            raise SimulationError(f"the engine's ctypes binding {struct.__name__} has field {py[i][0]!r} (number {i}) "
                                  f"that grid_engine.c's eng_t does not have ({n_c} fields)")
        c_name, c_type = lib.eng_field_name(i).decode(), lib.eng_field_type(i).decode()
        c_off, c_size = int(lib.eng_field_offset(i)), int(lib.eng_field_size(i))
        where = f"grid_engine.c's eng_t: {c_name!r}, {c_type}, offset {c_off}, {c_size} bytes"
        if i >= len(py):
            raise SimulationError(f"the engine's ctypes binding {struct.__name__} lacks field {i} of {where}")
        name, t = py[i][0], py[i][1]
        d = getattr(struct, name)
        if name != c_name or t is not _ctype_of(c_type) or d.offset != c_off or d.size != c_size:
            raise SimulationError(f"the engine's ctypes binding {struct.__name__} differs from grid_engine.c at field "
                                  f"{i}: binding {name!r}, {t.__name__}, offset {d.offset}, {d.size} bytes; {where}")
    if ctypes.sizeof(struct) != int(lib.eng_struct_size()):
        raise SimulationError(f"the engine's ctypes binding {struct.__name__} is {ctypes.sizeof(struct)} bytes, "
                              f"grid_engine.c's eng_t {int(lib.eng_struct_size())}")


def library(fns):
    """The loaded engine library (ctypes.CDLL) for these Functions (compiled into the cache on first
    use); a :class:`SimulationError` naming what to install when there is no C compiler."""
    cc = compiler()
    if cc is None:
        raise SimulationError(NO_COMPILER)
    check_no_work((fns.cell_geo, *fns.cell_law, fns.cell_history, fns.cell_entry))
    csrc = resources.files("symtrack.native").joinpath("grid_engine.c").read_bytes()
    hsrc = resources.files("symtrack.native").joinpath("subsoil.h").read_bytes()
    qsrc = resources.files("symtrack.native").joinpath("terrain_query.h").read_bytes()
    dstop = resources.files("symtrack.native").joinpath("distance_stop.h").read_bytes()
    dsrc = soil_dispatch_c(fns, vehicle_work_sizes(fns)).encode()
    flags, target = native_cflags(cc)
    key = digest(fns.serial_digest, csrc, hsrc, qsrc, dstop, dsrc, casadi_tag(BUILD_VERSION), target)

    def sources():
        with tempfile.TemporaryDirectory(prefix="symtrack-enginegen-") as scratch:
            cg = ca.CodeGenerator("engine_gen.c", {"with_header": False})
            for f in fns.all():
                cg.add(f)
            cg.generate(str(Path(scratch)) + "/")
            gen = (Path(scratch) / "engine_gen.c").read_bytes()
        if b"#error" in gen:
            raise SimulationError("the generated engine functions are not exportable (#error in engine_gen.c)")
        return {"engine.c": csrc, "engine_gen.inc": gen, "subsoil.h": hsrc, "terrain_query.h": qsrc,
                "distance_stop.h": dstop,
                "engine_soils.inc": dsrc}

    so = build(BuildSpec(kind="engine", key=key, output="libsymtrack_engine.so", sources=sources,
                         what="the terrain engine", cflags=flags, tuned=True), cc)
    lib = ctypes.CDLL(str(so))
    check_struct(lib)
    P = ctypes.POINTER(EngineStruct)
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
    lib.eng_track_rects.argtypes = [P, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, dp]
    lib.eng_track_rects.restype = None
    lib.eng_slopes.argtypes = [P]
    lib.eng_slopes.restype = None
    vp = ctypes.c_void_p
    lib.eng_static_cells.argtypes = [P, ctypes.c_longlong, vp, vp, vp, vp, vp]
    lib.eng_static_cells.restype = None
    lib.eng_info_out.argtypes = [P]
    lib.eng_info_out.restype = None
    lib.eng_uncovered.argtypes = [P, ctypes.c_double, ctypes.c_double, ctypes.c_double]
    lib.eng_uncovered.restype = ctypes.c_longlong
    lib.eng_surface.argtypes = [P, vp, vp, ctypes.c_longlong, vp, vp, vp]
    lib.eng_surface.restype = ctypes.c_longlong
    return lib


def static_sinkage_cells(lib, e: EngineStruct, z0, hist, soil, p_load) -> np.ndarray:
    """``lib``'s eng_static_cells on the struct ``e`` (only its law table and work vectors are read):
    :meth:`CKernel.static_sinkage`'s rule for callers without an engine state."""
    z0 = np.ascontiguousarray(z0, dtype=float).ravel()
    k = z0.size
    hist = np.ascontiguousarray(np.asarray(hist, dtype=float).reshape(5, k).T)
    soil = np.ascontiguousarray(np.broadcast_to(np.asarray(soil, dtype=np.uint8), (k,)))
    p_load = np.ascontiguousarray(np.broadcast_to(np.asarray(p_load, dtype=float), (k,)))
    z = np.empty(k)
    if k:
        lib.eng_static_cells(ctypes.byref(e), k, z0.ctypes.data, hist.ctypes.data, soil.ctypes.data,
                             p_load.ctypes.data, z.ctypes.data)
    return z


def dptr(a: np.ndarray):
    """A ctypes double pointer to a float64 array's data."""
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class CKernel:
    """engine.c through ctypes (the arrays are shared; the struct's scalars are copied in and out)."""

    compiled = True

    def __init__(self, lib, state: EngineState):
        self.lib, self.s = lib, state

    def assign(self, h: float) -> tuple[int, EngineStruct]:
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
        rc = self.lib.eng_run(ctypes.byref(e), T.size, float(t0), dptr(T), dptr(U), dptr(dist),
                              int(bool(check_covered)), dptr(T_out), dptr(X), dptr(Y), ctypes.byref(n_done))
        self.s.absorb(e)
        return rc, int(n_done.value), e

    def static(self) -> None:
        e = self.s.struct()
        self.lib.eng_static(ctypes.byref(e))

    def static_sinkage(self, z0, hist, soil, p_load) -> np.ndarray:
        """The set-down's rule (grid_engine.c set_down_z) on cells given by their values: z0 (k,), hist
        (5, k) (z_max, p_max, z_off, delta, d_c), soil (k,) (rows of the engine's law table), p_load (k,)
        -> the sinkage (k,) at which each cell's reaction equals its load."""
        return static_sinkage_cells(self.lib, self.s.struct(), z0, hist, soil, p_load)

    def info_out_all(self) -> None:
        """INFO_OUT of every active channel at its state (the IDAS reference path's after_step)."""
        e = self.s.struct()
        self.lib.eng_info_out(ctypes.byref(e))
        self.s.absorb(e)

    def uncovered(self, X: float, Y: float, psi: float) -> tuple[int, EngineStruct]:
        """The number of cells the tracks load at the pose that hold no channel (and the struct: err_a
        the first)."""
        e = self.s.struct()
        n = self.lib.eng_uncovered(ctypes.byref(e), float(X), float(Y), float(psi))
        return int(n), e

    def surface(self, x: np.ndarray, y: np.ndarray) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """The terrain query (terrain_query.h) at the points (x, y) on the engine's storage: (points
        outside, cell, phase, the (n, 8) rows elevation, sinkage, height, normal x, y, z, gradient x, y)."""
        x = np.ascontiguousarray(x, dtype=float)
        y = np.ascontiguousarray(y, dtype=float)
        n = x.size
        cell, phase, out = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.intc), np.zeros((n, 8))
        e = self.s.struct()
        outside = self.lib.eng_surface(ctypes.byref(e), x.ctypes.data, y.ctypes.data, n, cell.ctypes.data,
                                       phase.ctypes.data, out.ctypes.data)
        return int(outside), cell, phase, out

    def track_rects(self, X: float, Y: float, psi: float, pad: float) -> np.ndarray:
        """Each track's contact rectangle at the pose grown by pad (eng_track_rects, the rectangles the
        footprint scan visits): (2, 6) rows (centre x, centre y, cos psi, sin psi, half length, half
        width), left then right."""
        out = np.zeros((2, 6))
        e = self.s.struct()
        self.lib.eng_track_rects(ctypes.byref(e), float(X), float(Y), float(psi), float(pad), dptr(out))
        return out

    def slopes(self) -> None:
        """dp/dz of every active channel at its state into ch_dp (eng_slopes)."""
        e = self.s.struct()
        self.lib.eng_slopes(ctypes.byref(e))

    def lift(self, p_end, h, T, n, max_steps):
        e = self.s.struct()
        settled = ctypes.c_int(0)
        rc = self.lib.eng_lift(ctypes.byref(e), dptr(p_end), float(h), float(T), int(n), int(max_steps),
                               ctypes.byref(settled))
        self.s.absorb(e)
        return int(rc), bool(settled.value), e
