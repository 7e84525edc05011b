"""GIS rasters in and out (issue 25 item 2, docs/terrain.md "GIS rasters"): a soil map from a
GeoTIFF runs as the same map in TOML, bit for bit; the exported GeoTIFF layers read back with
rasterio with their arrays, transform and CRS; the NetCDF dataset opens in xarray (and in GDAL,
QGIS's reader) with its variables, units and CRS; bad rasters are refused before anything is
built; without the extra, symtrack runs and a raster feature names the install."""

import copy
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import symtrack
from symtrack.cli import main
from symtrack.foundations.errors import MissingExtraError, ScenarioError
from symtrack.simulation.scenario import load_scenario, scenario_from_dict
from symtrack.terrain import gis
from symtrack.terrain import world as world_module
from symtrack.terrain.storage import Grid, Terrain

rasterio = pytest.importorskip("rasterio")  # the extra symtrack[gis], in the dev extra: CI has it
xr = pytest.importorskip("xarray")
pyproj = pytest.importorskip("pyproj")
from rasterio.transform import from_origin  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
WET = "clayey_soil_thailand_55"
# the wet clay with the wet-soil strength of examples/wet_headland.py (30 kPa, the Schjønning & Lamandé 2018
# PTF at 1.35 Mg/m^3, 25 % clay, pF 1): the strip it lies under reaches the medium risk class
WET_SOIL = {"preset": WET, "precompression_stress_Pa": 30e3}
ORIGIN, CELL, SHAPE = (-3.0, -2.5), 0.1, (80, 50)
BASE = {
    "name": "gis_test", "run": {"duration_s": 3.0, "output_dt_s": 0.01, "integrator": "grid_fast",
                                "stop_after_distance_m": 0.6},
    "vehicle": {"preset": "reference_crawler"}, "soil": {"preset": "clayey_soil_thailand_38"},
    "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
    "terrain": {"size_m": [8.0, 5.0], "origin_m": list(ORIGIN), "cell_m": CELL},
    "torque": [{"t_s": 0.0, "left_N_m": 1500.0, "right_N_m": 1500.0}],
}
# the left track's strip (y > 0.3) on the wet clay, a patch of it under the right track too
ZONES = [{"soil": 1, "x_m": [-10.0, 10.0], "y_m": [0.3, 10.0]}, {"soil": 1, "x_m": [0.5, 1.5], "y_m": [-1.5, 0.0]}]


def _write_raster(path, cells_xy, origin=ORIGIN, pixel=CELL, crs="EPSG:32633", dtype="uint8", nodata=None):
    """A GeoTIFF of the (nx, ny) array ``cells_xy`` (i along x, j along y), north up."""
    nx, ny = cells_xy.shape
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype=dtype, crs=crs, nodata=nodata,
                       transform=from_origin(origin[0], origin[1] + ny * pixel, pixel, pixel)) as ds:
        ds.write(np.ascontiguousarray(cells_xy.T[::-1]).astype(dtype), 1)
    return str(path)


def _zone_index():
    """The soil of every cell that ZONES give (later zones over earlier), (nx, ny)."""
    nx, ny = SHAPE
    xc, yc = ORIGIN[0] + (np.arange(nx) + 0.5) * CELL, ORIGIN[1] + (np.arange(ny) + 0.5) * CELL
    idx = np.zeros(SHAPE, dtype=np.uint8)
    for z in ZONES:
        inside = ((xc >= z["x_m"][0]) & (xc <= z["x_m"][1]))[:, None] & ((yc >= z["y_m"][0]) & (yc <= z["y_m"][1]))
        idx[inside] = z["soil"]
    return idx


