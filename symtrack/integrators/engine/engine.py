"""The terrain engine (:class:`TerrainEngine`): the passes, the macro-step calls and the public
methods the plant (:class:`symtrack.simulation.plants.EnginePlant`) drives it by; the package doc
(:mod:`symtrack.integrators.engine`) gives the scheme."""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable

import numpy as np

from ...foundations import caches
from ...foundations.errors import ScenarioError, SimulationError
from ...model import SystemModel
from ...model.static import static_state
from ...native.grid_engine_model import build_engine_functions
from ...terrain import query
from ...terrain.world import LIFT_TIME_S
from ...vehicles import registry as vehicle_registry
from ...vehicles.base import CONTACT_HULL
from ..settings import EngineSettings, window_substeps
from .kernel import CKernel, library
from .state import EngineState, engine_error

__all__ = ["SETTLE_STEP_S", "TerrainEngine", "engine_functions"]

log = logging.getLogger("symtrack.terrain")

SETTLE_STEP_S = 0.01  # the settling steps of World.begin_pass
# the engine state's scalars besides its arrays (EngineState), and its scratch arrays (not saved)
STATE_SCALARS = ("n_act", "peak_active", "stamp")
STATE_SCRATCH = ("work", "agrid", "new_list", "geo")
STORAGE_ARRAYS = ("z", "zdot", "zmax", "pmax", "phase", "zoff", "cycles", "sigma_max")

_FUNCTIONS = caches.cache("engine_functions", 8)  # symtrack.foundations.caches


def engine_functions(opts, params: dict, vehicle_substeps: int, soils: tuple = (), surface=None):
    """build_engine_functions, cached per (options, substeps, a soil map or not, the 3D vehicle's ground)
    in this process; ``soils``: the parameter dicts of a soil map's soils (index 0 the scenario's);
    ``surface``: the ground's shape under the 3D vehicle (analytic; None: flat). The soils' values are
    not part of the Functions (the engine's law table takes them at run time: EngineState.soil_law),
    only whether there are several (the channel sums then carry the soil under each track)."""
    soils = tuple(soils) or (params,)
    ground = None if surface is None or surface.is_flat else surface._coefficients()
    raster = getattr(surface, "raster", None)
    if raster is not None:  # the raster's heights and place are part of the ground
        ground = (ground, hashlib.sha256(np.ascontiguousarray(raster.values, dtype=np.float64).tobytes()).hexdigest(),
                  raster.values.shape, tuple(raster.origin_m or ()), float(raster.pixel_m))
    key = (opts, vehicle_substeps, len(soils) > 1, ground)
    return _FUNCTIONS.get_or_build(key, lambda: build_engine_functions(
        opts, params, vehicle_substeps, soils if len(soils) > 1 else (), surface))


