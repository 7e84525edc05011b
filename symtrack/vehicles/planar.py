"""The planar tracked vehicle of docs/model.md, written once as CasADi SX expressions.

Body frame at the CG: x forward, y left, yaw counter-clockwise. Left track at y = +B/2, right
track at y = -B/2; each has its driven sprocket at the rear and its idler at the front.

The equations here need from the terrain only the compaction resistance of each track
(the terrain gets from here the pressure under each track), so the same vehicle serves the
homogeneous terrain and the channel-pool grid terrain. Reconstructions (not in Ferretti & Girelli
1999) are marked as such; docs/model.md gives their sources.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError
from ..foundations.params import param
from ..model.layout import ContactPose, StateLayout, VehicleState
from .base import VehicleModel

__all__ = ["ALGEBRAIC", "ENDS", "GRAVITY_M_S2", "INPUTS", "LATERAL_STATES", "PLANAR_LATERAL_LAYOUT", "PLANAR_LAYOUT",
           "PlanarLateralVehicle", "PlanarVehicle", "PressureDistribution", "SHEAR_LAWS", "SHEAR_UNLOADING_TIME_MIN_S",
           "SLIP_SPEED_SCALE_M_S", "TRACKS", "TRACK_SOIL_PARAMS", "TRACK_SOIL_PARAM_NAMES", "VEHICLE_PARAMS",
           "VEHICLE_STATES",
           "codegen_options", "creep_lateral_force", "direction", "gauss_nodes", "graded_nodes", "integrate_track",
           "internal_resistance_N", "lateral_resistance_max_N", "lateral_shear_rates", "mean_ground_pressure_Pa",
           "quadrature_is_mapped", "quadrature_points", "shear_eq2_rate", "shear_exchange_speed", "shear_forces",
           "shear_rate", "shear_retardation_time_s", "shear_unloading_ratio", "sprocket_acceleration",
           "sprocket_speed_abs", "track_signals", "track_slip", "traction_shape", "traction_sign", "vehicle_equations"]

# the lateral laws that take the tracks' forces from the soil's shear law (ModelOptions.lateral_law)
SHEAR_LAWS = ("shear", "shear_quasistatic")

# Standard gravity (a true constant: CGPM 1901).
GRAVITY_M_S2 = 9.80665

TRACKS = ("left", "right")
ENDS = ("sprocket", "idler")

VEHICLE_STATES = (
    "x_m", "y_m", "yaw_rad", "u_m_s", "v_m_s", "yaw_rate_rad_s",
    "omega_left_rad_s", "omega_right_rad_s", "shear_left_m", "shear_right_m",
    "torque_left_N_m", "torque_right_N_m",
)
# the planar vehicle's states in blocks (symtrack.model.layout)
PLANAR_LAYOUT = StateLayout((
    ("pose", VEHICLE_STATES[0:3]), ("velocity", VEHICLE_STATES[3:6]), ("sprockets", VEHICLE_STATES[6:8]),
    ("shear", VEHICLE_STATES[8:10]), ("torque", VEHICLE_STATES[10:12])))
# the "shear" law's lateral shear states (ModelOptions.lateral_law), after the planar vehicle's
# 12 (the vehicle model "planar_lateral"): per track the lateral shear displacement at the contact
# centre and the twist (the hull's rotation while an element crosses half the contact: the gradient
# of the lateral slip along the track)
LATERAL_STATES = ("lateral_shear_left_m", "lateral_shear_right_m", "shear_twist_left_rad", "shear_twist_right_rad")
PLANAR_LATERAL_LAYOUT = StateLayout(tuple((b, PLANAR_LAYOUT.block_names_of(b)) for b in
                                          ("pose", "velocity", "sprockets", "shear", "torque"))
                                    + (("lateral_shear", LATERAL_STATES),))
INPUTS = ("torque_cmd_left_N_m", "torque_cmd_right_N_m")
ALGEBRAIC = ("accel_x_m_s2", "accel_y_m_s2")

# The tread speed r |omega| below which the reported slip (track_slip) fades to 0 instead of growing
# without bound (1 - v / (r omega) has a pole at omega = 0). 1 cm/s lies far below any working speed
# (crawlers work at 0.3-4 m/s): the slip is reported (r omega)^2 / ((r omega)^2 + eps^2) of its true value,
# 1 - 1e-4 at a tread speed of 1 m/s, 0.99 at 0.1 m/s. An output only: no equation uses it.
SLIP_SPEED_SCALE_M_S = 0.01

_BODY = "Ferretti & Girelli (1999), the body equations (docs/model.md)"
_WONG = "Wong, Theory of Ground Vehicles: the internal resistance of a track"
# the planar vehicle's parameters (the 3D vehicle reads the same): the [vehicle] table
VEHICLE_PARAMS = (
    param("mass_kg", "vehicle mass", 0.0, 1e6, False, source=_BODY),
    param("yaw_inertia_kg_m2", "yaw moment of inertia about the CG", 0.0, 1e8, False, source=_BODY),
    param("track_gauge_m", "distance B between the track centre-lines", 0.0, 20.0, False, source=_BODY),
    param("track_width_m", "track width b", 0.0, 5.0, False, source=_BODY),
    param("contact_length_m", "track contact length l", 0.0, 20.0, False, source=_BODY),
    param("sprocket_radius_m", "sprocket pitch radius r", 0.0, 5.0, False, source=_BODY),
    param("cg_height_m", "CG height h above the ground", 0.0, 10.0, source=_BODY),
    param("cg_ahead_of_contact_centre_m", "CG offset e ahead of the contact centre", -5.0, 5.0, source=_BODY),
    param("sprocket_inertia_kg_m2", "equivalent inertia J_eq per side (sprocket, idler, rollers, track)",
          0.0, 1e5, False, source=_BODY),
    param("torque_time_constant_s", "time constant tau_T of the first-order torque actuator", 0.0, 100.0, False,
          source="the first-order torque actuator (docs/model.md)"),
    param("internal_resistance_const", "Wong's internal resistance R_in/W_k, speed-independent part", 0.0, 1.0,
          source=_WONG),
    param("internal_resistance_per_km_h", "Wong's internal resistance R_in/W_k per km/h of track speed",
          0.0, 0.1, source=_WONG, unit="h/km"),
    param("lateral_friction_coeff", "lateral friction coefficient mu_t between track and soil "
          "(lateral_law = \"creep\" only)", 0.0, 5.0, source="Wong, Theory of Ground Vehicles: skid steering"),
    param("lateral_creep_speed_m_s", "lateral slip speed eps_v at which friction reaches tanh(1) of mu_t "
          "(lateral_law = \"creep\" only)", 0.0, 10.0, False, source="the creep lateral law (docs/model.md)"),
    param("drawbar_pull_N", "drawbar pull P (external resistance at the hitch)", 0.0, 1e7, source=_BODY),
    param("hitch_height_m", "height h_d of the drawbar hitch", 0.0, 10.0, source=_BODY),
)
# the soil's coefficients the tracks' traction reads (the [soil] table; with a soil map the terrain
# engine carries them per soil and sums them under each track by name)
TRACK_SOIL_PARAMS = (
    param("cohesion_Pa", "Mohr-Coulomb cohesion c", 0.0, 1e7, source="Mohr-Coulomb, in Janosi & Hanamoto (1961)"),
    param("friction_angle_rad", "Mohr-Coulomb internal friction angle phi", 0.0, 1.5,
          source="Mohr-Coulomb, in Janosi & Hanamoto (1961)"),
    param("shear_modulus_K_m", "Janosi-Hanamoto shear deformation modulus K", 0.0, 1.0, False,
          source="Janosi & Hanamoto (1961)"),
)
TRACK_SOIL_PARAM_NAMES = tuple(s.name for s in TRACK_SOIL_PARAMS)


def contact_rectangles(params) -> list[tuple[float, float, float, float]]:
    """Each track's contact rectangle in the body frame, left then right: (its centre ahead of the CG,
    its centre to the left of it, half its length l / 2, half its width b / 2) [m] (the terrain engine's
    scan of the cells under the tracks, grid_engine.c, writes the same rectangles from geo)."""
    ahead, off = -params["cg_ahead_of_contact_centre_m"], 0.5 * params["track_gauge_m"]
    half_l, half_b = 0.5 * params["contact_length_m"], 0.5 * params["track_width_m"]
    return [(ahead, off, half_l, half_b), (ahead, -off, half_l, half_b)]


def mean_ground_pressure_Pa(params):
    """The tracks' mean ground pressure m g / (2 b l) [Pa] of the vehicle parameters ``params``."""
    return params["mass_kg"] * GRAVITY_M_S2 / (2 * params["track_width_m"] * params["contact_length_m"])


