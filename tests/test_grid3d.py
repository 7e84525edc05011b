"""The 3D vehicle on the grid terrain through the terrain engine (issue 22; docs/vehicle3d.md, "The grid
under the 3D vehicle"): the flat virgin field against the homogeneous 3D run (the same law in two places),
the cells' sinkage against the hull's penetration, the subsoil fields, the refusals."""

from __future__ import annotations

import numpy as np
import pytest

import symtrack
from symtrack.simulation.plants import advance_plant, make_plant
from symtrack.simulation.scenario import load_scenario

FIGURES = ("distance_m", "lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm", "sinkage_idler_mm",
           "speed_final_m_s", "shear_driven_max_m", "shear_idle_min_m")


pytestmark = pytest.mark.slow  # the 3D engine's first compile: about 30 s of CPU (more under load)


@pytest.fixture(scope="module")
def flat_runs():
    grid = symtrack.simulate(load_scenario("validation_grid", ["model.vehicle=3d"]))
    homo = symtrack.simulate(load_scenario("validation", ["model.vehicle=3d"]))
    return grid, homo


def test_flat_virgin_field_matches_the_homogeneous_3d_run(flat_runs):
    """One law in two places: on the flat virgin field every validation figure of the grid run is within
    1 % of the homogeneous 3D run's (the hull meets virgin soil along the whole track in both)."""
    grid, homo = flat_runs
    for k in FIGURES:
        a, b = homo.summary[k], grid.summary[k]
        # the sprocket sinkage is the run's largest: the peak after the torque step, where the grid's start
        # (set down in its own static rut) shows: -2.71 % (1.8531 against 1.9047 mm; the peak follows the
        # first swings of the sprocket on the soil's shear, which unloads elastically when they reverse the
        # slip; -1.20 % without the elastic unloading, where this was 2 %; measured again with the unloading
        # rate's bound: -2.71 %); it moves by -4.6 ... +2.9 % under cell refinement (docs/vehicle3d.md,
        # "Accuracy on the grid"), so 3 % for it, 1 % for every other figure
        assert abs(b / a - 1) < (0.03 if k == "sinkage_sprocket_mm" else 0.01), (k, a, b)
    # the grid's own figures: the subsoil stress and the bulk density are filled under the tracks
    s = grid.summary
    assert s["subsoil_loaded_area_m2"] > 30.0 and s["rut_cells"] > 3000
    st = grid.terrain
    touched = st.zmax > 0
    assert np.all(st.sigma_max[touched].max(axis=1) > 0)
    assert np.count_nonzero(st.specific_volume[touched] != st.specific_volume[~touched][:1]) > 0
    # the cells' work is the compaction resistance: positive, below the homogeneous hull's Bekker work at its
    # deepest penetration (as the planar engine's against the planar homogeneous run: docs/vehicle3d.md)
    rc_grid = grid.runs[-1].output("compaction_resistance_left_N")[-1]
    rc_homo = homo.runs[-1].output("compaction_resistance_left_N")[-1]
    assert 0.4 * rc_homo < rc_grid < rc_homo


def test_the_cells_sink_as_deep_as_the_hull_penetrates():
    """The coupling's consistency: under the tracks (cells wholly inside a contact) each cell's sinkage is
    the hull's penetration at that cell within 1 % (the cells integrate their own sinkage under the segment
    pressures; the hull's pressure is the law on the cells' history)."""
    sc = load_scenario("validation_grid", ["model.vehicle=3d"])
    plant = make_plant(sc)
    plant.world.clear()
    plant.start(0.0, 0.0, 0.0, [2000.0, 2000.0])
    # 2 s: the vehicle has left the cells it was set down on (they keep the start's deeper static sinkage)
    x, _ = advance_plant(plant, [2000.0, 2000.0], 2.0, sc.run.output_dt_s)
    X = dict(zip(plant.engine.fns.layout.vehicle_names, x, strict=True))
    P = sc.params
    l, e, h, B = (P[k] for k in ("contact_length_m", "cg_ahead_of_contact_centre_m", "cg_height_m", "track_gauge_m"))
    st = plant.engine.state
    act = st.active_channels()
    c, s = np.cos(X["yaw_rad"]), np.sin(X["yaw_rad"])
    dx, dy = st.ch_cx[act] - X["x_m"], st.ch_cy[act] - X["y_m"]
    xb, yb = c * dx + s * dy, -s * dx + c * dy
    # cells wholly inside a contact, between the first and the last segment centre (beyond them the
    # pieces are constant: the front's entering cells take the first segment's pressure)
    ds = l / sc.model.contact_segments
    s_track = (l / 2 - e) - xb
    full = (st.ch_g[act, 1] + st.ch_g[act, 2] > 0.999) & (s_track > ds / 2) & (s_track < l - ds / 2)
    # the track's ground line below the hull at the cell (small angles: the pose's own rotation, first order)
    z_line = X["z_m"] - h + xb * np.sin(X["pitch_rad"]) + np.sign(yb) * B / 2 * np.sin(X["roll_rad"])
    pen = -z_line
    z = st.ch_z[act]
    assert full.sum() > 100
    assert np.all(np.abs(z[full] / pen[full] - 1) < 0.01), np.max(np.abs(z[full] / pen[full] - 1))


