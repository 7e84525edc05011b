"""The terrain engine (run.integrator = "grid_fast", symtrack/integrators/engine/): against IDAS on a
small field, one cell against a tight reference under step refinement, compiled == interpreted
(the oracle of tests/engine_oracle.py),
the pool against every cell holding its own channel and against brute force, bit-exact
persistence, and the collision error."""

import copy
import dataclasses
import math
import types

import numpy as np
import pytest
from conftest import two_passes_against_a_continued_pass
from engine_oracle import PyKernel, ringing
from scipy.integrate import solve_ivp
from small_field import small_field

from symtrack.bench.terrain import brute_force_run, pool_run
from symtrack.foundations.errors import ScenarioError, SimulationError
from symtrack.integrators import engine, grid_idas
from symtrack.integrators.settings import STEADY_METHODS
from symtrack.native.grid_engine_model import build_engine_functions
from symtrack.simulation import loop
from symtrack.simulation.plants import EnginePlant, make_plant
from symtrack.simulation.scenario import load_scenario, scenario_from_dict
from symtrack.soil.law import BekkerWong
from symtrack.terrain import query
from symtrack.toolchain import find_compiler

# A 12 m x 4 m field at 0.25 m (768 cells, M = 18): from rest, both sprockets at 2000 N m, then the
# left one idle at 0.3 s: the vehicle accelerates and begins to turn.
SMALL = small_field("engine_small", torque=[{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0},
                                             {"t_s": 0.3, "left_N_m": 0.0, "right_N_m": 2000.0}])

# Stated tolerances against IDAS (reltol 1e-7) on SMALL, default engine settings (measured:
# pose 0.2 mm, speeds 6e-4 relative, sinkage before the lift 1.3 %, after it 1.1 %): the engine's
# 10 ms staggered step against IDAS's error control.
POSE_TOL_M = 1e-3
RATE_TOL = 3e-3  # velocities, speeds, shears, torques: relative to 1 + abs(value)
SINKAGE_REL_TOL = 0.03


def _scenario(integrator="grid_fast", **run):
    d = copy.deepcopy(SMALL)
    d["run"]["integrator"] = integrator
    d["run"].update(run)
    return scenario_from_dict(d)


def _engine_run(sc, settings=None, world=None, kernel=None, mean_stress=False):
    plant = make_plant(sc)
    if settings is not None or kernel is not None:
        plant = EnginePlant(plant.world, engine.TerrainEngine(plant.world, settings, kernel=kernel))
    plant.engine.state.compute_mean_stress = mean_stress  # (off by default: nothing uses it)
    res = loop.run(sc, plant)
    return plant.world, res


@pytest.fixture(scope="module")
def idas():
    sc = _scenario("idas", reltol=1e-7, abstol=1e-9)
    # the IDAS system without CasADi's cse (the same numbers to the last bit: grid_idas.CSE): for 0.6 s
    # of steps the cse costs more than it saves
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(grid_idas, "CSE", False)
        return pool_run(sc, SMALL["run"]["duration_s"])


@pytest.fixture(scope="module")
def fast():
    return _engine_run(_scenario())


def test_engine_matches_idas_on_a_small_field(idas, fast):
    (wi, ri), (wf, rf) = idas, fast
    assert rf.stats["engine_compiled"] == (find_compiler() is not None)
    assert rf.t.shape == ri.t.shape and np.allclose(rf.t, ri.t)
    assert rf.X[-1, 0] - rf.X[0, 0] > 0.1  # it did drive
    assert np.max(np.abs(rf.X[:, :3] - ri.X[:, :3])) < POSE_TOL_M
    assert np.max(np.abs(rf.X[:, 3:12] - ri.X[:, 3:12]) / (1 + np.abs(ri.X[:, 3:12]))) < RATE_TOL
    for zf, zi in ((wf.z_at_pass_end, wi.z_at_pass_end), (wf.storage.z, wi.storage.z)):
        assert zi.max() > 5e-4
        assert np.max(np.abs(zf - zi)) < SINKAGE_REL_TOL * zi.max()
    assert rf.output_names == ri.output_names
    assert rf.terrain["terrain_peak_active_cells"] > 0


