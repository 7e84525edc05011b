"""The world manager: the cell storage Cell[N, N] and the channel assignment (docs/model.md).

Storage
-------
Seven values per cell, as the INFO_IN / INFO_OUT of the Politecnico di Milano thesis
(docs/model.md): sinkage z [m], sinkage rate dz/dt [m/s], history z_max [m] and p_max [Pa] (float64:
the integrator's values are stored to the last bit, which the bit-exact continuation needs), the
phase flag (int8, see
:data:`~symtrack.terrain.channels.PHASE_VIRGIN`), and the cycle law's z_off [m] (float64) and
load-cycle count (uint16) (symtrack/soil/cell.py), the soil index (uint8, a soil map) and the
subsoil stress record (float32 per depth): 60 bytes per cell with the four default depths, 60 MB
for the default million-cell field. Cell (i, j) has its centre at world (x0 + (i + 1/2) dx, y0 + (j + 1/2) dx).

Per macro step (the rules; their one home is symtrack/native/grid_engine.c)
--------------------------------------------------------------------------
The terrain engine runs them inside its steps; the IDAS reference path runs the same C on this
World's channel tables through :class:`symtrack.integrators.engine.ChannelManager` (``before_step``,
``after_step``, ``check_covered``). This module holds the storage, the channel tables and the
constants of the rules (:func:`padding_m`, :func:`derive_modulus`), not a second copy of them.

1. The footprint: the cells whose centres lie in either track's contact rectangle, padded by
   ``pad = (sqrt(2)/2 + 1/4) dx``, at the pose at the start of the step and at the pose
   predicted for its end (body velocities held over the step). The padding covers every cell
   the channel law can load (its overlap is non-zero when the centre is within dx/2 of the
   rectangle in the track frame) and the prediction error.
2. Release: an active cell is released (its channel freed) only when it is outside the
   footprint, its reaction pressure is exactly 0 (clipped line: the soil has let go of the
   track) and |dz/dt| <= ``release_rate_m_s``. Its state was already written back. All
   other active cells stay active (still unloading).
3. Assignment by the thesis's sector rule, Cell[i, j] -> CHANNEL[i mod M, j mod M], with no search.
   A newly active cell whose channel is held by another active cell stops the run
   (:class:`~symtrack.foundations.errors.SimulationError` naming both cells and the M that the active set
   needs); so does a footprint that leaves the field.
4. INFO_IN: the channel's integrator states are reset to the cell's stored (z, dz/dt), its Q
   entries to the cell's centre and history, with the plastic increment delta its stay may add
   (cell.cycle_increment, from its cycle count); IDAS's algebraic guess is reset too.
5. After the step, INFO_OUT for every active channel: z, dz/dt and the history
   (cell.history_update: z_max, p_max on the loading branch, the stay's plastic progress d_c,
   stored as z_off + d_c; the cycle count + 1 at the stay's first plastic step), phase; written
   to storage and to Q. The
   run also checks that every cell the tracks loaded at the end of the step held a channel.

M ("auto")
----------
All cells active together lie in a rectangle of the body frame W x H with
W = l + 2 pad + v_max (dt + t_release) (the contact length, the padding, the travel over one
step and the unloading tail) and H = B + b + 2 pad (both tracks). In any orientation two
cell centres in it differ by at most D = sqrt(W^2 + H^2) along x and along y, so their indices
differ by at most floor(D / dx) and M = floor(D / dx) + 2 channels per axis keep them apart.
The bound assumes the speed stays below ``max_speed_m_s`` and a cell unloads within
``release_time_s``; if either fails the run stops with the collision error, never silently.

Shear memory: a cell that comes under a track starts with zero shear (Janosi & Hanamoto
measure shear from the front of the contact); cells store no shear, and the vehicle's mean
shear displacement is the vehicle's state.

A pass (``ChannelManager.begin_pass`` / ``end_pass``; the engine's ``begin_pass`` / ``end_pass``):
the vehicle is set down at rest at its start pose on the current terrain, the cells under it
placed at their static sinkage (grid_engine.c's ``eng_static`` and ``eng_static_cells``: a sudden
load would overshoot it and write the overshoot into the history), then they settle for
``settle_s`` with zero torque (the initial static state), the run follows its torque programme to
its stop rule, then the vehicle is lifted off: the active cells unload with zero load until they
are released. Between passes
the storage is the only state, which is why a saved and reloaded terrain continues bit-exactly.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError, ScenarioError
from ..foundations.memory import require_memory
from ..model import SystemModel
from ..model.layout import StateLayout
from ..model.options import ModelOptions
from ..model.parameters import check_set, known_soil_names, model_param_layout, soil_params
from ..soil import density, moisture
from ..vehicles import registry as vehicle_registry
from . import gis
from .channels import NF, NG, ChannelTerrain
from .settings import TerrainSettings
from .soil_map import MAX_SOILS, SoilMap, soil_index
from .storage import Grid, Terrain, file_geometry

__all__ = ["END_STRIP_CELLS", "LIFT_TIME_S", "World", "derive_modulus", "open_world", "padding_m",
           "run_memory_bytes", "world_storage_bytes_per_cell",
           "zero_in_place"]

END_STRIP_CELLS = 2  # the sprocket/idler sinkage averages over a strip of two cells
LIFT_TIME_S = 0.2  # the vehicle is lifted off over this time at the end of a pass
# A scenario's terrain.origin_m agrees with its continued terrain file's within a micrometre: far below
# a cell (at least 1 cm), above the rounding of a coordinate of 1e7 m (2e-9 m in float64)
ORIGIN_TOLERANCE_M = 1e-6


def _soil_map_for_model(settings: TerrainSettings, opts: ModelOptions) -> TerrainSettings:
    """``settings`` with the soils of its soil map as the model's ``[soil]`` table (the presets' values for
    the default model's parameters: a soil law's own coefficients added, with their defaults, and
    another law's left out), unchanged for the default model."""
    sm = settings.soil_map
    if sm is None:
        return settings
    specs, known = soil_params(opts), known_soil_names()
    try:
        soils = tuple(check_set(sp, specs, f"terrain.soil_map.soils[{i}]", known) for i, sp in enumerate(sm.soils))
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    if soils == sm.soils:
        return settings
    return dataclasses.replace(settings, soil_map=dataclasses.replace(sm, soils=soils))


