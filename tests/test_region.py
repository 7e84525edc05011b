"""The region study's inputs and its fast fidelity against independent truth: the package's closed forms
(stress below a uniform strip load by brute force, the density of n passes at one stress), the independent
rasteriser of traffic_seasons, and the inputs' refusals (docs/region.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.region import demo
from symtrack.region.fast import FastOp, density_change, run_season_fast, sweep_operation
from symtrack.region.fleet import load_fleet, parse_fleet, stress_profile, track_machine
from symtrack.region.inputs import class_soil, draw_day, load_region, moisture_class, read_suction_csv
from symtrack.soil import density, subsoil
from symtrack.studies.operations import OperationSettings
from symtrack.studies.traffic_seasons import Machine as TSMachine
from symtrack.studies.traffic_seasons import Wheel as TSWheel
from symtrack.studies.traffic_seasons import segment_counts, segment_geometry
from symtrack.vehicles.tyre import contact, footprint_stress_at_depth

DEPTHS = (0.1, 0.3, 0.5)


@pytest.fixture(scope="module")
def fleet():
    return load_fleet("builtin")


@pytest.fixture(scope="module")
def region(tmp_path_factory):
    folder = tmp_path_factory.mktemp("region")
    return demo.write_region(folder, n_fields=3, seed=3)


def _crawler():
    return track_machine("crawler", vehicle_preset("reference_crawler"), 8.0, 4.0)


# ---- the stress profile against the package's stress by brute force ------------------------------------------
def test_the_crawler_profile_is_the_uniform_tracks_stress_by_brute_force():
    m = _crawler()
    xi = 5.0
    prof = stress_profile(m, DEPTHS, xi)
    t = m.tracks
    p = t.pressure_Pa
    a = np.array([0.0, 0.0, 1.0, 0.0, p, 0.0, p, 0.0])
    geo = np.array([t.contact_length_m, t.track_width_m, t.track_gauge_m, 0.0, 0.1, 0.0])
    v = np.array([0.75, 0.6, 0.0])  # under the left track's centre, its inner part, between the tracks
    for k, d in enumerate(DEPTHS):
        # the largest stress of a uniform track is below the contact's middle (s = l/2: x = 0)
        ref = subsoil.stress_bruteforce(np.zeros(3), v, a, geo, d, xi)
        got = prof.at(v)[:, k]
        # (the engine's tables drop the tail below 1e-4 of the surface pressure: subsoil.TAIL_FRACTION)
        assert np.allclose(got, ref, rtol=5e-3, atol=subsoil.TAIL_FRACTION * p), (d, got, ref)


@pytest.mark.parametrize("accel", [0.4, -0.4, 3.0, -3.0])
def test_the_pitched_pressure_line_is_the_engines(accel):
    """An accelerating crawler's pressure line is the terrain engine's (vehicles/planar.py: each track's load and
    its share of the pitching moment -m a h of the inertial force at the centre of gravity), linear at the
    operations' 0.4 m/s^2, triangular where the resultant leaves the middle third (3 m/s^2)."""
    import casadi as ca

    from symtrack.region.fleet import peak_pressure_factor, pressure_line
    from symtrack.vehicles.planar import PressureDistribution

    params = vehicle_preset("reference_crawler")
    m = _crawler()
    assert m.cg_height_m == params["cg_height_m"]
    W = m.tracks.mass_kg * 9.81
    M = -m.tracks.mass_kg * accel * m.cg_height_m
    l, b = m.tracks.contact_length_m, m.tracks.track_width_m
    ref = PressureDistribution(ca.DM(W / 2), ca.DM(M / 2), b, l)
    alpha, beta = pressure_line(m, accel)
    s = np.linspace(0.0, l, 49)
    got = np.maximum(0.0, alpha + beta * s)
    want = np.array([float(ref.at(ca.DM(x))) for x in s])
    assert np.allclose(got, want, rtol=1e-9, atol=1e-6 * m.tracks.pressure_Pa), (got, want)
    assert peak_pressure_factor(m, accel) == pytest.approx(want.max() / m.tracks.pressure_Pa, rel=1e-9)
    # the total load is the track's: the line integrates to m g / 2
    assert np.trapezoid(got, s) * b == pytest.approx(W / 2, rel=1e-3)


