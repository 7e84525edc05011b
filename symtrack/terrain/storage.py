"""The field's cell storage (:class:`Grid`, :class:`Terrain`) and terrain files: the whole cell
storage in one ``.npz`` file, written atomically.

Schema (``TERRAIN_SCHEMA_VERSION`` = 6), one NumPy array per key:

- ``kind``: the string "symtrack-terrain"; ``schema_version``: int;
- ``origin_m`` (2,) float64: world (x, y) of the field's lower-left corner; ``cell_m`` float64;
  ``shape`` (2,) int64: cells along x and y. Cell (i, j) has its centre at
  origin + ((i + 1/2) cell_m, (j + 1/2) cell_m);
- ``z_m``, ``z_rate_m_s``, ``z_max_m``, ``p_max_Pa`` float64 (nx, ny) and ``phase`` int8 (nx, ny):
  every cell's five stored values (phase 0 untouched, 1 loading, 2 unloading/reloading);
- ``z_off_m`` float64 (nx, ny) and ``load_cycles`` uint16 (nx, ny) (schema 2): the cycle law's
  plastic sinkage of the cell's later load cycles and the number of load cycles it has seen
  (symtrack/soil/cell.py). A schema-1 file loads with z_off = 0 and the count inferred from its
  phase: 1 for a loaded cell (phase 1 or 2), 0 for an untouched one;
- ``subsoil_depths_m`` float64 (n_depths,) and ``sigma_max_Pa`` float32 (nx, ny, n_depths)
  (schema 2, optional): the largest vertical stress each cell's soil has carried at each depth
  over all passes (symtrack/soil/subsoil.py; float32: a stress to 7 digits);
- ``specific_volume`` float32 (nx, ny, n_depths) (schema 4, with ``subsoil_depths_m``): the soil's
  compression state at each depth, the specific volume v1 of its current recompression line at a
  mean normal stress of 1 kPa (symtrack/soil/density.py; the bulk density after the loads so far
  is rho_s / v1), 0 where the soil is still in its initial state (v1 = rho_s / rho_initial of the
  cell's soil; from schema 5, of the soil's layer at that depth: a soil whose ``subsoil_*`` values
  differ from its topsoil's has its own initial density, lines and strength below ``subsoil_top_m``,
  symtrack/soil/pedotransfer.py). A file of schema 1 to 3 loads with every cell in its initial state;
- ``soil_index`` uint8 (nx, ny) (schema 2): each cell's soil, 0 the soil of ``soil_values``,
  k >= 1 row k - 1 of ``soil_map_values`` (float64 (n, len(soil_map_names))) with its label in
  ``soil_map_labels`` (a soil map: symtrack/terrain/soil_map.py; absent when the field has one soil);
- ``soil_names`` (str array) and ``soil_values`` float64: the soil parameters the history
  was made with, each by its name (the layout of the model's ``[soil]`` table:
  :func:`symtrack.model.parameters.soil_params`). Loading a file into a scenario with a different
  soil is an error;
- ``soil_law`` str (schema 6): the soil law the history was made with (``model.soil_law``, whose
  coefficients are among ``soil_names`` and whose history the cells hold); continuing the file under
  another law is an error. A file before schema 6 was made with ``"bekker_wong"``, the one law then;
- ``crs_wkt`` (str, optional): the coordinate reference system of the field's x, y (WKT), when
  it came from a georeferenced raster (symtrack/terrain/gis.py); absent for local coordinates.
- ``file_id`` str (schema 3): this file's own id (32 hexadecimal digits, new at every write);
- ``history_json`` str (schema 3): the runs that produced the file, oldest first, a JSON list of
  objects ``{"run_id", "time_utc", "scenario", "scenario_sha256", "passes", "input_file_id"}``:
  the run's id (also in its summary.json as ``terrain_run_id``), when it wrote the file (ISO 8601,
  UTC), the scenario's name and the SHA-256 of its resolved TOML, the passes it ran, and the
  ``file_id`` of the terrain file it started from (null for a new field). A file written twice by
  ``--terrain-in F --terrain-out F`` lists both runs, the second's ``input_file_id`` the first's
  file. A schema-1 or -2 file loads with an empty history and no file id.
- ``elevation_m`` float64 (nx, ny) (schema 4, optional): the initial elevation z0 of each cell's
  centre, metres (the ground's shape: symtrack/terrain/surface.py); the ground under a track is
  z0 minus the cell's sinkage z. Absent for a flat field (and in files of schema 1 to 3, which
  load as flat). float64, not float32: a DEM's absolute heights (hundreds of metres) in float32
  keep 0.03 to 0.1 mm, the order of the elastic rebound the ruts' next pass rides on.
- The soil parameters added since a file was written (a soil map's ``soil_map_names`` too) take
  the registry's defaults (symtrack/model/parameters.py) on loading, or are derived from the file's
  soil description (the compression lines and strength; a file before schema 5 has soils of one
  layer: its subsoil values are its topsoil's).

Values are stored bit for bit, compressed (zip deflate): the default field of a million cells,
mostly untouched, takes well under its 76 MB in memory (76 bytes per cell: 5 float64, the int8
phase, the uint16 cycle count, the uint8 soil index, and 4 float32 subsoil stresses and 4 float32
specific volumes at the default depths).
"""

