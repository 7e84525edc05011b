"""One soil (symtrack/soil/pedotransfer.py, docs/subsoil.md "One soil"): the description's checks, the
one strength shared by the density model and the risk on every preset, the soil's own weight, the rut's
bound on the compression, and the risk classes against the density change they allow."""

import math

import numpy as np
import pytest

from symtrack.foundations.errors import ParameterError
from symtrack.model.parameters import SOIL_PARAMS, check_set
from symtrack.presets import soil_preset
from symtrack.presets.catalog import describe
from symtrack.presets.soils import SOILS
from symtrack.soil import density as D
from symtrack.soil import pedotransfer as PT
from symtrack.soil import subsoil as S

DEPTHS = (0.1, 0.3, 0.5, 0.8)


def _loam(**kw):
    """A described loam with the registry's other values (the Bekker set of a preset)."""
    return check_set({**dict(SOILS["sandy_loam_15"]), **kw}, SOIL_PARAMS, "soil")


def test_bad_descriptions_are_refused_naming_the_key():
    with pytest.raises(ParameterError, match=r"clay_kg_per_kg \+ silt_kg_per_kg \+ sand_kg_per_kg = 1.1"):
        _loam(clay_kg_per_kg=0.2, silt_kg_per_kg=0.3, sand_kg_per_kg=0.6)
    with pytest.raises(ParameterError, match="bulk_density_initial_Mg_per_m3 = 2.7 must be below"):
        _loam(bulk_density_initial_Mg_per_m3=2.7)
    with pytest.raises(ParameterError, match="matric_suction_kPa = -1"):
        _loam(matric_suction_kPa=-1.0)
    with pytest.raises(ParameterError, match="clay_kg_per_kg = 30"):
        _loam(clay_kg_per_kg=30.0)
    # the virgin line follows from the strength: giving it is refused with the strength it implies
    s = _loam()
    with pytest.raises(ParameterError, match="virgin_line_N = 2.9 cannot be given.*precompression_stress_Pa"):
        check_set({**dict(SOILS["sandy_loam_15"]), "virgin_line_N": 2.9}, SOIL_PARAMS, "soil")
    # a given strength wins over the PTF, and moves the virgin line with it
    weak = _loam(precompression_stress_Pa=40e3)
    assert weak["precompression_stress_Pa"] == 40e3 and weak["virgin_line_N"] < s["virgin_line_N"]


def test_a_changed_description_derives_again():
    s = soil_preset("sandy_loam_15")
    wetter = soil_preset("sandy_loam_15")
    wetter.update(matric_suction_kPa=1.0)  # a preset's set with one change (as a scenario's --set does)
    wetter = check_set(wetter, SOIL_PARAMS, "soil")
    assert wetter["precompression_stress_Pa"] < s["precompression_stress_Pa"]
    assert wetter["precompression_stress_Pa"] == pytest.approx(
        1e3 * PT.schjonning_lamande_2018_kPa(1.55, 1.0, 0.10), rel=1e-15)
    denser = soil_preset("sandy_loam_15")
    denser.update(bulk_density_initial_Mg_per_m3=1.65)
    denser = check_set(denser, SOIL_PARAMS, "soil")
    assert denser["compression_index_lambda"] == pytest.approx(PT.keller_arvidsson_2007(2.65, 1.65)[1], rel=1e-15)
    assert denser["precompression_stress_Pa"] > s["precompression_stress_Pa"]


@pytest.mark.parametrize("name", sorted(SOILS))
def test_one_strength_on_every_preset(name):
    """The density model's precompression stress (where the initial recompression line meets the virgin
    line) is the strength the risk grades against, and the yield line's k2 lies between kappa and lambda."""
    s = soil_preset(name)
    v0 = D.initial_specific_volume(s)
    lam, kap = s["compression_index_lambda"], s["recompression_index_kappa"]
    pc = float(D.precompression_stress_kPa(v0, s["virgin_line_N"], lam - kap))
    assert pc == pytest.approx(1e-3 * s["precompression_stress_Pa"], rel=1e-12)
    assert kap < s["yield_compression_index_k2"] < lam
    rows = {r[0]: r[4] for r in describe("soil", name)}
    assert rows["precompression_stress_Pa"].startswith("derived from")
    assert rows["virgin_line_N"].startswith("derived")