def test_a_second_pass_rides_in_the_ruts_of_the_first():
    """Two passes on one line (issue 22's second pass): pass 2 rides on the ruts of pass 1 and reloads
    the cells to the pressures they carried, so the rut deepens by the cycle law's closed form
    rut_1 (2^beta - 1) (docs/model.md, cell.rut_after_cycles; 20 % allowed), the hull sits lower at every
    point of the line, its front (the lightest segment) below the first rut's depth, and the cells' work
    (the compaction resistance) falls. Not the heights-only soil's 'lower by the whole rut': the soil
    remembers its compaction (docs/vehicle3d.md, measured: the hull 0.22 mm lower on a 1.0 mm rut)."""
    sets = ["model.vehicle=3d", "terrain.passes=2", "terrain.size_m=[30.0, 8.0]", "run.stop_after_distance_m=15.0"]
    sc = load_scenario("multipass", sets)
    r = symtrack.simulate(sc)
    p1, p2 = r.pass_summaries
    beta = sc.params["repeated_loading_exponent"]
    deepening = p2["new_sinkage_mean_mm"] / p1["rut_mean_depth_mm"]
    assert abs(deepening / (2**beta - 1) - 1) < 0.2, (deepening, 2**beta - 1)
    run1, run2 = r.runs
    xs = np.arange(4.0, 12.5, 0.5)
    drop = np.interp(xs, run1.state("x_m"), run1.state("z_m")) - np.interp(xs, run2.state("x_m"), run2.state("z_m"))
    rut1 = 1e-3 * p1["rut_max_depth_mm"]
    assert np.all(drop > 1e-3 * p2["new_sinkage_mean_mm"]) and np.all(drop < rut1), (drop, rut1)
    i1, i2 = (np.searchsorted(run.state("x_m"), 8.0) for run in (run1, run2))
    idler1 = run1.output("sinkage_idler_left_m")[i1]
    idler2 = run2.output("sinkage_idler_left_m")[i2]
    assert idler1 < rut1 < idler2, (idler1, rut1, idler2)
    assert p2["compaction_resistance_mean_N"] < 0.5 * p1["compaction_resistance_mean_N"]
    # the planar engine on the same two passes (validated against IDAS, docs/terrain.md): the same rut and
    # deepening (measured: -1.5 % and +2 %) and second-pass resistance (+6 %)
    q1, q2 = symtrack.simulate(load_scenario("multipass", ["model.vehicle=planar", *sets[1:]])).pass_summaries
    assert p1["rut_mean_depth_mm"] == pytest.approx(q1["rut_mean_depth_mm"], rel=0.05)
    assert deepening == pytest.approx(q2["new_sinkage_mean_mm"] / q1["rut_mean_depth_mm"], rel=0.05)
    assert p2["compaction_resistance_mean_N"] == pytest.approx(q2["compaction_resistance_mean_N"], rel=0.15)