from __future__ import annotations

import json
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, npz_bytes, real_path
from ..model.parameters import (
    DERIVED_SOIL_PARAM_NAMES,
    SOIL_DAY_PARAM_NAMES,
    SOIL_PARAM_NAMES,
    known_soil_names,
    spec,
)
from ..soil import law as soil_law
from ..soil.pedotransfer import derive_soil, precompression_from_virgin_line_kPa

__all__ = ["HISTORY_KEYS", "KIND", "STORAGE_FIELDS", "TERRAIN_SCHEMA_VERSION", "Grid", "Terrain", "file_bytes",
           "file_geometry", "file_identity", "load", "save", "soil_layout"]

STORAGE_FIELDS = ("z_m", "z_rate_m_s", "z_max_m", "p_max_Pa", "phase", "z_off_m", "load_cycles")
STORAGE_ATTRS = ("z", "zdot", "zmax", "pmax", "phase", "zoff", "cycles")  # the Terrain's attributes of them
SCHEMA1_FIELDS = STORAGE_FIELDS[:5]

TERRAIN_SCHEMA_VERSION = 6
READABLE_SCHEMAS = (1, 2, 3, 4, 5, 6)
HISTORY_KEYS = ("run_id", "time_utc", "scenario", "scenario_sha256", "passes", "input_file_id")
KIND = "symtrack-terrain"

# The bounds of a terrain file's values: :func:`load` refuses a file beyond them with a message naming
# the array (a damaged file, or one symtrack did not write: never a field's state). Each with its reason.
# |z_m|, z_max_m, z_off_m at most 10 m: no tracked machine sinks deeper than its hull (under 2 m for any
# of them) nor heaves the soil higher; 10 m leaves room for every vehicle and keeps out -1e6 m.
SINKAGE_LIMIT_M = 10.0
# z_m <= z_max_m + z_off_m: a cell's sinkage never exceeds the deepest point of its loading plus the
# plastic sinkage of its later cycles (symtrack/soil/cell.py); the margin, a micrometre, is far above
# the rounding of float64 metres (1e-16 m at 1 m) and far below a rut (millimetres).
SINKAGE_ORDER_TOLERANCE_M = 1e-6
# p_max_Pa in [0, 100 MPa]: a pressure the soil carried; 100 MPa is a strong rock's compressive
# strength, some 500 times the ground pressure of the heaviest tracked machines (20-200 kPa).
PRESSURE_LIMIT_PA = 1e8
# load_cycles at most 10 000: a cell under a headland sees some 50 passes a year, so 10 000 load
# cycles are two centuries of them; the terrain engine's counter stops at 65535 (grid_engine.c), the
# mark of a wrapped or uninitialised count, not of a field.
LOAD_CYCLES_LIMIT = 10_000


