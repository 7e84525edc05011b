"""The world manager's per-step work for the IDAS reference path (IDAS, the compiled grid
Rosenbrock, the brute-force runs): :class:`ChannelManager` runs the rules of
symtrack/native/grid_engine.c, their one home, on a :class:`~symtrack.terrain.world.World`'s channel
tables (docs/model.md, "Terrain cells, channels and the world manager"; the rules: the module doc of
:mod:`symtrack.terrain.world`).

Per macro step, :meth:`ChannelManager.before_step` loads the World's channel tables (which cell each
channel holds, its Q entries, its reaction p_soil, the channel states of the DAE's state vector x)
into the engine's state, calls the engine's ``eng_assign`` (footprint at the step's start pose and
at the pose predicted for its end, release, sector assignment with the collision error, INFO_IN)
and writes back what it changed: released channels zeroed, new channels loaded from their cells.
:meth:`ChannelManager.after_step` calls ``eng_info_out`` (INFO_OUT of every active channel: the
storage, the history in Q, p_soil), :meth:`ChannelManager.check_covered` ``eng_uncovered``. The
World owns the tables between calls (the engine's state is scratch here), so a World may pass
between the engine and this path (:meth:`symtrack.integrators.engine.TerrainEngine.sync_world`).

:meth:`ChannelManager.begin_pass` sets the vehicle down (the cells at their static sinkage by the
engine's rule, eng_static_cells, then settled with any integrator of the channel model) and
:meth:`ChannelManager.end_pass` lifts it off by the engine's eng_lift."""

from __future__ import annotations

import logging

import numpy as np

from ...terrain.channels import HIST_ROWS
from ...terrain.world import LIFT_TIME_S, World, zero_in_place
from ..settings import EngineSettings, window_substeps
from .engine import SETTLE_STEP_S, engine_functions
from .kernel import CKernel, library, static_sinkage_cells
from .state import EngineState, EngineStruct, array_address, engine_error

__all__ = ["ChannelManager", "static_sinkage"]

log = logging.getLogger("symtrack.terrain")

# the Q entries of a channel (symtrack.terrain.channels: NF per channel) and the engine's arrays
QC_COLUMNS = ((0, "ch_cx"), (1, "ch_cy"), (2, "ch_zmax"), (3, "ch_pmax"), (5, "ch_zoff"), (6, "ch_delta"), (7, "ch_dc"))


def static_sinkage(opts, params: dict, z0, hist, p_load, soils: tuple = (), soil=0) -> np.ndarray:
    """The set-down's rule (grid_engine.c set_down_z, the engine's) on cells given by their values, for a
    caller without a World (the brute-force reference): the sinkage at which each cell's reaction equals
    its load, p(z; hist) = p_load, bracketed from z0 and bisected on the monotone law to 1e-15 m.
    ``z0`` (k,), ``hist`` (5, k) (z_max, p_max, z_off, delta, d_c), ``p_load`` (k,); ``soils``: a soil
    map's parameter dicts (default: ``params``'s soil alone), ``soil`` each cell's index in them."""
    fns = engine_functions(opts, params, 1, soils)
    lib = library(fns)
    law = np.ascontiguousarray(fns.law_table(tuple(soils) or (params,)))
    work = np.zeros(max(f.sz_w() for f in fns.all()) + 1)
    iwork = np.zeros(1, dtype=np.int64)
    e = EngineStruct()
    e.soil_law, e.work, e.iwork = array_address(law), array_address(work), array_address(iwork)
    return static_sinkage_cells(lib, e, z0, hist, soil, p_load)


