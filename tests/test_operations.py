"""Field operations (issue 23; symtrack/studies/operations/): the plan's geometry against
independent truth, the plan's refusals, one small operation driven on the terrain engine (every
turn driven, nothing lifted) and the field's persistence through save and load."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.studies import operations as op
from symtrack.terrain.world import padding_m

BASE = {"name": "t", "model": {"lateral_law": "shear"}, "vehicle": {"preset": "reference_crawler"},
        "soil": {"preset": "clayey_soil_thailand_38"}}
PARAMS = {"contact_length_m": 2.4, "track_width_m": 0.45, "track_gauge_m": 1.5, "cg_ahead_of_contact_centre_m": 0.0}


def settings(**kw):
    return op.parse_operation({"size_m": [60.0, 48.0], "working_width_m": 4.0, "headland_passes": 2, "turn": "u",
                               "turn_radius_m": 2.0, **kw})


def test_covered_area_is_the_field_within_one_working_width():
    for w, n in ((4.0, 2), (3.0, 3), (6.0, 1)):
        fs = settings(working_width_m=w, headland_passes=n, turn="auto", turn_radius_m=min(0.5 * w, 3.0))
        plan = op.plan_operation(fs)
        cov = op.swath_mask(plan, (600, 480), 0.1)
        area = cov.sum() * 0.01
        assert abs(area - 60 * 48) <= w * 60, (w, area)
        # the headland rounds and the lines leave no strip unworked: the uncovered cells are the rounded corners
        assert area > 0.97 * 60 * 48


def test_controlled_lanes_share_is_the_lanes_share():
    fs = settings(tracks="controlled", lane_spacing_m=4.0, working_width_m=8.0, headland_passes=1, turn_radius_m=4.0)
    plan = op.plan_operation(fs)
    ys = op.lane_positions_m(fs)[::2]
    assert np.allclose(plan.line_y_m, ys)
    p = plan.path
    worked = op.sample_roles(plan) == 3
    mask = op.footprint_mask(p.x[worked], p.y[worked], p.psi[worked], PARAMS, (600, 480), 0.1)
    head = op.headland_mask(fs, (600, 480), 0.1)
    # the lanes' share of the in-field area: per lane two tracks over the worked length; a 0.45 m track
    # off the cell lines touches 5 cells of 0.1 m across (0.5 m), so that is the raster's track width
    x0, x1 = plan.worked_x_m
    inner = (60 - 2 * fs.headland_m) * (48 - 2 * fs.headland_m)
    expect = len(ys) * 2 * 0.5 * (x1 - x0) / inner
    got = mask[~head].sum() * 0.01 / inner
    assert abs(got - expect) <= 0.01 * expect, (got, expect)
    # and the lanes' own share (0.45 m tracks) within the cells' quantisation
    assert abs(got - len(ys) * 2 * 0.45 / (48 - 2 * fs.headland_m)) <= len(ys) * 2 * 0.05 / (48 - 2 * fs.headland_m)


def test_bad_plans_are_refused_before_anything_runs():
    with pytest.raises(ScenarioError, match="working_width_m = 70 is outside the allowed range"):
        op.plan_operation(settings(working_width_m=70.0))
    # a U-turn of 1.25 m reaches 1.25 m + half the contact (1.2 m) + the padding into a 2.5 m headland
    doc = {**BASE, "operation": {"size_m": [60.0, 48.0], "working_width_m": 2.5, "headland_passes": 1,
                                 "turn": "u", "turn_radius_m": 1.25}}
    with pytest.raises(ScenarioError, match="the plan leaves the field"):
        op.operation_spec_from_dict(doc)
    doc["operation"].update(headland_passes=2, turn_radius_m=2.0, working_width_m=4.0, turn_speed_m_s=3.0)
    with pytest.raises(ScenarioError, match="cannot hold this turn on this soil"):
        op.operation_spec_from_dict(doc)
    with pytest.raises(ScenarioError, match="operation.turn = 'spin'"):
        op.parse_operation({"turn": "spin"})
    with pytest.raises(ScenarioError, match="lateral_law"):
        op.operation_spec_from_dict({**BASE, "model": {"lateral_law": "creep"}, "operation": {}})


# the path-following law (the tests of what the engine keeps and of the law's own tracking; the default follower,
# the MPC, drives test_the_mpc_drives_a_small_operation_on_clay and the built-in seasons)
# 28 m x 22 m with one headland round: a headland with its corners, two lines and the U-turn between them
# (a 123 m path; 36 m x 30 m with two rounds, 235 m, for the same assertions at 1.5 x the CPU)
SMALL = {**BASE, "operation": {"size_m": [28.0, 22.0], "working_width_m": 4.0, "headland_passes": 1, "turn": "u",
                               "turn_radius_m": 2.0, "lines": 2, "follower": "law"}}


@pytest.fixture(scope="module")
def driven():
    spec = op.operation_spec_from_dict(SMALL)
    return spec, op.run_season(spec, None, through_files=False)


def test_small_operation_driven_every_turn(driven):
    spec, res = driven
    s = res.summary
    assert s["complete"], s["error"]
    assert s["turns_driven"] == spec.operations[0][1].turns >= 1 + 4 * 0  # the one U-turn between the 2 lines
    assert s["turns_lifted"] == 0
    assert 0 < s["trafficked_fraction"] < 1
    assert s["headland_trafficked_fraction"] > s["infield_trafficked_fraction"]
    assert s["energy_sprockets_J"] > 0 and s["distance_m"] > 0.9 * spec.operations[0][1].path.length_m
    # measured 0.045 m here (20 m lines, each starting with a turn's exit; 0.045 m too on 36 m x 30 m with two
    # headland rounds); before the yaw law's gains were scaled by the soil's steering stiffness and its
    # integral held in N m: 0.127 m
    assert s["rms_lateral_error_lines_m"] < 0.06


def test_trafficked_share_against_independent_rasters(driven):
    spec, res = driven
    plan, prm = spec.operations[0][1], spec.operations[0][2].params
    got = res.summary["trafficked_fraction"]  # the engine's record: the cells it stressed
    tr = res.operations[0].trajectory
    drv = op.footprint_mask(tr[:, 1], tr[:, 2], tr[:, 3], prm, res.counts.shape, 0.1)
    # the raster of the driven poses (every 0.1 s): within 1 % (measured 0.2524 against 0.2513)
    assert abs(got - drv.mean()) <= 0.01 * got, (got, drv.mean())
    p = plan.path
    end = int(np.nonzero(p.segment == -1)[0][0]) + 1
    planned = op.footprint_mask(p.x[:end], p.y[:end], p.psi[:end], prm, res.counts.shape, 0.1)
    # the raster of the plan: NOT within 1 % (measured 0.233 against 0.252): the driven path weaves
    # about the plan (RMS 0.2-0.3 m), which widens the trafficked band; kept as a bound, not the target
    assert abs(got - planned.mean()) <= 0.25 * planned.mean(), (got, planned.mean())


@pytest.mark.slow  # a two-operation season driven twice (about 40 s; make test-slow)
def test_field_persists_bit_for_bit_through_save_and_load(tmp_path):
    # on a 20 m x 16 m field (one headland round and one line: a 61 m path per operation, half SMALL's):
    # what is tested is the field's persistence, not the driving
    two = {**SMALL, "operation": {**SMALL["operation"], "size_m": [20.0, 16.0]},
           "season": {"operations": [{"name": "a", "lines": 1},
                                     {"name": "b", "lines": 1, "tracks": "random", "seed": 3}]}}
    spec = op.operation_spec_from_dict(two)
    mem = op.run_season(spec, None, through_files=False, figures=False)
    disk = op.run_season(spec, tmp_path / "s", through_files=True, figures=False)
    assert mem.summary["complete"] and disk.summary["complete"]
    for name, a in mem.terrain.arrays().items():
        assert np.array_equal(a, disk.terrain.arrays()[name]), name
    assert np.array_equal(mem.counts, disk.counts)
    assert (tmp_path / "s" / "summary.json").is_file()
    page = (tmp_path / "s" / "report.html").read_text()  # each operation's figures side by side
    assert "<h2>Operations</h2>" in page and "2 operation(s)" in page
    assert dataclasses.is_dataclass(spec.base)


@pytest.mark.slow
# on the clay (the built-in's own soil) the same target is checked on the same run, to the last bit, in
# tests/test_region_check.py::test_fast_agrees_with_full_on_operation_small (one run of it, not two)
@pytest.mark.parametrize("soil", ["sandy_loam_15"])
def test_operation_small_meets_the_tracking_target(soil):
    """The built-in operation on the sandy loam (it once failed at t = 222 s: the braked inner track's
    stick-slip in a U-turn and the line's speed asked for at once at the exit; docs/studies.md): the issue's
    target, RMS lateral error <= 5 cm on the lines, with one vehicle step per macro step."""
    # the law (the default follower, the MPC, tracks closer: test_the_mpc_drives_a_small_operation_on_clay)
    spec = op.load_operation_spec("operation_small", [f"soil.preset=\"{soil}\"", "operation.follower=\"law\""])
    res = op.run_season(spec, None, through_files=False, figures=False)
    s = res.summary
    assert s["complete"], s["error"]
    assert s["turns_driven"] == spec.operations[0][1].turns == 2 and s["turns_lifted"] == 0
    # measured 0.033 / 0.026 m (max 0.13 / 0.08 m), clay / sandy loam; before the stiffness-scaled yaw law
    # 0.090 / 0.111 m (max 0.27 / 0.29 m)
    assert s["rms_lateral_error_lines_m"] <= 0.05
    assert s["max_lateral_error_lines_m"] < 0.2


def test_pass_counts_and_first_contact_times():
    """count_passes_and_times against a hand case: a track parked over cells for 2 s, moved off for
    2 s (more than PASS_GAP_S) and back is two passes there; the first contact is when it arrived."""
    traj = [(0.1 * k, 10.0, 10.0, 0.0) for k in range(20)] + [(2.0 + 0.1 * k, 30.0, 10.0, 0.0) for k in range(20)] \
        + [(4.0 + 0.1 * k, 10.0, 10.0, 0.0) for k in range(5)]
    counts, first = op.count_passes_and_times(np.array(traj), PARAMS, (400, 200), 0.1)
    left_track = (100, 107)  # x = 10 m, y = 10 + 0.75 m: the left track's centre cell
    assert counts[left_track] == 2 and first[left_track] == 0.0
    assert counts[300, 107] == 1 and abs(first[300, 107] - 2.0) < 1e-6
    assert counts[200, 107] == 0 and np.isinf(first[200, 107])
    assert np.array_equal(counts, op.count_passes(np.array(traj), PARAMS, (400, 200), 0.1))
    # the footprint of a pose is the independent raster's
    assert np.array_equal(first < 1.0, op.footprint_mask(np.array([10.0]), np.array([10.0]), np.array([0.0]),
                                                        PARAMS, (400, 200), 0.1))


def test_operation_gif_reveals_the_field_over_time():
    from PIL import Image

    from symtrack.studies import field_plots

    z = np.zeros((200, 100))
    z[50:150, 40:60] = 0.01
    first = np.full((200, 100), np.inf, dtype=np.float32)
    first[50:150, 40:60] = np.linspace(0.0, 10.0, 100)[:, None]
    traj = np.array([(t, 5.0 + t, 5.0, 0.0) for t in np.linspace(0.0, 10.0, 11)])
    gif = field_plots.operation_gif(z, first, traj, (0.0, 20.0, 0.0, 10.0), "t", frames=5, blocks=100)
    im = Image.open(__import__("io").BytesIO(gif))
    assert im.n_frames == 5
    grey = []
    for k in range(5):
        im.seek(k)
        a = np.asarray(im.convert("RGB"))[22:]
        grey.append(int(np.all(a == 225, axis=2).sum()))
    assert all(g1 < g0 for g0, g1 in zip(grey, grey[1:], strict=False))  # more of the field shown each frame


@pytest.mark.slow
def test_season_4ha_reduced_writes_its_summary_and_animation(tmp_path):
    """The built-in season on a 56 m x 80 m field (the 4 ha run takes about 5 minutes: docs/studies.md):
    every operation complete, every turn driven, the summary's keys, the GIF's frames. 56 m along the lines
    is the shortest field on which the 24 m sprayer still turns (two headland rounds of the 8 m machines
    and one of the sprayer); the first two lines of each operation, one turn each (all lines: 5, 5, 1 and 4
    turns, 950 s of simulated driving). Driven by the path-following law, not the season's MPC: the season
    is what is tested here (the MPC's solves were 40 % of the test's CPU; the MPC drives an operation in
    test_the_mpc_drives_a_small_operation_on_clay). On 0.2 m cells (the season's own are 0.1 m): a quarter of
    the cells under the tracks, the terrain engine's share of the test's CPU about a third less (35.6 -> 25.2 s
    of CPU for the season)."""
    from PIL import Image

    spec = op.load_operation_spec("season_4ha", ["operation.size_m=[56.0, 80.0]", "operation.follower=\"law\"",
                                                 "operation.lines=2", "operation.cell_m=0.2"])
    assert all(op.follower_of(o[0], o[1]) == "law" for o in spec.operations)
    assert all(o[1].turns > 0 for o in spec.operations)
    assert [o[0].name for o in spec.operations] == ["tillage", "drilling", "spraying", "harvest"]
    res = op.run_season(spec, tmp_path / "s")
    s = res.summary
    assert s["complete"], s["error"]
    assert s["turns_driven"] == sum(o[1].turns for o in spec.operations) > 0 and s["turns_lifted"] == 0
    for k in ("trafficked_fraction", "headland_trafficked_fraction"):
        assert 0.0 < s[k] < 1.0
    # the season's union is at least each operation's own share and at most their sum
    own = [o["operation_trafficked_fraction"] for o in s["operations"]]
    assert max(own) <= s["trafficked_fraction"] <= sum(own) + 1e-9
    gif = Image.open(tmp_path / "s" / s["animation_gif"])
    assert gif.n_frames == 60
    assert (tmp_path / "s" / "04_harvest" / "animation.gif").is_file()


# ---- K-turns -------------------------------------------------------------------------------------------
def _turn_groups(plan):
    idx = [i for i, r in enumerate(plan.roles) if r == "turn"]
    return [idx[k:k + 3] for k in range(0, len(idx), 3)]


@pytest.mark.parametrize("R, w", [(3.0, 4.0), (4.0, 4.0), (2.5, 1.0), (6.0, 3.0)])
def test_k_turn_geometry_against_the_closed_form(R, w):
    """Each K-turn: forward, backwards, forward arcs of R, tangent at the cusps (the motion reverses
    along one tangent line), ending on the next line heading back; its reach into the headland (the
    footprint's largest x on the sampled path) is the closed form of k_turn_headland_m."""
    fs = settings(turn="k", turn_radius_m=R, working_width_m=w, headland_passes=int(np.ceil(8.0 / w)), lines=3)
    plan = op.plan_operation(fs)
    p = plan.path
    assert plan.turns == 2 and p.cusps_s.size == 4
    alpha = np.arccos((2 * R - w) / (4 * R))  # cos a = (2R - S) / 4R, independent of the code's degrees
    hl, hw = 1.2, 0.975
    for k, g in enumerate(_turn_groups(plan)):
        assert [p.segments[i].reverse for i in g] == [False, True, False]
        ii = np.nonzero(np.isin(p.segment, g))[0]
        a, b = ii[0], ii[-1] + 1
        # it ends on the next line, heading the other way, where that line starts (x of the last line's end)
        assert abs(p.y[b] - plan.line_y_m[k + 1]) < 1e-9 and abs(p.x[b] - p.x[a]) < 1e-9
        assert abs(np.cos(p.psi[b] - p.psi[a]) + 1) < 1e-12
        sgn = np.sign(np.cos(p.psi[a]))
        # the cusps: tangent (heading continuous, the displacement reverses along it) at x0 + R sin a
        for c in p.cusps_s[2 * k:2 * k + 2]:
            j = int(np.searchsorted(p.s, c))
            before, after = np.array([p.x[j] - p.x[j - 1], p.y[j] - p.y[j - 1]]), \
                np.array([p.x[j + 1] - p.x[j], p.y[j + 1] - p.y[j]])
            cosang = before @ after / np.linalg.norm(before) / np.linalg.norm(after)
            assert cosang < -0.999, cosang
            assert abs(sgn * (p.x[j] - p.x[a]) - R * np.sin(alpha)) < 1e-6
        ext = hl * np.abs(np.cos(p.psi[a:b + 1])) + hw * np.abs(np.sin(p.psi[a:b + 1]))
        reach = np.max(sgn * (p.x[a:b + 1] - p.x[a]) + ext)
        assert abs(reach - op.k_turn_headland_m(w, R, hl, hw)) < 2e-4, (reach, op.k_turn_headland_m(w, R, hl, hw))


def test_k_turn_refused_when_it_does_not_fit_the_headland():
    # R = 4 m, lines 4 m apart: the turn reaches 4.40 m (footprint and padding included) beyond a 4 m headland
    doc = {**BASE, "operation": {"size_m": [60.0, 48.0], "working_width_m": 4.0, "headland_passes": 1, "turn": "k",
                                 "turn_radius_m": 4.0, "lines": 2}}
    with pytest.raises(ScenarioError, match=r"operation.turn = \"k\".*allowed range of operation.turn_radius_m is "
                                            r"\(2, ([0-9.]+)\] m here, or operation.headland_passes >= 2") as err:
        op.operation_spec_from_dict(doc)
    r_max = float(err.value.args[0].split("(2, ")[1].split("]")[0])
    room = padding_m(0.1) + 0.1
    # the largest radius that fits: its closed-form reach is the headland (to the 3 digits the message gives)
    assert abs(op.k_turn_headland_m(4.0, r_max, 1.2, 0.975) + room - 4.0) < 5e-3
    doc["operation"]["turn_radius_m"] = r_max - 0.01
    op.operation_spec_from_dict(doc)  # and fits
    with pytest.raises(ScenarioError, match="a K-turn needs a spacing below 2 R"):
        op.plan_operation(settings(turn="k", turn_radius_m=2.0))


@pytest.mark.slow  # one K-turn driven (about 35 s)
def test_k_turn_driven_on_clay():
    doc = {**BASE, "operation": {"size_m": [36.0, 30.0], "working_width_m": 4.0, "headland_passes": 2, "turn": "k",
                                 "turn_radius_m": 4.0, "lines": 2}}
    spec = op.operation_spec_from_dict(doc)
    plan = spec.operations[0][1]
    res = op.run_season(spec, None, through_files=False, figures=False)
    s = res.summary
    assert s["complete"], s["error"]
    assert s["turns_driven"] == 1 and s["turns_lifted"] == 0
    # it drove backwards over the reverse arc (the poses' displacement against the heading), about its length
    tr = res.operations[0].trajectory
    d = np.diff(tr[:, 1:3], axis=0)
    along = d[:, 0] * np.cos(tr[:-1, 3]) + d[:, 1] * np.sin(tr[:-1, 3])
    planned = plan.path.cusps_s[1] - plan.path.cusps_s[0]
    back = -along[along < 0].sum()
    assert 0.8 * planned < back < 1.5 * planned, (back, planned)
    turn = res.operations[0].log
    turn = turn[turn[:, 4] == 1]
    # measured 0.033 m RMS, at most 0.09 m in the turn (0.052 / 0.15 m before the stiffness-scaled yaw law)
    assert np.sqrt(np.mean(turn[:, 2] ** 2)) < 0.06 and np.abs(turn[:, 2]).max() < 0.2


def test_the_default_follower_is_the_mpc_and_the_law_on_k_turns():
    fs = op.parse_operation({"size_m": [60.0, 48.0], "working_width_m": 4.0, "turn_radius_m": 1.5, "lines": 2})
    assert fs.follower == "auto" and op.follower_of(fs, op.plan_operation(fs)) == "rti"
    fk = op.parse_operation({"size_m": [60.0, 48.0], "working_width_m": 4.0, "turn": "k", "turn_radius_m": 4.0,
                             "lines": 2})
    plan = op.plan_operation(fk)
    assert plan.path.cusps_s.size and op.follower_of(fk, plan) == "law"
    assert op.follower_of(dataclasses.replace(fs, follower="law"), op.plan_operation(fs)) == "law"


def test_the_mpc_follower_refuses_k_turns():
    doc = {**BASE, "operation": {"size_m": [36.0, 30.0], "working_width_m": 4.0, "headland_passes": 2, "turn": "k",
                                 "turn_radius_m": 4.0, "lines": 2, "follower": "rti"}}
    with pytest.raises(ScenarioError, match="operation.follower = \"rti\" with operation.turn = \"k\""):
        op.operation_spec_from_dict(doc)
    with pytest.raises(ScenarioError, match="operation.follower = 'mpc' is not one of auto, law, rti"):
        op.parse_operation({"follower": "mpc"})


@pytest.mark.slow  # the MPC's build (cached) and one small operation (about 30 s)
def test_the_mpc_drives_a_small_operation_on_clay():
    # on SMALL (73 s of driving, 728 solves): the MPC's build is most of the cost, not the driving
    spec = op.operation_spec_from_dict({**SMALL, "operation": {**SMALL["operation"], "follower": "auto"}})
    assert op.follower_of(spec.operations[0][0], spec.operations[0][1]) == "rti"  # the default: the MPC
    res = op.run_season(spec, None, through_files=False, figures=False)
    s, o = res.summary, res.operations[0].figures
    assert s["complete"], s["error"]
    assert s["turns_driven"] == spec.operations[0][1].turns and s["turns_lifted"] == 0
    # one solve per 0.1 s control sample, all of the way (728 of 72.8 s here)
    assert o["follower"] == "rti" and o["solves"] >= 0.99 * o["sim_time_s"] / 0.1
    # measured 0.012 m on the lines, 0.012 m in the turns, 0 failed of 728 (36 m x 30 m with two headland
    # rounds: 0.012 / 0.012 m, 0 failed of 1351)
    assert s["rms_lateral_error_lines_m"] < 0.03 and s["rms_lateral_error_turns_m"] < 0.03
    assert o["failed_solves"] == 0
    # held over the engine's 10 ms macro steps, one vehicle step each at least (not one per 0.1 s sample)
    assert o["vehicle_steps"] >= 0.99 * o["sim_time_s"] / 0.01


# ---- polygon fields ------------------------------------------------------------------------------------
POLYGON = [[2.0, 2.0], [56.0, 5.0], [58.0, 40.0], [30.0, 47.0], [3.0, 38.0], [2.0, 2.0]]


def _write_geojson(path, ring, **extra):
    import json

    geom = {"type": "Polygon", "coordinates": [ring], **extra}
    path.write_text(json.dumps({"type": "Feature", "properties": {}, "geometry": geom}))
    return str(path)


def polygon_settings(tmp_path, **kw):
    f = _write_geojson(tmp_path / "field.geojson", POLYGON)
    return op.parse_operation({"size_m": [60.0, 50.0], "boundary_file": f, "working_width_m": 4.0,
                               "headland_passes": 2, "turn": "u", "turn_radius_m": 2.0, **kw})


def _shoelace(ring):
    x, y = np.array(ring)[:-1].T
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_polygon_plan_covers_the_field_within_one_working_width(tmp_path):
    for w, n in ((4.0, 2), (3.0, 2), (6.0, 1)):
        fs = polygon_settings(tmp_path, working_width_m=w, headland_passes=n, turn="auto",
                              turn_radius_m=min(0.5 * w, 3.0))
        plan = op.plan_operation(fs)
        cov = op.swath_mask(plan, (600, 500), 0.1)
        field = op.field_mask(fs, (600, 500), 0.1)
        area = _shoelace(POLYGON)  # 2151.5 m^2
        assert abs(field.sum() * 0.01 - area) < 0.005 * area  # the field's cells are its area
        covered = (cov & field).sum() * 0.01
        # within one working width along the field's length (56 m): the unworked rest is the
        # rounded corners and the slivers where the lines meet slanted in-field edges
        assert area - covered <= w * 56.0, (w, area, covered)
        assert (cov & ~field).sum() * 0.01 <= 0.01 * area  # the swath stays in the field


def _independent_footprint_raster(x, y, psi, params, shape, cell):
    """Cells whose square overlaps a track's contact rectangle, by another method than
    footprint_mask's separating axes: the rectangle grown by the cell's square (their Minkowski sum,
    the convex hull of the 16 vertex sums) tested on the cell centres by matplotlib's point-in-polygon."""
    from matplotlib.path import Path as MPath
    from scipy.spatial import ConvexHull

    mask = np.zeros(shape, dtype=bool)
    hl, hb, off = 0.5 * params["contact_length_m"], 0.5 * params["track_width_m"], 0.5 * params["track_gauge_m"]
    sq = 0.5 * cell * np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]])
    for xk, yk, pk in zip(x, y, psi, strict=True):
        c, s = np.cos(pk), np.sin(pk)
        for lat in (off, -off):
            cx, cy = xk - lat * s, yk + lat * c
            corners = np.array([[cx + a * hl * c - b * hb * s, cy + a * hl * s + b * hb * c]
                                for a in (1, -1) for b in (1, -1)])
            pts = (corners[:, None, :] + sq[None, :, :]).reshape(-1, 2)
            hull = pts[ConvexHull(pts).vertices]
            i0, j0 = np.maximum(np.floor(hull.min(0) / cell).astype(int), 0)
            i1, j1 = np.minimum(np.ceil(hull.max(0) / cell).astype(int) + 1, shape)
            gx, gy = np.meshgrid((np.arange(i0, i1) + 0.5) * cell, (np.arange(j0, j1) + 0.5) * cell, indexing="ij")
            inside = MPath(hull).contains_points(np.column_stack([gx.ravel(), gy.ravel()]))
            mask[i0:i1, j0:j1] |= inside.reshape(gx.shape)
    return mask