def _one_cell():
    """validation_grid's cell: (the engine's interpreted kernel, its law (z, z_max, p_max) -> (p, dp),
    areal mass, damping)."""
    sc = load_scenario("validation_grid")
    P = sc.params
    f = build_engine_functions(sc.model, P, 1)
    m, c = P["cell_areal_mass_kg_per_m2"], P["cell_damping_Pa_s_per_m"]

    row = f.law_row(P)

    def law(z, zm, pm):
        return tuple(float(v) for v in f.law(z, [zm, pm, 0, 0, 0], row))
    st = types.SimpleNamespace(areal_mass=m, damping=c, stats={"n_newton": 0, "n_cell_stages": 0},
                               soil_law=f.law_table([P]))
    return PyKernel(f, st), law, m, c


def _radau_step(law, load, m, c, t0, h, y, zm, pm):
    """The reference over one macro step: Radau at rtol 1e-10 on (z, dz/dt, rectified work
    int p max(dz/dt, 0) dt), the history (zm, pm) held; then the history updated. Returns
    (z, v, work over the step, zm, pm)."""
    def rhs(t, yy):
        pr = law(yy[0], zm, pm)[0]
        return [yy[1], (load(t) - pr - c * yy[1]) / m, pr * max(yy[1], 0.0)]
    sol = solve_ivp(rhs, (t0, t0 + h), [y[0], y[1], 0.0], method="Radau", rtol=1e-10, atol=1e-14, max_step=h / 50)
    z, v, w = sol.y[:, -1]
    pr = law(z, zm, pm)[0]
    return z, v, w, max(zm, z), (max(pm, pr) if z >= zm else pm)


def _one_cell_reference_and_engine(substep_counts, h=0.01, t_end=0.9):
    """One cell under a track passing at 3 m/s (the load ramps up over a cell, grows along the
    track, ramps down): the engine's cell step (exact load at its substep ends) at each of
    ``substep_counts`` against Radau at rtol 1e-10, the history updated after every macro step in
    both. Returns ({substeps: the engine's sinkages}, the reference's); the reference and the
    cell's Functions are computed once for all substep counts."""
    kern, law, m, c = _one_cell()
    t_in, t_c = 0.1 / 3.0, 1.8 / 3.0

    def load(t):
        frac = min(1.0, t / t_in) if t < t_c else max(0.0, 1 - (t - t_c) / t_in)
        return frac * (20000.0 + 10000.0 * min(t, t_c) / t_c)

    n = int(round(t_end / h))
    zr = vr = zmr = pmr = 0.0
    ref = []
    for k in range(n):
        zr, vr, _, zmr, pmr = _radau_step(law, load, m, c, k * h, h, (zr, vr), zmr, pmr)
        ref.append(zr)
    mine = {}
    for substeps in substep_counts:
        z = v = zm = pm = 0.0
        p, dp = law(0.0, 0.0, 0.0)
        zs = []
        for k in range(n):
            t0 = k * h
            pl = [load(t0 + j * h / substeps) for j in range(substeps + 1)]
            work = [0.0, 0.0]
            z, v, p, dp, _ = kern._cell_step(z, v, p, dp, pl, [1.0, 0.0] * (substeps + 1), [zm, pm, 0, 0, 0], 0, h,
                                             substeps, work)
            pm = max(pm, p) if z >= zm else pm
            zm = max(zm, z)
            zs.append(z)
        mine[substeps] = np.array(zs)
    return mine, np.array(ref)


