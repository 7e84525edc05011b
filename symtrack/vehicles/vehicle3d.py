"""The 3D tracked vehicle: a rigid hull that heaves, pitches and rolls on the
ground's shape, written once as CasADi SX expressions (``[model] vehicle = "3d"``).

States: the planar vehicle's (:data:`~symtrack.vehicles.planar.VEHICLE_STATES`, and the lateral shear
states of the "shear" law), then the hull's :data:`HULL_STATES`: the CG's height ``z_m`` (world
frame, the same datum as the surface's z0), the pitch (nose up positive) and the roll (left side up
positive), both Euler angles of the hull against the horizontal, and their rates.
``u_m_s``, ``v_m_s`` stay the CG's horizontal velocity in the yaw frame (x along the heading, y to
its left), ``x_m``, ``y_m`` its horizontal position.

Contact (reconstruction; the planar model's structure kept): each track's contact of length l is
``opts.contact_segments`` equal segments; the centre of segment i, at body (x_i, y_k, -h) (x from
the CG, y_k = +-B/2, h the CG height above the track's ground line), is placed in the world by the
hull's pose (R = Rz(yaw) Ry(-pitch) Rx(roll)). Its penetration into the ground is the height of the
surface above it, z0(X_i, Y_i) - Z_i, times the cosine of the ground's inclination there (the depth
measured normal to the ground: a plate pressed normal to the surface, as Bekker's law is measured).
Its pressure is the model's soil law at that sinkage, with the soil's history under it: the front segment
meets virgin soil, each later segment soil pressed to the sinkage H_i of the soil's memory under it (Bekker
loading if it sinks deeper, the unloading/reloading line if not), the states of the homogeneous terrain
:class:`ContactTerrain`, carried from the segment ahead as the track moves over the ground (in steady running
the deepest sinkage ahead of the segment, the history the homogeneous terrain gives its sprocket cell,
:mod:`symtrack.model.homogeneous`), plus the cells' areal damping c'' times the rate of
penetration (the cell equation without the cell's own areal mass: the soil under the track moves with
the hull) where the segment touches the soil (its soil pressure positive: a segment above the ground
feels no damping), never below zero (no tension). The segment's load p b (l / n) acts along the ground's
normal at the segment. Within a segment the pressure is linear, its slope that of the centres' pressures
(:func:`segment_gauss_offsets`), and carried by the segment's two Gauss-Legendre points: a couple
added to the normal loads' moment, and the creep law's lateral resistance summed over the 2 n points
(docs/vehicle3d.md, "Within a segment"; the ground and the soil law are sampled at the centres). So
the load split between and along the tracks follows from the hull's rigid-body equilibrium on the
ground: its shape, the weight's components and the accelerations
(no algebraic loop: ``accel_x_m_s2``, ``accel_y_m_s2`` are the hull's horizontal accelerations,
closed trivially).

Shear (the planar laws, in the local ground plane): each track's tractive and lateral forces are
the planar model's (Ferretti & Girelli's tractive effort and the creep law, or the shear laws of
docs/turning.md) with the track's normal load the sum of its segments' and its pressure the segments' (linear between
segment centres), the track's speed the velocity of its contact centre along the track's tangent in
the ground plane, its lateral sliding the velocity across it. The thrust acts along that tangent at
the contact centre, the lateral force across it (with the planar law's yaw moment about the CG).
Compaction resistance: the soil law's work per metre at the track's deepest penetration, against
the track's motion (the homogeneous terrain's). The internal running-gear resistance loads the
sprocket only (as in the planar model).

Body equations (yaw frame x', y', vertical z; forces F, moments M about the CG from every contact
force and the drawbar pull; W = m g):

    m (du/dt - v r_z) = F_x',   m (dv/dt + u r_z) = F_y',   m dw/dt = F_z - W
    I_pitch d2(pitch)/dt2 = -M_y' (+ the running gear's term below),   I_roll d2(roll)/dt2 = M_x',
    I_z dr_z/dt = M_z

Running gear (the braked chatter): the sprockets, idlers, rollers and tracks spin about the
hull's y axis with the angular momentum kappa J_eq omega_k (:func:`running_gear_momentum_ratio`), so the
hull's pitch and the sprockets share an inertia coupling (the equations of a gyrostat: Euler's second law
for the hull with internal rotors; the kinetic energy 1/2 I q^2 + 1/2 J sum omega^2 - kappa J q sum omega,
omega the sprockets' rates relative to the hull, q the pitch rate nose up):

    (I_pitch - 2 kappa^2 J) dq/dt = -M_y' + kappa sum_k (T_k - r (F_k + R_in,k))
    J domega_k/dt = T_k - r (F_k + R_in,k) + kappa J dq/dt

At steady speed nothing changes; when the thrust varies the running gear takes the reaction of its
spin-up: a fluctuating thrust dF at the ground pitches the hull with the lever h - kappa r (-0.03 m on the
reference crawler), not h (0.6 m). Without it the braked vehicle chattered: the sprocket's shear mode
(about 40 rad/s) drove the hull through the moment h dF, the hull's pitch and heave (coupled by the
contact, loaded off its centre when braking) moved the tracks' normal load, and the traction's
Mohr-Coulomb strength b l c + N tan(phi) times its (negative, braking) shear shape fed it back to the
sprocket (docs/vehicle3d.md, "Studies: a ramp"). The coupling is taken about the pitch axis only
(the roll's tilt of the axle axis, a cos(roll) factor, and the gyroscopic terms are dropped, as below).

Approximations (ASSUMED, said where they apply): the Euler angles' rates are taken as the body's
angular rates and the gyroscopic terms are dropped (pitch and roll rates and the yaw rate of a
crawler are small: 0.1 rad/s at most in the project's manoeuvres); the pitch and roll inertias are
:data:`PITCH_INERTIA_PER_YAW` and :data:`ROLL_INERTIA_PER_YAW` times the yaw inertia (no
parameters of their own yet); the roll and pitch axes are those of the yaw frame (on a ramp of t
the hull's roll axis is tilted by t: a cos t error on the roll inertia only).

The terrain this vehicle takes is :class:`ContactTerrain` (no travelling cells: the hull's
penetration is the sinkage), or on the grid the terrain engine's
:class:`~symtrack.native.grid_engine_model.SegmentSumsTerrain` (``contact_history``: the soil history
of the cells under each segment; docs/vehicle3d.md "The grid under the 3D vehicle"); the channel pool
of IDAS and the grid Rosenbrock is refused (:func:`symtrack.vehicles.registry.check_plant` on its
``plants``), and what the grid path cannot take (:func:`check_grid`).
"""