def test_no_two_presets_share_a_strength():
    pcs = {name: soil_preset(name)["precompression_stress_Pa"] for name in SOILS}
    assert len(set(pcs.values())) == len(pcs), pcs


def test_own_weight_closed_form():
    s = soil_preset("sandy_loam_15")
    theta = PT.van_genuchten_water_content(s["matric_suction_kPa"], s["clay_kg_per_kg"])
    rho = s["bulk_density_initial_Mg_per_m3"] + min(theta, 1 - s["bulk_density_initial_Mg_per_m3"] / 2.65)
    assert PT.geostatic_vertical_stress_Pa(s, DEPTHS) == pytest.approx(1e3 * rho * 9.81 * np.array(DEPTHS), rel=1e-15)
    assert D.geostatic_table([s, s], DEPTHS).shape == (2, 4)


def test_the_rut_bounds_the_compression():
    v0 = np.array([2.0, 2.0, 2.0])
    sv = np.zeros((3, 4), dtype=np.float32)
    sv[:, :3] = 1.9  # strain 0.05 down to 0.5 m, the initial state (0) at 0.8 m
    c = D.column_compression_m(np.where(sv > 0, sv, 2.0).astype(np.float64), v0, DEPTHS)
    # trapezoids: 0.05 * 0.1 + 0.05 * 0.2 + 0.05 * 0.2 + 0.5 * 0.05 * 0.3
    assert c == pytest.approx([0.0325] * 3, rel=1e-6)
    rut = np.array([0.1, 0.0325 / 2, 0.0])  # more than it, half of it, none
    before = sv.copy()
    assert D.cap_to_rut(sv, np.arange(3), v0, DEPTHS, rut) == 2
    assert np.array_equal(sv[0], before[0])
    assert sv[1, :3] == pytest.approx(2.0 - 0.5 * 0.1, rel=1e-6) and sv[1, 3] == 0.0  # the initial stays 0
    assert np.all(sv[2, :3] == np.float32(2.0)) and sv[2, 3] == 0.0
    after = D.column_compression_m(np.where(sv > 0, sv, 2.0).astype(np.float64), v0, DEPTHS)
    assert after[1] == pytest.approx(rut[1], rel=1e-5) and after[2] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("name", sorted(SOILS))
def test_risk_and_density_agree(name):
    """One load from the initial state at every stress: "high" (above 1.1 sigma_pc, own weight included)
    always densifies where the saturation bound leaves air to expel; "low" (below 0.5 sigma_pc)
    densifies at most (k2 - kappa) (lambda m / (lambda - kappa) - ln 2) in specific volume (the k2 line
    from the yield line to half the strength), a relative density change stated below."""
    s = soil_preset(name)
    a = D.soil_arrays([s])
    pc = s["precompression_stress_Pa"]
    geo = D.geostatic_table([s], DEPTHS)[0]
    sigma = np.geomspace(0.05 * pc, 3.0 * pc, 200)[:, None] * np.ones(len(DEPTHS))
    total = sigma + geo
    v0 = a["v0"][0]
    v1 = D.load_update(np.full(total.shape, v0), np.log(1e-3 * total), *(a[k][0] for k in (
        "N", "lambda", "kappa", "lambda_minus_kappa", "m", "k2", "v_min")))
    risk = S.risk_class(total, pc)
    lam, kap, m, k2 = (a[k][0] for k in ("lambda", "kappa", "m", "k2"))
    bound = (k2 - kap) * (lam * m / (lam - kap) - math.log(2.0))
    high, low = risk == 2, risk == 0
    assert high.any() and low.any()
    air = a["v_min"][0] + kap * np.log(1e-3 * total) < v0  # the saturation bound leaves room
    assert np.all(v1[high & air] < v0) and (high & air).any()
    assert np.all(v0 - v1[low] <= bound * (1 + 1e-12))
    # the stated amount: at most 2.5 % of the initial density on every preset
    assert bound / (v0 - bound) < 0.025


# ---- two layers: a subsoil described apart from the topsoil (pedotransfer.SUBSOIL_KEYS) -------------------

def _layered(**kw):
    """The loam with a denser, drier subsoil below 0.3 m (or ``kw``)."""
    return _loam(**{"subsoil_bulk_density_initial_Mg_per_m3": 1.65, "subsoil_matric_suction_kPa": 30.0, **kw})