@dataclass(frozen=True)
class Grid:
    origin_m: tuple[float, float]
    cell_m: float
    shape: tuple[int, int]

    @property
    def n_cells(self) -> int:
        return self.shape[0] * self.shape[1]

    def centres(self, i, j):
        return (self.origin_m[0] + (np.asarray(i) + 0.5) * self.cell_m,
                self.origin_m[1] + (np.asarray(j) + 0.5) * self.cell_m)

    def bounds(self):
        x0, y0 = self.origin_m
        return x0, x0 + self.shape[0] * self.cell_m, y0, y0 + self.shape[1] * self.cell_m


class Terrain:
    """The field's state, Cell[N, N]: seven values per cell (module doc), flat arrays indexed by
    i * ny + j, and the soil parameters the history was made with (None for a new field until a
    world with a soil writes into it).

    ``Terrain.load(path)`` reads a terrain file, :meth:`save` writes one; :meth:`arrays` gives
    the storage arrays by their file names (views: writing into them changes the terrain)."""

    def __init__(self, grid: Grid, soil: dict | None = None, subsoil_depths_m=()):
        n = grid.n_cells
        self.grid = grid
        self.soil = None if soil is None else {str(k): float(v) for k, v in soil.items()}
        # the soil law the history is of (model.soil_law; None for a new field until a world writes into it)
        self.soil_law: str | None = None
        self.z = np.zeros(n)
        self.zdot = np.zeros(n)
        self.zmax = np.zeros(n)
        self.pmax = np.zeros(n)
        self.phase = np.zeros(n, dtype=np.int8)
        self.zoff = np.zeros(n)
        self.cycles = np.zeros(n, dtype=np.uint16)
        self.subsoil_depths_m = tuple(float(d) for d in subsoil_depths_m)
        self.sigma_max = np.zeros((n, len(self.subsoil_depths_m)), dtype=np.float32)
        # the compression state per depth (module doc: specific_volume; 0 the soil's initial state)
        self.specific_volume = np.zeros((n, len(self.subsoil_depths_m)), dtype=np.float32)
        self.soil_index = np.zeros(n, dtype=np.uint8)
        self.soil_table: list[tuple[str, dict]] = []  # soils 1, 2, ... of a soil map: (label, parameters)
        self.crs_wkt: str | None = None  # the CRS of x, y (WKT), from a georeferenced soil map
        self.file_id: str | None = None  # the id of the terrain file this terrain was last read from or written to
        self.history: list[dict] = []  # the runs that produced it (module doc: history_json)
        # the initial elevation z0 of each cell centre [m], float64 (symtrack/terrain/surface.py); None: flat
        self.elevation: np.ndarray | None = None

    def __repr__(self) -> str:
        g = self.grid
        loaded = int(np.count_nonzero(self.phase))
        return (f"<Terrain {g.shape[0]} x {g.shape[1]} cells of {g.cell_m} m from {g.origin_m}, {loaded} loaded, "
                f"z max {1000 * float(self.z.max(initial=0.0)):.2f} mm, {self._history_text()}>")

    def _history_text(self) -> str:
        """What the history holds: the runs saved with the terrain's file (a run that was not saved
        with it is not in it)."""
        if self.file_id is None:
            return "not saved yet (a run enters the history when the terrain is saved with it)"
        return f"{len(self.history)} saved run(s) in the history of its file"

    def _all(self):
        return (self.z, self.zdot, self.zmax, self.pmax, self.phase, self.zoff, self.cycles)

    @property
    def nbytes(self) -> int:
        extra = 0 if self.elevation is None else self.elevation.nbytes
        return (sum(a.nbytes for a in self._all()) + self.sigma_max.nbytes + self.specific_volume.nbytes
                + self.soil_index.nbytes + extra)

    def set_elevation(self, elevation_m) -> None:
        """The field's initial elevation per cell (flat i * ny + j, float64), or None for flat."""
        if elevation_m is None:
            self.elevation = None
            return
        e = np.ascontiguousarray(elevation_m, dtype=np.float64).ravel()
        if e.size != self.grid.n_cells or not np.all(np.isfinite(e)):
            raise ScenarioError(f"the terrain's elevation must be {self.grid.n_cells} finite heights in m, got "
                                f"{e.size} ({int(np.count_nonzero(~np.isfinite(e)))} not finite)")
        self.elevation = e

    def surface_m(self) -> np.ndarray:
        """The ground now, per cell (flat): elevation minus sinkage (``-z`` on a flat field)."""
        return (0.0 if self.elevation is None else self.elevation) - self.z

    def arrays(self) -> dict:
        out = dict(zip(STORAGE_FIELDS, self._all(), strict=True))
        out["sigma_max_Pa"] = self.sigma_max
        out["specific_volume"] = self.specific_volume
        out["soil_index"] = self.soil_index
        return out

    def set_subsoil_depths(self, depths_m) -> None:
        """Use these depths for the stress field: a terrain without stress takes them; one that has
        recorded stress at other depths is an error (its record would not mean the same)."""
        depths = tuple(float(d) for d in depths_m)
        if depths == self.subsoil_depths_m:
            return
        if (self.sigma_max.size and np.any(self.sigma_max > 0)) or np.any(self.specific_volume > 0):
            raise ScenarioError(f"the terrain recorded subsoil stress at depths {list(self.subsoil_depths_m)} m, the "
                                f"scenario asks for terrain.subsoil_depths_m = {list(depths)}; use the same depths "
                                "to continue a terrain")
        self.subsoil_depths_m = depths
        self.sigma_max = np.zeros((self.grid.n_cells, len(depths)), dtype=np.float32)
        self.specific_volume = np.zeros((self.grid.n_cells, len(depths)), dtype=np.float32)

    def copy_z(self):
        """The sinkage as an (nx, ny) array (a copy)."""
        return self.z.reshape(self.grid.shape).copy()

    def save(self, path, soil: dict | None = None, run: dict | None = None) -> None:
        """Write the terrain file (schema in the module doc), atomically; ``run`` (the keys of
        :data:`HISTORY_KEYS` but ``input_file_id``) is added to its history. A run's folder and
        its terrain file are written together by :func:`symtrack.reports.run_files.write_folder`."""
        save(path, self, soil, run)

    @classmethod
    def load(cls, path, soil: dict | None = None) -> Terrain:
        """Read a terrain file; with ``soil`` given, check that it is the soil of the file."""
        return load(path, soil)