from __future__ import annotations

import logging
import math

import casadi as ca

from ..foundations.errors import ParameterError, SimulationError
from ..model.layout import ContactPose, StateLayout, VehicleState
from ..soil import law as soil_law
from .base import CONTACT_HULL, VehicleModel
from .planar import (
    ALGEBRAIC,
    GRAVITY_M_S2,
    INPUTS,
    LATERAL_STATES,
    PLANAR_LAYOUT,
    SHEAR_LAWS,
    TRACK_SOIL_PARAMS,
    TRACKS,
    VEHICLE_PARAMS,
    creep_lateral_force,
    direction,
    internal_resistance_N,
    lateral_shear_rates,
    shear_eq2_rate,
    shear_forces,
    shear_rate,
    shear_retardation_time_s,
    sprocket_acceleration,
    sprocket_speed_abs,
    track_signals,
    track_slip,
    traction_shape,
)

__all__ = ["COMPACTION_DEPTH_FLOOR_M", "GAUSS_OFFSET", "HULL_STATES", "PITCH_INERTIA_PER_YAW", "ROLL_INERTIA_PER_YAW",
           "ContactTerrain", "RasterGuard", "SegmentDistribution", "Vehicle3D", "check_contact", "check_grid",
           "check_raster", "footprint_radius_m", "hull_rotation", "make_vehicle", "running_gear_momentum_ratio",
           "segment_gauss_offsets"]

HULL_STATES = ("z_m", "pitch_rad", "roll_rad", "heave_rate_m_s", "pitch_rate_rad_s", "roll_rate_rad_s")
# ASSUMED (module doc): a hull box L x W x H with L ~ 2.3 W and H ~ W (the reference crawler's 3.5 m x
# 1.9 m of its yaw inertia's box) has I_pitch / I_yaw = (L^2 + H^2) / (L^2 + W^2) = 1 and
# I_roll / I_yaw = (W^2 + H^2) / (L^2 + W^2) = 0.32.
PITCH_INERTIA_PER_YAW = 1.0
ROLL_INERTIA_PER_YAW = 0.32
# The compaction resistance's depth is held at least this [m] (the MPC on the 3D vehicle):
# Bekker's work b k z^(n+1) / (n+1) has d/dn = W ln z and d2/dz2 = b k n z^(n-1), both NaN or infinite
# at z = 0, where a track whose every segment has lifted off (an NLP iterate) puts it; the NaN went
# into IPOPT's Hessian and the parameter gradient ("NaN detected for output hess_gamma_x_x",
# "grad_gamma_p") and failed every MPC solve. The value is the Bekker law's own regularisation cap
# (ModelOptions.bekker_regularisation_m, 1e-6 m): the work is unchanged wherever the track sinks at
# least 1 um (every run on the ground: 1-2 mm), and below it is W(1 um) = b k_eq (1e-6 m)^(n+1) / (n+1),
# at most 0.01 N over the soil presets (heavy_clay_wes_40, n = 0.11; 2.5e-5 N on sandy_loam_15), not 0.
COMPACTION_DEPTH_FLOOR_M = 1e-6


def _layout(lateral: bool) -> StateLayout:
    blocks = [(b, PLANAR_LAYOUT.block_names_of(b)) for b in ("pose", "velocity", "sprockets", "shear", "torque")]
    if lateral:
        blocks.append(("lateral_shear", LATERAL_STATES))
    blocks.append(("hull", HULL_STATES))
    return StateLayout(tuple(blocks))


class SegmentDistribution:
    """A track's normal pressure from its segments: ``p[i]`` at the segment centres ``s[i]``
    (from the front, s = 0, to the rear, s = l), linear between centres and constant beyond the
    first and last (the interface of :class:`~symtrack.vehicles.planar.PressureDistribution`:
    ``N``, ``at(s)``, ``idler``, ``sprocket``)."""

    def __init__(self, p, s, ds, N):
        self.p, self.s, self.ds, self.N = p, s, ds, N

    def at(self, s):
        n = len(self.p)
        if n == 1:
            return self.p[0]
        out = 0
        for i, (pi, si) in enumerate(zip(self.p, self.s, strict=True)):
            hat = 1 - ca.fabs(s - si) / self.ds
            if i == 0:
                hat = ca.if_else(s < si, 1, hat)
            elif i == n - 1:
                hat = ca.if_else(s > si, 1, hat)
            out += pi * ca.fmax(0, hat)
        return out

    @property
    def idler(self):
        return self.p[0]

    @property
    def sprocket(self):
        return self.p[-1]

    def least_squares_line(self):
        """(alpha, beta): the least-squares line p = alpha + beta s through the segment pressures (at
        the centres of equal segments its integral over the contact is the segments' load, and for a
        linear pressure it is that pressure). The subsoil stress takes it: the terrain engine's
        (subsoil.h's strip tables are for a linear line per track) and the homogeneous run's column
        (the outputs ``p_idler_*_Pa``, ``p_sprocket_*_Pa`` are its ends)."""
        n = len(self.p)
        if n == 1:
            return self.p[0], 0
        sbar = sum(self.s) / n
        pbar = sum(self.p) / n
        sxx = sum((si - sbar) ** 2 for si in self.s)
        beta = sum((si - sbar) * (pi - pbar) for si, pi in zip(self.s, self.p, strict=True)) / sxx
        return pbar - beta * sbar, beta


# the two-point Gauss-Legendre rule on a segment of length ds: its points at the centre -+ ds / (2 sqrt 3),
# weights ds / 2 each (exact for cubics; Abramowitz & Stegun 25.4.29)
GAUSS_OFFSET = 1 / (2 * math.sqrt(3))


