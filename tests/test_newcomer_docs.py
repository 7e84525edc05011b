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
