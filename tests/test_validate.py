"""``symtrack validate`` (docs/validation.md): the case files' schema, the command's folder, and the
fast cases' predictions against the package's functions computed here another way (not against
numbers the command printed once)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from symtrack.cli.main import main
from symtrack.foundations.errors import ScenarioError
from symtrack.soil import density, rigid_base, subsoil
from symtrack.studies import traffic_seasons
from symtrack.studies import validate as V
from symtrack.vehicles import tyre

FAST = ("ansorge2007_stress_tyre", "ansorge2007_density_pressure")


@pytest.fixture(scope="module")
def cases():
    return {n: V.load_case(V.CASES_DIR / f"{n}.toml") for n in V.case_names()}


# ---- the case files --------------------------------------------------------------------------

def test_every_case_file_has_its_source_and_assumptions_with_ranges(cases):
    assert len(cases) >= 3
    for name, c in cases.items():
        for key in V.SOURCE_KEYS:
            assert c.source[key].strip(), (name, key)
        assert c.x.size == c.measured.size > 0
        assert c.kind and c.unit and c.x_name
        assert c.assumptions, name
        assert len(c.findings) > 80, name  # what the comparison shows, in words
        for a in c.assumptions:
            assert len(a.reason) > 40, (name, a.name)  # a reason, not a label
            if a.range is not None:
                assert a.range[0] <= a.value <= a.range[1] and a.range[0] < a.range[1], (name, a.name)
                assert a.unit, (name, a.name)
            else:
                assert a.alternatives and a.value not in a.alternatives, (name, a.name)
        for rname, (rx, rv) in c.references.items():
            assert rx.size == rv.size and set(rx) <= set(c.x), (name, rname)
        # no parameter of these cases was fitted to their data
        assert c.calibration is False, name


@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace('reason = "Concentration factor.', 'why = "Concentration factor.'), "why"),
    (lambda t: t.replace("range = [4.0, 6.0]", "range = [5.5, 6.0]"), "assumptions.xi.value"),
    (lambda t: t.replace('page = "appendix', 'pages = "appendix'), "pages"),
    (lambda t: t.replace("values = [118.0, 88.0, 50.0]", "values = [118.0, 88.0]"), "measured.values"),
    (lambda t: t.replace('model = "tyre_stress_by_depth"', 'model = "tyre"'), "model"),
])
def test_a_bad_case_file_is_refused_naming_the_field(tmp_path, edit, field):
    text = (V.CASES_DIR / "ansorge2007_stress_tyre.toml").read_text()
    bad = tmp_path / "bad_case.toml"
    bad.write_text(edit(text))
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")) as err:
        V.load_case(bad)
    assert "\n" not in str(err.value)


# ---- the command -----------------------------------------------------------------------------

def test_list_shows_every_case_with_its_source(capsys, cases):
    assert main(["validate", "--list"]) == 0
    text = capsys.readouterr().out
    for name, c in cases.items():
        assert name in text and c.source["table"] in text
        assert c.source["citation"].split(")")[0] in text


def test_an_unknown_case_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "v"
    assert main(["validate", "no_such_case", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no_such_case" in err and "ansorge2007_stress_track" in err
    assert not out.exists()


@pytest.mark.parametrize("args, words", [(["--scheduler", "no-port-here"], ("--scheduler", "no-port-here")),
                                         (["--dask", "--workers", "0"], ("--workers",))])
def test_a_bad_dask_option_is_one_line_and_writes_nothing(tmp_path, capsys, args, words):
    out = tmp_path / "v"
    assert main(["validate", "rasool2018_motion_resistance", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and all(w in err for w in words)
    assert not out.exists()


def test_validate_writes_the_table_figures_and_report(tmp_path, capsys):
    out = tmp_path / "v"
    assert main(["validate", *FAST, "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "stress" in printed and "density_change" in printed and "worst relative" in printed
    rows = list(csv.DictReader((out / "validation.csv").open()))
    assert list(rows[0])[:len(V.CSV_COLUMNS)] == list(V.CSV_COLUMNS)
    assert {r["case"] for r in rows} == set(FAST) and len(rows) == 7
    for r in rows:
        m, p, e = float(r["measured"]), float(r["predicted"]), float(r["error"])
        assert math.isclose(e, p - m, rel_tol=1e-4, abs_tol=1e-4)
        assert float(r["band_low"]) <= p <= float(r["band_high"])
    tyre_rows = [r for r in rows if r["case"] == "ansorge2007_stress_tyre"]
    assert [float(r["ref_SOCOMO"]) for r in tyre_rows] == [134.0, 124.0, 102.0]  # the thesis' SOCOMO column
    for name in FAST:
        assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "report.html").read_text()
    assert all(n in page for n in FAST) and "Errors by kind of quantity" in page
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "symtrack-validate" and summary["cases"] == list(FAST)
    manifest = json.loads((out / ".symtrack-manifest.json").read_text())
    assert set(manifest["files"]) == {"validation.csv", "sensitivity.csv", "validation.md", "report.html",
                                      "summary.json", *(f"{n}.png" for n in FAST)}
    # docs/validation.md's tables are this command's validation.md (make validate); its rows of these cases agree
    docs = (Path(__file__).resolve().parents[1] / "docs" / "validation.md").read_text()
    heads = tuple(f"| {n} |" for n in FAST)
    ours = [ln for ln in (out / "validation.md").read_text().splitlines() if ln.startswith(heads)]
    assert len(ours) > 7 and [ln for ln in ours if ln not in docs] == []
    sens = list(csv.DictReader((out / "sensitivity.csv").open()))
    assert {(r["assumption"], r["end"]) for r in sens if r["case"] == FAST[0]} >= {("xi", "low"), ("xi", "high")}


# ---- the predictions, computed here another way ------------------------------------------------

# Radon's seven-point rule over a disc (written out here: the centre 1/4, six points at sqrt(2/3) R, 1/8 each)
def _radon(diameter_m):
    r = 0.5 * diameter_m * math.sqrt(2 / 3)
    th = np.arange(6) * np.pi / 3
    return [(0.0, 0.0, 0.25)] + [(r * math.cos(t), r * math.sin(t), 0.125) for t in th]


def test_the_face_rule_integrates_the_disc_exactly_to_degree_5():
    dx, dy, w = V._face_points(0.1)
    R = 0.05
    assert w.sum() == pytest.approx(1.0)
    # the disc's means: x^2 = R^2/4, x^4 = R^4/8, x^2 y^2 = R^4/24; odd moments 0
    for f, want in ((dx**2, R**2 / 4), (dy**2, R**2 / 4), (dx**4, R**4 / 8), (dx**2 * dy**2, R**4 / 24),
                    (dx, 0.0), (dx**3 * dy, 0.0), (dx * dy**2, 0.0)):
        assert float(np.sum(w * f)) == pytest.approx(want, abs=1e-15)
    assert np.allclose(np.column_stack([dx, dy, w]), np.array(_radon(0.1)), rtol=0, atol=1e-15)
    assert V._face_points(0.0)[2].tolist() == [1.0]


def test_track_stress_is_the_brute_force_sum_over_the_track(cases):
    c = cases["ansorge2007_stress_track"]
    a = c.nominal()
    got = V.track_stress_by_depth(c.setup, a, c.x)
    l_m, b_m, W = a["contact_length_m"], a["track_width_m"], c.setup["load_kN"]
    H, face = a["rigid_base_depth_m"], a["transducer_face_diameter_m"]
    assert (H, a["rigid_base_interface"], face) == (0.7, "rough", 0.1)
    # the point-load sum over the rectangle with the rough base's correction (subsoil.stress_bruteforce),
    # averaged over the transducer's face and the contact length
    px = np.linspace(-l_m / 2, l_m / 2, 41)
    pose = (0.0, 0.0, 1.0, 0.0, W * 1e3 / (l_m * b_m), 0.0, 0.0, 0.0)
    geo = (l_m, b_m, 1.0 + b_m, 0.0, 0.1, 0.0)  # another gauge: the second track unloaded either way
    for k, d in enumerate(c.x):
        want = 0.0
        for dx, dy, w in _radon(face):
            s = subsoil.stress_bruteforce(px + dx, np.full(px.shape, geo[2] / 2 + dy), pose, geo, d, a["xi"],
                                          rigid_base_depth_m=H) / 1e3
            want += w * np.trapezoid(s, px) / l_m
        assert got[k] == pytest.approx(want, rel=5e-3)
    # below the base there is no soil; without the base, the half-space (the base adds 4-23 % here)
    assert np.isnan(V.track_stress_by_depth(c.setup, a, [0.75]))[0]
    half = V.track_stress_by_depth(c.setup, {**a, "rigid_base_depth_m": None}, c.x)
    assert np.all(got > 1.03 * half) and np.all(got < 1.3 * half)


def test_tyre_stress_is_froehlichs_sum_over_kellers_contact(cases):
    c = cases["ansorge2007_stress_tyre"]
    a = c.nominal()
    got = V.tyre_stress_by_depth(c.setup, a, c.x)
    # the nominal case: the rig's 2 bar is the recommended pressure, so the tyre is rated at the wheel load
    W, p = c.setup["wheel_load_kN"], c.setup["inflation_kPa"]
    con = tyre.contact(tyre.Tyre(c.setup["tyre_width_m"], a["tyre_diameter_m"], W, p), W, p)
    H = a["rigid_base_depth_m"]
    xs = np.linspace(-con.length_m / 2, con.length_m / 2, 41)
    for k, d in enumerate(c.x):
        r_grid, dz, _ = rigid_base.correction_profile(d, H, 2.0)
        want = 0.0
        for dx, dy, w in _radon(a["transducer_face_diameter_m"]):
            s = []
            for x in xs:
                r = np.hypot(x + dx - con.x_m, dy - con.y_m)
                s.append(float(np.sum(con.force_kN * (subsoil.frohlich_point(1.0, r, d, a["xi"])
                                                      + np.interp(r, r_grid, dz)))))
            want += w * np.trapezoid(s, xs) / con.length_m
        assert got[k] == pytest.approx(want, rel=5e-3)


@pytest.mark.parametrize("yield_line", ["package_default", "none"])
def test_density_change_is_the_compression_lines_under_the_mean_stress(cases, yield_line):
    c = cases["ansorge2007_density_pressure"]
    a = {**c.nominal(), "yield_line": yield_line}
    setup = {**c.setup, **({"yield_line_offset_ln_p": 0.0} if yield_line == "none" else {})}
    got = V.density_change_vs_contact_pressure(setup, a, c.x)
    N, lam = c.setup["virgin_line_N"], c.setup["compression_index_lambda"]
    kap, rho_s, rho0 = a["recompression_index_kappa"], a["particle_density_Mg_per_m3"], \
        a["bulk_density_initial_Mg_per_m3"]
    w = c.setup["gravimetric_water_content"]
    v0, v_min = rho_s / rho0, 1.0 + w * rho_s
    soil = {"virgin_line_N": N, "compression_index_lambda": lam, "recompression_index_kappa": kap,
            "particle_density_Mg_per_m3": rho_s, "bulk_density_initial_Mg_per_m3": rho0,
            **({"yield_line_offset_ln_p": 0.0} if yield_line == "none" else {})}
    depths = np.linspace(c.setup["profile_top_m"], a["profile_bottom_m"], c.setup["profile_points"])
    b_m = a["footprint_width_m"]
    for k, p_kPa in enumerate(c.x):
        l_m = a["load_kN"] / (p_kPa * b_m)
        # the mean normal stress by the engine's tables (another path than the command's point sum)
        T = subsoil.build_mean_stress_tables(tuple(depths), a["xi"], l_m, b_m, b_m)
        pm = subsoil.stress_at(T, [0.0], [b_m / 2], (0, 0, 1, 0, p_kPa * 1e3, 0, 0, 0), (l_m, b_m, b_m, 0, 0.1, 0))[0]
        p_total = pm / 1e3 + rho0 * (1 + w) * 9.81 * depths
        # one load from the initial state by the three lines' closed form (density.passes_at_constant_stress)
        v1 = np.array([density.passes_at_constant_stress(soil, float(p), 1)[0] for p in p_total])
        assert np.all(v1 > v_min + kap * np.log(p_total))  # the saturation bound is not reached here
        inc = 100 * (v0 / v1 - 1)
        assert got[k] == pytest.approx(np.trapezoid(inc, depths) / (depths[-1] - depths[0]), rel=1e-2, abs=0.02)


def test_the_band_holds_the_prediction_and_each_assumption_moves_it(cases):
    r = V.run_case(cases["ansorge2007_stress_tyre"], line=False)
    assert np.all(r.band_low <= r.predicted) and np.all(r.predicted <= r.band_high)
    xi_low = next(p for n, end, _, p, _ in r.runs if n == "xi" and end == "low")
    xi_high = next(p for n, end, _, p, _ in r.runs if n == "xi" and end == "high")
    assert np.all(xi_high > xi_low)  # a higher concentration factor: more stress below the centre


def test_traffic_shares_are_the_seasons_shares_of_each_system(cases):
    c = cases["kroulik2009_trafficked_once"]
    setup = {**c.setup, "cell_m": 0.5}  # a small field at coarse cells: the wiring, not the figures
    a = {**c.nominal(), "field_length_m": 120.0}
    got = V.traffic_shares(setup, a, c.x)
    systems = {k: [op if "random_offset_m" in op else {**op, "random_offset_m": a["random_offset_m"]} for op in ops]
               for k, ops in traffic_seasons.SEASONS.items()}
    rows, _ = traffic_seasons.system_table((120.0, 80.0), 0.5, systems)
    by = {r["system"]: r for r in rows}
    assert list(got) == [100 * by[s]["trafficked_fraction"] for s in c.x_labels]


@pytest.mark.parametrize("xi", [3.0, 5.0, 8.0])
def test_below_a_uniform_footprint_the_log_slope_steepens_with_depth(xi):
    """The track case's finding (its findings field): below any uniform rectangle on a homogeneous
    half-space the stress's log-log slope steepens with depth, so the track's measured profile, whose
    slope flattens (-1.04 then -0.52 over 250-400-650 mm), is out of the model's reach."""
    depths = (0.25, 0.40, 0.65)
    for l_m in (0.3, 1.6, 4.0):
        for b_m in (0.2, 1.0):
            pose, geo = (0, 0, 1, 0, 1e5, 0, 0, 0), (l_m, b_m, b_m, 0, 0.1, 0)
            s = [subsoil.stress_bruteforce([0.0], [b_m / 2], pose, geo, d, xi)[0] for d in depths]
            slope1 = math.log(s[1] / s[0]) / math.log(depths[1] / depths[0])
            slope2 = math.log(s[2] / s[1]) / math.log(depths[2] / depths[1])
            assert slope2 < slope1 < 0
    m = (80.0, 49.0, 38.0)  # the track case's measured profile (kPa)
    assert math.log(m[2] / m[1]) / math.log(0.65 / 0.40) > math.log(m[1] / m[0]) / math.log(0.40 / 0.25)


