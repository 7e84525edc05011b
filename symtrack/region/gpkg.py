"""The per-field table as a GeoPackage (``fields.gpkg``; docs/region.md, "Outputs"): the fields' polygons with
the columns of ``fields.csv``, one feature per field and season, for a GIS.

Written with the standard library's sqlite3 and shapely's WKB, following the OGC GeoPackage Encoding Standard
1.3.1 (OGC 12-128r18): the ``application_id`` "GPKG" and ``user_version`` 10301, the tables
``gpkg_spatial_ref_sys`` (with the three definitions the standard requires and the study's CRS),
``gpkg_contents`` and ``gpkg_geometry_columns``, and the feature table ``fields`` (``fid``, ``geom`` a POLYGON
in the standard's binary form: the "GP" header, the SRS id and the envelope, then the polygon's WKB). No spatial
index and no extension. GDAL's GeoPackage driver (and so QGIS and geopandas) reads it; rasterio bundles only
GDAL's raster side and fiona/pyogrio are not dependencies of the package, which is why it is not written
through GDAL.

``gpkg_contents.last_change`` is the time of writing, or the time ``SOURCE_DATE_EPOCH`` gives (seconds since
1970, the reproducible-builds convention), for a file identical byte for byte between two runs.
"""

from __future__ import annotations

import datetime as dt
import os
import sqlite3
import struct
from pathlib import Path

from .table import TABLE_COLUMNS, cell_text

__all__ = ["APPLICATION_ID", "TABLE", "USER_VERSION", "column_types", "fields_gpkg", "geometry_blob"]

APPLICATION_ID = 0x47504B47  # "GPKG"
USER_VERSION = 10301  # GeoPackage 1.3.1
TABLE = "fields"
# a CRS without an authority's code (a WKT only): the SRS id given to it (ids of 32768 and more are free of the
# EPSG's)
CUSTOM_SRS_ID = 100000
INTEGER_COLUMNS = ("year", "passes_max")
TEXT_COLUMNS = ("field_id", "soil", "system", "days_worked", "fidelity")
# the SRS definitions every GeoPackage holds (the standard's requirement 11)
_WGS84_WKT = ('GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],'
              'AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",'
              '0.0174532925199433,AUTHORITY["EPSG","9122"]],AXIS["Latitude",NORTH],AXIS["Longitude",EAST],'
              'AUTHORITY["EPSG","4326"]]')
_REQUIRED_SRS = (("WGS 84 geodetic", 4326, "EPSG", 4326, _WGS84_WKT, "longitude/latitude coordinates in decimal "
                  "degrees on the WGS 84 spheroid"),
                 ("Undefined Cartesian SRS", -1, "NONE", -1, "undefined", "undefined Cartesian coordinate reference "
                  "system"),
                 ("Undefined geographic SRS", 0, "NONE", 0, "undefined", "undefined geographic coordinate reference "
                  "system"))


def column_types(depths_m) -> list[tuple[str, str]]:
    """(name, SQLite type) of the table's columns: those of fields.csv (TABLE_COLUMNS) in its order."""
    out = []
    for c in TABLE_COLUMNS(depths_m):
        out.append((c, "TEXT" if c in TEXT_COLUMNS else "INTEGER" if c in INTEGER_COLUMNS else "REAL"))
    return out


def _srs(crs_wkt: str | None) -> tuple:
    """(srs_name, srs_id, organization, organization_coordsys_id, definition) of the study's CRS."""
    if crs_wkt is None:
        return None
    from pyproj import CRS

    crs = CRS.from_wkt(crs_wkt)
    auth = crs.to_authority()
    if auth is not None and auth[1].isdigit():
        code = int(auth[1])
        return (crs.name, code, auth[0], code, crs_wkt)
    return (crs.name, CUSTOM_SRS_ID, "NONE", CUSTOM_SRS_ID, crs_wkt)


