"""The vehicle model against independent truth: Wong's closed forms, Bekker, M_r = mu W l / 4."""

import math

import casadi as ca
import numpy as np
import pytest

from symtrack.model import ModelOptions, SystemModel
from symtrack.model.static import static_state
from symtrack.vehicles.planar import GRAVITY_M_S2


def _state(model, **values):
    x = np.zeros(model.nx)
    for k, v in values.items():
        x[model.state_index(k)] = v
    return x


def _out(model, x, p, name, u=(0.0, 0.0)):
    return float(model.outputs(x, u, p)[model.output_index(name)])


def _steady_shear(model, x, p, track):
    """Zero of the model's own shear equation (all else fixed), by Newton."""
    i = model.state_index(f"shear_{track}_m")
    j = ca.SX.sym("j")
    xs = ca.SX(ca.DM(x))
    xs[i] = j
    g = ca.Function("g", [j], [model.ode(xs, [0, 0], p)[i]])
    return float(ca.rootfinder("r", "newton", g)(0.0))


_MODELS: dict = {}


@pytest.mark.parametrize("slip", [0.02, 0.1, 0.3])
@pytest.mark.parametrize("law, rel", [("creep", 1e-5), ("shear", 1e-4)])
def test_steady_shear_is_i_l_over_2_and_traction_is_wongs(params, slip, law, rel):
    """Ferretti & Girelli's tractive effort is Wong's closed form; the shear law's straight-running thrust
    is eq. (1) by its quadrature along the track (docs/turning.md section 1: 4e-5 at 10 %, 7e-5 at 30 % slip)."""
    model = _MODELS.setdefault(law, SystemModel(ModelOptions(lateral_law=law)))
    p = model.param_vector(params)
    r, l = params["sprocket_radius_m"], params["contact_length_m"]
    omega = 10.0
    u = r * omega * (1 - slip)
    x = _state(model, u_m_s=u, omega_left_rad_s=omega, omega_right_rad_s=omega)
    j = _steady_shear(model, x, p, "left")
    # tolerance: |omega| is regularised as sqrt(omega^2 + eps^2): relative (eps/omega)^2 / 2 = 5e-7
    assert j == pytest.approx(slip * l / 2, rel=2e-6)
    x[model.state_index("shear_left_m")] = j
    # Wong, Theory of Ground Vehicles: F = (A c + W tan phi) [1 - K/(i l) (1 - exp(-i l / K))]
    A = params["track_width_m"] * l
    W_track = params["mass_kg"] * GRAVITY_M_S2 / 2
    K = params["shear_modulus_K_m"]
    wong = (A * params["cohesion_Pa"] + W_track * math.tan(params["friction_angle_rad"])) * (
        1 - K / (slip * l) * (1 - math.exp(-slip * l / K)))
    assert _out(model, x, p, "tractive_left_N") == pytest.approx(wong, rel=rel)


def test_tanh_option_matches_smooth_away_from_zero(params):
    m_tanh = SystemModel(ModelOptions(traction_sign="tanh", tanh_steepness_per_m=1e4))
    m_smooth = SystemModel()
    p = m_smooth.param_vector(params)
    x = _state(m_smooth, shear_left_m=0.01, shear_right_m=-0.004, omega_left_rad_s=5, omega_right_rad_s=5)
    for name in ("tractive_left_N", "tractive_right_N"):
        a, b = _out(m_tanh, x, p, name), _out(m_smooth, x, p, name)
        assert a == pytest.approx(b, rel=1e-6)
        assert abs(a) > 100


def test_turning_resistance_moment_pure_yaw_uniform_pressure(params):
    """Wong: M_r = mu_t W l / 4 for pure yaw on a uniform pressure (saturated friction), for the
    creep law (the shear law's own test is in tests/test_lateral.py)."""
    model = SystemModel(ModelOptions(lateral_law="creep"))
    pr = dict(params, cg_ahead_of_contact_centre_m=0.0, lateral_creep_speed_m_s=1e-6)
    p = model.param_vector(pr)
    x = _state(model, yaw_rate_rad_s=0.5)  # at rest otherwise, no sinkage -> no compaction
    W = pr["mass_kg"] * GRAVITY_M_S2
    M_r = pr["lateral_friction_coeff"] * W * pr["contact_length_m"] / 4
    assert _out(model, x, p, "yaw_moment_N_m") == pytest.approx(-M_r, rel=1e-4)
    # and no net lateral force by symmetry
    assert abs(_out(model, x, p, "lateral_force_left_N") + _out(model, x, p, "lateral_force_right_N")) < 1e-6 * W