def _raster_scenario(raster, geometry=False):
    d = copy.deepcopy(BASE)
    if not geometry:  # the field's origin, cell and size from the raster's transform
        d["terrain"] = {}
    d["terrain"]["soil_map"] = {"soils": [WET_SOIL], "raster": raster}
    return scenario_from_dict(d)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same soil map as TOML zones and as a GeoTIFF (EPSG:32633): both runs."""
    tmp = tmp_path_factory.mktemp("gis")
    d = copy.deepcopy(BASE)
    d["terrain"]["soil_map"] = {"soils": [WET_SOIL], "zones": ZONES}
    toml_run = symtrack.simulate(scenario_from_dict(d))
    sc = _raster_scenario(_write_raster(tmp / "soils.tif", _zone_index()))
    return toml_run, symtrack.simulate(sc), sc, tmp


def test_a_geotiff_soil_map_gives_the_run_of_the_same_map_in_toml_bit_for_bit(runs):
    toml_run, tif_run, sc, _ = runs
    assert sc.terrain.origin_m == ORIGIN and sc.terrain.cell_m == CELL and sc.terrain.shape == SHAPE
    assert np.array_equal(tif_run.terrain.soil_index.reshape(SHAPE), _zone_index())
    assert len(np.unique(_zone_index())) == 2  # both soils under the tracks
    a, b = toml_run.runs[0], tif_run.runs[0]
    assert np.array_equal(a.t, b.t) and np.array_equal(a.X, b.X) and np.array_equal(a.Y, b.Y)
    for name, arr in toml_run.terrain.arrays().items():
        assert np.array_equal(arr, tif_run.terrain.arrays()[name]), name
    assert toml_run.terrain.crs_wkt is None
    assert rasterio.crs.CRS.from_wkt(tif_run.terrain.crs_wkt).to_epsg() == 32633


def test_the_crs_is_kept_in_the_terrain_file_and_the_geotiff_layers_read_back(runs, tmp_path):
    _, run, sc, _ = runs
    run.terrain.save(tmp_path / "t.npz", sc.soil)
    t = Terrain.load(tmp_path / "t.npz")
    assert gis.same_crs(t.crs_wkt, "EPSG:32633")
    # the terrain continues on its own soil map (the same CRS: no mismatch) and keeps its CRS
    w = world_module.open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s, terrain=Terrain.load(tmp_path /
                                                                                                         "t.npz"))
    assert gis.same_crs(w.storage.crs_wkt, t.crs_wkt) and np.array_equal(w.storage.soil_index, t.soil_index)
    files = gis.export_terrain(t, geotiff_dir=tmp_path / "tif")["geotiff"]
    layers = gis.layer_arrays(t)
    assert {f.stem for f in files} == set(layers) == {la.name for la in gis.LAYERS}
    assert t.z.max() > 1e-4 and t.cycles.max() == 1 and layers["risk_class"].max() >= 1  # layers with content
    for f in files:
        layer = next(la for la in gis.LAYERS if la.name == f.stem)
        with rasterio.open(f) as ds:
            assert ds.crs.to_epsg() == 32633
            assert ds.transform == from_origin(ORIGIN[0], ORIGIN[1] + SHAPE[1] * CELL, CELL, CELL)
            assert ds.count == (len(t.subsoil_depths_m) if layer.per_depth else 1)
            assert set(ds.units) == {layer.units} and all(ds.descriptions)
            a = ds.read()
        expected = layers[f.stem] if layer.per_depth else layers[f.stem][..., None]
        assert a.dtype == np.dtype(layer.dtype)
        for k in range(a.shape[0]):  # row 0 at the top (largest y), column along x
            assert np.array_equal(a[k], expected[..., k].T[::-1]), (f.stem, k)
    assert np.array_equal(layers["rut_depth"], t.z.reshape(SHAPE).astype(np.float32))


def test_the_netcdf_opens_in_xarray_and_gdal_with_its_variables_units_and_crs(runs, tmp_path):
    _, run, _, _ = runs
    nc = gis.export_terrain(run.terrain, netcdf=tmp_path / "field.nc")["netcdf"]
    with xr.open_dataset(nc, decode_coords="all") as ds:
        assert dict(ds.sizes) == {"x": SHAPE[0], "y": SHAPE[1], "depth": len(run.terrain.subsoil_depths_m)}
        assert np.allclose(ds.x, ORIGIN[0] + (np.arange(SHAPE[0]) + 0.5) * CELL, rtol=0, atol=1e-12)
        assert ds.x.attrs["units"] == "m" and ds.y.attrs["units"] == "m" and ds.depth.attrs["units"] == "m"
        assert ds.attrs["symtrack_schema_version"] == gis.GIS_SCHEMA_VERSION
        for layer in gis.LAYERS:
            v = ds[layer.name]
            assert v.attrs["units"] == layer.units and v.attrs["long_name"] == layer.long_name
            assert v.dims == (("depth", "y", "x") if layer.per_depth else ("y", "x"))
        assert np.array_equal(ds.rut_depth.values, run.terrain.z.reshape(SHAPE).T.astype(np.float32))
        assert np.array_equal(ds.passes.values, run.terrain.cycles.reshape(SHAPE).T)
        assert rasterio.crs.CRS.from_wkt(ds.spatial_ref.attrs["crs_wkt"]).to_epsg() == 32633
        # the CF grid mapping (CF-1.8 appendix F), read back by pyproj from the CF attributes alone
        cf = {k: v for k, v in ds.spatial_ref.attrs.items() if k not in ("crs_wkt", "spatial_ref", "long_name")}
        assert cf["grid_mapping_name"] == "transverse_mercator" and cf["longitude_of_central_meridian"] == 15.0
        assert pyproj.CRS.from_cf(cf).to_epsg() == 32633
    with rasterio.open(f"netcdf:{nc}:stress_max") as ds:  # GDAL's netCDF driver, as QGIS opens it
        assert ds.crs.to_epsg() == 32633 and ds.count == len(run.terrain.subsoil_depths_m)
        assert ds.transform == from_origin(ORIGIN[0], ORIGIN[1] + SHAPE[1] * CELL, CELL, CELL)
        assert np.array_equal(ds.read(2), run.terrain.sigma_max.reshape(*SHAPE, -1)[..., 1].T[::-1])


def test_the_cli_exports_a_terrain_file_in_the_given_crs(runs, tmp_path, capsys):
    toml_run, _, _, _ = runs  # a terrain without a CRS: --crs gives it one
    toml_run.terrain.save(tmp_path / "t.npz")
    assert main(["terrain", "export", str(tmp_path / "t.npz"), "--geotiff", str(tmp_path / "g"),
                 "--netcdf", str(tmp_path / "f.nc"), "--crs", "EPSG:25832"]) == 0
    assert "EPSG" not in capsys.readouterr().err
    with rasterio.open(tmp_path / "g" / "passes.tif") as ds:
        assert ds.crs.to_epsg() == 25832
    with xr.open_dataset(tmp_path / "f.nc") as ds:
        assert rasterio.crs.CRS.from_wkt(ds.spatial_ref.attrs["crs_wkt"]).to_epsg() == 25832
    # the same file without --crs: local coordinates, no CRS
    gis.export_terrain(tmp_path / "t.npz", geotiff_dir=tmp_path / "local")
    with rasterio.open(tmp_path / "local" / "rut_depth.tif") as ds:
        assert ds.crs is None


def test_a_relative_raster_in_a_scenario_file_is_found_next_to_the_file(tmp_path, monkeypatch):
    folder = tmp_path / "maps"
    folder.mkdir()
    _write_raster(folder / "soils.tif", _zone_index())
    (folder / "s.toml").write_text(f"""name = "rel"
