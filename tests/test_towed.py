"""A towed load following the crawler (symtrack/vehicles/towed.py, ``[terrain.towed]``): the towed
axle's kinematics against the steady circle's closed form r_axle = sqrt(r_hitch^2 - L^2) and against
an independent integration of dtheta/dt = (dH/dt . n) / L; the tabulated footprint against the direct
sum over the contact's elements; a straight run whose trailer wheels land on the crawler's ruts
against one whose wheels run beside them; a turn where the axle cuts inside; the run equal to the
crawler's run followed by the trailer's pass, bit for bit, and persisted; refusals."""

import copy
import math

import numpy as np
import pytest

import symtrack
from symtrack.api import IncompleteSimulation
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.model.parameters import SOIL_PARAMS
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.soil import moisture
from symtrack.terrain.storage import Grid, Terrain
from symtrack.vehicles import towed, tyre, wheeled

DEPTHS = (0.1, 0.3, 0.5, 0.8)
TOWED = {"axle_load_kN": 60.0, "wheel_gauge_m": 1.5, "tyre_width_m": 0.6, "tyre_diameter_m": 1.6,
         "tyre_rated_load_kN": 45.0, "tyre_rated_inflation_kPa": 240.0, "inflation_kPa": 160.0,
         "hitch_behind_track_centre_m": 1.6, "drawbar_length_m": 4.0}


def _soil():
    soil = {s.name: s.default for s in SOIL_PARAMS if s.default is not None}
    soil["bulk_density_initial_Mg_per_m3"] = 1.2
    return moisture.apply_moisture(soil, {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess"})


# ---- kinematics ------------------------------------------------------------------------------

@pytest.mark.parametrize("r_hitch, L", [(8.0, 4.0), (5.0, 4.5), (20.0, 3.0)])
def test_steady_circle_closed_form(r_hitch, L):
    """The hitch on a circle of radius r_h for six laps (1 cm chords), the trailer starting
    aligned with the hitch's path: over the last lap the axle runs on r_axle = sqrt(r_h^2 - L^2)
    (the approach is slow where L is close to r_h)."""
    n = int(6 * 2 * math.pi * r_hitch / 0.01)
    phi = np.linspace(0.0, 12 * math.pi, n)
    H = r_hitch * np.column_stack([np.cos(phi), np.sin(phi)])
    A = towed.axle_path(H, L, math.pi / 2)  # counter-clockwise: the path's heading at phi = 0
    r = np.hypot(A[:, 0], A[:, 1])
    last = phi > 10 * math.pi
    assert np.max(np.abs(r[last] - math.sqrt(r_hitch**2 - L**2))) < 1e-4
    # cutting inside: the axle's distance from the hitch's path is r_h - r_axle
    assert np.all(r[last] < r_hitch - 0.5 * (r_hitch - math.sqrt(r_hitch**2 - L**2)))
    # the drawbar keeps its length at every pose
    assert np.allclose(np.hypot(*(H - A[:, :2]).T), L, rtol=0, atol=1e-12)


def test_against_an_independent_integration():
    """A lane change (the hitch along a sine) and a reversing piece: the exact per-segment tractrix
    against RK4 of dtheta/ds = (t(s) . n(theta)) / L on the smooth path, t the unit tangent."""
    L = 3.0

    def hitch(s):  # arc-length-ish parameter: x = s, y = sin
        return np.column_stack([s, 1.2 * np.sin(s / 3.0)])

    def tangent(s):
        d = np.array([1.0, 0.4 * np.cos(s / 3.0)])
        return d  # d/ds of hitch(s), not normalised: dtheta/ds = (dH/ds . n) / L

    def f(s, th):
        t = tangent(s)
        return (-t[0] * math.sin(th) + t[1] * math.cos(th)) / L

    s = np.linspace(0.0, 30.0, 30001)
    A = towed.axle_path(hitch(s), L, math.atan2(0.4, 1.0))
    h = s[1] - s[0]
    th = math.atan2(0.4, 1.0)
    ref = [th]
    for k in range(len(s) - 1):
        k1 = f(s[k], th)
        k2 = f(s[k] + h / 2, th + h / 2 * k1)
        k3 = f(s[k] + h / 2, th + h / 2 * k2)
        k4 = f(s[k] + h, th + h * k3)
        th += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ref.append(th)
    assert np.max(np.abs(A[:, 2] - np.array(ref))) < 1e-5
    # reversing along a straight line, the trailer 10 deg off: the angle grows (jack-knifing)
    H = np.column_stack([-np.linspace(0.0, 2.0, 201), np.zeros(201)])
    B = towed.axle_path(H, L, math.radians(10.0))  # heading +10 deg while the hitch moves along -x
    delta0 = math.remainder(math.radians(10.0) - math.pi, 2 * math.pi)
    want = math.pi + 2 * math.atan(math.tan(delta0 / 2) * math.exp(-2.0 / L))
    assert math.remainder(B[-1, 2] - want, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert abs(math.remainder(B[-1, 2], 2 * math.pi)) > math.radians(10.0)


def test_spacing_and_repeated_points():
    H = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.3]])
    A = towed.axle_path(H, 2.0, 0.0, spacing_m=0.05)
    steps = np.hypot(*np.diff(A[:, :2], axis=0).T)
    assert steps.max() <= 0.05 + 1e-12 and len(A) == 1 + 20 + 6


