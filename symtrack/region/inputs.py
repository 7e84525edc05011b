"""A region study's inputs: the region TOML, its fields (GeoJSON polygons read with shapely), its soils (the
one-soil description by preset or by value), each soil's daily matric-suction series (CSV), the fleet and the
calendar of operations of each tillage system (docs/region.md, "Inputs"). Everything is read and checked by
:func:`load_region` before any work: a bad value is refused naming the file, the key, the value and the
allowed range.

The day an operation is done on a field (:func:`draw_day`): uniformly, with the study's seed, among the days of
its window on which the field's soil is workable (its matric suction at least ``workable_suction_kPa``); when no
day of the window is, the driest day of the window (the work is done anyway, on the least wet day).

Moisture classes: a day's matric suction h is put in its class of width ``moisture_class_pF`` in pF =
log10(h / hPa); the class's soil (:func:`class_soil`) is the soil described at the class's middle suction,
its strength and compression lines derived again (symtrack/soil/pedotransfer.py). The tables of a field's
season are built once per (machine, soil) and the soil's parameters once per (soil, moisture class).
"""

from __future__ import annotations

import csv
import datetime as dt
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..foundations.config import check_keys, integer, number
from ..foundations.errors import ParameterError, ScenarioError
from ..foundations.files import read_text
from .fleet import BUILTIN_FLEET, Fleet, load_fleet
from .full import FullFidelity, parse_full_fidelity
from .soilmap import field_soils, parse_soil_map

__all__ = ["FieldShape", "OpEntry", "RegionSpec", "class_soil", "draw_day", "load_region", "moisture_class",
           "read_fields", "read_suction_csv", "region_from_dict"]

SCHEMA_VERSION = 1
TOP_KEYS = ("schema_version", "name", "description", "fields_file", "crs", "fleet", "years", "seed", "cell_m",
            "map_cell_m", "depths_m", "rule", "workable_suction_kPa", "moisture_class_pF", "margin_m",
            "unplannable_fields", "soils", "soil_map", "full_fidelity",
            "systems", "outputs")
OUTPUTS_KEYS = ("field_maps",)
SOIL_ENTRY_KEYS = ("preset", "suction_file")  # and any soil parameter (symtrack presets NAME lists them)
SYSTEM_KEYS = ("operations",)
OP_KEYS = ("name", "machine", "window", "same_day_as", "loosens_to_m", "repeat", "same_lines_as", "tracks",
           "random_offset_m", "headland_passes")
FIELD_PROPERTY_KEYS = ("field_id", "soil", "system")  # soil: optional with a [soil_map]
# defaults (docs/region.md): 0.5 m cells hold a tyre's strip (0.38-0.80 m) in one to two cells; the area under the
# strips is unbiased with the centre rule; 1 m maps; the package's subsoil depths
DEFAULT_CELL_M = 0.5
DEFAULT_MAP_CELL_M = 1.0
# the soil is workable from field capacity on: pF 2 (10 kPa), the usual definition of field capacity (ASSUMED as
# the threshold of trafficability; a farm's own threshold is a key of the region file)
DEFAULT_WORKABLE_SUCTION_KPA = 10.0
# moisture classes a quarter of a pF unit wide: the precompression stress of the pedotransfer function changes by
# at most a few per cent within one (docs/region.md measures it on the demo's soils)
DEFAULT_CLASS_PF = 0.25
# the room around a field's polygon in its grid (the headland turns' and the wheels' reach stay on the grid)
DEFAULT_MARGIN_M = 8.0
RULES = ("centre", "overlap")
# a field no direction of the track lines fits (module doc of symtrack.region.study.check_plans): the study is
# refused, or the field is left out and listed in the study's region.json and report
UNPLANNABLE = ("refuse", "skip")
TRACK_CHOICES = ("random", "ab")
MAX_FIELDS = 100_000