def padding_m(cell_m: float) -> float:
    return (math.sqrt(2) / 2 + 0.25) * cell_m


def derive_modulus(params: dict, settings: TerrainSettings, dt_s: float) -> int:
    """M of the sector rule (module doc): two cells active together never share a channel."""
    dx = settings.cell_m
    pad = padding_m(dx)
    W = params["contact_length_m"] + 2 * pad + settings.max_speed_m_s * (dt_s + settings.release_time_s)
    H = params["track_gauge_m"] + params["track_width_m"] + 2 * pad
    return int(math.floor(math.hypot(W, H) / dx)) + 2


# The memory of a run on the grid terrain beyond what the process holds when its field is made
# (docs/terrain.md, "Memory"): :func:`run_memory_bytes`. Its parts:
# - the field's arrays as they come into memory: a continued field's all of them (read from its file),
#   a new field's subsoil stress record (every pass's end writes all of it) and its elevation; a new
#   field's other arrays are zeros whose pages the kernel maps only where a pass writes them;
# - PASS_BYTES_PER_CELL: the sinkage before and after each pass, kept for the figures (float64 each);
# - RUN_BYTES_PER_CELL: the rest that grows with the field, measured: the engine's records of the pass's
#   stresses as it writes them, the sinkage at the pass's end, the pass figures', the plots' and the
#   terrain file's temporaries;
# - RUN_FIXED_BYTES: what the run loads after the field is made, measured: the engine's functions, the
#   plotting library (imported when the first figure is drawn, after the check) and its figures.
# Measured as the peak resident set of `symtrack simulate` runs on 1e4 to 3e6 cells (new and continued
# fields, one and three passes; tests/test_memory_refusal.py). The process's own memory at the check
# differs between installs of the same packages (51 and 77 MB on 1e4 cells in two virtual environments
# here, the peak after it 83 and 67 MB more): RUN_FIXED_BYTES lies between the two, so that the estimate
# of a small field is within 10 % of its peak in either.
RUN_FIXED_BYTES = 70_000_000
RUN_BYTES_PER_CELL = 55
PASS_BYTES_PER_CELL = 16


