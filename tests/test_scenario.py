"""Scenario validation: bad input fails with a message naming key, value and allowed range."""

import pytest

from symtrack.foundations.config import to_toml
from symtrack.foundations.errors import ScenarioError
from symtrack.simulation.scenario import builtin_names, load_scenario, scenario_from_dict

GOOD = """
[run]
duration_s = 5.0
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[[torque]]
t_s = 0.0
left_N_m = 100.0
right_N_m = 100.0
"""


def _write(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(text)
    return str(p)


def test_builtin_validation_exists_and_resolves():
    assert "validation" in builtin_names()
    sc = load_scenario("validation")
    assert sc.vehicle["mass_kg"] > 0 and sc.torque[1].event == "idle"


def test_resolved_scenario_round_trips(tmp_path):
    sc = load_scenario("validation", ["vehicle.mass_kg=6000", "run.integrator=idas"])
    again = load_scenario(_write(tmp_path, to_toml(sc.to_dict())))
    assert again == sc
    assert again.vehicle["mass_kg"] == 6000.0 and again.run.integrator == "idas"


@pytest.mark.parametrize("patch, words", [
    (("[vehicle]\npreset = \"reference_crawler\"", "[vehicle]\npreset = \"reference_crawler\"\nmass_kg = -5.0"),
     ["mass_kg", "-5.0", "(0, 1e+06]"]),
    (("preset = \"reference_crawler\"", "preset = \"tank\""), ["vehicle.preset", "tank", "reference_crawler"]),
    (("duration_s = 5.0", "duraton_s = 5.0"), ["duraton_s", "duration_s"]),
    (("left_N_m = 100.0", "left_N_m = nan"), ["torque[0].left_N_m", "nan"]),
    (("duration_s = 5.0", "duration_s = 0.0"), ["run.duration_s", "0.0", "(0, 1e+06]"]),
    (("[soil]\npreset = \"clayey_soil_thailand_38\"", "[soil]\npreset = \"clayey_soil_thailand_38\"\nbekker_n = 7"),
     ["bekker_n", "7", "(0, 3]"]),
])
def test_bad_values_are_named(tmp_path, patch, words):
    text = GOOD.replace(*patch)
    assert text != GOOD
    with pytest.raises(ScenarioError) as err:
        load_scenario(_write(tmp_path, text))
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_torque_table_out_of_time_order(tmp_path):
    text = GOOD + "\n[[torque]]\nt_s = 3.0\nleft_N_m = 0.0\nright_N_m = 0.0\n" \
                  "\n[[torque]]\nt_s = 2.0\nleft_N_m = 0.0\nright_N_m = 0.0\n"
    with pytest.raises(ScenarioError, match=r"torque\[2\]\.t_s = 2\.0 .*increasing"):
        load_scenario(_write(tmp_path, text))


def test_unknown_section_and_override_errors():
    with pytest.raises(ScenarioError, match="unknown key"):
        scenario_from_dict({"runn": {}, "torque": [{"t_s": 0, "left_N_m": 0, "right_N_m": 0}]})
    with pytest.raises(ScenarioError, match="section.key=value"):
        load_scenario("validation", ["mass_kg=3"])
    with pytest.raises(ScenarioError, match="run.integrator"):
        load_scenario("validation", ["run.integrator=euler"])
    with pytest.raises(ScenarioError, match="neither a file nor a built-in"):
        load_scenario("no_such_scenario")
    with pytest.raises(ScenarioError, match="stop_distance_event"):
        load_scenario("validation", ["run.stop_distance_event=start"])


def test_the_engine_section_reaches_the_terrain_engine_and_bad_values_are_refused():
    import pytest as _pytest

    from symtrack.foundations.errors import ScenarioError as _SE
    from symtrack.simulation.plants import make_plant
    from symtrack.simulation.scenario import load_scenario as _load

    sc = _load("multipass", ["engine.cell_substeps=3", "engine.power=instantaneous"])
    plant = make_plant(sc)
    assert plant.engine.settings.cell_substeps == 3 and plant.engine.settings.power == "instantaneous"
    assert "engine" in sc.to_dict() and sc.to_dict()["engine"]["cell_substeps"] == 3
    with _pytest.raises(_SE, match=r"engine.entry_fraction = 2"):
        _load("multipass", ["engine.entry_fraction=2"])
    with _pytest.raises(_SE, match="unknown key"):
        _load("multipass", ["engine.substeps=2"])


def test_set_reaches_nested_tables():
    """--set section.table.key=value: [terrain.surface] and [terrain.towed] from the command line."""
    sc = load_scenario("validation", ["terrain.surface.slope_y_deg=5", "model.vehicle=3d"])
    assert sc.terrain is None and sc.surface.slope_y_deg == 5.0  # homogeneous soil on that ground
    sc = load_scenario("examples/scenarios/multipass_trailer.toml", ["terrain.towed.axle_load_kN=90.0"])
    assert sc.terrain.towed.raw["axle_load_kN"] == 90.0
    with pytest.raises(ScenarioError, match=r"\[terrain.surface\] is not a table"):
        load_scenario("validation", ["terrain.surface=1", "terrain.surface.slope_y_deg=5"])
    with pytest.raises(ScenarioError, match="empty name"):
        load_scenario("validation", ["terrain..slope_y_deg=5"])