# ---- the vehicle's cases: traction, motion resistance, turning ------------------------------------

def _fg_traction(setup, a, ci_kPa, slips):
    """The traction of one straight track in closed form (docs/model.md): Ferretti & Girelli's tractive
    effort with the Janosi-Hanamoto shape at j = i l / 2, Wong's internal resistance at the tread speed,
    Bekker's rut work at the static sinkage; the soil by the cone-bearing relation written out here."""
    phi = math.radians(a["friction_angle_deg"])
    nq = math.exp(math.pi * math.tan(phi)) * math.tan(math.pi / 4 + phi / 2) ** 2
    nc = (nq - 1) / math.tan(phi)
    c = max(0.0, (ci_kPa * 1e3 / a["cone_factor_multiplier"] - a["overburden_kPa"] * 1e3 * nq) / nc)
    N, b, l, K, n = a["normal_load_N"], setup["track_width_m"], setup["contact_length_m"], a["shear_modulus_K_m"], \
        a["bekker_n"]
    F = (b * l * c + N * math.tan(phi)) * (1 + K / (slips * l) * (np.exp(-slips * l / K) - 1))
    R_in = N * (setup["internal_resistance_const"] + setup["internal_resistance_per_km_h"] * 3.6 * a["speed_m_s"]
                / (1 - slips))
    k_eq = ci_kPa * 1e3 / a["cone_index_sinkage_m"] ** n
    z = (N / (b * l) / k_eq) ** (1 / n)
    R_c = b * k_eq * z ** (n + 1) / (n + 1)
    ntr, gtr = (F - R_c) / N, (F + R_in) / N
    return ntr, ntr / gtr * (1 - slips)