def save(path, storage: Terrain, soil: dict | None = None, run: dict | None = None) -> None:
    """Write ``storage`` with the soil parameters ``soil`` as a terrain file, atomically
    (:func:`file_bytes`; ``storage`` takes the file's id and history once it is written). Through a
    symbolic link the link's target is replaced, the link stays."""
    data, file_id, history = file_bytes(storage, soil, run)
    atomic_write_bytes(real_path(path), data)
    storage.file_id, storage.history = file_id, history


def file_bytes(storage: Terrain, soil: dict | None = None, run: dict | None = None) -> tuple[bytes, str, list[dict]]:
    """The terrain file of ``storage`` (soil parameters ``soil``, default the terrain's own) with
    ``run`` added to its history: ``(bytes, file id, history)``. ``storage`` is not changed (it
    takes the id and history when the file is in place: :func:`save`)."""
    soil = soil if soil is not None else storage.soil
    if soil is None:
        raise ScenarioError("Terrain.save: the terrain has no soil yet; give soil= (the soil parameters)")
    history = [dict(h) for h in storage.history]
    if run is not None:
        missing = [k for k in HISTORY_KEYS if k != "input_file_id" and k not in run]
        if missing:
            raise ScenarioError(f"Terrain.save: run = {run!r} lacks {', '.join(missing)}")
        history.append({**{k: run[k] for k in HISTORY_KEYS if k != "input_file_id"},
                        "input_file_id": storage.file_id})
    file_id = uuid.uuid4().hex
    g = storage.grid
    arrays = {k: v.reshape(g.shape) for k, v in storage.arrays().items()
              if k not in ("sigma_max_Pa", "specific_volume")}
    names = soil_layout(soil)
    if storage.soil_table:
        map_names = soil_layout(storage.soil_table[0][1])
        arrays["soil_map_labels"] = np.array([lab for lab, _ in storage.soil_table])
        arrays["soil_map_names"] = np.array(map_names)
        arrays["soil_map_values"] = np.array([[float(v[n]) for n in map_names] for _, v in storage.soil_table])
    arrays["sigma_max_Pa"] = storage.sigma_max.reshape(*g.shape, len(storage.subsoil_depths_m))
    arrays["specific_volume"] = storage.specific_volume.reshape(*g.shape, len(storage.subsoil_depths_m))
    arrays["subsoil_depths_m"] = np.array(storage.subsoil_depths_m, dtype=np.float64)
    if storage.crs_wkt is not None:
        arrays["crs_wkt"] = np.array(storage.crs_wkt)
    if storage.elevation is not None:
        arrays["elevation_m"] = storage.elevation.reshape(g.shape)
    data = npz_bytes(
        kind=np.array(KIND), schema_version=np.array(TERRAIN_SCHEMA_VERSION),
        origin_m=np.array(g.origin_m, dtype=np.float64), cell_m=np.array(g.cell_m, dtype=np.float64),
        shape=np.array(g.shape, dtype=np.int64),
        soil_names=np.array(names), soil_values=np.array([float(soil[n]) for n in names]),
        soil_law=np.array(storage.soil_law or soil_law.DEFAULT),
        file_id=np.array(file_id), history_json=np.array(json.dumps(history)), **arrays)
    return data, file_id, history


