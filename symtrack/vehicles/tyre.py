"""A tyre's contact area, its stress distribution and the stress it gives at depth
(docs/subsoil.md, "Wheeled machines"). numpy only; not in the terrain engine.

Contact model: Keller (2005), Biosyst. Eng. 92, 85-96, as the soilphysics R package codes it
(``stressTraffic``, github.com/arsilva87/soilphysics; the paper was not read). For a tyre of width
b and overall diameter D [m], wheel load W [kN], inflation pressure p_i and the recommended
inflation pressure p_rec for that load [kPa]:

    sigma_max = 34.4 + 1.13 p_i + 0.72 W - 33.4 ln(p_i / p_rec)          [kPa]
    L = 0.47 + 0.11 D^2 - 0.16 ln(p_i / p_rec)                             [m, contact length]
    contact: the super-ellipse |2x/L|^n + |2y/b|^n <= 1,  n = 2.1 (b D)^2 + 2
    sigma(x, y) = sigma_max (1 - (|x| / l(y))^alpha) g(y),  l(y) = L/2 (1 - |2y/b|^n)^(1/n)
    g(y) = C u exp(-delta u),  u = b/2 - |y|,  delta = 9.3 - 7.3 b,  C such that max g = 1

and alpha such that the stresses carry W. soilphysics searches alpha on a grid of [1, 16]; here the
integral along x is done in closed form (int (1 - (x/l)^alpha) dx over [-l, l] = 2 l alpha/(alpha+1)),
so W = sigma_max alpha/(alpha+1) I, I = int 2 l(y) g(y) dy, and alpha = r / (1 - r), r = W/(sigma_max I).
A load the model cannot carry (r >= 1) is refused.

Stress at depth: the project's Söhne / Fröhlich point formula (:func:`symtrack.soil.subsoil.frohlich_point`)
summed over the contact cut into square elements; the mean normal stress is
xi / (3 (xi - 2)) sigma_z(xi - 2) (subsoil.py's identity for the trace of the radial stress). Over a
rigid base each element also carries the base's correction (:mod:`symtrack.soil.rigid_base`).

Load and inflation: a tyre carries its rated load W_max at its rated pressure p_max (its load index
and the pressure it is rated at, from the tyre's data sheet); at a lower pressure it carries
W_max (p / p_max)^0.8, the inverse of the inflation rule p = p_max (W / W_max)^1.25 of tyre
pressure guides (Agrivi, "Risk of incorrect pressure in agricultural tires"; a practitioners' rule
at the rated speed, not a standard read here). That rule also gives p_rec for Keller's model.
A wheel load above what the tyre carries at its inflation pressure is refused.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError
from ..soil import rigid_base
from ..soil.subsoil import stress_bruteforce

__all__ = ["ARVIDSSON_KELLER_2007_TYRES", "INFLATION_RULE_EXPONENT", "Contact", "FootprintTable", "LoadsAndPressures",
           "TracksDualsSingles", "Tyre", "arvidsson_2011", "arvidsson_keller_2007", "contact",
           "footprint_stress_at_depth", "footprint_table", "load_capacity_kN", "recommended_inflation_kPa"]

# p = p_max (W / W_max)^1.25 (module doc): the tyre-pressure guides' rule
INFLATION_RULE_EXPONENT = 1.25
# Keller (2005) as stressTraffic codes it (module doc)
_SMAX = (34.4, 1.13, 0.72, -33.4)
_LEN = (0.47, 0.11, -0.16)
_N_SHAPE = (2.1, 2.0)
_DELTA = (9.3, -7.3)
_N_GAUSS = 64


def _num(name, v, lo, hi):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) or not lo < v <= hi:
        raise ParameterError(f"{name} = {v!r} is outside the allowed range ({lo}, {hi}]")
    return float(v)


@dataclasses.dataclass(frozen=True)
class Tyre:
    """A tyre: section width and overall diameter [m]; its rated load [kN] at its rated inflation
    pressure [kPa] (the load index's load and pressure). Width up to 1.2 m: delta = 9.3 - 7.3 b of
    Keller's transverse distribution must stay positive."""

    width_m: float
    diameter_m: float
    rated_load_kN: float
    rated_inflation_kPa: float

    def __post_init__(self):
        _num("tyre.width_m", self.width_m, 0.1, 1.2)
        _num("tyre.diameter_m", self.diameter_m, 0.3, 3.0)
        _num("tyre.rated_load_kN", self.rated_load_kN, 0.0, 500.0)
        _num("tyre.rated_inflation_kPa", self.rated_inflation_kPa, 0.0, 1000.0)


def load_capacity_kN(tyre: Tyre, inflation_kPa) -> float:
    """The load the tyre carries at an inflation pressure: W_max (p / p_max)^(1 / 1.25)."""
    p = _num("inflation_kPa", inflation_kPa, 0.0, tyre.rated_inflation_kPa)
    return tyre.rated_load_kN * (p / tyre.rated_inflation_kPa) ** (1.0 / INFLATION_RULE_EXPONENT)


def recommended_inflation_kPa(tyre: Tyre, wheel_load_kN) -> float:
    """The inflation pressure the rule recommends for a wheel load: p_max (W / W_max)^1.25."""
    W = _num("wheel_load_kN", wheel_load_kN, 0.0, tyre.rated_load_kN)
    return tyre.rated_inflation_kPa * (W / tyre.rated_load_kN) ** INFLATION_RULE_EXPONENT


@dataclasses.dataclass(frozen=True)
class Contact:
    """A tyre's contact: length, width [m], area [m^2], sigma_max [kPa], alpha, the recommended
    pressure used [kPa]; the elements' centres x, y [m] (x along the driving direction) and their
    forces [kN] (a square grid of side ``element_m`` over the contact); the super-ellipse's n."""

    length_m: float
    width_m: float
    area_m2: float
    sigma_max_kPa: float
    alpha: float
    recommended_inflation_kPa: float
    element_m: float
    x_m: np.ndarray
    y_m: np.ndarray
    force_kN: np.ndarray

    shape_n: float

    def stress_kPa(self, x, y):
        """The contact stress [kPa] at surface points (0 outside the contact)."""
        return _surface_stress(np.asarray(x, float), np.asarray(y, float), self.length_m, self.width_m,
                               self.shape_n, self.sigma_max_kPa, self.alpha)


def _half_length(y, L, b, n):
    return 0.5 * L * np.clip(1.0 - np.abs(2.0 * y / b) ** n, 0.0, 1.0) ** (1.0 / n)


def _transverse(y, b):
    delta = _DELTA[0] + _DELTA[1] * b
    u = np.clip(b / 2 - np.abs(y), 0.0, None)
    u_peak = min(1.0 / delta, b / 2)
    return u * np.exp(-delta * u) / (u_peak * math.exp(-delta * u_peak))


def _surface_stress(x, y, L, b, n, smax, alpha):
    ly = _half_length(y, L, b, n)
    inside = (np.abs(x) < ly) & (np.abs(y) < b / 2)
    ratio = np.where(inside, np.abs(x) / np.where(ly > 0, ly, 1.0), 1.0)
    return np.where(inside, smax * (1.0 - ratio**alpha) * _transverse(y, b), 0.0)


def contact(tyre: Tyre, wheel_load_kN, inflation_kPa, element_m=0.01) -> Contact:
    """Keller's (2005) contact (module doc) of ``tyre`` at a wheel load [kN] and inflation pressure
    [kPa]. Refuses a load beyond what the tyre carries at that pressure, and a load the stress model
    cannot carry."""
    p = _num("inflation_kPa", inflation_kPa, 0.0, tyre.rated_inflation_kPa)
    cap = load_capacity_kN(tyre, p)
    W = float(wheel_load_kN) if isinstance(wheel_load_kN, (int, float)) and not isinstance(wheel_load_kN, bool) \
        else float("nan")
    if not (math.isfinite(W) and 0.0 < W <= cap * (1.0 + 1e-12)):  # (the rule's own round trip)
        raise ParameterError(f"wheel_load_kN = {wheel_load_kN!r} is outside the allowed range (0, {cap:.4g}]: what "
                             f"the tyre (rated {tyre.rated_load_kN} kN at {tyre.rated_inflation_kPa} kPa) carries at "
                             f"{p} kPa by the rule W = W_max (p / p_max)^0.8")
    h = _num("element_m", element_m, 0.0, 0.1)
    b, D = tyre.width_m, tyre.diameter_m
    p_rec = recommended_inflation_kPa(tyre, W)
    lnr = math.log(p / p_rec)
    smax = _SMAX[0] + _SMAX[1] * p + _SMAX[2] * W + _SMAX[3] * lnr
    L = _LEN[0] + _LEN[1] * D**2 + _LEN[2] * lnr
    n = _N_SHAPE[0] * (b * D) ** 2 + _N_SHAPE[1]
    if not (smax > 0 and L > 0):
        raise ParameterError(f"inflation_kPa = {p}: Keller's model gives sigma_max = {smax:.4g} kPa, length "
                             f"{L:.4g} m for this tyre and load (both must be > 0)")
    g_nodes, g_weights = np.polynomial.legendre.leggauss(_N_GAUSS)
    # I = int 2 l(y) g(y) dy over [-b/2, b/2]: composite Gauss on 8 panels
    edges = np.linspace(-b / 2, b / 2, 9)
    panels = list(zip(edges[:-1], edges[1:], strict=True))
    yy = np.concatenate([0.5 * (lo + hi) + 0.5 * (hi - lo) * g_nodes for lo, hi in panels])
    ww = np.concatenate([0.5 * (hi - lo) * g_weights for lo, hi in panels])
    integral = float(np.sum(ww * 2.0 * _half_length(yy, L, b, n) * _transverse(yy, b)))
    r = W / (smax * integral)
    if not r < 1.0:
        raise ParameterError(f"wheel_load_kN = {W}: Keller's stress distribution cannot carry it on this tyre at "
                             f"{p} kPa (sigma_max {smax:.4g} kPa over {integral:.4g} m^2 carries at most "
                             f"{smax * integral:.4g} kN)")
    alpha = r / (1.0 - r)
    area = float(np.sum(ww * 2.0 * _half_length(yy, L, b, n)))
    # the elements: a square grid of side h, centres inside the bounding box; forces from the
    # stress at the centre, rescaled so that they sum to W exactly (the grid's error is O(h))
    nx, ny = max(2, int(math.ceil(L / h))), max(2, int(math.ceil(b / h)))
    xc = (np.arange(nx) + 0.5) * (L / nx) - L / 2
    yc = (np.arange(ny) + 0.5) * (b / ny) - b / 2
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    s = _surface_stress(X, Y, L, b, n, smax, alpha)
    F = s * (L / nx) * (b / ny)
    keep = F > 0
    F = F[keep] * (W / F[keep].sum())
    return Contact(L, b, area, smax, alpha, p_rec, h, X[keep], Y[keep], F, n)


def footprint_stress_at_depth(x_m, y_m, force_kN, px, py, depths_m, xi, chunk=256, rigid_base_depth_m=None,
                              rigid_base_interface="rough", mean_stress=True):
    """Vertical and mean normal stress [kPa] (two arrays (n_points, n_depths)) at the points (px, py)
    below a set of surface point forces [kN] at (x_m, y_m): Söhne / Fröhlich summed
    (:func:`~symtrack.soil.subsoil.frohlich_point`); the mean normal stress by the identity
    p(xi) = xi / (3 (xi - 2)) sigma_z(xi - 2) (needs xi >= 3). ``rigid_base_depth_m``: a rigid base
    under the soil layer, ``rigid_base_interface`` "rough" or "smooth"; each force then also carries
    the base's corrections to both stresses (:func:`symtrack.soil.rigid_base.point_correction`;
    None: a half-space). ``mean_stress=False`` skips the mean normal stress (returned as zeros)."""
    xi = float(xi)
    if not 3.0 <= xi <= 10.0:
        raise ParameterError(f"xi = {xi!r} is outside the allowed range [3, 10] (the mean normal stress needs "
                             "xi - 2 >= 1)")
    px, py = np.atleast_1d(np.asarray(px, float)), np.atleast_1d(np.asarray(py, float))
    x, y, F = (np.asarray(v, float).ravel() for v in (x_m, y_m, force_kN))
    d = np.atleast_1d(np.asarray(depths_m, float))
    if np.any(~(d > 0)):
        raise ParameterError(f"depths_m = {depths_m!r}: each depth must be > 0 m")
    profiles = None
    if rigid_base_depth_m is not None:
        reach = math.hypot(float(np.ptp(np.concatenate([x, px]))), float(np.ptp(np.concatenate([y, py]))))
        profiles = [rigid_base.correction_profile(z, rigid_base_depth_m, reach + 1e-9, rigid_base_interface)
                    for z in d]
    sz = np.zeros((px.size, d.size))
    pm = np.zeros((px.size, d.size))
    for a in range(0, px.size, chunk):
        r2 = (px[a:a + chunk, None] - x[None, :]) ** 2 + (py[a:a + chunk, None] - y[None, :]) ** 2
        r = np.sqrt(r2) if profiles is not None else None
        for k, z in enumerate(d):
            # frohlich_point's xi F cos^xi / (2 pi R^2), cos = z / R, as xi F z^xi R^-(xi + 2) / (2 pi): one
            # power a point and depth; its mean-stress twin xi / (3 (xi - 2)) of the same with xi - 2 is
            # xi F cos^xi / (6 pi z^2) (cos^(xi - 2) / R^2 = cos^xi / z^2), the same power again
            R2 = r2 + z * z
            cos_xi = z**xi * R2 ** (-xi / 2)
            sz[a:a + chunk, k] = xi / (2 * np.pi) * ((cos_xi / R2) @ F)
            if mean_stress:
                pm[a:a + chunk, k] = xi / (6 * np.pi * z * z) * (cos_xi @ F)
            if profiles is not None:
                r_grid, dz, dp = profiles[k]
                sz[a:a + chunk, k] += (F[None, :] * np.interp(r, r_grid, dz)).sum(axis=1)
                if mean_stress:
                    pm[a:a + chunk, k] += (F[None, :] * np.interp(r, r_grid, dp)).sum(axis=1)
    return sz, pm


@dataclasses.dataclass(frozen=True)
class FootprintTable:
    """A tyre's vertical and mean normal stress [kPa] at depth, tabulated once over the quadrant
    x, y in [0, (n - 1) step] of the wheel's frame (the contact is symmetric in x and in y) and
    interpolated bilinearly in |x|, |y|; 0 beyond the table. ``sz``, ``pm``: (n, n, n_depths)."""

    step_m: float
    depths_m: tuple
    xi: float
    sz: np.ndarray
    pm: np.ndarray

    def at(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_z, p) [kPa] (n_points, n_depths) at points (x, y) of the wheel's frame."""
        return self._interpolate((self.sz, self.pm), x, y)

    def sigma_z(self, x, y) -> np.ndarray:
        """sigma_z [kPa] (n_points, n_depths) at points (x, y) of the wheel's frame: :meth:`at`'s first
        table alone (the fields' and the region's stress maps read no other: half the interpolation)."""
        return self._interpolate((self.sz,), x, y)[0]

    def _interpolate(self, tables, x, y) -> list[np.ndarray]:
        n = self.sz.shape[0]
        u, v = np.abs(np.asarray(x, float)) / self.step_m, np.abs(np.asarray(y, float)) / self.step_m
        inside = (u <= n - 1) & (v <= n - 1)
        i = np.minimum(np.floor(u), n - 2).astype(np.int64)
        j = np.minimum(np.floor(v), n - 2).astype(np.int64)
        i, j = np.where(inside, i, 0), np.where(inside, j, 0)
        fu, fv = (np.where(inside, u - i, 0.0)[:, None], np.where(inside, v - j, 0.0)[:, None])
        # the four corners' weights once for every table; the corners gathered from the tables' flat rows
        # (cell i, j is row i n + j): a one-index take is faster than numpy's two-index gather
        w = ((1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv)
        rows = i * n + j
        corners = (rows, rows + n, rows + 1, rows + n + 1)
        out = []
        for T in tables:
            flat = T.reshape(n * n, -1)
            val = sum(wk * flat.take(ck, axis=0) for wk, ck in zip(w, corners, strict=True))
            out.append(np.where(inside[:, None], val, 0.0))
        return out


@functools.lru_cache(maxsize=8)
def footprint_table(tyre: Tyre, wheel_load_kN: float, inflation_kPa: float, element_m: float, depths_m: tuple,
                    xi: float, reach_m: float, step_m: float | None = None) -> tuple[Contact, FootprintTable]:
    """The contact of ``tyre`` (:func:`contact`) and its stresses at ``depths_m`` tabulated out to
    ``reach_m`` in x and y (:class:`FootprintTable`), built once per process for these arguments.
    Step: a tenth of the shallowest depth, at most 1 cm (bilinear error O(step^2 / depth^2) of the
    peak: tests/test_towed.py measures it against the direct sum)."""
    c = contact(tyre, wheel_load_kN, inflation_kPa, element_m)
    depths = tuple(float(d) for d in depths_m)
    h = float(step_m) if step_m is not None else min(0.01, 0.1 * depths[0])
    n = int(math.ceil(reach_m / h)) + 1
    g = np.arange(n) * h
    X, Y = np.meshgrid(g, g, indexing="ij")
    sz, pm = footprint_stress_at_depth(c.x_m, c.y_m, c.force_kN, X.ravel(), Y.ravel(), depths, xi)
    nd = len(depths)
    return c, FootprintTable(h, depths, float(xi), sz.reshape(n, n, nd), pm.reshape(n, n, nd))


@dataclasses.dataclass(frozen=True)
class LoadsAndPressures:
    """The largest vertical stress [kPa] across a wheel at each depth, per wheel load and inflation
    pressure (:func:`arvidsson_keller_2007`)."""

    depths_m: tuple
    tyres: dict  # wheel load [kN] -> (width, diameter) [m], ASSUMED
    peak_kPa: dict  # (wheel load [kN], inflation [kPa]) -> (n_depths,)


# Arvidsson & Keller (2007)'s wheel loads [kN] and the tyre sizes ASSUMED for them (width, diameter [m])
ARVIDSSON_KELLER_2007_TYRES = {11.0: (0.40, 1.25), 15.0: (0.50, 1.45), 33.0: (0.65, 1.75)}


def arvidsson_keller_2007(inflations_kPa=(100.0, 150.0), depths_m=(0.1, 0.3, 0.5, 0.7), xi=5.0) -> LoadsAndPressures:
    """The loads and pressures of Arvidsson & Keller (2007), Soil Till. Res. 96:284-291 (abstract read):
    wheel loads 11, 15, 33 kN at 70, 100, 150 kPa; "the maximum stress at 10 cm depth was considerably
    higher than the inflation pressure (39% on average) and also increased with increasing wheel load";
    inflation pressure "had a large influence on soil stresses measured at 10 cm depth, ... very little
    influence in the subsoil (30 cm and deeper). In contrast, wheel load had a very large influence on
    subsoil stresses."

    The tyres' sizes were not read: ASSUMED sizes growing with the load
    (:data:`ARVIDSSON_KELLER_2007_TYRES`), each rated so that its recommended pressure at its load is
    100 kPa (the paper used "the same recommended tyre inflation pressure" for the loads); a pressure
    below that (70 kPa) is refused by the load rule (:func:`contact` raises). The largest stress across
    the wheel (y in [-0.4, 0.4] m, 81 points) by :func:`footprint_stress_at_depth`. docs/subsoil.md
    ("Wheeled machines") and tests/test_tyre.py use it."""
    depths = tuple(float(d) for d in depths_m)
    ys = np.linspace(-0.4, 0.4, 81)
    peaks = {}
    for W, (b, D) in ARVIDSSON_KELLER_2007_TYRES.items():
        ty = Tyre(b, D, W * (240.0 / 100.0) ** 0.8, 240.0)  # rated at 240 kPa: p_rec = 100 kPa at W
        for p in inflations_kPa:
            c = contact(ty, W, float(p))
            sz, _ = footprint_stress_at_depth(c.x_m, c.y_m, c.force_kN, np.zeros_like(ys), ys, depths, xi,
                                              mean_stress=False)
            peaks[(W, float(p))] = sz.max(axis=0)
    return LoadsAndPressures(depths, dict(ARVIDSSON_KELLER_2007_TYRES), peaks)


@dataclasses.dataclass(frozen=True)
class TracksDualsSingles:
    """The largest vertical stress [kPa] at each depth under one machine on single wheels, on dual
    wheels and on tracks (:func:`arvidsson_2011`), with the pressures it ran at."""

    depths_m: tuple
    single_kPa: np.ndarray  # (n_depths,), the largest across the wheel
    duals_kPa: np.ndarray
    tracks_kPa: np.ndarray  # below a track's centre line
    single_inflation_kPa: float
    duals_inflation_kPa: float
    track_pressure_kPa: float  # uniform over each track's contact


def arvidsson_2011(depths_m=(0.15, 0.3, 0.5), xi=5.0) -> TracksDualsSingles:
    """The comparison of Arvidsson, Westlin, Keller & Gilbertsson (2011), Soil Till. Res. 117:103-109
    (from its abstract): a 7.7 t tractor on rubber tracks, on single and on dual wheels; measured at
    0.15, 0.3 and 0.5 m, the tracks' stress about equal to the duals', both below the singles'.

    ASSUMED here (the paper's machine was not read beyond its mass): the rear axle carries 60 % of
    the weight; 650/65R38 tyres (0.65 m wide, 1.85 m, load index 157: 4125 kg at 160 kPa) at the
    inflation rule's recommended pressure for their load (:func:`recommended_inflation_kPa`), duals
    0.1 m apart; the tracks of the reference crawler (2.4 x 0.45 m, gauge 1.5 m) at a uniform
    pressure carrying the whole weight. The wheels' stress by :func:`footprint_stress_at_depth`
    across the axle (y in [-1, 1] m, 201 points), the tracks' by
    :func:`symtrack.soil.subsoil.stress_bruteforce` below a track's centre line. docs/subsoil.md
    ("Wheeled machines") and tests/test_tyre.py use it."""
    g = 9.81
    depths = tuple(float(d) for d in depths_m)
    W = 7700.0 * g / 1e3  # kN, the whole tractor
    Wr = 0.6 * W / 2  # kN, a rear wheel's share (single)
    ty = Tyre(0.65, 1.85, 4125.0 * g / 1e3, 160.0)
    ys = np.linspace(-1.0, 1.0, 201)
    p1 = recommended_inflation_kPa(ty, Wr)
    c1 = contact(ty, Wr, p1)
    single, _ = footprint_stress_at_depth(c1.x_m, c1.y_m, c1.force_kN, 0 * ys, ys, depths, xi, mean_stress=False)
    p2 = recommended_inflation_kPa(ty, Wr / 2)
    c2 = contact(ty, Wr / 2, p2)
    gap = 0.65 + 0.1  # centre to centre
    x, y = np.concatenate([c2.x_m] * 2), np.concatenate([c2.y_m - gap / 2, c2.y_m + gap / 2])
    dual, _ = footprint_stress_at_depth(x, y, np.concatenate([c2.force_kN] * 2), 0 * ys, ys, depths, xi,
                                        mean_stress=False)
    length, width, gauge = 2.4, 0.45, 1.5
    pr = W * 1e3 / (2 * length * width)  # Pa
    a, geo = [0, 0, 1, 0, pr, 0, pr, 0], [length, width, gauge, 0.0, 0.05, 0.05]
    track = np.array([stress_bruteforce(np.zeros(1), np.array([gauge / 2]), a, geo, d, xi)[0] for d in depths]) / 1e3
    return TracksDualsSingles(depths, single.max(axis=0), dual.max(axis=0), track, float(p1), float(p2), pr / 1e3)


# bounded by their maxsize; emptied by symtrack.clear_caches() (symtrack.foundations.caches)
caches.register_clear("tyre.footprint_table", footprint_table)
