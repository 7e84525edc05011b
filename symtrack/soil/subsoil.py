"""Subsoil vertical stress under the tracks (Söhne / Fröhlich) and the compaction risk.

The model: docs/model.md, "Subsoil stress"; user documentation and sources in docs/subsoil.md.
numpy only: the terrain engine does the same lookup in C (symtrack/native/subsoil.h).

Stress propagation
------------------
A vertical point load Q at the surface gives at depth z and horizontal distance r

    sigma_z = xi Q cos^xi(theta) / (2 pi R^2),   R^2 = r^2 + z^2,  cos(theta) = z / R

(Fröhlich's concentration factor xi; xi = 3 is Boussinesq's elastic half-space), see
:func:`frohlich_point`. Each track k (left at body y = +B/2, right at -B/2) is a rigid l x b
rectangle whose contact pressure depends only on s, the distance behind the track's front end:
p_k(s) = max(0, alpha_k + beta_k s), s in [0, l], uniform across the width (the pressure line
of :func:`symtrack.native.grid_engine_model.pressure_line`). The pose and the pressure lines come
as the engine's ``a[8] = (X, Y, cos psi, sin psi, alpha_L, beta_L, alpha_R, beta_R)`` and
``geo[6] = (l, b, B, e, cell_m, end_strip_m)``; a world point (px, py) is in track k's frame at

    xb = c (px - X) + s (py - Y),  yb = -s (px - X) + c (py - Y),
    s_k = (l/2 - e) - xb,  t_k = yb -+ B/2

(:func:`symtrack.terrain.channels.build_cell_functions` and grid_engine.c's ``scan``).

The tables: strips summed at build time
---------------------------------------
Cut the track into strips of length ds' along s: the stress at a point is
sum_i p_k(s_i) T(s_k - s_i, t_k) with T the stress below a unit-pressure strip (ds' x b). With
2 n_s bilinear lookups per point and depth (~8 ns each, measured) that costs ~16 n_s ns; at the
engine's cell size (n_s = 24 on the reference crawler) ~10 times the 40 ns budget. Because p_k is linear on the loaded
part [s_a, s_b] of the track, the sum over strips can be done once, at build time, in the limit
ds' -> 0 (the prefix sums of the strip table): with K(u, t) the stress below a strip of unit
pressure, infinitesimal length du and width b (the Fröhlich kernel integrated across the width),

    H0(x, t) = int_0^x K(u, t) du     (odd in x),      H1(x, t) = int_0^x u K(u, t) du   (even in x),

and with p(s') = p_lin(s_k) - beta u, u = s_k - s', p_lin(s) = alpha + beta s,

    sigma_k = p_lin(s_k) [H0(x_a, t) - H0(x_b, t)] - beta [H1(x_a, t) - H1(x_b, t)],
    x_a = s_k - s_a,  x_b = s_k - s_b.

That is exact for the clamped line (no strip discretisation error); the only approximation is
the bilinear interpolation of H0, H1 on a grid per depth (x >= 0, t >= 0 by symmetry; step
proportional to the depth). Per point and depth: 4 bilinear lookups of an (H0, H1) pair.

The width integral is analytic up to a smooth 1-D integral: with A^2 = u^2 + d^2 and w = A tan(phi),
int dw / (A^2 + w^2)^((xi+2)/2) = A^-(xi+1) int cos^xi(phi) dphi, taken by Gauss-Legendre
(no singularity at any depth d > 0). The u integrals are composite Gauss-Legendre on the grid's
panels (panel <= depth / 4).

Range: x in [0, l + reach_m] (beyond: H saturates, i.e. the kernel's tail past l + reach is
dropped), t in [0, B + b/2 + reach_m] (beyond: 0). So a point within reach_m of the vehicle's
two-track rectangle gets the full superposition of both tracks. A shallow table stops earlier,
where the kernel's tail is below TAIL_FRACTION of the surface pressure.

The mean normal stress
----------------------
Fröhlich's point load gives a purely radial stress, sigma_r = xi Q cos^(xi-2)(theta) / (2 pi R^2)
(sigma_z = sigma_r cos^2(theta)); the trace of a radial stress is sigma_r, and traces add, so the
mean normal stress of any load is p = (1/3) sum sigma_r. Since xi cos^(xi-2) / (2 pi R^2) is
xi / (xi - 2) times the vertical kernel of concentration factor xi - 2,

    p(xi) = xi / (3 (xi - 2)) * sigma_z(xi - 2),

the same tables built with xi - 2 and scaled (:func:`build_mean_stress_tables`, :func:`stress_at`
on them gives p). Needs xi - 2 in XI_RANGE, i.e. xi >= 3. Below a wide uniform load p tends to
xi / (3 (xi - 2)) of the surface pressure (1 for xi = 3, 5/9 for xi = 5), below a point load to
sigma_z / 3.

A rigid base
------------
``rigid_base_depth_m`` (None: the half-space) puts a rigid base at depth H under a soil layer:
the stress below a point load is then Fröhlich's plus the base's correction d_sigma_z(r, z) of an
elastic layer on a rigid base, rough or smooth (:mod:`symtrack.soil.rigid_base`, docs/subsoil.md,
"A soil layer on a rigid base"). The tables fold it into K(u, t): its integral across the width
b by Gauss-Legendre (the correction is smooth on the scale 2H - d >= H) of the correction
interpolated on a radial grid. Depths must be <= H. The tables' reach keeps the correction's tail
(that of concentration factor 3) above TAIL_FRACTION.

Soil strength and risk
----------------------
Precompression stress from the pedotransfer function of Schjønning & Lamandé (2018)
(:func:`precompression_stress_kPa`) or given. Risk classes as Terranimo shows them (Stettler
et al. 2014): stress / strength < 0.5 low (0), 0.5..1.1 medium (1), > 1.1 high (2)
(:func:`risk_class`, :func:`risk_area_fractions`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np

from ..foundations.errors import ParameterError
from . import rigid_base
from .pedotransfer import SL2018

__all__ = ["DEFAULT_DEPTHS_M", "DEFAULT_REACH_M", "MEAN_STRESS_XI_MIN", "MEAN_T_STEP_PER_DEPTH",
           "MEAN_X_STEP_PER_DEPTH", "RISK_HIGH_ABOVE", "RISK_LOW_BELOW",
           "RISK_NAMES", "SubsoilTables", "XI_RANGE", "build_mean_stress_tables", "build_tables", "frohlich_point",
           "precompression_stress_kPa", "risk_area_fractions", "risk_class", "stress_at", "stress_bruteforce",
           "track_frame", "update_max"]

DEFAULT_DEPTHS_M = (0.1, 0.3, 0.5, 0.8)
DEFAULT_REACH_M = 0.5
# table steps as a fraction of the depth (along s, across t), measured in docs/subsoil.md: the
# lookup error stays below 0.5 % of the peak stress at every depth for xi in [3, 10] with these
DEFAULT_X_STEP_PER_DEPTH = 0.1
DEFAULT_T_STEP_PER_DEPTH = 0.05
XI_RANGE = (1.0, 10.0)
# Terranimo's classes of stress / strength (Stettler et al. 2014): low below, high above
RISK_LOW_BELOW = 0.5
RISK_HIGH_ABOVE = 1.1
RISK_NAMES = ("low", "medium", "high")

# a table stops where the kernel's tail (dropped beyond the last row, frozen beyond the last
# column) is below this fraction of the surface pressure: the bound of the tail of a half-plane
# load at distance D, c_xi (d / D)^xi, c_xi = sqrt(pi) Gamma((xi+1)/2) / (2 pi Gamma((xi+2)/2))
TAIL_FRACTION = 1e-4
_N_PHI = 32  # Gauss-Legendre nodes of the width integral in phi
_N_U = 8  # Gauss-Legendre nodes per panel of the u integrals
_SIDE = (1.0, -1.0)  # left, right: lateral sign of the track centre (body y = +-B/2)


def _check_range(name, value, lo, hi, lo_open=False):
    v = float(value)
    bad = not math.isfinite(v) or (v <= lo if lo_open else v < lo) or v > hi
    if bad:
        lo_s = f"({lo}" if lo_open else f"[{lo}"
        raise ParameterError(f"{name} = {value!r} is outside the allowed range {lo_s}, {hi}]")
    return v


def _check_xi(xi):
    return _check_range("xi (stress_concentration_factor)", xi, *XI_RANGE)


def _check_depths(depths_m):
    d = np.atleast_1d(np.asarray(depths_m, dtype=float))
    if d.ndim != 1 or d.size == 0:
        raise ParameterError(f"depths_m = {depths_m!r} must be a non-empty list of depths (m)")
    for v in d:
        _check_range("depth_m", v, 0.0, 10.0, lo_open=True)
    return d


def frohlich_point(Q_N, r_m, z_m, xi):
    """Vertical stress [Pa] at depth z_m and horizontal distance r_m from a vertical point load
    Q_N at the surface: xi Q cos^xi(theta) / (2 pi R^2), cos(theta) = z / R (Fröhlich; Söhne)."""
    xi = _check_xi(xi)
    z = np.asarray(z_m, dtype=float)
    if np.any(~(z > 0)):
        raise ParameterError(f"z_m = {z_m!r}: the depth must be > 0 m")
    R2 = np.asarray(r_m, dtype=float) ** 2 + z**2
    cos = z / np.sqrt(R2)
    return xi * np.asarray(Q_N, dtype=float) * cos**xi / (2 * np.pi * R2)


@dataclasses.dataclass(frozen=True)
class SubsoilTables:
    """The (H0, H1) tables of one vehicle geometry and concentration factor, one grid per depth,
    as the flat arrays of the C struct ``subsoil_tables_t`` (symtrack/native/subsoil.h).

    Depth k's grid: x_i = i * x_step_m[k] (i < n_x[k]), t_j = j * t_step_m[k] (j < n_t[k]);
    ``data[offset[k] + 2 * (i * n_t[k] + j) + (0 | 1)]`` = H0, H1 at (x_i, t_j)."""

    depth_m: np.ndarray  # float64 (n_depths,)
    x_step_m: np.ndarray  # float64 (n_depths,)
    t_step_m: np.ndarray  # float64 (n_depths,)
    n_x: np.ndarray  # int32 (n_depths,)
    n_t: np.ndarray  # int32 (n_depths,)
    offset: np.ndarray  # int64 (n_depths,): start of each depth's table in data (in doubles)
    inv_x_step: np.ndarray  # float64 (n_depths,): 1 / x_step_m (what C and _lookup multiply by)
    inv_t_step: np.ndarray  # float64 (n_depths,)
    data: np.ndarray  # float64
    xi: float
    contact_length_m: float
    track_width_m: float
    track_gauge_m: float
    reach_m: float
    rigid_base_depth_m: float | None = None  # the rigid base under the soil layer (None: a half-space)
    rigid_base_interface: str = "rough"  # rigid_base.INTERFACES; used only with a base

    @property
    def n_depths(self) -> int:
        return int(self.depth_m.size)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self.depth_m, self.x_step_m, self.t_step_m, self.n_x, self.n_t,
                                          self.offset, self.inv_x_step, self.inv_t_step, self.data)))

    def table(self, k: int) -> np.ndarray:
        """Depth k's table as an (n_x, n_t, 2) view."""
        n = int(self.n_x[k]) * int(self.n_t[k]) * 2
        o = int(self.offset[k])
        return self.data[o:o + n].reshape(int(self.n_x[k]), int(self.n_t[k]), 2)

    def to_bytes(self) -> bytes:
        """Everything that defines the tables, as bytes (for a cache key or a file)."""
        head = np.array([self.xi, self.contact_length_m, self.track_width_m, self.track_gauge_m, self.reach_m])
        if self.rigid_base_depth_m is not None:  # (a half-space's bytes are those of the tables before the base)
            head = np.append(head, [self.rigid_base_depth_m,
                                    rigid_base.INTERFACES.index(self.rigid_base_interface)])
        parts = (head, self.depth_m, self.x_step_m, self.t_step_m, self.n_x, self.n_t, self.offset, self.inv_x_step,
                 self.inv_t_step, self.data)
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    def key(self) -> str:
        """SHA-256 of :meth:`to_bytes`."""
        return hashlib.sha256(self.to_bytes()).hexdigest()

    def c_struct(self):
        """A ctypes ``subsoil_tables_t`` pointing into these arrays (keep this object alive while C
        uses it)."""
        import ctypes

        class _T(ctypes.Structure):
            _fields_ = [("n_depths", ctypes.c_int), ("inv_x_step", ctypes.POINTER(ctypes.c_double)),
                        ("inv_t_step", ctypes.POINTER(ctypes.c_double)), ("n_x", ctypes.POINTER(ctypes.c_int)),
                        ("n_t", ctypes.POINTER(ctypes.c_int)), ("offset", ctypes.POINTER(ctypes.c_longlong)),
                        ("data", ctypes.POINTER(ctypes.c_double))]

        def ptr(a, ct):
            return a.ctypes.data_as(ctypes.POINTER(ct))

        return _T(self.n_depths, ptr(self.inv_x_step, ctypes.c_double), ptr(self.inv_t_step, ctypes.c_double),
                  ptr(self.n_x, ctypes.c_int), ptr(self.n_t, ctypes.c_int), ptr(self.offset, ctypes.c_longlong),
                  ptr(self.data, ctypes.c_double))


