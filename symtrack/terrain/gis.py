"""GIS rasters in and out: soil maps from GeoTIFF, the field's state as GeoTIFF layers and as one
NetCDF dataset (user documentation: docs/terrain.md, "GIS rasters").

The optional extra ``symtrack[gis]`` brings rasterio (GeoTIFF, the CRS), pyproj (the CF grid
mapping of a CRS) and xarray (NetCDF, written by SciPy's NetCDF-3 writer: SciPy is already
installed with python-control, so the extra adds no HDF5 library). They are imported on first use:
without them symtrack runs everything else, and a raster feature stops with
:class:`~symtrack.foundations.errors.MissingExtraError` naming ``pip install 'symtrack[gis]'``.

Coordinates: world x, y of a field are the coordinates of its CRS, in metres (a projected CRS:
UTM, a national grid). Cell (i, j) of a :class:`~symtrack.terrain.storage.Grid` is the square
[x0 + i dx, x0 + (i + 1) dx] x [y0 + j dx, y0 + (j + 1) dx]; a raster is north up, row 0 at the
top (its largest y). A field without a CRS is written in its local coordinates, without one.

In (:func:`read_header`, :func:`field_geometry`, :func:`read_soil_raster`): a single-band
integer GeoTIFF, north up (no rotation), in a projected CRS in metres (or none). Each cell takes
the value of the pixel that holds its centre, so the raster may be finer or coarser than the
field; it must cover the whole field and have no nodata pixel under it.

Out (:func:`export_terrain`, schema version :data:`GIS_SCHEMA_VERSION`): the layers of
:data:`LAYERS`, one GeoTIFF per layer (``<name>.tif``, deflate, band descriptions and units; the
depth layers one band per depth) and/or one NetCDF-3 dataset (dims ``depth``, ``y``, ``x``;
coordinates the cell centres in metres; each variable with ``units``, ``long_name`` and
``grid_mapping = "spatial_ref"``, the CRS as WKT in that variable's ``crs_wkt`` and
``spatial_ref``, the attributes GDAL, QGIS and rioxarray read, and the CF grid mapping's
``grid_mapping_name`` and parameters (CF-1.8 appendix F, from pyproj) for CF readers). Both are written atomically.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
from pathlib import Path

import numpy as np

from ..foundations.errors import MissingExtraError, ScenarioError
from ..foundations.files import atomic_write_bytes
from ..soil import density
from ..soil.subsoil import risk_class
from .storage import Grid, Terrain

__all__ = ["GEOTIFF_SUFFIXES", "GIS_EXTRA", "GIS_SCHEMA_VERSION", "LAYERS", "Layer", "RasterHeader",
           "check_covers", "crs_label", "crs_wkt", "export_terrain", "field_geometry", "is_geotiff", "layer_arrays",
           "read_band", "read_header", "read_npy", "read_soil_raster", "same_crs", "write_geotiffs", "write_netcdf"]

GIS_EXTRA = "pip install 'symtrack[gis]'"
GEOTIFF_SUFFIXES = (".tif", ".tiff")
GIS_SCHEMA_VERSION = 2  # 2: the layers elevation_m and surface_m (the ground's shape)


def _extra(module: str, feature: str):
    """The optional package ``module`` (of the extra symtrack[gis]), imported on first use."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise MissingExtraError(f"{feature} needs the optional GIS packages ({module} is not installed): "
                                f"{GIS_EXTRA}") from err