def file_geometry(path) -> tuple[tuple[int, int], int, bool] | None:
    """A terrain file's ``shape`` (cells along x and y), its number of subsoil depths and whether it has
    an elevation, read from its header without its arrays; None when they cannot be read."""
    try:
        with np.load(Path(path), allow_pickle=False) as f:
            shape = tuple(int(v) for v in f["shape"])
            nd = int(f["subsoil_depths_m"].size) if "subsoil_depths_m" in f.files else 0
            shaped = "elevation_m" in f.files
    except (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile):
        return None
    if len(shape) != 2 or min(shape) < 1:
        return None
    return (shape[0], shape[1]), nd, shaped


def file_identity(path) -> tuple[str | None, list[str]]:
    """The ``file_id`` of the terrain file ``path`` and the run ids of its history, oldest first, read
    without its arrays; ``(None, [])`` for a missing file, one that is no terrain file, or one of
    schema 1 or 2 (no history). The check of a run's commit (symtrack/reports/run_files.py)."""
    try:
        with np.load(Path(path), allow_pickle=False) as f:
            if "file_id" not in f.files or "history_json" not in f.files:
                return None, []
            file_id, history = str(f["file_id"]), json.loads(str(f["history_json"]))
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
        return None, []
    runs = [str(h.get("run_id")) for h in history if isinstance(h, dict)] if isinstance(history, list) else []
    return file_id, runs


