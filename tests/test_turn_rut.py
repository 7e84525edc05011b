"""The rut of a steady turn on the grid terrain against a straight pass at the same speed
(examples/turn_rut.py, docs/turning.md section 5), on the lagged shear law."""

import math
import runpy

import pytest


@pytest.fixture(scope="module")
def rut():
    ns = runpy.run_path("examples/turn_rut.py")
    return ns["compare"]("sandy_loam_15", "shear", 2.0, 10.0, turn_deg=90.0)


def test_turn_rut_is_deeper_outside_shallower_inside_and_wider(rut):
    """The physics: a left turn's centripetal force m V^2 / R acts at the CG height, so the outer
    (right) track carries more of the weight and the inner less (N = W/2 +- m a_y h / B, docs/model.md,
    "Normal pressure and load transfer"); Bekker's z ~ p^(1/n) then makes the outer rut deeper and the
    inner shallower than the straight pass's, by (N_k / N_straight)^(1/n) - 1 (the cells' soil law; speed
    alone moves the straight rut by 0.1 % between 1.85 and 2.15 m/s, measured). And a rigid track turning
    on a circle sweeps a band wider than its width b: its ends lie (l/2)^2 / (2 r_k) outside its centre
    line's circle, so both turn ruts are wider and carry more soil per metre than the straight one. Every
    cell is loaded once (one pass) in both."""
    inner, outer = rut["turn"]["inner"], rut["turn"]["outer"]
    straight = rut["straight"]["left"]
    assert inner["depth_mm"] < straight["depth_mm"] < outer["depth_mm"]
    b_in, b_out = rut["bekker_load_transfer_inner_outer"]
    assert rut["inner_vs_straight_depth_mm"] == pytest.approx(b_in, abs=0.015)
    assert rut["outer_vs_straight_depth_mm"] == pytest.approx(b_out, abs=0.015)
    from symtrack.presets import vehicle_preset

    V = vehicle_preset("reference_crawler")
    half_l, B = V["contact_length_m"] / 2, V["track_gauge_m"]
    for side, r_k in ((inner, 10.0 - B / 2), (outer, 10.0 + B / 2)):
        assert side["width_m"] > straight["width_m"] + 0.5 * half_l**2 / (2 * r_k)
        assert side["area_mm_m"] > straight["area_mm_m"]
        assert side["load_cycles_mean"] == pytest.approx(1.0, abs=0.02)
    assert math.isclose(rut["radius_fitted_m"], 10.0, rel_tol=0.01)  # the grid run holds the trim's turn