class TerrainEngine:
    """Vehicle + grid terrain (package doc). ``world``: a :class:`~symtrack.terrain.world.World` (or
    an object with its ``storage``, ``grid``, ``M``, ``params``, ``opts``, ``settings``, ``touched``).
    ``kernel``: ``(functions, state) -> kernel``, the kernel that runs the steps (default: the
    compiled :class:`~.kernel.CKernel`; the tests pass their interpreted oracle)."""

    def __init__(self, world, settings: EngineSettings | None = None, kernel: Callable | None = None):
        self.world = world
        self.settings = settings or EngineSettings()
        vehicle = vehicle_registry.for_options(world.opts, surface=getattr(world, "surface", None))
        if vehicle.contact == CONTACT_HULL and getattr(world, "surface", None) is None and \
                getattr(world.storage, "elevation", None) is not None:
            raise ScenarioError("the terrain continued has an elevation of its own and the scenario no "
                                "[terrain.surface]: the 3D vehicle's ground is the surface's (the cells keep only "
                                "their heights at their centres); give the [terrain.surface] that made the terrain "
                                "(it is checked against the terrain's elevation), or model.vehicle = 'planar'")
        self.fns = engine_functions(world.opts, world.params, self.settings.vehicle_substeps, world.soils,
                                    getattr(world, "surface", None))
        # the channel model's outputs, when it was built (World.model is built on first use)
        names = getattr(vars(world).get("model"), "output_names", None)
        if names is not None and tuple(names) != tuple(self.fns.output_names):
            raise SimulationError("the engine's outputs differ from the channel model's")
        self.output_names = self.fns.output_names
        self.state = EngineState(world, self.settings, self.fns)
        self.kernel = CKernel(library(self.fns), self.state) if kernel is None else kernel(self.fns, self.state)
        self.compiled = self.kernel.compiled
        self.timing = {"kernel_s": 0.0, "calls": 0}
        self._hull_model = None  # the 3D vehicle's homogeneous model of its start (_hull_start)

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
        s.p_pass[:] = 0.0
        s.wv[:] = 0.0
        s.wv[self.fns.layout.pose_index] = x_m, y_m, yaw_rad
        if self.fns.n_seg:  # the 3D hull: first at rest on the virgin ground (then settled on the cells below)
            s.wv[self.fns.layout.block("vehicle")] = self._hull_start(x_m, y_m, yaw_rad)
        s.a[:] = np.array(self.fns.vehicle_a(s.wv, s.pv)).ravel()
        # the cells under the vehicle at their static sinkage first (World.begin_pass)
        rc, e = self.kernel.assign(0.0)
        if rc:
            raise engine_error(abs(rc), e, s)
        self.kernel.static()
        n = int(round(self.world.settings.settle_s / SETTLE_STEP_S))
        if n:
            T = SETTLE_STEP_S * np.arange(1, n + 1)
            self._call(0.0, T, np.zeros((n, 2)), np.array([0.0, -1.0, 0.0]), False)
        rc, e = self.kernel.assign(0.0)
        if rc:
            raise engine_error(abs(rc), e, s)
        return s.wv[self.fns.layout.block("vehicle")].copy()

    def _hull_start(self, x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
        """The 3D vehicle's static state at the pose on homogeneous virgin soil following the ground
        (:func:`symtrack.model.static.static_state`): the hull's start above the cells, which the
        set-down (the cells' static sinkage) and the settling then bring onto the field as it is
        (on the ruts of an earlier pass, lower)."""
        w = self.world
        if self._hull_model is None:  # built once per engine (every pass starts from it)
            self._hull_model = SystemModel(w.opts, vehicle=vehicle_registry.for_options(
                w.opts, surface=getattr(w, "surface", None)))
        model = self._hull_model
        x = static_state(model, w.params, x_m, y_m, yaw_rad)
        return np.asarray(x, dtype=float)[model.layout.block("vehicle")]

    def end_pass(self, dt_s: float = SETTLE_STEP_S, max_steps: int = 300) -> None:
        """The lift-off (grid_engine.c eng_lift, as the IDAS path's ChannelManager.end_pass): the vehicle
        lifted off (each active cell's load falls from its reaction at the pass end to zero over
        LIFT_TIME_S), the cells settle until released (or
        max_steps, with a warning), every channel freed; the pass's subsoil maxima folded into the
        terrain's record. The cells are integrated by the engine's own cell step (SDIRK, the exit
        windows' substep count per step): the same as CVODES over the pool (the tests' oracle) to the
        tolerance tested."""
        w, s = self.world, self.state
        w.z_at_pass_end = w.storage.z.copy()
        w.peak_active = s.peak_active  # the World's figures report it
        if s.n_act:
            n = window_substeps(self.settings)[1]
            rc, settled, e = self.kernel.lift(s.ch_p.copy(), dt_s, LIFT_TIME_S, n, max_steps)
            if rc < 0:
                raise engine_error(-rc, e, s)
            if not settled:
                log.warning("%d cells had not unloaded %g s after the vehicle was lifted; their state is stored",
                            s.n_act, max_steps * dt_s)
        self.release_all()
        w.release_all()
        w.fold_pass()

    def _call(self, t0, T, U, dist, check_covered):
        n = T.size
        T_out, X, Y = np.zeros(n), np.zeros((n, self.fns.layout.nv)), np.zeros((n, self.state.ny_out))
        T, U = np.ascontiguousarray(T, dtype=float), np.ascontiguousarray(U, dtype=float)
        w0 = time.perf_counter()  # (wall only: the process's CPU clock is a system call at every macro step)
        rc, n_done, e = self.kernel.run(t0, T, U, dist, check_covered, T_out, X, Y)
        self.timing["kernel_s"] += time.perf_counter() - w0
        self.timing["calls"] += 1
        if rc < 0:
            raise engine_error(-rc, e, self.state)
        return rc == 1, T_out[:n_done], X[:n_done], Y[:n_done]

    def advance(self, t0: float, T: np.ndarray, U: np.ndarray, dist: np.ndarray, check_covered: bool = True):
        """Macro steps from t0 to T[0], T[1], ... with the inputs U[k] (commanded torques) over step k.
        dist = [distance so far, stop distance (< 0: none), time from which it counts] is updated.
        Returns (stopped by distance?, end times, vehicle states, outputs) of the steps done."""
        return self._call(t0, T, U, dist, check_covered)

    def outputs_now(self, u) -> np.ndarray:
        s = self.state
        self.kernel.sums()
        return np.array(self.fns.outputs(s.wv[self.fns.layout.block("vehicle")], u, s.pv)).ravel()

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
        L = w.layout
        x = np.zeros(L.size)
        x[L.block("vehicle")] = s.wv[L.block("vehicle")]
        x[L.cell_index(act, "sinkage")] = s.ch_z[act]
        x[L.cell_index(act, "rate")] = s.ch_v[act]
        return x

    # -- the public view of the state (the plant's) ------------------------------------------------------------
    def vehicle_state(self) -> np.ndarray:
        """The vehicle's 12 states now (a copy)."""
        return self.state.wv[self.fns.layout.block("vehicle")].copy()

    def surface(self, x_m, y_m, outside: str = "raise") -> query.SurfaceQuery:
        """The terrain under the points (x_m, y_m) from the engine's storage, by the engine's C
        (symtrack/native/terrain_query.h): the same :class:`~symtrack.terrain.query.SurfaceQuery`,
        rule and numbers as :func:`symtrack.terrain.query.query` on the world's storage."""
        if outside not in query.OUTSIDE_MODES:
            raise SimulationError(f"outside = {outside!r} must be one of {', '.join(query.OUTSIDE_MODES)}")
        x, y = np.broadcast_arrays(np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float))
        n_out, cell, phase, out = self.kernel.surface(x.ravel(), y.ravel())
        if n_out and outside == "raise":
            query.cell_of(self.world.grid, x, y)  # the query's error: the first point outside, the field's extent
        shape = x.shape
        return query.SurfaceQuery(cell.reshape(shape), out[:, 0].reshape(shape), out[:, 1].reshape(shape),
                                  out[:, 2].reshape(shape), out[:, 3:6].reshape(shape + (3,)),
                                  phase.astype(np.int8).reshape(shape), out[:, 6:8].reshape(shape + (2,)))

    def active_cells(self) -> np.ndarray:
        """The flat indices of the cells that hold a channel, in channel order (a copy)."""
        ch = self.state.ch_cell
        return ch[ch >= 0].copy()

    @property
    def stats(self) -> dict:
        """The kernel's counters (Newton iterations, cell stages, vehicle steps; ns_*: the C kernel's
        wall time by part) since :meth:`reset_stats`."""
        return self.state.stats

    def reset_stats(self) -> None:
        for key in self.state.stats:
            self.state.stats[key] = 0

    def set_vehicle_state(self, state, u) -> np.ndarray:
        """Give the vehicle, set down and settled at rest (:meth:`begin_pass`), the 12 states
        ``state`` at the pose it was set down at, with the inputs ``u``: the accelerations of the DAE
        form and the tracks' pressure lines made consistent with it (a vehicle step of length 0),
        the active cells' geometry re-evaluated for those pressure lines, the channel sums
        recomputed. Returns the vehicle's states."""
        xv = np.array(state, dtype=float)
        s, fns = self.state, self.fns
        vs, pose = self.fns.layout.block("vehicle"), self.fns.layout.pose_index
        if xv.shape != (self.fns.layout.nv,):
            raise SimulationError(f"EnginePlant.start: expected the {self.fns.layout.nv} vehicle states, got shape "
                                  f"{xv.shape}")
        if not np.all(np.isfinite(xv)):
            raise SimulationError("EnginePlant.start: the state has non-finite values")
        if np.max(np.abs(xv[pose] - s.wv[pose])) > 1e-9:
            raise SimulationError(f"EnginePlant.start: the state's pose {tuple(xv[pose])} differs from the pose the "
                                  f"vehicle was set down at {tuple(s.wv[pose])}")
        s.wv[vs] = xv
        act = s.active_channels()
        for _ in range(2):  # accelerations <-> pressure lines <-> channel sums: a fixed point, 2 passes
            w1, a1, _ = fns.vehicle_step(s.wv, u, s.pv, 0.0)  # h = 0: the states stay, the algebraic ones settle
            s.wv[vs.stop:] = np.array(w1).ravel()[vs.stop:]  # the accelerations
            s.a[:] = np.array(a1).ravel()
            if act.size:
                G = fns.cell_geo.map(act.size)(np.vstack([s.ch_cx[act], s.ch_cy[act]]), s.a, s.geo)
                s.ch_g[act] = np.array(G).T
            self.kernel.sums()
        return s.wv[vs].copy()

    # -- checkpoints ---------------------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        """The engine's whole state: its arrays and scalars and the World's storage arrays (copies)."""
        s, st = self.state, self.world.storage
        arrays = {k: v.copy() for k, v in vars(s).items() if isinstance(v, np.ndarray) and k not in STATE_SCRATCH}
        return {"state": arrays, "scalars": {k: getattr(s, k) for k in STATE_SCALARS},
                "storage": {k: getattr(st, k).copy() for k in STORAGE_ARRAYS}}

    def restore(self, saved: dict) -> None:
        """Back to a :meth:`checkpoint` (in place: the C kernel and the World share these arrays)."""
        s, st = self.state, self.world.storage
        for k, v in saved["state"].items():
            getattr(s, k)[...] = v
        for k, v in saved["scalars"].items():
            setattr(s, k, v)
        for k, v in saved["storage"].items():
            getattr(st, k)[...] = v
