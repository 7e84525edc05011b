"""A soil layer on a rigid base: the change a rigid base at depth H makes to the stress of a
surface load (docs/subsoil.md, "A soil layer on a rigid base"). numpy only.

The elastic layer
-----------------
An elastic layer of thickness H on a rigid base, loaded at its free surface, is Burmister's (1945)
layered problem with a rigid lower layer; Poulos & Davis (1974, chapter 3) tabulate it for uniform
circles and strips. With Love's stress function phi = J0(k r) F(k z) (Timoshenko & Goodier 1951,
*Theory of Elasticity*, axisymmetric problems), z downward, s = k z, h = k H and F a solution of
(d^2/ds^2 - 1)^2 F = 0, the vertical stress, the trace of the stress (sigma_r + sigma_theta +
sigma_z), the shear stress and the displacements per wave number k are, up to powers of k,

    S_z = (1 - nu) F''' - (2 - nu) F',      S_tr = (1 + nu) (F''' - F'),
    tau = nu F'' + (1 - nu) F,               w = (1 - 2 nu) F'' - 2 (1 - nu) F,      u = F'.

The conditions: at the surface s = 0, S_z = 1 (the load's transform; compression positive) and
tau = 0; at the base s = h, w = 0 and either u = 0 (a **rough** base: the soil does not slip on
it) or tau = 0 (a **smooth** base). Solving the four conditions for F's four coefficients gives
the transfer functions S_z(s; h) and S_tr(s; h) (:func:`transfer`); a vertical point force Q at
the surface then gives

    sigma_z(r, z) = Q / (2 pi) int_0^inf k S_z(k z; k H) J0(k r) dk

and the same with S_tr for the trace. As H -> inf, S_z -> (1 + s) e^-s and S_tr -> 2 (1 + nu) e^-s
(Boussinesq's half-space). The package keeps the half-space's stress and adds the base's
**correction**, the difference of the two,

    d_sigma_z(r, z) = Q / (2 pi) int_0^inf k [S_z(k z; k H) - (1 + k z) e^-kz] J0(k r) dk,

a smooth field (its kernel decays as e^-k(2H - z)) that carries no net force across any horizontal
plane (the k = 0 term is zero): the load still reaches the base whole, more of it under the load
and less far from it. :func:`correction_profile` computes it on a radial grid per depth, for
:func:`symtrack.soil.subsoil.build_tables`, :func:`symtrack.soil.subsoil.stress_bruteforce` and
:func:`symtrack.vehicles.tyre.footprint_stress_at_depth`.

Poisson's ratio: Boussinesq's stress field is purely radial, as Fröhlich's is, only for
nu = 1/2 (the circumferential stress (1 - 2 nu) Q / (2 pi) [z / R^3 - 1 / (R (R + z))] vanishes
then), so Fröhlich's concentration factor 3 is the incompressible elastic half-space; the
correction uses nu = 1/2 (:data:`POISSON_RATIO`). With concentration factor 3 the package's
stress above a rigid base is then the elastic layer's exactly (tests/test_subsoil.py checks it
against a layered elastic program); for other concentration factors the elastic correction is
added to Fröhlich's half-space stress, an approximation (no solution of Fröhlich's model on a
rigid base was found in the literature).

Numerics: the k integral is composite Gauss-Legendre in kappa = k H on [0, KAPPA_MAX / (2 - z / H)]
(the kernel is below 1e-14 of its size beyond), panels short enough for J0's oscillation at the
largest radius asked; J0 from Abramowitz & Stegun (1964) 9.4.1 and 9.4.3 (error below 5e-8).
The transfer functions are solved in the basis e^(s-h), s e^(s-h), e^-s, s e^-s for h >= 1 and
cosh s, sinh s, s sinh s, s cosh s - sinh s (well conditioned as h -> 0) below.
"""

from __future__ import annotations

import math

import numpy as np

from ..foundations.errors import ParameterError

__all__ = ["INTERFACES", "POISSON_RATIO", "bessel_j0", "correction_profile", "disc_point_forces", "point_correction",
           "transfer"]

INTERFACES = ("rough", "smooth")
POISSON_RATIO = 0.5  # the incompressible layer of Fröhlich's concentration factor 3 (module doc)
KAPPA_MAX = 40.0  # the k integral's end in k (2H - z): e^-40 (times a cubic) is below 1e-14
_N_GAUSS = 8
_BASIS_SWITCH_H = 1.0

