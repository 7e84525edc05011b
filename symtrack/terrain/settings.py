"""The ``[terrain]`` scenario section, parsed once into a frozen :class:`TerrainSettings`.

Schema (every key optional; unknown keys are errors)::

    [terrain]
    size_m = [100.0, 100.0]     # field size along world x and y, each in [0.5, 10000] m
    cell_m = 0.1                # cell side, [0.01, 5] m (at most 1e8 cells)
    origin_m = [-50.0, -50.0]   # world (x, y) of the field's lower-left corner
                                # (default: the field centred on the start position)
    channels = "auto"           # "auto" or M: the pool is M x M channels, M in [2, 400]
    initial_state = "t.npz"     # a terrain file to continue from (symtrack simulate --terrain-in)
    passes = 1                  # [1, 100] passes over the same terrain in one run
    max_speed_m_s = 10.0        # (0, 100] speed bound used to derive M ("auto")
    release_time_s = 0.05       # (0, 10] bound on the time a cell takes to unload, for M
    release_rate_m_s = 1e-5     # (0, 1] |dz/dt| below which an unloaded cell is released
    settle_s = 0.2              # [0, 10] settling of the cells under the vehicle at rest
                                # before each pass (the pass's initial static state)
    subsoil_depths_m = [0.1, 0.3, 0.5, 0.8]  # depths of the subsoil stress (docs/subsoil.md),
                                # increasing, each in (0, 5] m, at most 8; [] switches it off
    [terrain.soil_map]          # a field of several soils (symtrack.terrain.soil_map)
    [terrain.surface]           # the ground's shape: slopes, furrows, an elevation raster
                                # (symtrack.terrain.surface)
    [terrain.moisture]          # each cell's water content on the day, a raster
                                # (symtrack.soil.moisture)
    [terrain.towed]             # a trailer on one axle of tyres behind the crawler, loading the
                                # same cells in the same run (symtrack.vehicles.towed)

With a GeoTIFF soil map (``soil_map.raster = "soils.tif"``), origin_m, cell_m and size_m not
given are the raster's (its lower-left corner, pixel and extent), and the raster must cover the
field (checked here, before anything is built); the keys it gives count as given (``given``).
A GeoTIFF elevation raster (``surface.elevation_file``) gives origin_m and size_m the same way
(the whole cells of cell_m it holds), never cell_m (heights are interpolated at the cell centres,
whatever the raster's pixel); a soil map's GeoTIFF comes first.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from ..foundations.config import Key, check_keys, list_hint, number
from ..foundations.errors import ScenarioError
from ..soil.moisture import PATH_KEYS as MOISTURE_PATH_KEYS
from ..soil.moisture import MoistureMap, parse_moisture_map
from ..vehicles.towed import Towed, parse_towed
from . import gis
from .soil_map import PATH_KEYS as SOIL_MAP_PATH_KEYS
from .soil_map import SoilMap, parse_soil_map
from .storage import Grid
from .surface import PATH_KEYS as SURFACE_PATH_KEYS
from .surface import Surface, parse_surface

__all__ = ["MAX_CELLS", "PATH_KEYS", "TerrainSettings", "settings_from_dict"]

# the keys of a scenario document that hold the terrain's files (resolved against a scenario file's folder)
PATH_KEYS = SOIL_MAP_PATH_KEYS + SURFACE_PATH_KEYS + MOISTURE_PATH_KEYS

MAX_CELLS = 100_000_000
MAX_SUBSOIL_DEPTHS = 8


# the [terrain] keys as TerrainSettings checks them (docs/scenarios.md's table is made from these and the defaults)
TERRAIN_KEYS = {k.name: k for k in (
    Key("size_m", "the field's size along world x and y [m]", 0.5, 1e4, allowed="[x, y], each in [0.5, 1e4]"),
    Key("cell_m", "the cell's side [m] (at most 1e8 cells)", 0.01, 5.0),
    Key("origin_m", "world (x, y) of the field's lower-left corner [m] (none: the field centred on the start)",
        -1e7, 1e7, allowed="[x, y], each in [-1e7, 1e7]"),
    Key("channels", "the channel pool is M x M channels (\"auto\": M from the speed bound)",
        allowed='`"auto"` or an integer M in [2, 400]'),
    Key("initial_state", "a terrain file to continue from", allowed="a terrain file's path"),
    Key("passes", "passes over the same terrain in one run", 1, 100, integer=True),
    Key("max_speed_m_s", "the speed bound M is derived from (\"auto\") [m/s]", 0, 100, low_open=True),
    Key("release_time_s", "bound on the time a cell takes to unload, for M [s]", 0, 10, low_open=True),
    Key("release_rate_m_s", "|dz/dt| below which an unloaded cell is released [m/s]", 0, 1, low_open=True),
    Key("settle_s", "settling of the cells under the vehicle at rest before each pass [s]", 0, 10),
    Key("subsoil_depths_m", "depths of the subsoil stress and the bulk density [m] ([]: off)", 0, 5, low_open=True,
        allowed=f"increasing, each in (0, 5], at most {MAX_SUBSOIL_DEPTHS}"),
    Key("soil_map", "a field of several soils (docs/terrain.md)", allowed="a table [terrain.soil_map]"),
    Key("surface", "the ground's shape: slopes, furrows, an elevation raster (docs/vehicle3d.md)",
        allowed="a table [terrain.surface]"),
    Key("moisture", "each cell's water content on the day, a raster (docs/subsoil.md)",
        allowed="a table [terrain.moisture]"),
    Key("towed", "a trailer on one axle of tyres behind the crawler (docs/subsoil.md)",
        allowed="a table [terrain.towed]"),
)}


@dataclass(frozen=True)
class TerrainSettings:
    """The ``[terrain]`` section, validated on construction (module doc for keys and ranges).
    ``given`` holds the keys the scenario set (the others are defaults): a terrain file's
    geometry replaces size_m and cell_m unless the scenario gave them, and
    :meth:`to_dict` writes back only those keys."""

    size_m: tuple[float, float] = (100.0, 100.0)
    cell_m: float = 0.1
    origin_m: tuple[float, float] | None = None
    channels: str | int = "auto"
    initial_state: str | None = None
    passes: int = 1
    max_speed_m_s: float = 10.0
    release_time_s: float = 0.05
    release_rate_m_s: float = 1e-5
    settle_s: float = 0.2
    subsoil_depths_m: tuple = (0.1, 0.3, 0.5, 0.8)
    soil_map: SoilMap | None = None
    surface: Surface | None = None
    moisture: MoistureMap | None = None
    towed: Towed | None = None
    given: frozenset = field(default=frozenset(), compare=False, repr=False)

    def __post_init__(self):
        K = TERRAIN_KEYS
        for i, v in enumerate(self.size_m):
            _num(f"size_m[{i}]", v, K["size_m"].low, K["size_m"].high)
        K["cell_m"].check("terrain", self.cell_m)
        n = self.shape[0] * self.shape[1]
        if n > MAX_CELLS:
            raise ScenarioError(f"terrain: size_m = {list(self.size_m)} at cell_m = {self.cell_m} gives {n} cells; "
                                f"at most {MAX_CELLS} are allowed (raise cell_m or shrink the field)")
        if self.origin_m is not None:
            for i, v in enumerate(self.origin_m):
                _num(f"origin_m[{i}]", v, -1e7, 1e7)
        if self.channels != "auto":
            if isinstance(self.channels, bool) or not isinstance(self.channels, int) or not 2 <= self.channels <= 400:
                raise ScenarioError(f"terrain.channels = {self.channels!r} must be \"auto\" or an integer M "
                                    "in [2, 400] (the pool has M x M channels)")
        if self.initial_state is not None and (not isinstance(self.initial_state, str) or not self.initial_state):
            raise ScenarioError(f"terrain.initial_state = {self.initial_state!r} must be a terrain file path")
        for name in ("passes", "max_speed_m_s", "release_time_s", "release_rate_m_s", "settle_s"):
            K[name].check("terrain", getattr(self, name))
        d = self.subsoil_depths_m
        if not isinstance(d, (list, tuple)) or len(d) > MAX_SUBSOIL_DEPTHS:
            raise ScenarioError(f"terrain.subsoil_depths_m = {d!r} must be a list of at most {MAX_SUBSOIL_DEPTHS} "
                                "depths in m (an empty list switches the subsoil stress off)")
        for i, v in enumerate(d):
            _num(f"subsoil_depths_m[{i}]", v, K["subsoil_depths_m"].low, K["subsoil_depths_m"].high, low_open=True)
            if i and not v > d[i - 1]:
                raise ScenarioError(f"terrain.subsoil_depths_m = {list(d)!r} must increase (entry {i} is {v!r})")

    @property
    def shape(self) -> tuple[int, int]:
        """Number of cells along x and y (the field is rounded to whole cells)."""
        return tuple(max(1, int(round(s / self.cell_m))) for s in self.size_m)


    def to_dict(self) -> dict:
        """The keys the scenario gave, as a TOML-writable dict (pairs as lists)."""
        out = {k: getattr(self, k) for k in sorted(self.given)}
        for k in ("size_m", "origin_m", "subsoil_depths_m"):
            if out.get(k) is not None:
                out[k] = list(out[k])
        if out.get("soil_map") is not None:
            out["soil_map"] = dict(self.soil_map.raw)
        if out.get("surface") is not None:
            out["surface"] = self.surface.to_dict()
        if out.get("moisture") is not None:
            out["moisture"] = dict(self.moisture.raw)
        if out.get("towed") is not None:
            out["towed"] = dict(self.towed.raw)
        return out


def _num(key, value, low, high, low_open=False):
    return number(f"terrain.{key}", value, low, high, low_open)


def _pair(key, value):
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ScenarioError(f"terrain.{key} = {value!r} must be a pair [x, y]{list_hint(f'terrain.{key}', value)}")
    return tuple(_num(f"{key}[{i}]", v, -1e7, 1e7) for i, v in enumerate(value))


def settings_from_dict(t: dict) -> TerrainSettings:
    """The ``[terrain]`` table -> :class:`TerrainSettings` (unknown keys and bad values raise)."""
    names = [f.name for f in dataclasses.fields(TerrainSettings) if f.name != "given"]
    check_keys("terrain", t, names)
    d = dict(t)
    if "size_m" in d:
        d["size_m"] = _pair("size_m", d["size_m"])
    if "origin_m" in d:
        d["origin_m"] = _pair("origin_m", d["origin_m"])
    if "subsoil_depths_m" in d and isinstance(d["subsoil_depths_m"], list):
        d["subsoil_depths_m"] = tuple(d["subsoil_depths_m"])
    filled = frozenset()
    if "soil_map" in d:
        d["soil_map"] = parse_soil_map(d["soil_map"])
        header = d["soil_map"].header
        if header is not None:  # a GeoTIFF: the field's geometry where the scenario gives none
            if "cell_m" in d:  # the whole cells of the given size the raster holds
                cell = number("terrain.cell_m", d["cell_m"], 0.01, 5.0)
                extent = (header.right_m - header.left_m, header.top_m - header.bottom_m)
                geometry = {"origin_m": (header.left_m, header.bottom_m),
                            "size_m": tuple(math.floor(e / cell + 1e-9) * cell for e in extent)}
            else:
                geometry = gis.field_geometry(header)
            for k, v in geometry.items():
                d.setdefault(k, v)
            filled = frozenset(geometry)  # given by the raster: as if the scenario had
    if "surface" in d:
        d["surface"] = parse_surface(d["surface"])
        r = d["surface"].raster
        if r is not None and r.crs_wkt is not None and "origin_m" not in d and "size_m" not in d:
            # a GeoTIFF's extent: the field (its whole cells of cell_m) where nothing else gives it
            cell = number("terrain.cell_m", d.get("cell_m", TerrainSettings.cell_m), 0.01, 5.0)
            left, right, bottom, top = r.bounds()
            d["origin_m"] = (left, bottom)
            d["size_m"] = tuple(math.floor(e / cell + 1e-9) * cell for e in (right - left, top - bottom))
            filled = filled | {"origin_m", "size_m"}
        sm = d.get("soil_map")
        if r is not None and r.crs_wkt is not None and sm is not None and sm.crs_wkt is not None and \
                not gis.same_crs(r.crs_wkt, sm.crs_wkt):
            raise ScenarioError(f"terrain.surface.elevation_file = {r.path!r} is in {gis.crs_label(r.crs_wkt)}, "
                                f"terrain.soil_map.raster in {gis.crs_label(sm.crs_wkt)}: the maps of one field "
                                "must share their CRS (reproject one, gdalwarp -t_srs)")
    if "moisture" in d:
        d["moisture"] = parse_moisture_map(d["moisture"])
    if "towed" in d:
        d["towed"] = parse_towed(d["towed"])
        if not d.get("subsoil_depths_m", TerrainSettings.subsoil_depths_m):
            raise ScenarioError("terrain.towed needs the subsoil stress: terrain.subsoil_depths_m = [] switches it "
                                "off (give at least one depth)")
    if isinstance(d.get("passes"), float) and d["passes"].is_integer():
        d["passes"] = int(d["passes"])
    out = TerrainSettings(**d, given=frozenset(t) | filled)
    if out.soil_map is not None and out.soil_map.header is not None:
        gis.check_covers(out.soil_map.header, Grid(out.origin_m, out.cell_m, out.shape))
    if out.surface is not None:
        grid = Grid(out.origin_m if out.origin_m is not None else (0.0, 0.0), out.cell_m, out.shape)
        # checked on the field (where a raster with its own origin lies on a field centred on the start: by the world)
        if out.origin_m is not None or out.surface.raster is None or out.surface.raster.origin_m is None:
            out.surface.placed(grid)
    return out
