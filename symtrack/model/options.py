"""Structural and numerical options of the symbolic model (not physical parameters)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ..foundations.config import Key
from ..foundations.errors import ParameterError
from ..soil.law import DEFAULT as DEFAULT_SOIL_LAW
from ..soil.law import REGISTRY as SOIL_LAWS
from ..vehicles import registry as vehicle_registry

TRACTION_SIGN_MODES = ("smooth", "tanh", "sign")
LATERAL_LAWS = ("shear", "creep", "shear_quasistatic")
# names a scenario may still use, read as the law they now name ("shear_transient" was the lagged shear
# law's name until it became "shear"; the quasi-static law that was "shear" is "shear_quasistatic")
LATERAL_LAW_ALIASES = {"shear_transient": "shear"}
SHEAR_STRENGTH_PRESSURES = ("mean", "local")
SLIDING_SIGNS = ("displacement", "velocity")
# the ModelOptions fields that the builders set on their own copy of a model, not scenario keys
BUILD_FLAGS = ("quadrature_call",)


# the [model] keys as ModelOptions checks them (the meanings in full: ModelOptions' docstring; docs/scenarios.md's
# table is made from these and the defaults)
_POSITIVE = dict(low=0.0, high=math.inf, low_open=True, allowed="> 0")
_BOOL = dict(choices=(True, False))
MODEL_KEYS = {k.name: k for k in (
    Key("traction_sign", "how the sign functions are evaluated (smooth: regularised; tanh: the thesis's; sign: "
        "discontinuous)", choices=TRACTION_SIGN_MODES),
    Key("tanh_steepness_per_m", "the steepness k of tanh(k j) (traction_sign = \"tanh\") [1/m]", **_POSITIVE),
    Key("shear_smoothing_m", "the smoothing d of sign(j) = j / sqrt(j^2 + d^2) [m]", **_POSITIVE),
    Key("omega_smoothing_rad_s", "the smoothing of the internal resistance's direction [rad/s]", **_POSITIVE),
    Key("motion_smoothing_m_s", "the smoothing of the compaction resistance's direction [m/s]", **_POSITIVE),
    Key("bekker_regularisation_m", "the regularisation of Bekker's z^n at zero sinkage, at most [m] (a soil whose law "
        "would be steeper than 30 x its elastic stiffness there takes what bounds it: docs/model.md)", **_POSITIVE),
    Key("lateral_segments", "creep law: Gauss-Legendre segments along each track", 1, 64, integer=True),
    Key("gauss_points", "creep law: Gauss-Legendre points per segment", 1, 16, integer=True),
    Key("accel_newton_iterations", "Newton steps on the load transfer's acceleration loop", 0, 20, integer=True),
    Key("lateral_shear_cap", "creep law: the lateral resistance capped at the soil's shear strength", **_BOOL),
    Key("shear_unloading", "the mean shear displacement unloads elastically when the slip reverses (false: Ferretti & "
        "Girelli's eq. (2) on unloading too; the MPC's prediction)", **_BOOL),
    Key("lateral_law", "how the tracks meet the soil: shear (lagged shear law), shear_quasistatic, creep (the "
        "validation's reconstruction)", choices=LATERAL_LAWS),
    Key("shear_strength_pressure", "the pressure in the shear strength c + p tan(phi): the track's mean or the "
        "local one", choices=SHEAR_STRENGTH_PRESSURES),
    Key("shear_points", "shear law: Gauss-Legendre points per half piece of the track", 1, 16, integer=True),
    Key("shear_grading", "shear law: the points graded as t^grading towards each piece's outer end", 1, 4,
        integer=True),
    Key("lateral_split", "shear law: split the integral at the pivot and at the shear's zero (false: the plain "
        "composite rule)", **_BOOL),
    Key("sliding_smoothing", "the regularisation of the sliding direction and of the shear's switch from loading to "
        "unloading (a slip ratio)", **_POSITIVE),
    Key("sliding_sign", "shear law: where the longitudinal stress's sign comes from", choices=SLIDING_SIGNS),
    Key("pivot_smoothing_rad_s", "the regularisation of the pivot's position [rad/s]", **_POSITIVE),
    Key("soil_law", "the terrain cells' soil law", choices=tuple(SOIL_LAWS)),
    Key("vehicle", "the vehicle model: planar, or 3d (heave, pitch and roll on the ground's shape)",
        choices=tuple(vehicle_registry.names())),  # the built-in menu (a plug-in registers later)
    Key("contact_segments", "3d: the segments along each track", 1, 64, integer=True),
)}


@dataclass(frozen=True)
class ModelOptions:
    """How the equations are written.

    traction_sign: how the sign functions of the model are evaluated: sign(j) of the tractive effort,
        and the direction sign(omega) of the internal resistance and sign(v_k) of the compaction
        resistance.
        "smooth" (default): sign(j) = j/sqrt(j^2 + d^2) with d = shear_smoothing_m (the product
        with the bracket of eq. (1) is then smooth and odd and differs from the exact law only
        for |j| ~ d); the directions are tanh(omega/omega_smoothing), tanh(v/motion_smoothing).
        "tanh": the approximation of the Politecnico di Milano thesis (docs/model.md), sign(j) =
        tanh(k j) with k = tanh_steepness_per_m; directions as in "smooth".
        "sign": the discontinuous sign() everywhere, kept to reproduce the thesis's numerical
        oscillations (Coulomb-like chattering of the internal resistance at omega = 0).
    lateral_law: how the tracks meet the soil (docs/turning.md).
        "shear_quasistatic": the shear stress at each point of the contact from the soil's shear law,
        Mohr-Coulomb strength c + p tan(phi) with Janosi-Hanamoto shear (modulus K), against the
        local sliding velocity, longitudinal and lateral together (combined slip; after Wong &
        Chiang 2001), with the lateral displacement field computed from the current velocities. The
        tractive force of each track is the longitudinal part of the same integral (Ferretti & Girelli's
        tractive effort exactly when the track does not slide sideways). Its fixed-step integrators
        need 0.5 ms steps.
        "shear" (default): the "shear_quasistatic" law with the sliding state lagged as the shear
        displacement's law lags the longitudinal one: each track carries two lateral shear states (the vehicle model
        "planar_lateral", four more states), j_y at the contact centre and the twist theta,
        dj_y/dt = -(2 r |omega| / l) j_y + v + r_z x_c (x_c the contact centre's body x) and
        dtheta/dt = -(2 r |omega| / l) theta + r_z, and the sliding direction and the displacement
        field use the lagged slips: 2 j / l longitudinally, 2 j_y / l + (2 theta / l)(l/2 - s)
        laterally. In steady running it is the quasi-static law exactly; a 10 ms step carries it
        (docs/turning.md section 8). "shear_transient", its earlier name, is read as "shear".
        "creep": the reconstruction of Ferretti & Girelli's (1999) model, on which the validation is calibrated
        (the validation scenarios declare it; with the shear law the validation's yaw is 15.5 deg
        against the paper's 0.4, docs/turning.md section 4): their tractive effort for the tractive force and a lateral
        resistance -mu_t q tanh((v + r_z x)/eps_v) with the vehicle's lateral_friction_coeff and
        lateral_creep_speed_m_s (a velocity creep, not a soil property).
    shear_strength_pressure: the pressure in the shear strength c + p tan(phi) of the "shear" law.
        "mean" (default): the track's mean pressure N/(b l), as Ferretti & Girelli's tractive effort
        does; the tractive force in straight running is then eq. (1) exactly. "local": the linear
        (or triangular) pressure p(s): the exact Janosi integral over the pressure distribution (3-5
        % more thrust than eq. (1) on the validation clay when traction loads the rear;
        docs/turning.md section 3).
    shear_points, shear_grading: the "shear" law's integral along each track is split at the pivot
        (where the lateral sliding velocity changes sign) and at the zero of the lateral shear
        displacement, each of the three pieces halved, and each half integrated by shear_points
        Gauss-Legendre points graded as t**shear_grading towards the half's outer end (where the
        shear builds up from zero or the sliding direction turns).
    lateral_split: false integrates the "shear" law with the plain composite rule
        lateral_segments x gauss_points instead (the reference of the convergence tests).
    sliding_smoothing: the sliding direction is (i_x, i_y)/sqrt(i_x^2 + i_y^2) with |i_x|
        regularised as sqrt(i_x^2 + d^2), d this value (a slip ratio, dimensionless). It matters
        only where both slips are below d: at 1e-5 and 2.6 m/s, within 0.1 mm of a turning track's
        pivot; in straight running the tractive force is eq. (1) for every slip (sign form as
        traction_sign says). The same d smooths the mean shear displacement's switch from loading
        to unloading when the slip ratio changes sign against it (symtrack.vehicles.planar.shear_rate).
    sliding_sign: ("shear" law only) where the sign of the longitudinal stress comes from.
        "displacement" (default): sign(j) of the tractive effort times the regularised |i_x| of the sliding
        velocity (eq. (1) exactly in straight running for every slip). "velocity": the sliding
        velocity's own i_x, so that the stress is -b tau (i_x, i_y)/sqrt(i_x^2 + i_y^2 + d^2): smooth
        where the track's longitudinal sliding changes sign while it slides sideways (sign(j) there
        flips the longitudinal stress over 2 shear_smoothing_m of j). Used with a large
        sliding_smoothing by the nonlinear MPC's prediction (MPCSettings.prediction_sliding_*;
        docs/turning.md, "Nonlinear MPC on the shear law"); not for simulation: with it a track needs
        a slip of order d to develop its tractive force.
    pivot_smoothing_rad_s: the pivot s = x_front + v/r_z is computed as x_front + v r_z/(r_z^2 + e^2),
        e this yaw rate ("shear_quasistatic"; "shear" places it at its lagged slip's zero, regularised by
        sliding_smoothing / l); it only places a split point (the integral depends on it through the
        quadrature's error alone).
    lateral_segments, gauss_points: the "creep" law is integrated along each track with composite
        Gauss-Legendre quadrature (segments x points per segment); the "shear" law too when
        lateral_split is false.
    lateral_shear_cap: ("creep" law only) when true, the lateral resistance per unit area, mu_t p, is capped at
        the soil's shear strength c + p tan(phi) (reconstruction). Without the cap
        the reference crawler on clayey soil (Thailand, 38 %) meets a turning resistance larger
        than the soil lets its tracks push (mu_t W = 29.7 kN > b l c + W tan(phi) = 21.4 kN) and
        holds no steady turn tighter than about 100 m. Off by default: the validation was
        calibrated without it (its lateral creep is far from either limit).
    shear_unloading: when true (default), a track's mean shear displacement unloads elastically from
        the stress it carries when the slip reverses against it: the stress falls with the shear
        curve's initial slope tau_max / K (docs/model.md, "Track kinematics and shear displacement";
        symtrack.vehicles.planar.shear_rate). False: Ferretti & Girelli's eq. (2) on unloading too (the
        stress follows the loading curve back, giving back the plastic work of a shear built up far
        beyond K). The MPC predicts with false (MPCSettings.prediction_shear_unloading): the switch
        between loading and unloading is a kink its one linearisation per sample does not resolve.
    soil_law: the terrain cells' soil law, a name of the soil-law registry
        (:mod:`symtrack.soil.law`); "bekker_wong" (default): Bekker loading, Wong
        unloading/reloading line and the cycle law of docs/model.md, "Pressure-sinkage".
    vehicle: the vehicle model. "planar" (default): the planar vehicle of
        docs/model.md (x, y, yaw; pitch from the quasi-static load transfer). "3d": the rigid hull that
        heaves, pitches and rolls on the ground's shape (:mod:`symtrack.vehicles.vehicle3d`,
        docs/vehicle3d.md), on the homogeneous terrain or on the grid through the terrain engine.
    contact_segments: ("3d" only) the segments along each track, each pressing on the ground under
        it (the load split between and along the tracks comes from their penetrations).
    accel_newton_iterations: the body accelerations a_x, a_y enter the pressure distribution
        (load transfer), which sets the forces, which set the accelerations. For the ODE form this
        algebraic loop is solved inside the expression: one fixed-point step from a = 0, then this
        many Newton steps on the 2x2 system; the DAE form (IDAS) solves it with algebraic
        variables. tests/test_vehicle.py measures the residual.
    quadrature_call: (a build flag, not a scenario key: :data:`BUILD_FLAGS`) a track quadrature of
        more than ``symtrack.vehicles.planar.INLINE_QUADRATURE_MAX_POINTS`` points is summed by one
        mapped CasADi Function called from the SX graph as a single node instead of being expanded,
        so that the generated C does not grow with the points. Set only by the
        builders of the fixed-step integrators' C (the compiled Rosenbrock: ``symtrack.native.cache.
        library(model, quadrature_call=True)``; the grid Rosenbrock) on their own copy of the model;
        CVODES, IDAS (interpreted or ``run.compiled``), trim and the MPC keep the expanded form: CasADi's
        virtual machine evaluates a call node slowly, and its Jacobian at every Newton setup made even
        the compiled CVODES slower than the interpreted expanded one (docs/codegen.md).
    """

    traction_sign: str = "smooth"
    tanh_steepness_per_m: float = 1000.0
    shear_smoothing_m: float = 1e-6
    omega_smoothing_rad_s: float = 0.01
    motion_smoothing_m_s: float = 0.01
    bekker_regularisation_m: float = 1e-6
    lateral_segments: int = 4
    gauss_points: int = 3
    accel_newton_iterations: int = 1
    lateral_shear_cap: bool = False
    shear_unloading: bool = True
    lateral_law: str = "shear"
    shear_strength_pressure: str = "mean"
    shear_points: int = 4
    shear_grading: int = 2
    lateral_split: bool = True
    sliding_smoothing: float = 1e-5
    sliding_sign: str = "displacement"
    pivot_smoothing_rad_s: float = 1e-5
    soil_law: str = DEFAULT_SOIL_LAW
    vehicle: str = "planar"
    contact_segments: int = 8
    quadrature_call: bool = False

    def __post_init__(self):
        if isinstance(self.lateral_law, str) and self.lateral_law in LATERAL_LAW_ALIASES:
            object.__setattr__(self, "lateral_law", LATERAL_LAW_ALIASES[self.lateral_law])
        if self.traction_sign not in TRACTION_SIGN_MODES:
            raise ParameterError(
                f"model.traction_sign = {self.traction_sign!r} is not one of {', '.join(TRACTION_SIGN_MODES)}"
            )
        for name, allowed in (("lateral_law", LATERAL_LAWS), ("shear_strength_pressure", SHEAR_STRENGTH_PRESSURES),
                              ("sliding_sign", SLIDING_SIGNS)):
            v = getattr(self, name)
            if v not in allowed:
                raise ParameterError(f"model.{name} = {v!r} is not one of {', '.join(allowed)}")
        vehicle_registry.get(self.vehicle)  # an unknown name: the error names the value and the menu
        if self.soil_law not in SOIL_LAWS:
            raise ParameterError(f"model.soil_law = {self.soil_law!r} is not one of {', '.join(SOIL_LAWS)}")
        for key in MODEL_KEYS.values():
            v = getattr(self, key.name)
            if key.allowed == "> 0" and not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0):
                raise ParameterError(f"model.{key.name} = {v!r} must be a number > 0")
            if key.integer and not (isinstance(v, int) and not isinstance(v, bool) and key.low <= v <= key.high):
                raise ParameterError(f"model.{key.name} = {v!r} must be an integer in [{key.low:g}, {key.high:g}]")
        for name in ("lateral_shear_cap", "shear_unloading", "lateral_split", "quadrature_call"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"model.{name} = {getattr(self, name)!r} must be true or false")


def scenario_keys() -> list[str]:
    """The ModelOptions fields a scenario's [model] table (or ``--set model.*``) may set: all but
    the :data:`BUILD_FLAGS`."""
    return [f.name for f in dataclasses.fields(ModelOptions) if f.name not in BUILD_FLAGS]