def test_a_soil_is_one_layer_unless_its_subsoil_is_described():
    s = _loam()
    assert not PT.is_layered(s) and PT.subsoil_set(s) is s
    assert all(s[sub] == s[top] for top, sub in PT.SUBSOIL_KEYS.items())
    # one layer: the per-depth tables are the per-soil values at every depth, bit for bit
    a, b = D.soil_arrays([s]), D.soil_arrays([s], DEPTHS)
    assert b["top"].all() and all(np.array_equal(b[k][0], np.full(4, a[k][0])) for k in a)
    # a changed topsoil moves the subsoil with it while the subsoil is not described
    denser = _loam()
    denser.update(bulk_density_initial_Mg_per_m3=1.6)  # (a set's update keeps what was derived)
    denser = check_set(denser, SOIL_PARAMS, "soil")
    assert denser["subsoil_bulk_density_initial_Mg_per_m3"] == 1.6 and not PT.is_layered(denser)


def test_a_described_subsoil_has_its_own_lines_strength_and_weight():
    s = _layered()
    assert PT.is_layered(s)
    sub = PT.subsoil_set(s)
    # the subsoil's own PTFs: Schjoenning & Lamande at its density and suction, Keller & Arvidsson at its v0
    assert sub["precompression_stress_Pa"] == pytest.approx(1e3 * PT.schjonning_lamande_2018_kPa(1.65, 30.0, 0.10),
                                                            rel=1e-15)
    assert sub["compression_index_lambda"] == pytest.approx(PT.keller_arvidsson_2007(2.65, 1.65)[1], rel=1e-15)
    assert sub["precompression_stress_Pa"] > s["precompression_stress_Pa"]
    a = D.soil_arrays([s], DEPTHS)
    assert list(a["top"][0]) == [True, False, False, False]  # 0.3 m is the subsoil's top
    assert a["pc"][0, 0] == s["precompression_stress_Pa"] and np.all(a["pc"][0, 1:] == sub["precompression_stress_Pa"])
    assert a["v0"][0, 0] == pytest.approx(2.65 / 1.55) and np.all(a["v0"][0, 1:] == pytest.approx(2.65 / 1.65))
    # the own weight: the topsoil's moist weight to 0.3 m, the subsoil's below
    g_top = 1e3 * PT.moist_bulk_density_Mg_per_m3(s) * 9.81
    g_sub = 1e3 * PT.moist_bulk_density_Mg_per_m3(sub) * 9.81
    assert D.geostatic_table([s], DEPTHS)[0] == pytest.approx(
        [0.1 * g_top, 0.3 * g_top, 0.3 * g_top + 0.2 * g_sub, 0.3 * g_top + 0.5 * g_sub], rel=1e-15)
    # a user's topsoil strength is the topsoil's: the subsoil keeps its PTF strength
    weak = _layered(precompression_stress_Pa=40e3)
    assert PT.subsoil_set(weak)["precompression_stress_Pa"] == sub["precompression_stress_Pa"]


def test_bad_subsoil_descriptions_are_refused_naming_the_key():
    with pytest.raises(ParameterError, match=r"subsoil_clay_kg_per_kg \+ subsoil_silt_kg_per_kg"):
        _loam(subsoil_clay_kg_per_kg=0.5)
    with pytest.raises(ParameterError, match="subsoil_bulk_density_initial_Mg_per_m3 = 2.8 must be in"):
        _loam(subsoil_bulk_density_initial_Mg_per_m3=2.8)
    with pytest.raises(ParameterError, match="subsoil_matric_suction_kPa = -2"):
        _loam(subsoil_matric_suction_kPa=-2.0)
    with pytest.raises(ParameterError, match="subsoil_top_m = 0"):
        _layered(subsoil_top_m=0.0)


