"""Integrators against each other and against a fine fixed-step reference; the validation run."""

import casadi as ca
import numpy as np
import pytest

from symtrack import validation
from symtrack.runner import run, summarise
from symtrack.scenario import load_scenario
from symtrack.simulate import IntegratorSettings, Stepper, static_state


@pytest.fixture(scope="module")
def summaries():
    out = {}
    for integ in ("cvodes", "idas"):
        res = run(load_scenario("validation", [f"run.integrator={integ}"]), progress=False)
        out[integ] = summarise(res)
    return out


# With the soil's shear law (lateral_law = "shear", the default since issue 11) the yaw and the
# lateral deviation of the validation are set by the Janosi shear modulus K and the soil's
# strength, not by a creep speed, and no parameter set in the plausible ranges of MODEL.md
# section 4 brings them into the seed's bands (docs/turning.md, "The validation"). Known, kept
# visible here.
YAW_FIGURES = ("yaw_final_deg", "lateral_deviation_m")


def test_validation_meets_the_reported_figures(summaries):
    for key, reported, value, ok in validation.check(summaries["cvodes"]):
        if key not in YAW_FIGURES:
            assert ok, f"{key} = {value} not within '{reported}'"
    assert summaries["cvodes"]["distance_after_idle_m"] == pytest.approx(20.0, abs=1e-3)


@pytest.mark.xfail(strict=True, reason="the shear law's yaw creep is set by K: docs/turning.md, The validation")
def test_validation_yaw_and_lateral_deviation_meet_the_reported_figures(summaries):
    rows = {key: (reported, value, ok) for key, reported, value, ok in validation.check(summaries["cvodes"])}
    for key in YAW_FIGURES:
        reported, value, ok = rows[key]
        assert ok, f"{key} = {value} not within '{reported}'"


def test_validation_with_the_creep_law_meets_every_reported_figure():
    """The earlier law, kept as an option, still reproduces the seed's table."""
    s = summarise(run(load_scenario("validation", ['model.lateral_law="creep"']), progress=False))
    for key, reported, value, ok in validation.check(s):
        assert ok, f"{key} = {value} not within '{reported}'"


def test_cvodes_and_idas_agree(summaries):
    a, b = summaries["cvodes"], summaries["idas"]
    for key in ("lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm", "sinkage_idler_mm",
                "shear_driven_max_m", "shear_idle_min_m", "sim_time_s"):
        assert a[key] == pytest.approx(b[key], rel=1e-4), key


def test_cvodes_and_idas_match_a_fine_fixed_step_reference(model, params):
    """Radau IIA (3 stages, order 5) with fixed 0.5 ms steps over the first second of the
    validation manoeuvre, a scheme independent of the BDF methods of CVODES and IDAS."""
    p = model.param_vector(params)
    x0 = static_state(model, params)
    u = [2000.0, 2000.0]
    dt, n_out = 0.05, 20
    ref = ca.integrator("ref", "collocation", {"x": model.x, "u": model.u, "p": model.p, "ode": model.ode_expr},
                        0, dt, {"number_of_finite_elements": 100, "collocation_scheme": "radau",
                                "interpolation_order": 3})
    xr = x0.copy()
    for _ in range(n_out):
        xr = np.array(ref(x0=xr, u=u, p=p)["xf"]).ravel()
    scale = np.maximum(np.abs(xr), 1e-3)
    scale[model.state_index("x_m")] = 1.0
    for method in ("cvodes", "idas"):
        st = Stepper(model, IntegratorSettings(method, reltol=1e-9, abstol=1e-12))
        x = x0.copy()
        for _ in range(n_out):
            x = st.step(x, u, p, dt)
        err = np.abs(x - xr) / scale
        assert err.max() < 1e-5, (method, model.state_names[int(err.argmax())], err.max())
    assert xr[model.state_index("u_m_s")] > 1.0  # it did accelerate