def test_polygon_plan_trafficked_share_against_an_independent_raster(tmp_path):
    fs = polygon_settings(tmp_path)
    plan = op.plan_operation(fs)
    p = plan.path
    end = int(np.nonzero(p.segment == -1)[0][0]) + 1
    x, y, psi = p.x[:end:2], p.y[:end:2], p.psi[:end:2]  # every 0.1 m
    shape = (600, 500)
    field = op.field_mask(fs, shape, 0.1)
    ours = op.footprint_mask(x, y, psi, PARAMS, shape, 0.1)
    other = _independent_footprint_raster(x, y, psi, PARAMS, shape, 0.1)
    a, b = (ours & field).sum() / field.sum(), (other & field).sum() / field.sum()
    assert 0.2 < a < 0.8
    assert abs(a - b) <= 0.01 * b, (a, b)  # measured 0.33173 both: the same cells
    # and the plan's shares through field_shares (in-field and headland apart) are those of the raster
    sh = op.field_shares(ours, ours.astype(np.uint16), fs)
    assert sh["trafficked_fraction"] == pytest.approx(a)
    assert sh["field_area_m2"] == pytest.approx(field.sum() * 0.01)


def test_polygon_boundary_csv_is_the_geojson(tmp_path):
    csv_file = tmp_path / "field.csv"
    csv_file.write_text("x_m,y_m\n" + "\n".join(f"{x},{y}" for x, y in POLYGON) + "\n")
    a = op.plan_operation(polygon_settings(tmp_path))
    b = op.plan_operation(polygon_settings(tmp_path, boundary_file=str(csv_file)))
    assert np.array_equal(a.path.x, b.path.x) and np.array_equal(a.path.y, b.path.y)
    # clockwise is the same field
    _write_geojson(tmp_path / "cw.geojson", POLYGON[::-1])
    c = op.plan_operation(polygon_settings(tmp_path, boundary_file=str(tmp_path / "cw.geojson")))
    assert np.allclose(a.path.x, c.path.x) and np.allclose(a.path.y, c.path.y)