@pytest.mark.slow  # a brute-force / step-refinement reference (make test-slow)
def test_one_cell_converges_under_step_refinement():
    mine, ref = _one_cell_reference_and_engine((1, 4, 16))
    errs = {n: (abs(z.max() / ref.max() - 1), abs(z[-1] / ref[-1] - 1)) for n, z in mine.items()}
    print("one cell: (peak, after the track) relative error per substep count:", errs)
    # the peak sinkage is right at any substep count; the rebound after the track needs the
    # substeps (the fast unloading on the elastic line): measured 1.8 %, 0.68 %, 0.096 %
    assert all(e[0] < 1e-3 for e in errs.values())
    assert errs[16][1] < errs[4][1] < errs[1][1]
    assert errs[16][1] < 1e-3


def _one_cell_work(ring_tolerance, speed_m_s=6.0, h=0.01, t_end=0.3):
    """One cell entering under a track at speed_m_s (the load ramps up over the 0.1 m cell, then
    grows along the track): the rectified work int p max(dz/dt, 0) dt of the engine's rule
    (an entry window of EngineSettings().entry_substeps substeps while the reaction is below
    entry_fraction of the load or the cell rings, else one implicit Euler step) against Radau at
    rtol 1e-10 with the work as a quadrature; the history updated after every macro step in both."""
    kern, law, m, c = _one_cell()
    es = engine.EngineSettings(ring_tolerance=ring_tolerance)
    t_in = 0.1 / speed_m_s

    def load(t):
        return min(1.0, t / t_in) * (20000.0 + 10000.0 * t / t_end)

    z = v = zm = pm = work_e = 0.0
    zr = vr = zmr = pmr = work_r = 0.0
    p, dp = law(0.0, 0.0, 0.0)
    windows = 0
    for k in range(int(round(t_end / h))):
        t0 = k * h
        plA, plB = load(t0), load(t0 + h)
        transient = p < es.entry_fraction * max(plA, plB) or ringing(
            es.ring_tolerance, z, v, p, dp, plA, plB, h, m, c)
        n = es.entry_substeps if transient else 1
        windows += transient
        pl = [load(t0 + j * h / n) for j in range(n + 1)]
        work = [0.0, 0.0]
        z, v, p, dp, _ = kern._cell_step(z, v, p, dp, pl, [1.0, 0.0] * (n + 1), [zm, pm, 0, 0, 0], 0, h, n, work,
                                         not transient and es.steady_method == "euler")
        work_e += work[0]
        pm = max(pm, p) if z >= zm else pm
        zm = max(zm, z)
        zr, vr, dw, zmr, pmr = _radau_step(law, load, m, c, t0, h, (zr, vr), zmr, pmr)
        work_r += dw
    return work_e, work_r, windows, z / zr - 1


def test_the_ringing_after_the_entry_is_resolved():
    """The end of the entry ramp excites the cell's lightly damped oscillation on its elastic line
    (docs/terrain.md, "The cells' ringing"); its reloads are part of the rectified compaction work.
    At 6 m/s (validation_grid's speed after its first seconds) the ring windows resolve them: the work
    within 0.2 % of Radau (measured -0.01 %); without them (ring_tolerance 0) the single 10 ms step
    after the entry window damps the oscillation and the work is 1.6 % low. The sinkage is right
    either way."""
    default = engine.EngineSettings().ring_tolerance
    (we, wr, nw, dz), (we0, _, nw0, dz0) = _one_cell_work(default), _one_cell_work(0.0)
    err, err0 = we / wr - 1, we0 / wr - 1
    print(f"one cell's work: {wr:.4f} J/m^2 (Radau); engine {err:+.3%} with {nw} windows, {err0:+.3%} with {nw0} "
          f"without ringing; sinkage {dz:+.2e} / {dz0:+.2e}")
    assert nw > nw0
    assert abs(err) < 2e-3
    assert err0 < -0.01
    assert abs(err) < abs(err0) / 5
    assert abs(dz) < 1e-3 and abs(dz0) < 1e-3