def gauss_nodes(length, n_segments: int, n_points: int):
    """Composite Gauss-Legendre nodes s in [0, length] and weights (they sum to length)."""
    xg, wg = np.polynomial.legendre.leggauss(n_points)
    s, w = [], []
    for k in range(n_segments):
        for xi, wi in zip(xg, wg, strict=True):
            s.append((k + 0.5 * (xi + 1.0)) / n_segments)
            w.append(0.5 * wi / n_segments)
    return [length * si for si in s], [length * wi for wi in w]


class PressureDistribution:
    """Normal pressure along one track, from its normal load N and pitching moment M about the
    contact centre (reconstruction: rigid track, quasi-static, linear distribution; triangular
    over a shorter length when the resultant leaves the middle third).

    s is measured from the front (idler end, s = 0) to the rear (sprocket end, s = l).
    """

    def __init__(self, N, M, b, l):
        self.N, self.b, self.l = N, b, l
        e_r = M / N
        e_c = ca.fmin(ca.fmax(e_r, -0.45 * l), 0.45 * l)
        self.e_r = e_r
        self.p_mean = N / (b * l)
        self.slope = 12.0 * M / (b * l**3)  # linear case: p(s) = p_mean + slope (l/2 - s)
        self.Lc_front = 3.0 * (l / 2 - e_c)
        self.Lc_rear = 3.0 * (l / 2 + e_c)

    def at(self, s):
        b, l, N = self.b, self.l, self.N
        linear = self.p_mean + self.slope * (l / 2 - s)
        tri_front = 2 * N / (b * self.Lc_front) * ca.fmax(0, 1 - s / self.Lc_front)
        tri_rear = 2 * N / (b * self.Lc_rear) * ca.fmax(0, 1 - (l - s) / self.Lc_rear)
        return ca.if_else(self.e_r > l / 6, tri_front, ca.if_else(self.e_r < -l / 6, tri_rear, linear))

    @property
    def idler(self):
        return self.at(0.0)

    @property
    def sprocket(self):
        return self.at(self.l)


def traction_sign(j, opts):
    """sign(j) of Ferretti & Girelli's tractive effort in the chosen form (ModelOptions.traction_sign)."""
    if opts.traction_sign == "smooth":
        return j / ca.sqrt(j**2 + opts.shear_smoothing_m**2)
    if opts.traction_sign == "tanh":
        return ca.tanh(opts.tanh_steepness_per_m * j)
    return ca.sign(j)


def traction_shape(j, K, opts):
    """sign(j) [1 + K/(2|j|) (exp(-2|j|/K) - 1)] of Ferretti & Girelli's tractive effort, in the chosen form."""
    a = ca.sqrt(j**2 + opts.shear_smoothing_m**2)
    bracket = 1 + K / (2 * a) * (ca.exp(-2 * a / K) - 1)
    return traction_sign(j, opts) * bracket


def direction(x, eps, opts):
    """sign(x) of a resistance's direction: tanh(x/eps), or the exact sign() in "sign" mode."""
    return ca.sign(x) if opts.traction_sign == "sign" else ca.tanh(x / eps)


def graded_nodes(n_points: int, grading: int):
    """Gauss-Legendre nodes t in [0, 1] mapped by t -> t**grading, with the mapped weights: a rule
    on [0, 1] whose nodes crowd towards 0, for integrands with a boundary layer there."""
    xg, wg = np.polynomial.legendre.leggauss(n_points)
    t = 0.5 * (xg + 1.0)
    weights = [float(0.5 * wi * grading * ti ** (grading - 1)) for ti, wi in zip(t, wg, strict=True)]
    return [float(ti**grading) for ti in t], weights