def _strip_kernel(u, t, d, b, xi, phi_nodes, phi_weights):
    """K(u, t): vertical stress at depth d below (u, t) from a strip of unit pressure, width b
    (|v| <= b/2) and infinitesimal length du, per unit du. u: (nu,), t: (nt,) -> (nu, nt)."""
    A = np.sqrt(u[:, None] ** 2 + d * d)  # (nu, 1)
    phi2 = np.arctan((t[None, :] + b / 2) / A)
    phi1 = np.arctan((t[None, :] - b / 2) / A)
    half = 0.5 * (phi2 - phi1)
    mid = 0.5 * (phi2 + phi1)
    cosx = np.cos(mid[..., None] + half[..., None] * phi_nodes) ** xi  # (nu, nt, n_phi)
    integral = half * (cosx @ phi_weights)
    return xi * d**xi / (2 * np.pi) * A ** (-xi - 1) * integral


def _grid(extent_m, step_m):
    n = max(int(math.ceil(extent_m / step_m - 1e-9)), 1) + 1
    return n, extent_m / (n - 1)


def _check_base(rigid_base_depth_m, rigid_base_interface, depths):
    """The rigid base's depth (None: a half-space) and interface, checked against the depths."""
    if rigid_base_depth_m is None:
        return None, "rough"
    H = _check_range("rigid_base_depth_m", rigid_base_depth_m, 0.0, 100.0, lo_open=True)
    if rigid_base_interface not in rigid_base.INTERFACES:
        raise ParameterError(f"rigid_base_interface = {rigid_base_interface!r} is not one of "
                             f"{', '.join(rigid_base.INTERFACES)}")
    below = [float(d) for d in np.atleast_1d(depths) if d > H * (1 + 1e-12)]
    if below:
        raise ParameterError(f"depths {below} are below the rigid base at rigid_base_depth_m = {H}: the stress is "
                             "defined in the soil layer only")
    return H, rigid_base_interface


