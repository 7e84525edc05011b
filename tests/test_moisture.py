"""The day's moisture (symtrack/soil/moisture.py, docs/subsoil.md "Moisture"): the pedotransfer
functions against their published polynomials and curves, the refusals, the scenario and soil-map
inputs (a uniform map equal to the single value bit for bit), and the same traffic on a dry and a
wet day through the terrain engine."""

import copy
import math

import numpy as np
import pytest
from small_field import small_field

import symtrack
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.soil import moisture as M
from symtrack.terrain.soil_map import parse_soil_map


def test_defossez_polynomials_hand_evaluated():
    # Défossez et al. (2003) as soilphysics' compressive.properties1 codes it, evaluated by hand at
    # w = 20 %: N = 1.9997 + 5.258 - 11.012 + 8.88 - 2.56, lambda = 0.1402 + 0.0384 + 0.084 - 0.104
    N, lam, kap = M.defossez_2003(0.20, "defossez_2003_loess")
    assert (N, lam, kap) == pytest.approx((2.5657, 0.1586, 0.0058), abs=1e-12)
    # calcareous at 10 %: 2.4196 + 1.3767 - 2.035 + 1.21 - 0.24; 0.08051 + 0.3131 - 0.502 + 0.31 - 0.06
    N, lam, _ = M.defossez_2003(0.10, "defossez_2003_calcareous")
    assert (N, lam) == pytest.approx((2.7313, 0.14161), abs=1e-12)


def test_severiano_curve_and_strength():
    # the van Genuchten curve forward (theta(h) = tr + (ts - tr) (1 + (alpha h)^n)^-m) and back
    for clay, (_, a, b, ts, tr, alpha, n) in zip((10, 25, 35, 45, 60), M.SEVERIANO_2013_CLASSES, strict=True):
        for h in (1.0, 10.0, 100.0, 1000.0):
            theta = tr + (ts - tr) * (1 + (alpha * h) ** n) ** -(1 - 1 / n)
            assert M.severiano_2013_suction_kPa(theta, clay) == pytest.approx(h, rel=1e-9)
            assert M.severiano_2013_precompression_kPa(clay, h) == pytest.approx(a * h**b, rel=1e-15)
    # 129 h^0.15 below 20 % clay, 62.7 h^0.15 above 52 % (Severiano et al. 2013 as soilphysics codes it)
    assert M.severiano_2013_precompression_kPa(10, 100.0) == pytest.approx(129 * 100**0.15)
    assert M.severiano_2013_precompression_kPa(60, 100.0) == pytest.approx(62.7 * 100**0.15)
    # wetter is weaker
    assert M.severiano_2013_precompression_kPa(25, 5.0) < M.severiano_2013_precompression_kPa(25, 50.0)


SOIL = {"bulk_density_initial_Mg_per_m3": 1.2, "particle_density_Mg_per_m3": 2.65, "virgin_line_N": 2.1,
        "compression_index_lambda": 0.19, "recompression_index_kappa": 0.042, "precompression_stress_Pa": 1.39e5}


def test_apply_moisture_and_refusals():
    out = M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess",
                                  "clay_percent": 25})
    # Défossez's lines, Severiano's strength, and the virgin line through both (one strength)
    _, lam, kap = M.defossez_2003(0.2, "defossez_2003_loess")
    assert (out["compression_index_lambda"], out["recompression_index_kappa"]) == (lam, kap)
    h = M.severiano_2013_suction_kPa(0.2 * 1.2, 25)
    assert out["precompression_stress_Pa"] == 1e3 * M.severiano_2013_precompression_kPa(25, h)
    v0 = SOIL["particle_density_Mg_per_m3"] / 1.2
    assert out["virgin_line_N"] == pytest.approx(v0 + (lam - kap) * math.log(out["precompression_stress_Pa"] / 1e3),
                                                 rel=1e-14)
    # Défossez alone: its virgin line sets the strength (and comes back as the derived N)
    alone = M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess"})
    assert alone["virgin_line_N"] == pytest.approx(M.defossez_2003(0.2, "defossez_2003_loess")[0], rel=1e-12)
    w_sat = (1 / 1.2 - 1 / 2.65)
    with pytest.raises(ParameterError, match=r"soil.moisture.water_content_kg_per_kg = 0.5 is outside \[0, 0.456"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.5, "compression_ptf": "defossez_2003_loess"})
    assert 0.45 < w_sat < 0.46
    with pytest.raises(ParameterError, match="water_content_kg_per_kg = -0.01"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": -0.01, "compression_ptf": "defossez_2003_loess"})
    with pytest.raises(ParameterError, match="texture classes"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_clay"})
    with pytest.raises(ParameterError, match=r"range of defossez_2003_loess \[0.05, 0.3\]"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.35, "compression_ptf": "defossez_2003_loess"})
    with pytest.raises(ParameterError, match="clay_percent = 120"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2, "clay_percent": 120})
    with pytest.raises(ParameterError, match="unknown key"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2, "ptf": "x"})
    with pytest.raises(ParameterError, match="needs compression_ptf"):
        M.apply_moisture(SOIL, {"water_content_kg_per_kg": 0.2})


