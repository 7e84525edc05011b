"""One terrain cell: the loading, unloading and reloading law against the analytic curves."""

import casadi as ca
import numpy as np
import pytest

from symtrack.presets import soil_preset
from symtrack.soil import cell

SOIL = soil_preset("clayey_soil_thailand_38")
B = 0.45
KEQ = cell.k_eq(SOIL["k_c_N_per_m_n1"], SOIL["k_phi_N_per_m_n2"], B)
N = SOIL["bekker_n"]
REG = 1e-6
LAW = dict(keq=KEQ, n=N, elastic_stiffness=SOIL["elastic_stiffness_Pa_per_m"],
           kappa=SOIL["unloading_stiffness_floor"], reg_m=REG)


def _cell_integrator(dt):
    """A single cell (docs/model.md, "Cell dynamics"), with the history updated between steps (as the world
    manager does)."""
    z, zd, pl, zmax, pmax = (ca.SX.sym(n) for n in ("z", "zd", "p_load", "z_max", "p_max"))
    p = cell.reaction_pressure(z, zmax, pmax, **LAW)
    acc = cell.cell_acceleration(zd, pl, p, SOIL["cell_areal_mass_kg_per_m2"], SOIL["cell_damping_Pa_s_per_m"])
    dae = {"x": ca.vertcat(z, zd), "p": ca.vertcat(pl, zmax, pmax), "ode": ca.vertcat(zd, acc)}
    F = ca.integrator("c", "cvodes", dae, 0, dt, {"abstol": 1e-12, "reltol": 1e-10})
    P = ca.Function("P", [z, zmax, pmax], [p])
    return F, P


def test_quasi_static_load_unload_reload_follows_the_analytic_law():
    dt = 2e-3
    F, P = _cell_integrator(dt)
    # slow load cycle: 0 -> 30 kPa -> 10 kPa -> 40 kPa, held (2 s per leg; the cell's time scale is ~ms)
    legs = [(0.0, 30e3), (30e3, 10e3), (10e3, 40e3), (40e3, 40e3)]
    x, zmax, pmax = np.zeros(2), 0.0, 0.0
    rows = []
    for a, b in legs:
        for s in np.linspace(0, 1, 1001)[1:]:
            pl = a + (b - a) * s
            x = np.array(F(x0=x, p=[pl, zmax, pmax])["xf"]).ravel()
            p_now = float(P(x[0], zmax, pmax))
            if x[0] > zmax:
                zmax, pmax = x[0], float(cell.bekker_pressure(x[0], KEQ, N, REG))
            rows.append((pl, x[0], p_now, zmax, pmax))
    rows = np.array(rows)
    pl, z = rows[:, 0], rows[:, 1]
    # loading leg: Bekker's inverse z = (p/k_eq)^(1/n). Tolerance: the regularisation
    # (relative (1-n) d / (n z) = 1.6e-3 at 0.6 mm) and the damping lag c'' dz/dt (~30 Pa).
    first = slice(600, 1000)
    assert np.allclose(z[first], (pl[first] / KEQ) ** (1 / N), rtol=3e-3)
    # after unloading to 10 kPa: on the straight line through (z_max, p_max) of the first leg
    z1max = (30e3 / KEQ) ** (1 / N)
    k_u = max(SOIL["elastic_stiffness_Pa_per_m"], SOIL["unloading_stiffness_floor"] * 30e3 / z1max)
    assert z[1999] == pytest.approx(z1max - (30e3 - 10e3) / k_u, rel=2e-3)
    assert z[1999] < z1max  # elastic rebound, but ...
    assert z[1999] > 0.5 * z1max  # ... most of the sinkage is permanent
    # reloading below the old maximum: the same line back (z linear in p)
    mid = 2000 + np.arange(100, 900)
    on_line = mid[pl[mid] < 29e3]
    assert np.allclose(z[on_line], z1max - (30e3 - pl[on_line]) / k_u, rtol=2e-3)
    # beyond the old maximum: back on the Bekker curve
    assert z[-1] == pytest.approx((40e3 / KEQ) ** (1 / N), rel=2e-3)


def test_unloaded_cell_carries_no_tension():
    p = cell.reaction_pressure(ca.DM(0.5e-3), ca.DM(1.5e-3), ca.DM(30e3), **LAW)
    assert float(p) == 0.0
    assert float(cell.bekker_pressure(ca.DM(-1e-3), KEQ, N, REG)) == 0.0


def test_unloading_line_stays_below_bekker_curve():
    zmax = 1.5e-3
    pmax = float(cell.bekker_pressure(zmax, KEQ, N, REG))
    for z in np.linspace(0, zmax, 50):
        line = float(cell.reaction_pressure(z, zmax, pmax, **LAW))
        assert line <= float(cell.bekker_pressure(z, KEQ, N, REG)) + 1e-9