def _strip_base_correction(u, t, b, r_grid, dz_grid, v_nodes, v_weights):
    """The rigid base's correction to K(u, t) (:func:`_strip_kernel`): the point correction
    tabulated on r_grid integrated across the width b (|v| <= b/2) at the nodes v_nodes."""
    r = np.sqrt(u[:, None, None] ** 2 + (t[None, :, None] - v_nodes[None, None, :]) ** 2)
    return np.interp(r, r_grid, dz_grid) @ v_weights


def _width_nodes(b, length_scale):
    """Gauss-Legendre nodes and weights across [-b/2, b/2] on panels <= length_scale / 4."""
    g, w = np.polynomial.legendre.leggauss(_N_U)
    n = max(1, int(math.ceil(b / (length_scale / 4))))
    edges = np.linspace(-b / 2, b / 2, n + 1)
    h = edges[1] - edges[0]
    return (edges[:-1, None] + 0.5 * h * (1 + g[None, :])).ravel(), np.tile(0.5 * h * w, n)


def build_tables(depths_m=DEFAULT_DEPTHS_M, xi=5.0, contact_length_m=2.4, track_width_m=0.45, track_gauge_m=1.5,
                 reach_m=DEFAULT_REACH_M, x_step_per_depth=DEFAULT_X_STEP_PER_DEPTH,
                 t_step_per_depth=DEFAULT_T_STEP_PER_DEPTH, rigid_base_depth_m=None,
                 rigid_base_interface="rough") -> SubsoilTables:
    """The (H0, H1) tables (module doc) at each depth for concentration factor xi and the track
    geometry l = contact_length_m, b = track_width_m, B = track_gauge_m. Grid steps
    x_step_per_depth * depth along s, t_step_per_depth * depth across. ``rigid_base_depth_m``: a
    rigid base under the soil layer, ``rigid_base_interface`` "rough" or "smooth" (module doc, "A
    rigid base"; None: a half-space)."""
    d_all = _check_depths(depths_m)
    H_base, interface = _check_base(rigid_base_depth_m, rigid_base_interface, d_all)
    xi = _check_xi(xi)
    l_m = _check_range("contact_length_m", contact_length_m, 0.0, 20.0, lo_open=True)
    b_m = _check_range("track_width_m", track_width_m, 0.0, 5.0, lo_open=True)
    B_m = _check_range("track_gauge_m", track_gauge_m, 0.0, 10.0, lo_open=True)
    if B_m < b_m:
        raise ParameterError(f"track_gauge_m = {B_m} must be >= track_width_m = {b_m} (the tracks would overlap)")
    reach = _check_range("reach_m", reach_m, 0.0, 20.0)
    fx = _check_range("x_step_per_depth", x_step_per_depth, 0.0, 2.0, lo_open=True)
    ft = _check_range("t_step_per_depth", t_step_per_depth, 0.0, 2.0, lo_open=True)
    phi_nodes, phi_weights = np.polynomial.legendre.leggauss(_N_PHI)
    u_nodes, u_weights = np.polynomial.legendre.leggauss(_N_U)
    x_full, t_full = l_m + reach, B_m + b_m / 2 + reach
    # beyond D the kernel's tail is below TAIL_FRACTION of the surface pressure (module doc)
    c_xi = math.sqrt(math.pi) * math.gamma((xi + 1) / 2) / (2 * math.pi * math.gamma((xi + 2) / 2))
    tail_per_depth = (c_xi / TAIL_FRACTION) ** (1.0 / xi)
    if H_base is not None:  # the base's correction has the tail of concentration factor 3
        c3 = math.sqrt(math.pi) * math.gamma(2.0) / (2 * math.pi * math.gamma(2.5))
        tail_per_depth = max(tail_per_depth, (c3 / TAIL_FRACTION) ** (1.0 / 3.0))
    steps_x, steps_t, nxs, nts, offs, blocks = [], [], [], [], [], []
    off = 0
    for d in d_all:
        n_x, dx = _grid(min(x_full, tail_per_depth * d), fx * d)
        n_t, dt = _grid(min(t_full, b_m / 2 + tail_per_depth * d), ft * d)
        # panels of the u integral: the grid's intervals, cut to <= d/4
        sub = max(1, int(math.ceil(dx / (d / 4))))
        t = np.arange(n_t) * dt
        if H_base is not None:
            r_grid, dz_grid, _ = rigid_base.correction_profile(
                d, H_base, math.hypot((n_x - 1) * dx, (n_t - 1) * dt + b_m / 2) + 1e-9, interface)
            v_nodes, v_weights = _width_nodes(b_m, 2 * H_base - d)
        H = np.zeros((n_x, n_t, 2))
        for i in range(n_x - 1):
            a0 = i * dx
            h = dx / sub
            lo = a0 + h * np.arange(sub)
            u = (lo[:, None] + 0.5 * h * (1 + u_nodes[None, :])).ravel()
            w = np.tile(0.5 * h * u_weights, sub)
            K = _strip_kernel(u, t, d, b_m, xi, phi_nodes, phi_weights)
            if H_base is not None:
                K = K + _strip_base_correction(u, t, b_m, r_grid, dz_grid, v_nodes, v_weights)
            H[i + 1, :, 0] = H[i, :, 0] + w @ K
            H[i + 1, :, 1] = H[i, :, 1] + (w * u) @ K
        steps_x.append(dx)
        steps_t.append(dt)
        nxs.append(n_x)
        nts.append(n_t)
        offs.append(off)
        blocks.append(H.ravel())
        off += H.size
    steps_x, steps_t = np.array(steps_x), np.array(steps_t)
    return SubsoilTables(depth_m=d_all.copy(), x_step_m=steps_x, t_step_m=steps_t, inv_x_step=1.0 / steps_x,
                         inv_t_step=1.0 / steps_t,
                         n_x=np.array(nxs, dtype=np.int32), n_t=np.array(nts, dtype=np.int32),
                         offset=np.array(offs, dtype=np.int64), data=np.concatenate(blocks), xi=xi,
                         contact_length_m=l_m, track_width_m=b_m, track_gauge_m=B_m, reach_m=reach,
                         rigid_base_depth_m=H_base, rigid_base_interface=interface)


