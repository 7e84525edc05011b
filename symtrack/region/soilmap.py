"""The fields' soils from a soil map (docs/region.md, "A soil map"): polygons of soil units (a GeoJSON
FeatureCollection whose features name their soil in an attribute) or a raster of soil-unit codes (a
single-band integer GeoTIFF and a table of its codes to the soils of ``[soils]``), in the fields' CRS.

Each field takes the soil that covers most of its polygon: the area of the field in each soil's units (the
polygons' intersections with the field, summed over the units of one soil), or, on a raster, the pixels whose
centre is in the field (every pixel the field touches, where no centre is in it), counted per soil. The share
of the field in its soil is recorded (``soil_share``); a field whose soil covers less than ``split_share`` of it
is a split field: warned about (``split_fields = "warn"``, the default: a log line naming the field and its
soils' shares), refused (``"refuse"``) or taken as it is (``"accept"``). A field no unit covers (nodata pixels
only, or outside every polygon) is refused.

Everything is checked before any work, with errors naming the file, the feature (its index and its ``id`` or
properties) or the pixel (its row, column and centre coordinates), the value and the allowed values: a soil name
that is not a soil of ``[soils]``, a code missing from the table (under a field: codes elsewhere are not read),
an invalid polygon, a raster in another CRS than the fields'.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ScenarioError
from ..foundations.files import read_text

__all__ = ["SOIL_MAP_KEYS", "SPLIT_CHOICES", "SoilMap", "field_soils", "parse_soil_map"]

log = logging.getLogger("symtrack.region")

SOIL_MAP_KEYS = ("file", "attribute", "codes", "split_fields", "split_share")
SPLIT_CHOICES = ("warn", "refuse", "accept")
POLYGON_SUFFIXES = (".geojson", ".json")
RASTER_SUFFIXES = (".tif", ".tiff")
# a field is split when its soil covers less than this share of it (ASSUMED: a soil survey's map unit is named
# after a soil that covers most of it; 0.8 leaves a field whose minor soil is a fifth or less as one soil)
DEFAULT_SPLIT_SHARE = 0.8


@dataclass(frozen=True)
class SoilMap:
    """The ``[soil_map]`` table, checked (module doc): the file, its kind ("polygons" or "raster"), the
    polygons' attribute, the raster's codes (code -> soil name), the split rule."""

    path: Path
    kind: str
    attribute: str
    codes: dict
    split_fields: str
    split_share: float


def parse_soil_map(t, soils, resolve) -> SoilMap:
    """``[soil_map]`` -> :class:`SoilMap`; ``soils`` the names of ``[soils]``, ``resolve`` the region file's
    path rule (relative to its folder)."""
    where = "soil_map"
    if not isinstance(t, dict):
        raise ScenarioError(f"[{where}] must be a table: file, attribute (polygons) or codes (a raster), "
                            "split_fields, split_share")
    check_keys(where, t, SOIL_MAP_KEYS)
    if "file" not in t:
        raise ScenarioError(f"{where}.file is required: a GeoJSON of soil-unit polygons or a GeoTIFF of soil-unit "
                            "codes")
    path = resolve(f"{where}.file", t["file"])
    suffix = path.suffix.lower()
    if suffix in POLYGON_SUFFIXES:
        kind = "polygons"
    elif suffix in RASTER_SUFFIXES:
        kind = "raster"
    else:
        raise ScenarioError(f"{where}.file = {t['file']!r}: a soil map is a GeoJSON of polygons "
                            f"({', '.join(POLYGON_SUFFIXES)}) or a GeoTIFF of codes ({', '.join(RASTER_SUFFIXES)})")
    if not path.is_file():
        raise ScenarioError(f"{where}.file = {t['file']!r}: no such file ({path})")
    attribute = t.get("attribute", "soil")
    if kind == "raster" and "attribute" in t:
        raise ScenarioError(f"{where}.attribute = {attribute!r}: a raster's pixels are codes; give "
                            f"{where}.codes (code = soil name) instead")
    if not isinstance(attribute, str) or not attribute:
        raise ScenarioError(f"{where}.attribute = {attribute!r} must be the name of the polygons' property that "
                            "names their soil")
    codes = {}
    if kind == "raster":
        raw = t.get("codes")
        if not isinstance(raw, dict) or not raw:
            raise ScenarioError(f"{where}.codes is required with a raster: a table of its codes to soils of [soils], "
                                "e.g. codes = { 1 = \"silt_loam\", 2 = \"clay_loam\" }")
        for k, v in raw.items():
            try:
                code = int(str(k).strip())
            except ValueError:
                raise ScenarioError(f"{where}.codes: the key {k!r} is not an integer code of the raster") from None
            if v not in soils:
                raise ScenarioError(f"{where}.codes.{k} = {v!r} is not a soil of [soils] ({', '.join(soils)})")
            codes[code] = v
    elif "codes" in t:
        raise ScenarioError(f"{where}.codes: a polygon file names its soils in {where}.attribute; codes are a "
                            "raster's")
    split = t.get("split_fields", "warn")
    if split not in SPLIT_CHOICES:
        raise ScenarioError(f"{where}.split_fields = {split!r} is not one of {', '.join(SPLIT_CHOICES)}")
    share = number(f"{where}.split_share", t.get("split_share", DEFAULT_SPLIT_SHARE), 0.0, 1.0)
    return SoilMap(path, kind, attribute, codes, split, share)


# ---- polygons ---------------------------------------------------------------------------------------------
def _feature_label(name: str, i: int, f: dict) -> str:
    fid = f.get("id") if isinstance(f, dict) else None
    return f"{name}: feature {i}" + (f" (id {fid!r})" if fid is not None else "")


def read_soil_polygons(sm: SoilMap, soils) -> list[tuple]:
    """[(soil name, shapely geometry, label)] of the polygon file, each checked (module doc)."""
    import shapely
    from shapely.geometry import shape

    p = sm.path
    try:
        doc = json.loads(read_text(p, "soil_map.file"))
    except ValueError as err:
        raise ScenarioError(f"soil_map.file = {str(p)!r}: not valid JSON ({err})") from None
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(feats, list) or not feats:
        raise ScenarioError(f"soil_map.file = {str(p)!r}: a GeoJSON FeatureCollection of Polygon or MultiPolygon "
                            "features is needed (at least one)")
    out = []
    for i, f in enumerate(doc["features"]):
        label = _feature_label(p.name, i, f)
        if not isinstance(f, dict) or f.get("type") != "Feature":
            raise ScenarioError(f"{label} is not a GeoJSON Feature")
        props = f.get("properties") or {}
        name = props.get(sm.attribute)
        if name not in soils:
            raise ScenarioError(f"{label}: properties.{sm.attribute} = {name!r} is not a soil of [soils] "
                                f"({', '.join(soils)})")
        try:
            geom = shape(f.get("geometry"))
        except Exception as err:  # noqa: BLE001 - shapely's message for a malformed geometry
            raise ScenarioError(f"{label}: the geometry cannot be read ({err})") from None
        if geom.geom_type not in ("Polygon", "MultiPolygon"):
            raise ScenarioError(f"{label}: the geometry is a {geom.geom_type}; a soil unit is a Polygon or a "
                                "MultiPolygon")
        if not geom.is_valid:
            raise ScenarioError(f"{label}: not a valid polygon ({shapely.is_valid_reason(geom)})")
        x0, y0, x1, y1 = geom.bounds
        if max(abs(x0), abs(x1), abs(y0), abs(y1)) < 360.0:
            raise ScenarioError(f"{label}: the coordinates look like degrees (longitude, latitude); the soil map "
                                "must be in the fields' projected CRS, in metres")
        out.append((name, geom, label))
    return out


def _polygon_shares(units, ring) -> dict:
    """{soil: the share of the field's area in its units}."""
    import shapely
    from shapely.geometry import Polygon

    field = Polygon(ring)
    tree = shapely.STRtree([g for _, g, _ in units])
    shares: dict = {}
    for k in tree.query(field):
        name, g, _ = units[int(k)]
        a = field.intersection(g).area
        if a > 0:
            shares[name] = shares.get(name, 0.0) + a / field.area
    return shares


# ---- raster -----------------------------------------------------------------------------------------------
def _raster_shares(sm: SoilMap, ds, h, field_id: str, ring) -> dict:
    """{soil: the share of the field's pixels (module doc)}; a code missing from the table is refused naming
    the pixel."""
    from rasterio import features, windows
    from shapely.geometry import Polygon, mapping

    poly = Polygon(ring)
    x0, y0, x1, y1 = poly.bounds
    # the pixels around the field's bounding box (one more each side), within the raster
    c0 = max(int(np.floor((x0 - h.left_m) / h.pixel_x_m)) - 1, 0)
    c1 = min(int(np.ceil((x1 - h.left_m) / h.pixel_x_m)) + 1, h.width)
    r0 = max(int(np.floor((h.top_m - y1) / h.pixel_y_m)) - 1, 0)
    r1 = min(int(np.ceil((h.top_m - y0) / h.pixel_y_m)) + 1, h.height)
    if c1 <= c0 or r1 <= r0:
        raise ScenarioError(f"soil_map.file = {str(sm.path)!r}: field {field_id!r} is outside the raster (x in "
                            f"[{h.left_m:.10g}, {h.right_m:.10g}] m, y in [{h.bottom_m:.10g}, {h.top_m:.10g}] m): "
                            "the raster must cover every field")
    w = windows.Window(c0, r0, c1 - c0, r1 - r0)
    data = ds.read(1, window=w)
    tr = windows.transform(w, ds.transform)
    inside = features.geometry_mask([mapping(poly)], data.shape, tr, invert=True)
    if not inside.any():  # a field smaller than a pixel's centre spacing: the pixels it touches
        inside = features.geometry_mask([mapping(poly)], data.shape, tr, invert=True, all_touched=True)
    vals = data[inside].astype(np.int64)
    n = vals.size
    if h.nodata is not None:
        vals = vals[vals != int(h.nodata)]
    shares: dict = {}
    for code, count in zip(*np.unique(vals, return_counts=True), strict=True):
        if int(code) not in sm.codes:
            rr, cc = np.argwhere(inside & (data == code))[0]
            row, col = int(rr) + r0, int(cc) + c0
            x, y = h.left_m + (col + 0.5) * h.pixel_x_m, h.top_m - (row + 0.5) * h.pixel_y_m
            raise ScenarioError(f"soil_map.file = {str(sm.path)!r}: the pixel at row {row}, column {col} (centre x = "
                                f"{x:.10g}, y = {y:.10g} m), under field {field_id!r}, has the code {int(code)}, which "
                                f"soil_map.codes does not give a soil (its codes: "
                                f"{', '.join(map(str, sorted(sm.codes)))})")
        name = sm.codes[int(code)]
        shares[name] = shares.get(name, 0.0) + int(count) / n
    return shares


# ---- the fields' soils ------------------------------------------------------------------------------------------
def field_soils(sm: SoilMap, fields: list[dict], soils, crs_wkt: str | None) -> dict:
    """{field_id: (soil, share, {soil: share})} of every field (dicts with ``field_id`` and ``world_ring``):
    the soil covering most of it (module doc), split fields warned about or refused."""
    out = {}
    if sm.kind == "polygons":
        units = read_soil_polygons(sm, soils)
        for f in fields:
            out[f["field_id"]] = _polygon_shares(units, f["world_ring"])
    else:
        import rasterio

        from ..terrain.gis import crs_label, read_header, same_crs

        h = read_header(sm.path, "soil_map.file")
        if h.crs_wkt is not None and crs_wkt is not None and not same_crs(h.crs_wkt, crs_wkt):
            raise ScenarioError(f"soil_map.file = {str(sm.path)!r} is in {crs_label(h.crs_wkt)}, the fields in "
                                f"{crs_label(crs_wkt)} (crs): warp the raster to the fields' CRS first (gdalwarp)")
        with rasterio.open(sm.path) as ds:
            for f in fields:
                out[f["field_id"]] = _raster_shares(sm, ds, h, f["field_id"], f["world_ring"])
    res = {}
    for fid, shares in out.items():
        if not shares:
            raise ScenarioError(f"soil_map.file = {str(sm.path)!r}: no soil unit covers field {fid!r} (outside every "
                                "polygon, or on nodata pixels only): the soil map must cover every field")
        soil = max(sorted(shares), key=lambda s: shares[s])  # the largest share (ties: the first name)
        share = shares[soil]
        if share < sm.split_share:
            parts = ", ".join(f"{s} {100 * v:.1f} %" for s, v in sorted(shares.items(), key=lambda x: -x[1]))
            msg = (f"soil_map: field {fid!r} is split across soils ({parts}): its soil {soil!r} covers "
                   f"{100 * share:.1f} % of it, outside the range [{100 * sm.split_share:g}, 100] % of "
                   "soil_map.split_share")
            if sm.split_fields == "refuse":
                raise ScenarioError(msg + " (split_fields = \"warn\" or \"accept\" takes it as its largest soil)")
            if sm.split_fields == "warn":
                log.warning("%s; the field is taken as %s", msg, soil)
        res[fid] = (soil, min(float(share), 1.0), dict(shares))  # (a share summed from areas: 1 + 1e-16)
    return res