DAY = {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess", "clay_percent": 25.0}


def _doc(moisture, soil_map=None, passes=1):
    d = small_field("moisture_small", run={"duration_s": 5.0, "stop_after_distance_m": 0.5},
                    terrain={"passes": passes})
    d["soil"]["bulk_density_initial_Mg_per_m3"] = 1.2
    # an 11 t crawler (50 kPa): the 5.5 t one stays below the yield line of Severiano's strength on both days
    d["vehicle"] = {**d.get("vehicle", {}), "mass_kg": 11000.0}
    d["soil"]["moisture"] = copy.deepcopy(moisture)
    if soil_map is not None:
        d["terrain"]["soil_map"] = soil_map
    return d


def test_scenario_moisture_and_uniform_soil_map_bit_for_bit():
    sc = scenario_from_dict(_doc(DAY))
    want = M.apply_moisture({**sc.soil}, DAY)
    assert sc.soil == want
    # --set gives the flat key "moisture.KEY"
    d = _doc(DAY)
    d["soil"].pop("moisture")
    d["soil"].update({f"moisture.{k}": v for k, v in DAY.items()})
    assert scenario_from_dict(d).soil == sc.soil
    # a soil map whose soil is the same soil on the same day: the same parameters, bit for bit
    sm = parse_soil_map({"soils": [{"preset": "clayey_soil_thailand_38", "bulk_density_initial_Mg_per_m3": 1.2,
                                    "moisture": dict(DAY)}], "zones": [{"soil": 1, "x_m": [-6, 6], "y_m": [-2, 2]}]})
    assert sm.soils[0] == sc.soil
    assert all(math.copysign(1, sm.soils[0][k]) == math.copysign(1, v) and sm.soils[0][k] == v
               for k, v in sc.soil.items())
    with pytest.raises(ScenarioError, match="soil.moisture.water_content_kg_per_kg = 0.9"):
        scenario_from_dict(_doc({**DAY, "water_content_kg_per_kg": 0.9}))
    with pytest.raises(ScenarioError, match=r"soils\[0\].moisture"):
        parse_soil_map({"soils": [{"preset": "clayey_soil_thailand_38", "moisture": {**DAY, "clay_percent": -1}}],
                        "zones": [{"soil": 1, "x_m": [-6, 6], "y_m": [-2, 2]}]})


def test_uniform_map_run_equals_single_value_and_wet_compacts_more():
    """The same traffic on a dry (w = 0.10) and a wet day (w = 0.20): the wet soil's virgin line is
    lower (Défossez's loess), so it compacts where the dry one does not; the risk's strength falls
    (Severiano). A field whose soil map gives every cell the same soil on the same day equals the
    single [soil] bit for bit."""
    dry = symtrack.simulate(scenario_from_dict(_doc({**DAY, "water_content_kg_per_kg": 0.10})))
    wet = symtrack.simulate(scenario_from_dict(_doc(DAY)))
    rd = np.array(dry.summary["passes"][0]["bulk_density_max_Mg_per_m3"])
    rw = np.array(wet.summary["passes"][0]["bulk_density_max_Mg_per_m3"])
    assert np.all(rw >= rd) and rw[0] > rd[0] + 0.003
    assert wet.summary["subsoil_precompression_stress_min_kPa"] < dry.summary["subsoil_precompression_stress_min_kPa"]
    sm = {"soils": [{"preset": "clayey_soil_thailand_38", "bulk_density_initial_Mg_per_m3": 1.2,
                     "moisture": dict(DAY)}], "zones": [{"soil": 1, "x_m": [-6, 6], "y_m": [-2, 2]}]}
    mapped = symtrack.simulate(scenario_from_dict(_doc(DAY, soil_map=sm)))
    assert np.array_equal(mapped.terrain.specific_volume, wet.terrain.specific_volume)
    assert mapped.summary["passes"][0]["bulk_density_max_Mg_per_m3"] == \
        wet.summary["passes"][0]["bulk_density_max_Mg_per_m3"]


def _raster_doc(tmp_path, w_grid, name="w.npy", soil_moisture=DAY):
    np.save(tmp_path / name, w_grid)
    d = _doc(soil_moisture)
    d["terrain"]["moisture"] = {"raster": str(tmp_path / name), "compression_ptf": "defossez_2003_loess",
                                "clay_percent": 25.0}
    return d


def test_moisture_raster_uniform_equals_single_value_and_split(tmp_path):
    shape = (48, 16)  # the small field: 12 m x 4 m at 0.25 m
    single = symtrack.simulate(scenario_from_dict(_doc(DAY)))
    uni = symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, np.full(shape, 0.2))))
    assert np.array_equal(uni.terrain.specific_volume, single.terrain.specific_volume)
    assert np.array_equal(uni.terrain.sigma_max, single.terrain.sigma_max)
    assert not uni.terrain.soil_index.any() and not uni.terrain.soil_table
    # the cells with y > 0 wet (0.2), the others dry (0.1): two soils, the wet half compacts more
    w = np.full(shape, 0.1)
    w[:, 8:] = 0.2
    split = symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, w, "split.npy")))
    st = split.terrain
    assert len(st.soil_table) == 1 and sorted(np.unique(st.soil_index)) == [0, 1]
    v = st.specific_volume.reshape(48, 16, -1)[:, :, 0]
    moved_dry, moved_wet = np.count_nonzero(v[:, :8]), np.count_nonzero(v[:, 8:])
    assert moved_wet > 0 and moved_dry == 0