def geometry_blob(geom, srs_id: int) -> bytes:
    """The standard's GeoPackageBinary of a polygon: "GP", version 0, flags (little-endian, an envelope of
    [minx, maxx, miny, maxy]), the SRS id, the envelope, then the geometry's WKB (little-endian)."""
    import shapely

    minx, miny, maxx, maxy = geom.bounds
    flags = 0b0000_0011  # bit 0: little-endian; bits 1-3: envelope type 1
    return b"GP" + struct.pack("<BBi4d", 0, flags, srs_id, minx, maxx, miny, maxy) + \
        shapely.to_wkb(geom, byte_order=1, output_dimension=2)


def _last_change() -> str:
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "")
    t = dt.datetime.fromtimestamp(int(epoch), dt.UTC) if epoch.isdigit() else dt.datetime.now(dt.UTC)
    return t.isoformat(timespec="milliseconds").replace("+00:00", "Z")  # the standard's form: ...T12:34:56.789Z


def fields_gpkg(path, spec, rows: list[dict]) -> Path:
    """Write ``path`` (a new file; module doc): a feature per row of fields.csv (``rows``: the field-seasons'
    summaries), its geometry the field's polygon in the study's CRS."""
    from shapely.geometry import Polygon

    path = Path(path)
    if path.exists():
        path.unlink()
    srs = _srs(spec.crs)
    srs_id = -1 if srs is None else srs[1]
    rings = {f.field_id: Polygon(f.world_ring) for f in spec.fields}
    cols = column_types(spec.depths_m)
    con = sqlite3.connect(path)
    try:
        con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        con.execute(f"PRAGMA user_version = {USER_VERSION}")
        con.execute("CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, "
                    "organization TEXT NOT NULL, organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, "
                    "description TEXT)")
        con.executemany("INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, ?, ?, ?, ?)", _REQUIRED_SRS)
        if srs is not None and srs[1] not in (4326, -1, 0):
            con.execute("INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, ?, ?, ?, ?)", (*srs, "the study's crs"))
        con.execute("CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, "
                    "identifier TEXT UNIQUE, description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT "
                    "(strftime('%Y-%m-%dT%H:%M:%fZ','now')), min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, "
                    "srs_id INTEGER, CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES "
                    "gpkg_spatial_ref_sys(srs_id))")
        con.execute("CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT NULL, "
                    "geometry_type_name TEXT NOT NULL, srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT "
                    "NULL, CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name), CONSTRAINT uk_gc_table_name "
                    "UNIQUE (table_name), CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES "
                    "gpkg_contents(table_name), CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES "
                    "gpkg_spatial_ref_sys (srs_id))")
        decl = ", ".join(f'"{c}" {t}' for c, t in cols)
        con.execute(f'CREATE TABLE "{TABLE}" (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom POLYGON, {decl})')
        used = [rings[r["field_id"]] for r in rows]
        b = [g.bounds for g in used] or [(0.0, 0.0, 0.0, 0.0)]
        box = (min(x[0] for x in b), min(x[1] for x in b), max(x[2] for x in b), max(x[3] for x in b))
        con.execute("INSERT INTO gpkg_contents VALUES (?, 'features', ?, ?, ?, ?, ?, ?, ?, ?)",
                    (TABLE, TABLE, f"region study {spec.name}: one feature per field and season (the columns of "
                     "fields.csv)", _last_change(), *box, srs_id))
        con.execute("INSERT INTO gpkg_geometry_columns VALUES (?, 'geom', 'POLYGON', ?, 0, 0)", (TABLE, srs_id))
        names = ", ".join(f'"{c}"' for c, _ in cols)
        marks = ", ".join("?" for _ in cols)
        values = []
        for r, g in zip(rows, used, strict=True):
            vals = []
            for c, t in cols:
                v = r.get(c)
                vals.append(None if v is None else cell_text(v) if t == "TEXT" else int(v) if t == "INTEGER"
                            else float(v))
            values.append((geometry_blob(g, srs_id), *vals))
        con.executemany(f'INSERT INTO "{TABLE}" (geom, {names}) VALUES (?, {marks})', values)
        con.commit()
    finally:
        con.close()
    return path