def test_traction_at_max_efficiency_is_ferretti_girellis_tractive_effort_in_closed_form(cases):
    slips = np.linspace(0.003, 0.3, 60001)
    for name, what in (("rasool2016_max_tractive_efficiency", "tractive_efficiency_pct"),
                       ("rasool2016_travel_reduction_at_max_efficiency", "travel_reduction"),
                       ("rasool2016_net_traction_at_max_efficiency", "net_traction_ratio")):
        c = cases[name]
        assert c.setup["quantity_at_max"] == what
        got = V.MODELS[c.model](c.setup, c.nominal(), c.x)
        for k, ci in enumerate(c.x):
            ntr, te = _fg_traction(c.setup, c.nominal(), ci, slips)
            best = int(np.argmax(te))
            want = {"tractive_efficiency_pct": 100 * te[best], "travel_reduction": slips[best],
                    "net_traction_ratio": ntr[best]}[what]
            assert got[k] == pytest.approx(want, rel=2e-3, abs=5e-4), (name, ci)


def test_traction_at_the_measured_slip_and_the_fixed_strength_alternative(cases):
    c = cases["rasool2016_net_traction_at_slip"]
    a = c.nominal()
    got = V.MODELS[c.model](c.setup, a, c.x)
    for k in range(c.x.size):
        s = np.array([c.setup["travel_reduction"][k]])
        assert got[k] == pytest.approx(_fg_traction(c.setup, a, c.setup["cone_index_kPa"][k], s)[0][0], rel=1e-3)
    # Wong's sandy loam instead of the cone-bearing strength: c and phi the same at every cone index
    r = V.run_case(c, line=False)
    fixed = next(p for n, end, _, p, _ in r.runs if n == "strength_relation")
    a_fixed = {**a, "friction_angle_deg": 29.0, "cone_factor_multiplier": 1e9, "overburden_kPa": 0.0}
    s = np.array(c.setup["travel_reduction"])
    want = [_fg_traction(c.setup, a_fixed, ci, s[k:k + 1])[0][0] for k, ci in enumerate(c.setup["cone_index_kPa"])]
    # with c = 0 from the relation, add the sandy loam's cohesion (1.72 kPa) by hand
    want = np.array(want) + 1.72e3 * c.setup["track_width_m"] * c.setup["contact_length_m"] / a["normal_load_N"] \
        * (1 + a["shear_modulus_K_m"] / (s * c.setup["contact_length_m"])
           * (np.exp(-s * c.setup["contact_length_m"] / a["shear_modulus_K_m"]) - 1))
    assert fixed == pytest.approx(want, rel=1e-3)