def test_moisture_raster_refusals(tmp_path):
    with pytest.raises(ScenarioError, match=r"terrain.moisture.raster = .*shape \(48, 16\).*cover the field"):
        symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, np.full((40, 16), 0.2))))
    w = np.full((48, 16), 0.2)
    w[3, 3] = 0.6
    with pytest.raises(ScenarioError, match=r"cell water content 0.6.*water_content_kg_per_kg = 0.6 is outside \[0,"):
        symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, w)))
    # split_soils refuses more pairs than a soil map holds (the world then keeps each cell's own day
    # parameters instead: test_moisture_raster_of_many_values)
    w = 0.1 + 0.001 * np.arange(48 * 16).reshape(48, 16) / 48
    mm = M.parse_moisture_map({"raster": "w.npy", "compression_ptf": "defossez_2003_loess"})
    with pytest.raises(ScenarioError, match="distinct .soil, water content. pairs"):
        M.split_soils([SOIL], ["[soil]"], np.zeros(w.size, dtype=np.uint8), w.ravel(), mm, 16)
    with pytest.raises(ScenarioError, match="unknown key"):
        scenario_from_dict({**_doc(DAY), "terrain": {**_doc(DAY)["terrain"], "moisture": {"raster": "w.npy",
                                                                                         "ptf": 1}}})