MEAN_STRESS_XI_MIN = XI_RANGE[0] + 2.0
# the mean normal stress tables' steps per depth: twice the vertical stress's (its kernel, of xi - 2,
# is smoother): a quarter of the memory (248 instead of 964 KiB at xi = 5, the reference crawler),
# about a third less time per lookup, the interpolation error 0.2-0.7 % of the depth's peak instead
# of 0.07-0.19 % (measured against steps of 0.03 d; docs/subsoil.md "Bulk density")
MEAN_X_STEP_PER_DEPTH = 2 * DEFAULT_X_STEP_PER_DEPTH
MEAN_T_STEP_PER_DEPTH = 2 * DEFAULT_T_STEP_PER_DEPTH


def build_mean_stress_tables(depths_m=DEFAULT_DEPTHS_M, xi=5.0, contact_length_m=2.4, track_width_m=0.45,
                             track_gauge_m=1.5, reach_m=DEFAULT_REACH_M) -> SubsoilTables:
    """Tables whose lookup (:func:`stress_at`, subsoil.h) gives the mean normal stress
    p = (sigma_x + sigma_y + sigma_z) / 3 of Fröhlich's radial stress field for concentration
    factor xi (module doc): the vertical-stress tables of xi - 2 scaled by xi / (3 (xi - 2)).
    Their ``xi`` field is the tables' exponent, xi - 2; their steps MEAN_X_STEP_PER_DEPTH and
    MEAN_T_STEP_PER_DEPTH. xi must be in [3, 10]."""
    xi = _check_range("xi (stress_concentration_factor, for the mean normal stress)", xi, MEAN_STRESS_XI_MIN,
                      XI_RANGE[1])
    T = build_tables(depths_m, xi - 2.0, contact_length_m, track_width_m, track_gauge_m, reach_m,
                     MEAN_X_STEP_PER_DEPTH, MEAN_T_STEP_PER_DEPTH)
    return dataclasses.replace(T, data=T.data * (xi / (3.0 * (xi - 2.0))))