def test_motion_resistance_is_wongs_internal_resistance_plus_bekkers_rut(cases):
    c = cases["rasool2018_motion_resistance"]
    a = c.nominal()
    got = V.MODELS[c.model](c.setup, a, c.x)
    N = c.setup["weight_N"] / c.setup["tracks"]
    b, l, n = a["track_width_m"], a["contact_length_m"], a["bekker_n"]
    for k, ci in enumerate(c.x):
        k_eq = ci * 1e3 / a["cone_index_sinkage_m"] ** n
        z = (N / (b * l) / k_eq) ** (1 / n)
        r_in = N * (c.setup["internal_resistance_const"]
                    + c.setup["internal_resistance_per_km_h"] * 3.6 * a["speed_m_s"])
        assert got[k] == pytest.approx(100 * (b * k_eq * z ** (n + 1) / (n + 1) + r_in) / N, rel=1e-4)


def test_turning_coefficient_is_the_trim_points_thrust_difference():
    """Wong's coefficient of lateral resistance 4 M_r / (W l) from the package's steady turn, with M_r the
    yaw moment of the tracks' net thrusts; it falls with the radius (the relation's direction)."""
    from symtrack.control.trim import trim
    from symtrack.model import ModelOptions, SystemModel
    from symtrack.presets import soil_preset, vehicle_preset

    p = {**vehicle_preset("reference_crawler"), **soil_preset("sandy_loam_15")}
    B, l, W = p["track_gauge_m"], p["contact_length_m"], p["mass_kg"] * 9.80665
    mu = [V.validate_vehicle.turning_resistance_coefficient("reference_crawler", "sandy_loam_15", "shear",
                                                            p["shear_modulus_K_m"], 0.5, x) for x in (1.0, 5.0, 20.0)]
    y = trim(SystemModel(ModelOptions(lateral_law="shear")), p, 0.5, 5.0 * B).outputs
    moment = B / 2 * ((y["tractive_right_N"] - y["compaction_resistance_right_N"])
                      - (y["tractive_left_N"] - y["compaction_resistance_left_N"]))
    assert mu[1] == pytest.approx(4 * moment / (W * l), rel=1e-9)
    assert mu[0] > mu[1] > mu[2] > 0