def segment_gauss_offsets(p):
    """d_i = g_i a: the pressure's change from a segment's centre to its rear Gauss point (s_i + a, a =
    ds / (2 sqrt 3)) of the linear pressure p_i + g_i (s - s_i) within segment i, g_i the slope of the
    centres' pressures ``p`` (front to rear, equal spacing ds): the central difference (p_{i+1} -
    p_{i-1}) / (2 ds) inside, the three-point one-sided difference (-3 p_0 + 4 p_1 - p_2) / (2 ds) at
    the ends (exact for a quadratic; the two-point one with two segments, 0 with one), clamped to
    [-p_i, p_i] so that neither Gauss point's pressure is negative (a segment lifted off, or beside
    one: the slope-limited linear reconstruction of finite-volume schemes, van Leer 1979). The segment's
    load p_i b ds and its centre stay; the slope adds the first moment g_i b ds^3 / 12 about the centre."""
    n = len(p)
    c = GAUSS_OFFSET  # a / ds
    out = []
    for i in range(n):
        if n == 1:
            d = 0 * p[0]
        elif n == 2:
            d = (p[1] - p[0]) * c
        elif i == 0:
            d = (-3 * p[0] + 4 * p[1] - p[2]) * (c / 2)
        elif i == n - 1:
            d = (3 * p[n - 1] - 4 * p[n - 2] + p[n - 3]) * (c / 2)
        else:
            d = (p[i + 1] - p[i - 1]) * (c / 2)
        out.append(ca.fmin(ca.fmax(d, -p[i]), p[i]))
    return out


def running_gear_momentum_ratio(contact_length_m, sprocket_radius_m):
    """kappa = H / (J_eq omega): the running gear's angular momentum about its axle's axis over the equivalent
    inertia's J_eq omega, for a track whose J_eq is its belt's m_track r^2 (the reference crawler's preset:
    "track mass about 200 kg, m_track r^2 ~ 29 kg m^2" of J_eq = 30) looped around a sprocket and an idler
    of radius r whose centres are the contact length l apart (ASSUMED: the simplest loop; no parameters of
    the loop's shape exist). A belt of mass per length lambda moving at v along a closed plane loop has
    the angular momentum lambda v oint(rho x d rho) = lambda v 2 A about any point (A the loop's area,
    Green's theorem), so with L = 2 l + 2 pi r, A = 2 r l + pi r^2 and v = r omega:
    H = m_track (2 A / L) r omega = J_eq omega (2 l + pi r) / (l + pi r). A round loop (l = 0) gives 1
    (a wheel); the reference crawler 1.668."""
    return (2 * contact_length_m + math.pi * sprocket_radius_m) / (contact_length_m + math.pi * sprocket_radius_m)


def hull_rotation(yaw, pitch, roll):
    """R = Rz(yaw) Ry(-pitch) Rx(roll): body -> world (pitch nose up, roll left side up)."""
    cy, sy, cp, sp, cr, sr = ca.cos(yaw), ca.sin(yaw), ca.cos(pitch), ca.sin(pitch), ca.cos(roll), ca.sin(roll)
    Rz = ca.SX(3, 3)
    Rz[0, 0], Rz[0, 1], Rz[1, 0], Rz[1, 1], Rz[2, 2] = cy, -sy, sy, cy, 1
    Ry = ca.SX(3, 3)  # rotation about y by -pitch
    Ry[0, 0], Ry[0, 2], Ry[1, 1], Ry[2, 0], Ry[2, 2] = cp, -sp, 1, sp, cp
    Rx = ca.SX(3, 3)
    Rx[0, 0], Rx[1, 1], Rx[1, 2], Rx[2, 1], Rx[2, 2] = 1, cr, -sr, sr, cr
    return Rz, ca.mtimes(Ry, Rx)