@pytest.mark.parametrize("n_exp", [0.5, 0.73])
def test_fast_law_equals_the_model_law(n_exp):
    """The engine's law (p and its slope by branch) against the model's law and its Jacobian, on
    every piece: below the surface, virgin, elastic line, reload line of a cycle, clipped at 0."""
    from symtrack.soil import cell

    sc = load_scenario("validation_grid")
    soil = BekkerWong(sc.model)
    law = soil.values({**sc.params, "bekker_n": n_exp})  # floats: the engine's form (sqrt at n = 0.5)
    lw = soil.named(law)
    keq, n, ke, kappa, reg = (lw[k] for k in ("k_eq", "n", "elastic_stiffness_Pa_per_m", "kappa", "regularisation_m"))
    import casadi as ca

    z, h = ca.SX.sym("z"), ca.SX.sym("h", 5)
    pf, dpf = soil.pressure_and_slope(z, h, law)
    a = ca.Function("a", [z, h], [pf, dpf])
    pm = cell.reaction_pressure(z, h[0], h[1], keq, n, ke, kappa, reg, z_off=h[2], delta=h[3], d_c=h[4])
    b = ca.Function("b", [z, h], [pm, ca.jacobian(pm, z)])
    # histories on this soil's own curve: virgin; loaded to 1.5 mm; the same with a cycle's offset
    # and increment (z_off, delta) and part of it taken (d_c)
    zm = 1.5e-3
    pmax = float(ca.evalf(cell.bekker_pressure(zm, keq, n, reg)))
    hist = ((0, 0, 0, 0, 0), (zm, pmax, 0, 0, 0), (zm, pmax, 2e-4, 1e-4, 3e-5))
    pieces = set()
    for zz in np.linspace(-1.03e-4, 2.21e-3, 61):  # off the round numbers, where two pieces can tie
        for hh in hist:
            (pa, da), (pb, db) = ([float(v) for v in f(zz, hh)] for f in (a, b))
            assert pa == pytest.approx(pb, rel=1e-14, abs=1e-9)
            assert da == pytest.approx(db, rel=1e-12, abs=1e-6), (zz, hh, pa, da, db)
            pieces.add("0" if pa == 0 else ("virgin" if zz >= hh[0] + hh[2] + hh[3] else f"line {da:.6g}"))
    # every piece was met: zero, virgin, and for the cycle's history both its elastic line (slope
    # k_u) and its reload line (slope k_r)
    _, _, _, delta, _ = hist[2]
    k_u = float(ca.evalf(cell.unloading_slope(zm, pmax, ke, kappa, reg)))
    k_r = float(ca.evalf(cell._reload_slope(pmax, k_u, delta, cell.CYCLE_THRESHOLD_FRACTION)))
    assert k_r < 0.9 * k_u
    missing = {"0", "virgin", f"line {k_u:.6g}", f"line {k_r:.6g}"} - pieces
    assert not missing, missing


@pytest.mark.parametrize("method", STEADY_METHODS)
def test_compiled_equals_interpreted(method):
    if find_compiler() is None:
        pytest.skip("no C compiler")
    sc = _scenario(duration_s=0.3)
    wc, rc = _engine_run(sc, engine.EngineSettings(steady_method=method), mean_stress=True)
    wi, ri = _engine_run(sc, engine.EngineSettings(steady_method=method), kernel=PyKernel, mean_stress=True)
    assert rc.stats["engine_compiled"] and not ri.stats["engine_compiled"]
    assert rc.stats["n_cell_stages"] == ri.stats["n_cell_stages"]  # the same algorithm, step by step
    scale = np.maximum(1.0, np.abs(ri.X))
    assert np.max(np.abs(rc.X - ri.X) / scale) < 1e-12
    assert np.max(np.abs(rc.Y - ri.Y) / np.maximum(1.0, np.abs(ri.Y))) < 1e-9
    assert np.max(np.abs(wc.z_at_pass_end - wi.z_at_pass_end)) < 1e-15
    assert np.array_equal(wc.touched, wi.touched)
    # the subsoil stress and, when asked for, the mean normal stress (C against numpy: 1e-12, then float32)
    for name in ("pass_sigma", "pass_p_mean"):
        c, i = getattr(wc, name), getattr(wi, name)
        assert np.any(c > 0) and np.allclose(c, i, rtol=1e-6, atol=0.0), name