[run]
integrator = "grid_fast"
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[terrain.soil_map]
soils = ["{WET}"]
raster = "soils.tif"
[[torque]]
t_s = 0.0
left_N_m = 0.0
right_N_m = 0.0
""")
    monkeypatch.chdir(tmp_path)  # not the file's folder
    sc = load_scenario("maps/s.toml")
    assert Path(sc.terrain.soil_map.raster) == folder / "soils.tif"
    assert sc.terrain.shape == SHAPE


def test_a_raster_finer_or_coarser_than_the_cells_is_sampled_at_the_cell_centres(tmp_path):
    zi = _zone_index()
    fine = np.repeat(np.repeat(zi, 2, axis=0), 2, axis=1)  # 0.05 m pixels
    sc = _raster_scenario(_write_raster(tmp_path / "fine.tif", fine, pixel=CELL / 2), geometry=True)
    w = world_module.open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s)
    assert np.array_equal(w.storage.soil_index.reshape(SHAPE), zi)
    coarse = np.zeros((4, 3), dtype=np.uint8)
    coarse[2, 1] = 1  # 2 m pixels: x in [1, 3), y in [-0.5, 1.5)
    sc = _raster_scenario(_write_raster(tmp_path / "coarse.tif", coarse, pixel=2.0), geometry=True)
    w = world_module.open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s)
    g = w.grid
    xc, yc = g.centres(np.arange(SHAPE[0]), np.arange(SHAPE[1]))
    want = ((xc >= 1.0) & (xc < 3.0))[:, None] & ((yc >= -0.5) & (yc < 1.5))[None, :]
    assert np.array_equal(w.storage.soil_index.reshape(SHAPE) > 0, want)


def test_a_raster_of_oblong_pixels_needs_the_cell_size(tmp_path):
    nx, ny = 80, 25  # 0.1 m x 0.2 m pixels over the 8 m x 5 m field
    path = tmp_path / "oblong.tif"
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="uint8", crs="EPSG:32633",
                       transform=from_origin(ORIGIN[0], ORIGIN[1] + 5.0, 0.1, 0.2)) as ds:
        ds.write(np.zeros((ny, nx), dtype=np.uint8), 1)
    with pytest.raises(ScenarioError, match=r"pixels of 0.1 x 0.2 m: .* give terrain.cell_m"):
        _raster_scenario(str(path))
    d = copy.deepcopy(BASE)
    d["terrain"] = {"cell_m": 0.25, "soil_map": {"soils": [WET_SOIL], "raster": str(path)}}
    t = scenario_from_dict(d).terrain
    assert (t.origin_m, t.shape) == (ORIGIN, (32, 20)) and {"origin_m", "size_m"} <= t.given


@pytest.fixture
def nothing_built(monkeypatch):
    """Fail the test if the world's channel pool (the first thing a world builds) is built."""
    def refuse(*a, **k):
        raise AssertionError("the channel pool was built before the error")

    monkeypatch.setattr(world_module, "ChannelTerrain", refuse)