class Vehicle3D(VehicleModel):
    """The 3D vehicle (module doc) as a vehicle model of :mod:`symtrack.vehicles.registry`: its own
    contact (the hull's penetration is the sinkage), on the homogeneous terrain and the terrain engine;
    the MPC's prediction may take its hull quasi-static; its figures are the attitude, the load split
    and the path's elevation.

    Parameters
    ----------
    surface : symtrack.terrain.surface.Surface or None
        The ground's shape z0(x, y) (None: flat ground at z0 = 0).
    lateral : bool
        True: with the four lateral shear states of the "shear" law (the registry's
        ``"3d_lateral"``); False: for "creep" and "shear_quasistatic" (``"3d"``).
    """

    input_names = INPUTS
    alg_names = ALGEBRAIC
    tracks = TRACKS
    contact = CONTACT_HULL  # the hull's penetration is the sinkage: it takes a ContactTerrain
    # the channel pool of IDAS and the grid Rosenbrock is coupled to the tracks' pressure lines, not to
    # segments; the standalone engine program and the engine FMU carry the planar vehicle's sums only
    plants = frozenset({"homogeneous", "engine"})
    hull_states = HULL_STATES
    figures = ("attitude", "load_split", "path_elevation")
    params = VEHICLE_PARAMS  # the planar vehicle's body and traction parameters
    soil_params = TRACK_SOIL_PARAMS

    def __init__(self, surface=None, lateral: bool = False):
        self.surface = None if surface is None or surface.is_flat else surface
        # (z0, dz0/dx, dz0/dy); an elevation raster is a B-spline of degree 1 (bilinear), a call node in SX:
        # the contact's points then go through one call of the surface mapped over them (grounds)
        self._ground_f = None if self.surface is None else self.surface.function()
        self._mapped = self.surface is not None and self.surface.raster is not None
        self._ground_maps = {}
        self.lateral = bool(lateral)
        self.name = "3d_lateral" if lateral else "3d"
        self.menu_name = "3d"
        self.layout = _layout(self.lateral)
        self.state_names = self.layout.names

    # -- the capabilities (symtrack.vehicles.base) ---------------------------------------------------------
    def for_options(self, opts, surface=None) -> Vehicle3D:
        """The 3D vehicle for ``opts`` (:func:`make_vehicle`) on the ground ``surface``."""
        return make_vehicle(opts, surface)

    def check_ground(self, opts, surface, params: dict) -> None:
        """:func:`check_contact`."""
        check_contact(opts, surface, params)

    def check_start(self, surface, params: dict, x_m: float, y_m: float) -> None:
        """:func:`check_raster`."""
        check_raster(surface, params, x_m, y_m)

    def check_grid(self, terrain) -> None:
        """:func:`check_grid`."""
        check_grid(terrain)

    # -- the ground ------------------------------------------------------------------------------------
    def ground(self, x, y):
        """(z0, dz0/dx, dz0/dy) of the ground at world (x, y) (CasADi)."""
        if self.surface is None:
            return 0, 0, 0
        z, gx, gy = self._ground_f(x, y)
        return z, gx, gy

    def grounds(self, points):
        """[(z0, dz0/dx, dz0/dy)] of the ground at the world points ``points`` (pairs (x, y), CasADi). On an
        elevation raster the points go through one call of the surface mapped over them
        (:meth:`~symtrack.terrain.surface.Surface.points_function`): one call node to the raster in the SX
        graph instead of one per point, and one per derivative of it (the penetrations' rates, the
        model's Jacobians: a few per Jacobian, not a few per point and per direction), the same values.
        An analytic surface (no call node) is expanded point by point as :meth:`ground` does."""
        if not self._mapped or len(points) < 2:
            return [self.ground(x, y) for x, y in points]
        n = len(points)
        f = self._ground_maps.get(n)
        if f is None:
            f = self._ground_maps[n] = self.surface.points_function(n, self._ground_f)
        z, gx, gy = f(ca.horzcat(*(x for x, _ in points)), ca.horzcat(*(y for _, y in points)))
        return [(z[i], gx[i], gy[i]) for i in range(n)]

    def contact_pose(self, xv) -> ContactPose:
        s = VehicleState(xv, self.layout)
        return ContactPose(s["x_m"], s["y_m"], s["yaw_rad"], s["z_m"], s["pitch_rad"], s["roll_rad"])

    # -- the equations -----------------------------------------------------------------------------------
    def equations(self, xv, u, acc, P: dict, compaction_N, opts, track_soil=None,
                  contact_history=None, segment_history=None) -> dict:
        """The vehicle's state derivatives and signals (module doc). ``acc`` is not used (no
        load-transfer loop: ``acc_implied`` returns the accelerations); ``compaction_N`` neither
        (the contact's own compaction resistance) unless ``contact_history`` is given; ``track_soil``
        as the planar model's. ``contact_history``: the grid under the hull (the terrain engine,
        docs/vehicle3d.md "The grid under the 3D vehicle"): track -> the soil history (the
        :data:`~symtrack.soil.law.HISTORY_NAMES`) of the cells under each segment; each segment's
        pressure is then the law on that history (not the homogeneous rule of the segments ahead) and
        the compaction resistance is ``compaction_N``, the cells' own work. ``segment_history``: the
        homogeneous terrain's memory (:class:`ContactTerrain`): track -> the deepest sinkage of the soil
        under each segment behind the front one, its rates set on ``dist[track].history_rates``
        (:func:`segment_history_rates`)."""
        if (opts.lateral_law == "shear") != self.lateral:
            raise ParameterError(f"model.lateral_law = {opts.lateral_law!r} needs the vehicle model "
                                 f"{'3d_lateral' if opts.lateral_law == 'shear' else '3d'}")
        lay = self.layout
        S = VehicleState(xv, lay)
        X, Y, psi = S["x_m"], S["y_m"], S["yaw_rad"]
        vx, vy, rz = S["u_m_s"], S["v_m_s"], S["yaw_rate_rad_s"]
        Z, pitch, roll = S["z_m"], S["pitch_rad"], S["roll_rad"]
        w, q, pr = S["heave_rate_m_s"], S["pitch_rate_rad_s"], S["roll_rate_rad_s"]
        m, Iz = P["mass_kg"], P["yaw_inertia_kg_m2"]
        B, b, l, r, h, e = (P[k] for k in ("track_gauge_m", "track_width_m", "contact_length_m", "sprocket_radius_m",
                                           "cg_height_m", "cg_ahead_of_contact_centre_m"))
        J, tauT, mu, eps_v = (P[k] for k in ("sprocket_inertia_kg_m2", "torque_time_constant_s",
                                             "lateral_friction_coeff", "lateral_creep_speed_m_s"))
        drawbar, hd = P["drawbar_pull_N"], P["hitch_height_m"]
        c, phi, K = P["cohesion_Pa"], P["friction_angle_rad"], P["shear_modulus_K_m"]
        W = m * GRAVITY_M_S2
        law_obj = soil_law.make(opts)
        law = law_obj.vector(P)
        damping = P["cell_damping_Pa_s_per_m"]

        # kinematics: the pose's rates (Euler rates = body rates, module doc)
        pose_idx = lay.indices(("x_m", "y_m", "yaw_rad", "z_m", "pitch_rad", "roll_rad"))
        Xdot = vx * ca.cos(psi) - vy * ca.sin(psi)
        Ydot = vx * ca.sin(psi) + vy * ca.cos(psi)
        pose_rates = ca.SX.zeros(xv.numel())
        for i, v in zip(pose_idx, (Xdot, Ydot, rz, w, q, pr), strict=True):
            pose_rates[i] = v
        Rz, Rpr = hull_rotation(psi, pitch, roll)
        R = ca.mtimes(Rz, Rpr)
        cg = ca.vertcat(X, Y, Z)

        def world(xb, yb, zb):
            return cg + ca.mtimes(R, ca.vertcat(xb, yb, zb))

        def rate(expr):
            return ca.jtimes(expr, xv, pose_rates)

        n_seg = opts.contact_segments
        ds = l / n_seg
        x_front = l / 2 - e
        s_c = [(i + 0.5) * ds for i in range(n_seg)]
        a_gauss = ds * GAUSS_OFFSET  # the Gauss-Legendre points of a segment: its centre -+ a_gauss
        ex = R[:, 0]  # the hull's forward axis in the world
        Fw = ca.SX.zeros(3)  # resultant contact force (world)
        Mw = ca.SX.zeros(3)  # resultant moment about the CG (world)
        F, R_in, Rc, Fy, Mz, jdot, omdot, N, dist, rates_lat, signals = ({} for _ in range(11))
        omega = {k: S[f"omega_{k}_rad_s"] for k in TRACKS}
        shear = {k: S[f"shear_{k}_m"] for k in TRACKS}
        torque = {k: S[f"torque_{k}_N_m"] for k in TRACKS}
        abs_om = {k: sprocket_speed_abs(omega[k], opts) for k in TRACKS}
        depth, v_tracks = {}, {}
        # the ground under the contact's points, all of them in one evaluation (grounds: one call node on a
        # raster): the segments' centres of both tracks; the tracks' ends and the CG (the signals)
        gauge = {k: B / 2 if k == "left" else -B / 2 for k in TRACKS}
        centres = {k: [world(x_front - s, gauge[k], -h) for s in s_c] for k in TRACKS}
        under = self.grounds([(pt[0], pt[1]) for k in TRACKS for pt in centres[k]])
        ends = {(k, end): world(x_front - s_end, gauge[k], -h) for k in TRACKS
                for end, s_end in (("idler", 0), ("sprocket", l))}
        under_ends = self.grounds([(pe[0], pe[1]) for pe in ends.values()] + [(X, Y)])
        ground_ends = dict(zip(ends, under_ends[:-1], strict=True))  # (the last: the CG's)
        # each centre's normal and penetration (normal to the ground) and its rate
        contact = []
        for pt, (z0, gx, gy) in zip((pt for k in TRACKS for pt in centres[k]), under, strict=True):
            norm = ca.sqrt(1 + gx**2 + gy**2)
            contact.append((ca.vertcat(-gx, -gy, 1) / norm, (z0 - pt[2]) / norm))
        if self._mapped:  # the rates of all in one derivative: one call node (grounds)
            rates = ca.vertsplit(rate(ca.vertcat(*(delta for _, delta in contact))))
        else:
            rates = [rate(delta) for _, delta in contact]
        for t, k in enumerate(TRACKS):
            yk = gauge[k]
            p_seg, n_sum, pts, normals, deltas = [], 0, [], [], []
            z_hist, deepest = 0, 0
            for i in range(n_seg):
                pt = centres[k][i]
                nrm, delta = contact[t * n_seg + i]
                ddelta = rates[t * n_seg + i]
                deltas.append(delta)
                if contact_history is not None:
                    p_soil = law_obj.pressure(delta, contact_history[k][i], law)
                elif i == 0:
                    p_soil = law_obj.pressure(delta, (0, 0, 0, 0, 0), law)
                else:
                    if segment_history is not None:  # the soil's memory under the segment (ContactTerrain)
                        z_hist = segment_history[k][i - 1]
                    p_soil = law_obj.pressure(delta, (z_hist, law_obj.virgin_pressure(z_hist, law), 0, 0, 0), law)
                z_hist = ca.fmax(z_hist, ca.fmax(delta, 0))
                deepest = ca.fmax(deepest, ca.fmax(delta, 0))
                # the cells' damping only where the segment touches the soil (p_soil > 0): above the ground
                # (or above the rebound of soil pressed ahead) a segment moving toward it feels nothing
                p = ca.fmax(p_soil + ca.if_else(p_soil > 0, damping * ddelta, 0), 0)
                p_seg.append(p)
                pts.append(pt)
                normals.append(nrm)
                n_sum += p * b * ds
            N[k] = n_sum
            # the pressure within each segment: linear, p_i + g_i (s - s_i), carried by its two
            # Gauss-Legendre points s_i -+ a (module doc, "Within a segment")
            dp = segment_gauss_offsets(p_seg)
            depth[k] = ca.fmax(deepest, COMPACTION_DEPTH_FLOOR_M)  # (not 0: the NaN of its derivatives)
            dist[k] = SegmentDistribution(p_seg, s_c, ds, n_sum)
            # the track's ground plane: its mean normal; the tangent along the track and across it
            nk = sum(normals[1:], normals[0]) / n_seg
            nk = nk / ca.norm_2(nk)
            tx = ex - ca.dot(ex, nk) * nk
            tx = tx / ca.norm_2(tx)
            ty = ca.cross(nk, tx)
            centre = world(-e, yk, -h)
            vel = rate(centre)
            v_track = ca.dot(vel, tx)
            v_tracks[k] = v_track
            if segment_history is not None:
                dist[k].history_rates = segment_history_rates(segment_history[k], deltas, v_track, ds, opts)
            v_lat_centre = ca.dot(vel, ty)
            vy_eff = v_lat_centre + rz * e  # the lateral speed at the CG's x that gives it at the centre (x = -e)
            if track_soil is not None:
                c, phi, K = track_soil[k]
            R_in[k] = internal_resistance_N(N[k], omega[k], abs_om[k], r, P, opts)
            if contact_history is not None:
                Rc[k] = compaction_N[TRACKS.index(k)] * direction(v_track, opts.motion_smoothing_m_s, opts)
            else:
                Rc[k] = law_obj.compaction_work(depth[k], law, b) * direction(v_track, opts.motion_smoothing_m_s, opts)
            # Ferretti & Girelli's mean shear displacement (elastic on unloading)
            jdot[k] = shear_rate(shear[k], omega[k], v_track, r, l, K, opts)
            if self.lateral:
                # the lagged law: its shear states with the soil's damping on their eq. (2) rates
                # (planar.shear_retardation_time_s)
                lagged = (S[f"lateral_shear_{k}_m"], S[f"shear_twist_{k}_rad"])
                rates_lat[k] = lateral_shear_rates(*lagged, omega[k], vy_eff, rz, -e, l, r, opts)
                t_d = shear_retardation_time_s(damping, K, c, phi, N[k], b, l)
                damped = shear[k] + t_d * shear_eq2_rate(shear[k], omega[k], v_track, r, l, opts)
                damped_lagged = tuple(x + t_d * xd for x, xd in zip(lagged, rates_lat[k], strict=True))
                F[k], Fy[k], Mz[k] = shear_forces(damped, omega[k], abs_om[k], v_track, vy_eff, rz, x_front, dist[k],
                                                  N[k], b, l, r, c, phi, K, opts, damped_lagged)
            elif opts.lateral_law in SHEAR_LAWS:
                F[k], Fy[k], Mz[k] = shear_forces(shear[k], omega[k], abs_om[k], v_track, vy_eff, rz, x_front, dist[k],
                                                  N[k], b, l, r, c, phi, K, opts)
            else:
                F[k] = traction_shape(shear[k], K, opts) * (b * l * c + N[k] * ca.tan(phi))
                fy_sum, mz_sum = 0, 0
                for s, p, d in zip(s_c, p_seg, dp, strict=True):
                    # the segment's two Gauss points: the front one (s - a) carries p - d, the rear one p + d
                    for x_body, pg in ((x_front - s + a_gauss, p - d), (x_front - s - a_gauss, p + d)):
                        fy = creep_lateral_force(pg * b * ds / 2, b * ds / 2 * c, ca.tan(phi), vy_eff + rz * x_body, mu,
                                                 eps_v, opts)
                        fy_sum += fy
                        mz_sum += x_body * fy
                Fy[k], Mz[k] = fy_sum, mz_sum
            omdot[k] = sprocket_acceleration(torque[k], F[k], R_in[k], r, J)
            # forces on the hull: the segments' normal loads, the thrust less the compaction
            # resistance along the track, the lateral force across it at the contact centre with the
            # rest of the planar law's yaw moment about the normal
            for pt, nrm, p, d in zip(pts, normals, p_seg, dp, strict=True):
                f = p * b * ds * nrm
                Fw += f
                # the two Gauss points' loads (p -+ d) b ds / 2 at pt +- a ex: the centre's moment and the
                # couple of the pressure's slope within the segment
                Mw += ca.cross(pt - cg, f) - a_gauss * d * b * ds * ca.cross(ex, nrm)
            f_shear = (F[k] - Rc[k]) * tx + Fy[k] * ty
            Fw += f_shear
            Mw += ca.cross(centre - cg, f_shear) + (Mz[k] - (-e) * Fy[k]) * nk
            # the sinkage under the track's ends (the rigid track's penetration there)
            for end in ("idler", "sprocket"):
                pe, ze = ends[(k, end)], ground_ends[(k, end)]
                signals[f"sinkage_{end}_{k}_m"] = (ze[0] - pe[2]) / ca.sqrt(1 + ze[1] ** 2 + ze[2] ** 2)
            # the track's pressure line: the least-squares line through its segments, at the track's ends
            alpha, beta = dist[k].least_squares_line()
            signals[f"p_idler_{k}_Pa"] = alpha
            signals[f"p_sprocket_{k}_Pa"] = alpha + beta * l
        # the drawbar pull, horizontal against the heading, at the hitch height
        hitch = world(-e, 0, hd - h)
        f_bar = -drawbar * ca.vertcat(ca.cos(psi), ca.sin(psi), 0)
        Fw += f_bar
        Mw += ca.cross(hitch - cg, f_bar)
        # into the yaw frame
        Fy_frame = ca.mtimes(Rz.T, Fw)
        My_frame = ca.mtimes(Rz.T, Mw)
        ax, ay = Fy_frame[0] / m, Fy_frame[1] / m
        I_pitch, I_roll = PITCH_INERTIA_PER_YAW * Iz, ROLL_INERTIA_PER_YAW * Iz
        yaw_moment = My_frame[2]
        # the running gear's angular momentum kappa J omega about the pitch axis (module doc, "Running
        # gear"): (I_pitch - 2 kappa^2 J) dq/dt = -M_y' + kappa sum_k J_eq f_k, domega_k/dt = f_k + kappa dq/dt,
        # f_k = (T_k - r (F_k + R_in,k)) / J the sprocket's own rate
        kappa = running_gear_momentum_ratio(l, r)
        pitch_acc = (-My_frame[1] + kappa * J * sum(omdot[k] for k in TRACKS)) / (I_pitch - 2 * kappa**2 * J)
        xdot = [None] * lay.size
        derivs = {
            "x_m": Xdot, "y_m": Ydot, "yaw_rad": rz,
            "u_m_s": ax + vy * rz, "v_m_s": ay - vx * rz, "yaw_rate_rad_s": yaw_moment / Iz,
            "z_m": w, "pitch_rad": q, "roll_rad": pr,
            "heave_rate_m_s": (Fy_frame[2] - W) / m,
            "pitch_rate_rad_s": pitch_acc,
            "roll_rate_rad_s": My_frame[0] / I_roll,
        }
        for k, ui in zip(TRACKS, (u[0], u[1]), strict=True):
            derivs[f"omega_{k}_rad_s"] = omdot[k] + kappa * pitch_acc
            derivs[f"shear_{k}_m"] = jdot[k]
            derivs[f"torque_{k}_N_m"] = (ui - torque[k]) / tauT
            if self.lateral:
                derivs[f"lateral_shear_{k}_m"], derivs[f"shear_twist_{k}_rad"] = rates_lat[k]
        for name, v in derivs.items():
            xdot[lay.index(name)] = v
        signals.update(track_signals(F, R_in, Rc, Fy, N, {k: track_slip(v_tracks[k], omega[k], r)
                                                          for k in TRACKS}))
        signals["pitch_rad"] = pitch
        signals["roll_rad"] = roll
        signals["z_m"] = Z
        signals["ground_z_m"] = under_ends[-1][0] + 0 * X
        return {"xdot": ca.vertcat(*xdot), "acc_implied": ca.vertcat(ax, ay), "dist": dist, "signals": signals,
                "yaw_moment_N_m": yaw_moment}