def load(path, soil: dict | None = None) -> Terrain:
    """Read a terrain file; with ``soil`` given, check that it is the soil of the file."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"terrain.initial_state = {str(path)!r}: no such terrain file")
    try:
        with np.load(path, allow_pickle=False) as f:
            d = {k: f[k] for k in f.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        what = "truncated or damaged zip archive" if isinstance(err, (zipfile.BadZipFile, EOFError)) else \
            "not a .npz archive"
        raise ScenarioError(f"{path}: not a symtrack terrain file ({what}; a terrain file is the .npz that "
                            "--terrain-out or Terrain.save writes)") from err
    if str(d.get("kind", "")) != KIND:
        raise ScenarioError(f"{path}: not a symtrack terrain file (kind = {d.get('kind')!r})")
    if "schema_version" not in d:
        raise ScenarioError(f"{path}: the terrain file lacks schema_version (truncated, or not written by symtrack)")
    version = int(d["schema_version"])
    if version not in READABLE_SCHEMAS:
        raise ScenarioError(f"{path}: terrain schema_version = {version}, this symtrack reads "
                            f"{', '.join(str(v) for v in READABLE_SCHEMAS)}")
    fields = STORAGE_FIELDS if version >= 2 else SCHEMA1_FIELDS
    missing = [k for k in ("shape", "origin_m", "cell_m", "soil_names", "soil_values", *fields) if k not in d]
    if missing:
        raise ScenarioError(f"{path}: the terrain file lacks {', '.join(missing)} "
                            "(truncated, or not written by symtrack)")
    try:
        shape = tuple(int(v) for v in d["shape"])
        grid = Grid(tuple(float(v) for v in d["origin_m"]), float(d["cell_m"]), shape)
        file_soil = {str(n): float(v) for n, v in zip(d["soil_names"], d["soil_values"], strict=True)}
    except (TypeError, ValueError) as err:
        raise ScenarioError(f"{path}: malformed terrain header: {err}") from err
    if len(shape) != 2 or min(shape) < 1 or not (grid.cell_m > 0 and np.all(np.isfinite(grid.origin_m))):
        raise ScenarioError(f"{path}: malformed terrain geometry: shape {shape}, cell_m {grid.cell_m}, "
                            f"origin_m {grid.origin_m}")
    st = Terrain(grid, file_soil)
    if version >= 6:
        if "soil_law" not in d or d["soil_law"].ndim != 0 or d["soil_law"].dtype.kind != "U":
            raise ScenarioError(f"{path}: the terrain file lacks soil_law, one string (schema 6): the file is damaged")
        st.soil_law = str(d["soil_law"])
    else:  # written when Bekker/Wong was the one soil law
        st.soil_law = soil_law.DEFAULT
    for name, attr, arr in zip(STORAGE_FIELDS, STORAGE_ATTRS, st._all(), strict=True):
        if name not in fields:
            continue
        a = d.pop(name)  # the file's array becomes the terrain's (no second copy of the field in memory)
        if a.shape != shape or a.dtype != arr.dtype:
            raise ScenarioError(f"{path}: {name} has shape {a.shape} and type {a.dtype}, "
                                f"expected {shape} and {arr.dtype}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            bad = int(np.count_nonzero(~np.isfinite(a)))
            raise ScenarioError(f"{path}: {name} holds {bad} non-finite value(s) (NaN or inf): the file is damaged")
        setattr(st, attr, np.ascontiguousarray(a).reshape(-1))
    if not np.all((st.phase >= 0) & (st.phase <= 2)):
        raise ScenarioError(f"{path}: phase holds values outside 0, 1, 2: the file is damaged")
    if version >= 2 and "subsoil_depths_m" in d:
        depths = d["subsoil_depths_m"]
        sig = d.get("sigma_max_Pa")
        if depths.ndim != 1 or sig is None or sig.dtype != np.float32 or sig.shape != (*shape, depths.size):
            raise ScenarioError(f"{path}: sigma_max_Pa must be float32 of shape {(*shape, depths.size)} for "
                                f"{depths.size} subsoil depths; the file is damaged")
        if not (np.all(np.isfinite(sig)) and np.all(sig >= 0)):
            raise ScenarioError(f"{path}: sigma_max_Pa holds negative or non-finite values: the file is damaged")
        st.subsoil_depths_m = tuple(float(v) for v in depths)
        st.sigma_max = np.ascontiguousarray(sig).reshape(grid.n_cells, depths.size)
        st.specific_volume = np.zeros(st.sigma_max.shape, dtype=np.float32)
        if version >= 4:
            sv = d.get("specific_volume")
            if sv is None or sv.dtype != np.float32 or sv.shape != (*shape, depths.size):
                raise ScenarioError(f"{path}: specific_volume must be float32 of shape {(*shape, depths.size)} for "
                                    f"{depths.size} subsoil depths (schema 4); the file is damaged")
            if not (np.all(np.isfinite(sv)) and np.all(sv >= 0)):
                raise ScenarioError(f"{path}: specific_volume holds negative or non-finite values: the file is "
                                    "damaged")
            st.specific_volume = np.ascontiguousarray(sv).reshape(grid.n_cells, depths.size)
    if version >= 2 and "soil_index" in d:
        si = d["soil_index"]
        if si.shape != shape or si.dtype != np.uint8:
            raise ScenarioError(f"{path}: soil_index has shape {si.shape} and type {si.dtype}, expected {shape} uint8")
        st.soil_index = np.ascontiguousarray(si).reshape(-1)
        if "soil_map_values" in d:
            names = [str(n) for n in d["soil_map_names"]]
            vals = d["soil_map_values"]
            labels = [str(v) for v in d["soil_map_labels"]]
            if vals.ndim != 2 or vals.shape != (len(labels), len(names)):
                raise ScenarioError(f"{path}: soil_map_values has shape {vals.shape}, expected "
                                    f"({len(labels)}, {len(names)}): the file is damaged")
            # parameters added since the file was written: the registry's defaults (module doc)
            added = {n: float(spec(n).default) for n in SOIL_PARAM_NAMES
                     if n not in names and spec(n).default is not None}
            st.soil_table = [(lab, {**dict(zip(names, (float(x) for x in row), strict=True)), **added})
                             for lab, row in zip(labels, vals, strict=True)]
        if int(st.soil_index.max(initial=0)) > len(st.soil_table):
            raise ScenarioError(f"{path}: soil_index refers to soil {int(st.soil_index.max())}, the file's soil map "
                                f"has {len(st.soil_table)}: the file is damaged")
    if "crs_wkt" in d:
        if d["crs_wkt"].ndim != 0 or d["crs_wkt"].dtype.kind != "U":
            raise ScenarioError(f"{path}: crs_wkt must be one string (a WKT); the file is damaged")
        st.crs_wkt = str(d["crs_wkt"])
    if version >= 4 and "elevation_m" in d:
        el = d["elevation_m"]
        if el.shape != shape or el.dtype != np.float64 or not np.all(np.isfinite(el)):
            raise ScenarioError(f"{path}: elevation_m must be finite float64 of shape {shape}, it is {el.dtype} "
                                f"{el.shape}: the file is damaged")
        st.elevation = np.ascontiguousarray(el).reshape(-1)
    if version >= 3:
        if "file_id" not in d or "history_json" not in d:
            raise ScenarioError(f"{path}: the terrain file lacks file_id or history_json (schema 3): "
                                "the file is damaged")
        try:
            history = json.loads(str(d["history_json"]))
        except ValueError as err:
            raise ScenarioError(f"{path}: history_json is not JSON ({err}): the file is damaged") from err
        if not isinstance(history, list) or not all(isinstance(h, dict) for h in history):
            raise ScenarioError(f"{path}: history_json must be a list of runs: the file is damaged")
        st.file_id, st.history = str(d["file_id"]), history
    if version < 2:
        st.cycles[:] = (st.phase > 0).astype(np.uint16)
    elif not np.all(st.zoff >= 0):
        raise ScenarioError(f"{path}: z_off_m holds negative values: the file is damaged")
    _check_bounds(path, st)
    if soil is not None:
        for n, v in file_soil.items():
            if n in soil and n in SOIL_DAY_PARAM_NAMES:  # the day's (moisture): the scenario's
                st.soil[n] = float(soil[n])
            elif n in soil and float(soil[n]) != float(v):
                raise ScenarioError(f"{path}: the terrain was made with soil {n} = {float(v)!r}, the scenario has "
                                    f"{float(soil[n])!r}; use the same [soil] to continue a terrain")
        # an older file lacks the soil parameters added since: the scenario's complete the set
        st.soil.update({n: float(soil[n]) for n in SOIL_PARAM_NAMES if n not in st.soil and n in soil})
    # the parameters added since the file was written that no scenario gave: the registry's defaults
    st.soil.update({n: float(spec(n).default) for n in SOIL_PARAM_NAMES
                    if n not in st.soil and spec(n).default is not None})
    st.soil.update(_derived_missing(st.soil))
    return st


def soil_layout(soil: dict) -> tuple[str, ...]:
    """The names of the soil parameters of ``soil`` (a soil, or a run's parameters: its vehicle's left out)
    in the order a terrain file records them (:func:`symtrack.model.parameters.known_soil_names`)."""
    return tuple(n for n in known_soil_names() if n in soil)


def _first_bad(st: Terrain, bad: np.ndarray) -> tuple[str, int]:
    """How many cells ``bad`` marks and the first one: ("N cell(s), e.g. cell (i, j)", its flat index)."""
    k = int(np.flatnonzero(bad)[0])
    i, j = divmod(k, st.grid.shape[1])
    return f"{int(np.count_nonzero(bad))} cell(s), e.g. cell ({i}, {j})", k


def _check_bounds(path, st: Terrain) -> None:
    """Refuse the physically impossible values of a terrain file (the bounds above :func:`load`: each
    named with its array, its value and the allowed range)."""
    for name, arr, low in (("z_m", st.z, -SINKAGE_LIMIT_M), ("z_max_m", st.zmax, -SINKAGE_LIMIT_M),
                           ("z_off_m", st.zoff, 0.0)):
        bad = (arr < low) | (arr > SINKAGE_LIMIT_M)
        if bad.any():
            where, k = _first_bad(st, bad)
            raise ScenarioError(f"{path}: {name} = {float(arr[k])!r} m at {where}, outside [{low:g}, "
                                f"{SINKAGE_LIMIT_M:g}] m (no vehicle sinks deeper): the file is damaged")
    bad = st.z > st.zmax + st.zoff + SINKAGE_ORDER_TOLERANCE_M
    if bad.any():
        where, k = _first_bad(st, bad)
        raise ScenarioError(f"{path}: z_max_m = {float(st.zmax[k])!r} m is below z_m = {float(st.z[k])!r} m (z_off_m "
                            f"{float(st.zoff[k])!r} m) at {where}; a cell never sinks below its deepest loading "
                            f"plus its cycles' sinkage (z_m <= z_max_m + z_off_m + {SINKAGE_ORDER_TOLERANCE_M:g} m): "
                            "the file is damaged")
    bad = (st.pmax < 0) | (st.pmax > PRESSURE_LIMIT_PA)
    if bad.any():
        where, k = _first_bad(st, bad)
        raise ScenarioError(f"{path}: p_max_Pa = {float(st.pmax[k])!r} Pa at {where}, outside "
                            f"[0, {PRESSURE_LIMIT_PA:g}] Pa (a pressure the soil carried): the file is damaged")
    bad = st.cycles > LOAD_CYCLES_LIMIT
    if bad.any():
        where, k = _first_bad(st, bad)
        raise ScenarioError(f"{path}: load_cycles = {int(st.cycles[k])} at {where}, above {LOAD_CYCLES_LIMIT} "
                            "(two centuries of headland traffic; 65535 is a saturated or uninitialised counter): "
                            "the file is damaged")


def _derived_missing(soil: dict) -> dict:
    """The derived soil parameters (symtrack/soil/pedotransfer.py) a file written before them lacks:
    derived from its description (the registry's defaults where it has none); the file's own virgin
    line, if it has one, sets the strength."""
    missing = [n for n in DERIVED_SOIL_PARAM_NAMES if n not in soil]
    if not missing:
        return {}
    vals = {**soil, **{n: None for n in missing}}
    if "precompression_stress_Pa" in missing and soil.get("virgin_line_N") is not None:
        v0 = float(soil["particle_density_Mg_per_m3"]) / float(soil["bulk_density_initial_Mg_per_m3"])
        lam = vals["compression_index_lambda"]
        kap = vals["recompression_index_kappa"]
        if lam is not None and kap is not None:
            vals["precompression_stress_Pa"] = 1e3 * float(precompression_from_virgin_line_kPa(
                v0, float(soil["virgin_line_N"]), float(lam), float(kap)))
    vals["virgin_line_N"] = None
    out = derive_soil(vals, "terrain file soil")
    return {n: float(out[n]) for n in missing}
