"""The pass rules written once, in grid_engine.c: the terrain engine and the IDAS reference path
(:class:`symtrack.integrators.engine.ChannelManager`) run the same C, and the interpreted copies of
the tests' oracle (tests/engine_oracle.py) agree with it."""

import importlib.resources
import types

import numpy as np
import pytest
from engine_oracle import static_sinkage
from small_field import small_field

from symtrack.integrators.engine import ChannelManager
from symtrack.simulation.plants import make_plant
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.terrain.world import open_world


def _plant(integrator: str, **terrain):
    d = small_field(f"rules_{integrator}", run={"integrator": integrator}, terrain=terrain)
    sc = scenario_from_dict(d)
    return sc, make_plant(sc)


def _manager(**terrain) -> ChannelManager:
    """The IDAS path's world manager on the small field (no integrator: a set-down without settling
    steps none)."""
    d = small_field("rules_idas", run={"integrator": "idas"}, terrain=terrain)
    sc = scenario_from_dict(d)
    return ChannelManager(open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s))


def test_the_set_down_is_the_engines_rule_on_the_idas_path():
    """The vehicle set down without settling (settle_s = 0) on the engine and on the IDAS path: the
    manager's set-down is eng_static's rule (the same C on the same loads gives the same cells, bit for
    bit); its loads are its DAE's, the engine's its cell geometry's, and both paths put the cells at
    the same sinkage (to 1e-12 of it); the oracle's interpreted copy agrees to 1e-15 m."""
    sc, pe = _plant("grid_fast", settle_s=0.0)
    pose = (sc.start.x_m, sc.start.y_m, np.radians(sc.start.yaw_deg))
    pe.engine.begin_pass(*pose)
    s = pe.engine.state
    act = s.active_channels().copy()
    z_engine = dict(zip(s.ch_cell[act].tolist(), s.ch_z[act].tolist(), strict=True))
    assert len(z_engine) > 50 and max(z_engine.values()) > 5e-4

    mgr = _manager(settle_s=0.0)
    calls = []
    kernel = mgr.kernel
    solve = kernel.static_sinkage

    def spy(z0, hist, soil, p_load):
        z = solve(z0, hist, soil, p_load)
        calls.append((np.array(z0), np.array(hist), np.array(soil), np.array(p_load), z.copy()))
        return z
    kernel.static_sinkage = spy
    x = mgr.begin_pass(types.SimpleNamespace(reset=lambda: None), *pose)
    assert len(calls) == 1  # the set-down went through the C rule
    w = mgr.world
    L = w.layout
    held = np.nonzero(w.channel_cell >= 0)[0]
    z_idas = dict(zip(w.channel_cell[held].tolist(), x[L.cell_index(held, "sinkage")].tolist(), strict=True))
    assert set(z_idas) == set(z_engine)
    zmax = max(z_engine.values())
    assert max(abs(z_idas[c] - z_engine[c]) for c in z_engine) < 1e-12 * zmax

    # the same loads through the engine's own eng_static (its state's channels): bit for bit
    z0, hist, soil, p_load, z_manager = calls[0]
    cells = w.channel_cell[held]
    s.ch_z[act] = 0.0
    by_cell = dict(zip(s.ch_cell[act].tolist(), act.tolist(), strict=True))
    chs = np.array([by_cell[c] for c in cells.tolist()])
    s.ch_z[chs] = z0
    s.ch_g[chs, 0] = p_load
    pe.engine.kernel.static()
    assert np.array_equal(s.ch_z[chs], z_manager)
    assert np.array_equal(x[L.cell_index(held, "sinkage")], z_manager)
    # the oracle's copy (numpy on CasADi's interpreter)
    z_oracle = static_sinkage(w.terrain.fn["soil"], w.laws[:, soil], z0, hist, p_load)
    assert np.max(np.abs(z_oracle - z_manager)) <= 1e-15
    # a second manager on the same World gives the same bits (one library, no state of its own)
    assert np.array_equal(ChannelManager(w).kernel.static_sinkage(z0, hist, soil, p_load), z_manager)


