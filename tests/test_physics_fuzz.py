"""The physics fuzzer (symtrack/bench/fuzz.py; issue 37, item 2): random but plausible homogeneous
scenarios drawn by hypothesis, each run on the compiled Rosenbrock and on CVODES and checked: finite
states or a clear refusal, the fixed step within 2 % of CVODES (or flagged by its own error estimate),
mirror symmetry on flat ground, no kinetic energy gained in a coast beyond the motors' work and the
shear's elastic energy, a vehicle at rest staying at rest. A small budget here (derandomized: CI sees
the same cases every run); ``python -m symtrack.bench.fuzz --budget N`` is the long run.

Shrunk failures of the long run are fixed scenarios below: the defects not fixed yet are expected
failures (strict: a fix makes them pass, and then the mark must go)."""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from symtrack.bench import fuzz

# the variants whose compiled Rosenbrock the rest of the suite builds too (one compile each, cached)
VARIANTS = ("planar-creep", "planar-shear", "3d-creep")
# CVODES on CasADi's interpreter: the compiled reference would compile each variant once more
REFERENCE = {"compiled": False}
# Outside the model's known limits, each kept by a shrunk case below or in docs/model.md ("The physics
# fuzzer"): no WES heavy clay (n = 0.11), and torques that do not spin the tracks up (at most 0.3 of the
# torque whose thrust is the weight).
SOILS = tuple(s for s in fuzz.SOILS if s != "heavy_clay_wes_40")
TORQUE_FRACTION = (0.03, 0.3)


class HypothesisDraw:
    """The two draws of :func:`symtrack.bench.fuzz.case_document`, through hypothesis (which then
    shrinks a failing case by its draws)."""

    def __init__(self, data):
        self.data = data

    def uniform(self, lo: float, hi: float) -> float:
        return self.data.draw(st.floats(lo, hi, allow_nan=False, allow_infinity=False))

    def choice(self, seq):
        return self.data.draw(st.sampled_from(list(seq)))


# SYMTRACK_FUZZ_EXAMPLES=200 for a longer search here; the long run is python -m symtrack.bench.fuzz
# (no shrinking here: a failure prints its scenario document, python -m symtrack.bench.fuzz shrinks)
@settings(max_examples=int(os.environ.get("SYMTRACK_FUZZ_EXAMPLES", "8")), deadline=None, derandomize=True,
          phases=[Phase.explicit, Phase.generate], suppress_health_check=[HealthCheck.too_slow,
                                                                          HealthCheck.data_too_large])
@given(st.data())
def test_a_random_plausible_scenario_keeps_every_property(data):
    doc, meta = fuzz.case_document(HypothesisDraw(data), VARIANTS, duration_s=(0.5, 1.0), soils=SOILS,
                                   torque_fraction=TORQUE_FRACTION)
    out = fuzz.check_case(doc, meta, reference=REFERENCE)
    assert not out.failed, f"{meta}: {out.messages}\n{doc}"


def _doc(model: dict, torque: list, vehicle=None, soil="clayey_soil_thailand_38", duration=1.0, surface=None) -> dict:
    doc = {"name": "fuzz-regression", "run": {"duration_s": duration, "output_dt_s": 0.01, "integrator": "rosenbrock"},
           "model": model, "vehicle": {"preset": "reference_crawler", **(vehicle or {})}, "soil": {"preset": soil},
           "torque": [{"t_s": t, "left_N_m": left, "right_N_m": right} for t, left, right in torque]}
    if surface is not None:
        doc["terrain"] = {"surface": surface}
    return doc


def test_the_checks_catch_a_fixed_step_run_without_error_control():
    """The comparison is not vacuous: the drive-and-coast case that a 10 ms step got wrong without the
    error control (run.fixed_step_tolerance = 0: every step taken as it is) is outside the tolerance of
    CVODES, and its own error estimate says so (flagged, not failed); with the default control it is
    within."""
    torque = [(0.0, 2500.0, 2500.0), (5.0, 0.0, 0.0)]
    doc = _doc({"lateral_law": "creep"}, torque, duration=5.5)
    meta = {"variant": "planar-creep", "programme": "coast", "flat": True}
    off = fuzz.check_case(fuzz._with_run(doc, fixed_step_tolerance=0.0), meta, reference=REFERENCE, symmetry=False)
    assert off.status["accuracy"] == "flagged" and "sinkage_sprocket_mm" in off.messages["accuracy (flagged)"]
    assert off.figures["fixed_step_error_max"] > 1.0
    on = fuzz.check_case(doc, meta, reference=REFERENCE, symmetry=False)
    assert on.status["accuracy"] == "pass" and on.status["energy"] == "pass", on.messages