def test_bench_rows_of_the_3d_vehicle_on_the_grid():
    """symtrack bench's validation_grid rows (symtrack.bench.vehicle3d.grid_rows) in quick mode: one run
    per vehicle on the terrain engine; the ratio row carries the CPU ratio and the 3D real-time factor
    against the issue's targets (the figures: docs/vehicle3d.md)."""
    from symtrack.bench import vehicle3d

    rows = vehicle3d.grid_rows(quick=True)
    assert [r["case"] for r in rows] == ["vehicle = planar", "vehicle = 3d", "3d / planar"]
    planar, solid = rows[0]["figures"], rows[1]["figures"]
    assert planar["yaw_final_deg"] == pytest.approx(0.4046, rel=1e-3)  # the planar engine's validation
    for k in ("yaw_final_deg", "lateral_deviation_m"):  # the 3D model's own +1.7 % at 8 segments
        assert solid[k] == pytest.approx(planar[k], rel=0.025), k
    ratio = rows[2]
    assert ratio["cpu_ratio"] > 0 and ratio["real_time_factor_cpu_3d"] > 0
    assert ratio["target_ratio"] == 1.5 and ratio["target_real_time_factor"] == 100.0


def test_the_segment_sums_against_numpy():
    """grid_engine.c's seg_sums (the cells -> vehicle coupling) against the same rule written here in numpy
    from the channel tables: per track and segment the load fraction times the hat function about the
    segment centres of the cell's position along the track, then the weighted z and soil history."""
    from symtrack.native.grid_engine_model import SEG_FIELDS

    sc = load_scenario("validation_grid", ["model.vehicle=3d"])
    plant = make_plant(sc)
    plant.world.clear()
    plant.start(0.0, 0.0, 0.0, [2000.0, 2000.0])
    advance_plant(plant, [2000.0, 1000.0], 2.5, sc.run.output_dt_s)  # turning: the pose's yaw in the weights
    eng = plant.engine
    st, n = eng.state, eng.fns.n_seg
    eng.kernel.sums()
    S = st.pv[-2 * n * len(SEG_FIELDS):].reshape(2, n, len(SEG_FIELDS))
    act = st.active_channels()
    l, e = st.geo[0], st.geo[3]
    a = st.a
    s = (l / 2 - e) - (a[2] * (st.ch_cx[act] - a[0]) + a[3] * (st.ch_cy[act] - a[1]))
    u = s * n / l - 0.5
    centres = np.arange(n)
    hat = np.clip(1 - np.abs(u[:, None] - centres[None, :]), 0, 1)
    hat[:, 0] = np.where(u < 0, 1.0, hat[:, 0])
    hat[:, -1] = np.where(u > n - 1, 1.0, hat[:, -1])
    q = np.stack([np.ones(act.size), st.ch_z[act], st.ch_zmax[act], st.ch_pmax[act], st.ch_zoff[act],
                  st.ch_delta[act], st.ch_dc[act]], axis=1)
    for t in range(2):
        w = st.ch_g[act, 1 + t][:, None] * hat
        ref = w.T @ q
        assert ref[:, 0].sum() > 10  # cells under the track
        np.testing.assert_allclose(S[t], ref, rtol=1e-12, atol=1e-18)


def test_the_subsoil_s_fitted_line_against_the_segment_pieces():
    """The subsoil stress takes each track's least-squares line through the segment pressures (subsoil.h's
    strip tables are for a linear line): at 2 s into validation_grid its vertical stress below the left
    track's centre line is the pieces' within 3 % at 0.1 m and 2 % at 0.3 m (Froehlich's point load
    summed over both contacts by the same quadrature for both; measured 2.2 % and 1.6 %, docs/vehicle3d.md),
    and the line carries the pieces' load."""
    from symtrack.soil.subsoil import frohlich_point

    sc = load_scenario("validation_grid", ["model.vehicle=3d"])
    plant = make_plant(sc)
    plant.world.clear()
    plant.start(0.0, 0.0, 0.0, [2000.0, 2000.0])
    advance_plant(plant, [2000.0, 2000.0], 2.0, sc.run.output_dt_s)
    st, n = plant.engine.state, plant.engine.fns.n_seg
    a = st.a.copy()
    P = sc.params
    l, b, B, e = (P[k] for k in ("contact_length_m", "track_width_m", "track_gauge_m", "cg_ahead_of_contact_centre_m"))
    centres = (np.arange(n) + 0.5) * l / n
    ss = (np.arange(400) + 0.5) * l / 400
    tt = (np.arange(40) + 0.5) * b / 40 - b / 2
    X, Y, c, s = a[:4]

    def sigma(p_of, px, py, depth):
        out = 0.0
        for side, sg in ((0, 1.0), (1, -1.0)):
            bx = (l / 2 - e) - ss[:, None] + 0.0 * tt[None, :]
            by = sg * B / 2 + tt[None, :] + 0.0 * ss[:, None]
            Q = (p_of(side, ss) * l / 400)[:, None] * (b / 40)
            r = np.hypot(X + c * bx - s * by - px, Y + s * bx + c * by - py)
            out += np.sum(frohlich_point(Q, r, depth, P["stress_concentration_factor"]))
        return out

    def pieces(side, x):
        return np.interp(x, centres, a[8 + side * n:8 + (side + 1) * n])

    def line(side, x):
        return np.maximum(0.0, a[4 + 2 * side] + a[5 + 2 * side] * x)

    assert np.sum(line(0, centres)) == pytest.approx(np.sum(a[8:8 + n]), rel=1e-12)  # the load kept
    for depth, tol in ((0.1, 0.03), (0.3, 0.02)):
        for sp in np.linspace(0.05, l - 0.05, 12):
            bx, by = (l / 2 - e) - sp, B / 2
            px, py = X + c * bx - s * by, Y + s * bx + c * by
            ref = sigma(pieces, px, py, depth)
            assert abs(sigma(line, px, py, depth) / ref - 1) < tol, (depth, sp)