def test_a_turned_track_sweeps_its_rigid_contact_by_brute_force():
    """On an arc, the cells a track's rigid l x b contact covers at some pose (fleet.arc_bands) and how many
    separate times (fleet.arc_stays), against the contact placed at 4,000 poses along the arc."""
    from symtrack.region.fleet import arc_bands, arc_stays

    m = _crawler()
    t = m.tracks
    for R in (2.0, -3.0):
        sweep = math.radians(90.0)
        sg = 1.0 if R > 0 else -1.0
        rng = np.random.default_rng(5)
        # points of the annulus the machine can reach, at angles within the arc
        r = rng.uniform(abs(R) - 1.2, abs(R) + 1.4, 4000)
        alpha = rng.uniform(0.0, sweep, r.size)
        # the arc from (0, -sg |R|) heading +x about the centre (0, 0); a point at angle alpha from the start
        px = r * np.sin(alpha)
        py = -sg * r * np.cos(alpha)
        theta = np.linspace(0.0, sweep, 4001)
        under = np.zeros((theta.size, r.size), dtype=bool)
        for k, th in enumerate(theta):
            x0, y0 = abs(R) * math.sin(th), -sg * abs(R) * math.cos(th)
            ax, ay = math.cos(th), sg * math.sin(th)  # ahead
            lx, ly = -ay, ax  # left
            u = (px - x0) * ax + (py - y0) * ay
            w = (px - x0) * lx + (py - y0) * ly
            for lat, b in m.strips():
                under[k] |= (np.abs(u) <= 0.5 * t.contact_length_m) & (np.abs(w - lat) <= 0.5 * b)
        runs = (np.diff(under.astype(np.int8), axis=0) == 1).sum(axis=0) + under[0]
        v = sg * (abs(R) - r)
        in_band = np.zeros(r.size, dtype=bool)
        for lo, hi in arc_bands(m, R):
            in_band |= (v >= lo) & (v < hi)
        stays = np.where(in_band, arc_stays(m, R, sweep, r, alpha), 0)
        # (points within a pose's step of a run's end may differ: 1 in 1,000 at most)
        assert np.mean(stays != runs) < 1e-3, (R, np.mean(stays != runs))
        assert np.mean(runs == 2) > 0.02  # the ends of the contact pass the outer rims twice
        # wider than the straight strips: the contact's ends sweep beyond its edges
        straight = np.zeros(r.size, dtype=bool)
        for lat, b in m.strips():
            straight |= np.abs(v - lat) <= 0.5 * b
        assert np.all(in_band >= straight) and in_band.sum() > 1.3 * straight.sum()


def test_the_combine_profile_under_a_wheel_is_the_direct_sum_of_its_contact(fleet):
    m = fleet.machines["combine_7m5"]
    xi = 5.0
    prof = stress_profile(m, DEPTHS, xi)
    w = m.wheels[0]  # front left, x = 0
    c = contact(w.tyre, w.load_kN, w.inflation_kPa, 0.01)
    # at x = 0 (the front axle) below the front left wheel's centre line: the front tyres' direct sum (the rear
    # axle 3.8 m behind adds nothing there within the reach); the profile is the max over x, at x = 0 here
    pts_y = np.array([w.y_m])
    ref = np.zeros(len(DEPTHS))
    for o in m.wheels[:2]:
        sz, _ = footprint_stress_at_depth(c.x_m + o.x_m, c.y_m + o.y_m, c.force_kN, np.zeros(1), pts_y, DEPTHS, xi)
        ref += 1e3 * sz[0]
    got = prof.at(pts_y)[0]
    # the profile's 3 cm tables against the 1 cm direct sum: within 1 % (fleet.PROFILE_STEP_M)
    assert np.allclose(got, ref, rtol=1e-2), (got, ref)