def test_the_lift_off_is_the_engines_rule_on_the_idas_path():
    """From one pass end (the engine's, checkpointed), the engine's lift-off and the IDAS path's
    (ChannelManager.end_pass, through eng_lift) leave the same terrain: the manager's pass-end
    reactions and slopes are its channel model's (CasADi's interpreter), the rule and the cell step
    the same C (measured: within 4e-18 m, the history and the cycle counts equal)."""
    from symtrack.simulation import loop

    sc, pe = _plant("grid_fast")
    pe.finish = lambda: None  # keep the pass end
    loop.run(sc, pe)
    eng, w = pe.engine, pe.world
    saved = eng.checkpoint()
    eng.end_pass()
    after_engine = {k: getattr(w.storage, k).copy() for k in ("z", "zdot", "zmax", "pmax", "phase", "zoff", "cycles")}
    eng.restore(saved)
    mgr = ChannelManager(w)
    lifts = []
    lift = mgr.kernel.lift

    def spy(*args):
        lifts.append(args)
        return lift(*args)
    mgr.kernel.lift = spy
    mgr.end_pass(eng.sync_world())
    assert len(lifts) == 1 and not (w.channel_cell >= 0).any()
    z = after_engine["z"]
    assert z.max() > 5e-4
    assert np.max(np.abs(w.storage.z - z)) < 1e-12 * z.max()
    assert np.max(np.abs(w.storage.zmax - after_engine["zmax"])) < 1e-12 * z.max()
    assert np.array_equal(w.storage.phase, after_engine["phase"])
    assert np.array_equal(w.storage.cycles, after_engine["cycles"])


def test_the_footprint_rectangles_are_the_engines_on_the_idas_path_and_the_plots():
    """The tracks' rectangles that the plots draw (ChannelManager.track_corners) and that the engine's
    footprint scan visits are grid_engine.c's eng_track_rects: equal bit for bit to the oracle's copy
    from the vehicle's contact_rectangles, in any heading; and the cells the C finds loaded at a pose
    with every channel free (eng_uncovered: centres in the rectangles padded by half a cell) are the
    cells whose centres lie in those rectangles."""
    from engine_oracle import cells_under, rectangles

    mgr = _manager()
    w = mgr.world
    rng = np.random.default_rng(3)
    for X, Y, psi in zip(rng.uniform(-3, 3, 8), rng.uniform(-0.5, 0.5, 8), rng.uniform(-np.pi, np.pi, 8),
                         strict=True):
        for pad in (0.0, 0.5 * w.grid.cell_m):
            c_rects = mgr.kernel.track_rects(X, Y, psi, pad)
            assert np.array_equal(c_rects, np.array(rectangles(w.params, X, Y, psi, pad)))
        for corners, rect in zip(mgr.track_corners(X, Y, psi), rectangles(w.params, X, Y, psi, 0.0), strict=True):
            assert np.allclose(corners.mean(axis=0), rect[:2], atol=1e-12)
            assert np.isclose(np.linalg.norm(corners[0] - corners[1]), 2 * rect[4])
            assert np.isclose(np.linalg.norm(corners[1] - corners[2]), 2 * rect[5])
        mgr.state.ch_cell[:] = -1
        n, _ = mgr.kernel.uncovered(X, Y, psi)
        assert n == cells_under(w, X, Y, psi, 0.5 * w.grid.cell_m, check_field=False).size > 0


_STOP_CHECK_C = b"""
#include "distance_stop.h"
/* a centre of gravity at x = bx + s, y = by + 0.3 s with s = a t^2 / 2 (the test's plant) */
typedef struct { double a, bx, by, t0; double xy[2]; } path_t;
static void at(const path_t *p, double t, double *xy) {
  double s = 0.5 * p->a * t * t;
  xy[0] = p->bx + s;
  xy[1] = p->by + 0.3 * s;
}
static int retake(void *ctx, double h) {
  path_t *p = (path_t *)ctx;
  at(p, p->t0 + h, p->xy);
  return 0;
}
/* the steps (t0[k], h[k]) in turn until the stop: out = (end time, distance, x, y); returns the steps done */
__attribute__((visibility("default")))
long long stop_run(double a, double bx, double by, double target, double from_t, long long n, const double *t0,
                   const double *h, double *out) {
  path_t p = {a, bx, by, 0.0, {0.0, 0.0}};
  double dist = 0.0, xy0[2];
  at(&p, 0.0, xy0);
  for (long long k = 0; k < n; ++k) {
    double hk = h[k], t_next = t0[k] + h[k];
    p.t0 = t0[k];
    at(&p, t0[k] + h[k], p.xy);
    int done = distance_stop(&dist, target, from_t, t0[k], &t_next, &hk, xy0, p.xy, retake, &p);
    xy0[0] = p.xy[0];
    xy0[1] = p.xy[1];
    if (done) {
      out[0] = t_next; out[1] = dist; out[2] = p.xy[0]; out[3] = p.xy[1];
      return k + 1;
    }
  }
  return -1;
}
"""


