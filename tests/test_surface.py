"""The ground's shape (symtrack/terrain/surface.py, issue 22 item 1): analytic surfaces against their
closed forms, numpy against CasADi against finite differences; the raster; the scenario's checks; the
terrain file; the query's height = z0 - sinkage after a pass on the engine; the planar vehicle's run
unchanged by the ground's shape; the exported layers and the figure."""

import copy
import math

import numpy as np
import pytest
from small_field import small_field

from symtrack.foundations.errors import ScenarioError
from symtrack.model.parameters import SOIL_PARAM_NAMES
from symtrack.reports import figures
from symtrack.simulation.passes import run_passes
from symtrack.simulation.plants import make_plant
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.terrain import gis, query, storage
from symtrack.terrain.settings import settings_from_dict
from symtrack.terrain.storage import Grid, Terrain
from symtrack.terrain.surface import GROUND_CLEARANCE_M, MAX_SLOPE_DEG, parse_surface
from symtrack.terrain.world import open_world
from symtrack.toolchain import find_compiler

SX, SY, D, L, H = 4.0, -3.0, 0.06, 0.8, 30.0  # slopes, furrow depth and spacing, heading [deg]


def _closed_form(x, y):
    """z0 and its gradient of the planes and the furrows, written out."""
    tx, ty, h, k = math.tan(math.radians(SX)), math.tan(math.radians(SY)), math.radians(H), 2 * math.pi / L
    s = -x * math.sin(h) + y * math.cos(h)
    z = tx * x + ty * y + D / 2 * np.cos(k * s)
    return z, tx + D / 2 * k * math.sin(h) * np.sin(k * s), ty - D / 2 * k * math.cos(h) * np.sin(k * s)


def _points(n=50):
    rng = np.random.default_rng(2)
    return rng.uniform(-5.0, 5.0, n), rng.uniform(-5.0, 5.0, n)


def test_analytic_surface_numeric_symbolic_and_finite_differences():
    s = parse_surface({"slope_x_deg": SX, "slope_y_deg": SY, "furrow_spacing_m": L, "furrow_depth_m": D,
                       "furrow_heading_deg": H})
    x, y = _points()
    z, gx, gy = s.evaluate(x, y)
    for got, want in zip((z, gx, gy), _closed_form(x, y), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)
    f = s.function()
    sym = [np.array(v).ravel() for v in f.map(x.size)(x, y)]
    for got, want in zip(sym, (z, gx, gy), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)
    h = 1e-6
    np.testing.assert_allclose((s.elevation(x + h, y) - s.elevation(x - h, y)) / (2 * h), gx, atol=1e-8)
    np.testing.assert_allclose((s.elevation(x, y + h) - s.elevation(x, y - h)) / (2 * h), gy, atol=1e-8)
    # furrows with heading 0 run along x: the ground does not change along x
    s0 = parse_surface({"furrow_spacing_m": L, "furrow_depth_m": D})
    np.testing.assert_array_equal(s0.elevation(x, y), s0.elevation(x + 1.7, y))
    assert float(s0.elevation(0.0, 0.0)) == D / 2 and abs(float(s0.elevation(0.0, L / 2)) + D / 2) < 1e-15


def test_raster_bilinear_numpy_and_casadi(tmp_path):
    """A .npy raster of a plane is the plane (bilinear is exact on it) and its gradient; a random
    raster: numpy's bilinear sample equals CasADi's linear interpolant, and finite differences
    inside a patch equal the gradient."""
    px, origin = 0.5, (-3.0, -2.0)
    i, j = np.meshgrid(np.arange(14), np.arange(10), indexing="ij")
    xc, yc = origin[0] + (i + 0.5) * px, origin[1] + (j + 0.5) * px
    np.save(tmp_path / "plane.npy", 0.05 * xc - 0.02 * yc + 3.0)
    s = parse_surface({"elevation_file": str(tmp_path / "plane.npy"), "elevation_cell_m": px,
                       "elevation_origin_m": list(origin)})
    x = np.random.default_rng(4).uniform(-2.7, 3.7, 40)
    y = np.random.default_rng(5).uniform(-1.7, 2.7, 40)
    z, gx, gy = s.evaluate(x, y)
    np.testing.assert_allclose(z, 0.05 * x - 0.02 * y + 3.0, atol=1e-13)
    np.testing.assert_allclose(gx, 0.05, atol=1e-13)
    np.testing.assert_allclose(gy, -0.02, atol=1e-13)
    np.save(tmp_path / "rough.npy", np.random.default_rng(6).uniform(0.0, 0.05, (14, 10)))
    r = parse_surface({"elevation_file": str(tmp_path / "rough.npy"), "elevation_cell_m": px,
                       "elevation_origin_m": list(origin), "slope_x_deg": 2.0})
    z, gx, gy = r.evaluate(x, y)
    sym = [np.array(v).ravel() for v in r.function().map(x.size)(x, y)]
    np.testing.assert_allclose(sym[0], z, atol=1e-13)
    np.testing.assert_allclose(sym[1], gx, atol=1e-12)
    np.testing.assert_allclose(sym[2], gy, atol=1e-12)
    h = 1e-7
    np.testing.assert_allclose((r.elevation(x + h, y) - r.elevation(x - h, y)) / (2 * h), gx, atol=1e-5)