# ---- the footprint table ---------------------------------------------------------------------

def test_table_against_the_direct_sum():
    """Off the table's lattice (a rotated path at an odd offset): the tabulated pass within 0.5 % of
    each depth's peak of the direct sum over the contact's elements, at every cell."""
    ty = tyre.Tyre(0.6, 1.6, 45.0, 240.0)
    _, tb = tyre.footprint_table(ty, 30.0, 160.0, 0.025, DEPTHS, 5.0, 2 * wheeled.DEFAULT_REACH_M)
    c = tyre.contact(ty, 30.0, 160.0, 0.025)
    wheels = [wheeled.Wheel(c, 0.0, 0.75), wheeled.Wheel(c, 0.0, -0.75)]
    s = np.arange(10) * 0.0249
    psi = 0.37
    poses = np.column_stack([0.0137 + s * math.cos(psi), -0.0213 + s * math.sin(psi), 0 * s + psi])
    t1, t2 = (Terrain(Grid((-2.0, -2.0), 0.1, (40, 40)), _soil(), DEPTHS) for _ in range(2))
    wheeled.wheeled_pass(t1, wheels, poses, 5.0)
    wheeled.wheeled_pass(t2, wheels, poses, 5.0, tables=[tb, tb])
    s1, s2 = (t.sigma_max.astype(float).reshape(-1, 4) for t in (t1, t2))
    err = np.abs(s1 - s2).max(axis=0) / s1.max(axis=0)
    assert np.all(err < 5e-3), err
    assert err.max() > 0  # off the lattice: the interpolation is at work
    with pytest.raises(ParameterError, match="footprint table is of depths"):
        wheeled.wheeled_pass(t2, wheels, poses, 4.0, tables=[tb, tb])


# ---- on the field ------------------------------------------------------------------------------