@dataclass(frozen=True)
class FieldShape:
    """A field: its id, soil and tillage system, its polygon in the region's CRS and its own grid: the ring in
    the field's frame (m, counter-clockwise; the track lines along x, the polygon's minimum rotated rectangle's
    long side), the grid's size, and the frame: world = origin + R(theta) (local - offset)."""

    field_id: str
    index: int
    soil: str
    system: str
    area_m2: float
    world_ring: tuple
    ring: tuple
    size_m: tuple
    theta_rad: float
    origin: tuple
    offset: tuple
    # where the soil comes from: the field's own property ("fields_file") or the soil map ("soil_map", the soil
    # covering most of the field: soil_share of its area; symtrack.region.soilmap)
    soil_from: str = "fields_file"
    soil_share: float = 1.0
    # the fidelity its seasons run in: "fast" or "full" ([full_fidelity]: symtrack.region.full)
    fidelity: str = "fast"

    def to_world(self, x, y):
        c, s = math.cos(self.theta_rad), math.sin(self.theta_rad)
        lx, ly = np.asarray(x) - self.offset[0], np.asarray(y) - self.offset[1]
        return self.origin[0] + c * lx - s * ly, self.origin[1] + s * lx + c * ly

    def to_local(self, X, Y):
        c, s = math.cos(self.theta_rad), math.sin(self.theta_rad)
        dx, dy = np.asarray(X) - self.origin[0], np.asarray(Y) - self.origin[1]
        return c * dx + s * dy + self.offset[0], -s * dx + c * dy + self.offset[1]


@dataclass(frozen=True)
class OpEntry:
    name: str
    machine: str
    window: tuple  # (first, last) day of the year, inclusive
    loosens_to_m: float | None
    repeat: int
    same_lines_as: str | None
    tracks: str
    random_offset_m: float
    headland_passes: int | None
    same_day_as: str | None = None  # done on the day of this earlier operation (grain transport with the harvest)


@dataclass
class RegionSpec:
    name: str
    description: str
    folder: Path
    fields: list
    soils: dict  # name -> ParamSet (the soil as described)
    suction: dict  # soil name -> {year: np.ndarray of the year's daily suction [kPa], day 1 at index 0}
    fleet: Fleet
    systems: dict  # name -> [OpEntry]
    years: tuple
    seed: int
    cell_m: float
    map_cell_m: float
    depths_m: tuple
    rule: str
    workable_suction_kPa: float
    moisture_class_pF: float
    crs: str | None
    document: dict = field(default_factory=dict)
    margin_m: float = DEFAULT_MARGIN_M
    unplannable_fields: str = "refuse"
    skipped: list = field(default_factory=list)  # [{"field_id", "reason"}] of the fields left out
    full_fidelity: FullFidelity | None = None  # [full_fidelity]: the fields run in the full fidelity, the vehicle
    # [outputs] field_maps: each field-season's maps also as Cloud-Optimized GeoTIFFs in its folder
    field_maps: bool = True

    @property
    def area_ha(self) -> float:
        return sum(f.area_m2 for f in self.fields) / 1e4


# ---- soils and suction ------------------------------------------------------------------------------------
def _soil(name: str, t: dict):
    from ..model.parameters import SOIL_PARAMS, ParamSet, check_set
    from ..presets.soils import soil_preset

    where = f"soils.{name}"
    if not isinstance(t, dict):
        raise ScenarioError(f"[{where}] must be a table (preset, suction_file and soil parameters)")
    names = {s.name for s in SOIL_PARAMS}
    check_keys(where, t, (*SOIL_ENTRY_KEYS, *sorted(names)))
    values, derived = {}, {}
    if "preset" in t:
        try:
            preset = soil_preset(t["preset"])
        except ParameterError as err:
            raise ScenarioError(f"{where}.preset: {err}") from None
        # a key the region file gives is given, never derived (even where it equals the preset's derived value)
        values, derived = dict(preset), {k: v for k, v in preset.derived.items() if k not in t}
    values.update({k: v for k, v in t.items() if k in names})
    try:  # (the preset's derived values derived again from a changed description: ParamSet)
        return check_set(ParamSet(values, derived=derived), SOIL_PARAMS, where)
    except ParameterError as err:
        raise ScenarioError(str(err)) from None


