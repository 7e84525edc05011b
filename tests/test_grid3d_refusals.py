"""What the 3D vehicle on the grid cannot take is refused at load, before any work, naming the key and
what is allowed (docs/vehicle3d.md, "The grid under the 3D vehicle"). No compile: fast."""

from __future__ import annotations

import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.simulation.scenario import load_scenario, scenario_from_dict


def _doc(run=None, **terrain):
    return {"run": {"integrator": "grid_fast", "output_dt_s": 0.01, **(run or {})}, "model": {"vehicle": "3d"},
            "vehicle": {"preset": "reference_crawler"}, "soil": {"preset": "clayey_soil_thailand_38"},
            "torque": [{"t_s": 0.0, "left_N_m": 0.0, "right_N_m": 0.0}],
            "terrain": {"size_m": [20.0, 10.0], "cell_m": 0.1, **terrain}}


def test_the_engine_takes_the_3d_vehicle():
    sc = scenario_from_dict(_doc())
    assert sc.model.vehicle == "3d" and sc.terrain is not None
    assert load_scenario("validation_grid", ["model.vehicle=3d"]).terrain is not None


def test_the_channel_pool_integrators_are_refused():
    for integrator in ("idas", "rosenbrock"):
        with pytest.raises(ScenarioError, match=r"model.vehicle = '3d' .*run.integrator = 'grid_fast'"):
            scenario_from_dict(_doc({"integrator": integrator}))


TOWED = {"axle_load_kN": 60.0, "wheel_gauge_m": 1.5, "tyre_width_m": 0.6, "tyre_diameter_m": 1.6,
         "tyre_rated_load_kN": 45.0, "tyre_rated_inflation_kPa": 240.0, "inflation_kPa": 160.0,
         "hitch_behind_track_centre_m": 1.6, "drawbar_length_m": 4.0}
SOIL_MAP = {"soils": ["clayey_soil_thailand_38", "sandy_loam_15"],
            "zones": [{"soil": 1, "x_m": [-5.0, 0.0], "y_m": [-5.0, 5.0]}]}


@pytest.mark.parametrize("key, table", [("towed", TOWED), ("soil_map", SOIL_MAP)])
def test_what_the_segments_cannot_take_is_refused(key, table):
    with pytest.raises(ScenarioError, match=rf"terrain.{key}: .* not coupled to the 3D vehicle on the grid .*allowed"):
        scenario_from_dict(_doc(**{key: table}))
    scenario_from_dict({**_doc(**{key: table}), "model": {"vehicle": "planar"}})  # the planar vehicle takes it


def test_an_elevation_raster_is_taken_and_coarse_segments_are_refused(tmp_path):
    import numpy as np

    f = tmp_path / "dem.npy"
    np.save(f, np.zeros((201, 101)))
    sc = scenario_from_dict(_doc(surface={"elevation_file": str(f), "elevation_cell_m": 0.1}))
    assert sc.terrain.surface.raster is not None  # (the run: tests/test_grid3d.py, the raster of a plane)
    with pytest.raises(ScenarioError, match=r"model.contact_segments = 8 .* allowed range is \[20, 64\]"):
        scenario_from_dict(_doc(surface={"furrow_spacing_m": 0.5, "furrow_depth_m": 0.05}))


def test_a_continued_shaped_terrain_without_its_surface_is_refused(tmp_path):
    """A terrain file with an elevation of its own, continued by the 3D vehicle without the
    [terrain.surface] that made it: refused when the engine is built, before the run (the hull's ground
    is the surface's, the cells keep only their heights); with the surface given it is checked against
    the file's elevation (symtrack/terrain/world.py), and the planar vehicle takes the file as it is."""
    import numpy as np

    from symtrack.presets import soil_preset
    from symtrack.simulation.plants import make_plant
    from symtrack.terrain import storage as persist
    from symtrack.terrain.storage import Grid, Terrain

    g = Grid((-5.0, -5.0), 0.1, (200, 100))
    t = Terrain(g)
    xc, yc = g.centres(np.arange(200), np.arange(100))
    t.set_elevation(np.ascontiguousarray((0.05 * yc[None, :] + 0.0 * xc[:, None]).ravel()))
    f = tmp_path / "sloped.npz"
    persist.save(f, t, soil_preset("clayey_soil_thailand_38"))
    doc = _doc(initial_state=str(f))
    del doc["terrain"]["size_m"], doc["terrain"]["cell_m"]
    sc = scenario_from_dict(doc)
    with pytest.raises(ScenarioError, match=r"elevation of its own .*3D vehicle's ground .*\[terrain.surface\] that "
                                            r"made the terrain.*model.vehicle = 'planar'"):
        make_plant(sc)
    planar = make_plant(scenario_from_dict({**doc, "model": {"vehicle": "planar"}}))
    assert planar.world.storage.elevation is not None