def track_speed_abs(v, opts):
    """|v| of a track's speed over the ground in the soil history's transport (:func:`segment_history_rates`):
    sqrt(v^2 + e^2) (1 - exp(-v^2 / e^2)) with e = ``opts.motion_smoothing_m_s`` (exact in ``traction_sign =
    "sign"`` mode): smooth and even, |v| from |v| = 10 e on, 0 at rest (a standing hull's soil keeps its
    memory), as the shear states' exchange speed (:func:`~symtrack.vehicles.planar.shear_exchange_speed`)."""
    if opts.traction_sign == "sign":
        return ca.fabs(v)
    eps = opts.motion_smoothing_m_s
    return ca.sqrt(v**2 + eps**2) * (1 - ca.exp(-(v / eps) ** 2))


def segment_history_rates(history, deltas, v_track, ds, opts):
    """dH_i/dt of the soil's memory under a track's segments i = 1 .. n - 1 (:class:`ContactTerrain`): the soil
    under segment i is replaced, at the track's speed over the ground |v| (:func:`track_speed_abs`) per segment
    length ds, by the soil under the segment ahead with the deepest sinkage it has had there,
    T_i = max(H_(i-1), max(delta_(i-1), 0)) (H_0 = 0: the front segment meets virgin soil), the first-order
    upwind transport dH_i/dt = |v| (T_i - H_i) / ds. Its steady state is the deepest sinkage ahead of the
    segment at the present pose. ``history`` are the H_i, ``deltas`` the n segments' penetrations (front
    first)."""
    speed = track_speed_abs(v_track, opts) / ds
    rates, ahead = [], 0
    for i, h in enumerate(history):
        ahead = ca.fmax(ahead, ca.fmax(deltas[i], 0)) if i == 0 else ca.fmax(history[i - 1], ca.fmax(deltas[i], 0))
        rates.append(speed * (ahead - h))
    return rates


