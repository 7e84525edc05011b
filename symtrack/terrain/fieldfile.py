"""The raw field file (``.field``): a terrain's cell storage in a flat binary layout that C reads with
libc alone (the engine FMU's ``field_file`` parameter: symtrack/codegen/engine_fmu.py; docs/terrain.md,
"Files"). The npz terrain file (:mod:`symtrack.terrain.storage`) stays the project's terrain file and
Python its one writer; this module converts both ways (``symtrack terrain convert IN OUT``).

Layout (``FIELD_VERSION`` = 2), little-endian, no padding:

====== ======================= ================================================================
offset type                    content
====== ======================= ================================================================
0      8 bytes                 magic ``SYMFIELD``
8      uint32                  version (2)
12     uint32                  header bytes H = 64 + 8 n_soil + 8 n_depths + 64 (1 + n_soil) (the
                               arrays start at H)
16     int64, int64            nx, ny: cells along x and y (cell (i, j) at flat index i ny + j)
32     float64 x 3             origin x, origin y [m] (the field's lower-left corner), cell size [m]
56     uint32, uint32          n_soil (the count of soil values), n_depths (the subsoil depths)
64     float64 x n_soil        the soil parameters the history was made with
       float64 x n_depths      the subsoil depths [m] (``subsoil_depths_m``)
       64 bytes x (1 + n_soil) the parameter layout: the soil law's name (``model.soil_law``), then
                               the name of each soil value in order (ASCII, padded with NUL bytes)
H      float64 x n, five times z_m, z_rate_m_s, z_max_m, p_max_Pa, z_off_m (n = nx ny)
H+40n  uint16 x n              load_cycles
H+42n  int8 x n                phase (0 untouched, 1 loading, 2 unloading/reloading)
H+43n  float32 x n n_depths    sigma_max_Pa (per cell its n_depths depths), then
       float32 x n n_depths    specific_volume (as the npz's: 0 the soil's initial state)
end-8  8 bytes                 magic ``ENDFIELD`` (a truncated file lacks it)
====== ======================= ================================================================

A version-1 file (no names: its values in the order of :data:`FIELD_V1_SOIL_NAMES`, a file of an older
symtrack the first of them, the Bekker/Wong law's) is read here; the engine FMU reads version 2 only
(``symtrack terrain convert`` to npz and back writes one).

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
from ..model.parameters import soil_params, spec
from ..soil import law as soil_law
from ..soil.pedotransfer import SUBSOIL_KEYS
from .storage import Grid, Terrain, load, save, soil_layout

__all__ = ["FIELD_ARRAYS", "FIELD_HEADER", "FIELD_MAGIC", "FIELD_NAME_BYTES", "FIELD_TRAILER", "FIELD_V1_SOIL_NAMES",
           "FIELD_VERSION", "convert", "field_bytes", "read_field", "write_field"]

FIELD_MAGIC = b"SYMFIELD"
FIELD_TRAILER = b"ENDFIELD"
FIELD_VERSION = 2
FIELD_NAME_BYTES = 64  # each name of the parameter layout (version 2)
# the soil values of a version-1 file, in its order (a file of an older symtrack: the first n_soil of them)
FIELD_V1_SOIL_NAMES = (
    "bekker_n", "k_c_N_per_m_n1", "k_phi_N_per_m_n2", "cohesion_Pa", "friction_angle_rad", "shear_modulus_K_m",
    "elastic_stiffness_Pa_per_m", "unloading_stiffness_floor", "cell_areal_mass_kg_per_m2",
    "cell_damping_Pa_s_per_m", "repeated_loading_exponent", "stress_concentration_factor",
    "precompression_stress_Pa", "virgin_line_N", "compression_index_lambda", "recompression_index_kappa",
    "particle_density_Mg_per_m3", "bulk_density_initial_Mg_per_m3", "yield_line_offset_ln_p",
    "yield_compression_index_k2", "specific_volume_min", "clay_kg_per_kg", "silt_kg_per_kg", "sand_kg_per_kg",
    "matric_suction_kPa", "subsoil_top_m", "subsoil_bulk_density_initial_Mg_per_m3", "subsoil_clay_kg_per_kg",
    "subsoil_silt_kg_per_kg", "subsoil_sand_kg_per_kg", "subsoil_matric_suction_kPa")
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
    law = st.soil_law or soil_law.DEFAULT
    missing = [s.name for s in soil_params(law=soil_law.get(law, "the terrain's soil law")) if s.name not in soil]
    if missing:
        raise ScenarioError(f"{where}: the soil lacks {', '.join(missing)}")
    g = st.grid
    names = soil_layout(soil)
    values = np.array([float(soil[n]) for n in names], dtype="<f8")
    depths = np.array(st.subsoil_depths_m, dtype="<f8")
    head = FIELD_HEADER.pack(FIELD_MAGIC, FIELD_VERSION, _header_bytes(FIELD_VERSION, values.size, depths.size),
                             g.shape[0], g.shape[1], float(g.origin_m[0]), float(g.origin_m[1]), float(g.cell_m),
                             values.size, depths.size)
    parts = [head, values.tobytes(), depths.tobytes(), *(_name_bytes(n) for n in (law, *names))]
    parts += [np.ascontiguousarray(getattr(st, attr), dtype=dt).tobytes() for attr, dt, _ in FIELD_ARRAYS]
    parts += [np.ascontiguousarray(getattr(st, attr), dtype="<f4").tobytes() for attr, _ in SUBSOIL_ARRAYS]
    parts.append(FIELD_TRAILER)
    return b"".join(parts)


def _header_bytes(version: int, n_soil: int, n_depths: int) -> int:
    return FIELD_HEADER.size + 8 * (n_soil + n_depths) + (FIELD_NAME_BYTES * (1 + n_soil) if version >= 2 else 0)


def _name_bytes(name: str) -> bytes:
    raw = name.encode("ascii")
    if len(raw) >= FIELD_NAME_BYTES:
        raise ScenarioError(f"field file: the name {name!r} is longer than {FIELD_NAME_BYTES - 1} characters")
    return raw.ljust(FIELD_NAME_BYTES, b"\0")


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
    if version not in (1, FIELD_VERSION):
        raise ScenarioError(f"{path}: field file version {version}, this symtrack reads 1 and {FIELD_VERSION}")
    if hbytes != _header_bytes(version, n_soil, n_depths) or nx < 1 or ny < 1 or not dx > 0 or n_depths > 64 or \
            n_soil < 1 or n_soil > 1000 or len(data) < hbytes:
        raise ScenarioError(f"{path}: malformed field header (header bytes {hbytes}, nx {nx}, ny {ny}, cell {dx} m, "
                            f"{n_soil} soil values, {n_depths} subsoil depths)")
    if version == 1:  # no names: the first values of the version-1 list, the Bekker/Wong law's
        if n_soil > len(FIELD_V1_SOIL_NAMES):
            raise ScenarioError(f"{path}: {n_soil} soil values in a version-1 field file, which holds at most "
                                f"{len(FIELD_V1_SOIL_NAMES)}: the file is damaged")
        law, names = soil_law.DEFAULT, FIELD_V1_SOIL_NAMES[:n_soil]
    else:
        off = FIELD_HEADER.size + 8 * (n_soil + n_depths)
        raw = [data[off + FIELD_NAME_BYTES * i:off + FIELD_NAME_BYTES * (i + 1)] for i in range(1 + n_soil)]
        try:
            law, *names = (r.rstrip(b"\0").decode("ascii") for r in raw)
        except UnicodeDecodeError as err:
            raise ScenarioError(f"{path}: the field file's parameter layout is not ASCII: the file is damaged") from err
        if len(set(names)) != len(names) or not all(names):
            raise ScenarioError(f"{path}: the field file's parameter layout names a value twice or not at all: the "
                                "file is damaged")
    if law not in soil_law.names():
        raise ScenarioError(f"{path}: the field was made with the soil law {law!r}, which this symtrack does not have "
                            f"(model.soil_law: one of {', '.join(soil_law.names())})")
    expected = [s.name for s in soil_params(law=soil_law.get(law))]
    unknown = [nm for nm in names if nm not in expected]
    if unknown:
        raise ScenarioError(f"{path}: the field file holds soil parameter(s) {', '.join(unknown)}, which the soil "
                            f"law {law!r} does not read (the file was written by another version)")
    # a file written before soil parameters were added lacks them: they take the registry's defaults, as a
    # terrain file's do (storage.load), a subsoil layer's description its topsoil's
    missing = [nm for nm in expected if nm not in names]
    lacking = [nm for nm in missing if spec(nm).default is None and nm not in SAME_AS_TOPSOIL]
    if lacking:
        raise ScenarioError(f"{path}: {n_soil} soil values, without {', '.join(lacking)}, which has no default "
                            "(the file was written by another version)")
    n = nx * ny
    size = hbytes + (BYTES_PER_CELL + 8 * n_depths) * n + len(FIELD_TRAILER)
    if len(data) != size or data[-8:] != FIELD_TRAILER:
        raise ScenarioError(f"{path}: {len(data)} bytes, a field of {nx} x {ny} cells and {n_depths} subsoil depths "
                            f"takes {size} ending in ENDFIELD: the file is truncated or damaged")
    soil_values = np.frombuffer(data, "<f8", n_soil, FIELD_HEADER.size)
    depths = np.frombuffer(data, "<f8", n_depths, FIELD_HEADER.size + 8 * n_soil)
    soil = dict(zip(names, (float(v) for v in soil_values), strict=True))
    for name in missing:  # (in the list's order: a subsoil value is its topsoil's, filled before it)
        soil[name] = float(spec(name).default) if name not in SAME_AS_TOPSOIL else soil[SAME_AS_TOPSOIL[name]]
    st = Terrain(Grid((float(x0), float(y0)), float(dx), (int(nx), int(ny))), soil,
                 tuple(float(d) for d in depths))
    st.soil_law = law
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