# ---- the footprint against traffic_seasons' rasteriser -----------------------------------------------------------
def test_the_centre_rule_counts_are_traffic_seasons_counts(fleet):
    m = fleet.machines["plough"]
    fs = OperationSettings(name="p", size_m=(80.0, 50.0), cell_m=0.25, working_width_m=m.working_width_m,
                           headland_passes=3, tracks="random", seed=4, turn="auto", turn_radius_m=m.turn_radius_m)
    op = FastOp("p", fs, m, 1, None, stress_profile(m, DEPTHS, 5.0), dict(soil_preset("sandy_loam_15")))
    shape = (320, 200)
    counts, sig, cover = sweep_operation(op, shape, 0.25, "centre")
    from symtrack.studies.operations import plan_operation

    ts = TSMachine("p", m.working_width_m, m.outer_width_m, m.turn_radius_m,
                   tuple(TSWheel(w.name, w.y_m, w.width_m) for w in m.wheels))
    ref = segment_counts(segment_geometry(plan_operation(fs)), ts, shape, 0.25)
    assert np.array_equal(counts, ref)
    assert np.array_equal(sig[..., 0] > 0, counts > 0)  # the stress is recorded under the footprint, only there
    # the overlap rule covers more: every centre-rule cell and a rim
    # (the centre rule's cells are at least half under a strip; the overlap rule's rim, less)
    assert cover[counts > 0].min() >= 0.5 - 1e-6 and np.all(cover[counts == 0] == 0)
    c2, _, cover2 = sweep_operation(op, shape, 0.25, "overlap")
    assert cover2[(c2 > 0) & (counts == 0)].max() <= 0.5 + 1e-6
    assert np.all(c2[counts > 0] > 0) and (c2 > 0).sum() > (counts > 0).sum()


def test_a_drive_covers_its_strips_area():
    m = _crawler()
    # cells of 7 cm, incommensurate with the tracks' 0.45 m and 1.5 m gauge (on cells of 10 cm a track aligned
    # with the grid covers 5 cells, 0.5 m: the centre rule is unbiased over the positions, not at each)
    fs = OperationSettings(name="s", size_m=(60.0, 40.0), cell_m=0.07, working_width_m=8.0, headland_passes=2,
                           tracks="ab", turn="u", turn_radius_m=4.0, lines=1)
    op = FastOp("s", fs, m, 1, None, stress_profile(m, DEPTHS, 5.0), dict(soil_preset("sandy_loam_15")))
    shape = (int(60 / 0.07) + 1, int(40 / 0.07) + 1)
    counts, _, _ = sweep_operation(op, shape, 0.07, "centre")
    from symtrack.studies.operations import plan_operation

    plan = plan_operation(fs)
    # the area the tracks ran over, each segment's own (passes x cell area: a cell under two segments counts
    # twice): on a straight its length times the two tracks' width; on an arc of sweep A each track's rigid
    # contact sweeps the annulus from its inner edge's radius rho_in to its outer corners' sqrt(rho_out^2 + l^2/4),
    # and the part beyond rho_out (by more than half a cell) twice where its two stays fit in the arc:
    # A/2 (r_hi^2 - rho_in^2) + the integral of max(0, A - 2 acos(rho_out / r)) r dr
    t = m.tracks
    area = 0.0
    for seg in plan.path.segments:
        if seg.kind == "straight":
            area += seg.length_m * 2 * t.track_width_m
            continue
        A, R = math.radians(seg.angle_deg), abs(seg.radius_m)
        for lat in (-0.5 * t.track_gauge_m, 0.5 * t.track_gauge_m):
            rho_in, rho_out = R + lat - 0.5 * t.track_width_m, R + lat + 0.5 * t.track_width_m
            r_hi = math.hypot(rho_out, 0.5 * t.contact_length_m)
            area += 0.5 * A * (r_hi ** 2 - rho_in ** 2)
            rr = np.linspace(rho_out + 0.035, r_hi, 2001)
            area += np.trapezoid(np.maximum(0.0, A - 2 * np.arccos(rho_out / rr)) * rr, rr)
    assert abs(counts.sum() * 0.07 ** 2 - area) < 0.02 * area, (counts.sum() * 0.07 ** 2, area)


