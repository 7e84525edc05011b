"""The terrain engine's state: the channel tables, the vehicle, the constants (numpy arrays), and
the C struct ``eng_t`` of symtrack/native/grid_engine.c that points at them (:class:`EngineStruct`)."""

from __future__ import annotations

import ctypes
import logging
import math

import numpy as np

from ...foundations import caches
from ...foundations.errors import SimulationError
from ...native.grid_engine_model import NGEO, cell_constants, geo_vector, pv_base, track_soil_vector
from ...soil import subsoil
from ...terrain.settings import MAX_SUBSOIL_DEPTHS
from ...terrain.world import END_STRIP_CELLS, padding_m
from ..settings import POWER_MODES, VEHICLE_ATOL, VEHICLE_MAX_HALVINGS, EngineSettings, window_substeps

__all__ = ["ERR_COLLISION", "ERR_FIELD", "ERR_NEWTON", "ERR_NONFINITE", "ERR_UNCOVERED", "EngineState",
           "EngineStruct", "NEWTON_ACCEPT_STEP", "NEWTON_MAX_ITER", "SDIRK_GAMMA", "array_address", "engine_error",
           "mean_stress_tables", "subsoil_tables", "vehicle_work_sizes"]

ERR_FIELD, ERR_COLLISION, ERR_UNCOVERED, ERR_NONFINITE, ERR_NEWTON = 1, 2, 3, 4, 5
SDIRK_GAMMA = 1.0 - 1.0 / math.sqrt(2.0)  # Alexander (1977): L-stable two-stage SDIRK
NEWTON_MAX_ITER = 100
# a Newton step inside the bracket below this fraction of |Z| is the stage's last (grid_engine.c
# NEWTON_ACCEPT): the result is then within about its square (1e-8) of the root, as the law is
# smooth there; at a kink of the law between the iterate and the root, within this fraction
# (docs/terrain.md, "The terrain engine")
NEWTON_ACCEPT_STEP = 1e-4
_TABLES = caches.cache("subsoil_tables", 16)  # symtrack.foundations.caches
log = logging.getLogger("symtrack.terrain")


class EngineStruct(ctypes.Structure):
    """grid_engine.c's eng_t, field by field (the arrays as addresses)."""

    _fields_ = ([(n, ctypes.c_longlong) for n in ("nx", "ny", "M", "n_ch")]
                + [(n, ctypes.c_double) for n in ("x0", "y0", "dx")]
                + [(n, ctypes.c_void_p) for n in ("z", "zdot", "zmax", "pmax", "phase", "touched",
                                                  "ch_cell", "ch_foot", "ch_new_stamp", "ch_new_cell",
                                                  "ch_z", "ch_v", "ch_zmax", "ch_pmax", "ch_p", "ch_cx", "ch_cy",
                                                  "ch_g", "ch_dp", "ch_pw", "ch_vr", "ch_new", "act", "new_list")]
                + [(n, ctypes.c_longlong) for n in ("n_act", "n_new", "peak_active", "stamp")]
                + [(n, ctypes.c_void_p) for n in ("pv", "geo", "wv", "a", "work", "agrid")]
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
                + [(n, ctypes.c_void_p) for n in ("soil_index", "ch_soil", "soil_veh", "soil_law")]
                + [("n_sums", ctypes.c_longlong), ("exit_substeps", ctypes.c_longlong),
                   ("agrid_entry", ctypes.c_void_p), ("steady_euler", ctypes.c_longlong),
                   ("ring_tol", ctypes.c_double), ("elev", ctypes.c_void_p), ("subsoil_p", ctypes.c_void_p),
                   ("p_pass", ctypes.c_void_p), ("vehicle_rtol", ctypes.c_double),
                   ("vehicle_atol", ctypes.c_double), ("vehicle_max_halvings", ctypes.c_longlong),
                   ("n_vehicle_halved", ctypes.c_longlong), ("iwork", ctypes.c_void_p)])