def test_an_empirical_case_is_marked_so(cases):
    c = cases["nikitin_sergeev_turning_resistance"]
    assert c.kind.endswith("_empirical") and "not a measurement" in c.source["measured_as"].lower()
    # its values are the relation's, relative to R/B = 1
    assert c.measured == pytest.approx((0.925 + 0.15) / (0.925 + 0.15 * c.x), abs=1e-4)


def test_line_points_must_be_a_whole_number(tmp_path):
    text = (V.CASES_DIR / "rasool2018_motion_resistance.toml").read_text().replace("line_points = 15",
                                                                                   "line_points = 1.5")
    bad = tmp_path / "bad_case.toml"
    bad.write_text(text)
    with pytest.raises(ScenarioError, match="line_points"):
        V.load_case(bad)


# ---- sinkage and ruts: Bekker's inverse under a track and under Keller's tyre contact ----------------

NEW_ANSORGE = ("ansorge2007_track_unit_sinkage", "ansorge2007_field_ruts")


def _table8(density):
    """Bekker's n and k [kN/m^(n+2) or kN/m^(n+1)] of the thesis' Table 8, linear in the density between its rows."""
    rows = ((1.2, 0.89, 700.0), (1.4, 0.62, 2150.0), (1.6, 0.42, 2400.0))
    for (r0, n0, k0), (r1, n1, k1) in zip(rows[:-1], rows[1:], strict=True):
        if r0 <= density <= r1:
            f = (density - r0) / (r1 - r0)
            return n0 + f * (n1 - n0), k0 + f * (k1 - k0)
    raise ValueError(density)