def shear_forces(j, omega, abs_om, v_k, vy, rz, x_front, dist, N, b, l, r, c, phi, K, opts,
                 lagged=None):
    """Tractive force, lateral force and yaw moment (about the CG) of one track from the soil's
    shear law (reconstruction after Wong & Chiang 2001; docs/turning.md).

    At a point s of the contact (s from the front, body x = x_front - s) the track slides over the
    soil with, per unit of tread speed r|omega|, the longitudinal slip (r omega - v_k)/(r|omega|)
    and the lateral slip i_y(s) = (v + r_z x(s)) / (r|omega|). The shear displacement is accumulated
    from the end where the track element entered the contact (the front when omega > 0):
    longitudinally j_x(s) = i_x s with i_x = 2 j / l from the state of the shear law (its steady
    state is Wong's j = i s), laterally j_y(s) = integral of i_y from 0 to s (quasi-static). The
    shear stress has the Mohr-Coulomb / Janosi magnitude (c + p tan phi)(1 - exp(-|j|/K)) and acts
    against the local sliding velocity (combined slip: a track that slips longitudinally resists
    less laterally, and the other way round), with the longitudinal sign of the tractive effort, sign(j).

    With no lateral sliding the longitudinal force is Ferretti & Girelli's tractive effort (mean-pressure strength, the
    default; to the quadrature's accuracy, 7e-5 at 30 % slip) or the exact Janosi integral over p(s)
    (``shear_strength_pressure = "local"``).

    The integral is split where the integrand has its features (the pivot, where i_y changes sign;
    the point where j_y returns to zero; the ends, where the shear builds up from zero), each piece
    halved and integrated by Gauss-Legendre graded towards its ends, so that its accuracy does not
    depend on where the pivot falls.

    ``lagged``: (j_y, theta), the track's lateral shear states of the "shear" law (their
    dynamics: :func:`lateral_shear_rates`): the sliding direction and the displacement field then
    use the lagged slips, longitudinal 2 j / l, lateral 2 j_y / l at the contact centre and its
    slope along the track 2 theta / l, instead of the sliding velocity now. In steady running the
    lagged slips equal the instantaneous ones: the "shear" law.
    """
    # regularised |r omega| > 0 (also in traction_sign = "sign" mode, where abs_om is exact)
    tread = r * ca.sqrt(omega**2 + opts.omega_smoothing_rad_s**2)
    i_x = 2 * j / l
    fwd = 0.5 * (1 + ca.tanh(omega / opts.omega_smoothing_rad_s))  # 1: the contact is entered at the front
    # lateral slip i_y(s) = a0 - a1 s
    if lagged is None:
        a1 = rz / tread
        a0 = (vy + rz * x_front) / tread
    else:
        # the lagged lateral slip: 2 j_y / l at the contact centre (s = l/2), slope 2 theta / l
        a1 = 2 * lagged[1] / l
        a0 = 2 * lagged[0] / l + a1 * l / 2
    JF_l = a0 * l - a1 * l**2 / 2

    # the sliding direction from the track's sliding velocity now: longitudinal r omega - v_k,
    # lateral v + r_z x (per unit tread speed), with the longitudinal sign of the tractive effort, sign(j)
    # ("shear": the lagged longitudinal slip 2 j / l of the shear displacement's law)
    i_x_now = (r * omega - v_k) / tread if lagged is None else i_x
    ax = ca.sqrt(i_x_now**2 + opts.sliding_smoothing**2)  # regularised |i_x|
    if opts.sliding_sign == "velocity":
        # the longitudinal sign from the sliding velocity too (ModelOptions.sliding_sign): smooth
        # through i_x = 0 while the track slides sideways (the MPC's prediction, docs/turning.md)
        sgn_ax = i_x_now
    else:
        sgn_ax = traction_sign(j, opts) * ax

    q = {"a0": a0, "a1": a1, "i_x": i_x, "JF_l": JF_l, "fwd": fwd, "K": K, "sgn_ax": sgn_ax, "ax": ax, "b": b,
         "l": l, "c": c, "phi": phi, "x_front": x_front,
         **({"N": N} if opts.shear_strength_pressure == "mean" else _distribution_scalars(dist))}

    if not opts.lateral_split:
        sn, wn = gauss_nodes(1.0, opts.lateral_segments, opts.gauss_points)
        nodes = [(si * l, wi * l) for si, wi in zip(sn, wn, strict=True)]
        rule = ((0, l, l, sn, wn),)
    else:
        # features inside the contact: the pivot (i_y = 0) and the zero of j_y
        if lagged is None:
            s_pivot = x_front + vy * rz / (rz**2 + opts.pivot_smoothing_rad_s**2)
        else:
            # the lagged slip's own zero a0 / a1 = x_front + (a0 - a1 x_front) / a1, regularised on the slip's
            # gradient a1 [1/m] by sliding_smoothing / l (below it the lateral slip turns by less than the
            # sliding direction's smoothing over the whole contact: no sharp turn inside it to split at; at
            # a1 = 0, straight running, the split stays at the CG's x as the quasi-static law's). Not through
            # a yaw rate a1 r|omega|: at a standing sprocket that is below pivot_smoothing_rad_s, and the split
            # then moved with omega; the quadrature's error moved with it, a slope dF/domega of -9e5 N s that
            # no soil has, an unstable sprocket mode of 2e4 1/s (the physics fuzzer, seed 37, case 410)
            a1_reg = opts.sliding_smoothing / l
            s_pivot = x_front + (a0 - a1 * x_front) * a1 / (a1**2 + a1_reg**2)
        s_zero = 2 * s_pivot - (1 - fwd) * l
        clip = lambda z: ca.fmin(ca.fmax(z, 0), l)  # noqa: E731
        s1 = clip(ca.fmin(s_pivot, s_zero))
        s2 = clip(ca.fmax(s_pivot, s_zero))
        tg, wg = graded_nodes(opts.shear_points, opts.shear_grading)
        nodes, rule = [], []
        for lo, hi in ((0, s1), (s1, s2), (s2, l)):
            half = 0.5 * (hi - lo)
            for t, w in zip(tg, wg, strict=True):
                nodes.append((lo + half * t, half * w))  # graded towards lo
                nodes.append((hi - half * t, half * w))  # graded towards hi
            rule += [(lo, half, half, tg, wg), (hi, -half, half, tg, wg)]
    return integrate_track(_shear_integrand, nodes, rule, q, opts)