def test_bad_boundaries_are_refused_naming_the_key(tmp_path):
    def refused(ring, match, name="b.geojson", **kw):
        f = _write_geojson(tmp_path / name, ring, **kw)
        with pytest.raises(ScenarioError, match=r"operation.boundary_file = .*" + match):
            op.parse_operation({"size_m": [60.0, 50.0], "boundary_file": f, "working_width_m": 4.0})

    refused([[2, 2], [50, 2], [2, 40], [50, 40], [2, 2]], "not a simple polygon: edge")  # a bow tie
    refused([[2, 2], [50, 2], [50, 40], [2, 40]], "not closed")
    refused(None, "hole", coordinates=[[[2, 2], [50, 2], [50, 40], [2, 40], [2, 2]], [[5, 5], [6, 5], [6, 6], [5, 5]]])
    refused([[2, 2], [70, 2], [50, 40], [2, 2]], "vertex 1 at \\(70, 2\\) m is outside the grid")
    refused([[2, 2], [5, 2], [5, 5], [2, 5], [2, 2]], "too small for one working width of 4 m")
    refused([[2, 2], [50, 2], [50, 2], [2, 40], [2, 2]], "not a simple polygon: vertex 2 repeats vertex 1")
    (tmp_path / "b.csv").write_text("x,y\n2,2\n")
    with pytest.raises(ScenarioError, match="operation.boundary_file = .*header x_m,y_m"):
        op.parse_operation({"size_m": [60.0, 50.0], "boundary_file": str(tmp_path / "b.csv")})
    with pytest.raises(ScenarioError, match="operation.boundary_file = .*no such file"):
        op.parse_operation({"size_m": [60.0, 50.0], "boundary_file": str(tmp_path / "none.geojson")})
    # a headland too deep for the polygon: named by its own key
    with pytest.raises(ScenarioError, match="operation.headland_passes = 6"):
        op.plan_operation(polygon_settings(tmp_path, headland_passes=6))