def _bekker_rut_mm(p_Pa, k_eq, n, under_load, K_e=4e7, kappa=3.0):
    """Bekker's inverse z = (p / k_eq)^(1/n) [mm], or the rut after unloading on the elastic line
    z - p / max(K_e, kappa p / z) (docs/model.md, "Pressure-sinkage")."""
    z = (p_Pa / k_eq) ** (1.0 / n)
    return 1e3 * (z if under_load else z - p_Pa / max(K_e, kappa * p_Pa / z))


@pytest.mark.parametrize("k_reading, sinkage_as", [("k_eq", "under_load"), ("k_c", "under_load"),
                                                   ("k_eq", "rut_after_unloading")])
def test_track_unit_sinkage_is_bekkers_inverse_of_the_mean_pressure(cases, k_reading, sinkage_as):
    c = cases["ansorge2007_track_unit_sinkage"]
    a = {**c.nominal(), "k_reading": k_reading, "sinkage_as": sinkage_as, "pts_contact_length_m": 2.4,
         "westtrack_track_width_m": 0.89}
    got = V.MODELS[c.model](c.setup, a, c.x)
    n, k = _table8(a["bulk_density_initial_Mg_per_m3"])
    for i, unit in enumerate(("stocks", "pts", "westtrack", "terra_trac")):
        length, width = a[f"{unit}_contact_length_m"], a[f"{unit}_track_width_m"]
        k_eq = k * 1e3 / (width if k_reading == "k_c" else 1.0)
        want = _bekker_rut_mm(117.68e3 / (length * width), k_eq, n, sinkage_as == "under_load")
        assert got[i] == pytest.approx(want, rel=1e-9), unit
    # the units differ only where their dimensions do; a longer contact sinks less, and a wider one too unless
    # k is k_c / b (then the width cancels: p / k_eq = W / (l k_c))
    assert got[0] == got[3] and got[1] < got[0]
    assert got[2] < got[0] if k_reading == "k_eq" else got[2] == pytest.approx(got[0], rel=1e-12)