# the scalars that define a PressureDistribution (its ``at`` reads only these)
_DIST_FIELDS = ("N", "b", "l", "e_r", "p_mean", "slope", "Lc_front", "Lc_rear")


def _distribution_scalars(dist) -> dict:
    return {f"dist_{k}": getattr(dist, k) for k in _DIST_FIELDS}


def _distribution_from(q: dict) -> PressureDistribution:
    dist = object.__new__(PressureDistribution)
    for k in _DIST_FIELDS:
        setattr(dist, k, q[f"dist_{k}"])
    return dist


def _shear_integrand(s, q: dict, opts):
    """(f_x, f_y) per unit length at s of the shear law (shear_forces' integrand; q: its scalars)."""
    a0, a1, i_x, JF_l, fwd, K, b, l, c, phi = (q[k] for k in ("a0", "a1", "i_x", "JF_l", "fwd", "K", "b", "l", "c",
                                                               "phi"))
    d2 = opts.shear_smoothing_m**2
    i_y = a0 - a1 * s
    JF = a0 * s - a1 * s**2 / 2
    # |j| of an element that entered at the front (moving forward) or at the rear (moving
    # backward), blended by the direction of motion (at standstill both are large: saturated)
    j_front = ca.sqrt((i_x * s) ** 2 + JF**2 + d2)
    j_rear = ca.sqrt((i_x * (l - s)) ** 2 + (JF_l - JF) ** 2 + d2)
    if opts.shear_strength_pressure == "mean":
        tau_max = c + q["N"] / (b * l) * ca.tan(phi)
    else:
        tau_max = c + _distribution_from(q).at(s) * ca.tan(phi)
    tau = tau_max * (1 - ca.exp(-(fwd * j_front + (1 - fwd) * j_rear) / K))
    norm = ca.sqrt(q["ax"]**2 + i_y**2)
    return b * tau * q["sgn_ax"] / norm, -b * tau * i_y / norm


def _creep_integrand(s, q: dict, opts):
    """(0, f_y) per unit length at s of the creep law (vehicle_equations' lateral integrand)."""
    x_body = q["x_front"] - s
    line = q["b"] * _distribution_from(q).at(s)
    return 0, creep_lateral_force(line, q["b"] * q["c"], ca.tan(q["phi"]), q["vy"] + q["rz"] * x_body, q["mu"],
                                  q["eps_v"], opts)


# Quadratures of more points per track than this are summed by one mapped CasADi Function, called
# from the SX graph as a single node, when the model is built for generated C
# (ModelOptions.quadrature_call, set by the fixed-step integrators' builders of C): the
# generated code then stays the same size whatever the quadrature, so a refined variant (a 64 x 5
# reference rule: 320 points) compiles in seconds, where its expanded Rosenbrock step of ~300,000
# instructions took minutes of gcc (docs/codegen.md). Up to this many the sum is
# expanded (the defaults: 24 points of the shear laws, 12 of the creep law; expanded code runs
# fastest, and CasADi's virtual machine, which CVODES and IDAS use, evaluates a call node slowly).
# ASSUMED: 48 = twice the default shear rule, a bound with room above the defaults, not a measured optimum.
INLINE_QUADRATURE_MAX_POINTS = 48
_MAPPED = caches.cache("quadrature_call_nodes", 16)  # symtrack.foundations.caches


def quadrature_points(opts) -> int:
    """The points per track of the tracks' quadrature under these options (the shear laws' split
    rule, or the composite rule lateral_segments x gauss_points; 0 for the 3D vehicle's creep law,
    which sums over its contact segments instead: symtrack.vehicles.vehicle3d)."""
    if opts.lateral_law in SHEAR_LAWS and opts.lateral_split:
        return 6 * opts.shear_points
    if opts.lateral_law not in SHEAR_LAWS and opts.vehicle == "3d":
        return 0
    return opts.lateral_segments * opts.gauss_points


def quadrature_is_mapped(opts) -> bool:
    """Whether a model of these options sums its tracks' quadrature by a call node."""
    return opts.quadrature_call and quadrature_points(opts) > INLINE_QUADRATURE_MAX_POINTS


def codegen_options(opts):
    """The options to generate C from: ``opts`` with ``quadrature_call`` set when that makes its
    quadrature a call node (:func:`quadrature_is_mapped`), else ``opts`` itself (the same code)."""
    mapped = dataclasses.replace(opts, quadrature_call=True)
    return mapped if quadrature_is_mapped(mapped) else opts


