"""Subsoil stress and compaction risk (symtrack/soil/subsoil.py, symtrack/native/subsoil.h),
each against an independent truth: closed forms (uniform circle, Boussinesq/Newmark rectangle),
a brute-force integration of the point-load formula, a refined table, and numpy for the C."""

from __future__ import annotations

import ctypes
import math
import os
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

from symtrack import toolchain as build
from symtrack.foundations.errors import ParameterError
from symtrack.native import cache
from symtrack.soil import rigid_base
from symtrack.soil import subsoil as S

GEO = (2.4, 0.45, 1.5, 0.1, 0.1, 0.2)  # l, b, B, e (CG 0.1 m ahead of the contact centre), cell, end strip
DEPTHS = S.DEFAULT_DEPTHS_M
# pressure lines (alpha, beta) of the left and right tracks [Pa, Pa/m]
LINEAR = (30e3, -5e3, 22e3, 4e3)
TRIANGULAR = (2 * 50e3 / 1.8, -2 * 50e3 / 1.8**2, 0.0, 2 * 40e3 / 2.4**2)  # front: zero from s = 1.8; rear: from 0
NATIVE = Path(S.__file__).resolve().parents[1] / "native"


def _a(X, Y, psi, line):
    return np.array([X, Y, math.cos(psi), math.sin(psi), *line])


def _world(a, bx, by):
    """World points of body coordinates (bx, by) at the pose of a."""
    c, s = a[2], a[3]
    return a[0] + c * np.asarray(bx) - s * np.asarray(by), a[1] + s * np.asarray(bx) + c * np.asarray(by)


@pytest.fixture(scope="module")
def tables5():
    return S.build_tables(DEPTHS, 5.0, GEO[0], GEO[1], GEO[2])


# (a) ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("xi", [3.0, 4.0, 5.0, 6.0])
def test_uniform_circle_centre_closed_form(xi):
    """Point loads over a uniform disc (radius a, pressure p) integrated numerically give, at the
    centre, p (1 - cos^xi(alpha)), tan(alpha) = a / z: integral of xi p z^xi r / (r^2 + z^2)^((xi+2)/2)."""
    p, a_m = 100e3, 0.3
    nodes, weights = np.polynomial.legendre.leggauss(8)
    for z in (0.05, 0.3, 1.0):
        n = 200
        h = a_m / n
        r = (h * np.arange(n)[:, None] + 0.5 * h * (1 + nodes)).ravel()
        w = np.tile(0.5 * h * weights, n)
        sigma = float(np.sum(S.frohlich_point(p * 2 * np.pi * r * w, r, z, xi)))
        exact = p * (1 - (z / math.hypot(a_m, z)) ** xi)
        assert sigma == pytest.approx(exact, rel=1e-9)


# (b) ---------------------------------------------------------------------------------------------
def _newmark_corner(q, m, n):
    """Boussinesq vertical stress below the corner of a uniform m z x n z rectangle (Newmark)."""
    s2 = m * m + n * n + 1
    root = math.sqrt(s2)
    return q / (4 * math.pi) * (2 * m * n * root / (s2 + m * m * n * n) * (s2 + 1) / s2
                                + math.atan2(2 * m * n * root, s2 - m * m * n * n))


def test_rectangle_centre_boussinesq():
    """xi = 3, the left track loaded uniformly: the stress below its centre is 4 Newmark corners."""
    l_m, b_m = GEO[0], GEO[1]
    q = 40e3
    T = S.build_tables(DEPTHS, 3.0, l_m, b_m, GEO[2])
    a = _a(3.0, -1.0, 0.7, (q, 0.0, 0.0, 0.0))
    px, py = _world(a, -GEO[3], GEO[2] / 2)  # the track centre: body (-e, +B/2)
    table = S.stress_at(T, px, py, a, GEO)[0]
    for k, z in enumerate(DEPTHS):
        exact = 4 * _newmark_corner(q, b_m / 2 / z, l_m / 2 / z)
        assert S.stress_bruteforce(px, py, a, GEO, z, 3.0)[0] == pytest.approx(exact, rel=1e-6)
        assert table[k] == pytest.approx(exact, rel=5e-3)


# (c) ---------------------------------------------------------------------------------------------
# body coordinates: under the left track (centre, near the front end, near the rear end), under the
# right track, between the tracks, beyond the front and the rear end, outside the right track
POINTS_BODY = np.array([(-0.1, 0.75), (1.05, 0.70), (-1.25, 0.80), (0.2, -0.75), (0.0, 0.0),
                        (1.35, 0.75), (-1.5, -0.75), (0.4, -1.15), (-0.6, 0.55)])