def class_soil(soil, suction_kPa: float, where: str = "soil"):
    """The soil described at matric suction ``suction_kPa`` (its derived strength and lines derived again)."""
    from ..model.parameters import SOIL_PARAMS, ParamSet, check_set

    values = ParamSet({**soil, "matric_suction_kPa": float(suction_kPa)}, derived=getattr(soil, "derived", {}))
    return check_set(values, SOIL_PARAMS, where)


def moisture_class(suction_kPa: float, width_pF: float) -> int:
    """The class of a suction: floor(pF / width), pF = log10(suction / hPa)."""
    return int(math.floor(math.log10(10.0 * suction_kPa) / width_pF))


def class_suction_kPa(k: int, width_pF: float) -> float:
    """The middle suction of class k [kPa]."""
    return 0.1 * 10.0 ** ((k + 0.5) * width_pF)


def read_suction_csv(path, years, where: str) -> dict:
    """A daily matric-suction series: a CSV with the header ``date,matric_suction_kPa`` (ISO dates). Returns
    {year: suction per day of that year [kPa]}; every day of every study year must be there once."""
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{where} = {str(path)!r}: no such file")
    rows = list(csv.reader(read_text(p, where).splitlines()))
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows or [c.strip() for c in rows[0]] != ["date", "matric_suction_kPa"]:
        raise ScenarioError(f"{where} = {str(path)!r}: a suction series starts with the header date,matric_suction_kPa")
    want = set(years)
    got: dict = {y: {} for y in want}
    for k, r in enumerate(rows[1:], start=2):
        if len(r) != 2:
            raise ScenarioError(f"{p}: line {k} has {len(r)} values, not date,matric_suction_kPa")
        try:
            d = dt.date.fromisoformat(r[0].strip())
        except ValueError:
            raise ScenarioError(f"{p}: line {k}: date = {r[0]!r} is not an ISO date (YYYY-MM-DD)") from None
        if d.year not in want:
            continue
        try:
            v = float(r[1])
        except ValueError:
            raise ScenarioError(f"{p}: line {k}: matric_suction_kPa = {r[1]!r} must be a number") from None
        if not (math.isfinite(v) and 0.0 < v <= 1.5e6):
            raise ScenarioError(f"{p}: line {k} ({d}): matric_suction_kPa = {r[1].strip()} is outside the allowed "
                                "range "
                                "(0, 1.5e6] kPa (suction is > 0 in an unsaturated soil)")
        doy = d.timetuple().tm_yday
        if doy in got[d.year]:
            raise ScenarioError(f"{p}: line {k}: the date {d} is given twice")
        got[d.year][doy] = v
    out = {}
    for y in sorted(want):
        n = 366 if (y % 4 == 0 and (y % 100 != 0 or y % 400 == 0)) else 365
        missing = [d for d in range(1, n + 1) if d not in got[y]]
        if missing:
            first = dt.date(y, 1, 1) + dt.timedelta(days=missing[0] - 1)
            raise ScenarioError(f"{where} = {str(path)!r}: the year {y} lacks {len(missing)} day(s), the first {first} "
                                "(every day of every study year is needed)")
        out[y] = np.array([got[y][d] for d in range(1, n + 1)])
    return out


def draw_day(series: np.ndarray, window: tuple, workable_kPa: float, rng: np.random.Generator) -> int:
    """The day of the year an operation is done (module doc)."""
    lo, hi = window
    hi = min(hi, series.size)
    days = np.arange(lo, hi + 1)
    s = series[days - 1]
    ok = days[s >= workable_kPa]
    if ok.size:
        return int(rng.choice(ok))
    return int(days[int(np.argmax(s))])