def integrate_track(integrand, nodes, rule, q: dict, opts):
    """(sum w f_x, sum w f_y, sum w (x_front - s) f_y) over the nodes (s, w) of integrand(s, q, opts),
    expanded, or (more than INLINE_QUADRATURE_MAX_POINTS nodes and ``opts.quadrature_call``) one
    call of a mapped Function of the points. ``rule``: the same nodes as affine images of fixed
    unit rules, ((a, b, c, t, w), ...) with nodes s = a + b t_i and weights c w_i (a, b, c
    expressions, t and w sequences of floats): the call takes these few scalars and q, not every
    node (what the generated C copies into the call per evaluation)."""
    x_front = q["x_front"]
    if not (opts.quadrature_call and len(nodes) > INLINE_QUADRATURE_MAX_POINTS):
        Fx, Fy, Mz = 0, 0, 0
        for s, w in nodes:
            fx, fy = integrand(s, q, opts)
            Fx += w * fx
            Fy += w * fy
            Mz += w * (x_front - s) * fy
        return Fx, Fy, Mz
    if sum(len(t) for _, _, _, t, _ in rule) != len(nodes):
        raise ValueError("integrate_track: the rule does not hold the nodes")
    names = tuple(sorted(q))
    units = tuple((tuple(map(float, t)), tuple(map(float, w))) for _, _, _, t, w in rule)
    key = (integrand.__name__, units, names, opts)
    mapped = _MAPPED.get(key)
    if mapped is None:
        n = len(nodes)
        s_sym, w_sym = ca.SX.sym("s"), ca.SX.sym("w")
        q_sym = {k: ca.SX.sym(k) for k in names}
        fx, fy = integrand(s_sym, q_sym, opts)
        point = ca.Function(f"{integrand.__name__.strip('_')}_point", [s_sym, w_sym, ca.vertcat(*q_sym.values())],
                            [ca.vertcat(w_sym * fx, w_sym * fy, w_sym * (q_sym["x_front"] - s_sym) * fy)],
                            {"cse": True})
        Q, R = ca.MX.sym("q", len(names)), ca.MX.sym("rule", 3 * len(units))
        S = ca.horzcat(*(R[3 * g] + R[3 * g + 1] * ca.DM(t).T for g, (t, _) in enumerate(units)))
        W = ca.horzcat(*(R[3 * g + 2] * ca.DM(w).T for g, (_, w) in enumerate(units)))
        total = ca.sum2(point.map(n, "serial")(S, W, ca.repmat(Q, 1, n)))
        mapped = _MAPPED.put(key, ca.Function(f"{integrand.__name__.strip('_')}_{n}", [Q, R], [total], ["q", "rule"],
                                              ["sum"], {"never_inline": True}))
    out = mapped(ca.vertcat(*(q[k] for k in names)), ca.vertcat(*(v for a, b, c, _, _ in rule
                                                                        for v in (a, b, c))))
    return out[0], out[1], out[2]


def sprocket_speed_abs(omega, opts):
    """|omega| as the laws use it: exact in ``traction_sign = "sign"`` mode, else regularised by
    ``omega_smoothing_rad_s``."""
    if opts.traction_sign == "sign":
        return ca.fabs(omega)
    return ca.sqrt(omega**2 + opts.omega_smoothing_rad_s**2)


def internal_resistance_N(N, omega, abs_om, r, P: dict, opts):
    """Internal running-gear resistance of a track with normal load N (reconstruction; Wong):
    N (0.0222 + 0.0003 V[km/h]) against the sprocket's rotation."""
    V_kmh = 3.6 * r * abs_om
    return N * (P["internal_resistance_const"] + P["internal_resistance_per_km_h"] * V_kmh) \
        * direction(omega, opts.omega_smoothing_rad_s, opts)


def creep_lateral_force(q, c_line, tan_phi, v_lat, mu, eps_v, opts):
    """The creep law's lateral resistance (reconstruction: a velocity creep) of a load q sliding
    sideways at v_lat; with ``lateral_shear_cap`` at most the soil's strength c_line + q tan(phi)."""
    if opts.lateral_shear_cap:
        return -ca.fmin(mu * q, c_line + q * tan_phi) * ca.tanh(v_lat / eps_v)
    return -mu * q * ca.tanh(v_lat / eps_v)


def shear_exchange_speed(omega, opts):
    """|omega| in the shear states' exchange term (the rate 2 r |omega| / l at which a track's elements
    leave the contact with their displacement and enter with none): sqrt(omega^2 + e^2) (1 - exp(-omega^2
    / e^2)) with e = ``opts.omega_smoothing_rad_s`` (exact in ``traction_sign = "sign"`` mode). From
    |omega| = 10 e on (0.1 rad/s; the factor is then 1 - 4e-44) it is the regularised |omega| the shear law
    divides its slips by (so the lagged law's steady states are the quasi-static law's to rounding), and it
    is 0 at rest, where no element is exchanged: a standing track's shear states then hold the displacement
    that carries its load, as the soil under it does. (The regularised |omega| alone relaxed them with the
    time constant l / (2 r e), 316 s on the reference crawler: a parked vehicle crept downhill at
    0.03 mm/s.) Smooth and even in omega."""
    if opts.traction_sign == "sign":
        return ca.fabs(omega)
    eps = opts.omega_smoothing_rad_s
    return ca.sqrt(omega**2 + eps**2) * (1 - ca.exp(-(omega / eps) ** 2))


# Below this x = 2 |j| / K the unloading ratio is its series (the closed form loses digits to cancellation there:
# its denominator 1 - e^-x (1 + x) is x^2 / 2 to leading order; at 1e-3 the series' error is 1e-10)
_UNLOADING_SERIES_BELOW = 1e-3

# The shortest time constant of the mean shear displacement's elastic unloading [s]: the unloading term of
# shear_rate, u = (M(j) - 1) times the slip, is bounded smoothly by u_max = sqrt(j^2 + K^2) / this (u / sqrt(1 +
# (u / u_max)^2)), so that j far beyond K runs back towards 0 no faster than exp(-t / 1 ms). Far beyond K the
# ratio M ~ 2 j^2 / K^2 is huge (6000 at j = 55 K, 54000 at the 165 K of a spinning track's l / 2) and it
# switches on within sliding_smoothing of the slip's reversal: the unbounded term (its Jacobian 4 j slip / K^2,
# 10^4-10^5 1/s at a 3D hull's landing on hard soil) outran the compiled Rosenbrock's linearly implicit steps
# even at 1/64 of the 10 ms step, and its states went non-finite where eq. (2) on unloading too finished (the
# physics fuzzer, docs/model.md). Below K the bound leaves the elastic unloading as it is (at j = K and 1 m/s
# of reversed slip u is 0.21 of it, the rate 2 % slower; at 0.1 m/s 0.02 %); far beyond K it binds, and the
# stress falls from its plateau within a few ms instead of at once (from 165 K to K in about ln(165) ms =
# 5 ms). (The floor K, not a smaller one: near j = 0 a bound that varies on the scale of shear_smoothing_m is a
# sharp curvature on which CVODES's step choices amplify rounding: a plane's raster against the plane 1.2e-6
# apart with the floor 1 um, 5e-8 without the bound.)
SHEAR_UNLOADING_TIME_MIN_S = 1e-3