def read_npy(path, where: str) -> np.ndarray:
    """A raster given as a ``.npy`` array (a soil map's indices, an elevation), read without
    pickles; errors name ``where`` (the scenario key) and the path. The caller checks its shape and type."""
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{where} = {str(path)!r}: no such file")
    try:
        return np.load(p, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise ScenarioError(f"{where} = {str(path)!r}: not a .npy array ({err})") from err


def is_geotiff(path) -> bool:
    return str(path).lower().endswith(GEOTIFF_SUFFIXES)


# ---- CRS ------------------------------------------------------------------------------------------

def _crs(text: str, where: str):
    rio_crs = _extra("rasterio.crs", f"{where} (a CRS)")
    rio_errors = _extra("rasterio.errors", f"{where} (a CRS)")
    try:
        crs = rio_crs.CRS.from_user_input(text)
    except (rio_errors.CRSError, ValueError, TypeError) as err:
        raise ScenarioError(f"{where} = {text!r} is not a CRS rasterio knows (EPSG:32633, a WKT, a PROJ "
                            f"string): {err}") from err
    _check_metric(crs, where, text)
    return crs


def _check_metric(crs, where: str, text) -> None:
    unit, factor = crs.linear_units_factor if crs.is_projected else (crs.linear_units, 0.0)
    if not crs.is_projected or factor != 1.0:
        raise ScenarioError(f"{where} = {str(text)[:80]!r}: the CRS must be projected in metres (UTM, a national "
                            f"grid): the field's cells are squares in metres; it is "
                            f"{'projected in ' + str(unit) if crs.is_projected else 'geographic (degrees)'}")


def crs_wkt(text: str, where: str = "--crs") -> str:
    """The WKT of a CRS given as ``EPSG:32633``, a WKT or a PROJ string (projected, in metres)."""
    return _crs(text, where).to_wkt()


def same_crs(a: str | None, b: str | None) -> bool:
    """Whether two CRSs (WKT or any text :func:`crs_wkt` takes) are the same; None is no CRS."""
    if a is None or b is None:
        return a is None and b is None
    return a == b or _crs(a, "a CRS") == _crs(b, "a CRS")


def crs_label(wkt: str | None) -> str:
    if wkt is None:
        return "no CRS"
    crs = _crs(wkt, "a CRS")
    epsg = crs.to_epsg()
    return f"EPSG:{epsg}" if epsg else wkt.split('"')[1] if '"' in wkt else wkt[:40]


# ---- in: soil maps ---------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RasterHeader:
    """A raster's georeference (north up): its file, CRS (WKT or None), edges in metres, pixel
    sizes, pixels along x (width) and y (height), the band's type and nodata value."""

    path: str
    crs_wkt: str | None
    left_m: float
    bottom_m: float
    right_m: float
    top_m: float
    pixel_x_m: float
    pixel_y_m: float
    width: int
    height: int
    dtype: str
    nodata: float | None


def read_header(path, where: str = "terrain.soil_map.raster", values: str = "integer") -> RasterHeader:
    """The header of a single-band GeoTIFF, north up, in a projected CRS in metres (or none), of
    integers (``values = "integer"``: a soil map) or of any numbers (``"real"``: an elevation map,
    symtrack.terrain.surface); anything else is a :class:`ScenarioError` naming ``where``."""
    rio = _extra("rasterio", f"{where} = {str(path)!r} (a GeoTIFF)")
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{where} = {str(path)!r}: no such file")
    try:
        with rio.open(p) as ds:
            t, count, dtype, crs, nodata = ds.transform, ds.count, ds.dtypes[0], ds.crs, ds.nodata
            width, height = ds.width, ds.height
    except rio.errors.RasterioIOError as err:
        raise ScenarioError(f"{where} = {str(path)!r}: not a raster GDAL reads ({err})") from err
    if values == "integer" and (count != 1 or np.dtype(dtype).kind not in "iu"):
        raise ScenarioError(f"{where} = {str(path)!r}: a soil map is one band of integers (the soil of each "
                            f"pixel), the file has {count} band(s) of {dtype}")
    if values == "real" and (count != 1 or np.dtype(dtype).kind not in "iuf"):
        raise ScenarioError(f"{where} = {str(path)!r}: an elevation map is one band of heights in m, the file has "
                            f"{count} band(s) of {dtype}")
    if t.b != 0 or t.d != 0 or not (t.a > 0 and t.e < 0):
        raise ScenarioError(f"{where} = {str(path)!r}: the raster must be north up (transform (dx, 0, x0, 0, -dy, "
                            f"y0), dx, dy > 0), its transform is {tuple(t)[:6]}: warp it first (gdalwarp)")
    if crs is not None:
        _check_metric(crs, where, path)
    return RasterHeader(str(path), None if crs is None else crs.to_wkt(), float(t.c), float(t.f + height * t.e),
                        float(t.c + width * t.a), float(t.f), float(t.a), float(-t.e), int(width), int(height),
                        str(dtype), None if nodata is None else float(nodata))


def field_geometry(h: RasterHeader, where: str = "terrain.soil_map.raster") -> dict:
    """The field a raster describes, as ``[terrain]`` keys: ``origin_m`` its lower-left corner,
    ``cell_m`` its pixel (square pixels only), ``size_m`` its extent."""
    if not np.isclose(h.pixel_x_m, h.pixel_y_m, rtol=1e-9, atol=0.0):
        raise ScenarioError(f"{where} = {h.path!r} has pixels of {h.pixel_x_m:g} x {h.pixel_y_m:g} m: the field's "
                            "cells are square; give terrain.cell_m (the raster is then sampled at the cell centres)")
    return {"origin_m": (h.left_m, h.bottom_m), "cell_m": h.pixel_x_m,
            "size_m": (h.width * h.pixel_x_m, h.height * h.pixel_y_m)}


def check_covers(h: RasterHeader, grid: Grid, where: str = "terrain.soil_map.raster") -> None:
    """A :class:`ScenarioError` unless the raster covers the whole field."""
    x0, x1, y0, y1 = grid.bounds()
    tol = 1e-6 * grid.cell_m
    if x0 < h.left_m - tol or x1 > h.right_m + tol or y0 < h.bottom_m - tol or y1 > h.top_m + tol:
        raise ScenarioError(
            f"{where} = {h.path!r} covers x in [{h.left_m:.10g}, {h.right_m:.10g}] m, y in [{h.bottom_m:.10g}, "
            f"{h.top_m:.10g}] m ({crs_label(h.crs_wkt)}); the field is x in [{x0:.10g}, {x1:.10g}] m, y in "
            f"[{y0:.10g}, {y1:.10g}] m: the raster must cover the whole field (move or shrink the field with "
            "terrain.origin_m and size_m, or give a larger raster)")


def read_band(path, where: str) -> np.ndarray:
    """The first band of a GeoTIFF as stored (rows from the top); its header checked by :func:`read_header`."""
    rio = _extra("rasterio", where)
    with rio.open(Path(path)) as ds:
        return ds.read(1)


def read_soil_raster(path, grid: Grid, where: str = "terrain.soil_map.raster") -> np.ndarray:
    """The raster's value at every cell centre of ``grid``, (nx, ny) int64: the pixel that holds
    the centre. The raster must cover the field (:func:`check_covers`) with no nodata under it."""
    h = read_header(path, where)
    check_covers(h, grid, where)
    rio = _extra("rasterio", where)
    with rio.open(Path(path)) as ds:
        data = ds.read(1)
    nx, ny = grid.shape
    xc, yc = grid.centres(np.arange(nx), np.arange(ny))
    col = np.clip(np.floor((xc - h.left_m) / h.pixel_x_m).astype(np.int64), 0, h.width - 1)
    row = np.clip(np.floor((h.top_m - yc) / h.pixel_y_m).astype(np.int64), 0, h.height - 1)
    values = data[row[None, :], col[:, None]].astype(np.int64)  # (nx, ny): cell (i, j) <- pixel (row_j, col_i)
    if h.nodata is not None and np.any(values == h.nodata):
        n = int(np.count_nonzero(values == h.nodata))
        raise ScenarioError(f"{where} = {h.path!r}: {n} cell(s) of the field lie on nodata pixels ({h.nodata:g}): "
                            "every cell needs a soil")
    return values


# ---- out: layers -----------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Layer:
    """One exported layer: its file stem and NetCDF variable ``name``, ``long_name``, ``units``
    (UDUNITS; "1" for counts and classes), the GeoTIFF type and the NetCDF-3 type, and whether it
    has one band per subsoil depth."""

    name: str
    long_name: str
    units: str
    dtype: str
    netcdf_dtype: str
    per_depth: bool = False


LAYERS = (
    Layer("rut_depth", "rut depth: the sinkage z of the cell after the last pass (elastic rebound included)", "m",
          "float32", "float32"),
    Layer("max_sinkage", "largest sinkage z_max the cell has reached", "m", "float32", "float32"),
    Layer("max_pressure", "largest contact pressure p_max on the cell's loading branch", "Pa", "float32", "float32"),
    Layer("cycle_sinkage", "plastic sinkage of the later load cycles z_off (the cycle law)", "m", "float32",
          "float32"),
    Layer("passes", "load cycles the cell has seen (its passes)", "1", "uint16", "int32"),
    Layer("soil_index", "the cell's soil: 0 the terrain's soil, k soil k of its soil map", "1", "uint8", "int8"),
    Layer("precompression_stress", "precompression stress sigma_pc of the cell's soil (its strength; a soil of two "
          "layers: its topsoil's)", "Pa",
          "float32", "float32"),
    Layer("elevation_m", "initial elevation z0 of the cell centre (the ground's shape before any pass; 0: flat)",
          "m", "float64", "float64"),
    Layer("surface_m", "the ground now: the elevation minus the cell's sinkage (z0 - z)", "m", "float64", "float64"),
    Layer("stress_max", "largest vertical stress at the depth over all passes (the subsoil record)", "Pa", "float32",
          "float32", per_depth=True),
    Layer("risk_class", "compaction risk class at the depth (Terranimo): 0 low, 1 medium, 2 high", "1", "uint8",
          "int8", per_depth=True),
)


def _soils(terrain: Terrain) -> list[dict]:
    """The terrain's soils, soil 0 its own, then its soil map's (as vehicles/wheeled.py's terrain_soils)."""
    soil = terrain.soil or {}
    return [dict(soil)] + [{**soil, **sp} for _, sp in terrain.soil_table]


def layer_arrays(terrain: Terrain) -> dict:
    """The layers of :data:`LAYERS` of a terrain: name -> array (nx, ny) or (nx, ny, n_depths) in
    the layer's GeoTIFF type (the depth layers only when the terrain has subsoil depths)."""
    shape = terrain.grid.shape
    nd = len(terrain.subsoil_depths_m)
    soil = terrain.soil or {}
    pcs = [soil.get("precompression_stress_Pa", np.nan)] + [sp["precompression_stress_Pa"]
                                                             for _, sp in terrain.soil_table]
    pc = np.asarray(pcs, dtype=float)[terrain.soil_index].reshape(shape)
    out = {"rut_depth": terrain.z, "max_sinkage": terrain.zmax, "max_pressure": terrain.pmax,
           "cycle_sinkage": terrain.zoff, "passes": terrain.cycles, "soil_index": terrain.soil_index}
    out["elevation_m"] = np.zeros(terrain.grid.n_cells) if terrain.elevation is None else terrain.elevation
    out["surface_m"] = terrain.surface_m()
    out = {k: v.reshape(shape) for k, v in out.items()}
    out["precompression_stress"] = pc
    if nd:
        sig = terrain.sigma_max.reshape(*shape, nd)
        out["stress_max"] = sig
        # the risk grades the traffic's stress plus the soil's own weight (soil/density.py)
        geo = density.geostatic_table(_soils(terrain), terrain.subsoil_depths_m)[terrain.soil_index].reshape(sig.shape)
        # against each depth's strength (a subsoil layer has its own)
        pcd = (density.precompression_table(_soils(terrain), terrain.subsoil_depths_m)[terrain.soil_index]
               .reshape(sig.shape) if terrain.soil else pc[..., None])
        out["risk_class"] = risk_class(np.where(sig > 0, sig + geo, sig), pcd)
    types = {layer.name: layer.dtype for layer in LAYERS}
    return {k: v.astype(types[k]) for k, v in out.items()}


def _north_up(a: np.ndarray) -> np.ndarray:
    """(nx, ny) with j along +y -> raster rows (ny, nx), row 0 at the top."""
    return np.ascontiguousarray(a.T[::-1, :])


def write_geotiffs(terrain: Terrain, folder, crs: str | None = None) -> list[Path]:
    """Write each layer as ``folder/<name>.tif`` (module doc); returns the files written."""
    rio_io = _extra("rasterio.io", "GeoTIFF export")
    transform = _extra("rasterio.transform", "GeoTIFF export")
    g = terrain.grid
    x0, _, _, y1 = g.bounds()
    crs_obj = None if crs is None else _crs(crs, "the terrain's CRS")
    depths = terrain.subsoil_depths_m
    written = []
    for name, a in layer_arrays(terrain).items():
        layer = next(la for la in LAYERS if la.name == name)
        bands = [a[..., k] for k in range(a.shape[2])] if layer.per_depth else [a]
        profile = {"driver": "GTiff", "width": g.shape[0], "height": g.shape[1], "count": len(bands),
                   "dtype": layer.dtype, "crs": crs_obj, "transform": transform.from_origin(x0, y1, g.cell_m, g.cell_m),
                   "compress": "deflate"}
        with rio_io.MemoryFile() as mem:
            with mem.open(**profile) as ds:
                for b, arr in enumerate(bands, start=1):
                    ds.write(_north_up(arr), b)
                    at = f" at {depths[b - 1]:g} m" if layer.per_depth else ""
                    ds.set_band_description(b, f"{name}{at} [{layer.units}]")
                    ds.set_band_unit(b, layer.units)
                    ds.update_tags(b, units=layer.units, long_name=layer.long_name + at,
                                   **({"depth_m": f"{depths[b - 1]!r}"} if layer.per_depth else {}))
                ds.update_tags(symtrack_kind="symtrack-terrain-layer", symtrack_schema_version=str(GIS_SCHEMA_VERSION),
                               layer=name, units=layer.units, long_name=layer.long_name)
            data = mem.read()
        path = Path(folder) / f"{name}.tif"
        atomic_write_bytes(path, data)
        written.append(path)
    return written


def _dataset(terrain: Terrain, crs: str | None):
    xr = _extra("xarray", "NetCDF export")
    g = terrain.grid
    nx, ny = g.shape
    xc, yc = g.centres(np.arange(nx), np.arange(ny))
    coords = {"x": ("x", xc, {"units": "m", "long_name": "x of the cell centre", "axis": "X",
                              "standard_name": "projection_x_coordinate"}),
              "y": ("y", yc, {"units": "m", "long_name": "y of the cell centre", "axis": "Y",
                              "standard_name": "projection_y_coordinate"})}
    depths = terrain.subsoil_depths_m
    if depths:
        coords["depth"] = ("depth", np.asarray(depths, dtype=float),
                           {"units": "m", "long_name": "depth below the surface", "positive": "down", "axis": "Z"})
    ds = xr.Dataset(coords=coords)
    for name, a in layer_arrays(terrain).items():
        layer = next(la for la in LAYERS if la.name == name)
        attrs = {"units": layer.units, "long_name": layer.long_name}
        if crs is not None:
            attrs["grid_mapping"] = "spatial_ref"
        if layer.per_depth:
            ds[name] = (("depth", "y", "x"), np.transpose(a, (2, 1, 0)).astype(layer.netcdf_dtype), attrs)
        else:
            ds[name] = (("y", "x"), a.T.astype(layer.netcdf_dtype), attrs)
    if crs is not None:
        wkt = crs_wkt(crs, "the terrain's CRS")
        # a coordinate, as rioxarray writes it (GDAL derives the transform from x, y), with the CF
        # grid-mapping attributes (grid_mapping_name and its parameters, CF-1.8 appendix F) that pyproj
        # derives from the CRS, so that CF readers without WKT support know the projection too
        cf = _extra("pyproj", "NetCDF export with a CRS").CRS.from_wkt(wkt).to_cf()
        attrs = {k: v for k, v in cf.items() if k != "crs_wkt" and v is not None}
        ds = ds.assign_coords(spatial_ref=((), np.int32(0), {**attrs, "crs_wkt": wkt, "spatial_ref": wkt,
                                                             "long_name": "coordinate reference system"}))
    ds.attrs = {"Conventions": "CF-1.8", "title": "symtrack field state", "source": "symtrack (symtrack.terrain.gis)",
                "symtrack_kind": "symtrack-terrain-dataset", "symtrack_schema_version": np.int32(GIS_SCHEMA_VERSION),
                "cell_m": float(g.cell_m), "origin_m": np.asarray(g.origin_m, dtype=float),
                "soil_labels": json.dumps(["the terrain's soil"] + [lab for lab, _ in terrain.soil_table])}
    return ds


def write_netcdf(terrain: Terrain, path, crs: str | None = None) -> Path:
    """Write the layers as one NetCDF-3 dataset (module doc), atomically; returns the file."""
    ds = _dataset(terrain, crs)
    encoding = {v: {"_FillValue": None} for v in ds.variables}
    data = ds.to_netcdf(engine="scipy", encoding=encoding)
    atomic_write_bytes(Path(path), bytes(data))
    return Path(path)


def export_terrain(terrain, geotiff_dir=None, netcdf=None, crs: str | None = None) -> dict:
    """Export a terrain (a :class:`Terrain` or a terrain file) as GeoTIFF layers in
    ``geotiff_dir`` and/or one NetCDF dataset ``netcdf``. ``crs``: the CRS of a terrain that has
    none (a terrain that has one keeps it; another is an error). Returns {"geotiff": [files],
    "netcdf": file, "crs": WKT or None}."""
    if geotiff_dir is None and netcdf is None:
        raise ScenarioError("export_terrain: give geotiff_dir and/or netcdf (nothing to write)")
    if geotiff_dir is not None:
        _extra("rasterio", "GeoTIFF export")
    if netcdf is not None:
        _extra("xarray", "NetCDF export")
    if not isinstance(terrain, Terrain):
        terrain = Terrain.load(terrain)
    wkt = terrain.crs_wkt
    if crs is not None:
        given = crs_wkt(crs)
        if wkt is not None and not same_crs(wkt, given):
            raise ScenarioError(f"--crs = {crs!r}: the terrain was made in {crs_label(wkt)}; its coordinates are "
                                "in that CRS (leave --crs out, or give the same)")
        wkt = wkt if wkt is not None else given
    out = {"geotiff": [], "netcdf": None, "crs": wkt}
    if geotiff_dir is not None:
        out["geotiff"] = write_geotiffs(terrain, geotiff_dir, wkt)
    if netcdf is not None:
        out["netcdf"] = write_netcdf(terrain, netcdf, wkt)
    return out
