"""What no crawler has is refused, warned or stopped (symtrack.model.plausibility; issue 37)."""

import logging

import numpy as np
import pytest
from conftest import run_once

from symtrack.control import scenario as mpc_scenario
from symtrack.foundations.errors import ScenarioError, SimulationError
from symtrack.model import plausibility
from symtrack.simulation import scenario as sim_scenario
from symtrack.simulation.loop import IncompleteRun


def test_every_built_in_scenario_is_plausible(caplog):
    """The built-in vehicles, soils and torques pass without a warning (the reference crawler: 25 kPa)."""
    with caplog.at_level(logging.WARNING, logger="symtrack.plausibility"):
        for name in sim_scenario.builtin_names():
            sim_scenario.load_scenario(name)
        for name in mpc_scenario.builtin_names():
            mpc_scenario.load(name)
    assert not caplog.records, [r.getMessage() for r in caplog.records]
    sc = sim_scenario.load_scenario("validation")
    assert plausibility.ground_pressure_kPa(sc.vehicle) == pytest.approx(25.0, rel=0.01)


def test_a_mass_in_tonnes_is_refused_with_the_hint():
    with pytest.raises(ScenarioError) as e:
        sim_scenario.load_scenario("validation", ["vehicle.mass_kg=7.0"])
    msg = str(e.value)
    assert "mean ground pressure" in msg and "mass_kg = 7" in msg and "[5, 300] kPa" in msg
    assert "mass_kg is in kg (7 t is mass_kg = 7000)" in msg
    with pytest.raises(ScenarioError, match="mass_kg is in kg"):
        mpc_scenario.load("headland_uturn", ["vehicle.mass_kg=5.5"])


def test_too_high_a_ground_pressure_is_refused():
    with pytest.raises(ScenarioError, match=r"mean ground pressure .* is outside the allowed range \[5, 300\] kPa"):
        sim_scenario.load_scenario("validation", ["vehicle.contact_length_m=0.024"])


def test_a_track_as_wide_as_the_gauge_is_refused():
    with pytest.raises(ScenarioError, match=r"vehicle\.track_width_m = 1\.5 is outside the allowed range "
                                            r"\(0, vehicle\.track_gauge_m = 1\.5\)"):
        sim_scenario.load_scenario("validation", ["vehicle.track_width_m=1.5"])


def test_implausible_proportions_and_torques_are_warned_and_the_run_goes_on(caplog):
    with caplog.at_level(logging.WARNING, logger="symtrack.plausibility"):
        sc = sim_scenario.load_scenario("validation", ["vehicle.track_gauge_m=0.6"])
    assert sc.vehicle["track_gauge_m"] == 0.6
    assert any("contact_length_m / track_gauge_m = 4" in r.getMessage() for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="symtrack.plausibility"):
        mpc_scenario.load("headland_uturn", ["mpc.torque_max_N_m=60000"])
    (rec,) = caplog.records
    assert "mpc.torque_max_N_m" in rec.getMessage() and "x the weight" in rec.getMessage()


def test_a_run_faster_than_any_crawler_stops_with_a_message(monkeypatch):
    """The speed limit stops the run (the package's SimulationError, the partial run kept); here the
    limit is lowered to 1.5 m/s so that the validation's reference crawler crosses it in seconds."""
    monkeypatch.setattr(plausibility, "MAX_SPEED_M_S", 1.5)
    sc = sim_scenario.load_scenario("validation", ["run.duration_s=20", "run.integrator=rosenbrock"])
    with pytest.raises(IncompleteRun) as e:
        run_once(sc)
    assert isinstance(e.value, SimulationError)
    msg = str(e.value)
    assert "speed = " in msg and "is outside the allowed range [0, 1.5] m/s" in msg and "mass_kg is in kg" in msg
    assert e.value.partial.stopped_by == "error"
    with pytest.raises(SimulationError, match=r"speed = 100\.6 m/s \(362\.2 km/h\) at t = 3\.000 s .* \[0, 30\] m/s"):
        monkeypatch.undo()
        plausibility.check_speed(100.6, 3.0)


def test_tracks_that_spin_faster_than_any_crawler_stop_the_run():
    """The physics fuzzer's shrunk case (docs/model.md, "The physics fuzzer"): 14 000 N m on the
    validation clay spins the tracks up without bound (the sprocket torque has no speed limit); the run
    stops at a tread speed of 30 m/s with a message, its trajectory kept up to the last sample within
    the limit."""
    sc = sim_scenario.scenario_from_dict({
        "name": "spin", "run": {"duration_s": 3.0, "output_dt_s": 0.01, "integrator": "rosenbrock"},
        "model": {"lateral_law": "creep"}, "vehicle": {"preset": "reference_crawler"},
        "soil": {"preset": "clayey_soil_thailand_38"},
        "torque": [{"t_s": 0.0, "left_N_m": 14000.0, "right_N_m": 14000.0}]})
    with pytest.raises(IncompleteRun) as e:
        run_once(sc)
    msg = str(e.value)
    assert "tread speed = " in msg and "[0, 30] m/s" in msg and "the tracks spin" in msg
    part = e.value.partial
    r = sc.params["sprocket_radius_m"]
    tread = r * np.max(np.abs(np.column_stack([part.state("omega_left_rad_s"), part.state("omega_right_rad_s")])))
    assert tread <= plausibility.MAX_TREAD_SPEED_M_S and part.t[-1] < 3.0
    assert f"kept up to t = {part.t[-1]:.3f} s" in msg


def test_a_track_sunk_deeper_than_the_cg_height_stops_the_run(monkeypatch):
    """The hull in the soil is out of the model's domain (no hull contact): a run stops when a track end
    sinks deeper than SINKAGE_OVER_CG_HEIGHT_MAX x the CG height. Here the limit is lowered to 1/400 of
    the reference crawler's 0.6 m CG height (1.5 mm: above its 1.2 mm at rest), which the validation's
    1.9 mm crosses."""
    monkeypatch.setattr(plausibility, "SINKAGE_OVER_CG_HEIGHT_MAX", 1.0 / 400.0)
    sc = sim_scenario.load_scenario("validation", ["run.integrator=rosenbrock"])
    with pytest.raises(IncompleteRun) as e:
        run_once(sc)
    msg = str(e.value)
    assert "sinkage = " in msg and "vehicle.cg_height_m = 0.6 m" in msg and "hull would be in the soil" in msg
    part = e.value.partial
    deepest = max(float(np.max(part.state(n))) for n in part.state_names if n.startswith("sinkage_")
                  and n.endswith("_m") and "rate" not in n)
    assert deepest <= 0.0015 + 1e-12 and part.t[-1] > 0
    monkeypatch.undo()
    with pytest.raises(SimulationError, match=r"sinkage = 93 m at t = 1\.000 s is outside the allowed range "
                                              r"\[0, 0\.6\]"):
        plausibility.check_sinkage(93.0, 0.6, 1.0)