def shear_unloading_ratio(j, K, opts):
    """M(j) = S'(0) / S'(j) >= 1: the ratio of the initial slope of Ferretti & Girelli's tractive-effort shape
    S(j) = 1 + K / (2|j|) (exp(-2|j|/K) - 1) to its slope at j. With x = 2|j| / K it is
    x^2 / (2 (1 - e^-x (1 + x))): 1 at j = 0, x^2 / 2 far beyond K (1 + 2x/3 + 7x^2/36 below
    :data:`_UNLOADING_SERIES_BELOW`). A mean displacement j that runs back at M times the slip unloads the
    track's mean stress at the initial slope 1 / K (:func:`shear_rate`)."""
    x = 2 * ca.sqrt(j**2 + opts.shear_smoothing_m**2) / K
    xe = ca.fmax(x, _UNLOADING_SERIES_BELOW)
    exact = xe**2 / (2 * (1 - ca.exp(-xe) * (1 + xe)))
    return ca.if_else(x < _UNLOADING_SERIES_BELOW, 1 + 2 * x / 3 + 7 * x**2 / 36, exact)


def shear_rate(j, omega, v_track, r, l, K, opts):
    """dj/dt of a track's mean shear displacement j (Ferretti & Girelli's eq. 2, elastic on unloading;
    docs/model.md, "Track kinematics and shear displacement"). While the track slides in the sense of j
    (loading) it is eq. (2), -(2 r |omega| / l) j + r omega - v_k (|omega| as :func:`shear_exchange_speed`):
    elements leave the
    contact with their displacement and enter with none, and the mean stress follows S(j). While it slides
    against j (unloading: the slip has reversed) the soil under it unloads from the stress it carries with
    the shear curve's initial slope tau_max / K (Wong's unloading and reloading of a sheared soil; the Bouc-
    Wen hysteresis with equal loading and unloading coefficients, which gives Janosi-Hanamoto's exponential
    on loading): the slip term is M(j) times larger (:func:`shear_unloading_ratio`), so that the mean stress
    S(j) falls at slip / K, not at S'(j) slip. The switch is smooth over ``opts.sliding_smoothing`` of the
    slip ratio (exact in ``traction_sign = "sign"`` mode); steady running is always loading (eq. 2's steady
    state j = i l / 2 unchanged). ``opts.shear_unloading`` false: eq. (2) throughout."""
    if not opts.shear_unloading:
        return shear_eq2_rate(j, omega, v_track, r, l, opts)
    slip = r * omega - v_track
    tread = r * ca.sqrt(omega**2 + opts.omega_smoothing_rad_s**2)
    against = 0.5 * (1 - direction(slip / tread * traction_sign(j, opts), opts.sliding_smoothing, opts))
    unload = (shear_unloading_ratio(j, K, opts) - 1) * against * slip
    # no faster than sqrt(j^2 + K^2) / SHEAR_UNLOADING_TIME_MIN_S (a smooth bound; the constant's note)
    bound = ca.sqrt(j**2 + K**2) / SHEAR_UNLOADING_TIME_MIN_S
    return shear_eq2_rate(j, omega, v_track, r, l, opts) + unload / ca.sqrt(1 + (unload / bound) ** 2)


def shear_eq2_rate(j, omega, v_track, r, l, opts):
    """Ferretti & Girelli's eq. (2), -(2 r |omega| / l) j + r omega - v_k (|omega| as
    :func:`shear_exchange_speed`): the slip that shears the soil under the track less the displacement its
    elements carry out of the contact; dj/dt while the track loads the soil (:func:`shear_rate`), and
    the rate the soil's damping acts on (:func:`shear_retardation_time_s`): zero in steady running."""
    return -(2 * r / l) * shear_exchange_speed(omega, opts) * j + r * omega - v_track


def sprocket_acceleration(torque, F, R_in, r, J):
    """domega/dt of a sprocket: its torque against the thrust and the internal resistance."""
    return (torque - r * (F + R_in)) / J


def shear_retardation_time_s(damping_Pa_s_per_m, K, c, phi, N, b, l):
    """t_d = c'' K / tau_max [s]: the Kelvin-Voigt retardation time of the soil's shear under a track of
    normal load N (docs/model.md, "Lateral resistance and turning", shear damping): the lagged law's shear
    states q (j, j_y, theta) enter
    its forces as q + t_d dq/dt with dq/dt their eq. (2) rate (:func:`shear_eq2_rate`,
    :func:`lateral_shear_rates`; without the unloading factor), so that on the shear curve's initial
    slope tau_max / K the stress is tau_max q / K + c'' dq/dt, the soil's areal damping c'' on the rate
    of its shear deformation (a Kelvin-Voigt element; ASSUMED the cells' c'' in shear as in compression),
    fading with the curve's slope as the strength is mobilised and 0 in steady running. tau_max = c + N tan(phi)
    / (b l), the track's mean strength, floored at 1 Pa (a track that has lifted off a cohesionless soil
    carries none; every contact that carries the vehicle has thousands)."""
    tau_max = ca.fmax(c + N / (b * l) * ca.tan(phi), 1.0)
    return damping_Pa_s_per_m * K / tau_max


def track_slip(v_track, omega, r):
    """The track's longitudinal slip i = 1 - v / (r omega), written (r omega - v) r omega / ((r omega)^2
    + eps^2) with eps = SLIP_SPEED_SCALE_M_S: dimensionally consistent, exactly i times (r omega)^2 /
    ((r omega)^2 + eps^2) (a relative error, never an offset: straight running at 1 m/s reports its true
    slip), and 0 through r omega = 0 instead of a pole."""
    tread = r * omega
    return (tread - v_track) * tread / (tread**2 + SLIP_SPEED_SCALE_M_S**2)


def track_signals(F, R_in, Rc, Fy, N, slip) -> dict:
    """The per-track output signals of a vehicle model (dicts over TRACKS)."""
    signals = {}
    for k in TRACKS:
        signals[f"tractive_{k}_N"] = F[k]
        signals[f"internal_resistance_{k}_N"] = R_in[k]
        signals[f"compaction_resistance_{k}_N"] = Rc[k]
        signals[f"lateral_force_{k}_N"] = Fy[k]
        signals[f"normal_load_{k}_N"] = N[k]
        signals[f"slip_{k}"] = slip[k]
    return signals