def run_memory_bytes(n_cells: int, n_depths: int, passes: int = 1, continued: bool = False,
                     shaped: bool = False) -> int:
    """The memory a run of ``passes`` passes over a field of ``n_cells`` cells with ``n_depths``
    subsoil depths takes beyond what the process holds before the field is made (the comment above):
    a new field, or with ``continued`` one read from a terrain file; ``shaped``: the field has an
    elevation."""
    if continued:
        field = world_storage_bytes_per_cell(n_depths, shaped)
    else:
        field = 4 * n_depths + (8 if shaped else 0)
    return int(RUN_FIXED_BYTES + n_cells * (RUN_BYTES_PER_CELL + field + PASS_BYTES_PER_CELL * passes))


def world_storage_bytes_per_cell(n_depths: int, shaped: bool = False) -> int:
    """The bytes per cell of a terrain's arrays (measured from a one-cell :class:`Terrain`)."""
    one = Terrain(Grid((0.0, 0.0), 1.0, (1, 1)), None, [0.1 * (k + 1) for k in range(n_depths)])
    if shaped:
        one.set_elevation([0.0])
    return one.nbytes


def zero_in_place(a: np.ndarray, block: int = 1 << 16) -> None:
    """Set the contiguous array ``a`` to 0, writing only its blocks that hold a value other than 0: a
    field's arrays start as pages the kernel has not mapped (np.zeros), and a pass writes a few of them;
    writing zeros over the whole array would map every page (the whole field's memory) for nothing."""
    if not a.flags.c_contiguous:
        a[...] = 0
        return
    flat = a.reshape(-1)
    for i in range(0, flat.size, block):
        b = flat[i:i + block]
        if b.any():
            b[...] = 0


# the vehicle + channel pool models built in this process, by the model options and the pool's size
# (symtrack.foundations.caches): a second world of the same vehicle, soil law and channel count (the
# passes of a continued terrain, a run again on its saved field, the channel-per-cell reference) takes
# the first's, as the homogeneous terrain's models are shared (symtrack.simulation.builder.system_model:
# a SystemModel is not changed after its construction). Building one of 512 channels takes seconds.
_CHANNEL_MODELS = caches.cache("channel_models", 2)


def channel_model(opts: ModelOptions, n_channels: int, terrain: ChannelTerrain | None = None) -> SystemModel:
    """The vehicle of ``opts`` with a pool of ``n_channels`` channels as one symbolic system, built
    on the first call for these options and this size (on ``terrain``, a ChannelTerrain of them, if
    given) and then shared."""
    n = int(n_channels)
    return _CHANNEL_MODELS.get_or_build((opts, n), lambda: SystemModel(opts, terrain if terrain is not None
                                                                       else ChannelTerrain(opts, n)))


