"""A field whose soil varies (docs/model.md, "Soil that varies over the field"): the ``[terrain.soil_map]``
table and the per-cell soil index it gives.

Schema (docs/terrain.md, "Soil maps")::

    [terrain.soil_map]
    # soil 0 is the scenario's [soil]; these are soils 1, 2, ...: a built-in preset name, a user
    # preset file (*.toml), or a table {preset = NAME, <soil parameter> = value, ...}
    soils = ["clayey_soil_thailand_55", {preset = "sandy_loam_15", precompression_stress_Pa = 8e4}]
    # rectangles in world coordinates, later ones over earlier ones (a cell belongs to a zone
    # when its centre lies in it)
    zones = [{soil = 1, x_m = [-50.0, -40.0], y_m = [-50.0, 50.0]}]
    # or/and a raster (applied first): a .npy file of integers (nx, ny), the soil of every cell,
    # or a GeoTIFF (.tif, .tiff; the extra symtrack[gis]) of integers: each cell the soil of the
    # pixel holding its centre; its transform gives the field's origin_m, cell_m and size_m
    # unless [terrain] gives them, its CRS is kept in the terrain (symtrack/terrain/gis.py)
    raster = "soils.npy"

A relative raster path in a scenario file is resolved against the file's folder.

A soil map is applied to a new field; a terrain file keeps its own (``soil_index`` and the soil
table in the file, schema 2). Only the terrain engine (``run.integrator = "grid_fast"``) runs a
field of several soils.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ParameterError, ScenarioError
from ..model.parameters import SOIL_PARAMS, check_set, known_soil_names, spec
from ..presets.catalog import read_preset_file
from ..presets.soils import soil_preset
from ..soil import moisture
from . import gis

__all__ = ["MAX_SOILS", "PATH_KEYS", "SoilMap", "parse_soil_map", "soil_index"]

MAX_SOILS = 16  # soils of one field (a soil map and its terrain file; the engine reads their law rows at run time)
SOIL_NAMES = tuple(s.name for s in SOIL_PARAMS)
# the keys of a scenario document that hold a soil map's file (resolved against a scenario file's folder)
PATH_KEYS = (("terrain", "soil_map", "raster"),)


@dataclasses.dataclass(frozen=True)
class SoilMap:
    """The parsed ``[terrain.soil_map]``: ``labels`` and ``soils`` (parameter sets) of soils 1..n,
    ``zones`` as (soil, x0, x1, y0, y1), ``raster`` a path or None, ``header`` a GeoTIFF's
    georeference (:class:`~symtrack.terrain.gis.RasterHeader`, read when the map is parsed) or
    None; ``raw`` the table as given."""

    labels: tuple
    soils: tuple
    zones: tuple
    raster: str | None
    raw: dict = dataclasses.field(compare=False, repr=False, default_factory=dict)
    header: gis.RasterHeader | None = dataclasses.field(compare=False, repr=False, default=None)

    @property
    def crs_wkt(self) -> str | None:
        """The CRS of the map's GeoTIFF (WKT), None for a map without one."""
        return None if self.header is None else self.header.crs_wkt


def _soil(entry, i: int) -> tuple[str, dict]:
    where = f"terrain.soil_map.soils[{i}]"
    try:
        if isinstance(entry, str):
            values = read_preset_file(entry, "soil")[0] if entry.endswith(".toml") else soil_preset(entry)
            return entry, check_set(values, SOIL_PARAMS, where)
        if isinstance(entry, dict):
            # the default model's soil parameters, or a registered soil law's own (the World keeps the run's model's)
            check_keys(where, entry, ["preset", "moisture", *SOIL_NAMES,
                                      *(n for n in known_soil_names() if n not in SOIL_NAMES)])
            specs = SOIL_PARAMS + tuple(spec(n) for n in entry
                                        if n not in SOIL_NAMES and n not in ("preset", "moisture"))
            preset = entry.get("preset")
            if not isinstance(preset, str):
                raise ScenarioError(f"{where}.preset is required (a soil preset name or file), got {preset!r}")
            values = read_preset_file(preset, "soil")[0] if preset.endswith(".toml") else soil_preset(preset)
            values.update({k: v for k, v in entry.items() if k not in ("preset", "moisture")})
            extra = ", ".join(f"{k}={v}" for k, v in entry.items() if k != "preset")
            values = check_set(values, specs, where)
            if "moisture" in entry:  # the day's moisture of this soil (symtrack.soil.moisture)
                values = check_set(moisture.apply_moisture(values, entry["moisture"], f"{where}.moisture"),
                                   specs, where)
            return (f"{preset} ({extra})" if extra else preset), values
    except ParameterError as err:  # the preset lookups name soil.preset: name the soil map's entry instead
        key = where if isinstance(entry, str) else f"{where}.preset"
        raise ScenarioError(str(err).replace("soil.preset", key, 1)) from err
    raise ScenarioError(f"{where} = {entry!r} must be a soil preset name, a preset file or a table with preset")


