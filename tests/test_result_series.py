"""A Result's named series: ``res["yaw_rad"]``, the names with their units, and ``to_xarray`` with units and
descriptions in the attributes (xarray optional, a clear error without it)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import symtrack
from symtrack.api import describe_series
from symtrack.foundations.errors import ScenarioError
from symtrack.reports import validation


@pytest.fixture(scope="module")
def res():
    return symtrack.simulate(symtrack.load_scenario("validation", {"run.integrator": "rosenbrock",
                                                                   "run.duration_s": 1.0}))


def test_series_by_name(res):
    assert np.array_equal(res["yaw_rad"], res.column("yaw_rad"))
    assert np.array_equal(res["t_s"], res.t)
    assert res.columns[0] == "t_s" and "yaw_rad" in res and "nothere" not in res
    assert len(res.columns) == len(set(res.columns))
    with pytest.raises(KeyError, match="no column 'yaw_deg'.*yaw_rad"):
        res["yaw_deg"]
    with pytest.raises(KeyError):
        res[3]
    units = res.units()
    assert units["yaw_rad"] == "rad" and units["p_sprocket_left_Pa"] == "Pa" and units["slip_left"] == "1"
    assert units["torque_cmd_left_N_m"] == "N m" and units["accel_x_m_s2"] == "m/s^2"


def test_every_series_is_described(res):
    for name in res.columns:
        unit, text = describe_series(name)
        assert text != "model output", f"{name} has no description of its own"


def test_to_xarray_carries_units_and_descriptions(res):
    pytest.importorskip("xarray")
    ds = res.to_xarray()
    assert np.array_equal(ds["t"].values, res.t) and ds["t"].attrs["units"] == "s"
    assert np.array_equal(ds["yaw_rad"].values, res["yaw_rad"])
    assert ds["yaw_rad"].attrs == {"units": "rad", "description": "yaw angle (heading) in the world frame"}
    assert ds["sinkage_idler_right_m"].attrs["description"] == "sinkage under the idler end of the right track"
    assert set(ds.data_vars) == set(res.columns) - {"t_s"}
    assert ds.attrs["scenario"] == "validation" and ds.attrs["integrator"] == "rosenbrock"


def test_to_xarray_without_xarray_says_what_to_install(res, monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ScenarioError, match="pip install xarray"):
        res.to_xarray()


def test_the_notebook_view_says_what_ran_and_gives_the_figures_with_units(res):
    import xml.etree.ElementTree as ET

    page = res._repr_html_()
    root = ET.fromstring(page)  # a well-formed fragment (every cell escaped)
    assert root.tag == "div"
    text = "".join(root.itertext())
    for fact in ("scenario: validation", "integrator: rosenbrock", "terrain: homogeneous",
                 "vehicle: reference_crawler", "soil: clayey_soil_thailand_38"):
        assert fact in text.replace("\n", ""), fact
    tables = root.findall("table")
    rows = {tr[0].text: (tr[1].text, tr[2].text) for tr in tables[0].iter("tr") if tr[0].tag == "td"}
    assert rows["sinkage_sprocket_mm"] == (f"{res.summary['sinkage_sprocket_mm']:.6g}", "mm")
    assert rows["speed_final_m_s"][1] == "m/s" and rows["yaw_final_deg"][1] == "deg"
    assert rows["sim_time_s"] == (f"{res.summary['sim_time_s']:.6g}", "s")
    # this run stops at 1 s, before the validation's distance stop: compared in its table, not graded here
    assert len(tables) == 1 and "ended by duration before its distance stop" in res.validation_table
    # the run as published: the graded rows, one per quantity of the published case
    full = symtrack.simulate(symtrack.load_scenario("validation", {"run.integrator": "rosenbrock"}))
    full_tables = ET.fromstring(full._repr_html_()).findall("table")
    graded = [[td.text for td in tr] for tr in full_tables[1].iter("tr") if tr[0].tag == "td"]
    assert len(full_tables) == 2 and len(graded) == len(validation.check(full.summary))
    assert all(row[3] in ("yes", "NO") for row in graded)
    # an incomplete run says so first
    broken = symtrack.api.Result(res.scenario, res.runs, {**res.summary, "complete": False, "error": "boom"},
                                 res.pass_summaries)
    assert "Incomplete run: boom" in broken._repr_html_()
