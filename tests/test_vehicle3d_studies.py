"""The 3D vehicle's studies of issue 22 item 3 (docs/vehicle3d.md "Studies"), each example run with
short settings and checked against the geometry and statics that hold independently of the model:
the ramp (examples/ramp_3d.py), the furrows (examples/furrows_3d.py), the second pass in the ruts
(examples/second_pass_3d.py, in tests/test_grid3d.py's slow set: the 3D engine's compile)."""

from __future__ import annotations

import math
import runpy

import pytest


def test_example_ramp_3d_climb_and_descent():
    """A 10 deg ramp, 4 s each: the CG rises by the distance along the slope times sin t (0.1 % on the climb,
    measured 1e-5), the pitch is the ramp's less the ends' sinkage difference
    over the contact, the tracks carry W cos t, and on the climb the load's centre lies behind the
    contact centre by the statics' h (W sin t + m a) / (W cos t) (2 %; measured 0.2 % over 8 s, 1.4 % over 4 s).
    The statics' pressures are Bekker's virgin loading at every segment, the soil of steady running: the climb
    has run over more than its contact length of fresh soil by the last 2 s of 4 s (2.9 m); in 3 s (1.5 m)
    the front of the track is still on the soil it pressed at rest, whose memory holds it on its reloading
    lines (-12 %; docs/vehicle3d.md, "The model").
    The descent brakes at 0.75 x the holding torque and rolls down smoothly (it chattered before the
    running gear's angular momentum was in the hull's pitch, docs/vehicle3d.md "Studies: a ramp"): the
    idler pressure's range over the last 2 s within 1 kPa (measured 8 s: 29.713-29.732 kPa; before,
    0-170 kPa)."""
    ns = runpy.run_path("examples/ramp_3d.py")
    out = ns["main"](["--duration", "4"])
    climb, descent = out["climb"], out["descent"]
    assert climb["distance_along_slope_m"] > 1.0 and descent["distance_along_slope_m"] > 1.0
    for r in (climb, descent):
        assert abs(r["cg_rise_error_rel"]) < 1e-3, r
        assert r["pitch_mean_deg"] == pytest.approx(r["pitch_expected_deg"], abs=0.01)
        assert r["roll_max_abs_deg"] < 1e-6
        assert r["normal_load_sum_over_W_cos_t"] == pytest.approx(1.0, abs=0.01)
    assert climb["pitch_mean_deg"] > 9.9 and descent["pitch_mean_deg"] < -9.9
    assert climb["pressure_centre_behind_m"] == pytest.approx(climb["pressure_centre_statics_m"], rel=0.02)
    assert climb["p_sprocket_kPa"] > 1.5 * climb["p_idler_kPa"]  # the climb loads the rear
    lo, hi = descent["p_idler_range_kPa"]
    assert hi - lo < 1.0 and descent["p_idler_kPa"] > descent["p_sprocket_kPa"]  # smooth; braking loads the front


def test_example_furrows_3d_across_and_along():
    """Across furrows 9.6 m apart (4 contact lengths; 3 s, the first half wave) the pitch follows the
    rigid ground's geometry (RMS 0.18 deg measured against a largest slope of 1.87 deg); along furrows
    as far apart as the tracks both tracks run at one height: no roll, the load shared equally, and
    the hull drifts back into the furrows and off the ridges at the creep law's closed-form speed
    (measured 1 % of the change; 10 % allowed), its height between the two the furrow depth."""
    ns = runpy.run_path("examples/furrows_3d.py")
    out = ns["main"](["--spacings", "9.6", "--duration", "3", "--segments", "8"])
    (cross,) = out["across"]
    assert cross["pitch_rms_difference_deg"] < 0.3 and cross["roll_max_abs_deg"] < 1e-6
    assert cross["pitch_range_deg"][0] < -1.5  # it pitches nose down into the first furrow
    furrow, ridge = out["along"]
    assert furrow["tracks"] == "in the furrows" and ridge["tracks"] == "on the ridges"
    for r in (furrow, ridge):
        assert r["roll_max_abs_deg"] < 1e-3 and r["pitch_max_abs_deg"] < 0.05
        assert r["lower_share_mean"] == pytest.approx(0.5, abs=1e-4)
        change = r["offset_end_m"] - r["offset_start_m"]
        closed = r["offset_end_creep_closed_form_m"] - r["offset_start_m"]
        assert change == pytest.approx(closed, rel=0.1), r
    assert furrow["offset_end_m"] < furrow["offset_start_m"] and ridge["offset_end_m"] > ridge["offset_start_m"]
    # the CG's heights: the track lines' ground, a cos(k delta) below / above the mean, 0.1 m apart at delta = 0
    a, k = 0.05, 2 * math.pi / 1.5
    geometry = a * math.cos(k * ridge["offset_end_m"]) + a * math.cos(k * furrow["offset_end_m"])
    assert ridge["cg_height_end_m"] - furrow["cg_height_end_m"] == pytest.approx(geometry, abs=2e-4)
