"""What a new user met reading the docs (issue 41), each answered where it happens: the console line of a
field study's pattern, the starting files' headers, the scenario keys' table, the presets' sources and
their compact view, the field study's soil record, its per-depth strength and its density."""

from __future__ import annotations

from symtrack.cli.field import pattern_lines


def test_the_pattern_line_counts_cells_by_pass_count():
    f = {"passes_per_cell_histogram": [9048, 17, 7, 2592], "trafficked_area_fraction": 0.2243,
         "rut_mean_depth_mm": 0.7, "rut_max_depth_mm": 1.25, "passes_done": 6, "wall_time_s": 0.6,
         "subsoil_depths_m": [0.1, 0.3], "risk_fraction_of_field_medium": [0.061, 0.028]}
    lines = pattern_lines("controlled", f)
    assert "cells by pass count {0: 9048, 1: 17, 2: 7, 3: 2592}" in lines[0]
    assert "per pass count" not in lines[0]
    assert lines[1] == "  medium risk (% of the field): 0.1 m 6.10 %, 0.3 m 2.80 %"


def test_a_value_given_equal_to_the_bases_derived_one_is_kept(tmp_path):
    """sandy_loam_15's topsoil is 1.55 Mg/m^3, so its derived subsoil density is 1.55 too: a file (or a
    scenario) that loosens the topsoil to 1.35 and gives the subsoil 1.55 keeps its subsoil at 1.55, not
    re-derived to the new topsoil's 1.35."""
    from symtrack.presets.catalog import read_preset_file
    from symtrack.simulation.scenario import load_scenario

    path = tmp_path / "two_layers.toml"
    path.write_text('base = "sandy_loam_15"\nsubsoil_top_m = 0.25\nbulk_density_initial_Mg_per_m3 = 1.35\n'
                    "subsoil_bulk_density_initial_Mg_per_m3 = 1.55\n")
    values, _, _ = read_preset_file(path, "soil")
    assert values["bulk_density_initial_Mg_per_m3"] == 1.35
    assert values["subsoil_bulk_density_initial_Mg_per_m3"] == 1.55
    sc = load_scenario("validation", ["soil.preset=sandy_loam_15", "soil.bulk_density_initial_Mg_per_m3=1.35",
                                      "soil.subsoil_bulk_density_initial_Mg_per_m3=1.55"])
    assert sc.soil["subsoil_bulk_density_initial_Mg_per_m3"] == 1.55
    # what is not given is still derived from the new values
    sc = load_scenario("validation", ["soil.preset=sandy_loam_15", "soil.bulk_density_initial_Mg_per_m3=1.35"])
    assert sc.soil["subsoil_bulk_density_initial_Mg_per_m3"] == 1.35