@pytest.mark.parametrize("line", [LINEAR, TRIANGULAR], ids=["linear", "triangular"])
def test_tables_against_bruteforce(tables5, line):
    a = _a(-2.0, 5.0, -0.4, line)
    px, py = _world(a, *POINTS_BODY.T)
    sigma = S.stress_at(tables5, px, py, a, GEO)
    for k, z in enumerate(DEPTHS):
        ref = S.stress_bruteforce(px, py, a, GEO, z, 5.0)
        assert np.max(np.abs(sigma[:, k] - ref)) < 0.01 * ref.max(), (z, sigma[:, k], ref)
        # the other track and the ends are covered: under the right track, the stress is mostly its own
        assert ref[3] > 0


# (d) ---------------------------------------------------------------------------------------------
def test_halving_the_table_step_changes_little(tables5):
    fine = S.build_tables(DEPTHS, 5.0, GEO[0], GEO[1], GEO[2], x_step_per_depth=S.DEFAULT_X_STEP_PER_DEPTH / 2,
                          t_step_per_depth=S.DEFAULT_T_STEP_PER_DEPTH / 2)
    rng = np.random.default_rng(7)
    bx, by = rng.uniform(-1.7, 1.7, 3000), rng.uniform(-1.45, 1.45, 3000)
    for line in (LINEAR, TRIANGULAR):
        a = _a(0.5, 0.5, 1.1, line)
        px, py = _world(a, bx, by)
        coarse, ref = S.stress_at(tables5, px, py, a, GEO), S.stress_at(fine, px, py, a, GEO)
        change = np.max(np.abs(coarse - ref), axis=0) / np.max(ref, axis=0)
        assert np.all(change < 0.005), change


# (f) ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def clib():
    if build.find_compiler() is None:
        pytest.skip("no C compiler")
    sources = {n: (NATIVE / n).read_bytes() for n in ("subsoil.h", "subsoil_check.c")}
    flags, target = build.native_cflags(build.find_compiler())  # the engine's flags (integrators/engine/kernel.py)
    # its SIMD code is what is checked: the tuned flags themselves, never $SYMTRACK_(TUNED_)OPT_LEVEL's
    with mock.patch.dict(os.environ):
        os.environ.pop(build.TUNED_OPT_LEVEL_ENV, None)
        so = build.build(build.BuildSpec(kind="subsoil_check",
                                         key=build.digest(*(sources[n] for n in sorted(sources)), target),
                                         output="libsubsoil_check.so", sources=lambda: sources, cflags=flags,
                                         what="the subsoil check library", suffix=f"-b{cache.BUILD_VERSION}",
                                         tuned=True))
    lib = ctypes.CDLL(str(so))
    lib.subsoil_stress_bench.restype = ctypes.c_longlong
    return lib