def _document(towed_table, length_m=8.0):
    return {
        "name": "towed",
        "run": {"duration_s": 20.0, "output_dt_s": 0.01, "integrator": "grid_fast", "stop_after_distance_m": length_m},
        "vehicle": {"preset": "reference_crawler"},
        "soil": {"preset": "clayey_soil_thailand_38", "bulk_density_initial_Mg_per_m3": 1.2,
                 "moisture": {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess"}},
        "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
        "terrain": {"size_m": [length_m + 12.0, 6.0], "origin_m": [-9.0, -3.0], "cell_m": 0.2, "passes": 1,
                    **({} if towed_table is None else {"towed": towed_table})},
        "torque": [{"t_s": 0.0, "left_N_m": 1500.0, "right_N_m": 1500.0}],
    }


@pytest.fixture(scope="module")
def runs():
    """The crawler alone and the crawler towing the trailer (wheels on its ruts: gauge 1.5 m)."""
    alone = symtrack.simulate(scenario_from_dict(_document(None)))
    both = symtrack.simulate(scenario_from_dict(_document(TOWED)))
    return alone, both


def test_run_is_the_crawler_then_the_trailer(runs, tmp_path):
    alone, both = runs
    # the crawler's own run is unchanged by the trailer (the load does not act on it)
    assert np.array_equal(alone.runs[0].X, both.runs[0].X)
    # the towed run's field = the crawler's field + the trailer's pass along its path, bit for bit
    sc = both.scenario
    t = copy.deepcopy(alone.terrain)
    figs = towed.towed_pass(t, sc.terrain.towed, alone.runs[0].X[:, :3], 0.0,
                            both._study.world.soils, float(sc.params["stress_concentration_factor"]))
    for name, a in t.arrays().items():
        assert np.array_equal(a, both.terrain.arrays()[name]), name
    p = both.summary["passes"][0]
    assert p["towed_subsoil_sigma_z_max_kPa"] == figs["towed_subsoil_sigma_z_max_kPa"]
    assert p["crawler_bulk_density_max_Mg_per_m3"] == alone.summary["passes"][0]["bulk_density_max_Mg_per_m3"]
    assert p["bulk_density_max_Mg_per_m3"] == figs["towed_bulk_density_max_Mg_per_m3"]
    assert p["towed_wheel_load_kN"] == 30.0 and p["towed_offtracking_max_m"] < 1e-9
    # persisted: saved and loaded bit for bit; the scenario's resolved TOML keeps [terrain.towed]
    path = tmp_path / "t.npz"
    both.terrain.save(path)
    back = Terrain.load(path)
    for name, a in both.terrain.arrays().items():
        assert np.array_equal(a, back.arrays()[name]), name
    assert sc.terrain.to_dict()["towed"] == TOWED


def test_wheels_on_the_ruts_and_beside_them(runs):
    """Wheels on the crawler's ruts (gauge 1.5 m = the tracks' gauge) load the rut cells again, to a
    larger stress and density than the crawler gave them; wheels 3.0 m apart leave the rut cells'
    density at 0.1 m as the crawler left it and compact cells the crawler did not touch."""
    alone, both = runs
    g = alone.terrain.grid
    nx, ny = g.shape
    xc, yc = g.centres(np.arange(nx), np.arange(ny))
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    X, Y = X.ravel(), Y.ravel()
    # the axle starts 5.6 m behind the CG and ends 2.4 m ahead of the crawler's start: x in (-0.5, 2)
    # is where both machines passed at full load
    mid = (X > -0.5) & (X < 2.0)
    rut = mid & (np.abs(np.abs(Y) - 0.75) < 0.2)
    beside = mid & (np.abs(np.abs(Y) - 1.5) < 0.1)
    soils = both._study.world.soils
    from symtrack.soil import density

    def rho(t):
        return density.bulk_density(t.specific_volume, t.soil_index, soils)

    r0, r1 = rho(alone.terrain), rho(both.terrain)
    assert np.all(r1[rut, 0] > r0[rut, 0] + 0.05)  # at 0.1 m: the trailer's 30 kN wheels on the ruts
    assert np.all(both.terrain.sigma_max[rut, 0] > 2 * alone.terrain.sigma_max[rut, 0])
    # offset: the same trailer on a 3.0 m gauge
    wide = towed.parse_towed({**TOWED, "wheel_gauge_m": 3.0})
    t = copy.deepcopy(alone.terrain)
    towed.towed_pass(t, wide, alone.runs[0].X[:, :3], 0.0, soils, 5.0)
    r2 = rho(t)
    assert np.max(np.abs(r2[rut, 0] - r0[rut, 0])) < 2e-3
    assert np.all(r0[beside, 0] == 1.2) and np.all(r2[beside, 0] > 1.25)


def test_turn_the_axle_cuts_inside():
    """The crawler's CG on a steady circle (synthetic poses, radius 8 m): the hitch runs on
    r_h = sqrt(8^2 + 1.6^2), the axle on sqrt(r_h^2 - L^2); the inner wheel's track, where the
    trailer's stress at 0.1 m peaks across the path, is at r_axle - gauge/2, inside the hitch's
    r_h - gauge/2, by the off-tracking."""
    R, L = 8.0, 4.0
    tw = towed.parse_towed({**TOWED, "drawbar_length_m": L})
    phi = np.arange(0.0, 2 * math.pi, 0.04 / R)
    poses = np.column_stack([R * np.cos(phi), R * np.sin(phi), phi + math.pi / 2])
    t = Terrain(Grid((-12.0, -12.0), 0.1, (240, 240)), _soil(), DEPTHS)
    figs = towed.towed_pass(t, tw, poses, 0.0, [_soil()], 5.0)
    r_h = math.hypot(R, 1.6)
    r_a = math.sqrt(r_h**2 - L**2)
    assert figs["towed_offtracking_max_m"] == pytest.approx(r_h - r_a, abs=5e-3)
    # across the path at the last quarter of the lap (steady): the inner wheel's track
    g = t.grid
    xc, yc = g.centres(np.arange(240), np.arange(240))
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    ang = np.arctan2(Y, X).ravel() % (2 * math.pi)
    rad = np.hypot(X, Y).ravel()
    sector = (ang > 1.6 * math.pi) & (ang < 1.75 * math.pi) & (rad < r_a)
    s = t.sigma_max[:, 0].astype(float)
    inner = sector & (s > 0.95 * s[sector].max())
    assert abs(np.median(rad[inner]) - (r_a - 0.75)) < 0.1
    assert np.median(rad[inner]) < r_h - 0.75 - 0.5 * (r_h - r_a)


# ---- refusals ------------------------------------------------------------------------------

@pytest.mark.parametrize("change, match", [
    ({"axle_load_kN": 90.0}, r"terrain.towed.axle_load_kN = 90.0 is outside the allowed range \(0, 65.07\]"),
    ({"inflation_kPa": 300.0}, r"terrain.towed.inflation_kPa = 300.0 is outside the allowed range \(0, 240\]"),
    ({"wheel_gauge_m": 0.5}, r"terrain.towed.wheel_gauge_m = 0.5 is outside the allowed range \[0.6, 10\]"),
    ({"drawbar_length_m": 0.0}, r"terrain.towed.drawbar_length_m = 0.0 is outside the allowed range \(0, 20\]"),
    ({"tyre_width_m": 1.5}, r"terrain.towed.tyre_width_m = 1.5 is outside the allowed range \(0.1, 1.2\]"),
    ({"colour": "red"}, r"unknown key\(s\) in \[terrain.towed\]: colour"),
])
def test_refusals_on_parsing(change, match):
    with pytest.raises(ScenarioError, match=match):
        towed.parse_towed({**TOWED, **change})


def test_example_scenario_loads():
    """examples/scenarios/multipass_trailer.toml: its cart is what the comments say, and one tonne
    more on the axle than its tyres carry at 200 kPa is refused, naming the key and the range."""
    sc = symtrack.load_scenario("examples/scenarios/multipass_trailer.toml")
    tw = sc.terrain.towed
    assert tw.wheel_load_kN == 50.0 and tw.contact.force_kN.sum() == pytest.approx(50.0, rel=1e-12)
    assert tyre.load_capacity_kN(tw.tyre, 200.0) == pytest.approx(58.9 * (200 / 240) ** 0.8, rel=1e-12)
    with pytest.raises(ScenarioError, match=r"axle_load_kN = 110.0 is outside the allowed range \(0, 101.\d\]"):
        symtrack.load_scenario("examples/scenarios/multipass_trailer.toml", {"terrain.towed.axle_load_kN": 110.0})


def test_refusals_before_the_run():
    t = dict(TOWED)
    del t["drawbar_length_m"]
    with pytest.raises(ScenarioError, match=r"\[terrain.towed\] needs drawbar_length_m"):
        scenario_from_dict(_document(t))
    d = _document(TOWED)
    d["terrain"]["subsoil_depths_m"] = []
    with pytest.raises(ScenarioError, match="terrain.towed needs the subsoil stress"):
        scenario_from_dict(d)
    # the trailer behind the field's edge at the start: refused with the scenario, before anything is built
    d = _document({**TOWED, "drawbar_length_m": 8.0})
    with pytest.raises(ScenarioError, match="terrain.towed at the start: the towed axle's wheel contact reaches"):
        scenario_from_dict(d)
    d["terrain"].pop("origin_m")  # the field centred on the start (20 m long): the cart fits
    assert scenario_from_dict(d).terrain.towed.drawbar_length_m == 8.0
    d["terrain"]["size_m"] = [12.0, 6.0]  # 6 m behind the start: it does not
    with pytest.raises(ScenarioError, match=r"outside the field x \[-6, 6\]"):
        scenario_from_dict(d)
    d = _document(TOWED)
    d["soil"]["stress_concentration_factor"] = 2.5
    with pytest.raises(ScenarioError, match=r"stress_concentration_factor = 2.5 is outside the allowed range \[3, 10"):
        scenario_from_dict(d)


def test_trailer_pushed_out_of_the_field():
    """The crawler reversing 1.5 m pushes the aligned trailer straight back, 0.9 m beyond the field's
    edge: the pass fails with the crawler's part kept (its figures, no towed ones) and no cell loaded
    by the trailer."""
    d = _document(TOWED)
    d["terrain"]["origin_m"] = [-6.9, -3.0]  # the cart's contact reaches -6.0 - 0.37 at the start
    d["torque"] = [{"t_s": 0.0, "left_N_m": -1500.0, "right_N_m": -1500.0}]
    d["run"]["stop_after_distance_m"] = 1.5
    with pytest.raises(IncompleteSimulation, match="pass 1: terrain.towed: the towed axle's wheel") as e:
        symtrack.simulate(scenario_from_dict(d))
    r = e.value.result
    p = r.summary["passes"][0]
    assert "towed_cells_loaded" not in p and p["distance_m"] > 1.4
    alone = symtrack.simulate(scenario_from_dict({**d, "terrain": {k: v for k, v in d["terrain"].items()
                                                                    if k != "towed"}}))
    for name, a in alone.terrain.arrays().items():
        assert np.array_equal(a, r.terrain.arrays()[name]), name