class ChannelManager:
    """The world manager's rules (grid_engine.c) on ``world``'s channel tables (module doc)."""

    def __init__(self, world: World):
        self.world = world
        self.fns = engine_functions(world.opts, world.params, 1, world.soils)
        self.state = EngineState(world, EngineSettings(), self.fns)
        self.kernel = CKernel(library(self.fns), self.state)
        self._soil_maps: dict = {}

    def _soil_map(self, k: int):
        """The channel model's soil law mapped over k channels (built once per count)."""
        if k not in self._soil_maps:
            self._soil_maps[k] = self.world.terrain.fn["soil"].map(k)
        return self._soil_maps[k]

    def _load(self, x: np.ndarray) -> np.ndarray:
        """The World's channel tables and the channel states of x into the engine's state; returns
        the active channels."""
        w, s = self.world, self.state
        s.soil_index = w.storage.soil_index  # (a storage may have been replaced)
        s.ch_cell[:] = w.channel_cell
        L = w.layout
        s.ch_z[:] = x[L.cell_field("sinkage")]
        s.ch_v[:] = x[L.cell_field("rate")]
        s.ch_p[:] = w.p_soil
        for col, name in QC_COLUMNS:
            getattr(s, name)[:] = w.qc[:, col]
        s.ch_counted[:] = w.counted
        s.ch_soil[:] = w.ch_soil
        act = np.nonzero(w.channel_cell >= 0)[0]
        s.act[:act.size] = act
        s.n_act = act.size
        return act

    # ---- per macro step ----------------------------------------------------------------------
    def before_step(self, x: np.ndarray, dt: float, stepper=None):
        """Assign channels for the step from x over dt; returns (x with INFO_IN loaded, p)."""
        w, s = self.world, self.state
        x = np.array(x, dtype=float)
        self._load(x)
        L = w.layout
        head = L.indices(("x_m", "y_m", "yaw_rad", "u_m_s", "v_m_s", "yaw_rate_rad_s"))
        s.wv[head] = x[head]  # the pose and the body velocities: the footprint at the start and the predicted end
        rc, e = self.kernel.assign(dt)
        if rc:
            raise engine_error(abs(rc), e, s)
        changed = s.ch_cell != w.channel_cell
        rel = np.nonzero(changed & (w.channel_cell >= 0))[0]  # released (and maybe taken by a new cell)
        if rel.size:
            w.channel_cell[rel] = -1
            w.qc[rel] = 0.0
            w.p_soil[rel] = 0.0
            x[L.cell_index(rel, "sinkage")] = 0.0
            x[L.cell_index(rel, "rate")] = 0.0
        new = np.nonzero(changed & (s.ch_cell >= 0))[0]
        if new.size:
            w.channel_cell[new] = s.ch_cell[new]
            for col, name in QC_COLUMNS:
                w.qc[new, col] = getattr(s, name)[new]
            w.qc[new, 4] = 1.0
            w.ch_soil[new] = s.ch_soil[new]
            w.counted[new] = False
            w.p_soil[new] = s.ch_p[new]
            x[L.cell_index(new, "sinkage")] = s.ch_z[new]
            x[L.cell_index(new, "rate")] = s.ch_v[new]
            if stepper is not None:
                stepper.reset()
        w.peak_active = max(w.peak_active, int(s.n_act))
        return x, w.param_vector()

    def after_step(self, x: np.ndarray) -> None:
        """INFO_OUT: write every active channel's state and history back to its cell."""
        w, s = self.world, self.state
        x = np.asarray(x, dtype=float)
        act = self._load(x)
        if act.size:  # the reaction of the integrated model's law (the channel model's), on the step's history
            z_act = x[w.layout.cell_index(act, "sinkage")]
            s.ch_p[act] = np.array(self._soil_map(act.size)(
                z_act[None, :], w.qc[act][:, HIST_ROWS].T, w.laws[:, w.ch_soil[act]])).ravel()
        self.kernel.info_out_all()
        w.qc[act, 2] = s.ch_zmax[act]
        w.qc[act, 3] = s.ch_pmax[act]
        w.qc[act, 7] = s.ch_dc[act]
        w.p_soil[act] = s.ch_p[act]
        w.counted[act] = s.ch_counted[act] > 0

    def check_covered(self, x: np.ndarray) -> None:
        """Every cell that the tracks load at state x holds a channel (else the prediction missed)."""
        s = self.state
        s.ch_cell[:] = self.world.channel_cell
        n, e = self.kernel.uncovered(*x[self.world.layout.pose_index])
        if n:
            raise engine_error(e.err_code, e, s)

    def track_corners(self, X: float, Y: float, psi: float) -> list[np.ndarray]:
        """The corners (4, 2) of each track's contact rectangle at the pose in world coordinates, left
        then right: the rectangles of the engine's footprint (grid_engine.c eng_track_rects, unpadded)."""
        out = []
        for cx, cy, c, s, hl, hw in self.kernel.track_rects(X, Y, psi, 0.0):
            loc = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
            out.append(np.column_stack([cx + c * loc[:, 0] - s * loc[:, 1], cy + s * loc[:, 0] + c * loc[:, 1]]))
        return out

    # ---- passes ------------------------------------------------------------------------------
    def begin_pass(self, stepper, x_m: float, y_m: float, yaw_rad: float, dt_s: float = 0.01) -> np.ndarray:
        """The vehicle at rest at the pose with the cells under it settled: the initial state.
        ``stepper``: any integrator of the world's model (``step(x, u, p, dt)``, ``reset()``)."""
        w = self.world
        w.release_all()
        w.peak_active = 0
        w.touched[:] = False
        zero_in_place(w.pass_sigma)  # only the pages the last pass wrote (terrain/world.py)
        zero_in_place(w.pass_p_mean)
        stepper.reset()
        L = w.layout
        x = np.zeros(L.size)
        x[L.pose_index] = x_m, y_m, yaw_rad
        u = np.zeros(2)
        # the cells under the vehicle at their static sinkage first (set down quasi-statically: a
        # sudden load would overshoot it by some 10 % and write the overshoot into the history)
        x, p = self.before_step(x, 0.0, stepper)
        act = np.nonzero(w.channel_cell >= 0)[0]
        if act.size:
            acc = np.array(w.model.ode(x, u, p)).ravel()[L.cell_field("rate")][act]
            zc, vc = x[L.cell_field("sinkage")][act], x[L.cell_field("rate")][act]
            hist = w.qc[act][:, HIST_ROWS].T
            p_soil = np.array(w.terrain.fn["soil"].map(act.size)(
                zc[None, :], hist, w.laws[:, w.ch_soil[act]])).ravel()
            p_load = w.params["cell_areal_mass_kg_per_m2"] * acc + p_soil + w.params[
                "cell_damping_Pa_s_per_m"] * vc
            x[L.cell_index(act, "sinkage")] = self.kernel.static_sinkage(zc, hist, w.ch_soil[act], p_load)
            x[L.cell_index(act, "rate")] = 0.0
            stepper.reset()
        n = int(round(w.settings.settle_s / dt_s))
        for _ in range(n):
            x, p = self.before_step(x, dt_s, stepper)
            x = stepper.step(x, u, p, dt_s)
            self.after_step(x)
        cs = L.block("cells")
        x[cs] = np.where(np.repeat(w.channel_cell >= 0, L.cell_width), x[cs], 0.0)
        x, _ = self.before_step(x, 0.0, stepper)
        stepper.reset()
        return x

    def end_pass(self, x: np.ndarray, dt_s: float = SETTLE_STEP_S, max_steps: int = 300) -> None:
        """Lift the vehicle off by the engine's rule (grid_engine.c eng_lift, as
        :meth:`TerrainEngine.end_pass`): each active cell's load falls linearly from its reaction pressure
        at the end of the pass to zero over LIFT_TIME_S (quasi-statically: a sudden removal would fling
        the underdamped cells above their unloaded rest, as no tension holds them back), the cells alone
        by the engine's cell step (SDIRK, the exit windows' substeps), INFO_OUT after every step, until
        every active cell has let go of the track and come to rest; all channels are then freed. Cells
        that have not come to rest within max_steps keep their (stored) state and a warning says so."""
        w, s = self.world, self.state
        self.after_step(x)
        w.z_at_pass_end = w.storage.z.copy()  # the terrain with the vehicle still on it
        act = self._load(x)
        if act.size:
            self.kernel.slopes()  # dp/dz at the pass end: the cells' first stage starts from it
            n = window_substeps(s.settings)[1]
            rc, settled, e = self.kernel.lift(w.p_soil.copy(), dt_s, LIFT_TIME_S, n, max_steps)
            if rc < 0:
                raise engine_error(-rc, e, s)
            if not settled:
                log.warning("%d cells had not unloaded %g s after the vehicle was lifted; their state is stored",
                            act.size, max_steps * dt_s)
        w.release_all()
        w.fold_pass()