def _lookup(T: SubsoilTables, k: int, x, t):
    """(H0, H1) at depth k for arrays x, t: bilinear on (|x|, |t|), H0 odd in x, H1 even; |x| past
    the grid saturates, |t| past it gives 0. The same operations, in the same order, as subsoil.h."""
    n_x, n_t = int(T.n_x[k]), int(T.n_t[k])
    tab = T.table(k)
    ux = np.minimum(np.abs(x) * T.inv_x_step[k], float(n_x - 1))
    ut = np.abs(t) * T.inv_t_step[k]
    inside = ut < n_t - 1
    ut = np.where(inside, ut, 0.0)
    i = np.minimum(ux.astype(np.int64), n_x - 2)
    j = np.minimum(ut.astype(np.int64), n_t - 2)
    fx = ux - i
    ft = ut - j
    v00, v01, v10, v11 = tab[i, j], tab[i, j + 1], tab[i + 1, j], tab[i + 1, j + 1]
    gx, gt = (1.0 - fx)[:, None], (1.0 - ft)[:, None]
    fx, ft = fx[:, None], ft[:, None]
    v = gx * (gt * v00 + ft * v01) + fx * (gt * v10 + ft * v11)
    sign = np.where(x < 0, -1.0, 1.0)
    h0 = np.where(inside, sign * v[:, 0], 0.0)
    h1 = np.where(inside, v[:, 1], 0.0)
    return h0, h1


