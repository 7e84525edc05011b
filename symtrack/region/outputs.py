"""A region study's outputs (docs/region.md, "Outputs"): the per-field table (``fields.csv``), the region's maps
(Cloud-Optimized GeoTIFFs per season and over the years), the region's figures (``summary.json``) and
``report.html``, and ``fields.gpkg`` (:mod:`symtrack.region.gpkg`); and each field-season's maps as
Cloud-Optimized GeoTIFFs on its own grid (:func:`field_cogs`, written by its task and committed with its
maps.npz: symtrack.region.study).

Committed once: the top-level files (region.json, fields.csv, fields.gpkg, maps/, the report's images,
report.html, summary.json) are written by the package's one run writer,
:func:`symtrack.reports.run_files.write_folder` (without clearing: the field-seasons' folders stay): staged
beside the folder, then moved into place after its journal, summary.json last. A study killed while it writes
them leaves the folder's earlier outputs (none, or those of the run before) or, past the commit point, a journal
the next writer completes; never a mixture.

The maps are on one grid over the region (the fields' bounding box in the region's CRS, ``map_cell_m``
cells, north up): each map cell takes the value of the field cell its centre falls in (nearest neighbour;
no value outside the fields). Layers, each a file with a band per depth where it has depths:

==============================  ==========  =================================================================
file                            type        value
==============================  ==========  =================================================================
``trafficked_count.tif``        uint16      passes in the season (over the years: their sum); 65535 no data
``stress_max_kPa.tif``          float32     largest vertical traffic stress at the depth [kPa]; NaN no data
``density_change_Mg_per_m3.tif`` float32    dry bulk density minus the initial one at the depth after the
                                            season [Mg/m^3]; NaN no data
``risk_class.tif``              uint8       Terranimo's class of the season's largest (stress + own weight) /
                                            precompression stress: 0 low, 1 medium, 2 high; 255 no data
==============================  ==========  =================================================================
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..reports.html import report_html
from ..reports.run_files import write_folder
from .gpkg import fields_gpkg
from .table import TABLE_COLUMNS, fields_csv

__all__ = ["LAYERS", "TABLE_COLUMNS", "fields_csv", "region_grid", "write_outputs"]

RISK_NAMES = ("low", "medium", "high")
LAYERS = {  # name: (dtype, nodata, per depth, unit, long name)
    "trafficked_count": ("uint16", 65535, False, "1", "passes per cell"),
    "stress_max_kPa": ("float32", float("nan"), True, "kPa", "largest vertical traffic stress"),
    "density_change_Mg_per_m3": ("float32", float("nan"), True, "Mg/m^3", "dry bulk density minus the initial one"),
    "risk_class": ("uint8", 255, True, "1", "compaction risk class (0 low, 1 medium, 2 high)"),
}
# ---- the region's maps -----------------------------------------------------------------------------------------
def region_grid(spec) -> tuple:
    """(x0, y1, nx, ny): the region grid's west and north edges and its size in map cells."""
    pts = np.vstack([np.array(f.world_ring) for f in spec.fields])
    c = spec.map_cell_m
    x0, y0 = np.floor(pts.min(axis=0) / c) * c
    x1, y1 = np.ceil(pts.max(axis=0) / c) * c
    return float(x0), float(y1), int(round((x1 - x0) / c)), int(round((y1 - y0) / c))


