"""Terrain files: the whole cell storage in one ``.npz`` file, written atomically.

Schema (``TERRAIN_SCHEMA_VERSION`` = 1), one NumPy array per key:

- ``kind``: the string "symtrack-terrain"; ``schema_version``: int;
- ``origin_m`` (2,) float64: world (x, y) of the field's lower-left corner; ``cell_m`` float64;
  ``shape`` (2,) int64: cells along x and y. Cell (i, j) has its centre at
  origin + ((i + 1/2) cell_m, (j + 1/2) cell_m);
- ``z_m``, ``z_rate_m_s``, ``z_max_m``, ``p_max_Pa`` float64 (nx, ny) and ``phase`` int8 (nx, ny):
  every cell's five stored values (phase 0 untouched, 1 loading, 2 unloading/reloading);
- ``soil_names`` (str array) and ``soil_values`` float64: the soil parameters the history
  was made with. Loading a file into a scenario with a different soil is an error.

Values are stored bit for bit (float64), compressed (zip deflate): the default field of a
million cells, mostly untouched, takes well under its 33 MB in memory.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..errors import ScenarioError
from ..output import atomic_write_bytes
from ..parameters import SOIL_PARAM_NAMES
from .world import STORAGE_FIELDS, CellStorage, Grid

TERRAIN_SCHEMA_VERSION = 1
KIND = "symtrack-terrain"


def save(path, storage: CellStorage, soil: dict) -> None:
    g = storage.grid
    arrays = {k: v.reshape(g.shape) for k, v in storage.arrays().items()}
    buf = io.BytesIO()
    np.savez_compressed(
        buf, kind=np.array(KIND), schema_version=np.array(TERRAIN_SCHEMA_VERSION),
        origin_m=np.array(g.origin_m, dtype=np.float64), cell_m=np.array(g.cell_m, dtype=np.float64),
        shape=np.array(g.shape, dtype=np.int64),
        soil_names=np.array(SOIL_PARAM_NAMES), soil_values=np.array([float(soil[n]) for n in SOIL_PARAM_NAMES]),
        **arrays)
    atomic_write_bytes(Path(path), buf.getvalue())


def load(path, soil: dict | None = None) -> CellStorage:
    """Read a terrain file; with ``soil`` given, check that it is the soil of the file."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"terrain.initial_state = {str(path)!r}: no such terrain file")
    try:
        with np.load(path, allow_pickle=False) as f:
            d = {k: f[k] for k in f.files}
    except (OSError, ValueError) as err:
        raise ScenarioError(f"{path}: not a terrain file ({err})") from err
    if str(d.get("kind", "")) != KIND:
        raise ScenarioError(f"{path}: not a symtrack terrain file (kind = {d.get('kind')!r})")
    version = int(d["schema_version"])
    if version != TERRAIN_SCHEMA_VERSION:
        raise ScenarioError(f"{path}: terrain schema_version = {version}, this symtrack reads {TERRAIN_SCHEMA_VERSION}")
    shape = tuple(int(v) for v in d["shape"])
    grid = Grid(tuple(float(v) for v in d["origin_m"]), float(d["cell_m"]), shape)
    st = CellStorage(grid)
    for name, arr in zip(STORAGE_FIELDS, (st.z, st.zdot, st.zmax, st.pmax, st.phase), strict=True):
        a = d[name]
        if a.shape != shape or a.dtype != arr.dtype:
            raise ScenarioError(f"{path}: {name} has shape {a.shape} and type {a.dtype}, "
                                f"expected {shape} and {arr.dtype}")
        arr[:] = a.ravel()
    if soil is not None:
        names = [str(n) for n in d["soil_names"]]
        for n, v in zip(names, d["soil_values"], strict=True):
            if n in soil and float(soil[n]) != float(v):
                raise ScenarioError(f"{path}: the terrain was made with soil {n} = {float(v)!r}, the scenario has "
                                    f"{float(soil[n])!r}; use the same [soil] to continue a terrain")
    return st