def test_soils_that_differ_in_law_values_share_one_engine_build():
    """The soil's law values reach the engine at run time (eng_t.soil_law: a row per soil, the cell
    Functions' input ``law``): soils that differ only in a law value (k_phi, as a sweep over it does) or
    in n (the general law instead of its n = 0.5 copy, chosen at run time) make the same Functions and
    run on one build of the engine, each with its own sinkage: the compiled run equals the interpreted
    oracle's on each soil."""
    if find_compiler() is None:
        pytest.skip("no C compiler")
    from symtrack import toolchain

    n_builds = len(toolchain.builds)
    keys, libs, sinkage = set(), set(), []
    for soil in ({}, {"k_phi_N_per_m_n2": 2 * 692.15e3}, {"bekker_n": 0.7}):
        d = copy.deepcopy(SMALL)
        d["run"]["duration_s"] = 0.3
        d["soil"].update(soil)
        sc = scenario_from_dict(d)
        keys.add(tuple(f.serialize() for f in build_engine_functions(sc.model, sc.params, 1).all()))
        plant = make_plant(sc)
        libs.add(plant.engine.kernel.lib._name)
        rc = loop.run(sc, plant)
        wc = plant.world
        wi, ri = _engine_run(sc, kernel=PyKernel)
        assert rc.stats["n_cell_stages"] == ri.stats["n_cell_stages"]
        assert np.max(np.abs(rc.X - ri.X) / np.maximum(1.0, np.abs(ri.X))) < 1e-12
        assert np.max(np.abs(wc.z_at_pass_end - wi.z_at_pass_end)) < 1e-15
        sinkage.append(float(wc.z_at_pass_end.max()))
    assert len(keys) == 1 and len(libs) == 1  # one engine (its Functions hold no soil value)
    assert sum(b.kind == "engine" for b in toolchain.builds[n_builds:]) <= 1  # built at most once (else cached)
    z, z_stiff, z_n = sinkage
    assert z > 5e-4 and z_stiff < 0.8 * z and abs(z_n - z) > 0.2 * z  # each soil its own sinkage


@pytest.mark.slow  # a brute-force / step-refinement reference (make test-slow)
def test_pool_equals_one_channel_per_cell_and_brute_force(fast, monkeypatch):
    wf, rf = fast
    sc = _scenario()
    nx, ny = wf.grid.shape
    # every cell its own channel (M >= the field): the same run to the last bit (the sector rule
    # only renames the channels)
    sc_big = dataclasses.replace(sc, terrain=dataclasses.replace(sc.terrain, channels=max(nx, ny)))
    wb, rb = _engine_run(sc_big)
    assert wb.M >= max(nx, ny) > wf.M
    assert np.array_equal(rb.X, rf.X) and np.array_equal(rb.Y, rf.Y)
    assert np.array_equal(wb.z_at_pass_end, wf.z_at_pass_end)
    # the lift-off (World.end_pass: CVODES over the whole pool, whose size differs) to its tolerance
    assert np.max(np.abs(wb.storage.z - wf.storage.z)) < 1e-9
    # brute force (every cell a state of one IDAS system): the engine's tolerances against IDAS; built
    # without CasADi's cse (the same numbers to the last bit: grid_idas.CSE; on 768 cells its build cost
    # more than 0.6 s of steps)
    monkeypatch.setattr(grid_idas, "CSE", False)
    brute = brute_force_run(_scenario("idas", reltol=1e-7, abstol=1e-9), SMALL["run"]["duration_s"])
    assert np.max(np.abs(rf.X[:, :3] - brute.X[:, :3])) < POSE_TOL_M
    zb = brute.z.ravel()
    assert np.max(np.abs(wf.z_at_pass_end - zb)) < SINKAGE_REL_TOL * zb.max()
    assert rf.terrain["terrain_peak_active_cells"] < wf.grid.n_cells / 4