@pytest.mark.slow  # a polygon field driven: headland rounds, two lines, one U-turn (about 20 s)
def test_polygon_operation_driven_on_clay(tmp_path):
    ring = [[1.0, 1.0], [38.0, 3.0], [36.5, 31.0], [2.0, 29.0], [1.0, 1.0]]
    f = _write_geojson(tmp_path / "small.geojson", ring)
    doc = {**BASE, "operation": {"size_m": [40.0, 32.0], "boundary_file": f, "working_width_m": 4.0,
                                 "headland_passes": 2, "turn": "u", "turn_radius_m": 2.0, "lines": 2}}
    spec = op.operation_spec_from_dict(doc)
    res = op.run_season(spec, None, through_files=False, figures=False)
    s = res.summary
    assert s["complete"], s["error"]
    assert s["turns_driven"] == 1 and s["outside_field_trafficked_m2"] == 0.0
    assert s["field_area_m2"] == pytest.approx(_shoelace(ring), rel=0.005)
    fs, prm = spec.operations[0][0], spec.operations[0][2].params
    tr = res.operations[0].trajectory
    field = op.field_mask(fs, res.counts.shape, 0.1)
    drv = op.footprint_mask(tr[:, 1], tr[:, 2], tr[:, 3], prm, res.counts.shape, 0.1)
    # the engine's record against the raster of the driven poses, over the polygon's cells (measured 0.3059
    # against 0.3051)
    assert abs(s["trafficked_fraction"] - drv[field].mean()) <= 0.01 * s["trafficked_fraction"]


