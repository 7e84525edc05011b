"""GIS rasters in and out
======================

GIS rasters in and out (docs/terrain.md, "GIS rasters"; needs ``pip install 'symtrack[gis]'``):
a soil map given as a GeoTIFF in a projected CRS, one pass of the reference crawler over it on the
terrain engine, the field's state exported as GeoTIFF layers and one NetCDF dataset, and the rut
depth read back from its GeoTIFF with rasterio and drawn in the CRS's coordinates.

    python examples/gis_field.py --out out/gis_field [--png docs/gis/rut_depth.png] [--distance 18]

The soil map is made here: a 26 m x 8 m field at 0.5 m pixels in UTM zone 32N (EPSG:32632), its
lower-left corner at an illustrative E 530 000 m, N 6 250 000 m (not a surveyed field), the
validation clay (38 % moisture) with a wet hollow of the same clay at 55 % moisture (Wong Table
2.3) and the wet-soil precompression stress of examples/wet_headland.py (30 kPa, the Schjønning &
Lamandé 2018 PTF at 1.35 Mg/m^3, 25 % clay, pF 1). World x, y are the CRS's metres: the vehicle
starts at E 530 004 m, N 6 250 004 m.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import rasterio  # noqa: E402
from rasterio.transform import from_origin  # noqa: E402

import symtrack  # noqa: E402
from symtrack.simulation.scenario import load_scenario  # noqa: E402
from symtrack.soil.subsoil import precompression_stress_kPa  # noqa: E402
from symtrack.terrain.gis import export_terrain  # noqa: E402

CRS = "EPSG:32632"
CORNER_M = (530_000.0, 6_250_000.0)  # lower-left corner of the field (illustrative)
SIZE_M, PIXEL_M = (26.0, 8.0), 0.5
WET_PTF = {"bulk_density_Mg_m3": 1.35, "matric_suction_hPa": 10.0, "clay_kg_kg": 0.25}


def write_soil_map(path: Path) -> None:
    """Soil 1 (the wet clay) in a disc of 3.5 m radius 15 m along the field, soil 0 elsewhere."""
    w, h = int(SIZE_M[0] / PIXEL_M), int(SIZE_M[1] / PIXEL_M)
    xc = CORNER_M[0] + (np.arange(w) + 0.5) * PIXEL_M
    yc = CORNER_M[1] + SIZE_M[1] - (np.arange(h) + 0.5) * PIXEL_M  # row 0 at the top
    wet = np.hypot(xc[None, :] - (CORNER_M[0] + 15.0), yc[:, None] - (CORNER_M[1] + 4.0)) < 3.5
    with rasterio.open(path, "w", driver="GTiff", width=w, height=h, count=1, dtype="uint8", crs=CRS,
                       transform=from_origin(CORNER_M[0], CORNER_M[1] + SIZE_M[1], PIXEL_M, PIXEL_M)) as ds:
        ds.write(wet.astype(np.uint8), 1)
        ds.set_band_description(1, "soil: 0 clay 38 %, 1 clay 55 % (wet)")


def write_scenario(path: Path, distance_m: float = 18.0) -> None:
    wet_pc_Pa = 1e3 * float(precompression_stress_kPa(**WET_PTF))
    path.write_text(f"""name = "gis_field"
description = "one pass over a GeoTIFF soil map with a wet hollow (EPSG:32632)"
[run]
duration_s = 30.0
output_dt_s = 0.01
integrator = "grid_fast"
stop_after_distance_m = {distance_m!r}
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[start]
x_m = {CORNER_M[0] + 4.0!r}
y_m = {CORNER_M[1] + 4.0!r}
yaw_deg = 0.0
[terrain]
cell_m = 0.1
[terrain.soil_map]
soils = [{{preset = "clayey_soil_thailand_55", precompression_stress_Pa = {wet_pc_Pa!r}}}]
raster = "soils.tif"   # relative: next to this file
[[torque]]
t_s = 0.0
left_N_m = 1500.0
right_N_m = 1500.0
""")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/gis_field")
    ap.add_argument("--distance", type=float, default=18.0, help="length of the pass [m]")
    ap.add_argument("--png", default=None, help="also write the figure here (e.g. docs/gis/rut_depth.png)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_soil_map(out / "soils.tif")
    write_scenario(out / "gis_field.toml", a.distance)
    sc = load_scenario(out / "gis_field.toml")
    print(f"field: origin {sc.terrain.origin_m} m, cell {sc.terrain.cell_m} m, {sc.terrain.shape} cells (from the "
          "GeoTIFF's transform)")
    res = symtrack.simulate(sc, progress=True)
    res.write(out / "run")
    res.terrain.save(out / "field.npz", sc.soil)
    files = export_terrain(out / "field.npz", geotiff_dir=out / "geotiff", netcdf=out / "field.nc")
    print("wrote", ", ".join(str(f) for f in [*files["geotiff"], files["netcdf"]]))

    with rasterio.open(out / "geotiff" / "rut_depth.tif") as ds:  # read back, as a GIS user would
        rut_mm, b, crs, unit = 1e3 * ds.read(1), ds.bounds, ds.crs, ds.units[0]
    with rasterio.open(out / "soils.tif") as ds:
        soil, sb = ds.read(1), ds.bounds
    fig, ax = plt.subplots(figsize=(9, 3.6), layout="constrained")
    im = ax.imshow(np.ma.masked_equal(rut_mm, 0.0), extent=(b.left, b.right, b.bottom, b.top), cmap="viridis")
    px, py = (sb.right - sb.left) / soil.shape[1], (sb.top - sb.bottom) / soil.shape[0]
    ax.contour(sb.left + (np.arange(soil.shape[1]) + 0.5) * px, sb.top - (np.arange(soil.shape[0]) + 0.5) * py, soil,
               levels=[0.5], colors="tab:red", linewidths=1.0)
    fig.colorbar(im, ax=ax, label=f"rut depth [mm] (file unit: {unit})")
    ax.set_xlabel(f"easting [m] ({crs})")
    ax.set_ylabel("northing [m]")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set_title("rut_depth.tif read back with rasterio; red: the wet hollow of soils.tif")
    for target in [out / "rut_depth.png", *([Path(a.png)] if a.png else [])]:
        target.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(target, dpi=110)
        print(f"wrote {target}")
    s = res.summary["passes"][0]
    print(f"rut mean {s['rut_mean_depth_mm']:.3f} mm, max {s['rut_max_depth_mm']:.3f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