def vehicle_work_sizes(fns) -> tuple[int, int, int]:
    """(arg, res, integer work) sizes of the vehicle's Functions as engine.c calls them (eng_vehicle_step,
    eng_outputs: ENG_SZ_ARG, ENG_SZ_RES, eng_t.iwork); more than their inputs and outputs when they hold
    call nodes (an elevation raster's interpolant under the 3D vehicle)."""
    vf = (fns.vehicle_step, fns.outputs)
    return (max(4, *(f.sz_arg() for f in vf)), max(3, *(f.sz_res() for f in vf)), max(1, *(f.sz_iw() for f in vf)))


def array_address(a: np.ndarray) -> int:
    """The address of a C-contiguous array's data (without building a ctypes object)."""
    if not a.flags.c_contiguous:
        raise SimulationError("the engine's arrays must be C-contiguous")
    return a.__array_interface__["data"][0]



def engine_error(code: int, e, state) -> SimulationError:
    """The :class:`SimulationError` of grid_engine.c's error ``code`` (its struct ``e``: err_a, err_b,
    err_ch, err_x, n_new) on ``state`` (an :class:`EngineState`): the field, the channel collision
    (the two cells, the channel and the M the active set needs), a loaded cell without a channel, a
    non-finite vehicle step, a cell stage that did not converge."""
    s = state
    g = s.grid

    def ij(cell):
        return tuple(int(v) for v in divmod(int(cell), g.shape[1]))
    if code == ERR_FIELD:
        x0, x1 = g.origin_m[0], g.origin_m[0] + g.shape[0] * g.cell_m
        y0, y1 = g.origin_m[1], g.origin_m[1] + g.shape[1] * g.cell_m
        return SimulationError(
            f"the vehicle left the terrain field: a track's contact around ({e.err_x[0]:.2f}, {e.err_x[1]:.2f}) m "
            f"is outside x in [{x0:g}, {x1:g}] m, y in [{y0:g}, {y1:g}] m; enlarge terrain.size_m "
            "or move terrain.origin_m")
    if code == ERR_COLLISION:
        held = s.ch_cell[s.ch_cell >= 0]
        new = s.new_list[:int(e.n_new)]
        cells = np.unique(np.concatenate([held, new, [e.err_a, e.err_b]]).astype(np.int64))
        i, j = np.divmod(cells, g.shape[1])
        need = int(max(np.ptp(i), np.ptp(j))) + 1
        return SimulationError(
            f"channel collision: cells {ij(e.err_a)} and {ij(e.err_b)} (i, j) are both active and both map to "
            f"channel {int(e.err_ch)} with M = {s.M} (Cell[i, j] -> CHANNEL[i mod M, j mod M]); the active set "
            f"spans {np.ptp(i) + 1} x {np.ptp(j) + 1} cells and needs M >= {need}. "
            "Raise terrain.channels, terrain.max_speed_m_s or terrain.release_time_s")
    if code == ERR_UNCOVERED:
        return SimulationError(
            f"cell {ij(e.err_a)} came under a track without a channel ({int(e.err_b)} cells): "
            "the footprint prediction missed it; reduce run.output_dt_s")
    if code == ERR_NONFINITE:
        return SimulationError("the terrain engine's vehicle step returned a non-finite state "
                               "(raise engine vehicle_substeps)")
    if code == ERR_NEWTON:
        return SimulationError(f"the implicit stage of cell {ij(e.err_a)} did not converge in "
                               f"{NEWTON_MAX_ITER} iterations")
    return SimulationError(f"terrain engine error {code}")