# Abramowitz & Stegun (1964), Handbook of Mathematical Functions, 9.4.1 (|x| <= 3) and 9.4.3 (x >= 3)
_J0_SMALL = (1.0, -2.2499997, 1.2656208, -0.3163866, 0.0444479, -0.0039444, 0.0002100)
_J0_F0 = (0.79788456, -0.00000077, -0.00552740, -0.00009512, 0.00137237, -0.00072805, 0.00014476)
_J0_THETA0 = (-0.78539816, -0.04166397, -0.00003954, 0.00262573, -0.00054125, -0.00029333, 0.00013558)


def bessel_j0(x) -> np.ndarray:
    """J0(x), the Bessel function of the first kind of order 0, by Abramowitz & Stegun 9.4.1 and
    9.4.3 (absolute error below 5e-8)."""
    x = np.abs(np.asarray(x, dtype=float))
    small = x <= 3.0
    out = np.empty_like(x)
    y = (x[small] / 3.0) ** 2
    out[small] = np.polyval(_J0_SMALL[::-1], y)
    xl = x[~small]
    t = 3.0 / xl
    f0 = np.polyval(_J0_F0[::-1], t)
    theta = xl + np.polyval(_J0_THETA0[::-1], t)
    out[~small] = f0 * np.cos(theta) / np.sqrt(xl)
    return out


def _check_interface(interface: str) -> str:
    if interface not in INTERFACES:
        raise ParameterError(f"rigid_base_interface = {interface!r} is not one of {', '.join(INTERFACES)}")
    return interface


def _basis(s, h, large):
    """F and its first three derivatives (4, 4, ...) for the four basis functions at s (module doc)."""
    if large:
        e1, e2 = np.exp(s - h), np.exp(-s)
        F = (e1, s * e1, e2, s * e2)
        F1 = (e1, (1 + s) * e1, -e2, (1 - s) * e2)
        F2 = (e1, (2 + s) * e1, e2, (s - 2) * e2)
        F3 = (e1, (3 + s) * e1, -e2, (3 - s) * e2)
    else:
        c, sh = np.cosh(s), np.sinh(s)
        F = (c, sh, s * sh, s * c - sh)
        F1 = (sh, c, sh + s * c, s * sh)
        F2 = (c, sh, 2 * c + s * sh, sh + s * c)
        F3 = (sh, c, 3 * sh + s * c, 2 * c + s * sh)
    return [np.stack(np.broadcast_arrays(*v), axis=-1) for v in (F, F1, F2, F3)]


def transfer(s, h, interface: str = "rough", nu: float = POISSON_RATIO):
    """(S_z, S_tr): the vertical stress and the trace of the stress per unit surface pressure at
    s = k z of the wave number k in a layer of h = k H over a rigid base (module doc). s, h
    broadcast; 0 <= s <= h."""
    _check_interface(interface)
    s, h = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(h, dtype=float))
    sz, tr = np.empty(s.shape), np.empty(s.shape)
    for large in (True, False):
        m = (h >= _BASIS_SWITCH_H) if large else (h < _BASIS_SWITCH_H)
        if not np.any(m):
            continue
        hm, sm = h[m], s[m]
        F0, F10, F20, F30 = _basis(np.zeros_like(hm), hm, large)
        Fh, F1h, F2h, F3h = _basis(hm, hm, large)
        rows = [(1 - nu) * F30 - (2 - nu) * F10,  # S_z(0) = 1
                nu * F20 + (1 - nu) * F0,  # tau(0) = 0
                (1 - 2 * nu) * F2h - 2 * (1 - nu) * Fh]  # w(h) = 0
        rows.append(F1h if interface == "rough" else nu * F2h + (1 - nu) * Fh)  # u(h) = 0 | tau(h) = 0
        A = np.stack(rows, axis=-2)
        rhs = np.zeros(hm.shape + (4, 1))
        rhs[..., 0, 0] = 1.0
        coef = np.linalg.solve(A, rhs)[..., 0]
        _, F1, _, F3 = _basis(sm, hm, large)
        sz[m] = np.sum(((1 - nu) * F3 - (2 - nu) * F1) * coef, axis=-1)
        tr[m] = np.sum((1 + nu) * (F3 - F1) * coef, axis=-1)
    return sz, tr