# ---- fields -----------------------------------------------------------------------------------------------
def read_fields(path, margin_m: float, where: str = "fields_file", soil_required: bool = True) -> list[dict]:
    """The fields of a GeoJSON FeatureCollection of Polygon features (properties field_id, soil, system), each
    checked with shapely (a valid polygon without holes, in a metric CRS). Returns dicts of the properties, the
    ring (world), the area and the field's frame (:class:`FieldShape`'s theta, origin, offset, ring, size).
    Without ``soil_required`` (a soil map gives the soils) a field's ``soil`` may be left out (None)."""
    import shapely
    from shapely.geometry import Polygon, shape

    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{where} = {str(path)!r}: no such file")
    try:
        doc = json.loads(read_text(p, where))
    except ValueError as err:
        raise ScenarioError(f"{where} = {str(path)!r}: not valid JSON ({err})") from None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        raise ScenarioError(f"{where} = {str(path)!r}: a GeoJSON FeatureCollection of Polygon features is needed")
    feats = doc["features"]
    if not feats or len(feats) > MAX_FIELDS:
        raise ScenarioError(f"{where} = {str(path)!r}: {len(feats)} features; the allowed range is [1, {MAX_FIELDS}]")
    out, seen = [], set()
    for i, f in enumerate(feats):
        label = f"{p.name}: feature {i}"
        if not isinstance(f, dict) or f.get("type") != "Feature":
            raise ScenarioError(f"{label} is not a GeoJSON Feature")
        props = f.get("properties") or {}
        for k in FIELD_PROPERTY_KEYS:
            if k == "soil" and not soil_required and props.get(k) is None:
                continue
            if not isinstance(props.get(k), str) or not props.get(k):
                raise ScenarioError(f"{label}: properties.{k} = {props.get(k)!r} must be a non-empty string")
        fid = props["field_id"]
        label = f"{p.name}: field {fid!r}"
        if fid in seen:
            raise ScenarioError(f"{label}: field_id is given twice")
        if not all(c.isalnum() or c in "-_." for c in fid):
            raise ScenarioError(f"{label}: field_id may hold letters, digits, '-', '_' and '.' only (it names a "
                                "folder)")
        seen.add(fid)
        try:
            geom = shape(f.get("geometry"))
        except Exception as err:  # noqa: BLE001 - shapely's message for a malformed geometry
            raise ScenarioError(f"{label}: the geometry cannot be read ({err})") from None
        if geom.geom_type == "MultiPolygon" and len(geom.geoms) == 1:
            geom = geom.geoms[0]
        if geom.geom_type != "Polygon":
            raise ScenarioError(f"{label}: the geometry is a {geom.geom_type}; a field is one Polygon")
        if len(geom.interiors):
            raise ScenarioError(f"{label}: the polygon has {len(geom.interiors)} hole(s); a field with holes is not "
                                "supported (give its exterior ring only)")
        if not geom.is_valid:
            raise ScenarioError(f"{label}: not a valid polygon ({shapely.is_valid_reason(geom)})")
        coords = np.asarray(geom.exterior.coords)[:-1, :2]
        if np.abs(coords).max() < 360.0 and geom.area < 1e-2:
            raise ScenarioError(f"{label}: the coordinates look like degrees (longitude, latitude); the fields must be "
                                "in a projected CRS in metres (export them in UTM, and give its crs)")
        if geom.area < 1e3:
            raise ScenarioError(f"{label}: its area {geom.area:.4g} m^2 is outside the allowed range [1000, inf) m^2")
        geom = shapely.geometry.polygon.orient(Polygon(coords), 1.0)
        rect = np.asarray(geom.minimum_rotated_rectangle.exterior.coords)[:4]
        edges = np.diff(np.vstack([rect, rect[:1]]), axis=0)
        k = int(np.argmax(np.hypot(edges[:, 0], edges[:, 1])))
        theta = math.atan2(edges[k, 1], edges[k, 0])
        theta = math.atan2(math.sin(theta), math.cos(theta))
        if theta > math.pi / 2:
            theta -= math.pi
        elif theta <= -math.pi / 2:
            theta += math.pi
        ring = np.asarray(geom.exterior.coords)[:-1, :2]
        out.append({"field_id": fid, "index": i, "soil": props.get("soil"), "system": props["system"],
                    "area_m2": float(geom.area), "world_ring": tuple(map(tuple, ring.tolist())),
                    **field_frame(ring, theta, margin_m)})
    return out