def test_the_cells_and_the_query_height_and_gradient():
    """z0 at the cell centres; the query: height = z0 - sinkage, the gradient exact on a plane and
    sin(k dx) / (k dx) of the slope on furrows (central differences of the cells)."""
    g = Grid((-2.0, -1.0), 0.1, (40, 30))
    s = parse_surface({"slope_x_deg": SX, "slope_y_deg": SY})
    t = Terrain(g)
    t.set_elevation(s.cell_elevation(g))
    t.z[:] = np.random.default_rng(7).uniform(0.0, 0.02, t.z.size)
    ii, jj = np.divmod(np.arange(g.n_cells), g.shape[1])
    xc, yc = g.centres(ii, jj)
    q = query.query(t, xc, yc)
    np.testing.assert_array_equal(q.elevation_m, s.elevation(xc, yc))
    np.testing.assert_array_equal(q.height_m, q.elevation_m - t.z)
    np.testing.assert_allclose(q.gradient[:, 0], math.tan(math.radians(SX)), atol=1e-12)
    np.testing.assert_allclose(q.gradient[:, 1], math.tan(math.radians(SY)), atol=1e-12)
    n = np.array([-math.tan(math.radians(SX)), -math.tan(math.radians(SY)), 1.0])
    np.testing.assert_allclose(q.normal, np.broadcast_to(n / np.linalg.norm(n), q.normal.shape), atol=1e-12)
    f = parse_surface({"furrow_spacing_m": 0.8, "furrow_depth_m": D})
    t.set_elevation(f.cell_elevation(g))
    q = query.query(t, xc, yc)
    inner = (jj > 0) & (jj < g.shape[1] - 1)
    k = 2 * math.pi / 0.8
    _, _, gy = f.evaluate(xc, yc)
    np.testing.assert_allclose(q.gradient[inner, 1], gy[inner] * math.sin(k * 0.1) / (k * 0.1), atol=1e-12)


@pytest.mark.parametrize("table, match", [
    ({"slope_x_deg": 25.0}, r"terrain\.surface\.slope_x_deg = 25\.0 is outside the allowed range \[-20, 20\] deg: "
                            r"the cells are vertical columns"),
    ({"slope_y_deg": -95.0}, r"terrain\.surface\.slope_y_deg = -95\.0"),
    ({"slope_x_deg": 15.0, "slope_y_deg": 15.0}, r"make a slope of up to 20\.8 deg; the allowed range is \[0, 20\]"),
    ({"furrow_spacing_m": 0.5, "furrow_depth_m": 0.5}, r"furrow_depth_m = 0\.5 is outside the allowed range \[0, "
                                                       r"0\.4\] m: furrows deeper than the vehicle's ground clearance"),
    ({"furrow_depth_m": 0.1}, r"furrow_depth_m = 0\.1 needs furrow_spacing_m"),
    ({"furrow_heading_deg": "x"}, r"furrow_heading_deg"),
    ({"slope_z_deg": 1.0}, r"slope_z_deg"),
    ({"elevation_cell_m": 1.0}, r"elevation_cell_m is given without elevation_file"),
    ({"elevation_file": "dem.csv"}, r"elevation_file = 'dem\.csv' must be the path of a \.npy"),
    ({"elevation_file": "nowhere.npy", "elevation_cell_m": 1.0}, r"'nowhere\.npy': no such file"),
])
def test_bad_input_is_refused_naming_the_key(table, match):
    with pytest.raises(ScenarioError, match=match):
        parse_surface(table)


def test_a_surface_of_zeros_is_flat():
    assert parse_surface({"slope_x_deg": 0.0, "furrow_spacing_m": 1.0, "furrow_depth_m": 0.0}).is_flat
    assert not parse_surface({"slope_y_deg": 0.5}).is_flat