def test_static_sinkage_is_bekkers_inverse(model, params):
    """At rest on level ground (e = 0): uniform pressure W/(2 b l), sinkage (p/k_eq)^(1/n)."""
    x = static_state(model, params)
    p_mean = params["mass_kg"] * GRAVITY_M_S2 / (2 * params["track_width_m"] * params["contact_length_m"])
    keq = params["k_c_N_per_m_n1"] / params["track_width_m"] + params["k_phi_N_per_m_n2"]
    z = (p_mean / keq) ** (1 / params["bekker_n"])
    for end in ("sprocket", "idler"):
        for k in ("left", "right"):
            # tolerance: the finite-slope regularisation, relative |1-n| d / z / n ~ 6e-4
            assert x[model.state_index(f"sinkage_{end}_{k}_m")] == pytest.approx(z, rel=1e-3)


def test_exact_jacobian_matches_finite_differences(model, params):
    p = model.param_vector(params)
    rng = np.random.default_rng(1)
    x = static_state(model, params)
    for k in ("left", "right"):  # nose up, away from the branch switch z_sprocket = z_idler
        x[model.state_index(f"sinkage_sprocket_{k}_m")] *= 1.3
        x[model.state_index(f"sinkage_rate_idler_{k}_m_s")] = -1e-3
    x[model.state_index("u_m_s")] = 4.0
    x[model.state_index("v_m_s")] = 0.003
    x[model.state_index("yaw_rate_rad_s")] = 0.004
    x[model.state_index("omega_left_rad_s")] = 11.0
    x[model.state_index("omega_right_rad_s")] = 11.5
    x[model.state_index("shear_left_m")] = 0.006
    x[model.state_index("shear_right_m")] = 0.009
    x[model.state_index("torque_left_N_m")] = 1500
    x[model.state_index("torque_right_N_m")] = 1800
    u = np.array([1600.0, 1900.0])
    A, B = (np.array(m) for m in model.jac_ode(x, u, p))
    f0 = lambda xx, uu: np.array(model.ode(xx, uu, p)).ravel()  # noqa: E731
    for i in rng.choice(model.nx, size=model.nx, replace=False):
        h = 1e-6 * max(1.0, abs(x[i])) if not model.state_names[i].startswith("sinkage_") else 1e-9
        e = np.zeros(model.nx)
        e[i] = h
        fd = (f0(x + e, u) - f0(x - e, u)) / (2 * h)
        scale = np.maximum(np.abs(A[:, i]), 1e-6 * np.abs(A).max(axis=1) + 1e-9)
        assert np.all(np.abs(fd - A[:, i]) <= 2e-4 * scale + 1e-6), model.state_names[i]
    for i in range(2):
        e = np.zeros(2)
        e[i] = 1.0
        fd = (f0(x, u + e) - f0(x, u - e)) / 2
        assert np.allclose(fd, B[:, i], rtol=1e-6, atol=1e-9)


def test_load_transfer_loop_fixed_point_residual_is_negligible(model, params):
    """The ODE form closes the acceleration/pressure loop by fixed-point iterations: at states of
    a hard manoeuvre the remaining residual z - g(x, z) is far below the accelerations."""
    p = model.param_vector(params)
    x = static_state(model, params)
    x[model.state_index("u_m_s")] = 5.0
    x[model.state_index("yaw_rate_rad_s")] = 0.3
    x[model.state_index("v_m_s")] = -0.02
    x[model.state_index("omega_left_rad_s")] = 12.0
    x[model.state_index("omega_right_rad_s")] = 16.0
    x[model.state_index("shear_left_m")] = -0.004
    x[model.state_index("shear_right_m")] = 0.03
    u = [0.0, 2000.0]
    z = model.accel(x, u, p)
    _, alg = model.dae(x, z, u, p)
    assert float(ca.norm_inf(alg)) < 1e-6 * max(1.0, float(ca.norm_inf(z)))
    assert float(ca.norm_inf(z)) > 0.1  # the manoeuvre does accelerate