def _keller_area_m2(width, diameter, p_i, p_rec):
    """Keller's (2005) contact area in closed form: the super-ellipse |2x/L|^s + |2y/b|^s <= 1 has the area
    L b Gamma(1 + 1/s)^2 / Gamma(1 + 2/s), L = 0.47 + 0.11 D^2 - 0.16 ln(p_i / p_rec), s = 2.1 (b D)^2 + 2."""
    L = 0.47 + 0.11 * diameter**2 - 0.16 * math.log(p_i / p_rec)
    s = 2.1 * (width * diameter) ** 2 + 2.0
    return L * width * math.gamma(1 + 1 / s) ** 2 / math.gamma(1 + 2 / s)


@pytest.mark.parametrize("changes", [{}, {"sandy_loam_soil": "sandy_loam_15", "sinkage_as": "under_load"},
                                     {"recommended_inflation_kPa": 160.0, "clay_soil": "north_gower_clayey_loam_46",
                                      "k_reading": "k_c", "subsoiled_density_Mg_per_m3": 1.3}])
def test_combine_ruts_are_bekkers_inverse_under_the_track_and_kellers_tyre_contact(cases, changes):
    from symtrack.presets import soil_preset

    c = cases["ansorge2007_field_ruts"]
    a = {**c.nominal(), **changes}
    got = V.MODELS[c.model](c.setup, a, c.x)
    under = a["sinkage_as"] == "under_load"
    for i, (field, machine) in enumerate(zip(c.setup["fields"], c.setup["machines"], strict=True)):
        if machine == "track":
            width = a["track_width_m"]
            p = a["track_unit_load_kN"] * 1e3 / (a["track_contact_length_m"] * width)
        else:
            width, p_i = a["tyre_width_m"], c.setup["inflation_kPa" if machine == "tyre" else "high_inflation_kPa"]
            p = a["wheel_load_kN"] * 1e3 / _keller_area_m2(width, a["tyre_diameter_m"], p_i,
                                                           a["recommended_inflation_kPa"])
        preset = a["clay_soil"] if field == "clay" else a["sandy_loam_soil"]
        if preset == "density_table":
            n, k = _table8(a[f"{field}_density_Mg_per_m3"])
            k_eq, K_e = k * 1e3 / (width if a["k_reading"] == "k_c" else 1.0), 4e7
        else:
            s = soil_preset(preset)
            n, k_eq, K_e = s["bekker_n"], s["k_c_N_per_m_n1"] / width + s["k_phi_N_per_m_n2"], \
                s["elastic_stiffness_Pa_per_m"]
        # Keller's area by the package's quadrature against the closed form: within 0.1 %
        assert got[i] == pytest.approx(_bekker_rut_mm(p, k_eq, n, under, K_e), rel=3e-3), (field, machine)
    # on every field the track's rut is the shallowest and the high pressure's the deepest
    assert np.all(got[1::3] < got[0::3]) and np.all(got[0::3] < got[2::3])


def test_the_sinkage_cases_write_their_rows_references_and_figures(tmp_path, capsys):
    out = tmp_path / "v"
    assert main(["validate", *NEW_ANSORGE, "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "sinkage" in printed and "rut_depth" in printed
    rows = list(csv.DictReader((out / "validation.csv").open()))
    assert [r["case"] for r in rows] == [NEW_ANSORGE[0]] * 4 + [NEW_ANSORGE[1]] * 9
    track = rows[:4]
    assert [r["depth_or_pass"] for r in track] == ["Stocks", "PTS", "Westtrack", "Terra Trac"]
    assert [float(r["ref_Bekker_track_slag_0_02"]) for r in track] == [64.0, 79.0, 57.0, 62.0]
    assert [float(r["ref_Bernstein"]) for r in track] == [51.0, 58.0, 36.0, 29.0]
    assert all(r["ref_Bernstein"] == "" for r in rows[4:])
    for r in rows:
        assert float(r["band_low"]) <= float(r["predicted"]) <= float(r["band_high"])
        assert r["calibration"] == "false"
    for name in NEW_ANSORGE:
        assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert name in (out / "report.html").read_text()
    # docs/validation.md's tables hold this command's rows of these cases
    docs = (Path(__file__).resolve().parents[1] / "docs" / "validation.md").read_text()
    heads = tuple(f"| {n} |" for n in NEW_ANSORGE)
    ours = [ln for ln in (out / "validation.md").read_text().splitlines() if ln.startswith(heads)]
    assert len(ours) > 13 and [ln for ln in ours if ln not in docs] == []