def _check_geo(T: SubsoilTables, geo):
    l_m, b_m, B_m = float(geo[0]), float(geo[1]), float(geo[2])
    for name, got, want in (("l", l_m, T.contact_length_m), ("b", b_m, T.track_width_m),
                            ("B", B_m, T.track_gauge_m)):
        if abs(got - want) > 1e-9 * max(1.0, abs(want)):
            raise ParameterError(f"geo {name} = {got} differs from the tables' {want}: rebuild the tables "
                                 f"(build_tables) for this vehicle")


def _active(alpha, beta, l_m):
    """The loaded part [s_a, s_b] of [0, l] for p = max(0, alpha + beta s); None when unloaded."""
    if beta == 0.0:
        return (0.0, l_m) if alpha > 0.0 else None
    s0 = -alpha / beta
    sa, sb = (0.0, min(l_m, s0)) if beta < 0.0 else (max(0.0, s0), l_m)
    return (sa, sb) if sb > sa else None


def track_frame(px, py, a, geo):
    """(s, t_left, t_right) of world points: s behind the tracks' front end, t across each track
    from its centre line (module doc; the frame of channels.build_cell_functions)."""
    px = np.atleast_1d(np.asarray(px, dtype=float))
    py = np.atleast_1d(np.asarray(py, dtype=float))
    X, Y, c, s = (float(v) for v in a[:4])
    l_m, B_m, e_m = float(geo[0]), float(geo[2]), float(geo[3])
    ddx, ddy = px - X, py - Y
    xb = c * ddx + s * ddy
    yb = -s * ddx + c * ddy
    return (l_m / 2 - e_m) - xb, yb - _SIDE[0] * B_m / 2, yb - _SIDE[1] * B_m / 2