def test_moisture_raster_of_many_values(tmp_path, monkeypatch):
    """More distinct water contents than a soil map holds: each cell keeps its own day parameters
    (N, lambda, kappa, sigma_pc) and the engine its one soil. (a) Two values across the field (the test
    above's: its engines, compiled once) run both ways (soils of a map; per cell, the map's limit
    lowered to force it): each cell's day parameters
    equal its map soil's bit for bit (the fold of the same pass's stresses gives the same compression
    state, the same precompression stress per cell); the engine's numbers agree to 1e-7 of their
    largest (not bit for bit: the engine's soil-map path sums per soil). (b) Every cell its own
    value (768): each cell's compression state is the virgin line's closed form at its own water
    content and the pass's mean normal stress, and the precompression figure the weakest loaded
    cell's own."""
    from symtrack.soil import density
    from symtrack.terrain import world
    w2 = np.ones((48, 1)) * np.where(np.arange(16) % 3 == 0, 0.1, 0.2)[None, :]
    split = symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, w2, "w2.npy")))
    ws = split._study.world
    # (0.20 is [soil.moisture]'s day: folded into soil 0, so one soil besides it)
    assert len(split.terrain.soil_table) == 1 and ws.cell_day is None
    monkeypatch.setattr(world, "MAX_SOILS", 2)
    cell = symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, w2, "w2.npy")))
    wc = cell._study.world
    assert wc.cell_day is not None and not cell.terrain.soil_table and len(wc.soils) == 1
    assert np.array_equal(wc.precompression_stress_Pa(), ws.precompression_stress_Pa())
    # the fold (World.fold_pass): the pass's stress and the soil's own weight, then the rut's bound
    v = np.zeros_like(split.terrain.specific_volume)
    touched = np.flatnonzero(ws.touched)
    density.pass_update(v, ws.pass_sigma, np.zeros_like(split.terrain.soil_index), wc.soils,
                        cells=touched, cell_params=wc.cell_day, geostatic_Pa=wc.geostatic_Pa())
    density.cap_to_rut(v, touched, density.soil_arrays(wc.soils)["v0"][np.zeros(touched.size, dtype=int)],
                       split.terrain.subsoil_depths_m, split.terrain.z[touched])
    assert np.count_nonzero(v) > 20 and np.array_equal(v, split.terrain.specific_volume)
    for name, a in split.terrain.arrays().items():
        if name != "soil_index":
            b = cell.terrain.arrays()[name].astype(float)
            assert np.allclose(a.astype(float), b, rtol=0, atol=1e-7 * max(np.abs(a).max(), 1e-30)), name
    monkeypatch.undo()
    # (b) every cell its own water content
    w = 0.12 + 0.1 * np.arange(48 * 16).reshape(16, 48).T / (48 * 16)  # wetter with y, every cell its own
    res = symtrack.simulate(scenario_from_dict(_raster_doc(tmp_path, w, "many.npy")))
    wd = res._study.world
    assert len(wd.soils) == 1 and not res.terrain.soil_table
    soil = res.scenario.soil
    # the pass's fold before the rut's bound: each cell's own day parameters
    v = np.zeros_like(res.terrain.specific_volume)
    density.pass_update(v, wd.pass_sigma, np.zeros_like(res.terrain.soil_index), wd.soils,
                        cells=np.flatnonzero(wd.touched), cell_params=wd.cell_day, geostatic_Pa=wd.geostatic_Pa())
    moved = np.flatnonzero(v.any(axis=1))
    assert moved.size > 15  # (the wetter track of a 0.5 m run)
    p = wd.pass_sigma.astype(np.float64) + wd.geostatic_Pa()[0]
    v0 = density.initial_specific_volume(soil)
    for c in moved:
        day = M.apply_moisture(soil, {"water_content_kg_per_kg": float(w.ravel()[c]),
                                      "compression_ptf": "defossez_2003_loess", "clay_percent": 25.0})
        lam, kap = day["compression_index_lambda"], day["recompression_index_kappa"]
        line = density.load_update(np.full(p[c].shape, v0), np.log(1e-3 * p[c]), day["virgin_line_N"], lam, kap,
                                   lam - kap, day["yield_line_offset_ln_p"], day["yield_compression_index_k2"],
                                   day["specific_volume_min"])
        want = np.where((wd.pass_sigma[c] > 0) & (line < v0), line, 0.0).astype(np.float32)
        assert np.array_equal(v[c], want), c
    loaded = wd.pass_sigma[:, 0] > 0
    pc = [M.apply_moisture(soil, {"water_content_kg_per_kg": float(x), "clay_percent": 25.0})[
        "precompression_stress_Pa"] for x in w.ravel()[loaded]]
    assert res.summary["subsoil_precompression_stress_min_kPa"] == 1e-3 * min(pc)