def _check_depth(z_m, base_depth_m):
    H = float(base_depth_m)
    if not (math.isfinite(H) and 0.0 < H <= 100.0):
        raise ParameterError(f"rigid_base_depth_m = {base_depth_m!r} is outside the allowed range (0, 100]")
    z = float(z_m)
    if not (0.0 < z <= H * (1.0 + 1e-12)):
        raise ParameterError(f"depth_m = {z_m!r} is below the rigid base at rigid_base_depth_m = {H} (or <= 0): "
                             "the stress is defined in the soil layer only")
    return min(z, H), H


def point_correction(r_m, z_m, base_depth_m, interface: str = "rough", nu: float = POISSON_RATIO):
    """The rigid base's correction to the vertical stress and to the mean normal stress [1/m^2, per
    newton of a vertical point force at the surface] at horizontal distances r_m and depth z_m
    (module doc): (d_sigma_z, d_p) with d_p = d(sigma_r + sigma_theta + sigma_z) / 3."""
    z, H = _check_depth(z_m, base_depth_m)
    _check_interface(interface)
    r = np.atleast_1d(np.asarray(r_m, dtype=float))
    rho_max = float(np.max(r)) / H if r.size else 0.0
    zeta = z / H
    kappa_end = KAPPA_MAX / (2.0 - zeta)
    # panels: J0(kappa rho) has period 2 pi / rho; a panel half of that (and <= 2) with 8 nodes
    width = min(2.0, math.pi / max(rho_max, 1e-9))
    n = max(8, int(math.ceil(kappa_end / width)))
    g, w = np.polynomial.legendre.leggauss(_N_GAUSS)
    edges = np.linspace(0.0, kappa_end, n + 1)
    kappa = (0.5 * (edges[:-1, None] + edges[1:, None]) + 0.5 * (edges[1] - edges[0]) * g[None, :]).ravel()
    wk = np.tile(0.5 * (edges[1] - edges[0]) * w, n)
    sz, tr = transfer(kappa * zeta, kappa, interface, nu)
    s = kappa * zeta
    d_sz = kappa * (sz - (1.0 + s) * np.exp(-s)) * wk
    d_tr = kappa * (tr - 2.0 * (1.0 + nu) * np.exp(-s)) * wk
    out_z, out_p = np.empty(r.shape), np.empty(r.shape)
    flat = r.ravel()
    for a in range(0, flat.size, 512):
        J = bessel_j0(np.outer(flat[a:a + 512] / H, kappa))
        out_z.ravel()[a:a + 512] = J @ d_sz
        out_p.ravel()[a:a + 512] = J @ d_tr
    scale = 1.0 / (2.0 * math.pi * H * H)
    return out_z * scale, out_p * (scale / 3.0)


def correction_profile(z_m, base_depth_m, r_max_m, interface: str = "rough"):
    """(r_m, d_sigma_z, d_p): :func:`point_correction` on a radial grid from 0 to r_max_m with
    steps of (2 H - z) / 100 (the correction's smallest length scale is 2 H - z >= H; linear
    interpolation on it is accurate to about 1e-4 of the correction's peak)."""
    z, H = _check_depth(z_m, base_depth_m)
    step = (2.0 * H - z) / 100.0
    n = max(2, int(math.ceil(float(r_max_m) / step)) + 1)
    r = np.arange(n) * step
    dz, dp = point_correction(r, z, H, interface)
    return r, dz, dp


def disc_point_forces(q_kPa: float, radius_m: float, radial: int = 24, angular: int = 12):
    """A uniform circular load of ``q_kPa`` on a disc of ``radius_m`` cut into vertical point forces by
    polar Gauss-Legendre (8 points in each of ``radial`` rings and ``angular`` sectors): (x, y) [m] and
    the forces [kN], for the point-load stress sums (:func:`symtrack.vehicles.tyre.footprint_stress_at_depth`,
    :func:`symtrack.soil.subsoil.stress_bruteforce`) checked against the elastic layer's uniform circle."""
    g, w = np.polynomial.legendre.leggauss(8)

    def nodes(lo, hi, n):
        e = np.linspace(lo, hi, n + 1)
        h = e[1] - e[0]
        return (e[:-1, None] + 0.5 * h * (1 + g)).ravel(), np.tile(0.5 * h * w, n)

    r, wr = nodes(0.0, radius_m, radial)
    th, wth = nodes(0.0, 2 * np.pi, angular)
    x = (r[:, None] * np.cos(th)[None, :]).ravel()
    y = (r[:, None] * np.sin(th)[None, :]).ravel()
    return x, y, ((q_kPa * r * wr)[:, None] * wth[None, :]).ravel()