def stress_at(T: SubsoilTables, px, py, a, geo) -> np.ndarray:
    """Vertical stress [Pa], shape (n_points, n_depths), at the world points (px, py) at the
    tables' depths, from both tracks with the engine's a[8] and geo[6] (module doc)."""
    _check_geo(T, geo)
    l_m = float(geo[0])
    s_pt, t_left, t_right = track_frame(px, py, a, geo)
    out = np.zeros((s_pt.size, T.n_depths))
    for t, (alpha, beta) in zip((t_left, t_right), ((float(a[4]), float(a[5])), (float(a[6]), float(a[7]))),
                                strict=True):
        act = _active(alpha, beta, l_m)
        if act is None:
            continue
        p_lin = alpha + beta * s_pt
        xa, xe = s_pt - act[0], s_pt - act[1]
        for k in range(T.n_depths):
            h0a, h1a = _lookup(T, k, xa, t)
            h0b, h1b = _lookup(T, k, xe, t)
            out[:, k] += p_lin * (h0a - h0b) - beta * (h1a - h1b)
    return out


def stress_bruteforce(px, py, a, geo, depth_m, xi, n_per_depth=4, n_gauss=4, rigid_base_depth_m=None,
                      rigid_base_interface="rough") -> np.ndarray:
    """Independent reference for :func:`stress_at` (tests): :func:`frohlich_point` summed over both
    contact rectangles by composite Gauss-Legendre in (s, t) with panels <= depth / n_per_depth
    and the s-range cut at the kink of the clamped pressure line; with ``rigid_base_depth_m`` each
    point load also carries the base's correction (:func:`symtrack.soil.rigid_base.point_correction`,
    interpolated on its radial profile). Returns (n_points,) [Pa]."""
    d = _check_range("depth_m", depth_m, 0.0, 10.0, lo_open=True)
    xi = _check_xi(xi)
    H_base, interface = _check_base(rigid_base_depth_m, rigid_base_interface, [d])
    px = np.atleast_1d(np.asarray(px, dtype=float))
    py = np.atleast_1d(np.asarray(py, dtype=float))
    X, Y, c, s = (float(v) for v in a[:4])
    l_m, b_m, B_m, e_m = (float(v) for v in geo[:4])
    g_nodes, g_weights = np.polynomial.legendre.leggauss(n_gauss)
    h_max = d / n_per_depth

    def composite(lo, hi):
        n = max(1, int(math.ceil((hi - lo) / h_max)))
        h = (hi - lo) / n
        starts = lo + h * np.arange(n)
        return ((starts[:, None] + 0.5 * h * (1 + g_nodes)).ravel(), np.tile(0.5 * h * g_weights, n))

    out = np.zeros(px.size)
    for side, (alpha, beta) in zip(_SIDE, ((float(a[4]), float(a[5])), (float(a[6]), float(a[7]))), strict=True):
        cuts = [0.0, l_m]
        if beta != 0.0 and 0.0 < -alpha / beta < l_m:
            cuts = [0.0, -alpha / beta, l_m]
        ss, ws = zip(*(composite(cuts[i], cuts[i + 1]) for i in range(len(cuts) - 1)), strict=True)
        ss, ws = np.concatenate(ss), np.concatenate(ws)
        p = np.maximum(0.0, alpha + beta * ss)
        tt, wt = composite(-b_m / 2, b_m / 2)
        # the load element's world position: body x = (l/2 - e) - s, body y = side B/2 + t
        bx = (l_m / 2 - e_m) - ss[:, None] + 0.0 * tt[None, :]
        by = side * B_m / 2 + tt[None, :] + 0.0 * ss[:, None]
        wx = X + c * bx - s * by
        wy = Y + s * bx + c * by
        Q = (p * ws)[:, None] * wt[None, :]
        if H_base is not None:
            reach = math.hypot(float(np.ptp(np.concatenate([wx.ravel(), px]))),
                               float(np.ptp(np.concatenate([wy.ravel(), py]))))
            r_grid, dz_grid, _ = rigid_base.correction_profile(d, H_base, reach + 1e-9, interface)
        for n in range(px.size):
            r = np.sqrt((wx - px[n]) ** 2 + (wy - py[n]) ** 2)
            out[n] += float(np.sum(frohlich_point(Q, r, d, xi)))
            if H_base is not None:
                out[n] += float(np.sum(Q * np.interp(r, r_grid, dz_grid)))
    return out