class ContactTerrain:
    """The homogeneous terrain of the 3D vehicle: virgin soil following the surface, no travelling
    cells (the hull's penetration is the sinkage, :mod:`symtrack.vehicles.vehicle3d`); the soil law's
    signals come from the vehicle. Its states are the soil's memory under the tracks: for each track and
    each segment i behind the front one (``soil_history_{track}_{i}_m``, i = 1 .. n - 1 from the front),
    the deepest sinkage H_i the soil under it has had, carried from the segment ahead as the track moves over
    the ground (:func:`segment_history_rates`); the segment's pressure is the soil law on it (docs/vehicle3d.md,
    "The soil's memory under the hull"). At rest the memory holds, so the contact's pressure is a function of
    the pose and of that memory, elastic at a given memory: a cycle of the hull's heave and pitch gives back
    what it took. (A history taken from the present pose, the deepest sinkage of the segments ahead now, gave a
    contact whose forces have no potential: such a cycle fed the hull energy, the sign of the work set by the
    sense of the cycle; tests/test_physics_fuzz.py.)"""

    name = "homogeneous"
    param_names = ()

    def __init__(self, opts, memory: bool = True):
        """``memory`` false: no states, each segment's history the deepest sinkage of the segments ahead at the
        present pose (the memory's steady state: the MPC's quasi-static hull, symtrack.control.mpc)."""
        self.opts = opts
        self.memory = bool(memory)
        self.state_names = history_state_names(opts.contact_segments) if self.memory else ()

    def segment_history(self, xc):
        """track -> the memory states H_1 .. H_(n-1) of its segments (front to rear)."""
        n = self.opts.contact_segments - 1
        return {k: [xc[t * n + i] for i in range(n)] for t, k in enumerate(TRACKS)}

    def compaction(self, xv, xc, P, Q):
        return ca.DM.zeros(len(TRACKS))  # the 3D vehicle computes its own (module doc)

    def equations(self, xv, xc, dist, P, Q):
        if not self.memory or not self.state_names:
            return ca.SX(0, 1), {}
        return ca.vertcat(*(r for k in TRACKS for r in dist[k].history_rates)), {}


