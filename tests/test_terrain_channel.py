"""One channel (symtrack.terrain.channels) through load, unload and reload against the analytic law,
with its history kept by the channel's INFO_OUT function, as the world manager keeps it; and the
channel geometry (load fraction, end-strip weights) against hand computations."""

import casadi as ca
import numpy as np
import pytest

from symtrack.model.options import ModelOptions
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.soil import cell
from symtrack.soil.law import BekkerWong
from symtrack.terrain.channels import PHASE_LOADING, PHASE_UNLOADING, build_cell_functions
from symtrack.vehicles.planar import LATERAL_STATES, VEHICLE_STATES

PARAMS = {**vehicle_preset("reference_crawler"), **soil_preset("clayey_soil_thailand_38")}
FN = build_cell_functions(ModelOptions())
SOIL = BekkerWong(ModelOptions())
LAW = SOIL.values(PARAMS)
KE, KAPPA = SOIL.named(LAW)["elastic_stiffness_Pa_per_m"], SOIL.named(LAW)["kappa"]


def _channel_step(dt):
    z, zd, pl, zmax, pmax = (ca.SX.sym(n) for n in ("z", "zd", "p_load", "z_max", "p_max"))
    p = FN["soil"](z, ca.vertcat(zmax, pmax, 0, 0, 0), LAW)
    xdot = FN["dynamics"](zd, pl, p, 1.0, [PARAMS["cell_areal_mass_kg_per_m2"], PARAMS["cell_damping_Pa_s_per_m"]])
    dae = {"x": ca.vertcat(z, zd), "p": ca.vertcat(pl, zmax, pmax), "ode": xdot}
    return ca.integrator("ch", "cvodes", dae, 0, dt, {"abstol": 1e-12, "reltol": 1e-10})


def test_one_channel_load_unload_reload_matches_the_analytic_curves():
    F = _channel_step(2e-3)
    x, zmax, pmax = np.zeros(2), 0.0, 0.0
    ends, phases = [], []
    for a, b in [(0.0, 30e3), (30e3, 10e3), (10e3, 30e3), (30e3, 40e3)]:
        for k, s in enumerate(np.linspace(0, 1, 501)[1:]):
            x = np.array(F(x0=x, p=[a + (b - a) * s, zmax, pmax])["xf"]).ravel()
            zmax, pmax, _, _, phase, _ = (float(v) for v in FN["history"](x[0], [zmax, pmax, 0, 0, 0], LAW))
            if k == 300:
                phases.append(phase)  # the phase flag on the ramp
        for _ in range(200):  # hold: settle to the static state
            x = np.array(F(x0=x, p=[b, zmax, pmax])["xf"]).ravel()
            zmax, pmax, _, _, phase, _ = (float(v) for v in FN["history"](x[0], [zmax, pmax, 0, 0, 0], LAW))
        ends.append((x[0], zmax, pmax))
    bekker = lambda p: SOIL.static_sinkage(p, LAW)  # noqa: E731  Bekker's z = (p / k_eq)^(1/n)
    z1 = bekker(30e3)
    assert ends[0][0] == pytest.approx(z1, rel=2e-3)  # virgin loading on Bekker's curve
    assert ends[0][2] == pytest.approx(30e3, rel=2e-3)  # p_max recorded
    k_u = max(KE, KAPPA * ends[0][2] / ends[0][1])
    assert ends[1][0] == pytest.approx(ends[0][1] - 20e3 / k_u, rel=2e-3)  # unloading line
    assert ends[2][0] == pytest.approx(ends[0][1], rel=2e-3)  # reloading line back to z_max
    assert ends[3][0] == pytest.approx(bekker(40e3), rel=2e-3)  # rejoins Bekker beyond p_max
    assert (phases[0], phases[1], phases[3]) == (PHASE_LOADING, PHASE_UNLOADING, PHASE_LOADING)


def _geometry(cx, cy, X=0.0, Y=0.0, psi=0.0, active=1.0, dx=0.1):
    P = PARAMS
    geo = [P["contact_length_m"], P["track_width_m"], P["track_gauge_m"], P["cg_ahead_of_contact_centre_m"],
           dx, 2 * dx]
    return np.array(FN["geometry"]([cx, cy, 0, 0, active, 0, 0, 0], [X, Y, psi], geo)).ravel()


def test_load_fraction_is_the_overlap_of_the_cell_with_the_track():
    l, b, B = PARAMS["contact_length_m"], PARAMS["track_width_m"], PARAMS["track_gauge_m"]
    # a cell fully under the left track
    g = _geometry(0.0, B / 2)
    assert g[0] == pytest.approx(1.0) and g[1] == 0.0
    # a cell straddling the left track's outer edge by a quarter of its width
    g = _geometry(0.0, B / 2 + b / 2 + 0.025)
    assert g[0] == pytest.approx(0.25)
    # a cell straddling the front end by 30 %
    g = _geometry(l / 2 + 0.02, -B / 2)
    assert g[1] == pytest.approx(0.3) and g[0] == 0.0
    # rotated by 90 deg: the left track now lies along -x
    g = _geometry(-B / 2, 0.0, psi=np.pi / 2)
    assert g[0] == pytest.approx(1.0)
    # an inactive channel carries no load and no weight
    assert np.all(_geometry(0.0, B / 2, active=0.0)[[0, 1, 4, 5, 6, 7]] == 0)