def _paint(spec, f, maps: dict, canvas: dict, grid) -> None:
    """The field's maps (its own grid) into the region's canvases (rows north first) by nearest neighbour."""
    x0, y1, nx, ny = grid
    c = spec.map_cell_m
    ring = np.array(f.world_ring)
    lo, hi = ring.min(axis=0), ring.max(axis=0)
    i0, i1 = max(int((lo[0] - x0) / c) - 1, 0), min(int((hi[0] - x0) / c) + 2, nx)
    r0, r1 = max(int((y1 - hi[1]) / c) - 1, 0), min(int((y1 - lo[1]) / c) + 2, ny)
    X = x0 + (np.arange(i0, i1) + 0.5) * c
    Y = y1 - (np.arange(r0, r1) + 0.5) * c
    XX, YY = np.meshgrid(X, Y)
    lx, ly = f.to_local(XX, YY)
    fm = maps["field_mask"]
    cell = float(maps["cell_m"])
    ii, jj = np.floor(lx / cell).astype(np.int64), np.floor(ly / cell).astype(np.int64)
    ok = (ii >= 0) & (jj >= 0) & (ii < fm.shape[0]) & (jj < fm.shape[1])
    ii, jj = np.where(ok, ii, 0), np.where(ok, jj, 0)
    ok &= fm[ii, jj]
    for name, arr in canvas.items():
        src = maps[name]
        win = arr[..., r0:r1, i0:i1]
        if src.ndim == 2:
            win[ok] = src[ii[ok], jj[ok]]
        else:
            vals = src[ii[ok], jj[ok]]  # (n, n_depths)
            for k in range(src.shape[2]):
                win[k][ok] = vals[:, k]


def _canvas(nd: int, ny: int, nx: int) -> dict:
    out = {}
    for name, (dtype, nodata, per_depth, _, _) in LAYERS.items():
        shape = (nd, ny, nx) if per_depth else (ny, nx)
        out[name] = np.full(shape, nodata, dtype=dtype)
    return out


# the maps are painted and written in tiles of this many map cells a side: the memory is bounded whatever the
# region's size (a 2,000 km^2 region at 1 m is 2e9 cells a layer)
TILE_CELLS = 1024
# the report's maps: at most this many pixels across (the region's maps decimated)
PREVIEW_PX = 1200


def _open_layer(path: Path, name: str, spec, grid, depths):
    """A scratch GeoTIFF for one layer (tiled, deflate), with its bands' descriptions and tags, beside ``path``
    (in the study's scratch folder)."""
    import rasterio
    from rasterio.transform import from_origin

    dtype, nodata, per_depth, unit, long_name = LAYERS[name]
    x0, y1, nx, ny = grid
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".scratch.tif", dir=path.parent)
    os.close(fd)
    ds = rasterio.open(tmp, "w", driver="GTiff", width=nx, height=ny, count=len(depths) if per_depth else 1,
                       dtype=dtype, crs=spec.crs, transform=from_origin(x0, y1, spec.map_cell_m, spec.map_cell_m),
                       nodata=nodata, tiled=True, blockxsize=512, blockysize=512, compress="deflate",
                       BIGTIFF="IF_SAFER")
    _describe(ds, name, depths)
    ds.update_tags(symtrack_kind="symtrack-region-layer", layer=name, units=unit, long_name=long_name)
    return ds, tmp


def _describe(ds, name: str, depths) -> None:
    """The bands' descriptions and tags of one layer's GeoTIFF (the region's maps and a field's own): its name,
    unit and long name, and the depth of each band where the layer has depths."""
    _, _, per_depth, unit, long_name = LAYERS[name]
    for b in range(ds.count):
        at = f" at {depths[b]:g} m" if per_depth else ""
        ds.set_band_description(b + 1, f"{name}{at} [{unit}]")
        ds.update_tags(b + 1, units=unit, long_name=long_name + at, **({"depth_m": repr(depths[b])} if per_depth
                                                                      else {}))


# GDAL's COG driver's options of every map the study writes
COG_OPTIONS = {"driver": "COG", "compress": "DEFLATE", "overview_resampling": "NEAREST"}


def _finish_cog(ds, tmp: str, path: Path) -> None:
    """The scratch GeoTIFF copied as a Cloud-Optimized GeoTIFF (GDAL's COG driver: tiled, overviews) into
    ``path`` (in the study's scratch folder: the commit moves it into place); the scratch removed."""
    from rasterio.shutil import copy as rio_copy

    ds.close()
    try:
        rio_copy(tmp, path, **COG_OPTIONS, BIGTIFF="IF_SAFER")
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


# ---- a field-season's own maps -----------------------------------------------------------------------------------
# the layers of a field-season's maps.npz, by the name of their file
FIELD_ARRAYS = {"trafficked_count": "counts", "stress_max_kPa": "sigma_max_kPa",
                "density_change_Mg_per_m3": "density_change_Mg_per_m3", "risk_class": "risk_class"}