def test_a_pass_folds_each_depth_on_its_layers_lines():
    """The same stress on a one-layer and a two-layer soil: the topsoil's depth moves the same, the
    subsoil's depths move by their own lines from their own initial state (the fold equals
    density.load_update with the subsoil's arrays), and the cap keeps the column within the rut."""
    one, two = _loam(), _layered()
    p = np.full((1, 4), 150e3, dtype=np.float32)
    sv1, sv2 = np.zeros((1, 4), np.float32), np.zeros((1, 4), np.float32)
    si = np.zeros(1, dtype=np.intp)
    D.pass_update(sv1, p, si, [one], depths_m=DEPTHS, geostatic_Pa=D.geostatic_table([one], DEPTHS))
    geo2 = D.geostatic_table([two], DEPTHS)
    D.pass_update(sv2, p, si, [two], depths_m=DEPTHS, geostatic_Pa=geo2)
    assert sv2[0, 0] == sv1[0, 0] > 0
    b = D.soil_arrays([PT.subsoil_set(two)])
    lnp = np.log(1e-3 * (150e3 + geo2[0, 1:]))
    want = D.load_update(np.full(3, b["v0"][0]), lnp, *(b[k][0] for k in (
        "N", "lambda", "kappa", "lambda_minus_kappa", "m", "k2", "v_min")))
    assert np.array_equal(sv2[0, 1:], np.where(want < b["v0"][0], want, 0.0).astype(np.float32))
    rho = D.bulk_density(sv2, si, [two], DEPTHS)[0]
    assert rho[1] > 1.65 and rho[0] > 1.55
    with pytest.raises(ParameterError, match="depths"):
        D.pass_update(sv2, p, si, [two])


# ---- the column under the tracks of a homogeneous run (symtrack/simulation/column.py) ------------------------

class _OneStep:
    """A homogeneous run's result of one output step with the given contact pressures and loads."""

    def __init__(self, scenario, p_idler, p_sprocket, sinkage_m=0.002):
        from symtrack.presets import vehicle_preset

        self.scenario = scenario
        self.t = np.array([0.0])
        b, l_m = scenario.params["track_width_m"], scenario.params["contact_length_m"]
        load = 0.5 * (p_idler + p_sprocket) * b * l_m  # a linear pressure's load (none of it below 0)
        self.output_names = tuple(f"{w}_{s}_{u}" for s in ("left", "right") for w, u in (
            ("p_idler", "Pa"), ("p_sprocket", "Pa"), ("normal_load", "N"), ("sinkage_idler", "m"),
            ("sinkage_sprocket", "m")))
        self.Y = np.array([[p_idler, p_sprocket, load, sinkage_m, sinkage_m] * 2])
        assert vehicle_preset  # (the scenario's vehicle)

    def output(self, name):
        return self.Y[:, self.output_names.index(name)]


@pytest.mark.parametrize("p_idler, p_sprocket", [(40e3, 40e3), (20e3, 55e3)])
def test_the_column_stress_is_the_contacts_integral(p_idler, p_sprocket):
    """The column's vertical stress under a track's centre-line equals the largest over that line of
    subsoil.stress_bruteforce (Gauss-Legendre over both contacts) within 0.5 % at every depth."""
    from symtrack.simulation.column import POINTS_ALONG, column_figures
    from symtrack.simulation.scenario import load_scenario

    sc = load_scenario("validation")
    f = column_figures(_OneStep(sc, p_idler, p_sprocket))
    p = sc.params
    l_m, b, B = p["contact_length_m"], p["track_width_m"], p["track_gauge_m"]
    a = (0.0, 0.0, 1.0, 0.0, p_idler, (p_sprocket - p_idler) / l_m, p_idler, (p_sprocket - p_idler) / l_m)
    geo = (l_m, b, B, 0.0)
    px = np.linspace(-0.5 * l_m, 0.5 * l_m, POINTS_ALONG)
    for z, got in zip(f["subsoil_depths_m"], f["subsoil_sigma_z_max_kPa"], strict=True):
        ref = S.stress_bruteforce(px, np.full(px.size, 0.5 * B), a, geo, z, p["stress_concentration_factor"])
        assert got == pytest.approx(1e-3 * ref.max(), rel=5e-3), z
    # the fold from the stress and the own weight: the density model's own numbers at each depth
    soil = sc.params
    a2 = D.soil_arrays([soil], f["subsoil_depths_m"])
    total = 1e3 * np.array(f["subsoil_sigma_z_max_kPa"]) + D.geostatic_table([soil], f["subsoil_depths_m"])[0]
    assert [r for r in f["subsoil_risk_by_depth"]] == [S.RISK_NAMES[c] for c in S.risk_class(total, a2["pc"][0])]
    assert np.all(np.array(f["bulk_density_after_Mg_per_m3"]) >= np.array(f["bulk_density_initial_Mg_per_m3"]))
    assert f["column_compression_mm"] <= 2.0 + 1e-9  # the rut (2 mm here) bounds it