class _PathPlant:
    """A plant whose centre of gravity follows x = x0 + s, y = y0 + 0.3 s, s = a t^2 / 2, whatever its
    torques (the distance stop's test); it records the intervals it is asked for."""

    kind = "homogeneous"
    max_intervals = short_intervals = 1
    output_names = ()

    def __init__(self, state_names, a):
        self.state_names, self.a = tuple(state_names), a
        self.ix, self.iy, self.iu = (self.state_names.index(n) for n in ("x_m", "y_m", "u_m_s"))
        self.intervals = []

    def _x(self, t):
        x = np.zeros(len(self.state_names))
        s = 0.5 * self.a * t * t
        x[self.ix], x[self.iy], x[self.iu] = self.x0 + s, self.y0 + 0.3 * s, self.a * t
        return x

    def start(self, x_m, y_m, yaw_rad, u0, state=None):
        self.x0, self.y0 = x_m, y_m
        return self._x(0.0), np.zeros(0)

    def synchronize(self, intervals):
        (self.t0, self.h, _), = intervals
        self.intervals.append((self.t0, self.h))

    def advance(self):
        return self._x(self.t0 + self.h)[None, :]

    def retry(self, k, length_s):
        return self._x(self.t0 + length_s)

    def commit(self, k):
        return np.zeros((k, 0))

    def finish(self):
        pass

    def figures(self):
        return {}

    def stats(self):
        return {}


def test_the_distance_stop_of_the_compiled_runs_is_the_python_loops():
    """The distance stop's one C copy (symtrack/native/distance_stop.h: the terrain engine's eng_run, the
    grid and homogeneous standalone programs, the engine FMU) and the Python time loop's (for the plants it
    steps itself: CVODES, IDAS, the Rosenbrock steppers, which need no compiler) end a run at the same
    time and place, bit for bit, on a path the secant does not hit exactly."""
    import ctypes

    from symtrack.simulation import loop
    from symtrack.simulation.scenario import load_scenario
    from symtrack.toolchain import BuildSpec, build, digest, find_compiler
    from symtrack.vehicles.planar import VEHICLE_STATES

    cc = find_compiler()
    if cc is None:
        pytest.skip("no C compiler")
    native = importlib.resources.files("symtrack.native")
    sources = {"distance_stop.h": native.joinpath("distance_stop.h").read_bytes(), "stop_check.c": _STOP_CHECK_C}
    so = build(BuildSpec(kind="distance_stop_check", key=digest(*(sources[n] for n in sorted(sources))),
                         output="libdistance_stop_check.so", sources=lambda: sources,
                         what="the distance stop's C check"), cc)
    lib = ctypes.CDLL(str(so))
    vp = ctypes.c_void_p
    lib.stop_run.restype = ctypes.c_longlong
    lib.stop_run.argtypes = [ctypes.c_double] * 5 + [ctypes.c_longlong, vp, vp, vp]
    for target, a in ((0.5, 0.5), (0.3, 0.7)):
        sc = load_scenario("validation", [f"run.stop_after_distance_m={target}"])
        plant = _PathPlant(VEHICLE_STATES, a)
        res = loop.run(sc, plant)
        assert res.stopped_by == "distance"
        t0 = np.array([iv[0] for iv in plant.intervals])
        h = np.array([iv[1] for iv in plant.intervals])
        out = np.zeros(4)
        n = lib.stop_run(a, sc.start.x_m, sc.start.y_m, target, sc.event_time(sc.run.stop_distance_event), t0.size,
                         t0.ctypes.data, h.ctypes.data, out.ctypes.data)
        assert n == t0.size  # the C stopped in the interval where Python did
        assert out[0] == res.t[-1] and res.t[-1] < t0[-1] + h[-1]  # the same shortened step
        assert (out[2], out[3]) == (res.X[-1, plant.ix], res.X[-1, plant.iy])
        assert abs(out[1] - target) < 1e-6 * target  # the secant's distance