def test_example_second_pass_3d_runs():
    """examples/second_pass_3d.py on a 20 m x 8 m field, 8 m a pass: the hull of pass 2 rides lower than
    pass 1's over the middle of the line, by more than its new sinkage and less than the first rut; the
    rut deepens by the cycle law's closed form (20 %); the attitude flattens; the cells' work falls."""
    import runpy

    ns = runpy.run_path("examples/second_pass_3d.py")
    out = ns["main"](["--size-m", "20", "8", "--stop-m", "8"])
    lo, hi = out["hull_drop_mm"]
    assert out["new_sinkage_pass_2_mean_mm"] < lo and hi < out["rut_after_pass_1_max_mm"], out
    assert out["deepening"] == pytest.approx(out["deepening_closed_form"], rel=0.2)
    assert 0 < out["pitch_pass_2_mrad"] < out["pitch_pass_1_mrad"]
    assert out["compaction_resistance_pass_2_N"] < 0.5 * out["compaction_resistance_pass_1_N"]


def test_an_elevation_raster_of_a_plane_gives_the_analytic_side_slope(tmp_path):
    """The 3D vehicle on the grid over an elevation raster (the hull's ground the raster's bilinear
    surface, CasADi's B-spline of degree 1; the cells' elevations sampled from the same): a raster of
    the 5 deg side slope's plane at 0.1 m pixels drives as `slope_y_deg = 5` does, every state within
    1e-5 over 3 s of 2000 N m on both sprockets (measured: 3e-6 rad/s on the sprockets, 8e-7 m on x,
    4e-9 on z; the interpolation of a plane is exact, the rest is rounding), and the field's
    elevations are the analytic surface's."""
    import math

    from symtrack.simulation.scenario import scenario_from_dict

    t, px = 5.0, 0.1
    ys = -5.0 + (np.arange(100) + 0.5) * px
    f = tmp_path / "plane.npy"
    np.save(f, np.tile(ys * math.tan(math.radians(t)), (200, 1)))

    def doc(surface):
        return {"run": {"integrator": "grid_fast", "output_dt_s": 0.01, "duration_s": 3.0},
                "model": {"vehicle": "3d"}, "vehicle": {"preset": "reference_crawler"},
                "soil": {"preset": "clayey_soil_thailand_38"},
                "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0}],
                "terrain": {"size_m": [20.0, 10.0], "cell_m": 0.1, "origin_m": [-5.0, -5.0], "surface": surface}}

    ana = symtrack.simulate(scenario_from_dict(doc({"slope_y_deg": t})))
    ras = symtrack.simulate(scenario_from_dict(doc({"elevation_file": str(f), "elevation_cell_m": px})))
    a, b = np.asarray(ana.runs[-1].X), np.asarray(ras.runs[-1].X)
    assert a.shape == b.shape and a.shape[0] > 250
    assert np.abs(a - b).max() < 1e-5
    assert ras.summary["distance_m"] > 5.0  # it drove
    np.testing.assert_allclose(ras.terrain.elevation, ana.terrain.elevation, atol=1e-12)