class World:
    """The world manager for one field and one vehicle (see the module doc)."""

    def __init__(self, settings: TerrainSettings, params: dict, opts: ModelOptions, dt_s: float,
                 start_xy=(0.0, 0.0), modulus: int | None = None, storage: Terrain | None = None):
        self.settings, self.params, self.opts = settings, dict(params), opts
        # the soil parameters of the model (its vehicle's and soil law's declarations and the soil's)
        self.soil_names = tuple(s.name for s in soil_params(opts))
        settings = self.settings = _soil_map_for_model(settings, opts)
        # the estimated peak memory of the process (run_memory_bytes; open_world's, for a terrain file)
        self.memory_estimate_bytes: int | None = None
        if not settings.cell_m < params["track_width_m"]:
            raise ScenarioError(f"terrain.cell_m = {settings.cell_m!r} must be smaller than the track width "
                                f"{params['track_width_m']!r} m (cells resolve the contact patch)")
        if storage is not None:
            self.grid = storage.grid
        else:
            nx, ny = settings.shape
            origin = settings.origin_m
            if origin is None:
                origin = (start_xy[0] - 0.5 * nx * settings.cell_m, start_xy[1] - 0.5 * ny * settings.cell_m)
            self.grid = Grid((float(origin[0]), float(origin[1])), float(settings.cell_m), (nx, ny))
            n, nd = self.grid.n_cells, len(settings.subsoil_depths_m)
            shaped = settings.surface is not None and not settings.surface.is_flat
            self.memory_estimate_bytes = require_memory(
                run_memory_bytes(n, nd, settings.passes, shaped=shaped), f"terrain.size_m = {list(settings.size_m)} "
                f"at terrain.cell_m = {settings.cell_m} ({nx} x {ny} = {n} cells, {nd} subsoil depths, "
                f"terrain.passes = {settings.passes})",
                "raise terrain.cell_m, shrink terrain.size_m or drop terrain.subsoil_depths_m")
        # the soil map's cells first: a raster that misses the field, or a CRS that is not the
        # terrain's, stops here, before the channel pool is built
        sm = settings.soil_map
        self._map_index = None if sm is None else soil_index(self.grid, sm)
        if sm is not None and sm.header is not None and storage is not None and \
                not gis.same_crs(storage.crs_wkt, sm.crs_wkt) and (storage.crs_wkt or storage.soil_index.any()):
            raise ScenarioError(f"terrain.soil_map.raster = {sm.raster!r} is in {gis.crs_label(sm.crs_wkt)}, the "
                                f"terrain continued is in {gis.crs_label(storage.crs_wkt)}: two maps of one field must "
                                "share their CRS (reproject the raster, gdalwarp -t_srs)")
        self.storage = storage if storage is not None else Terrain(self.grid)
        if self.storage.soil_law is None:
            self.storage.soil_law = opts.soil_law
        elif self.storage.soil_law != opts.soil_law:
            raise ScenarioError(f"the terrain's history was made with the soil law {self.storage.soil_law!r}, the "
                                f"scenario has model.soil_law = {opts.soil_law!r}; continue a terrain under the law "
                                "it was made with")
        self.surface = self._apply_surface(settings.surface, storage is not None)
        if self.storage.soil is None:
            self.storage.soil = {k: float(params[k]) for k in self.soil_names}
        self.storage.set_subsoil_depths(settings.subsoil_depths_m)
        # the largest vertical stress of this pass at each subsoil depth, per cell (the terrain
        # engine writes it; end_pass folds it into the storage's record over all passes)
        # (np.zeros, not zeros_like: the kernel maps the pages the engine writes, not the whole field's)
        self.pass_sigma = np.zeros(self.storage.sigma_max.shape, dtype=self.storage.sigma_max.dtype)
        # and of the mean normal stress (the bulk density's; docs/subsoil.md "Bulk density")
        self.pass_p_mean = np.zeros(self.storage.sigma_max.shape, dtype=self.storage.sigma_max.dtype)
        if modulus is None:
            modulus = settings.channels if settings.channels != "auto" else derive_modulus(params, settings, dt_s)
        self.M = int(modulus)
        self.n_channels = self.M * self.M
        self.terrain = ChannelTerrain(opts, self.n_channels)
        n = self.n_channels
        self.channel_cell = np.full(n, -1, dtype=np.int64)
        self.Q = np.zeros(NG + NF * n)
        self.Q[0] = self.grid.cell_m
        self.Q[1] = END_STRIP_CELLS * self.grid.cell_m
        self.qc = self.Q[NG:].reshape(n, NF)  # a view: writes go to Q
        self.p_soil = np.zeros(n)
        self._pbase = np.array(model_param_layout(opts).pack(params))  # SystemModel.param_vector's order
        # each cell's own day parameters (N, lambda, kappa, sigma_pc; None: its soil's): a moisture raster of
        # more distinct values than a soil map holds (symtrack.soil.moisture.cell_day_parameters)
        self.cell_day = None
        # the field's soils (a soil map: docs/terrain.md "Soil maps"; index 0 the scenario's [soil]):
        # their parameter sets, cell laws (5 x n_soils) and cycle-law exponents; each channel's soil
        if settings.moisture is not None:  # each cell's water content (symtrack.soil.moisture)
            if storage is not None:
                raise ScenarioError("terrain.moisture (a moisture raster) applies to a new field; a terrain file "
                                    "keeps the soils it was made with: leave terrain.moisture out to continue it")
            settings = self._split_by_moisture(settings, params)
        self.soils = self._apply_soil_map(settings, params)
        self.laws = np.column_stack([self.terrain.law.values(sp) for sp in self.soils])
        self.betas = np.array([float(sp["repeated_loading_exponent"]) for sp in self.soils])
        self.ch_soil = np.zeros(n, dtype=np.uint8)
        self.counted = np.zeros(n, dtype=bool)  # the channel's stay has counted as a load cycle
        self.peak_active = 0
        self.touched = np.zeros(self.grid.n_cells, dtype=bool)
        self.z_at_pass_end = None

    @functools.cached_property
    def layout(self) -> StateLayout:
        """The state layout of :attr:`model` (the options' vehicle's, then this pool's channels),
        without building the model."""
        return vehicle_registry.for_options(self.opts).layout.with_cells(self.terrain.state_names)

    @functools.cached_property
    def model(self) -> SystemModel:
        """The vehicle with this world's channel pool as one symbolic system (built on first use:
        for 1600 channels it takes seconds, and the compiled terrain engine does not need it)."""
        if len(self.soils) > 1:
            raise ScenarioError("this field has a soil map (several soils): it runs on the terrain engine only "
                                "(run.integrator = \"grid_fast\"); IDAS and the grid Rosenbrock take one soil")
        return channel_model(self.opts, self.n_channels, self.terrain)

    def _apply_surface(self, surface, continued: bool):
        """The ground's shape (symtrack/terrain/surface.py): a new field takes the scenario's
        elevation at its cell centres; a continued terrain keeps its own (the scenario's, if given,
        must give the same heights). Returns the surface placed on the field (None: flat or not given)."""
        st = self.storage
        if surface is None or surface.is_flat:
            if surface is not None and continued and st.elevation is not None:
                raise ScenarioError("the terrain has an elevation of its own, the scenario's [terrain.surface] is "
                                    "flat; leave [terrain.surface] out to continue the terrain's")
            return None
        surface = surface.placed(self.grid)
        z0 = surface.cell_elevation(self.grid)
        if continued:
            if st.elevation is None or not np.array_equal(st.elevation, z0):
                what = "is flat" if st.elevation is None else "has another elevation"
                raise ScenarioError(f"the terrain {what} than the scenario's [terrain.surface] gives; leave "
                                    "[terrain.surface] out to continue the terrain's")
        else:
            st.set_elevation(z0)
        if surface.crs_wkt is not None:
            if st.crs_wkt is not None and not gis.same_crs(st.crs_wkt, surface.crs_wkt):
                raise ScenarioError(f"terrain.surface.elevation_file is in {gis.crs_label(surface.crs_wkt)}, the "
                                    f"terrain in {gis.crs_label(st.crs_wkt)}: the maps of one field must share "
                                    "their CRS (reproject the raster, gdalwarp -t_srs)")
            st.crs_wkt = surface.crs_wkt
        return surface

    def _split_by_moisture(self, settings, params):
        """The field's soils on the day of the moisture raster: each distinct (soil, water content)
        pair a soil of the map (symtrack.soil.moisture.split_soils); the settings with that map. More
        pairs than a map holds: each cell's day parameters in ``cell_day``, the settings unchanged."""
        mm, sm = settings.moisture, settings.soil_map
        water = moisture.read_moisture(self.grid, mm)
        base = [{n: float(params[n]) for n in self.soil_names}] + ([] if sm is None else list(sm.soils))
        labels = ["[soil]"] + ([] if sm is None else list(sm.labels))
        index = self._map_index if self._map_index is not None else np.zeros(self.grid.n_cells, dtype=np.uint8)
        pairs = moisture.distinct_pairs(index, water)
        if len(pairs[0]) > MAX_SOILS - 1:  # per cell: the field's soils stay what they were
            self.cell_day = moisture.cell_day_parameters(base, index, water, mm, pairs)
            return settings
        new_labels, new_soils, self._map_index = moisture.split_soils(base, labels, index, water, mm, MAX_SOILS)
        raw = {} if sm is None else sm.raw
        new = SoilMap(new_labels, new_soils, (), None, raw, None if sm is None else sm.header)
        return dataclasses.replace(settings, soil_map=new)

    def _apply_soil_map(self, settings, params) -> list[dict]:
        """The field's soils: a new field takes the scenario's soil map; a terrain that has one keeps
        it (the scenario's must then be the same). Soils equal to the scenario's [soil] and soils no
        cell has are folded into soil 0, so that a uniform map is the single soil, bit for bit."""
        st = self.storage
        sm = settings.soil_map
        if sm is not None:
            table = [(lab, {k: float(v) for k, v in sp.items()}) for lab, sp in zip(sm.labels, sm.soils, strict=True)]
            idx = self._map_index
            if st.soil_table or st.soil_index.any():
                # the same soil in every cell (compared by the soils' parameters, not their numbering:
                # the terrain's table was folded when it was made)
                ids: dict = {}

                def cell_soils(index, tab):
                    keys = [tuple(float(params[n]) for n in self.soil_names)]
                    keys += [tuple(float(v[n]) for n in self.soil_names) for _, v in tab]
                    return np.array([ids.setdefault(k, len(ids)) for k in keys])[index]

                if not np.array_equal(cell_soils(idx, table), cell_soils(st.soil_index, st.soil_table)):
                    raise ScenarioError("the terrain has a soil map of its own that differs from the scenario's "
                                        "[terrain.soil_map]; leave the soil map out to continue the terrain's")
            else:
                st.soil_index[:] = idx
                st.soil_table = table
            if sm.crs_wkt is not None:
                st.crs_wkt = sm.crs_wkt
        base = {k: float(params[k]) for k in self.soil_names}
        soils, table = [dict(params)], []
        remap = np.zeros(len(st.soil_table) + 1, dtype=np.uint8)
        used = np.bincount(st.soil_index, minlength=len(st.soil_table) + 1) > 0
        for k, (label, sp) in enumerate(st.soil_table, start=1):
            if not used[k] or {n: sp[n] for n in self.soil_names} == base:
                continue
            full = {**params, **{n: sp[n] for n in self.soil_names}}
            for n in ("cell_areal_mass_kg_per_m2", "cell_damping_Pa_s_per_m"):
                if full[n] != float(params[n]):
                    raise ScenarioError(f"terrain.soil_map: soil {k} has {n} = {full[n]!r}, the scenario's soil "
                                        f"{float(params[n])!r}: the cells of one field share their dynamics")
            remap[k] = len(soils)
            soils.append(full)
            table.append((label, sp))
        if st.soil_table:
            st.soil_index[:] = remap[st.soil_index]
            st.soil_table = table
        return soils

    # ---- cells -----------------------------------------------------------------------------------
    def ij(self, cell: int) -> tuple[int, int]:
        return tuple(int(v) for v in divmod(int(cell), self.grid.shape[1]))

    # ---- the parameter vector --------------------------------------------------------------------
    def param_vector(self) -> np.ndarray:
        return np.concatenate([self._pbase, self.Q])

    def active_cells(self) -> np.ndarray:
        return self.channel_cell[self.channel_cell >= 0]

    # ---- passes ------------------------------------------------------------------------------
    def clear(self) -> None:
        """The same field as virgin soil again (a study's next pattern, a benchmark's next run): every
        cell's stored state zero (sinkage, history, stress record, compression state: 0 is the initial
        specific volume) and the pass's records empty; the field's soils (soil_index) and its ground's
        shape are kept."""
        for name, a in self.storage.arrays().items():
            if name != "soil_index":
                zero_in_place(a)
        zero_in_place(self.pass_sigma)
        zero_in_place(self.pass_p_mean)
        self.touched[:] = False

    def release_all(self) -> None:
        self.channel_cell[:] = -1
        self.qc[:] = 0.0
        self.p_soil[:] = 0.0
        self.counted[:] = False

    def fold_pass(self) -> None:
        """At a pass's end: its largest vertical stress into the terrain's record, and the same stress
        plus the soil's own weight into the soil's compression state (the bulk density,
        soil/density.py): the density model and the risk grade one stress against one strength."""
        st = self.storage
        np.maximum(st.sigma_max, self.pass_sigma, out=st.sigma_max)
        cells = np.flatnonzero(self.touched)
        before = st.specific_volume[cells].copy()  # what the earlier passes compressed (kept: density.cap_to_rut)
        density.pass_update(st.specific_volume, self.pass_sigma, st.soil_index, self.soils,
                            cells=cells, cell_params=self.cell_day, geostatic_Pa=self.geostatic_Pa(),
                            depths_m=st.subsoil_depths_m, arrays=self.layer_arrays())
        # the rut bounds the compression below it: one deformation (density.cap_to_rut)
        if st.subsoil_depths_m:
            v0 = self.layer_arrays()["v0"][st.soil_index[cells]]
            density.cap_to_rut(st.specific_volume, cells, v0, st.subsoil_depths_m, st.z[cells], before)

    def layer_arrays(self) -> dict:
        """density.soil_arrays of the field's soils at the subsoil depths ((n_soils, n_depths): each
        depth's layer)."""
        if getattr(self, "_layer_arrays", None) is None:
            self._layer_arrays = density.soil_arrays(self.soils, self.storage.subsoil_depths_m)
        return self._layer_arrays

    def geostatic_Pa(self) -> np.ndarray:
        """(n_soils, n_depths): each soil's own weight at the subsoil depths [Pa] (density.geostatic_table)."""
        if getattr(self, "_geostatic", None) is None:
            self._geostatic = density.geostatic_table(self.soils, self.storage.subsoil_depths_m)
        return self._geostatic

    def bulk_density_max(self) -> list[float]:
        """The field's largest bulk density [Mg/m^3] at each subsoil depth (soil/density.py)."""
        return density.field_max(self.storage.specific_volume, self.storage.soil_index, self.soils,
                                 self.storage.subsoil_depths_m)

    def precompression_stress_Pa(self, cells=None) -> np.ndarray:
        """Each cell's precompression stress at each subsoil depth [Pa], (n_cells, n_depths): its soil's
        layer's (a soil map gives cells different ones; a subsoil layer its own below the topsoil), or,
        in the topsoil, its own on the day of a moisture map of many values; of the cells ``cells``
        (indices) only when given."""
        st = self.storage
        sel = slice(None) if cells is None else cells
        a = self.layer_arrays()
        si = st.soil_index[sel]
        pc = a["pc"][si]
        if self.cell_day is not None:
            pc = np.where(a["top"][si], self.cell_day["precompression_stress_Pa"][sel][:, None], pc)
        return pc

    # ---- figures -----------------------------------------------------------------------------
    def figures(self) -> dict:
        return {
            "terrain_cells": self.grid.n_cells,
            "terrain_cell_m": self.grid.cell_m,
            "terrain_channel_modulus_M": self.M,
            "terrain_channels": self.n_channels,
            "terrain_peak_active_cells": int(self.peak_active),
            "terrain_storage_MB": self.storage.nbytes / 1e6,
            "terrain_cells_touched": int(np.count_nonzero(self.storage.zmax > 0)),
            "terrain_max_sinkage_mm": 1e3 * float(self.storage.z.max()),
            # the memory check's estimate of the process's peak (docs/terrain.md "Memory"; None: not checked)
            "terrain_memory_estimate_MB": None if self.memory_estimate_bytes is None else
            self.memory_estimate_bytes / 1e6,
        }