def update_max(sigma_max, cells, sigma):
    """sigma_max[cells[n], :] = max(sigma_max[cells[n], :], sigma[n, :]) in place (repeated cells
    allowed); returns sigma_max."""
    np.maximum.at(sigma_max, np.asarray(cells, dtype=np.int64), np.asarray(sigma, dtype=float))
    return sigma_max


# Schjønning & Lamandé's (2018) coefficients: their one home is symtrack/soil/pedotransfer.py
PTF_SL2018 = SL2018


def precompression_stress_kPa(bulk_density_Mg_m3, matric_suction_hPa, clay_kg_kg):
    """Precompression stress sigma_pc [kPa] from the pedotransfer function of Schjønning &
    Lamandé (2018): sigma_pc = (-26.51 + 25.57 rho_b - 20.40 clay + 10.26 clay pF)^2, pF =
    log10(matric suction / hPa), clay as a mass fraction (kg/kg), rho_b in Mg/m^3; 0 where the
    bracket is negative. docs/subsoil.md says where the coefficients come from."""
    rho = np.asarray(bulk_density_Mg_m3, dtype=float)
    h = np.asarray(matric_suction_hPa, dtype=float)
    clay = np.asarray(clay_kg_kg, dtype=float)
    if np.any(~((rho > 0.5) & (rho < 2.65))):
        raise ParameterError(f"bulk_density_Mg_m3 = {bulk_density_Mg_m3!r} is outside the allowed range (0.5, 2.65)")
    if np.any(~((h >= 1.0) & (h <= 1e7))):
        raise ParameterError(f"matric_suction_hPa = {matric_suction_hPa!r} is outside the allowed range [1, 1e7] "
                             f"(pF 0..7)")
    if np.any(~((clay >= 0.0) & (clay <= 1.0))):
        raise ParameterError(f"clay_kg_kg = {clay_kg_kg!r} is outside the allowed range [0, 1] (a mass fraction, "
                             f"not %)")
    c = PTF_SL2018
    root = c["c0"] + c["c_rho"] * rho + c["c_clay"] * clay + c["c_clay_pF"] * clay * np.log10(h)
    return np.maximum(root, 0.0) ** 2


def risk_class(sigma, sigma_pc) -> np.ndarray:
    """Terranimo's risk class of stress / strength: 0 (low) below 0.5, 1 (medium) from 0.5 to 1.1
    (both included), 2 (high) above 1.1. sigma and sigma_pc in the same unit, broadcast."""
    sigma = np.asarray(sigma, dtype=float)
    pc = np.asarray(sigma_pc, dtype=float)
    if np.any(~(pc > 0)):
        raise ParameterError(f"sigma_pc = {sigma_pc!r}: the precompression stress must be > 0")
    ratio = sigma / pc
    return np.where(ratio < RISK_LOW_BELOW, 0, np.where(ratio > RISK_HIGH_ABOVE, 2, 1)).astype(np.int8)


def risk_area_fractions(sigma_max, sigma_pc, touched_mask, cell_area_m2) -> dict:
    """Area of each risk class at each depth over the touched cells.

    sigma_max (n_cells, n_depths); sigma_pc broadcast against it (a scalar, per depth
    (n_depths,), or per cell and depth); touched_mask (n_cells,) bool. Returns
    ``touched_area_m2`` and, per class name of :data:`RISK_NAMES`, ``fraction_<name>`` and
    ``area_<name>_m2`` (arrays over the depths); fractions are 0 when nothing was touched."""
    sm = np.asarray(sigma_max, dtype=float)
    if sm.ndim != 2:
        raise ParameterError(f"sigma_max has shape {sm.shape}; expected (n_cells, n_depths)")
    mask = np.asarray(touched_mask, dtype=bool).ravel()
    if mask.size != sm.shape[0]:
        raise ParameterError(f"touched_mask has {mask.size} cells, sigma_max {sm.shape[0]}")
    area = _check_range("cell_area_m2", cell_area_m2, 0.0, 1e6, lo_open=True)
    cls = risk_class(sm, np.broadcast_to(np.asarray(sigma_pc, dtype=float), sm.shape))[mask]
    n = int(mask.sum())
    out = {"touched_area_m2": n * area}
    for k, name in enumerate(RISK_NAMES):
        count = (cls == k).sum(axis=0).astype(float)
        out[f"area_{name}_m2"] = count * area
        out[f"fraction_{name}"] = count / n if n else np.zeros(sm.shape[1])
    return out