@pytest.mark.parametrize("ptf, lo, hi", [({"compression_ptf": "defossez_2003_loess", "clay_percent": 25.0}, 0.073, 0.3),
                                         ({"compression_ptf": "defossez_2003_calcareous"}, 0.05, 0.3),
                                         ({"clay_percent": 45.0}, 0.106, 0.41)])
def test_cell_day_parameters_equal_apply_moisture_bit_for_bit(ptf, lo, hi):
    """The vectorised per-cell PTFs against apply_moisture's scalar ones at 20 000 random water contents
    (numpy's own pow would differ in the last bit for a few % of them); a value apply_moisture refuses
    is refused with its message."""
    soil = {**SOIL, "bulk_density_initial_Mg_per_m3": 1.2}
    w = np.concatenate([lo + (hi - lo) * np.random.default_rng(5).random(20000), [lo, hi]])
    mm = M.MoistureMap("w.npy", ptf)
    day = M.cell_day_parameters([soil], np.zeros(w.size, dtype=np.uint8), w, mm)
    for k in range(w.size):
        sp = M.apply_moisture(soil, {**ptf, "water_content_kg_per_kg": float(w[k])})
        assert all(sp[key] == day[key][k] for key in M.DAY_KEYS), k
    bad = w.copy()
    bad[17] = 0.04 if "compression_ptf" in ptf else 0.6
    where = f"terrain.moisture (soil 0, cell water content {float(bad[17])!r})"
    with pytest.raises(ParameterError) as want:
        M.apply_moisture(soil, {**ptf, "water_content_kg_per_kg": float(bad[17])}, where)
    with pytest.raises(ScenarioError) as got:
        M.cell_day_parameters([soil], np.zeros(w.size, dtype=np.uint8), bad, mm)
    assert str(got.value) == str(want.value)


def test_moisture_geotiff_must_cover_the_field(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import from_origin
    path = tmp_path / "w.tif"
    # 1 m pixels over x in [-6, 0], y in [-2, 2]: half the field
    with rasterio.open(path, "w", driver="GTiff", height=4, width=6, count=1, dtype="float32",
                       transform=from_origin(-6.0, 2.0, 1.0, 1.0)) as ds:
        ds.write(np.full((1, 4, 6), 0.2, dtype=np.float32))
    d = _doc(DAY)
    d["terrain"]["moisture"] = {"raster": str(path), "compression_ptf": "defossez_2003_loess"}
    with pytest.raises(ScenarioError, match="must cover the whole field"):
        symtrack.simulate(scenario_from_dict(d))


def test_a_dry_day_then_a_wet_day_on_the_same_field(tmp_path):
    """A terrain file continues on another day: the moisture's parameters (N, lambda, kappa,
    sigma_pc) are the new day's, the compression state carries over; any other soil parameter
    must still match."""
    dry = symtrack.simulate(scenario_from_dict(_doc({**DAY, "water_content_kg_per_kg": 0.10})))
    path = tmp_path / "dry.npz"
    dry.terrain.save(path)
    d = _doc(DAY)
    d["terrain"]["initial_state"] = str(path)
    wet = symtrack.simulate(scenario_from_dict(d))
    # the dry day compacted nothing, the wet day on its (rutted) field does; the risk's strength is the wet day's
    assert not dry.terrain.specific_volume.any()
    assert wet.summary["passes"][0]["bulk_density_max_Mg_per_m3"][0] > 1.203
    h = M.severiano_2013_suction_kPa(0.2 * 1.2, 25.0)
    pc_kPa = M.severiano_2013_precompression_kPa(25, h)
    assert wet.summary["subsoil_precompression_stress_min_kPa"] == pytest.approx(pc_kPa)
    # the day's lines carry over: the virgin line through the day's (Severiano's) strength
    assert wet.terrain.soil["virgin_line_N"] == wet.scenario.soil["virgin_line_N"]
    assert wet.terrain.soil["compression_index_lambda"] == M.defossez_2003(0.2, "defossez_2003_loess")[1]
    d["soil"]["cohesion_Pa"] = 4000.0
    with pytest.raises(ScenarioError, match="the terrain was made with soil cohesion_Pa"):
        symtrack.simulate(scenario_from_dict(d))