def open_world(settings: TerrainSettings, params: dict, opts: ModelOptions, dt_s: float, start_xy=(0.0, 0.0),
               terrain: Terrain | str | None = None, where: str = "[terrain]") -> World:
    """The world of a scenario's ``[terrain]`` section, on a new field or on ``terrain`` (a
    :class:`Terrain` or a terrain file path; default: ``settings.initial_state``). A terrain
    brings its geometry: it replaces the section's size_m and cell_m unless the section gave them,
    in which case they must agree. The terrain's soil must be the scenario's."""
    if terrain is None and settings.initial_state:
        terrain = settings.initial_state
    storage = None
    if terrain is not None:
        label = str(terrain) if not isinstance(terrain, Terrain) else "the terrain"
        if isinstance(terrain, Terrain):
            storage = terrain
            if storage.soil is not None:
                for n, v in storage.soil.items():
                    if n in params and float(params[n]) != v:
                        raise ScenarioError(f"{label} was made with soil {n} = {v!r}, the scenario has "
                                            f"{float(params[n])!r}; use the same [soil] to continue a terrain")
        else:
            estimate = _check_file_memory(terrain, settings)  # before the file is read
            storage = Terrain.load(terrain, params)
        g = storage.grid
        cell_differs = "cell_m" in settings.given and abs(g.cell_m - settings.cell_m) > 1e-12
        shape_differs = "size_m" in settings.given and tuple(g.shape) != tuple(settings.shape)
        if cell_differs:
            raise ScenarioError(f"{label}: the terrain file has cells of {g.cell_m} m, the scenario's {where} asks "
                                f"for terrain.cell_m = {settings.cell_m}; make them agree (or leave cell_m out to "
                                "take the file's)")
        origin = settings.origin_m
        if "origin_m" in settings.given and origin is not None and max(
                abs(a - b) for a, b in zip(origin, g.origin_m, strict=True)) > ORIGIN_TOLERANCE_M:
            raise ScenarioError(f"{label}: the terrain file's field starts at origin_m = {list(g.origin_m)}, the "
                                f"scenario's {where} asks for terrain.origin_m = {list(origin)}; make them agree (or "
                                "leave origin_m out to take the file's)")
        if shape_differs:
            raise ScenarioError(
                f"{label}: the terrain file has {g.shape[0]} x {g.shape[1]} cells of {g.cell_m} m, the scenario's "
                f"{where} asks for terrain.size_m = {list(settings.size_m)} ({settings.shape[0]} x "
                f"{settings.shape[1]} cells); make them agree (or leave size_m out to take the file's)")
        settings = dataclasses.replace(settings, cell_m=g.cell_m, size_m=(g.shape[0] * g.cell_m,
                                                                          g.shape[1] * g.cell_m))
    world = World(settings, params, opts, dt_s, start_xy=start_xy, storage=storage)
    if terrain is not None and not isinstance(terrain, Terrain):
        world.memory_estimate_bytes = estimate
    return world


def _check_file_memory(path, settings: TerrainSettings) -> int | None:
    """Refuse a terrain file whose run would not fit in memory, before it is read (its size from the
    file's header); the estimated peak of the process, None when the header cannot be read (loading
    the file then says what is wrong with it)."""
    head = file_geometry(path)
    if head is None:
        return None
    shape, nd, shaped = head
    n = shape[0] * shape[1]
    return require_memory(run_memory_bytes(n, nd, settings.passes, continued=True, shaped=shaped),
                          f"the terrain file {str(path)!r} ({shape[0]} x {shape[1]} = {n} cells, {nd} subsoil "
                          f"depths, terrain.passes = {settings.passes})",
                          "continue it on a machine with more memory (or close other programs)")