def field_transform(f, cell_m: float, shape: tuple):
    """The affine transform of a field's own grid (``shape`` cells (along the track lines, across them) of
    ``cell_m``) in the region's CRS: the raster's columns run along the field's x (the track lines), its rows
    down its y, so row r holds the field's cells j = shape[1] - 1 - r (:func:`field_band`); rotated by the
    field's theta (north up where theta is 0)."""
    from affine import Affine

    c, s = math.cos(f.theta_rad), math.sin(f.theta_rad)
    ox, oy = f.to_world(0.0, shape[1] * cell_m)  # the raster's corner: local (0, top)
    return Affine(c * cell_m, s * cell_m, float(ox), s * cell_m, -c * cell_m, float(oy))


def field_band(arr: np.ndarray, k: int | None = None) -> np.ndarray:
    """A field's map (cells (i along x, j along y[, depth])) as a raster band: rows down y, columns along x."""
    a = arr if k is None else arr[..., k]
    return np.ascontiguousarray(a.T[::-1])


def field_cogs(spec, f, arrays: dict) -> dict:
    """A field-season's maps (``arrays``: its maps.npz's arrays, by their names there) as Cloud-Optimized
    GeoTIFFs on the field's own grid (:func:`field_transform`), the layers and bands of the region's maps:
    {"<layer>.tif": bytes}. Written in GDAL's memory file system (nothing on the worker's disk), a band at a
    time."""
    import rasterio
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy as rio_copy

    shape = arrays["counts"].shape
    transform = field_transform(f, spec.cell_m, shape)
    depths = spec.depths_m
    out = {}
    for name, key in FIELD_ARRAYS.items():
        dtype, nodata, per_depth, unit, long_name = LAYERS[name]
        src = arrays[key]
        with MemoryFile() as scratch, MemoryFile() as cog:
            with scratch.open(driver="GTiff", width=shape[0], height=shape[1], count=len(depths) if per_depth else 1,
                              dtype=dtype, crs=spec.crs, transform=transform, nodata=nodata, tiled=True,
                              blockxsize=512, blockysize=512) as ds:
                _describe(ds, name, depths)
                for b in range(ds.count):
                    ds.write(field_band(src, b if per_depth else None).astype(dtype, copy=False), b + 1)
                ds.update_tags(symtrack_kind="symtrack-region-field-layer", layer=name, units=unit,
                               long_name=long_name, field_id=f.field_id, cell_m=repr(float(spec.cell_m)),
                               lines_direction_deg=repr(math.degrees(f.theta_rad)))
            with rasterio.open(scratch.name) as ds:
                rio_copy(ds, cog.name, **COG_OPTIONS)
            out[f"{name}.tif"] = cog.read()
    return out


def _read_maps(path: Path) -> dict:
    with np.load(path) as z:
        return {**{layer: z[key] for layer, key in FIELD_ARRAYS.items()}, "field_mask": z["field_mask"],
                "cell_m": z["cell_m"]}


def _combine(cs: list) -> dict:
    """Over the years: passes summed, the largest stress and class, the density after the last season."""
    inside = cs[0]["risk_class"][0] != 255
    tc = np.sum([c["trafficked_count"].astype(np.int64) for c in cs], axis=0)
    return {"trafficked_count": np.where(inside, np.minimum(tc, 65534), 65535).astype(np.uint16),
            "stress_max_kPa": np.fmax.reduce([c["stress_max_kPa"] for c in cs]),
            "density_change_Mg_per_m3": cs[-1]["density_change_Mg_per_m3"],
            "risk_class": np.where(cs[0]["risk_class"] == 255, 255,
                                   np.max([c["risk_class"] for c in cs], axis=0)).astype(np.uint8)}