def test_a_raster_that_does_not_cover_the_field_is_refused_before_anything_is_built(tmp_path, nothing_built):
    small = _write_raster(tmp_path / "small.tif", np.zeros((60, 50), dtype=np.uint8))  # 6 m of the field's 8
    with pytest.raises(ScenarioError, match=r"soil_map.raster = .*covers x in \[-3, 3\] m.*the field is x in "
                                            r"\[-3, 5\] m.*must cover the whole field"):
        _raster_scenario(small, geometry=True)
    # a terrain file (its own geometry) elsewhere than the raster's field (whose origin the scenario takes):
    # refused when the world opens
    t = Terrain(Grid((10.0, 10.0), CELL, SHAPE))
    sc = _raster_scenario(_write_raster(tmp_path / "ok.tif", _zone_index()))
    with pytest.raises(ScenarioError, match=r"origin_m = \[10.0, 10.0\].*asks for terrain.origin_m = \[-3.0, -2.5\]"):
        world_module.open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s, terrain=t)


def test_a_crs_mismatch_between_two_maps_is_refused_before_anything_is_built(tmp_path, runs, nothing_built):
    _, run, sc, _ = runs  # a terrain made on the EPSG:32633 soil map
    other = _raster_scenario(_write_raster(tmp_path / "utm32.tif", _zone_index(), crs="EPSG:32632"))
    with pytest.raises(ScenarioError, match=r"is in EPSG:32632, the terrain continued is in EPSG:32633: two maps "
                                            "of one field must share their CRS"):
        world_module.open_world(other.terrain, other.params, other.model, other.run.output_dt_s, terrain=run.terrain)
    with pytest.raises(ScenarioError, match=r"--crs = 'EPSG:32632': the terrain was made in EPSG:32633"):
        gis.export_terrain(run.terrain, geotiff_dir=tmp_path / "x", crs="EPSG:32632")
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("kwargs, match", [
    ({"crs": "EPSG:4326"}, "must be projected in metres"),
    ({"nodata": 7, "fill": 7}, "lie on nodata pixels"),
    ({"fill": 3}, r"soil indices must be in \[0, 1\], the raster has 3..3"),
    ({"dtype": "float32"}, "one band of integers"),
])
def test_a_bad_raster_is_refused_naming_it(tmp_path, kwargs, match):
    kwargs = dict(kwargs)
    fill = kwargs.pop("fill", 0)
    path = _write_raster(tmp_path / "bad.tif", np.full(SHAPE, fill, dtype=np.uint8), **kwargs)
    with pytest.raises(ScenarioError, match=match):
        sc = _raster_scenario(path)
        world_module.open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s)


def test_without_the_extra_symtrack_runs_and_a_raster_feature_names_the_install(tmp_path, monkeypatch):
    for mod in ("rasterio", "rasterio.crs", "rasterio.errors", "rasterio.io", "rasterio.transform", "xarray"):
        monkeypatch.setitem(sys.modules, mod, None)  # import of these now raises ImportError
    with pytest.raises(MissingExtraError, match=r"pip install 'symtrack\[gis\]'"):
        _raster_scenario(str(tmp_path / "soils.tif"))
    with pytest.raises(MissingExtraError, match=r"NetCDF export needs .*pip install 'symtrack\[gis\]'"):
        gis.export_terrain(Terrain(Grid((0.0, 0.0), CELL, (4, 4))), netcdf=tmp_path / "f.nc")
    # a fresh interpreter without the GIS packages: the package imports, loads and checks a field
    code = ("import sys\nfor m in ('rasterio', 'xarray'): sys.modules[m] = None\n"
            "import symtrack, symtrack.terrain.gis, symtrack.cli\n"
            "from symtrack.simulation.scenario import load_scenario\n"
            "sc = load_scenario('multipass')\nprint(sc.terrain.shape)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr


def test_the_gis_example_writes_the_layers_and_the_figure(tmp_path, capsys):
    example = runpy.run_path(str(ROOT / "examples" / "gis_field.py"))
    assert example["main"](["--out", str(tmp_path), "--distance", "3"]) == 0
    out = capsys.readouterr().out
    assert "(530000.0, 6250000.0) m, cell 0.1 m, (260, 80) cells" in out
    with rasterio.open(tmp_path / "geotiff" / "rut_depth.tif") as ds:
        assert ds.crs.to_epsg() == 32632 and ds.read(1).max() > 0
    assert (tmp_path / "rut_depth.png").stat().st_size > 10_000 and (tmp_path / "field.nc").is_file()