def test_two_passes_equal_one_pass_save_load_and_a_second_pass(tmp_path):
    d = copy.deepcopy(SMALL)
    d["run"].update({"duration_s": 5.0, "stop_after_distance_m": 0.3})
    two, again = two_passes_against_a_continued_pass(d, tmp_path)
    figs2 = two.summary["passes"]
    res1b = again.runs[0]
    assert res1b.stopped_by == "distance" and res1b.stats["n_cell_stages"] > 0
    assert figs2[1]["new_sinkage_mean_mm"] < figs2[0]["new_sinkage_mean_mm"]
    assert figs2[1]["compaction_resistance_mean_N"] < figs2[0]["compaction_resistance_mean_N"]


def test_a_pool_too_small_stops_with_the_cells_and_the_M_needed():
    d = copy.deepcopy(SMALL)
    d["terrain"]["channels"] = 6
    with pytest.raises(SimulationError, match=r"channel collision: cells \(\d+, \d+\) and \(\d+, \d+\).*M = 6.*"
                                              r"needs M >= \d+"):
        _engine_run(scenario_from_dict(d))


def test_leaving_the_field_is_an_error():
    d = copy.deepcopy(SMALL)
    d["start"]["x_m"] = 5.5
    with pytest.raises(SimulationError, match="left the terrain field"):
        _engine_run(scenario_from_dict(d))


def test_grid_fast_needs_a_terrain_and_settings_are_validated():
    sc = load_scenario("validation", ["run.integrator=grid_fast"])
    with pytest.raises(ScenarioError, match="does not integrate the homogeneous terrain"):
        make_plant(sc)
    with pytest.raises(ScenarioError, match="entry_substeps"):
        engine.EngineSettings(entry_substeps=0)
    with pytest.raises(ScenarioError, match="power"):
        engine.EngineSettings(power="bogus")
    for bad in (-1e-3, 1.5, True, "0.01"):
        with pytest.raises(ScenarioError, match=r"engine.ring_tolerance = .* must be a number in \[0, 1\]"):
            engine.EngineSettings(ring_tolerance=bad)
    with pytest.raises(ScenarioError, match="ring_tolerance"):  # from a scenario override, before any work
        load_scenario("validation_grid", ["engine.ring_tolerance=2"])
    assert math.isclose(engine.SDIRK_GAMMA, 1 - 1 / math.sqrt(2))


def test_a_loaded_cell_without_a_channel_is_an_error():
    sc = _scenario(duration_s=0.2)
    plant = make_plant(sc)
    plant.engine.state.pad = -0.2  # a footprint shrunk by 0.2 m misses cells the tracks load
    with pytest.raises(SimulationError, match=r"cell \(\d+, \d+\) came under a track without a channel"):
        loop.run(sc, plant)


