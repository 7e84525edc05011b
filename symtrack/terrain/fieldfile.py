"""The raw field file (``.field``): a terrain's cell storage in a flat binary layout that C reads with
libc alone (the engine FMU's ``field_file`` parameter: symtrack/codegen/engine_fmu.py; docs/terrain.md,
"Files"). The npz terrain file (:mod:`symtrack.terrain.storage`) stays the project's terrain file and
Python its one writer; this module converts both ways (``symtrack terrain convert IN OUT``).

Layout (``FIELD_VERSION`` = 1), little-endian, no padding:

====== ======================= ================================================================
offset type                    content
====== ======================= ================================================================
0      8 bytes                 magic ``SYMFIELD``
8      uint32                  version (1)
12     uint32                  header bytes H = 64 + 8 n_soil + 8 n_depths (the arrays start at H)
16     int64, int64            nx, ny: cells along x and y (cell (i, j) at flat index i ny + j)
32     float64 x 3             origin x, origin y [m] (the field's lower-left corner), cell size [m]
56     uint32, uint32          n_soil (the count of soil values), n_depths (the subsoil depths)
64     float64 x n_soil        the soil parameters the history was made with, in the order of
                               :data:`symtrack.model.parameters.SOIL_PARAM_NAMES`
       float64 x n_depths      the subsoil depths [m] (``subsoil_depths_m``)
H      float64 x n, five times z_m, z_rate_m_s, z_max_m, p_max_Pa, z_off_m (n = nx ny)
H+40n  uint16 x n              load_cycles
H+42n  int8 x n                phase (0 untouched, 1 loading, 2 unloading/reloading)
H+43n  float32 x n n_depths    sigma_max_Pa (per cell its n_depths depths), then
       float32 x n n_depths    specific_volume (as the npz's: 0 the soil's initial state)
end-8  8 bytes                 magic ``ENDFIELD`` (a truncated file lacks it)
====== ======================= ================================================================

These are the storage arrays the terrain engine reads and writes over a pass (grid_engine.c's
``z, zdot, zmax, pmax, zoff, cycles, phase``) and the subsoil records a pass's end folds into
(World.fold_pass), bit for bit. Not carried (a terrain that has them is refused by
:func:`write_field`, naming what): a soil map (``soil_index``), an elevation (``elevation_m``).
Also not carried: the CRS, the file id and the history (a npz written from a field file starts a
new history, its ``input_file_id`` null); the per-pass ``touched`` flags, which every pass clears at
its start.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, real_path
from ..model.parameters import SOIL_PARAM_NAMES, spec
from ..soil.pedotransfer import SUBSOIL_KEYS
from .storage import Grid, Terrain, load, save

__all__ = ["FIELD_ARRAYS", "FIELD_HEADER", "FIELD_MAGIC", "FIELD_TRAILER", "FIELD_VERSION", "convert", "field_bytes",
           "read_field", "write_field"]

FIELD_MAGIC = b"SYMFIELD"
FIELD_TRAILER = b"ENDFIELD"
FIELD_VERSION = 1
# the soil values a file may lack that take another's: a subsoil layer's description is its topsoil's
# in a file written before the subsoil layer (a soil of one layer)
SAME_AS_TOPSOIL = {sub: top for top, sub in SUBSOIL_KEYS.items()}
FIELD_HEADER = struct.Struct("<8sIIqqdddII")  # 64 bytes, before the soil values
# (Terrain attribute, dtype, npz name) in file order
FIELD_ARRAYS = (("z", "<f8", "z_m"), ("zdot", "<f8", "z_rate_m_s"), ("zmax", "<f8", "z_max_m"),
                ("pmax", "<f8", "p_max_Pa"), ("zoff", "<f8", "z_off_m"), ("cycles", "<u2", "load_cycles"),
                ("phase", "i1", "phase"))
SUBSOIL_ARRAYS = (("sigma_max", "sigma_max_Pa"), ("specific_volume", "specific_volume"))  # float32, per depth
BYTES_PER_CELL = 5 * 8 + 2 + 1


def _refuse_unrepresentable(st: Terrain, where: str) -> None:
    if st.soil_table or np.any(st.soil_index):
        raise ScenarioError(f"{where}: the terrain has a soil map (soil_index): a field file carries one soil")
    if st.elevation is not None:
        raise ScenarioError(f"{where}: the terrain has an elevation (elevation_m): a field file holds a flat field")


def field_bytes(st: Terrain, soil: dict | None = None, where: str = "field file") -> bytes:
    """The field file of the terrain ``st`` (soil parameters ``soil``, default the terrain's own)."""
    _refuse_unrepresentable(st, where)
    soil = soil if soil is not None else st.soil
    if soil is None:
        raise ScenarioError(f"{where}: the terrain has no soil yet; give soil= (the soil parameters)")
    missing = [n for n in SOIL_PARAM_NAMES if n not in soil]
    if missing:
        raise ScenarioError(f"{where}: the soil lacks {', '.join(missing)}")
    g = st.grid
    values = np.array([float(soil[n]) for n in SOIL_PARAM_NAMES], dtype="<f8")
    depths = np.array(st.subsoil_depths_m, dtype="<f8")
    head = FIELD_HEADER.pack(FIELD_MAGIC, FIELD_VERSION, FIELD_HEADER.size + 8 * (values.size + depths.size),
                             g.shape[0], g.shape[1], float(g.origin_m[0]), float(g.origin_m[1]), float(g.cell_m),
                             values.size, depths.size)
    parts = [head, values.tobytes(), depths.tobytes()]
    parts += [np.ascontiguousarray(getattr(st, attr), dtype=dt).tobytes() for attr, dt, _ in FIELD_ARRAYS]
    parts += [np.ascontiguousarray(getattr(st, attr), dtype="<f4").tobytes() for attr, _ in SUBSOIL_ARRAYS]
    parts.append(FIELD_TRAILER)
    return b"".join(parts)


def write_field(path, st: Terrain, soil: dict | None = None) -> None:
    """Write the terrain ``st`` as a field file (atomically; through a symbolic link, its target)."""
    atomic_write_bytes(real_path(path), field_bytes(st, soil, str(path)))


def read_field(path) -> Terrain:
    """Read a field file into a :class:`~symtrack.terrain.storage.Terrain` (its soil the file's; no
    subsoil depths, no history): a ScenarioError naming what is wrong for a damaged file."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"{path}: no such field file")
    data = path.read_bytes()
    if len(data) < FIELD_HEADER.size or data[:8] != FIELD_MAGIC:
        raise ScenarioError(f"{path}: not a symtrack field file (no SYMFIELD magic)")
    _, version, hbytes, nx, ny, x0, y0, dx, n_soil, n_depths = FIELD_HEADER.unpack_from(data)
    if version != FIELD_VERSION:
        raise ScenarioError(f"{path}: field file version {version}, this symtrack reads {FIELD_VERSION}")
    if hbytes != FIELD_HEADER.size + 8 * (n_soil + n_depths) or nx < 1 or ny < 1 or not dx > 0 or n_depths > 64:
        raise ScenarioError(f"{path}: malformed field header (header bytes {hbytes}, nx {nx}, ny {ny}, cell {dx} m, "
                            f"{n_soil} soil values, {n_depths} subsoil depths)")
    # a file written before soil parameters were added (appended to the list) has fewer values: the
    # missing ones take the registry's defaults, as a terrain file's do (storage.load)
    missing = SOIL_PARAM_NAMES[n_soil:]
    if n_soil > len(SOIL_PARAM_NAMES) or n_soil < 1 or any(spec(n).default is None and n not in SAME_AS_TOPSOIL
                                                            for n in missing):
        raise ScenarioError(f"{path}: {n_soil} soil values, this symtrack has {len(SOIL_PARAM_NAMES)} soil "
                            "parameters (the file was written by another version)")
    n = nx * ny
    size = hbytes + (BYTES_PER_CELL + 8 * n_depths) * n + len(FIELD_TRAILER)
    if len(data) != size or data[-8:] != FIELD_TRAILER:
        raise ScenarioError(f"{path}: {len(data)} bytes, a field of {nx} x {ny} cells and {n_depths} subsoil depths "
                            f"takes {size} ending in ENDFIELD: the file is truncated or damaged")
    soil_values = np.frombuffer(data, "<f8", n_soil, FIELD_HEADER.size)
    depths = np.frombuffer(data, "<f8", n_depths, FIELD_HEADER.size + 8 * n_soil)
    soil = dict(zip(SOIL_PARAM_NAMES[:n_soil], (float(v) for v in soil_values), strict=True))
    for name in missing:  # (in the list's order: a subsoil value is its topsoil's, filled before it)
        soil[name] = float(spec(name).default) if name not in SAME_AS_TOPSOIL else soil[SAME_AS_TOPSOIL[name]]
    st = Terrain(Grid((float(x0), float(y0)), float(dx), (int(nx), int(ny))), soil,
                 tuple(float(d) for d in depths))
    off = hbytes
    for attr, dt, name in FIELD_ARRAYS:
        a = np.frombuffer(data, dt, n, off)
        off += a.nbytes
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ScenarioError(f"{path}: {name} holds non-finite values: the file is damaged")
        getattr(st, attr)[:] = a
    for attr, name in SUBSOIL_ARRAYS:
        a = np.frombuffer(data, "<f4", n * n_depths, off)
        off += a.nbytes
        if not (np.all(np.isfinite(a)) and np.all(a >= 0)):
            raise ScenarioError(f"{path}: {name} holds negative or non-finite values: the file is damaged")
        getattr(st, attr)[...] = a.reshape(n, n_depths)
    if not np.all((st.phase >= 0) & (st.phase <= 2)):
        raise ScenarioError(f"{path}: phase holds values outside 0, 1, 2: the file is damaged")
    if not np.all(st.zoff >= 0):
        raise ScenarioError(f"{path}: z_off_m holds negative values: the file is damaged")
    return st


def convert(src, dst) -> Terrain:
    """``symtrack terrain convert SRC DST``: a terrain file (.npz) to a field file (.field) or back,
    by the names' suffixes; returns the terrain read."""
    src, dst = Path(src), Path(dst)
    kinds = (src.suffix, dst.suffix)
    if kinds == (".npz", ".field"):
        st = load(src)
        write_field(dst, st)
    elif kinds == (".field", ".npz"):
        st = read_field(src)
        save(dst, st)
    else:
        raise ScenarioError(f"symtrack terrain convert {src} {dst}: converts FILE.npz to FILE.field or FILE.field to "
                            "FILE.npz (by the suffixes)")
    return st