def test_a_mirrored_turn_is_the_mirror_image_and_rest_stays_rest():
    """A turn and its mirror on the planar shear law; zero torque from rest on the 3D hull."""
    turn = _doc({"lateral_law": "shear"}, [(0.0, 1500.0, 1500.0), (0.4, 300.0, 1500.0)])
    out = fuzz.check_case(turn, {"variant": "planar-shear", "programme": "turn", "flat": True}, reference=REFERENCE)
    assert out.status["symmetry"] == "pass" and not out.failed, out.messages
    rest = _doc({"lateral_law": "creep", "vehicle": "3d"}, [(0.0, 0.0, 0.0)])
    out = fuzz.check_case(rest, {"variant": "3d-creep", "programme": "zero", "flat": True}, reference=REFERENCE)
    assert out.status["rest"] == "pass" and not out.failed, out.messages


def test_a_case_is_redrawn_from_its_seed():
    """The long run's CSV names each case's seed: the same seed gives the same document."""
    a, _ = fuzz.case_document(fuzz.RandomDraw(37_000_111))
    b, _ = fuzz.case_document(fuzz.RandomDraw(37_000_111))
    assert a == b


# ---- shrunk failures of the long run ------------------------------------------------------------------------
def test_3d_at_rest_on_a_ramp_of_heavy_clay_settles():
    """Shrunk from the long run: the reference crawler with its CG 5 cm behind the contact centre, at rest on
    an 8 deg ramp of the WES heavy clay (n = 0.11: the pressure-sinkage law is nearly flat, its stiffness
    n p / z enormous at the micrometre sinkage of 25 kPa): the settling to the static state before the run
    failed with CV_TOO_MUCH_WORK on CasADi's default step budget, raised as a RuntimeError (a traceback);
    it settles now, and the run keeps every property."""
    doc = _doc({"lateral_law": "creep", "vehicle": "3d"}, [(0.0, 0.0, 0.0)], soil="heavy_clay_wes_40",
               vehicle={"cg_ahead_of_contact_centre_m": -0.05}, duration=0.2, surface={"slope_x_deg": 8.0})
    out = fuzz.check_case(doc, {"variant": "3d-creep-ramp8", "programme": "zero", "flat": False}, reference=REFERENCE)
    assert not out.failed, out.messages


@pytest.mark.xfail(strict=True, reason="defect: the tractive force is a function of the lagged mean shear "
                                       "displacement alone, so shear far beyond K gives its (plastic) work back "
                                       "when the slip reverses")
def test_a_coast_after_spinning_tracks_gains_no_energy():
    """Shrunk from the long run: the reference crawler on the validation's clay, 6000 N m on both sprockets
    for 1 s (the tracks spin: tread 17.5 m/s, body 3.5 m/s, shear displacement 0.95 m = 63 K), then 0 N m.
    After the release the tread slows below the body's speed, yet the force stays forward while the
    displacement runs back from 0.95 m to 0: the body goes on accelerating to 5.4 m/s, the sprocket is
    driven backwards, and the running gear rings between the two saturated forces; the kinetic energy rises
    by some 9 kJ beyond the motors' work (CVODES and the Rosenbrock alike)."""
    doc = _doc({"lateral_law": "shear"}, [(0.0, 6000.0, 6000.0), (1.0, 0.0, 0.0)], duration=1.6)
    out = fuzz.check_case(doc, {"variant": "planar-shear", "programme": "coast", "flat": True}, reference=REFERENCE,
                          symmetry=False)
    assert out.status["energy"] == "pass", out.messages


@pytest.mark.xfail(strict=True, reason="defect: the compiled Rosenbrock diverges on the 3D shear law at rest across "
                                       "a side slope, where CVODES holds the vehicle")
def test_3d_at_rest_across_a_side_slope_stays_bounded_on_the_fixed_step():
    """Shrunk from the long run (8 cases of 2000, all this variant): the reference crawler (CG 6.4 cm ahead of the
    contact centre, J_eq 10 kg m^2) parked across an 8 deg side slope of the 15 % sandy loam on the "shear" law,
    zero torque. CVODES keeps it within centimetres; the compiled Rosenbrock at 10 ms keeps steps whose error
    estimate stays above its tolerance after the halvings, and the run diverges (here stopped by the speed
    limit at 2.6e6 m/s; in the other cases complete with tread speeds of hundreds of m/s and the hull rolled
    over, or stopped on a non-finite state)."""
    doc = _doc({"lateral_law": "shear", "vehicle": "3d"}, [(0.0, 0.0, 0.0)], soil="sandy_loam_15", duration=0.855,
               vehicle={"cg_ahead_of_contact_centre_m": 0.063973, "sprocket_inertia_kg_m2": 10.0},
               surface={"slope_y_deg": 8.0})
    doc["start"] = {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 180.0}
    out = fuzz.check_case(doc, {"variant": "3d-shear-side8", "programme": "zero", "flat": False}, reference=REFERENCE)
    assert not out.failed, out.messages