# ---- the density against the package's closed form -------------------------------------------------------------
def test_n_passes_fold_as_the_closed_form_of_n_loads():
    m = _crawler()
    soil = dict(soil_preset("sandy_loam_15"))
    fs = OperationSettings(name="s", size_m=(60.0, 40.0), cell_m=0.1, working_width_m=8.0, headland_passes=2,
                           tracks="ab", turn="u", turn_radius_m=4.0, lines=1)
    prof = stress_profile(m, DEPTHS, float(soil["stress_concentration_factor"]))
    n = 4
    op = FastOp("s", fs, m, n, None, prof, soil)
    res = run_season_fast([op], (600, 400), 0.1, DEPTHS)
    counts1, sig, _ = sweep_operation(op, (600, 400), 0.1, "centre")
    cell = np.flatnonzero(counts1.ravel() == 1)[len(np.flatnonzero(counts1.ravel() == 1)) // 2]
    geo = density.geostatic_table([soil], list(DEPTHS))[0]
    for k in range(len(DEPTHS)):
        p_kPa = 1e-3 * (float(sig.reshape(-1, len(DEPTHS))[cell, k]) + geo[k])
        ref = density.passes_at_constant_stress(soil, p_kPa, n)[-1]
        v = float(res.state[cell, k]) if res.state[cell, k] > 0 else density.initial_specific_volume(soil)
        assert v == pytest.approx(ref, rel=2e-6), (k, v, ref)
    assert np.array_equal(res.counts, n * counts1)  # each pass of the drive, n times


def test_the_same_pass_compacts_more_on_a_wet_day():
    m = _crawler()
    soil = soil_preset("north_gower_clayey_loam_46")
    fs = OperationSettings(name="s", size_m=(60.0, 40.0), cell_m=0.2, working_width_m=8.0, headland_passes=2,
                           tracks="ab", turn="u", turn_radius_m=4.0, lines=2)
    prof = stress_profile(m, DEPTHS, float(soil["stress_concentration_factor"]))
    out = {}
    # (within Schjønning & Lamandé's range and where their strength carries the soil's weight: this soil's
    # strength grows with the suction from 30 kPa on, and falls back to Severiano et al.'s below: 20 kPa is
    # stronger than 30 kPa; docs/region.md)
    for label, suction in (("wet", 30.0), ("dry", 300.0)):
        s = dict(class_soil(soil, suction))
        res = run_season_fast([FastOp("s", fs, m, 1, None, prof, s)], (300, 200), 0.2, DEPTHS)
        out[label] = density_change(res.state, s, DEPTHS).mean(axis=0)
    assert np.all(out["wet"] >= out["dry"]) and out["wet"][0] > out["dry"][0] + 1e-4, out


def test_tillage_loosens_above_its_depth_and_leaves_the_rest():
    m = _crawler()
    soil = dict(soil_preset("north_gower_clayey_loam_46"))
    fs = OperationSettings(name="s", size_m=(60.0, 40.0), cell_m=0.2, working_width_m=8.0, headland_passes=2,
                           tracks="ab", turn="u", turn_radius_m=4.0)
    prof = stress_profile(m, DEPTHS, float(soil["stress_concentration_factor"]))
    first = run_season_fast([FastOp("a", fs, m, 2, None, prof, soil)], (300, 200), 0.2, DEPTHS)
    till = FastOp("till", fs, m, 1, 0.2, prof, soil)
    after = run_season_fast([till], (300, 200), 0.2, DEPTHS, state=first.state)
    assert np.all(after.state[:, 0] == 0)  # 0.1 m: back at the initial state
    assert np.array_equal(after.state[:, 1:] != 0, (first.state[:, 1:] != 0) | (after.state[:, 1:] != 0))
    moved = first.state[:, 1] > 0
    assert moved.any() and np.all(after.state[moved, 1] <= first.state[moved, 1])  # below: persists (or compacts)


# ---- inputs ---------------------------------------------------------------------------------------------------
def test_the_demo_region_loads_and_every_machine_has_a_source(region, fleet):
    spec = load_region(region)
    assert len(spec.fields) == 3 and set(spec.years) == {2021, 2022}
    assert all(m.source for m in fleet.machines.values())
    f = spec.fields[0]
    # the frame round-trips and puts the ring inside the field's grid
    X, Y = np.array(f.world_ring).T
    x, y = f.to_local(X, Y)
    assert np.allclose(np.column_stack([x, y]), np.array(f.ring), atol=1e-6)
    assert x.min() > 0 and y.min() > 0 and x.max() < f.size_m[0] and y.max() < f.size_m[1]


def test_the_day_is_drawn_among_workable_days_or_is_the_driest():
    s = np.full(365, 5.0)
    s[100:110] = 20.0
    days = {draw_day(s, (95, 120), 10.0, np.random.default_rng(k)) for k in range(50)}
    assert days <= set(range(101, 111)) and len(days) > 3
    s2 = np.full(365, 5.0)
    s2[130] = 8.0
    assert draw_day(s2, (120, 140), 10.0, np.random.default_rng(0)) == 131


def test_moisture_classes_and_the_wetter_soil_is_weaker():
    assert moisture_class(10.0, 0.25) == 8  # pF 2.0
    soil = soil_preset("north_gower_clayey_loam_46")
    wet, dry = class_soil(soil, 30.0), class_soil(soil, 100.0)
    assert wet["precompression_stress_Pa"] < dry["precompression_stress_Pa"]


def _edit(region, fn):
    text = region.read_text()
    region.write_text(fn(text))


@pytest.mark.parametrize("change, message", [
    (lambda t: t.replace('years = [2021, 2022]', 'years = [2021, 2023]'), "the year 2023 lacks 365 day"),
    (lambda t: t.replace('machine = "plough"', 'machine = "plow"'), "'plow' is not a machine"),
    (lambda t: t.replace('cell_m = 0.5', 'cell_m = 5.0'), "cell_m = 5.0 is outside the allowed range [0.05, 2]"),
    (lambda t: t.replace('window = [245, 268]', 'window = [268, 245]'), "window[1] = 245 must be an integer in [268"),
    (lambda t: t.replace('clay_kg_per_kg = 0.18', 'clay_kg_per_kg = 0.5'), "must sum to 1"),
])
def test_bad_region_inputs_are_refused_naming_the_key(tmp_path, change, message):
    p = demo.write_region(tmp_path, n_fields=2, seed=5)
    _edit(p, change)
    with pytest.raises(ScenarioError, match=message.replace("[", r"\[").replace("(", r"\(")):
        load_region(p)


def test_a_bad_suction_value_names_the_file_line_and_range(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("date,matric_suction_kPa\n2021-01-01,12\n2021-01-02,-3\n")
    with pytest.raises(ScenarioError, match=r"line 3 \(2021-01-02\): matric_suction_kPa = -3 is outside the allowed "
                                            r"range \(0, 1.5e6\]"):
        read_suction_csv(p, (2021,), "soils.x.suction_file")


def test_bad_fields_are_refused(tmp_path):
    p = demo.write_region(tmp_path, n_fields=2, seed=5)
    fields = json.loads((tmp_path / "fields.geojson").read_text())
    good = json.dumps(fields)
    ring = fields["features"][0]["geometry"]["coordinates"][0]
    fields["features"][0]["geometry"]["coordinates"].append([ring[0], ring[1], ring[2], ring[0]])
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    with pytest.raises(ScenarioError, match="hole"):
        load_region(p)
    fields = json.loads(good)
    fields["features"][1]["geometry"]["coordinates"] = [[[14.1, 50.1], [14.2, 50.1], [14.2, 50.2], [14.1, 50.1]]]
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    with pytest.raises(ScenarioError, match="degrees"):
        load_region(p)
    fields = json.loads(good)
    fields["features"][1]["properties"]["soil"] = "peat"
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    with pytest.raises(ScenarioError, match="soil = 'peat' is not a soil of"):
        load_region(p)


def test_a_fleet_without_sources_or_overloaded_tyres_is_refused():
    tyre = {"width_m": 0.6, "diameter_m": 1.6, "rated_load_kN": 45.0, "rated_inflation_kPa": 160.0, "source": "ASSUMED"}
    mach = {"working_width_m": 6.0, "source": "ASSUMED: a test",
            "wheels": [{"x_m": 0.0, "y_m": 1.0, "tyre": "t", "load_kN": 30.0}]}
    parse_fleet({"tyres": {"t": tyre}, "machines": {"m": mach}})
    with pytest.raises(ScenarioError, match=r"tyres.t.source is required"):
        parse_fleet({"tyres": {"t": {**tyre, "source": ""}}, "machines": {"m": mach}})
    heavy = {**mach, "wheels": [{"x_m": 0.0, "y_m": 1.0, "tyre": "t", "load_kN": 50.0}]}
    with pytest.raises(ScenarioError, match=r"load_kN = 50.0 is outside the allowed range \(0, 45\]"):
        parse_fleet({"tyres": {"t": tyre}, "machines": {"m": heavy}})
    assert math.isfinite(stress_profile(parse_fleet({"tyres": {"t": tyre}, "machines": {"m": mach}}).machines["m"],
                                        DEPTHS, 5.0).sigma_Pa.max())


def test_a_catalogs_crawler_with_its_cg_height_gets_the_pitched_pressure_line():
    from symtrack.region.fleet import peak_pressure_factor

    tracks = {"contact_length_m": 2.4, "track_width_m": 0.45, "track_gauge_m": 1.5, "mass_kg": 9000.0}
    mach = {"working_width_m": 6.0, "source": "ASSUMED: a test", "tracks": tracks}
    flat = parse_fleet({"machines": {"c": mach}}).machines["c"]
    tall = parse_fleet({"machines": {"c": {**mach, "tracks": {**tracks, "cg_height_m": 0.9}}}}).machines["c"]
    assert flat.cg_height_m is None and peak_pressure_factor(flat, 0.4) == 1.0
    # the loaded end's pressure m g / (2 l b) (1 + 6 a h / (g l)) (docs/region.md, step 3)
    assert tall.cg_height_m == 0.9
    assert peak_pressure_factor(tall, 0.4) == pytest.approx(1 + 6 * 0.4 * 0.9 / (9.81 * 2.4), rel=1e-3)
    with pytest.raises(ScenarioError, match=r"machines.c.tracks.cg_height_m = -1 is outside the allowed range"):
        parse_fleet({"machines": {"c": {**mach, "tracks": {**tracks, "cg_height_m": -1}}}})


# ---- soils from a soil map ---------------------------------------------------------------------------------------
def _soil_map_region(tmp_path, **kw):
    p = demo.write_region(tmp_path, n_fields=4, seed=7, soil_map=True, length_m=(90.0, 120.0), width_m=(60.0, 80.0),
                          spacing_m=160.0, **kw)
    units = json.loads((tmp_path / "soil_units.geojson").read_text())
    return p, units


def test_each_field_takes_the_soil_covering_most_of_it_from_polygons(tmp_path, caplog):
    from shapely.geometry import Polygon

    p, units = _soil_map_region(tmp_path)
    spec = load_region(p)
    xm = units["features"][0]["geometry"]["coordinates"][0][1][0]  # the units' boundary (x)
    for f in spec.fields:  # the generated map: silt loam west of the boundary, clay loam east of it
        west = Polygon(f.world_ring).centroid.x < xm
        assert f.soil == ("silt_loam" if west else "clay_loam") and f.soil_from == "soil_map"
        assert f.soil_share == pytest.approx(1.0)
    # the boundary moved through a field: its soil is the one over most of its area, its share that area's
    f = spec.fields[0]
    poly = Polygon(f.world_ring)
    x0, _, x1, _ = poly.bounds
    cut = x0 + 0.45 * (x1 - x0)
    for k, u in enumerate(units["features"]):
        ring = u["geometry"]["coordinates"][0]
        for pt in ring:
            if pt[0] == xm:
                pt[0] = cut
        units["features"][k] = u
    (tmp_path / "soil_units.geojson").write_text(json.dumps(units))
    west_share = poly.intersection(Polygon([(x0 - 1, -1e9), (cut, -1e9), (cut, 1e9), (x0 - 1, 1e9)])).area / poly.area
    assert 0.25 < west_share < 0.5
    with caplog.at_level("WARNING", logger="symtrack.region"):
        spec = load_region(p)
    g = spec.fields[0]
    assert g.soil == "clay_loam" and g.soil_share == pytest.approx(1 - west_share, rel=1e-9)
    assert f"field '{f.field_id}' is split across soils (clay_loam" in caplog.text
    p.write_text(p.read_text().replace('attribute = "soil"', 'attribute = "soil"\nsplit_fields = "refuse"'))
    with pytest.raises(ScenarioError, match=rf"field '{f.field_id}' is split across soils \(clay_loam \d+\.\d %, "
                                            r"silt_loam \d+\.\d %\): .* outside the range \[80, 100\] %"):
        load_region(p)
    p.write_text(p.read_text().replace('split_fields = "refuse"', 'split_fields = "refuse"\nsplit_share = 0.5'))
    assert load_region(p).fields[0].soil == "clay_loam"


def test_a_fields_own_soil_wins_over_the_map(tmp_path):
    p, _ = _soil_map_region(tmp_path)
    fields = json.loads((tmp_path / "fields.geojson").read_text())
    fields["features"][0]["properties"]["soil"] = "clay_loam"
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    f = load_region(p).fields[0]
    assert f.soil == "clay_loam" and f.soil_from == "fields_file" and f.soil_share == 1.0


@pytest.mark.parametrize("change, message", [
    (lambda u: u["features"][1]["properties"].update(soil="peat"),
     r"soil_units.geojson: feature 1 \(id 'U2'\): properties.soil = 'peat' is not a soil of \[soils\] "
     r"\(silt_loam, clay_loam\)"),
    (lambda u: u["features"][0]["geometry"].update(coordinates=[[[0, 0], [1e5, 1e5], [1e5, 0], [0, 1e5], [0, 0]]]),
     r"feature 0 \(id 'U1'\): not a valid polygon \(Self-intersection"),
    (lambda u: u["features"][0]["geometry"].update(type="LineString", coordinates=[[5e5, 5e6], [5e5, 5.1e6]]),
     r"feature 0 \(id 'U1'\): the geometry is a LineString"),
    (lambda u: u["features"].pop(1), r"no soil unit covers field 'F002'"),
])
def test_bad_soil_polygons_are_refused_naming_the_feature(tmp_path, change, message):
    p, units = _soil_map_region(tmp_path)
    change(units)
    (tmp_path / "soil_units.geojson").write_text(json.dumps(units))
    with pytest.raises(ScenarioError, match=message):
        load_region(p)


def _soil_raster(path, spec_fields, codes, crs="EPSG:32633", pixel_m=10.0, nodata=0):
    """A GeoTIFF of soil-unit codes over the fields: ``codes(x, y)`` gives each pixel's code."""
    import rasterio
    from rasterio.transform import from_origin

    pts = np.vstack([np.array(f.world_ring) for f in spec_fields])
    x0, y0 = pts.min(axis=0) - 50.0
    x1, y1 = pts.max(axis=0) + 50.0
    nx, ny = int(math.ceil((x1 - x0) / pixel_m)), int(math.ceil((y1 - y0) / pixel_m))
    xs = x0 + (np.arange(nx) + 0.5) * pixel_m
    ys = y1 - (np.arange(ny) + 0.5) * pixel_m
    data = codes(xs[None, :], ys[:, None]).astype(np.uint8)
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="uint8", crs=crs,
                       transform=from_origin(x0, y1, pixel_m, pixel_m), nodata=nodata) as ds:
        ds.write(data, 1)
    return (x0, y1)


def test_soils_from_a_raster_of_codes_and_its_refusals(tmp_path):
    from shapely.geometry import Polygon

    p, units = _soil_map_region(tmp_path)
    fields = load_region(p).fields
    xm = units["features"][0]["geometry"]["coordinates"][0][1][0]
    text = p.read_text().replace('file = "soil_units.geojson"\nattribute = "soil"',
                                 'file = "soil_units.tif"\ncodes = { 1 = "silt_loam", 2 = "clay_loam" }')
    p.write_text(text)
    # codes 1 west of the boundary, 2 east of it, 3 (not in the table) and nodata far from the fields
    _soil_raster(tmp_path / "soil_units.tif", fields, lambda x, y: np.where(x < xm, 1, 2) + 0 * y)
    spec = load_region(p)
    for f, g in zip(fields, spec.fields, strict=True):
        assert g.soil == f.soil and g.soil_from == "soil_map" and g.soil_share == 1.0
    # a code the table does not give, under a field: refused naming the pixel, the code and the codes allowed
    f0 = Polygon(fields[0].world_ring).centroid
    _soil_raster(tmp_path / "soil_units.tif", fields,
                 lambda x, y: np.where((abs(x - f0.x) < 10) & (abs(y - f0.y) < 10), 7, np.where(x < xm, 1, 2)))
    with pytest.raises(ScenarioError, match=r"soil_units.tif': the pixel at row \d+, column \d+ \(centre x = [\d.]+, "
                                            r"y = [\d.]+ m\), under field 'F001', has the code 7, which "
                                            r"soil_map.codes does not give a soil \(its codes: 1, 2\)"):
        load_region(p)
    # nodata under a whole field, another CRS, a code that is no soil
    _soil_raster(tmp_path / "soil_units.tif", fields, lambda x, y: np.where(x < xm, 0, 2) + 0 * y)
    with pytest.raises(ScenarioError, match=r"no soil unit covers field 'F001'"):
        load_region(p)
    _soil_raster(tmp_path / "soil_units.tif", fields, lambda x, y: np.where(x < xm, 1, 2) + 0 * y, crs="EPSG:32632")
    with pytest.raises(ScenarioError, match=r"soil_units.tif' is in EPSG:32632, the fields in EPSG:32633"):
        load_region(p)
    p.write_text(text.replace('2 = "clay_loam"', '2 = "loess"'))
    with pytest.raises(ScenarioError, match=r"soil_map.codes.2 = 'loess' is not a soil of \[soils\] \(silt_loam, "
                                            r"clay_loam\)"):
        load_region(p)