def lateral_shear_rates(j_y, theta, omega, vy, rz, x_centre, l, r, opts):
    """(dj_y/dt, dtheta/dt) of a track's lateral shear states (the "shear" law): Ferretti
    & Girelli's shear law written for the lateral sliding velocity at the contact centre, v + r_z x_centre
    (x_centre the centre's body x), and for the yaw rate (the lateral sliding velocity's gradient
    along the track), with eq. (2)'s time constant l / (2 r |omega|) (|omega| as
    :func:`shear_exchange_speed`: no relaxation at rest). Steady states: j_y = (l/2)
    i_y(l/2), half the contact times the lateral slip, as eq. (2)'s j = i l / 2; theta = r_z l /
    (2 r |omega|), the hull's rotation while an element crosses half the contact."""
    decay = (2 * r / l) * shear_exchange_speed(omega, opts)
    return -decay * j_y + vy + rz * x_centre, -decay * theta + rz


def lateral_resistance_max_N(params: dict, opts) -> float:
    """The largest lateral force the two tracks can carry on level ground (for trim's limit
    checks): the soil's shear strength over both contacts, 2 b l c + W tan(phi), for the "shear"
    law (mean pressure or not, the integral of c + p tan(phi) is the same); mu_t W for the "creep"
    law (with lateral_shear_cap, the smaller of the two)."""
    W = params["mass_kg"] * GRAVITY_M_S2
    strength = 2 * params["track_width_m"] * params["contact_length_m"] * params["cohesion_Pa"] \
        + W * np.tan(params["friction_angle_rad"])
    if opts.lateral_law in SHEAR_LAWS:
        return float(strength)
    friction = params["lateral_friction_coeff"] * W
    return float(min(friction, strength)) if opts.lateral_shear_cap else float(friction)


def vehicle_equations(xv, u, acc, P: dict, compaction_N, opts, track_soil=None,
                      layout: StateLayout = PLANAR_LAYOUT) -> dict:
    """All vehicle expressions.

    xv: the 12 states of VEHICLE_STATES (``layout``: PLANAR_LAYOUT), or with the four lateral shear
    states of the "shear" law (PLANAR_LATERAL_LAYOUT); u: commanded torques; acc: the body
    accelerations (a_x, a_y) assumed for the load transfer; P: parameter name -> symbol; compaction_N: the
    compaction resistance (magnitude) of the left and right track from the terrain; track_soil:
    optional track -> (cohesion, friction angle, shear modulus K) of the soil under that track (a
    terrain whose soil varies over the field: symtrack/terrain, soil maps); default P's soil.

    Returns a dict with 'xdot', 'acc_implied' (the accelerations the forces imply: equal to
    acc on the solution of the algebraic loop), the pressure distributions and named signals.
    """
    X, Y, psi, vx, vy, rz, omL, omR, jL, jR, TL, TR = (xv[i] for i in layout.indices(VEHICLE_STATES))
    transient = opts.lateral_law == "shear"
    if transient != (tuple(layout.names) == PLANAR_LATERAL_LAYOUT.names):
        raise ParameterError(f"model.lateral_law = {opts.lateral_law!r} needs the vehicle model "
                             f"{'planar_lateral' if transient else 'planar'} (states {', '.join(layout.names)})")
    lagged = {k: (xv[layout.index(f"lateral_shear_{k}_m")], xv[layout.index(f"shear_twist_{k}_rad")])
              for k in TRACKS} if transient else None
    m = P["mass_kg"]
    Iz = P["yaw_inertia_kg_m2"]
    B = P["track_gauge_m"]
    b = P["track_width_m"]
    l = P["contact_length_m"]
    r = P["sprocket_radius_m"]
    h = P["cg_height_m"]
    e = P["cg_ahead_of_contact_centre_m"]
    J = P["sprocket_inertia_kg_m2"]
    tauT = P["torque_time_constant_s"]
    mu = P["lateral_friction_coeff"]
    eps_v = P["lateral_creep_speed_m_s"]
    drawbar = P["drawbar_pull_N"]
    hd = P["hitch_height_m"]
    c = P["cohesion_Pa"]
    phi = P["friction_angle_rad"]
    K = P["shear_modulus_K_m"]
    ax, ay = acc[0], acc[1]
    W = m * GRAVITY_M_S2

    # Normal loads with lateral load transfer (a left turn, a_y > 0, loads the right track).
    dN = m * ay * h / B
    N = {"left": ca.fmax(W / 2 - dN, 1e-6 * W), "right": ca.fmax(W / 2 + dN, 1e-6 * W)}
    # Pitching moment about the contact centre: traction at ground level moves load rearwards.
    M_N = W * e - m * ax * h - drawbar * hd
    dist = {k: PressureDistribution(N[k], M_N * N[k] / W, b, l) for k in TRACKS}

    omega = {"left": omL, "right": omR}
    shear = {"left": jL, "right": jR}
    torque = {"left": TL, "right": TR}
    # Track centre-line speeds (not the CG speed).
    v_track = {"left": vx - rz * B / 2, "right": vx + rz * B / 2}
    abs_om = {k: sprocket_speed_abs(omega[k], opts) for k in TRACKS}

    F, R_in, Rc, Fy, Mz, jdot, omdot, rates = {}, {}, {}, {}, {}, {}, {}, {}
    s_nodes, w_nodes = gauss_nodes(1.0, opts.lateral_segments, opts.gauss_points)
    x_front = l / 2 - e  # body x of the front end of the contact (s = 0)
    for idx, k in enumerate(TRACKS):
        R_in[k] = internal_resistance_N(N[k], omega[k], abs_om[k], r, P, opts)
        # Compaction resistance from the terrain, opposing the track's motion.
        Rc[k] = compaction_N[idx] * direction(v_track[k], opts.motion_smoothing_m_s, opts)
        if track_soil is not None:
            c, phi, K = track_soil[k]
        # Ferretti & Girelli's mean shear displacement (elastic on unloading)
        jdot[k] = shear_rate(shear[k], omega[k], v_track[k], r, l, K, opts)
        if transient:
            # the lagged law: its shear states with the soil's damping on their eq. (2) rates
            # (shear_retardation_time_s)
            rates[k] = lateral_shear_rates(*lagged[k], omega[k], vy, rz, -e, l, r, opts)
            t_d = shear_retardation_time_s(P["cell_damping_Pa_s_per_m"], K, c, phi, N[k], b, l)
            damped = shear[k] + t_d * shear_eq2_rate(shear[k], omega[k], v_track[k], r, l, opts)
            damped_lagged = tuple(x + t_d * xd for x, xd in zip(lagged[k], rates[k], strict=True))
            F[k], Fy[k], Mz[k] = shear_forces(damped, omega[k], abs_om[k], v_track[k], vy, rz, x_front, dist[k], N[k],
                                              b, l, r, c, phi, K, opts, damped_lagged)
        elif opts.lateral_law in SHEAR_LAWS:
            F[k], Fy[k], Mz[k] = shear_forces(
                shear[k], omega[k], abs_om[k], v_track[k], vy, rz, x_front, dist[k], N[k], b, l, r, c, phi, K, opts)
        else:
            # Ferretti & Girelli's tractive effort: b l [c + (p_s + p_i)/2 tan phi] for a linear distribution equals the
            # integral of the shear strength over the contact, b l c + N tan phi, used here so that
            # the triangular case is right too.
            F[k] = traction_shape(shear[k], K, opts) * (b * l * c + N[k] * ca.tan(phi))
            # Lateral resistance along the track (reconstruction: the velocity-creep law),
            # composite Gauss-Legendre.
            q = {"x_front": x_front, "b": b, "c": c, "phi": phi, "mu": mu, "vy": vy, "rz": rz, "eps_v": eps_v,
                 **_distribution_scalars(dist[k])}
            _, Fy[k], Mz[k] = integrate_track(_creep_integrand, [(sn * l, wn * l) for sn, wn in zip(
                s_nodes, w_nodes, strict=True)], ((0, l, l, s_nodes, w_nodes),), q, opts)
        omdot[k] = sprocket_acceleration(torque[k], F[k], R_in[k], r, J)

    Fx_net = (F["left"] - Rc["left"]) + (F["right"] - Rc["right"]) - drawbar
    acc_implied = ca.vertcat(Fx_net / m, (Fy["left"] + Fy["right"]) / m)
    yaw_moment = (B / 2) * ((F["right"] - Rc["right"]) - (F["left"] - Rc["left"])) + Mz["left"] + Mz["right"]

    xdot = ca.vertcat(
        vx * ca.cos(psi) - vy * ca.sin(psi),
        vx * ca.sin(psi) + vy * ca.cos(psi),
        rz,
        ax + vy * rz,
        ay - vx * rz,
        yaw_moment / Iz,
        omdot["left"], omdot["right"],
        jdot["left"], jdot["right"],
        (u[0] - TL) / tauT,
        (u[1] - TR) / tauT,
    )
    if transient:
        xdot = ca.vertcat(xdot, *(rates[k][0] for k in TRACKS), *(rates[k][1] for k in TRACKS))
    signals = track_signals(F, R_in, Rc, Fy, N, {k: track_slip(v_track[k], omega[k], r) for k in TRACKS})
    return {
        "xdot": xdot,
        "acc_implied": acc_implied,
        "dist": dist,
        "signals": signals,
        "yaw_moment_N_m": yaw_moment,
    }