def field_frame(ring, theta: float, margin_m: float) -> dict:
    """The field's frame for track lines at ``theta`` (module doc of :class:`FieldShape`): its local ring, its
    grid's size, theta, the origin and the offset."""
    ring = np.asarray(ring, dtype=float)
    origin = ring.mean(axis=0)
    c, s = math.cos(theta), math.sin(theta)
    d = ring - origin
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
    offset = -local.min(axis=0) + margin_m
    local = local + offset
    size = local.max(axis=0) + margin_m
    return {"ring": tuple(map(tuple, local.tolist())), "size_m": (float(size[0]), float(size[1])),
            "theta_rad": float(theta), "origin": (float(origin[0]), float(origin[1])),
            "offset": (float(offset[0]), float(offset[1]))}


# ---- the calendar -----------------------------------------------------------------------------------------
def _op(where: str, t, fleet: Fleet, earlier=()) -> OpEntry:
    if not isinstance(t, dict):
        raise ScenarioError(f"{where} = {t!r} must be a table of {', '.join(OP_KEYS)}")
    check_keys(where, t, OP_KEYS)
    for k in ("name", "machine"):
        if k not in t:
            raise ScenarioError(f"{where}.{k} is required")
    if ("window" in t) == ("same_day_as" in t):
        raise ScenarioError(f"{where}: give either window = [first, last] (days of the year) or same_day_as = the name "
                            "of an earlier operation, not " + ("both" if "window" in t else "neither"))
    if not isinstance(t["name"], str) or not t["name"]:
        raise ScenarioError(f"{where}.name = {t['name']!r} must be a non-empty string")
    if t["machine"] not in fleet.machines:
        raise ScenarioError(f"{where}.machine = {t['machine']!r} is not a machine of {fleet.label} "
                            f"({', '.join(fleet.machines)})")
    w = t.get("window", [1, 365])
    if not isinstance(w, list) or len(w) != 2:
        raise ScenarioError(f"{where}.window = {w!r} must be [first, last] days of the year")
    a = integer(f"{where}.window[0]", w[0], 1, 365)
    b = integer(f"{where}.window[1]", w[1], a, 365)
    same_day = t.get("same_day_as")
    if same_day is not None and (not isinstance(same_day, str) or same_day not in earlier):
        raise ScenarioError(f"{where}.same_day_as = {same_day!r} must name an earlier operation of the system "
                            f"({', '.join(earlier) or 'none before it'})")
    lo = t.get("loosens_to_m")
    lo = None if lo in (None, "none") else number(f"{where}.loosens_to_m", lo, 0.0, 1.0, low_open=True)
    rep = integer(f"{where}.repeat", t.get("repeat", 1), 1, 100)
    same = t.get("same_lines_as")
    if same is not None and (not isinstance(same, str) or not same):
        raise ScenarioError(f"{where}.same_lines_as = {same!r} must be a name shared by the operations on one plan")
    tracks = t.get("tracks", "random")
    if tracks not in TRACK_CHOICES:
        raise ScenarioError(f"{where}.tracks = {tracks!r} is not one of {', '.join(TRACK_CHOICES)}")
    off = number(f"{where}.random_offset_m", t.get("random_offset_m", 0.5), 0.0, 50.0)
    hp = t.get("headland_passes", "auto")
    hp = None if hp == "auto" else integer(f"{where}.headland_passes", hp, 1, 20)
    return OpEntry(t["name"], t["machine"], (a, b), lo, rep, same, tracks, off, hp, same_day)