def test_nose_up_under_traction(model, params):
    """Traction at ground level moves load to the rear: p_sprocket > p_idler when accelerating."""
    p = model.param_vector(params)
    x = static_state(model, params)
    x[model.state_index("shear_left_m")] = 0.01
    x[model.state_index("shear_right_m")] = 0.01
    x[model.state_index("omega_left_rad_s")] = 1.0
    x[model.state_index("omega_right_rad_s")] = 1.0
    ps, pi = _out(model, x, p, "p_sprocket_left_Pa"), _out(model, x, p, "p_idler_left_Pa")
    assert _out(model, x, p, "accel_x_m_s2") > 0.5
    assert ps > pi * 1.1


def test_lateral_shear_cap_limits_the_turning_resistance_to_the_soil_strength(params):
    """With the cap, pure yaw on uniform pressure meets M = (c + p tan phi) b l^2 / 4 per track
    where the soil is weaker than mu_t p (clayey soil: c + p tan phi < 0.55 p at 25 kPa)."""
    model = SystemModel(ModelOptions(lateral_law="creep", lateral_shear_cap=True))
    pr = dict(params, cg_ahead_of_contact_centre_m=0.0, lateral_creep_speed_m_s=1e-6)
    p = model.param_vector(pr)
    x = _state(model, yaw_rate_rad_s=0.5)
    b, l = pr["track_width_m"], pr["contact_length_m"]
    p_mean = pr["mass_kg"] * GRAVITY_M_S2 / (2 * b * l)
    strength = pr["cohesion_Pa"] + p_mean * math.tan(pr["friction_angle_rad"])
    assert strength < pr["lateral_friction_coeff"] * p_mean  # the cap binds on this soil
    M = 2 * strength * b * l**2 / 4
    assert _out(model, x, p, "yaw_moment_N_m") == pytest.approx(-M, rel=1e-4)


def test_with_the_cap_the_creep_law_turns_on_clay(params):
    from symtrack.control.trim import TrimError, trim

    with pytest.raises(TrimError, match="traction limit"):
        trim(SystemModel(ModelOptions(lateral_law="creep")), params, 2.0, 20.0)
    tp = trim(SystemModel(ModelOptions(lateral_law="creep", lateral_shear_cap=True)), params, 2.0, 20.0)
    assert tp.u[0] < 0 < tp.u[1]  # a left turn: the inner (left) sprocket brakes


@pytest.mark.parametrize("speed_m_s", [0.3, 1.0, 4.0])
def test_reported_slip_is_the_true_slip_in_straight_running(model, params, speed_m_s):
    """slip = 1 - v / (r omega): a true slip of 1e-5 (straight running) is reported as 1e-5, not with
    the offset of a dimensionally inconsistent regularisation (which gave 1.45e-3 at 1 m/s)."""
    r = params["sprocket_radius_m"]
    omega = speed_m_s / (r * (1 - 1e-5))
    x = _state(model, u_m_s=speed_m_s, omega_left_rad_s=omega, omega_right_rad_s=omega)
    for k in ("left", "right"):
        # the regularisation's relative error (eps / (r omega))^2: 1.1e-3 at 0.3 m/s, 1e-4 at 1 m/s
        assert _out(model, x, model.param_vector(params), f"slip_{k}") == pytest.approx(1e-5, rel=1.2e-3)


def test_reported_slip_is_regularised_through_omega_zero():
    """track_slip is 0 at omega = 0, bounded near it, and the exact slip once r omega >> SLIP_SPEED_SCALE_M_S;
    it depends on r omega and v only (dimensionally consistent: r scaled at fixed tread speed is the same)."""
    from symtrack.vehicles.planar import SLIP_SPEED_SCALE_M_S, track_slip
    assert float(track_slip(1.0, 0.0, 0.38)) == 0.0
    eps = SLIP_SPEED_SCALE_M_S
    assert abs(float(track_slip(1.0, eps / 0.38, 0.38))) <= 1.0 / (2 * eps) + 1e-9
    assert float(track_slip(0.7, 2.0, 0.5)) == pytest.approx(0.3, rel=1e-4)
    assert float(track_slip(0.7, 2.0, 0.5)) == pytest.approx(float(track_slip(0.7, 1.0, 1.0)), rel=1e-12)
    assert float(track_slip(-0.7, -2.0, 0.5)) == pytest.approx(0.3, rel=1e-4)  # reversing: the same slip