class PlanarVehicle(VehicleModel):
    """The planar tracked vehicle of this module as a vehicle model (the registry's ``"planar"``,
    :mod:`symtrack.vehicles.registry`, which says what a vehicle model provides): its tracks load the
    terrain's cells, on every plant; the standalone engine carries it.

    Parameters
    ----------
    lateral : PlanarVehicle or None
        The variant with the lateral shear states that :meth:`for_options` gives for the lateral laws
        it carries (its ``lateral_laws``); None: this model for every law.
    """

    name = "planar"
    layout = PLANAR_LAYOUT
    state_names = VEHICLE_STATES
    input_names = INPUTS
    alg_names = ALGEBRAIC
    tracks = TRACKS
    standalone_engine = True
    params = VEHICLE_PARAMS
    soil_params = TRACK_SOIL_PARAMS

    def __init__(self, lateral: PlanarVehicle | None = None):
        self.lateral = lateral

    def for_options(self, opts, surface=None) -> PlanarVehicle:
        """The variant with the lateral shear states for the laws it carries, else this model (the
        planar vehicle feels no ground's shape: ``surface`` is not read)."""
        if self.lateral is not None and opts.lateral_law in self.lateral.lateral_laws:
            return self.lateral
        return self

    def equations(self, xv, u, acc, P: dict, compaction_N, opts, track_soil=None) -> dict:
        """:func:`vehicle_equations`."""
        return vehicle_equations(xv, u, acc, P, compaction_N, opts, track_soil)

    def contact_pose(self, xv) -> ContactPose:
        """x, y and yaw from the state ``xv`` (the vehicle's states, a vector); no heave, pitch or roll."""
        s = VehicleState(xv, self.layout)
        return ContactPose(s["x_m"], s["y_m"], s["yaw_rad"])


class PlanarLateralVehicle(PlanarVehicle):
    """The planar vehicle with two lateral shear states per track (:data:`LATERAL_STATES`, after the
    planar vehicle's 12): the vehicle model of the "shear" lateral law (the registry's
    ``"planar_lateral"``; :func:`symtrack.vehicles.registry.for_options` picks it)."""

    name = "planar_lateral"
    menu_name = "planar"
    lateral_laws = ("shear",)  # the lateral laws whose states it carries (PlanarVehicle.for_options)
    layout = PLANAR_LATERAL_LAYOUT
    state_names = PLANAR_LATERAL_LAYOUT.names

    def equations(self, xv, u, acc, P: dict, compaction_N, opts, track_soil=None) -> dict:
        """:func:`vehicle_equations` on :data:`PLANAR_LATERAL_LAYOUT`."""
        return vehicle_equations(xv, u, acc, P, compaction_N, opts, track_soil, PLANAR_LATERAL_LAYOUT)