def region_from_dict(doc: dict, folder: Path, name: str = "region") -> RegionSpec:
    """A region document (its relative paths from ``folder``) -> :class:`RegionSpec`, every input read and
    checked (module doc). The fields' plans are checked by :func:`symtrack.region.study.check_plans`."""
    if not isinstance(doc, dict):
        raise ScenarioError("a region file is a TOML document")
    check_keys("region", doc, TOP_KEYS)
    v = doc.get("schema_version", SCHEMA_VERSION)
    if v != SCHEMA_VERSION:
        raise ScenarioError(f"schema_version = {v!r}: this symtrack reads region files of version {SCHEMA_VERSION}")
    for k in ("fields_file", "years", "soils", "systems"):
        if k not in doc:
            raise ScenarioError(f"{k} is required in a region file (docs/region.md)")

    def path(key, value):
        if not isinstance(value, str) or not value:
            raise ScenarioError(f"{key} = {value!r} must be a file path")
        p = Path(value)
        return p if p.is_absolute() else folder / p

    years = doc["years"]
    if not isinstance(years, list) or not years:
        raise ScenarioError(f"years = {years!r} must be a non-empty list of years, e.g. [2021, 2022]")
    years = tuple(integer(f"years[{i}]", y, 1900, 2200) for i, y in enumerate(years))
    if list(years) != sorted(set(years)):
        raise ScenarioError(f"years = {list(years)!r} must be increasing, each year once")
    seed = integer("seed", doc.get("seed", 1), 0, 2 ** 62)
    cell = number("cell_m", doc.get("cell_m", DEFAULT_CELL_M), 0.05, 2.0)
    map_cell = number("map_cell_m", doc.get("map_cell_m", DEFAULT_MAP_CELL_M), cell, 100.0)
    depths = doc.get("depths_m", [0.1, 0.3, 0.5, 0.8])
    if not isinstance(depths, list) or not depths:
        raise ScenarioError(f"depths_m = {depths!r} must be a non-empty list of depths (m)")
    depths = tuple(number(f"depths_m[{i}]", d, 0.0, 2.0, low_open=True) for i, d in enumerate(depths))
    if list(depths) != sorted(set(depths)):
        raise ScenarioError(f"depths_m = {list(depths)!r} must be increasing")
    rule = doc.get("rule", "centre")
    if rule not in RULES:
        raise ScenarioError(f"rule = {rule!r} is not one of {', '.join(RULES)}")
    workable = number("workable_suction_kPa", doc.get("workable_suction_kPa", DEFAULT_WORKABLE_SUCTION_KPA), 0.0, 1e4)
    width = number("moisture_class_pF", doc.get("moisture_class_pF", DEFAULT_CLASS_PF), 0.01, 2.0)
    margin = number("margin_m", doc.get("margin_m", DEFAULT_MARGIN_M), 0.0, 100.0)
    unplannable = doc.get("unplannable_fields", "refuse")
    if unplannable not in UNPLANNABLE:
        raise ScenarioError(f"unplannable_fields = {unplannable!r} is not one of {', '.join(UNPLANNABLE)}")
    outputs = doc.get("outputs", {})
    check_keys("outputs", outputs, OUTPUTS_KEYS)
    field_maps = outputs.get("field_maps", True)
    if not isinstance(field_maps, bool):
        raise ScenarioError(f"outputs.field_maps = {field_maps!r} must be true or false")
    crs = doc.get("crs")
    if crs is not None:
        from ..terrain.gis import crs_wkt

        crs = crs_wkt(crs, "crs")
    fleet = load_fleet(doc.get("fleet", BUILTIN_FLEET) if doc.get("fleet", BUILTIN_FLEET) == BUILTIN_FLEET
                       else path("fleet", doc["fleet"]))
    st = doc["soils"]
    if not isinstance(st, dict) or not st:
        raise ScenarioError("[soils] must be a table of soil tables, one per soil of the fields")
    soils, suction = {}, {}
    for sname, t in st.items():
        soils[sname] = _soil(sname, t)
        if "suction_file" not in t:
            raise ScenarioError(f"soils.{sname}.suction_file is required: the soil's daily matric suction (CSV)")
        suction[sname] = read_suction_csv(path(f"soils.{sname}.suction_file", t["suction_file"]), years,
                                          f"soils.{sname}.suction_file")
        for y, s in suction[sname].items():  # every day's soil must be derivable
            for k in sorted({moisture_class(x, width) for x in s}):
                try:
                    class_soil(soils[sname], class_suction_kPa(k, width), f"soils.{sname} at {y}'s suction")
                except (ParameterError, ScenarioError) as err:
                    raise ScenarioError(f"soils.{sname}.suction_file: a day of {y} gives a soil that cannot be "
                                        f"described ({err})") from None
    sy = doc["systems"]
    if not isinstance(sy, dict) or not sy:
        raise ScenarioError("[systems] must be a table of tillage systems, each with [[systems.NAME.operations]]")
    systems = {}
    for sname, t in sy.items():
        check_keys(f"systems.{sname}", t, SYSTEM_KEYS)
        ops = t.get("operations")
        if not isinstance(ops, list) or not ops:
            raise ScenarioError(f"systems.{sname}.operations must be a non-empty list of operation tables")
        entries = []
        for i, o in enumerate(ops):
            entries.append(_op(f"systems.{sname}.operations[{i}]", o, fleet, [e.name for e in entries]))
        names = [e.name for e in entries]
        if len(set(names)) != len(names):
            raise ScenarioError(f"systems.{sname}.operations: the names {names} must differ")
        systems[sname] = entries
    soil_map = None if doc.get("soil_map") is None else parse_soil_map(doc["soil_map"], tuple(soils), path)
    raw = read_fields(path("fields_file", doc["fields_file"]), margin, soil_required=soil_map is None)
    if soil_map is not None:  # the soil covering most of each field; a field's own soil property wins
        mapped = field_soils(soil_map, [f for f in raw if f["soil"] is None], tuple(soils), crs)
        for f in raw:
            if f["soil"] is None:
                soil, share, _ = mapped[f["field_id"]]
                f.update(soil=soil, soil_from="soil_map", soil_share=share)
    full = None if doc.get("full_fidelity") is None else \
        parse_full_fidelity(doc["full_fidelity"], [f["field_id"] for f in raw])
    chosen = full.choose([f["field_id"] for f in raw], seed) if full is not None else set()
    fields = []
    for f in raw:
        f["fidelity"] = "full" if f["field_id"] in chosen else "fast"
        if f["soil"] not in soils:
            raise ScenarioError(f"fields_file: field {f['field_id']!r}: soil = {f['soil']!r} is not a soil of [soils] "
                                f"({', '.join(soils)})")
        if f["system"] not in systems:
            raise ScenarioError(f"fields_file: field {f['field_id']!r}: system = {f['system']!r} is not a system of "
                                f"[systems] ({', '.join(systems)})")
        fields.append(FieldShape(**f))
    return RegionSpec(doc.get("name", name), doc.get("description", ""), folder, fields, soils, suction, fleet, systems,
                      years, seed, cell, map_cell, depths, rule, workable, width, crs, doc, margin, unplannable,
                      full_fidelity=full, field_maps=field_maps)


def load_region(path) -> RegionSpec:
    """A region TOML file -> :class:`RegionSpec` (its paths relative to its folder)."""
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"region file {str(path)!r}: no such file (or the built-in region_demo)")
    try:
        doc = tomllib.loads(read_text(p, "region file"))
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"region file {str(path)!r}: not valid TOML: {err}") from None
    return region_from_dict(doc, p.resolve().parent, p.stem)