def test_bad_rasters_and_fields_are_refused(tmp_path):
    a = np.zeros((10, 10))
    a[3, 4] = np.nan
    np.save(tmp_path / "nan.npy", a)
    with pytest.raises(ScenarioError, match=r"holds 1 NaN, inf or nodata pixel\(s\) \(the first at i, j = 3, 4\)"):
        parse_surface({"elevation_file": str(tmp_path / "nan.npy"), "elevation_cell_m": 1.0})
    np.save(tmp_path / "small.npy", np.zeros((10, 10)))
    with pytest.raises(ScenarioError, match=r"covers x in \[0, 5\] m, y in \[0, 5\] m; the field is x in \[0, 6\]"):
        settings_from_dict({"size_m": [6.0, 4.0], "cell_m": 0.1, "origin_m": [0.0, 0.0],
                            "surface": {"elevation_file": str(tmp_path / "small.npy"), "elevation_cell_m": 0.5}})
    np.save(tmp_path / "steep.npy", np.outer(np.arange(10) * 0.3, np.ones(10)))  # 0.3 m rise per 1 m pixel
    with pytest.raises(ScenarioError, match=r"slope_x_deg = 5\.0, slope_y_deg = 5\.0, elevation_file = .* make a slope "
                                            r"of up to 23 deg; the allowed range is \[0, 20\] deg"):
        parse_surface({"elevation_file": str(tmp_path / "steep.npy"), "elevation_cell_m": 1.0, "slope_y_deg": 5.0,
                       "slope_x_deg": 5.0})
    parse_surface({"elevation_file": str(tmp_path / "steep.npy"), "elevation_cell_m": 1.0})  # 16.7 deg: allowed
    assert not parse_surface({"furrow_spacing_m": 0.75, "furrow_depth_m": 0.25}).is_flat  # potato ridges: allowed
    with pytest.raises(ScenarioError, match=r"furrow_spacing_m = 0\.3 must be at least 4 cells \(4 x terrain\.cell_m "
                                            r"= 0\.4 m\)"):
        settings_from_dict({"size_m": [6.0, 4.0], "cell_m": 0.1,
                            "surface": {"furrow_spacing_m": 0.3, "furrow_depth_m": 0.005}})
    assert GROUND_CLEARANCE_M == 0.4 and MAX_SLOPE_DEG == 20.0