def _dp(x):
    return np.ascontiguousarray(x, dtype=float).ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def test_c_equals_numpy(clib, tables5):
    rng = np.random.default_rng(3)
    st = tables5.c_struct()
    geo = np.array(GEO)
    for line in (LINEAR, TRIANGULAR, (25e3, 0.0, -1.0, 0.0)):
        a = _a(10.0, -3.0, 2.5, line)
        bx, by = rng.uniform(-4.5, 4.5, 4000), rng.uniform(-3.0, 3.0, 4000)  # also past the tables' ends
        px, py = _world(a, bx, by)
        out = np.zeros((px.size, tables5.n_depths))
        clib.subsoil_stress_many(ctypes.byref(st), _dp(a), _dp(geo), _dp(px), _dp(py), ctypes.c_longlong(px.size),
                                 out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        ref = S.stress_at(tables5, px, py, a, GEO)
        np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_c_block_equals_the_scalar_lookup_bit_for_bit(clib, tables5):
    """subsoil_stress_block (the engine's SIMD path over the loaded cells, with the engine's compile flags)
    gives subsoil_stress's sums to the last bit, for the vertical and the mean normal stress tables at
    once and for a block count that leaves a partial block; also prints the cost of both per point and
    depth on the engine's ~250 loaded cells (a measurement, not a timed assertion)."""
    geo = np.array(GEO)
    P = S.build_mean_stress_tables(DEPTHS, 5.0, GEO[0], GEO[1], GEO[2])
    st, sp = tables5.c_struct(), P.c_struct()
    rng = np.random.default_rng(11)
    for line in (LINEAR, TRIANGULAR, (25e3, 0.0, -1.0, 0.0), (0.0, 0.0, 0.0, 0.0)):
        a = _a(10.0, -3.0, 2.5, line)
        px, py = _world(a, rng.uniform(-4.5, 4.5, 1000 + 37), rng.uniform(-3.0, 3.0, 1000 + 37))
        n = px.size
        for T, cs in ((tables5, st), (P, sp)):
            ref = np.zeros((n, T.n_depths))
            clib.subsoil_stress_many(ctypes.byref(cs), _dp(a), _dp(geo), _dp(px), _dp(py), ctypes.c_longlong(n),
                                     ref.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            out, out_p = np.full((n, T.n_depths), np.nan), np.full((n, P.n_depths), np.nan)
            clib.subsoil_stress_many_block(ctypes.byref(cs), ctypes.byref(sp), _dp(a), _dp(geo), _dp(px), _dp(py),
                                           ctypes.c_longlong(n), out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                                           out_p.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            assert np.array_equal(out, ref), np.abs(out - ref).max()
            ref_p = np.zeros((n, P.n_depths))
            clib.subsoil_stress_many(ctypes.byref(sp), _dp(a), _dp(geo), _dp(px), _dp(py), ctypes.c_longlong(n),
                                     ref_p.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            assert np.array_equal(out_p, ref_p)
        assert line[0] == 0.0 or np.abs(ref).max() > 0.0  # the lines load the points
    a = _a(1.0, 2.0, 0.3, LINEAR)
    px, py = _world(a, rng.uniform(-1.3, 1.3, 250), rng.uniform(-1.0, 1.0, 250))
    out = np.zeros((250, tables5.n_depths))
    reps = 2000
    per = {}
    for name in ("subsoil_stress_bench", "subsoil_stress_block_bench"):
        fn = getattr(clib, name)
        fn.restype = ctypes.c_longlong
        ns = fn(ctypes.byref(st), _dp(a), _dp(geo), _dp(px), _dp(py), ctypes.c_longlong(250),
                out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), ctypes.c_longlong(reps))
        per[name] = ns / reps / 250 / tables5.n_depths
    flags = " ".join(build.native_cflags(build.find_compiler())[0])
    print(f"\nsubsoil stress: {per['subsoil_stress_bench']:.1f} ns per point and depth scalar, "
          f"{per['subsoil_stress_block_bench']:.1f} in blocks (flags {flags}); "
          f"tables {tables5.nbytes / 1024:.0f} KiB")


# (g) ---------------------------------------------------------------------------------------------
def test_risk_classes_at_the_thresholds():
    pc = 100.0
    sigma = np.array([0.0, 49.999, 50.0, 80.0, 110.0, 110.001, 500.0])
    assert S.risk_class(sigma, pc).tolist() == [0, 0, 1, 1, 1, 2, 2]
    assert S.risk_class(sigma, pc).dtype == np.int8


def test_risk_area_fractions():
    # 5 cells, 2 depths; cell 4 untouched; strength 100 at depth 0, 50 at depth 1
    sm = np.array([[10.0, 10.0], [60.0, 30.0], [120.0, 60.0], [200.0, 100.0], [900.0, 900.0]])
    touched = np.array([True, True, True, True, False])
    out = S.risk_area_fractions(sm, np.array([100.0, 50.0]), touched, 0.01)
    assert out["touched_area_m2"] == pytest.approx(0.04)
    # depth 0: ratios 0.1, 0.6, 1.2, 2.0 -> 1 low, 1 medium, 2 high; depth 1: 0.2, 0.6, 1.2, 2.0 -> same
    np.testing.assert_allclose(out["fraction_low"], [0.25, 0.25])
    np.testing.assert_allclose(out["fraction_medium"], [0.25, 0.25])
    np.testing.assert_allclose(out["fraction_high"], [0.5, 0.5])
    np.testing.assert_allclose(out["area_high_m2"], [0.02, 0.02])


def test_precompression_ptf():
    """Schjønning & Lamandé (2018) as cited in docs/subsoil.md (no value printed in a source we
    could read to test against): the formula's own structure, the floor at 0 and the range checks."""
    c = S.PTF_SL2018
    rho, h, clay = 1.46, 100.0, 0.3
    root = c["c0"] + c["c_rho"] * rho + c["c_clay"] * clay + c["c_clay_pF"] * clay * 2.0
    assert float(S.precompression_stress_kPa(rho, h, clay)) == pytest.approx(root**2, rel=1e-12)
    # stronger when denser, and when drier for a clay soil (pF > 2 here: 10.26 pF > 20.40)
    assert S.precompression_stress_kPa(1.6, h, clay) > S.precompression_stress_kPa(1.4, h, clay)
    assert S.precompression_stress_kPa(rho, 300.0, clay) > S.precompression_stress_kPa(rho, 100.0, clay)
    assert float(S.precompression_stress_kPa(0.9, 10.0, 0.5)) == 0.0  # the bracket is negative: floored
    with pytest.raises(ParameterError, match="clay_kg_kg"):
        S.precompression_stress_kPa(1.4, 100.0, 30.0)  # 30 %, not a fraction
    with pytest.raises(ParameterError, match="matric_suction_hPa"):
        S.precompression_stress_kPa(1.4, 0.0, 0.2)


def test_update_max_and_errors(tables5):
    sm = np.zeros((4, 2))
    S.update_max(sm, [1, 1, 3], np.array([[1.0, 5.0], [3.0, 2.0], [7.0, 0.5]]))
    assert sm.tolist() == [[0, 0], [3.0, 5.0], [0, 0], [7.0, 0.5]]
    with pytest.raises(ParameterError, match="depth_m"):
        S.build_tables([0.3, 0.0])
    with pytest.raises(ParameterError, match=r"xi .*\[1.0, 10.0\]"):
        S.build_tables(xi=12.0)
    with pytest.raises(ParameterError, match="geo l"):
        S.stress_at(tables5, [0.0], [0.0], _a(0, 0, 0, LINEAR), (2.0, 0.45, 1.5, 0.0, 0.1, 0.2))
    assert len(tables5.key()) == 64 and tables5.key() == S.build_tables(DEPTHS, 5.0, *GEO[:3]).key()


def test_plots_are_pngs_of_the_arrays(tables5):
    from symtrack.reports import subsoil_plots as P

    a = _a(2.0, 0.0, 0.0, LINEAR)
    xs, ys = np.arange(0.05, 4.0, 0.1), np.arange(-1.45, 1.5, 0.1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    sm = S.stress_at(tables5, gx.ravel(), gy.ravel(), a, GEO)
    touched = (sm[:, 0] > 1e3).reshape(gx.shape)
    risk = S.risk_class(sm, 25e3).reshape(*gx.shape, len(DEPTHS))
    pngs = [P.risk_map_png(risk, touched, DEPTHS, (0.0, 4.0, -1.5, 1.5)),
            P.stress_profile_png(DEPTHS, sm.max(axis=0) / 1e3, [25.0, 30.0, 30.0, 35.0]),
            P.passes_subsoil_png([1.0, 1.4], np.vstack([sm.max(axis=0), sm.max(axis=0)]) / 1e3, DEPTHS)]
    assert all(p.startswith(b"\x89PNG") for p in pngs)
    with pytest.raises(ValueError, match="risk has shape"):
        P.risk_map_png(risk[:, :, :2], touched, DEPTHS, (0.0, 4.0, -1.5, 1.5))


def test_track_frame_is_the_channels_frame():
    """The cells' load geometry of symtrack.terrain.channels (an independent implementation of the
    same frame): its overlap fractions follow from track_frame's (s, t) with the same clamped overlaps."""
    import casadi as ca

    from symtrack.model.options import ModelOptions
    from symtrack.terrain.channels import build_cell_functions

    geometry = build_cell_functions(ModelOptions())["geometry"]

    def overlap(c, h, lo, hi):
        return np.clip(np.minimum(hi, c + h) - np.maximum(lo, c - h), 0, 2 * h) / (2 * h)

    rng = np.random.default_rng(5)
    l_m, b_m, _, _, dx, _ = GEO
    loaded = 0
    for _ in range(40):
        X, Y, psi = rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-np.pi, np.pi)
        a = _a(X, Y, psi, LINEAR)
        px, py = _world(a, rng.uniform(-1.6, 1.6, 1), rng.uniform(-1.2, 1.2, 1))
        g = np.array(geometry(ca.DM([px[0], py[0], 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), ca.DM([X, Y, psi]),
                              ca.DM(GEO))).ravel()
        s, tl, tr = S.track_frame(px, py, a, GEO)
        for frac, t in ((g[0], tl[0]), (g[1], tr[0])):
            mine = overlap(s[0], dx / 2, 0, l_m) * overlap(t, dx / 2, -b_m / 2, b_m / 2)
            assert mine == pytest.approx(frac, abs=1e-12)
            loaded += frac > 0
    assert loaded >= 5  # the check saw cells under the tracks, not only empty ground


def test_lamande_2007_load_sets_the_subsoil_stress_and_area_the_topsoil_stress():
    """Lamandé, Schjønning & Tøgersen (2007), Soil Till. Res. 97, 91-106 (abstract; their stress
    table could not be read): stiff plates of A = 0.45 m^2 and 2A = 0.90 m^2 loaded with F = 43 kN
    and 2F = 85 kN; stresses at 30-90 cm below the centre. Their finding: "doubling the contact
    area reduced stresses ... in the topsoil, but load determined stresses ... in the subsoil,
    which supports the elasticity theory". The model (square plates, the stiff plate's pressure
    taken uniform, xi = 5) reproduces the trend: the small plate's stress is 1.9 x the large one's
    at 0.3 m and 1.3 x at 0.9 m, and twice the load gives twice the stress at every depth. (Their
    measured values, to test the magnitudes, are not in the abstract.)"""
    depths = (0.3, 0.5, 0.7, 0.9)

    def centre_stress(F_N, area_m2):
        side = math.sqrt(area_m2)
        T = S.build_tables(depths, 5.0, contact_length_m=side, track_width_m=side, track_gauge_m=10.0)
        geo = (side, side, 10.0, 0.0, 0.1, 0.2)
        a = _a(0.0, 0.0, 0.0, (F_N / area_m2, 0.0, 0.0, 0.0))  # the left "track" is the plate
        return S.stress_at(T, np.array([0.0]), np.array([5.0]), a, geo)[0]  # the left track's centre

    small, large, heavy = centre_stress(43e3, 0.45), centre_stress(43e3, 0.90), centre_stress(85e3, 0.45)
    area_effect = small / large  # measured: 1.86, 1.59, 1.38, 1.27 at 0.3 ... 0.9 m
    assert area_effect[0] > 1.5  # topsoil: halving the area nearly doubles the stress
    assert np.all(np.diff(area_effect) < 0) and area_effect[-1] < 1.3  # the area matters less with depth
    assert area_effect[0] - 1 > 2.5 * (area_effect[-1] - 1)
    assert np.allclose(heavy / small, 85 / 43, rtol=1e-9)  # the load sets the stress at every depth
    assert np.all(np.diff(small) < 0)  # the stress falls with depth


# (g) a soil layer on a rigid base ----------------------------------------------------------------
# The independent truth: PyMastic (M. Nakhaei, github.com/Mostafa-Nakhaei/PyMastic, a layered
# elastic program checked by its author against WESLEA and Kenpave), run for a uniform circle of
# q = 100 kPa and radius a on a layer of thickness h, nu = 0.5, bonded to a base 1e5 times stiffer
# (the rough rigid base), at z / h = 0.25, 0.5, 0.75, 0.9999, on the axis and at r = 1.5 a:
# (sigma_z on the axis, at 1.5 a), (mean normal stress on the axis, at 1.5 a), kPa.
PYMASTIC_ROUGH = {
    1.0: ((102.4871, 102.7804, 96.6995, 82.5338), (0.6986, 3.8235, 6.4926, 8.9544),
          (67.1732, 64.4340, 68.6785, 82.5179), (5.1720, 9.4781, 10.7070, 8.9573)),
    2.0: ((93.6657, 72.7207, 56.1493, 42.1135), (6.5819, 14.2368, 16.0644, 14.8386),
          (52.2909, 34.0143, 31.4563, 42.0983), (7.6922, 11.4302, 13.0779, 14.8371)),
}


@pytest.mark.parametrize("h_over_a", [1.0, 2.0])
def test_rigid_base_with_xi_3_is_the_elastic_layer_on_a_rough_base(h_over_a):
    """Concentration factor 3 over a rough rigid base: the vertical and the mean normal stress of a
    uniform circle are the elastic layer's (PyMastic) to 5e-5 of the surface pressure. The
    half-space's stress differs from them by up to 0.18 q (at the base, h = a), the smooth base's
    vertical stress by up to 0.14 q: the check sees the base, and which base."""
    from symtrack.vehicles import tyre

    a_m = 0.3
    H = h_over_a * a_m
    x, y, F = rigid_base.disc_point_forces(100.0, a_m)
    depths = tuple(f * H for f in (0.25, 0.5, 0.75, 0.9999))
    px, py = np.array([0.0, 1.5 * a_m]), np.zeros(2)
    sz, pm = tyre.footprint_stress_at_depth(x, y, F, px, py, depths, 3.0, rigid_base_depth_m=H)
    sz_axis, sz_off, p_axis, p_off = (np.array(v) for v in PYMASTIC_ROUGH[h_over_a])
    for got, want in ((sz[0], sz_axis), (sz[1], sz_off), (pm[0], p_axis), (pm[1], p_off)):
        assert np.max(np.abs(got - want)) < 5e-3, (got, want)
    half, _ = tyre.footprint_stress_at_depth(x, y, F, px, py, depths, 3.0)
    smooth, _ = tyre.footprint_stress_at_depth(x, y, F, px, py, depths, 3.0, rigid_base_depth_m=H,
                                               rigid_base_interface="smooth")
    assert np.max(np.abs(half - sz)) > 10.0 and np.max(np.abs(smooth - sz)) > 4.0
    # the half-space below the disc's centre is the closed form q (1 - cos^3 alpha)
    want_half = 100.0 * (1 - (np.array(depths) / np.hypot(a_m, depths)) ** 3)
    assert np.max(np.abs(half[0] - want_half)) < 5e-3


def test_a_rigid_base_far_below_is_the_half_space_and_none_is_todays_tables():
    T0 = S.build_tables((0.3, 0.6), 5.0, GEO[0], GEO[1], GEO[2])
    assert S.build_tables((0.3, 0.6), 5.0, GEO[0], GEO[1], GEO[2], rigid_base_depth_m=None).to_bytes() == \
        T0.to_bytes()
    deep = S.build_tables((0.3, 0.6), 5.0, GEO[0], GEO[1], GEO[2], rigid_base_depth_m=30.0)
    assert deep.key() != T0.key()
    a = _a(0.0, 0.0, 0.3, LINEAR)
    px, py = _world(a, *POINTS_BODY.T)
    s0, s_deep = S.stress_at(T0, px, py, a, GEO), S.stress_at(deep, px, py, a, GEO)
    assert np.max(np.abs(s_deep - s0)) < 2e-3 * np.max(s0)


def test_rigid_base_tables_against_bruteforce_and_what_the_base_does():
    """The tables with a rough base at 0.7 m against the brute-force sum with the same base (the
    table's interpolation error, < 1 % of the peak), for a 12 t track unit: the base raises the
    stress the more the deeper (elastic layer theory: the base concentrates the load)."""
    l_m, b_m = 1.9, 0.635
    geo = (l_m, b_m, b_m, 0.0, 0.1, 0.0)
    depths = (0.25, 0.4, 0.65)
    T = S.build_tables(depths, 5.0, l_m, b_m, b_m, rigid_base_depth_m=0.7)
    T0 = S.build_tables(depths, 5.0, l_m, b_m, b_m)
    a = _a(0.0, 0.0, 0.0, (97.5e3, -5e3, 0.0, 0.0))
    px, py = np.array([0.0, 0.6, -0.8, 0.3, 1.3]), np.array([0.32, 0.32, 0.5, 0.95, 0.32])
    tab, half = S.stress_at(T, px, py, a, geo), S.stress_at(T0, px, py, a, geo)
    for k, d in enumerate(depths):
        ref = S.stress_bruteforce(px, py, a, geo, d, 5.0, rigid_base_depth_m=0.7)
        assert np.max(np.abs(tab[:, k] - ref)) < 0.01 * ref.max(), (d, tab[:, k], ref)
    rise = tab[0] / half[0] - 1  # below the track's centre
    assert 0 < rise[0] < rise[1] < rise[2]


def test_rigid_base_refusals():
    with pytest.raises(ParameterError, match="below the rigid base"):
        S.build_tables((0.3, 0.8), 5.0, rigid_base_depth_m=0.7)
    with pytest.raises(ParameterError, match="rigid_base_interface"):
        S.build_tables((0.3,), 5.0, rigid_base_depth_m=0.7, rigid_base_interface="glued")
    with pytest.raises(ParameterError, match="rigid_base_depth_m"):
        S.stress_bruteforce([0.0], [0.0], _a(0, 0, 0, LINEAR), GEO, 0.3, 5.0, rigid_base_depth_m=-1.0)


def test_bessel_j0_is_abramowitz_and_stegun():
    special = pytest.importorskip("scipy.special")
    from symtrack.soil import rigid_base

    x = np.linspace(0.0, 400.0, 40001)
    assert np.max(np.abs(rigid_base.bessel_j0(x) - special.j0(x))) < 6e-8