def mean_stress_tables(params: dict, depths_m) -> subsoil.SubsoilTables | None:
    """The mean normal stress tables (subsoil.build_mean_stress_tables) at the depths, cached like
    :func:`subsoil_tables`; None for no depths, or (with a warning, once per soil) for a
    concentration factor below subsoil.MEAN_STRESS_XI_MIN, where they do not exist: no bulk density."""
    if not depths_m:
        return None
    key = ("mean", tuple(depths_m), float(params["stress_concentration_factor"]), float(params["contact_length_m"]),
           float(params["track_width_m"]), float(params["track_gauge_m"]))
    def build():
        if key[2] < subsoil.MEAN_STRESS_XI_MIN:
            log.warning("stress_concentration_factor = %g: the mean normal stress needs >= %g (docs/subsoil.md, "
                        "'Bulk density'); no bulk density is computed", key[2], subsoil.MEAN_STRESS_XI_MIN)
            return None
        return subsoil.build_mean_stress_tables(key[1], key[2], key[3], key[4], key[5])
    return _TABLES.get_or_build(key, build)


def subsoil_tables(params: dict, depths_m) -> subsoil.SubsoilTables | None:
    """The subsoil stress tables of the vehicle's tracks and the soil's concentration factor at the
    depths (None for no depths), cached per (geometry, xi, depths) in this process."""
    if not depths_m:
        return None
    key = (tuple(depths_m), float(params["stress_concentration_factor"]), float(params["contact_length_m"]),
           float(params["track_width_m"]), float(params["track_gauge_m"]))
    return _TABLES.get_or_build(key, lambda: subsoil.build_tables(key[0], key[1], key[2], key[3], key[4]))


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
        self.pv = np.array(pv_base(fns.param_layout, world.params, g.cell_m, strip) + [0.0] * self.n_sums)
        # the soil map: each channel's soil, per soil what the traction uses
        self.soil_index = world.storage.soil_index
        self.ch_soil = np.zeros(n, dtype=np.uint8)
        self.soil_veh = np.array(track_soil_vector(world.soils))
        # per soil its law row (the cell Functions' input law: the soils' values at run time)
        self.soil_law = np.ascontiguousarray(fns.law_table(world.soils))
        self.geo = np.array(geo_vector(world.params, g.cell_m, strip))
        self.wv = np.zeros(fns.nw)
        self.a = np.zeros(fns.na)
        self.work = np.zeros(max(f.sz_w() for f in fns.all()) + 1)
        # the vehicle's Functions' integer work (an elevation raster's interpolant: vehicle_work_sizes)
        self.iwork = np.zeros(vehicle_work_sizes(fns)[2], dtype=np.int64)
        n_entry, n_exit = window_substeps(settings)
        self.agrid, self.agrid_entry = np.zeros(fns.na * (n_exit + 1)), np.zeros(fns.na * (n_entry + 1))
        self.pad = padding_m(g.cell_m)
        self.release_rate = float(world.settings.release_rate_m_s)
        self.areal_mass, self.damping = cell_constants(world.params)
        self.settings = settings
        self.ny_out = len(fns.output_names)
        # ns_*: the C kernel's parts (0: interpreted); n_vehicle_halved: the vehicle steps its error control halved
        self.stats = {"n_newton": 0, "n_cell_stages": 0, "n_vehicle_steps": 0, "n_vehicle_halved": 0, "ns_manager": 0,
                      "ns_vehicle": 0, "ns_cells": 0, "ns_outputs": 0, "ns_subsoil": 0}
        # the subsoil stress (docs/subsoil.md): tables for the vehicle and soil, this pass's maxima
        self.sig_pass = world.pass_sigma
        self._addresses = None  # struct(): the arrays and their addresses
        self.subsoil = subsoil_tables(world.params, world.storage.subsoil_depths_m)
        self._subsoil_c = self.subsoil.c_struct() if self.subsoil is not None else None
        # the mean normal stress at the depths (this pass's maxima into p_pass): nothing uses it (the bulk
        # density and the risk take the vertical stress and the soil's own weight: docs/subsoil.md "One
        # soil"), so the kernel leaves it out unless asked (the bench's density rows,
        # symtrack.bench.laws.density_rows, measure what it costs)
        self.p_pass = world.pass_p_mean
        self._world_for_tables = world
        self.subsoil_p = None
        self._subsoil_p_c = None
        self._compute_mean_stress = False

    @property
    def compute_mean_stress(self) -> bool:
        """Whether the kernel records the mean normal stress at the depths (``p_pass``; off by default:
        nothing uses it). Switched on, the tables are built (once) and both kernels fill ``p_pass``."""
        return self._compute_mean_stress

    @compute_mean_stress.setter
    def compute_mean_stress(self, on: bool) -> None:
        self._compute_mean_stress = bool(on)
        if on and self.subsoil_p is None and self.subsoil is not None:
            w = self._world_for_tables
            self.subsoil_p = mean_stress_tables(w.params, w.storage.subsoil_depths_m)
            self._subsoil_p_c = self.subsoil_p.c_struct() if self.subsoil_p is not None else None

    def struct(self) -> EngineStruct:
        g, st, s = self.grid, self.storage, self.settings
        e = EngineStruct()
        e.nx, e.ny, e.M, e.n_ch = g.shape[0], g.shape[1], self.M, self.n_ch
        e.x0, e.y0, e.dx = g.origin_m[0], g.origin_m[1], g.cell_m
        arrays = [("z", st.z), ("zdot", st.zdot), ("zmax", st.zmax), ("pmax", st.pmax), ("phase", st.phase),
                  ("touched", self.touched), ("zoff", st.zoff), ("cycles", st.cycles), ("sig_pass", self.sig_pass),
                  ("soil_index", self.soil_index), ("p_pass", self.p_pass)]
        arrays += [(name, getattr(self, name)) for name in (
            "ch_cell", "ch_foot", "ch_new_stamp", "ch_new_cell", "ch_z", "ch_v", "ch_zmax", "ch_pmax", "ch_p", "ch_cx",
            "ch_cy", "ch_g", "ch_dp", "ch_pw", "ch_vr", "ch_new", "act", "new_list", "pv", "geo", "wv", "a", "work",
            "agrid", "agrid_entry", "ch_zoff", "ch_delta", "ch_dc", "ch_counted", "ch_soil",
            "soil_veh", "soil_law", "iwork")]
        # the addresses, taken again only when an array was replaced (a call runs 100 macro steps:
        # ctypes' data_as for the 43 arrays was a few percent of a call)
        cached = self._addresses
        if cached is None or len(cached[0]) != len(arrays) or any(
                a is not b for (_, a), b in zip(arrays, cached[0], strict=True)):
            cached = self._addresses = ([a for _, a in arrays], [array_address(a) for _, a in arrays])
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
        e.vehicle_rtol, e.vehicle_atol, e.vehicle_max_halvings = float(s.vehicle_tolerance), VEHICLE_ATOL, \
            VEHICLE_MAX_HALVINGS
        for k, v in self.stats.items():
            setattr(e, k, v)
        e.n_depths = self.sig_pass.shape[1] if self.subsoil is not None else 0
        if e.n_depths > MAX_SUBSOIL_DEPTHS:  # subsoil.h's SUBSOIL_MAX_DEPTHS (the scenario's limit)
            raise SimulationError(f"{e.n_depths} subsoil depths: the engine takes at most {MAX_SUBSOIL_DEPTHS}")
        e.subsoil = ctypes.addressof(self._subsoil_c) if self._subsoil_c is not None else None
        e.subsoil_p = (ctypes.addressof(self._subsoil_p_c) if self._subsoil_p_c is not None and self.subsoil is not None
                       and self.compute_mean_stress else None)
        e.n_sums = self.n_sums
        el = st.elevation  # None: a flat field (NULL); read by eng_surface only
        e.elev = None if el is None else array_address(el)
        return e

    def absorb(self, e: EngineStruct) -> None:
        """The scalar fields the C kernel changed."""
        self.n_act, self.peak_active, self.stamp = int(e.n_act), int(e.peak_active), int(e.stamp)
        for k in self.stats:
            self.stats[k] = int(getattr(e, k))

    def active_channels(self) -> np.ndarray:
        return self.act[:self.n_act]