def history_state_names(contact_segments: int) -> tuple:
    """The names of :class:`ContactTerrain`'s states for ``contact_segments`` segments per track."""
    return tuple(f"soil_history_{k}_{i}_m" for k in TRACKS for i in range(1, contact_segments))


def make_vehicle(opts, surface=None) -> Vehicle3D:
    """The 3D vehicle for model options ``opts`` (with the lateral shear states for the "shear" law)."""
    return Vehicle3D(surface, lateral=opts.lateral_law == "shear")


# segments per furrow period at least (the same sampling the grid's cells need: MIN_FURROW_CELLS)
MIN_SEGMENTS_PER_FURROW = 4
log = logging.getLogger("symtrack.vehicle3d")
# (contact_segments, furrow spacing, depth, heading) already warned of in this process (check_contact)
_FURROWS_WARNED: set = set()


def check_contact(opts, surface, params: dict) -> None:
    """A :class:`ParameterError` naming ``model.contact_segments`` when the track's segments cannot
    resolve the furrows of ``surface``: a segment at most a quarter of the furrow spacing (furrows
    running across the track are sampled like the grid's cells, four points a period at least).
    Furrows it takes are warned of, one line once a process for a ground and a segment count: across
    them the run's figures still change with the segments (docs/vehicle3d.md, "Limits")."""
    if surface is None or getattr(surface, "furrow_depth_m", 0.0) <= 0.0:
        return
    l = float(params["contact_length_m"])
    need = math.ceil(MIN_SEGMENTS_PER_FURROW * l / surface.furrow_spacing_m - 1e-9)
    if opts.contact_segments < need:
        raise ParameterError(
            f"model.contact_segments = {opts.contact_segments} is too few for furrows every "
            f"{surface.furrow_spacing_m:g} m under a {l:g} m contact: the allowed range is [{need}, 64] (a segment "
            f"at most a quarter of the furrow spacing, {MIN_SEGMENTS_PER_FURROW} segments a furrow period)")
    key = (opts.contact_segments, surface.furrow_spacing_m, surface.furrow_depth_m, surface.furrow_heading_deg)
    if key not in _FURROWS_WARNED:
        _FURROWS_WARNED.add(key)
        log.warning(
            "terrain.surface: furrows every %g m, %g m deep, under the 3D vehicle with model.contact_segments = %d: "
            "across them its figures are not converged in the segments (where the rigid track's ends press in, the "
            "soil being loaded can be centimetres long, a segment is %.3g m; docs/vehicle3d.md, \"Limits\"): compare "
            "runs at several counts (1 to 64); the run goes on", surface.furrow_spacing_m, surface.furrow_depth_m,
            opts.contact_segments, l / opts.contact_segments)