def test_controlled_turns_cross_the_headland_on_one_lane():
    """turn_lane_m = "auto": the drill's (4 m, radius 1.5 m, headland 8 m) and the sprayer's (12 m,
    radius 4 m, headland 12 m) U-turns cross their headland on the same lane, 6 m = (1 + 1/2) x 4 m
    from the border; the lines run on, unworked, to it."""
    across = []
    for w, n, R in ((4.0, 2, 1.5), (12.0, 1, 4.0)):
        fs = settings(tracks="controlled", lane_spacing_m=4.0, working_width_m=w, headland_passes=n, turn_radius_m=R,
                      turn_lane_m="auto", lines=3)
        plan = op.plan_operation(fs)
        p = plan.path
        turn = op.sample_roles(plan) == 1
        # the across leg: where the turn heads along y, x is the lane's
        leg = turn & (np.abs(np.cos(p.psi)) < 1e-9)
        xs = sorted({round(float(x), 6) for x in p.x[leg]})
        across.append(xs)
        assert xs == ([6.0, 54.0] if w == 4.0 else [54.0]), xs  # (the sprayer's two lines: one turn, east)
        # the worked lines are unchanged; the extension is a line outside the worked range (role 2)
        assert ((op.sample_roles(plan) == 2) & (p.segment >= 0) & (np.abs(p.x - 30) < 30 - fs.headland_m)).sum() == 0
    with pytest.raises(ScenarioError, match="operation.turn_lane_m = 5 is not a headland lane"):
        op.plan_operation(settings(tracks="controlled", lane_spacing_m=4.0, turn_radius_m=1.5, turn_lane_m=5.0))
    with pytest.raises(ScenarioError, match=r"operation.turn_lane_m = 10 is outside the allowed range \(0, 6.5\]"):
        op.plan_operation(settings(tracks="controlled", lane_spacing_m=4.0, turn_radius_m=1.5, turn_lane_m=10.0))
    with pytest.raises(ScenarioError, match="headland lanes are controlled traffic's"):
        op.plan_operation(settings(turn_lane_m="auto"))