def test_load_fraction_is_continuous_in_the_pose():
    xs = np.linspace(-0.1, 0.2, 301)  # the front end (X + l/2) passes over the cell at x = 1.25
    fr = np.array([_geometry(1.25, PARAMS["track_gauge_m"] / 2, X=x)[0] for x in xs])
    assert np.max(np.abs(np.diff(fr))) < 0.02
    assert fr[0] == 0.0 and fr[-1] == pytest.approx(1.0)


def test_end_strip_weights_select_the_ends_and_skip_partly_covered_cells():
    l, b, B = PARAMS["contact_length_m"], PARAMS["track_width_m"], PARAMS["track_gauge_m"]
    front = _geometry(l / 2 - 0.1, B / 2)  # one cell behind the front end, inside
    assert front[5] == pytest.approx(1.0) and front[4] == 0.0  # idler weight, no sprocket weight
    rear = _geometry(-l / 2 + 0.1, B / 2)
    assert rear[4] == pytest.approx(1.0) and rear[5] == 0.0
    edge = _geometry(l / 2 - 0.1, B / 2 + b / 2 - 0.025)  # 3/4 under the track, at its edge
    assert edge[0] == pytest.approx(0.75) and edge[5] < 0.3
    assert cell.k_eq(1.0, 2.0, 0.5) == 4.0


def _small_system(n=30):
    from symtrack.model import SystemModel
    from symtrack.terrain.channels import ChannelTerrain

    return SystemModel(ModelOptions(), ChannelTerrain(ModelOptions(), n))


def test_the_dae_jacobian_is_an_arrowhead():
    n = 30
    m = _small_system(n)
    nv = m.layout.nv  # the default law's 16 vehicle states
    J = ca.jacobian(ca.vertcat(m.ode_dae_expr, m.alg_expr), ca.vertcat(m.x, m.z)).sparsity()
    rows, cols = J.get_triplet()
    for r, c in zip(rows, cols, strict=True):
        if nv <= r < m.nx and nv <= c < m.nx:
            assert (r - nv) // 2 == (c - nv) // 2  # a channel couples only to itself among the channels
    assert J.nnz() < 20 * m.nx  # linear in the channel count, not quadratic


def test_the_block_built_jacobian_equals_casadi_automatic_jacobian():
    from symtrack.integrators.grid_idas import channel_dae
    from symtrack.terrain.channels import NF, NG

    n = 30
    m = _small_system(n)
    F = channel_dae(m)
    rng = np.random.default_rng(3)
    Q = np.zeros(NG + NF * n)
    Q[0], Q[1] = 0.25, 0.5
    qc = Q[NG:].reshape(n, NF)
    qc[:, 0] = rng.uniform(-1.5, 1.5, n)
    qc[:, 1] = rng.uniform(-1.0, 1.0, n)
    qc[:, 2] = rng.uniform(0, 1e-3, n)
    qc[:, 3] = rng.uniform(0, 3e4, n)
    qc[:, 4] = rng.integers(0, 2, n)
    p = np.r_[m.param_vector(PARAMS, Q), 0.01]
    vehicle = dict(zip(VEHICLE_STATES, [0.1, 0.05, 0.02, 2.0, 0.01, 0.03, 5.0, 5.5, 0.01, 0.012, 1900, 2000],
                       strict=True))
    vehicle.update(zip(LATERAL_STATES, [0.004, -0.003, 0.01, 0.012], strict=True))  # the default law's
    x = np.r_[rng.uniform(0, 2e-3, 2 * n), [vehicle[k] for k in m.layout.vehicle_names]]
    z = np.array([0.5, 0.01])
    u = np.array([2000.0, 1800.0])
    xs, zs = ca.MX.sym("x", x.size), ca.MX.sym("z", 2)
    out = F(t=0, x=xs, z=zs, p=p, u=u)
    J_custom = ca.Function("jc", [xs, zs], [ca.jacobian(ca.vertcat(out["ode"], out["alg"]), ca.vertcat(xs, zs))])
    # the reference: CasADi's own AD on the permuted expressions
    h = ca.SX.sym("h")
    vs, cs = m.layout.block("vehicle"), m.layout.block("cells")
    xp = ca.vertcat(m.x[cs], m.x[vs])
    ode = h * m.ode_dae_expr
    expr = ca.vertcat(ode[cs], ode[vs], m.alg_expr)
    J_ref = ca.Function("jr", [xp, m.z, m.p, h, m.u], [ca.jacobian(expr, ca.vertcat(xp, m.z))])
    A = np.array(J_custom(x, z))
    B = np.array(J_ref(x, z, p[:-1], 0.01, u))
    assert np.max(np.abs(A - B)) <= 1e-9 * max(1.0, np.max(np.abs(B)))