def _pair(where, v):
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise ScenarioError(f"{where} = {v!r} must be a pair [low, high] in m")
    lo, hi = (number(f"{where}[{k}]", x, -1e7, 1e7) for k, x in enumerate(v))
    if not hi > lo:
        raise ScenarioError(f"{where} = {list(v)!r} must have low < high")
    return lo, hi


def parse_soil_map(t) -> SoilMap:
    """The ``soil_map`` table -> :class:`SoilMap` (unknown keys and bad values raise, naming them)."""
    if not isinstance(t, dict):
        raise ScenarioError(f"terrain.soil_map = {t!r} must be a table (soils, zones, raster)")
    check_keys("terrain.soil_map", t, ["soils", "zones", "raster"])
    soils = t.get("soils", [])
    if not isinstance(soils, list) or not 1 <= len(soils) <= MAX_SOILS - 1:
        raise ScenarioError(f"terrain.soil_map.soils = {soils!r} must list 1 to {MAX_SOILS - 1} soils "
                            "(soil 0 is the scenario's [soil])")
    parsed = [_soil(e, i) for i, e in enumerate(soils)]
    zones = []
    for i, z in enumerate(t.get("zones", [])):
        where = f"terrain.soil_map.zones[{i}]"
        if not isinstance(z, dict):
            raise ScenarioError(f"{where} = {z!r} must be a table {{soil, x_m, y_m}}")
        check_keys(where, z, ["soil", "x_m", "y_m"])
        k = z.get("soil")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= len(soils):
            raise ScenarioError(f"{where}.soil = {k!r} must be an integer in [0, {len(soils)}] (0: the scenario's "
                                "[soil], i: soils[i - 1])")
        zones.append((k, *_pair(f"{where}.x_m", z.get("x_m")), *_pair(f"{where}.y_m", z.get("y_m"))))
    raster = t.get("raster")
    if raster is not None and (not isinstance(raster, str) or not (raster.endswith(".npy") or gis.is_geotiff(raster))):
        raise ScenarioError(f"terrain.soil_map.raster = {raster!r} must be the path of a .npy file of integers or "
                            f"of a GeoTIFF ({', '.join(gis.GEOTIFF_SUFFIXES)})")
    if not zones and raster is None:
        raise ScenarioError("terrain.soil_map needs zones or a raster (which cells have which soil)")
    header = gis.read_header(raster) if raster is not None and gis.is_geotiff(raster) else None
    return SoilMap(tuple(p[0] for p in parsed), tuple(p[1] for p in parsed), tuple(zones), raster, dict(t), header)


def soil_index(grid, sm: SoilMap) -> np.ndarray:
    """The soil of every cell (flat uint8, i * ny + j) on ``grid``: the raster, then the zones."""
    nx, ny = grid.shape
    idx = np.zeros((nx, ny), dtype=np.uint8)
    if sm.raster is not None and gis.is_geotiff(sm.raster):
        r = gis.read_soil_raster(sm.raster, grid)
        if r.min() < 0 or r.max() > len(sm.soils):
            raise ScenarioError(f"terrain.soil_map.raster = {sm.raster!r}: soil indices must be in "
                                f"[0, {len(sm.soils)}], the raster has {int(r.min())}..{int(r.max())} under the field")
        idx[:] = r.astype(np.uint8)
    elif sm.raster is not None:
        r = gis.read_npy(sm.raster, "terrain.soil_map.raster")
        if r.shape != (nx, ny) or r.dtype.kind not in "iu":
            raise ScenarioError(f"terrain.soil_map.raster = {sm.raster!r}: an integer array of shape {(nx, ny)} "
                                f"(the field's cells along x, y) is needed, the file holds {r.dtype} {r.shape}")
        if r.min() < 0 or r.max() > len(sm.soils):
            raise ScenarioError(f"terrain.soil_map.raster = {sm.raster!r}: soil indices must be in "
                                f"[0, {len(sm.soils)}], the file has {int(r.min())}..{int(r.max())}")
        idx[:] = r.astype(np.uint8)
    xc, yc = grid.centres(np.arange(nx), np.arange(ny))
    for k, x0, x1, y0, y1 in sm.zones:
        inside = ((xc >= x0) & (xc <= x1))[:, None] & ((yc >= y0) & (yc <= y1))[None, :]
        idx[inside] = k
    return idx.ravel()
