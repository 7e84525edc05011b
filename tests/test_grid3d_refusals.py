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