def footprint_radius_m(params: dict) -> float:
    """The radius [m] of a horizontal circle about the CG that holds every point of the tracks' contact
    whatever the hull's attitude: hypot(l/2 + |e|, (B + b)/2), the contact's corners, plus h, the
    largest horizontal offset of the ground line below the CG when the hull tilts."""
    l, e, B, b, h = (float(params[k]) for k in ("contact_length_m", "cg_ahead_of_contact_centre_m", "track_gauge_m",
                                                "track_width_m", "cg_height_m"))
    return math.hypot(l / 2 + abs(e), (B + b) / 2) + h


def _raster_area(raster, radius_m: float) -> tuple[float, float, float, float]:
    """Where the CG may be on ``raster``: its pixel centres' hull (between them the heights are bilinear,
    beyond it they would be the edge's) less ``radius_m`` on every side."""
    x0, x1, y0, y1 = raster.bounds()
    half = 0.5 * raster.pixel_m
    return x0 + half + radius_m, x1 - half - radius_m, y0 + half + radius_m, y1 - half - radius_m


def check_raster(surface, params: dict, x_m: float, y_m: float, where: str = "terrain.surface") -> None:
    """A :class:`ParameterError` naming the key unless the 3D vehicle on homogeneous soil can start on
    ``surface``'s elevation raster at (``x_m``, ``y_m``): the raster needs its place (a .npy's
    ``elevation_origin_m``: there is no field to put it at) and must hold the vehicle's footprint
    (:func:`footprint_radius_m` about the CG) inside its pixel centres' hull. NaN and the slope limit are
    checked when the raster is read (:func:`~symtrack.terrain.surface.parse_surface`); leaving the
    raster during a run is :class:`RasterGuard`'s."""
    raster = getattr(surface, "raster", None)
    if raster is None:
        return
    if raster.origin_m is None:
        raise ParameterError(f"{where}.elevation_origin_m is needed with elevation_file = {raster.path!r} under the "
                             "3D vehicle on homogeneous soil (model.vehicle = '3d' without a grid): there is no field "
                             "to put the raster at; give the world [x, y] of its lower-left corner")
    radius = footprint_radius_m(params)
    ax0, ax1, ay0, ay1 = _raster_area(raster, radius)
    if not (ax0 <= x_m <= ax1 and ay0 <= y_m <= ay1):
        rx0, rx1, ry0, ry1 = raster.bounds()
        raise ParameterError(
            f"{where}.elevation_file = {raster.path!r} covers x in [{rx0:.10g}, {rx1:.10g}] m, y in [{ry0:.10g}, "
            f"{ry1:.10g}] m: the start (x, y) = ({x_m:g}, {y_m:g}) m must lie in x in [{ax0:.10g}, {ax1:.10g}], y in "
            f"[{ay0:.10g}, {ay1:.10g}] (the raster's pixel centres less the vehicle's footprint, {radius:.3g} m): "
            "move the start or the raster (elevation_origin_m)")


class RasterGuard:
    """Stops a run of the 3D vehicle on homogeneous soil (a :class:`SimulationError`, the run kept up to
    there) when its CG comes within the footprint (:func:`footprint_radius_m`) of its elevation raster's
    edge: beyond the pixel centres the heights would be the edge's, a ground that is not the raster's.
    ``guard(X)`` checks the rows of states ``X`` (columns ``state_names``)."""

    def __init__(self, surface, params: dict, state_names):
        raster = surface.raster
        self.path, self.bounds = raster.path, raster.bounds()
        self.radius = footprint_radius_m(params)
        self.area = _raster_area(raster, self.radius)
        self.ix, self.iy = list(state_names).index("x_m"), list(state_names).index("y_m")

    @classmethod
    def of(cls, model, params: dict):
        """The guard of ``model``'s 3D vehicle on a raster, else None."""
        surface = getattr(getattr(model, "vehicle", None), "surface", None)
        if surface is None or getattr(surface, "raster", None) is None:
            return None
        return cls(surface, params, model.state_names)

    def __call__(self, X) -> None:
        ax0, ax1, ay0, ay1 = self.area
        for row in X:
            x, y = float(row[self.ix]), float(row[self.iy])
            if not (ax0 <= x <= ax1 and ay0 <= y <= ay1):
                rx0, rx1, ry0, ry1 = self.bounds
                raise SimulationError(
                    f"the vehicle left terrain.surface.elevation_file = {self.path!r} at (x, y) = ({x:.4g}, {y:.4g}) "
                    f"m: the raster covers x in [{rx0:.10g}, {rx1:.10g}] m, y in [{ry0:.10g}, {ry1:.10g}] m and the "
                    f"CG must stay {self.radius:.3g} m (the footprint) inside its pixel centres; a larger raster, or "
                    "a shorter run (run.duration_s, run.stop_after_distance_m)")


def check_grid(terrain) -> None:
    """A :class:`ParameterError` naming the key for what the 3D vehicle on the grid cannot take (before
    any work): ``terrain`` a :class:`~symtrack.terrain.settings.TerrainSettings`; a soil map or a
    moisture raster (the segments take one soil: the traction's soil means are the planar sums'), a
    towed trailer (its tyres load the cells through the planar vehicle's pass). (An elevation raster is
    taken: the hull's ground is its bilinear surface, the cells' elevations are sampled from the same.)"""
    if terrain is None:
        return
    refused = (("soil_map", "terrain.soil_map", "a field of several soils"),
               ("moisture", "terrain.moisture", "a moisture raster (a soil per cell)"),
               ("towed", "terrain.towed", "a towed trailer"))
    for attr, key, what in refused:
        if getattr(terrain, attr, None) is not None:
            raise ParameterError(f"{key}: {what} is not coupled to the 3D vehicle on the grid (model.vehicle = "
                                 "'3d' takes one soil and no trailer; allowed: leave it out, or model.vehicle = "
                                 "'planar')")