def write_maps(spec, out: Path, scratch: Path):
    """The region's maps per season and over the years (module doc), painted from the field-seasons' maps in
    ``out``/fields and written tile by tile into ``scratch``/maps; returns (the files written, the decimated
    maps of each season and over the years for the report)."""
    from rasterio.windows import Window

    grid = region_grid(spec)
    x0, y1, nx, ny = grid
    c = spec.map_cell_m
    nd = len(spec.depths_m)
    keys = [str(y) for y in spec.years] + ["all_years"]
    step = max(1, int(math.ceil(max(nx, ny) / PREVIEW_PX)))
    previews = {k: _canvas(nd, (ny + step - 1) // step, (nx + step - 1) // step) for k in keys}
    files = {(k, name): _open_layer(scratch / "maps" / k / f"{name}.tif", name, spec, grid, spec.depths_m)
             for k in keys for name in LAYERS}
    boxes = []
    for f in spec.fields:
        ring = np.array(f.world_ring)
        lo, hi = ring.min(axis=0), ring.max(axis=0)
        boxes.append((int((lo[0] - x0) / c) - 1, int((hi[0] - x0) / c) + 2, int((y1 - hi[1]) / c) - 1,
                      int((y1 - lo[1]) / c) + 2))
    cache: dict = {}
    try:
        for r0 in range(0, ny, TILE_CELLS):
            for c0 in range(0, nx, TILE_CELLS):
                th, tw = min(TILE_CELLS, ny - r0), min(TILE_CELLS, nx - c0)
                tile = (x0 + c0 * c, y1 - r0 * c, tw, th)
                inside = [k for k, (i0, i1, j0, j1) in enumerate(boxes)
                          if i1 > c0 and i0 < c0 + tw and j1 > r0 and j0 < r0 + th]
                canv = {}
                for y in spec.years:
                    cv = _canvas(nd, th, tw)
                    for k in inside:
                        key = (k, y)
                        if key not in cache:
                            if len(cache) > 32:  # the fields of a row of tiles (their seasons), at most
                                cache.pop(next(iter(cache)))
                            cache[key] = _read_maps(out / "fields" / spec.fields[k].field_id / str(y) / "maps.npz")
                        _paint(spec, spec.fields[k], cache[key], cv, tile)
                    canv[str(y)] = cv
                canv["all_years"] = _combine([canv[str(y)] for y in spec.years])
                win = Window(c0, r0, tw, th)
                pr, pc = (-r0) % step, (-c0) % step
                for k in keys:
                    for name, arr in canv[k].items():
                        ds, _ = files[(k, name)]
                        ds.write(arr if arr.ndim == 3 else arr[None], window=win)
                        pv = previews[k][name]
                        sub = arr[..., pr::step, pc::step]
                        R0, C0 = (r0 + pr) // step, (c0 + pc) // step
                        pv[..., R0:R0 + sub.shape[-2], C0:C0 + sub.shape[-1]] = sub
        written = []
        for (k, name), (ds, tmp) in files.items():
            p = scratch / "maps" / k / f"{name}.tif"
            _finish_cog(ds, tmp, p)
            written.append(p)
    finally:
        for ds, tmp in files.values():
            if not ds.closed:
                ds.close()
            if os.path.exists(tmp):
                os.unlink(tmp)
    return written, {y: previews[str(y)] for y in spec.years}, previews["all_years"]


# ---- the figures and the report ---------------------------------------------------------------------------------
def region_figures(spec, rows: list[dict]) -> dict:
    """Share of the region's area at each risk class by depth and year (area-weighted over the fields), the
    trafficked share, the mean density change by depth, and the worst fields."""
    out = {"schema_version": 1, "kind": "symtrack-region", "name": spec.name, "fields": len(spec.fields),
           "area_ha": spec.area_ha, "years": list(spec.years), "depths_m": list(spec.depths_m),
           "cell_m": spec.cell_m, "rule": spec.rule, "by_year": {}}
    for y in spec.years:
        rs = [r for r in rows if r["year"] == y]
        w = np.array([r["area_ha"] for r in rs])
        fy = {"trafficked_fraction": float(np.average([r["trafficked_fraction"] for r in rs], weights=w))}
        for d in spec.depths_m:
            tag = f"{d:g}m"
            for nm in RISK_NAMES:
                fy[f"risk_{nm}_fraction_{tag}"] = float(np.average([r[f"risk_{nm}_fraction_{tag}"] for r in rs],
                                                                   weights=w))
            fy[f"density_change_mean_{tag}_Mg_per_m3"] = float(np.average(
                [r[f"density_change_mean_{tag}_Mg_per_m3"] for r in rs], weights=w))
        out["by_year"][str(y)] = fy
    key = _worst_key(spec)
    last = [r for r in rows if r["year"] == spec.years[-1]]
    worst = sorted(last, key=lambda r: (-r[key], r["field_id"]))[:10]
    out["worst_fields"] = [{"field_id": r["field_id"], "soil": r["soil"], "system": r["system"], key: r[key]}
                           for r in worst]
    out["worst_fields_by"] = f"{key} in {spec.years[-1]}"
    out["wall_time_s_sum"] = float(sum(r.get("wall_time_s", 0.0) for r in rows))
    out["fields_full_fidelity"] = sorted({r["field_id"] for r in rows if r.get("fidelity") == "full"})
    out["fields_left_out"] = list(spec.skipped)
    return out


def _worst_key(spec) -> str:
    d = min(spec.depths_m, key=lambda x: abs(x - 0.3))
    return f"risk_high_fraction_{d:g}m"


def _map_png(spec, canvases: dict, title: str) -> bytes:
    """Passes per cell and the risk class at the depth nearest 0.3 m, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    k = int(np.argmin([abs(d - 0.3) for d in spec.depths_m]))
    tc = canvases["trafficked_count"].astype(float)
    tc[tc == 65535] = np.nan
    rk = canvases["risk_class"][k].astype(float)
    rk[rk == 255] = np.nan
    fig, ax = plt.subplots(1, 2, figsize=(12, 5.5))
    im = ax[0].imshow(tc, cmap="magma_r", interpolation="nearest")
    fig.colorbar(im, ax=ax[0], shrink=0.8, label="passes")
    ax[0].set_title(f"{title}: passes per cell")
    im2 = ax[1].imshow(rk, cmap=ListedColormap(["#4daf4a", "#ffbf00", "#e41a1c"]), vmin=-0.5, vmax=2.5,
                       interpolation="nearest")
    cb = fig.colorbar(im2, ax=ax[1], shrink=0.8, ticks=[0, 1, 2])
    cb.ax.set_yticklabels(list(RISK_NAMES))
    ax[1].set_title(f"{title}: risk class at {spec.depths_m[k]:g} m")
    for a in ax:
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def _shares_png(spec, figs: dict) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    years = [str(y) for y in spec.years]
    fig, axes = plt.subplots(1, len(years), figsize=(5 * len(years), 4), squeeze=False)
    colours = ("#4daf4a", "#ffbf00", "#e41a1c")
    for ax, y in zip(axes[0], years, strict=True):
        fy = figs["by_year"][y]
        bottom = np.zeros(len(spec.depths_m))
        labels = [f"{d:g} m" for d in spec.depths_m]
        for nm, col in zip(RISK_NAMES, colours, strict=True):
            v = np.array([100 * fy[f"risk_{nm}_fraction_{d:g}m"] for d in spec.depths_m])
            ax.bar(labels, v, bottom=bottom, color=col, label=nm)
            bottom += v
        ax.set_title(f"{y}: share of the area by risk class")
        ax.set_ylabel("% of the fields' area")
        ax.set_xlabel("depth")
    axes[0][0].legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


SCRATCH_PREFIX = ".symtrack-region-scratch-"


def write_outputs(spec, out: Path, rows: list[dict], region_json: str | None = None) -> dict:
    """The study's top-level files committed once (module doc, "Committed once"): ``region_json`` (the study's
    region.json), fields.csv, fields.gpkg, the maps, the report's images, report.html and summary.json, last;
    returns the region's figures. The maps are written into a scratch folder in ``out`` first (removed
    whatever happens; a killed run's is removed by the next, which holds the folder's lock)."""
    out = Path(out)
    for old in out.glob(SCRATCH_PREFIX + "*"):  # a killed run's (this process holds the folder's lock)
        shutil.rmtree(old, ignore_errors=True)
    scratch = Path(tempfile.mkdtemp(prefix=SCRATCH_PREFIX, dir=out))
    try:
        return _write_outputs(spec, out, rows, region_json, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _write_outputs(spec, out, rows, region_json, scratch) -> dict:
    files: dict = {}
    if region_json is not None:
        files["region.json"] = region_json
    files["fields.csv"] = fields_csv(rows, spec.depths_m)
    gpkg = scratch / "fields.gpkg"
    fields_gpkg(gpkg, spec, rows)
    files["fields.gpkg"] = gpkg
    figs = region_figures(spec, rows)
    written, years, allc = write_maps(spec, out, scratch)
    maps = {p.relative_to(scratch).as_posix(): p for p in written}
    files.update(sorted(maps.items()))
    figs["maps"] = sorted(maps)
    images = {f"map_{y}.png": _map_png(spec, years[y], str(y)) for y in spec.years}
    images["map_all_years.png"] = _map_png(spec, allc, "all years")
    images["risk_shares.png"] = _shares_png(spec, figs)
    files.update(images)
    share_rows = []
    for y in spec.years:
        fy = figs["by_year"][str(y)]
        for d in spec.depths_m:
            tag = f"{d:g}m"
            share_rows.append([y, d, *(round(100 * fy[f"risk_{nm}_fraction_{tag}"], 2) for nm in RISK_NAMES),
                               round(fy[f"density_change_mean_{tag}_Mg_per_m3"], 5)])
    key = _worst_key(spec)
    last = {r["field_id"]: r for r in rows if r["year"] == spec.years[-1]}
    worst_rows = []
    for w in figs["worst_fields"]:
        r = last[w["field_id"]]
        worst_rows.append([r["field_id"], r["soil"], r["system"], r.get("fidelity", "fast"), round(r["area_ha"], 2),
                           round(100 * r["trafficked_fraction"], 1), round(100 * r[key], 1),
                           round(r[key.replace("risk_high_fraction_", "density_change_mean_") + "_Mg_per_m3"], 5)])
    summary = {k: v for k, v in figs.items() if not isinstance(v, (list, dict))}
    for y in spec.years:
        summary[f"trafficked_fraction_{y}"] = figs["by_year"][str(y)]["trafficked_fraction"]
    depth_tag = key.replace("risk_high_fraction_", "")
    full = sorted({r["field_id"] for r in rows if r.get("fidelity") == "full"})
    fidelity = (f"the fast fidelity on {spec.cell_m:g} m cells ({spec.rule} rule)" if not full else
                f"the fast fidelity on {spec.cell_m:g} m cells ({spec.rule} rule), the full fidelity (each plan "
                f"driven over the field's terrain) on {len(full)} field(s): {', '.join(full[:20])}"
                + (" ..." if len(full) > 20 else "") + " (fields.csv: fidelity)")
    note = (f"{len(spec.fields)} fields, {spec.area_ha:.1f} ha, seasons {', '.join(map(str, spec.years))}; "
            f"{fidelity}. Shares are of the fields' area (a cell no "
            "machine passed is low risk). The maps are Cloud-Optimized GeoTIFFs in maps/; the per-field table is "
            "fields.csv (and fields.gpkg, with the fields' polygons)."
            + (f" Left out (no plan fits them): {', '.join(x['field_id'] for x in spec.skipped)}; their reasons are "
               "in summary.json." if spec.skipped else ""))
    text = (spec.folder / "region.toml").read_text() if (spec.folder / "region.toml").is_file() else \
        json.dumps(spec.document, indent=2, default=str)
    html = report_html(f"symtrack region: {spec.name}", summary, images, text, note=note, tables={
        "Share of the area at each risk class, by depth and year (%)":
            (["year", "depth_m", "low", "medium", "high", "density_change_mean_Mg_per_m3"], share_rows),
        f"The worst fields in {spec.years[-1]} (by the high-risk share at {depth_tag})":
            (["field_id", "soil", "system", "fidelity", "area_ha", "trafficked_%", f"high_risk_%_{depth_tag}",
              f"density_change_mean_{depth_tag}_Mg_per_m3"], worst_rows)})
    files["report.html"] = html
    files["summary.json"] = json.dumps(figs, indent=2) + "\n"  # the study's outputs are whole once it is in place
    write_folder(out, files, clear=False)
    return figs