def test_the_engines_terrain_query_is_the_numpy_query():
    """The engine's C query on its own storage (terrain_query.h, eng_surface) against the numpy query
    on the world's storage after a short pass (rutted cells and untouched ones), outside points
    included; the interpreted oracle answers the same."""
    sc = _scenario(duration_s=0.3)
    plant = make_plant(sc)
    loop.run(sc, plant)
    w = plant.world
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-6.5, 6.5, 3000), [-6.0, 6.0, 0.0]])
    y = np.concatenate([rng.uniform(-2.5, 2.5, 3000), [-2.0, 2.0, 2.0]])
    ref = query.query(w.storage, x, y, outside="nan")
    assert np.nanmax(ref.sinkage_m) > 1e-4 and np.any(ref.cell < 0)  # the run left ruts; some points outside
    for eng in (plant.engine, engine.TerrainEngine(w, kernel=PyKernel)):
        got = eng.surface(x, y, outside="nan")
        for name in ("cell", "elevation_m", "sinkage_m", "height_m", "normal", "phase", "gradient"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    with pytest.raises(SimulationError, match=r"terrain query at \(100, 0\) m: outside the field"):
        plant.engine.surface(100.0, 0.0)



@pytest.mark.slow  # a second engine build (about 10 s)
def test_cells_in_lanes_equal_one_cell_at_a_time(tmp_path, monkeypatch):
    """grid_engine.c integrates the cells in batches of CELL_LANES interleaved lanes (cell_step_block):
    every lane runs the one-cell sequence of operations, so the engine built with one lane gives the
    same run to the last bit (states, outputs, stored cells, subsoil and mean-stress maxima)."""
    if find_compiler() is None:
        pytest.skip("no C compiler")
    import importlib.resources
    from pathlib import Path

    from symtrack.integrators.engine import kernel as engine_kernel
    native = importlib.resources.files("symtrack.native")
    for name in ("grid_engine.c", "subsoil.h", "terrain_query.h", "distance_stop.h"):
        (tmp_path / name).write_bytes(native.joinpath(name).read_bytes())
    src = (tmp_path / "grid_engine.c").read_text()
    assert "#define CELL_LANES 8\n" in src
    (tmp_path / "grid_engine.c").write_text(src.replace("#define CELL_LANES 8\n", "#define CELL_LANES 1\n"))
    sc = _scenario(duration_s=1.0)
    wa, ra = _engine_run(sc)
    monkeypatch.setattr(engine_kernel, "resources", types.SimpleNamespace(files=lambda pkg: Path(tmp_path)))
    wb, rb = _engine_run(sc)
    assert ra.stats["n_cell_stages"] == rb.stats["n_cell_stages"] > 0
    assert np.array_equal(ra.X, rb.X) and np.array_equal(ra.Y, rb.Y)
    sa, sb = wa.storage.arrays(), wb.storage.arrays()
    assert sa.keys() == sb.keys() and np.any(sa["z_m"] > 0)
    for name in sa:
        assert np.array_equal(sa[name], sb[name]), name
    for name in ("pass_sigma", "pass_p_mean"):
        assert np.array_equal(getattr(wa, name), getattr(wb, name)), name


def test_the_ctypes_binding_is_checked_against_the_c_struct():
    """The ctypes EngineStruct is compared with the eng_t the library was compiled with (the field table
    grid_engine.c exports) when the library is loaded: a binding with a field moved, retyped, renamed,
    missing or extra stops with an error naming the first field that differs."""
    if find_compiler() is None:
        pytest.skip("no C compiler")
    import ctypes

    from symtrack.integrators.engine.kernel import check_struct
    from symtrack.integrators.engine.state import EngineStruct

    lib = make_plant(_scenario()).engine.kernel.lib
    check_struct(lib)  # the package's binding agrees
    assert int(lib.eng_field_count()) == len(EngineStruct._fields_) > 80
    fields = list(EngineStruct._fields_)

    def perturbed(new_fields):
        return type("EngineStruct", (ctypes.Structure,), {"_fields_": new_fields})

    i = next(k for k, (n, _) in enumerate(fields) if n == "zdot")
    swapped = fields[:i] + [fields[i + 1], fields[i]] + fields[i + 2:]
    with pytest.raises(SimulationError, match=r"at field \d+: binding 'zmax'.*eng_t: 'zdot', double \*"):
        check_struct(lib, perturbed(swapped))
    j = next(k for k, (n, _) in enumerate(fields) if n == "ring_tol")
    retyped = fields[:j] + [("ring_tol", ctypes.c_longlong)] + fields[j + 1:]
    with pytest.raises(SimulationError, match="binding 'ring_tol', c_long.*eng_t: 'ring_tol', double,"):
        check_struct(lib, perturbed(retyped))
    with pytest.raises(SimulationError, match="lacks field .* 'iwork'"):
        check_struct(lib, perturbed(fields[:-1]))
    with pytest.raises(SimulationError, match="has field 'extra'"):
        check_struct(lib, perturbed(fields + [("extra", ctypes.c_double)]))
    k = next(k for k, (n, _) in enumerate(fields) if n == "err_x")
    shorter = fields[:k] + [("err_x", ctypes.c_double * 3)] + fields[k + 1:]
    with pytest.raises(SimulationError, match=r"'err_x', c_double_Array_3.*'err_x', double\[2\]"):
        check_struct(lib, perturbed(shorter))
