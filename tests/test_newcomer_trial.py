"""What a newcomer met following the getting-started tutorial: a parameter named in another unit is
refused with the name it should have, and the starting files carry no measured speeds (the
documentation's performance page has them, measured on the reader's kind of machine)."""

from __future__ import annotations

import re
from importlib import resources

import pytest

import symtrack
from symtrack.foundations.config import key_hints
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.presets.catalog import read_preset_file


def test_key_hints_name_the_key_in_its_unit():
    allowed = ["preset", "cohesion_Pa", "friction_angle_rad", "mass_kg"]
    assert "did you mean friction_angle_rad (in radians" in key_hints(["friction_angle_deg"], allowed)
    assert "did you mean cohesion_Pa (in Pa)" in key_hints(["cohesion_kPa"], allowed)
    assert "did you mean mass_kg" in key_hints(["mass"], allowed)
    assert "did you mean preset" in key_hints(["presett"], allowed)
    assert key_hints(["colour"], allowed) == ""


def test_a_soil_angle_in_degrees_is_refused_with_its_name_in_radians(tmp_path):
    f = tmp_path / "wet.toml"
    f.write_text('base = "clayey_soil_thailand_38"\nfriction_angle_deg = 18.0\n')
    with pytest.raises(ParameterError, match=r"friction_angle_deg: did you mean friction_angle_rad"):
        read_preset_file(f, "soil")
    with pytest.raises(ScenarioError, match=r"cohesion_kPa: did you mean cohesion_Pa"):
        symtrack.load_scenario("validation", ["soil.cohesion_kPa=3"])


def test_the_starting_files_hold_no_measured_speed():
    for f in resources.files("symtrack.cli").joinpath("templates").iterdir():
        if f.name.endswith(".toml"):
            text = f.read_text(encoding="utf-8")
            assert not re.search(r"\d\s*x real time", text), f.name