def test_geotiff_elevation_gives_origin_and_pixel(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import from_origin
    data = np.arange(12 * 8, dtype=np.float32).reshape(8, 12) * 0.01  # rows from the top
    path = tmp_path / "dem.tif"
    with rasterio.open(path, "w", driver="GTiff", width=12, height=8, count=1, dtype="float32", crs="EPSG:32632",
                       transform=from_origin(530000.0, 6250004.0, 0.5, 0.5), nodata=-9999.0) as ds:
        ds.write(data, 1)
    t = settings_from_dict({"cell_m": 0.1, "surface": {"elevation_file": str(path)}})
    assert t.origin_m == (530000.0, 6250000.0) and t.shape == (60, 40)
    r = t.surface.raster
    assert r.pixel_m == 0.5 and r.values[0, 0] == np.float32(data[-1, 0]) and r.values[11, 7] == np.float32(data[0, 11])
    assert gis.same_crs(r.crs_wkt, "EPSG:32632")
    with pytest.raises(ScenarioError, match=r"elevation_cell_m = 1\.0: a GeoTIFF's transform gives its pixel"):
        parse_surface({"elevation_file": str(path), "elevation_cell_m": 1.0})
    data[2, 3] = -9999.0
    with rasterio.open(path, "w", driver="GTiff", width=12, height=8, count=1, dtype="float32", crs="EPSG:32632",
                       transform=from_origin(530000.0, 6250004.0, 0.5, 0.5), nodata=-9999.0) as ds:
        ds.write(data, 1)
    with pytest.raises(ScenarioError, match=r"holds 1 NaN, inf or nodata pixel"):
        parse_surface({"elevation_file": str(path)})


def test_terrain_file_round_trip_and_old_files_load_flat(tmp_path):
    g = Grid((1.0, 2.0), 0.25, (9, 7))
    soil = {n: 1.0 for n in SOIL_PARAM_NAMES}
    t = Terrain(g, soil)
    t.set_elevation(np.random.default_rng(8).normal(300.0, 2.0, g.n_cells))
    t.z[:] = np.random.default_rng(9).uniform(0, 0.01, g.n_cells)
    t.zmax[:] = t.z  # loaded that deep (storage.load checks z <= z_max + z_off)
    t.save(tmp_path / "t.npz")
    back = Terrain.load(tmp_path / "t.npz")
    assert back.elevation.dtype == np.float64 and np.array_equal(back.elevation, t.elevation)
    np.testing.assert_array_equal(back.surface_m(), t.elevation - t.z)
    flat = Terrain(g, soil)
    flat.save(tmp_path / "flat.npz")
    assert Terrain.load(tmp_path / "flat.npz").elevation is None
    with np.load(tmp_path / "t.npz") as f:  # the same file as schema 3 wrote it: no elevation, loads flat
        d = {k: f[k] for k in f.files if k != "elevation_m"}
    d["schema_version"] = np.array(3)
    np.savez(tmp_path / "old.npz", **d)
    old = Terrain.load(tmp_path / "old.npz")
    assert storage.TERRAIN_SCHEMA_VERSION >= 4 and old.elevation is None and np.array_equal(old.z, t.z)
    np.testing.assert_array_equal(query.query(old, 2.0, 3.0).normal, [0.0, 0.0, 1.0])
    d["schema_version"] = np.array(4)
    d["elevation_m"] = np.full(g.shape, np.nan)
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(ScenarioError, match="elevation_m must be finite float64"):
        Terrain.load(tmp_path / "bad.npz")
    layers = gis.layer_arrays(back)
    np.testing.assert_array_equal(layers["elevation_m"], t.elevation.reshape(g.shape))
    np.testing.assert_array_equal(layers["surface_m"], (t.elevation - t.z).reshape(g.shape))
    np.testing.assert_array_equal(gis.layer_arrays(flat)["elevation_m"], 0.0)


SMALL = small_field("surface_small", run={"duration_s": 0.3})  # tests/small_field.py


@pytest.mark.skipif(find_compiler() is None, reason="no C compiler")
def test_a_pass_on_shaped_ground():
    """On the engine: the query's height is z0 - sinkage after a pass (C and numpy alike), the planar
    vehicle rides the same as on flat ground (bit for bit), the terrain keeps its elevation through a
    continuation (another surface is refused), and the figure is drawn only for shaped ground."""
    shaped = copy.deepcopy(SMALL)
    shaped["terrain"]["surface"] = {"slope_x_deg": 5.0, "slope_y_deg": -2.0, "furrow_spacing_m": 1.0,
                                    "furrow_depth_m": 0.05}
    runs = {}
    for name, d in (("flat", SMALL), ("shaped", shaped)):
        sc = scenario_from_dict(copy.deepcopy(d))
        plant = make_plant(sc)
        runs[name] = (sc, plant, run_passes(sc, plant))
    (_, pf, sf), (sc, plant, study) = runs["flat"], runs["shaped"]
    np.testing.assert_array_equal(study.runs[0].X, sf.runs[0].X)
    np.testing.assert_array_equal(plant.world.storage.z, pf.world.storage.z)
    w = plant.world
    assert w.storage.elevation is not None and pf.world.storage.elevation is None
    nx, ny = w.grid.shape
    xc, yc = w.grid.centres(np.arange(nx)[:, None], np.arange(ny)[None, :])
    np.testing.assert_array_equal(w.storage.elevation, w.surface.elevation(xc, yc).ravel())
    x, y = np.meshgrid(np.linspace(-5.9, 5.9, 80), np.linspace(-1.9, 1.9, 30), indexing="ij")
    got = plant.engine.surface(x, y)
    ref = query.query(w.storage, x, y)
    for name in ("cell", "elevation_m", "sinkage_m", "height_m", "normal", "phase", "gradient"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    rut = got.sinkage_m > 1e-4
    assert rut.sum() > 20  # the pass left ruts
    np.testing.assert_array_equal(got.height_m[rut], w.storage.elevation[got.cell[rut]] - w.storage.z[got.cell[rut]])
    files = figures.figures("terrain", figures.TerrainRun(sc, study))
    assert files["surface.png"][:4] == b"\x89PNG"
    assert "surface.png" not in figures.figures("terrain", figures.TerrainRun(runs["flat"][0], sf))
    # a continuation keeps the terrain's elevation; another surface is refused

    again = open_world(sc.terrain, w.params, w.opts, 0.01, terrain=w.storage)
    assert again.surface is not None
    other = settings_from_dict({**shaped["terrain"], "surface": {"slope_x_deg": 4.0}})
    with pytest.raises(ScenarioError, match="has another elevation than the scenario's"):
        open_world(other, w.params, w.opts, 0.01, terrain=w.storage)
    plain = settings_from_dict({k: v for k, v in shaped["terrain"].items() if k != "surface"})
    assert open_world(plain, w.params, w.opts, 0.01, terrain=w.storage).storage.elevation is not None
