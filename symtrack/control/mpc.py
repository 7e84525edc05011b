"""Nonlinear MPC of the commanded sprocket torques for path tracking.

Prediction model
    The model's own ``dae`` Function (no equation is written here): the DAE form, whose two
    algebraic accelerations close the load-transfer loop exactly, costs one evaluation of the
    vehicle equations where the ODE form iterates them; the Hessian of one collocation point has
    5.5 k instead of 49 k instructions. Two variants:

    - ``prediction = "vehicle"`` (default): the 12 vehicle states are predicted; the 8 terrain-cell
      states are frozen over the horizon at their measured values and enter ``dae`` as
      parameters. The cells feed back on the vehicle only through the compaction resistance
      (a function of the sinkage), and their 350-1500 rad/s modes are far faster than anything
      a 0.1 s controller can act on. ``symtrack.control.bench.prediction_effect`` measures the
      difference in the predicted trajectories against ``"full"``.
    - ``prediction = "full"``: all 20 states, cells included.

    On the shear law (``ModelOptions.lateral_law = "shear_quasistatic"``) the prediction is the model with a
    regularised sliding direction (:func:`prediction_model`; docs/turning.md section 6).

    On the 3D vehicle the hull is quasi-static by default (``prediction_hull``): its height above the
    ground, pitch and roll are algebraic variables fixed by the hull's force and moment balances at zero
    hull acceleration (the singular-perturbation reduction of its 7 Hz heave, pitch and roll modes, far
    faster than the 0.1 s element); the measured hull states are not read (docs/vehicle3d.md).

Discretisation
    The model is stiff even without the cells (lateral creep mode about -600 1/s, yaw -225 1/s,
    shear/sprocket oscillation about 80 rad/s), so explicit Runge-Kutta would need millisecond
    sub-steps. Each sample interval is one Radau IIA collocation element (degree 1-3; default 2,
    order 3, L-stable) written into the NLP: the collocation state values are extra variables of
    the stage and the collocation equations are stage equality constraints. Because the Radau
    end point is the last collocation value, the gap constraint is x_{k+1} - F(x_k, w_k) with F
    linear, as fatrop's structure detection requires.

NLP layout (stage ordered, as fatrop's structure detection needs)
    w = [x_0, u_0, K_0, x_1, u_1, K_1, ..., x_N]; x_k = [vehicle states, previous command] (the
    previous command makes the torque-rate bound and its penalty stage-local); u_k the two torque
    commands in kN m; K_k the collocation states and accelerations. All variables are scaled to O(1). The stage
    function is built once and applied with one ``map(N)``. x_0 is fixed through its bounds.

Cost (per stage, reference point k of the path sampled at the reference speed)
    lateral error (quadratic, or pseudo-Huber with ``lateral_huber_m``), heading error,
    along-track error, speed error, yaw-rate error against the path curvature times speed,
    torque-rate and torque magnitude penalties; the terminal state is weighted
    ``terminal_factor`` times more, its lateral error ``terminal_lateral_factor`` times.

Solvers
    ``ipopt`` (default) or ``fatrop`` (structure detection ``auto``), both with the exact Hessian,
    or ``rti``: the real-time iteration of :mod:`symtrack.control.rti` (one Gauss-Newton SQP step
    per sample on this same NLP, preparation/feedback split; why the earlier Gauss-Newton attempts
    failed is in that module and docs/control.md). ``jit = True`` compiles the NLP functions
    (``expand`` off, as the notes require), or the RTI's mapped Functions, once into the solver
    cache of :mod:`symtrack.control.solver_cache` (``jit_dir``, default
    ``~/.cache/symtrack/mpc``), keyed by the problem, the CasADi version and the flags; later
    processes load the library without calling a compiler.

A failed solve (solver error, non-success status or non-finite result) never raises: the
fallback solver (by default the other of ipopt / fatrop, interpreted) is tried from the same warm
start; if it fails too, the controller applies the next command of its previous plan (shifted),
counts the failure and warm-starts the next solve from the shifted plan.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError
from ..foundations.interrupt import InterruptWatch
from ..model import SystemModel
from ..model.homogeneous import HomogeneousTerrain
from ..model.options import SLIDING_SIGNS
from ..vehicles.base import CONTACT_HULL
from ..vehicles.vehicle3d import PITCH_INERTIA_PER_YAW, ROLL_INERTIA_PER_YAW, ContactTerrain
from .linearization import scale_by_name
from .rti import QP_SOLVERS, RTI, gn_solve, shift_guess
from .solver_cache import compiled_nlp_library

__all__ = ["MPCSettings", "MPCStats", "PREDICTIONS", "PREDICTION_HULLS", "PathTrackingMPC", "QS_HULL_VARIABLES",
           "RTI_COLD_STARTS", "SOLVERS", "SolveInfo", "TORQUE_SCALE_N_M", "realtime_figures"]

log = logging.getLogger("symtrack.control.mpc")
# the NLP solvers built in this process, by problem (PathTrackingMPC._nlpsol; symtrack.foundations.caches)
_NLPSOLS = caches.cache("mpc_nlpsols", 8)

SOLVERS = ("ipopt", "fatrop")  # the NLP solvers (also the fallbacks)
SOLVER_CHOICES = SOLVERS + ("rti",)  # rti: real-time iteration (symtrack.control.rti)
PREDICTIONS = ("vehicle", "full")
RTI_COLD_STARTS = ("solution", "shift")  # MPCSettings.rti_cold_start
PREDICTION_HULLS = ("auto", "quasi_static", "dynamic")
# The quasi-static hull's algebraic variables (mpc.prediction_hull = "quasi_static"): the CG's height
# above the ground under it [m], the pitch and the roll [rad], each scaled by 1 mm (1 mrad): the hull's
# contact stiffness (heave, pitch, roll near 7 Hz: (44 rad/s)^2 per m) then gives their balance rows
# derivatives of order 1 per scaled unit.
QS_HULL_VARIABLES = ("clearance_m", "pitch_rad", "roll_rad")
QS_HULL_SCALE = 1e-3

# Typical magnitudes (scaling of the NLP variables), by state name prefix.
_SCALES = (
    ("x_m", 1.0), ("y_m", 1.0), ("yaw_rad", 0.1), ("u_m_s", 1.0), ("v_m_s", 0.05), ("yaw_rate_rad_s", 0.1),
    ("omega_", 5.0), ("shear_", 0.02), ("torque_", 1000.0), ("sinkage_rate_", 0.01), ("sinkage_", 0.002),
    # The 3D vehicle's hull states (its hull_states, symtrack.vehicles.vehicle3d.HULL_STATES) keep the scale 1: z_m is a
    # position (0.6 m on flat ground, metres on a slope) and the angles and rates are small, but scaling
    # the rates to 0.01 makes their collocation rows 100 x larger, and the hull's bounce in the plant
    # (heave, pitch, roll near 7 Hz, lightly damped) then puts the measurement itself far outside the
    # RTI's defect bound: headland_uturn on the 3D vehicle, RTI, with z 1, angles 0.1, rates 0.01: 37
    # failed solves before the run was stopped, against 7 over the whole path with all at 1
    # (measured; docs/vehicle3d.md). IPOPT: 5 and 6 failed in the first 30 samples of
    # straight_offset (no difference).
)
TORQUE_SCALE_N_M = 1000.0


def _scale(name: str) -> float:
    return scale_by_name(name, _SCALES)


@dataclass(frozen=True)
class MPCSettings:
    """Settings of the MPC (validated; errors name the field, the value and the range).

    Weights are per unit of the error named in SI (m, rad, m/s, rad/s) and kN m for torques.
    """

    horizon_steps: int = 20
    sample_time_s: float = 0.1
    # the real-time iteration by default: it meets the 0.1 s sample time with margin (feedback about
    # 1 ms) and fails no solve on the built-in scenarios, where IPOPT took a median 127.5 ms on the
    # U-turn (222 of 336 samples over the sample time) and failed 4 solves there (docs/control.md,
    # "The default solver"); "ipopt" and "fatrop" solve the NLP to convergence
    solver: str = "rti"
    # compile the solver's functions once into the solver cache; None: the solver's default (see
    # ``uses_jit``): on for the RTI (its feedback is the real-time path: with DAQP, median / p95
    # 1.5 / 2.4 ms against 2.6 / 4.6 ms interpreted with qrqp on the clay U-turn, docs/control.md),
    # off for the NLP solvers (fatrop's build takes 45 s, IPOPT's time is inside IPOPT and MUMPS)
    jit: bool | None = None
    jit_dir: str | None = None
    prediction: str = "vehicle"
    # the 3D vehicle's hull in the prediction (symtrack.vehicles.vehicle3d.HULL_STATES; docs/vehicle3d.md,
    # "The MPC on the 3D vehicle"): "quasi_static" (the singular-perturbation reduction: the hull's height,
    # pitch and roll are algebraic variables of the prediction's DAE, fixed by its vertical force and pitch
    # and roll moment balances at zero hull acceleration, its rates those of the ground pose under the
    # moving hull; the measured hull states are not read), "dynamic" (the hull's six states predicted, as
    # the plant's). "auto": quasi_static on the 3D vehicle (measured: `symtrack mpc
    # straight_offset --set model.vehicle=3d`, IPOPT, 0 failed of 299 against 96 failed before the dynamic
    # hull's run was stopped at 7 min; RTI 0 against 1; headland_uturn RTI 0 and 0). The planar vehicle
    # has no hull and takes "auto" only.
    prediction_hull: str = "auto"
    collocation_degree: int = 2
    torque_max_N_m: float = 8000.0  # ASSUMED sprocket torque limit (no data sheet); the field operations' too
    torque_rate_max_N_m_s: float = 40000.0
    weight_lateral: float = 10.0
    weight_heading: float = 30.0
    weight_along: float = 1.0
    weight_speed: float = 3.0
    weight_yaw_rate: float = 3.0
    weight_torque: float = 0.001
    weight_torque_rate: float = 0.3
    terminal_factor: float = 5.0
    terminal_lateral_factor: float | None = 50.0
    lateral_huber_m: float = 0.0
    # the NLP solvers' iterations per solve (and the RTI's Gauss-Newton cold start without a fallback): 300.
    # headland_uturn on IPOPT needs more than 60 at 4 of its 336 samples (the turn entering the horizon),
    # where 60 gave 4 failed solves (Maximum_Iterations_Exceeded, the fatrop fallback failing too) and 300
    # none; the median stays 4 (measured: symtrack mpc headland_uturn --solver ipopt [--set mpc.max_iter=300])
    max_iter: int = 300
    prediction_lateral_creep_speed_m_s: float | None = None
    # the shear law's prediction regularisation (used only when the model's lateral_law is "shear";
    # docs/turning.md, "Nonlinear MPC on the shear law"): the sliding direction's slip floor d and
    # the sign of the longitudinal stress from the sliding velocity (ModelOptions.sliding_sign).
    # None / "model": the model's own (then IPOPT stalls on the clay: measured)
    prediction_sliding_smoothing: float | None = 0.01
    prediction_sliding_sign: str = "velocity"
    # the prediction's shear displacement on unloading (ModelOptions.shear_unloading; docs/model.md, "Track
    # kinematics and shear displacement"): False predicts with Ferretti & Girelli's eq. (2) throughout, the
    # plant unloads elastically. The switch between loading and unloading is a kink (the unloading slope is up
    # to thousands of times the loading one far beyond K) that the RTI's one linearisation per sample does not
    # resolve: predicting with it, headland_uturn (20 m + the 4 m U-turn + 4 m) had 9 failed solves on the
    # shear law and 2 IPOPT fallbacks on the creep law, 0 and 0 with False (measured). None: the model's own
    prediction_shear_unloading: bool | None = False
    fallback_solver: str | None = "auto"
    tol: float = 1e-5
    # the RTI's dense QP solver: DAQP (dual active set) solves the condensed QP in 0.05 ms against
    # qrqp's 0.35 ms (docs/control.md); the generated C (symtrack codegen mpc) embeds qrqp, the
    # solver CasADi generates dependency-free C for
    rti_qp_solver: str = "daqp"
    rti_max_defect: float = 0.1
    rti_step_halvings: int = 3
    # Gauss-Newton iterations after a rejected RTI step, each linearised at the shortest step of
    # the one before, before the NLP fallback (symtrack.control.rti.RTI.feedback; docs/control.md).
    # 3: straight_offset's 1 m approach needs 2 at its hardest samples (1 left 6 failed solves
    # there, IPOPT's fallback hitting max_iter; measured, docs/control.md); each costs about 2 ms
    # and only on a rejected step
    rti_relinearisations: int = 3
    # where the RTI prepares its first feedback after the cold start: "solution" linearises at the
    # cold solution itself (the measurement it solved for; straight_offset's 1 m approach needs it),
    # "shift" at its shift one sample ahead (what an operation's follower keeps: from "solution" the
    # random-traffic season of tests/test_traffic_sweep.py left its path at t = 46.9 s, measured)
    rti_cold_start: str = "solution"

    def __post_init__(self):
        def rng(name, lo, hi, integer=False, lo_open=False):
            v = getattr(self, name)
            ok_type = isinstance(v, int) if integer else isinstance(v, (int, float))
            if isinstance(v, bool) or not ok_type or not math.isfinite(v) or v > hi or (v <= lo if lo_open else v < lo):
                kind = "an integer" if integer else "a number"
                lb = "(" if lo_open else "["
                raise ParameterError(f"mpc.{name} = {v!r} must be {kind} in {lb}{lo:g}, {hi:g}]")

        rng("horizon_steps", 2, 500, integer=True)
        rng("sample_time_s", 0.001, 5.0)
        rng("collocation_degree", 1, 3, integer=True)
        rng("torque_max_N_m", 0.0, 1e6, lo_open=True)
        rng("torque_rate_max_N_m_s", 0.0, 1e8, lo_open=True)
        for w in ("weight_lateral", "weight_heading", "weight_along", "weight_speed", "weight_yaw_rate",
                  "weight_torque", "weight_torque_rate"):
            rng(w, 0.0, 1e8)
        rng("terminal_factor", 0.0, 1e6)
        rng("lateral_huber_m", 0.0, 100.0)
        if self.terminal_lateral_factor is not None:
            rng("terminal_lateral_factor", 0.0, 1e6)
        rng("max_iter", 1, 10000, integer=True)
        rng("tol", 0.0, 1.0, lo_open=True)
        rng("rti_max_defect", 0.0, 1e6, lo_open=True)
        rng("rti_step_halvings", 0, 20, integer=True)
        rng("rti_relinearisations", 0, 10, integer=True)
        if self.rti_cold_start not in RTI_COLD_STARTS:
            raise ParameterError(f"mpc.rti_cold_start = {self.rti_cold_start!r} is not one of "
                                 f"{', '.join(RTI_COLD_STARTS)}")
        if self.prediction_lateral_creep_speed_m_s is not None:
            rng("prediction_lateral_creep_speed_m_s", 0.0, 10.0, lo_open=True)
        if self.prediction_sliding_smoothing is not None:
            rng("prediction_sliding_smoothing", 0.0, 1.0, lo_open=True)
        if self.prediction_shear_unloading is not None and not isinstance(self.prediction_shear_unloading, bool):
            raise ParameterError(f"mpc.prediction_shear_unloading = {self.prediction_shear_unloading!r} must be true, "
                                 "false or left out (the model's own)")
        if self.prediction_sliding_sign not in ("model",) + SLIDING_SIGNS:
            raise ParameterError(f"mpc.prediction_sliding_sign = {self.prediction_sliding_sign!r} is not one of "
                                 f"model, {', '.join(SLIDING_SIGNS)}")
        if self.solver not in SOLVER_CHOICES:
            raise ParameterError(f"mpc.solver = {self.solver!r} is not one of {', '.join(SOLVER_CHOICES)}")
        if self.rti_qp_solver not in QP_SOLVERS:
            raise ParameterError(f"mpc.rti_qp_solver = {self.rti_qp_solver!r} is not one of {', '.join(QP_SOLVERS)}")
        if self.fallback_solver is not None and self.fallback_solver not in SOLVERS + ("auto", "none"):
            raise ParameterError(f"mpc.fallback_solver = {self.fallback_solver!r} is not one of "
                                 f"{', '.join(SOLVERS)}, auto (the other solver), none")
        if self.prediction_hull not in PREDICTION_HULLS:
            raise ParameterError(f"mpc.prediction_hull = {self.prediction_hull!r} is not one of "
                                 f"{', '.join(PREDICTION_HULLS)}")
        if self.prediction not in PREDICTIONS:
            raise ParameterError(f"mpc.prediction = {self.prediction!r} is not one of {', '.join(PREDICTIONS)}")
        if self.jit is not None and not isinstance(self.jit, bool):
            raise ParameterError(f"mpc.jit = {self.jit!r} must be true or false (or absent: on for solver = \"rti\", "
                                 f"off for the NLP solvers)")
        if self.jit_dir is not None and not isinstance(self.jit_dir, str):
            raise ParameterError(f"mpc.jit_dir = {self.jit_dir!r} must be a folder path or None")

    @property
    def uses_jit(self) -> bool:
        """Whether the solver's functions are compiled: ``jit`` when given, else on for the RTI only."""
        return self.jit if self.jit is not None else self.solver == "rti"

    @property
    def horizon_s(self) -> float:
        return self.horizon_steps * self.sample_time_s


def realtime_figures(stats, sample_time_s: float) -> dict:
    """Real-time honesty: the samples whose computation (solve, plus the RTI preparation) took
    longer than the sample time, the worst of them, and the preparation times. Logs a warning
    when the median computation exceeds the sample time (the controller is not real-time here)."""
    solve = np.array([s.solve_time_s for s in stats.solves]) * 1e3
    prep = np.array([getattr(s, "preparation_time_s", 0.0) for s in stats.solves]) * 1e3
    total = solve + prep
    limit = 1e3 * sample_time_s
    over = total > limit
    out = {
        "overrun_samples": int(over.sum()),
        "overrun_worst_ms": float(total.max()) if over.any() else None,
        "computation_per_sample_median_ms": float(np.median(total)) if total.size else None,
        "computation_per_sample_max_ms": float(total.max()) if total.size else None,
        "preparation_time_median_ms": float(np.median(prep)) if prep.size else None,
        "preparation_time_p95_ms": float(np.percentile(prep, 95)) if prep.size else None,
        "preparation_time_max_ms": float(prep.max()) if prep.size else None,
        "overrun_note": f"samples whose solve (+ RTI preparation) took longer than the sample time {limit:g} ms",
    }
    if total.size and np.median(total) > limit:
        log.warning("MPC not real-time on this machine: the median computation per sample %.1f ms exceeds the "
                    "sample time %.0f ms (%d of %d samples over)", np.median(total), limit, int(over.sum()), total.size)
    return out


def prediction_model(model: SystemModel, settings: MPCSettings) -> SystemModel:
    """The model the MPC predicts with: ``model`` itself, except on the shear law, where the
    sliding direction is regularised for the NLP (``prediction_sliding_smoothing``,
    ``prediction_sliding_sign``). Why: the shear law's tractive force and yaw moment depend on the
    ratio of the longitudinal to the lateral sliding velocity, and in the MPC's working range
    (straight running and path corrections, slips 1e-5 ... 1e-2) that ratio turns over changes of
    the sprocket speed of 1e-3 rad/s; the exact law's curvature then stalls IPOPT
    (docs/turning.md, "Nonlinear MPC on the shear law").

    Which laws: the quasi-static law only. On the default lagged "shear" law the prediction is
    the exact law for every solver (measured, docs/turning.md section 6): the RTI does better on it
    (headland_uturn on clay / sandy loam / the grid: 1 / 0 / 0-1 failed solves, RMS 0.4-0.5 cm,
    against 0 / 4 / 3 and 1.4-1.8 cm regularised), and so does the lane keeping on the grid
    (regularised, the second pass did not converge onto the lanes); IPOPT on the clay is the open
    case (headland_uturn: 80 failed solves exact, 0 regularised).

    On every law the shear displacement's unloading is ``prediction_shear_unloading`` (default False:
    Ferretti & Girelli's eq. (2) throughout, where the plant unloads elastically; the switch is a kink
    the RTI does not resolve, MPCSettings).

    The 3D vehicle's quasi-static hull (``prediction_hull``) is in steady running, so its contact reads the
    soil history of steady running, the deepest sinkage of the segments ahead at the present pose: the
    steady state of the plant's soil memory (:class:`~symtrack.vehicles.vehicle3d.ContactTerrain` with
    ``memory`` false: no memory states in the prediction)."""
    o = model.opts
    quasi_static_hull = model.vehicle.contact == CONTACT_HULL and settings.prediction_hull in ("auto", "quasi_static")
    if quasi_static_hull and getattr(model.terrain, "memory", False):
        model = SystemModel(o, terrain=ContactTerrain(o, memory=False), vehicle=model.vehicle)
    changes = {}
    if o.lateral_law == "shear_quasistatic":
        if settings.prediction_sliding_smoothing is not None:
            changes["sliding_smoothing"] = settings.prediction_sliding_smoothing
        if settings.prediction_sliding_sign != "model":
            changes["sliding_sign"] = settings.prediction_sliding_sign
    if settings.prediction_shear_unloading is not None:
        changes["shear_unloading"] = settings.prediction_shear_unloading
    if all(getattr(o, k) == v for k, v in changes.items()):
        return model
    opts = dataclasses.replace(o, **changes)
    if model.vehicle.contact == CONTACT_HULL:
        # a hull of its own (the 3D vehicle): the same ground under the prediction (its surface kept), the same
        # contact terrain (with or without the soil's memory)
        terrain = ContactTerrain(opts, memory=not quasi_static_hull)
        return SystemModel(opts, terrain=terrain, vehicle=model.vehicle.for_options(opts, model.vehicle.surface))
    if not isinstance(model.terrain, HomogeneousTerrain):
        raise ParameterError("mpc.prediction_sliding_*, mpc.prediction_shear_unloading: the prediction's "
                             "regularisation needs the homogeneous terrain's model (set "
                             "prediction_sliding_smoothing = None, prediction_sliding_sign = \"model\" and "
                             "prediction_shear_unloading = None for another terrain)")
    return SystemModel(opts)


def _hull_quasi_static(model: SystemModel, settings: MPCSettings) -> bool:
    """Whether the prediction takes the 3D hull as quasi-static (``prediction_hull``); a
    :class:`ParameterError` for a choice the model cannot take (the planar vehicle has no hull)."""
    has_hull = bool(model.vehicle.hull_states)
    choice = settings.prediction_hull
    if not has_hull:
        if choice != "auto":
            raise ParameterError(f"mpc.prediction_hull = {choice!r} needs the 3D vehicle (model.vehicle = '3d'); the "
                                 "planar vehicle has no hull states: allowed is 'auto'")
        return False
    return choice in ("auto", "quasi_static")  # "auto": the quasi-static hull (MPCSettings.prediction_hull)


@dataclass
class SolveInfo:
    success: bool
    solve_time_s: float  # RTI: the feedback phase (measurement -> command)
    iterations: int
    status: str
    cost: float = float("nan")
    preparation_time_s: float = 0.0  # RTI: the preparation phase after the command (else 0)


@dataclass
class MPCStats:
    solves: list = field(default_factory=list)
    failed: int = 0
    fallbacks: int = 0  # primary solver failed, the fallback solver succeeded (not a failure)

    def solve_times_ms(self) -> np.ndarray:
        return np.array([1e3 * s.solve_time_s for s in self.solves])


class PathTrackingMPC:
    """Nonlinear MPC of the two commanded torques on the model's dynamics.

    ``step(x_plant_by_name, reference)`` returns the command to apply now; ``reference`` is a
    (N+1) x 5 array of [x_m, y_m, yaw_rad, speed_m_s, curvature_1_per_m] for the stages.
    """

    REF_COLUMNS = ("x_m", "y_m", "yaw_rad", "speed_m_s", "curvature_1_per_m")

    def __init__(self, model: SystemModel, params: dict, settings: MPCSettings | None = None, *,
                 solvers: bool = True):
        # solvers=False: the prediction (stage_fn, the NLP's functions and bounds) without its solvers, for
        # what integrates the prediction and never solves (control.bench.prediction_effect)
        self.settings = settings or MPCSettings()
        s = self.settings
        self.plant_model = model
        self.model = model = prediction_model(model, s)
        self.params = dict(params)
        if s.prediction_lateral_creep_speed_m_s is not None:
            self.params["lateral_creep_speed_m_s"] = s.prediction_lateral_creep_speed_m_s
        self.p_model = np.asarray(model.param_vector(self.params), dtype=float)
        names, lay = model.state_names, model.layout
        self.hull_quasi_static = _hull_quasi_static(model, s)
        pred = lay.vehicle_names if s.prediction == "vehicle" else tuple(names)
        if self.hull_quasi_static:  # the hull's states are not states of the prediction
            pred = tuple(n for n in pred if n not in model.vehicle.hull_states)
        self.pred_names = pred
        self.cell_names = lay.cell_names if s.prediction == "vehicle" else ()
        self.nxp = len(self.pred_names)
        # the prediction's states: their positions in the model's state (pred_index) and their block at the
        # head of the augmented state and of each collocation point (pred)
        self.pred_index = lay.indices(self.pred_names)
        self.pred = slice(0, self.nxp)
        self.nu = 2
        self.nxa = self.nxp + self.nu  # + previous command
        self.N = s.horizon_steps
        self.d = s.collocation_degree
        self.nza = len(model.alg_names)  # body accelerations of the DAE form
        # + the quasi-static hull's algebraic variables (QS_HULL_VARIABLES)
        self.nz = self.nza + (len(QS_HULL_VARIABLES) if self.hull_quasi_static else 0)
        self.nc = self.nxp + self.nz  # one collocation point: states and accelerations
        self.nk = self.d * self.nc
        self.sx = np.array([_scale(n) for n in self.pred_names] + [TORQUE_SCALE_N_M] * 2)
        self._hull_fn = self._hull_function() if self.hull_quasi_static else None
        self._build(solvers)
        self.stats = MPCStats()
        self._w = None
        self._plan_u = None  # (N, 2) commands in N m of the last accepted plan
        self._plan_age = 0

    # ------------------------------------------------------------------ construction
    def _stage_function(self):
        s, model = self.settings, self.model
        nxp, nu, d, h = self.nxp, self.nu, self.d, s.sample_time_s
        Xs = ca.SX.sym("xs", self.nxa)
        Us = ca.SX.sym("us", nu)
        Ks = ca.SX.sym("ks", self.nk)
        ref = ca.SX.sym("ref", 5)
        P = ca.SX.sym("p", len(self.p_model))
        XC = ca.SX.sym("xc", len(self.cell_names))
        Sx = ca.DM(self.sx[self.pred])
        x = Xs[self.pred] * Sx
        u = Us * TORQUE_SCALE_N_M

        def f(xp, zp):
            # the DAE form: the load-transfer loop closed by algebraic accelerations (one
            # evaluation of the vehicle equations instead of the ODE form's fixed-point
            # iterations: its Hessian has 9x fewer instructions)
            if self.hull_quasi_static:
                return self._quasi_static_dae(xp, zp, u, P)
            if self.cell_names:
                ode, alg = model.dae(ca.vertcat(xp, XC), zp, u, P)
                return ode[self.pred_index], alg
            return model.dae(xp, zp, u, P)

        # Radau IIA collocation (Lagrange basis on [0, tau_1..tau_d]).
        tau = [0.0] + list(ca.collocation_points(d, "radau"))
        C = np.zeros((d + 1, d + 1))
        for j in range(d + 1):
            coeff = np.poly1d([1.0])
            for r in range(d + 1):
                if r != j:
                    coeff *= np.poly1d([1.0, -tau[r]]) / (tau[j] - tau[r])
            dp = np.polyder(coeff)
            for r in range(d + 1):
                C[j, r] = dp(tau[r])
        nc = self.nc
        xs_col = [x] + [Ks[j * nc:j * nc + nxp] * Sx for j in range(d)]
        zs_col = [None] + [Ks[j * nc + nxp:(j + 1) * nc] for j in range(d)]
        gcoll = []
        for j in range(1, d + 1):
            xp_deriv = sum(C[r, j] * xs_col[r] for r in range(d + 1))
            fj, aj = f(xs_col[j], zs_col[j])
            gcoll.append((h * fj - xp_deriv) / (h * Sx * 10.0))
            gcoll.append(aj)
        x_next = ca.vertcat(Ks[(d - 1) * nc:(d - 1) * nc + nxp], Us)  # scaled; the previous command becomes u
        g_rate = Us - Xs[nxp:]  # kN m per step
        res = self._residuals(x, ref)
        r_u = ca.vertcat(math.sqrt(s.weight_torque) * Us, math.sqrt(s.weight_torque_rate) * g_rate)
        r_all = ca.vertcat(res[1:], r_u)
        cost = s.weight_lateral * self._lateral_penalty(res[0]) + ca.sumsqr(r_all)
        stage = ca.Function("mpc_stage", [Xs, Us, Ks, ref, P, XC],
                            [x_next, ca.vertcat(*gcoll), g_rate, cost],
                            ["x", "u", "k", "ref", "p", "xc"], ["x_next", "g_coll", "g_rate", "cost"],
                            {"cse": True})
        XN = ca.SX.sym("xN", self.nxa)
        resN = self._residuals(XN[self.pred] * Sx, ref)
        tf_lat = s.terminal_factor if s.terminal_lateral_factor is None else s.terminal_lateral_factor
        costN = tf_lat * s.weight_lateral * self._lateral_penalty(resN[0]) + s.terminal_factor * ca.sumsqr(resN[1:])
        term = ca.Function("mpc_terminal", [XN, ref], [costN], ["x", "ref"], ["cost"])
        # The same cost as least squares (cost = |r|^2, to round-off), for the Gauss-Newton
        # Hessian of the real-time iteration (symtrack.control.rti): the residuals are affine in
        # the states for a given reference, so GN is exact for the cost and drops only the
        # curvature of the collocation equations.
        r_stage = ca.vertcat(math.sqrt(s.weight_lateral) * self._lateral_residual(res[0]), r_all)
        r_term = ca.vertcat(math.sqrt(tf_lat * s.weight_lateral) * self._lateral_residual(resN[0]),
                            math.sqrt(s.terminal_factor) * resN[1:])
        self.res_fn = ca.Function("mpc_res", [Xs, Us, ref], [r_stage, ca.jacobian(r_stage, Xs),
                                                             ca.jacobian(r_stage, Us)],
                                  ["x", "u", "ref"], ["r", "r_x", "r_u"], {"cse": True})
        self.res_term_fn = ca.Function("mpc_res_term", [XN, ref], [r_term, ca.jacobian(r_term, XN)],
                                       ["x", "ref"], ["r", "r_x"], {"cse": True})
        g_c = ca.vertcat(*gcoll)
        self.coll_fn = ca.Function("mpc_coll", [Xs, Us, Ks, P, XC],
                                   [g_c, ca.jacobian(g_c, Ks), ca.jacobian(g_c, Xs), ca.jacobian(g_c, Us)],
                                   ["x", "u", "k", "p", "xc"], ["g", "g_k", "g_x", "g_u"], {"cse": True})
        self.coll_res_fn = ca.Function("mpc_coll_res", [Xs, Us, Ks, P, XC], [g_c], ["x", "u", "k", "p", "xc"], ["g"],
                                       {"cse": True})
        return stage, term

    # ------------------------------------------------------------------ the quasi-static hull
    def _ground_pose_function(self) -> ca.Function:
        """(X, Y, yaw, dX/dt, dY/dt, yaw rate) -> the ground under the CG: its height z0, the pitch
        and roll of a hull lying on its plane there (R = Rz(yaw) Ry(-pitch) Rx(roll) with the body's
        x and y axes in the plane: tan(pitch) = a, tan(roll) = b cos(pitch), a and b the ground's
        rise along the heading and to its left), the rates of the three along the motion, and
        sqrt(1 + |grad z0|^2) (1 / the cosine of the ground's inclination)."""
        X, Y, psi, Xd, Yd, rd = (ca.SX.sym(n) for n in ("X", "Y", "psi", "Xd", "Yd", "rd"))
        z0, gx, gy = (ca.SX(v) if not isinstance(v, ca.SX) else v for v in self.model.vehicle.ground(X, Y))
        a = gx * ca.cos(psi) + gy * ca.sin(psi)
        pitch = ca.atan(a)
        roll = ca.atan((-gx * ca.sin(psi) + gy * ca.cos(psi)) * ca.cos(pitch))
        pose, rates = ca.vertcat(X, Y, psi), ca.vertcat(Xd, Yd, rd)
        geo = ca.vertcat(z0, pitch, roll)
        return ca.Function("ground_pose", [X, Y, psi, Xd, Yd, rd],
                           [geo, ca.jtimes(geo, pose, rates), ca.sqrt(1 + gx**2 + gy**2)])

    def _quasi_static_full_state(self, xp, hull):
        """The model's full state from the prediction's states ``xp`` and the quasi-static hull
        ``hull`` = (clearance [m], pitch, roll [rad]): the CG at the clearance above the ground under
        it; the hull's rates those of the ground pose along the motion (zero on flat ground; on a
        plane the hull keeps its penetration, so the soil's damping c'' dz/dt is not excited)."""
        i = {n: k for k, n in enumerate(self.pred_names)}
        X, Y, psi, vx, vy, rz = (xp[i[n]] for n in ("x_m", "y_m", "yaw_rad", "u_m_s", "v_m_s", "yaw_rate_rad_s"))
        geo, geo_rate, _ = self._ground_pose(X, Y, psi, vx * ca.cos(psi) - vy * ca.sin(psi),
                                             vx * ca.sin(psi) + vy * ca.cos(psi), rz)
        hull = {"z_m": geo[0] + hull[0], "pitch_rad": hull[1], "roll_rad": hull[2], "heave_rate_m_s": geo_rate[0],
                "pitch_rate_rad_s": geo_rate[1], "roll_rate_rad_s": geo_rate[2]}
        return ca.vertcat(*[xp[i[n]] if n in i else hull[n] for n in self.model.state_names])

    def _quasi_static_dae(self, xp, zp, u, P):
        """The prediction's DAE with the quasi-static hull (``prediction_hull``): the model's ODE rows
        of the predicted states, its algebraic rows, then the hull's vertical force, pitch moment
        and roll moment balances at zero hull accelerations, each as an acceleration of the
        vehicle's mass [m/s^2]: the heave acceleration, the pitch moment over (m l/2) and the roll
        moment over (m B/2) (rows of the size of the acceleration rows)."""
        model = self.model
        za, hull = zp[:self.nza], zp[self.nza:] * QS_HULL_SCALE
        ode, alg = model.dae(self._quasi_static_full_state(xp, hull), za, u, P)
        pn = model.param_names
        m, Iz, l, B = (P[pn.index(n)] for n in ("mass_kg", "yaw_inertia_kg_m2", "contact_length_m", "track_gauge_m"))
        keep = [model.state_index(n) for n in self.pred_names]
        balance = ca.vertcat(ode[model.state_index("heave_rate_m_s")],
                             ode[model.state_index("pitch_rate_rad_s")] * PITCH_INERTIA_PER_YAW * Iz / (m * l / 2),
                             ode[model.state_index("roll_rate_rad_s")] * ROLL_INERTIA_PER_YAW * Iz / (m * B / 2))
        return ode[keep], ca.vertcat(alg, balance)

    def _hull_function(self) -> ca.Function:
        """(prediction states [SI], scaled hull variables, model parameters) -> the hull's balance
        rows, their Jacobian in the hull variables, the ground pose (z0, pitch, roll) and
        sqrt(1 + |grad z0|^2): the Newton of the guess (:meth:`_hull_guess`)."""
        self._ground_pose = self._ground_pose_function()
        xp = ca.SX.sym("xp", self.nxp)
        hv = ca.SX.sym("hull", len(QS_HULL_VARIABLES))
        P = ca.SX.sym("p", len(self.p_model))
        u = xp[[self.pred_names.index(f"torque_{k}_N_m") for k in ("left", "right")]]
        _, alg = self._quasi_static_dae(xp, ca.vertcat(ca.SX.zeros(self.nza), hv), u, P)
        rows = alg[self.nza:]
        i = {n: k for k, n in enumerate(self.pred_names)}
        geo, _, secant = self._ground_pose(xp[i["x_m"]], xp[i["y_m"]], xp[i["yaw_rad"]], 0, 0, 0)
        return ca.Function("mpc_hull", [xp, hv, P], [rows, ca.jacobian(rows, hv), geo, secant])

    def _hull_guess(self, xp_si: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """The quasi-static hull (scaled QS_HULL_VARIABLES) under the prediction state ``xp_si``:
        Newton with backtracking on its three balances from ``start``, or from the hull lying on the
        ground's plane with the CG at cg_height_m less 3 mm of sinkage above it (every segment
        pressed: the balances' Jacobian is singular with a track in the air)."""
        f = self._hull_fn
        _, _, geo, secant = f(xp_si, np.zeros(3), self.p_model)
        geo = np.array(geo).ravel()
        first = np.array([(self.params["cg_height_m"] - 3e-3) * float(secant), geo[1], geo[2]]) / QS_HULL_SCALE
        hv = first if start is None else np.asarray(start, float).copy()
        for _ in range(60):
            r, J, _, _ = f(xp_si, hv, self.p_model)
            r, J = np.array(r).ravel(), np.array(J)
            nr = float(np.linalg.norm(r))
            if nr < 1e-10:
                break
            try:
                step = -np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                break
            alpha = 1.0
            while alpha > 1e-4:
                trial = hv + alpha * step
                if float(np.linalg.norm(np.array(f(xp_si, trial, self.p_model)[0]).ravel())) < nr:
                    hv = trial
                    break
                alpha *= 0.5
            else:
                break
        return hv

    def _lateral_residual(self, e):
        """r with r^2 = the lateral penalty: e, or for the pseudo-Huber penalty
        e sqrt(2 / (sqrt(1 + (e/delta)^2) + 1)) (smooth through e = 0)."""
        dl = self.settings.lateral_huber_m
        if dl <= 0:
            return e
        return e * ca.sqrt(2 / (ca.sqrt(1 + (e / dl) ** 2) + 1))

    def _lateral_penalty(self, e):
        """e^2 near the path; with lateral_huber_m = delta > 0 the pseudo-Huber
        2 delta^2 (sqrt(1 + (e/delta)^2) - 1), which grows only linearly far from the path, so
        a large offset does not ask for a violent manoeuvre."""
        dl = self.settings.lateral_huber_m
        if dl <= 0:
            return e**2
        return 2 * dl**2 * (ca.sqrt(1 + (e / dl) ** 2) - 1)

    def _residuals(self, x, ref):
        s = self.settings
        i = {n: k for k, n in enumerate(self.pred_names)}
        X, Y, psi = x[i["x_m"]], x[i["y_m"]], x[i["yaw_rad"]]
        dx, dy = X - ref[0], Y - ref[1]
        c, sn = ca.cos(ref[2]), ca.sin(ref[2])
        e_lat = -dx * sn + dy * c
        e_lon = dx * c + dy * sn
        e_psi = psi - ref[2]
        e_v = x[i["u_m_s"]] - ref[3]
        e_r = x[i["yaw_rate_rad_s"]] - ref[3] * ref[4]
        return ca.vertcat(e_lat, math.sqrt(s.weight_heading) * e_psi,
                          math.sqrt(s.weight_along) * e_lon, math.sqrt(s.weight_speed) * e_v,
                          math.sqrt(s.weight_yaw_rate) * e_r)

    def _build(self, solvers: bool = True):
        s = self.settings
        N, nxa, nu, nk = self.N, self.nxa, self.nu, self.nk
        stage, term = self._stage_function()
        self.stage_fn = stage
        self._term_fn = term
        blk = nxa + nu + nk
        self.block = blk
        nw = N * blk + nxa
        w = ca.MX.sym("w", nw)
        npar = len(self.p_model)
        ncell = len(self.cell_names)
        par = ca.MX.sym("par", 5 * (N + 1) + npar + ncell)
        refs = ca.reshape(par[:5 * (N + 1)], 5, N + 1)
        P = par[5 * (N + 1):5 * (N + 1) + npar]
        XC = par[5 * (N + 1) + npar:]
        W = ca.reshape(w[:N * blk], blk, N)
        Xk, Uk, Kk = W[:nxa, :], W[nxa:nxa + nu, :], W[nxa + nu:, :]
        Xnext = ca.horzcat(W[:nxa, 1:], w[N * blk:])
        F = stage.map(N)
        xn, gcoll, grate, cost = F(Xk, Uk, Kk, refs[:, :N], ca.repmat(P, 1, N), ca.repmat(XC, 1, N))
        costN = term(w[N * blk:], refs[:, N])
        gap = Xnext - xn
        # constraints ordered stage by stage: [gap_k; collocation_k; rate_k] (fatrop's structure
        # detection needs the gap first in each stage)
        g = ca.vertcat(*[ca.vertcat(gap[:, k], gcoll[:, k], grate[:, k]) for k in range(N)])
        f = ca.sum2(cost) + costN
        ng_stage = nxa + nk + nu
        eq = ([True] * nxa + [True] * nk + [False] * nu) * N
        self.ng_stage = ng_stage
        nlp = {"x": w, "p": par, "f": f, "g": g}
        self.nlp = nlp
        self.rti = None
        if not solvers:
            self.solver = None
        elif s.solver == "rti":
            self.solver = None
            self.rti = RTI(self, s.rti_qp_solver, compiled=s.uses_jit, max_defect=s.rti_max_defect,
                           halvings=s.rti_step_halvings, cache=Path(s.jit_dir) if s.jit_dir else None,
                           relinearisations=s.rti_relinearisations)
        else:
            self.solver = self._nlpsol(nlp, eq, s.solver, s.uses_jit)
        # the fallback: interpreted (no compilation), tried when the primary solver fails and for the RTI's
        # cold start. On the MX graph, not expanded to SX: building IPOPT on the expanded U-turn NLP took
        # 3.0 s of CPU in every process that ran an MPC, on the MX graph 0.3 s, and the few solves it makes
        # (the cold start, a rare fallback) cost less than the difference (measured: the U-turn's closed loop
        # 10.0 -> 7.2-7.6 s of CPU in a fresh process, its figures equal to 1e-6 relative, 0 failed solves on
        # the three built-in scenarios; straight_offset's cold start converges to another iterate of its 1 m
        # approach, its 0.1 mm RMS 2 % lower; docs/control.md)
        self.fallback = None
        fb = s.fallback_solver
        if fb == "auto":
            fb = next(x for x in SOLVERS if x != s.solver)
        if solvers and fb not in (None, "none") and (fb, False) != (s.solver, s.uses_jit):
            self.fallback = self._nlpsol(nlp, eq, fb, False, expand=False)
        self.fallback_name = fb
        # bounds
        rate = s.torque_rate_max_N_m_s * s.sample_time_s / TORQUE_SCALE_N_M
        self.rate_scaled = rate
        self.tmax_scaled = s.torque_max_N_m / TORQUE_SCALE_N_M
        lbg = np.tile(np.concatenate([np.zeros(nxa), np.zeros(nk), -rate * np.ones(nu)]), N)
        ubg = np.tile(np.concatenate([np.zeros(nxa), np.zeros(nk), rate * np.ones(nu)]), N)
        self.lbg, self.ubg = lbg, ubg
        tmax = s.torque_max_N_m / TORQUE_SCALE_N_M
        lbx = -np.inf * np.ones(nw)
        ubx = np.inf * np.ones(nw)
        for k in range(N):
            o = k * blk
            lbx[o + nxa:o + nxa + nu] = -tmax
            ubx[o + nxa:o + nxa + nu] = tmax
        self.lbx0, self.ubx0 = lbx, ubx

    def _nlpsol(self, nlp, eq, solver: str, jit: bool, expand: bool | None = None):
        s = self.settings
        common = {"print_time": False, "error_on_fail": False}
        # jit: the NLP's functions compiled once into the solver cache (symtrack.control.solver_cache,
        # keyed by the problem, the CasADi version and the flags) and loaded by the next process
        # without a compiler; expand off (the expanded SX graph takes minutes of gcc, notes section 6).
        # ``expand``: the interpreted solver on the SX graph (faster solves, seconds to build) or the MX
        # graph (the fallback's); default: expanded unless jit
        common["expand"] = (not jit) if expand is None else bool(expand)
        if solver == "ipopt":
            opts = dict(common)
            # Primal warm start only: with warm_start_init_point = yes (and the shifted multipliers)
            # the warm solves of this NLP hit max_iter (measured); from the default barrier start
            # they converge in 4-6 iterations.
            opts["ipopt"] = {"print_level": 0, "sb": "yes", "max_iter": s.max_iter, "tol": s.tol,
                             "acceptable_tol": 10 * s.tol, "acceptable_iter": 3, "linear_solver": "mumps"}
            name = "ipopt"
        else:
            opts = dict(common)
            opts.update({"structure_detection": "auto", "equality": eq, "debug": False})
            opts["fatrop"] = {"print_level": 0, "max_iter": s.max_iter, "tol": s.tol, "mu_init": 1e-2}
            name = "fatrop"
        problem = ca.Function("mpc_nlp", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]]).serialize()
        payload = f"{name}|{sorted(opts.items())!r}|".encode() + problem.encode()

        def build():
            if jit:
                symbolic = ca.nlpsol("mpc", name, nlp, opts)
                so = compiled_nlp_library(symbolic, payload, root=Path(s.jit_dir) if s.jit_dir else None)
                return ca.nlpsol("mpc", name, str(so), opts)
            return ca.nlpsol("mpc", name, nlp, opts)

        # one solver per problem in this process: the NLP's parameters carry the vehicle, the soil, the
        # references and the cells, so the MPCs of a season's operations, a sweep's runs or the tests
        # with the same model and settings share it (building IPOPT's interpreted solver takes about
        # 2 s of CPU; the solver keeps no state between calls: each solve is given its start)
        key = (jit, s.jit_dir, hashlib.sha256(payload).hexdigest())
        return _NLPSOLS.get_or_build(key, build)

    # ------------------------------------------------------------------ run time
    def _initial_guess(self, x0s, ref):
        """A cold start: the stage states at the current state, moved along the reference."""
        N, blk, nxa, nu, nxp = self.N, self.block, self.nxa, self.nu, self.nxp
        w = np.zeros(N * blk + nxa)
        i = {n: k for k, n in enumerate(self.pred_names)}
        hull = None
        for k in range(N + 1):
            xs = x0s.copy()
            xs[i["x_m"]] = ref[k, 0] / self.sx[i["x_m"]]
            xs[i["y_m"]] = ref[k, 1] / self.sx[i["y_m"]]
            xs[i["yaw_rad"]] = ref[k, 2] / self.sx[i["yaw_rad"]]
            o = k * blk
            w[o:o + nxa] = xs
            if k < N:
                w[o + nxa:o + nxa + nu] = x0s[nxp:]
                if self.hull_quasi_static:  # the hull settled under the stage's pose
                    hull = self._hull_guess(xs[self.pred] * self.sx[self.pred], hull)
                for j in range(self.d):
                    a = o + nxa + nu + j * self.nc
                    w[a:a + nxp] = xs[self.pred]
                    if hull is not None:
                        w[a + nxp + self.nza:a + self.nc] = hull
        return w

    def _shift(self, v, block, tail):
        """Shift a stage-ordered vector by one stage (the last stage is repeated)."""
        N = self.N
        out = v.copy()
        out[:(N - 1) * block] = v[block:N * block]
        out[(N - 1) * block:N * block] = v[(N - 1) * block:N * block]
        if tail:
            out[N * block:] = v[N * block:]
        return out

    def reset(self):
        self._w = self._plan_u = None
        self._plan_age = 0
        if self.rti is not None:
            self.rti.lin = None

    def prepare(self, x_pred, x_cells, u_prev, ref, attempts: int = 10) -> SolveInfo:
        with InterruptWatch():
            return self._prepare(x_pred, x_cells, u_prev, ref, attempts)

    def step(self, x_pred: np.ndarray, x_cells: np.ndarray | None, u_prev: np.ndarray, ref: np.ndarray):
        """One MPC step. x_pred: the prediction states (names ``pred_names``) now; x_cells: the
        frozen cell states (prediction "vehicle") or None; u_prev: the command applied during the
        last interval [N m]; ref: (N+1) x 5 reference. Returns (command [N m], SolveInfo).
        Ctrl-C raises KeyboardInterrupt (:class:`InterruptWatch`)."""
        with InterruptWatch():
            return self._step(x_pred, x_cells, u_prev, ref)

    def _prepare(self, x_pred, x_cells, u_prev, ref, attempts: int = 10) -> SolveInfo:
        """Cold start before the loop engages (not counted in the step statistics): solve the
        first problem, restarting from the last iterate up to ``attempts`` times, so that the
        first closed-loop step is already warm. Returns the info of the last attempt."""
        self.reset()
        if self.rti is not None:
            return self._prepare_rti(x_pred, x_cells, u_prev, ref, attempts)
        total = 0.0
        info = None
        w = None
        for _ in range(attempts):
            info, w = self._solve(x_pred, x_cells, u_prev, ref, w)
            total += info.solve_time_s
            if info.success:
                break
        info.solve_time_s = total
        if info.success:
            self._accept(w)
        return info

    def _step(self, x_pred, x_cells, u_prev, ref):
        N, blk = self.N, self.block
        if self.rti is not None:
            info, wopt = self._feedback_rti(x_pred, x_cells, u_prev, ref)
        else:
            info, wopt = self._solve(x_pred, x_cells, u_prev, ref, None)
        if not info.success and self.fallback is not None:
            # from the same warm start (starting from where the primary stopped was measured worse)
            w_start = None
            if self.rti is not None:
                # from the prepared guess, unless it is far off the dynamics: then from a cold guess
                lin = self.rti.lin
                if lin is not None and self.rti.defect(lin["w"]) <= 10.0 * self.settings.rti_max_defect:
                    w_start = lin["w"]
                else:
                    w_start = self._initial_guess(self._x0s(x_pred, u_prev), ref)
            info2, wopt2 = self._solve(x_pred, x_cells, u_prev, ref, w_start, self.fallback)
            info2.solve_time_s += info.solve_time_s
            info2.iterations += info.iterations
            info2.status = f"{info.status} -> fallback {self.fallback_name}: {info2.status}"
            if info2.success:
                self.stats.fallbacks += 1
            info, wopt = info2, wopt2
        self.stats.solves.append(info)
        if info.success:
            self._accept(wopt)
            u = self._plan_u[0].copy()
        else:
            self.stats.failed += 1
            log.warning("MPC solve failed (%s); applying the shifted previous plan", info.status)
            if self._plan_u is None:
                u = np.asarray(u_prev, float).copy()
            else:
                self._plan_age += 1
                u = self._plan_u[min(self._plan_age, N - 1)].copy()
                if self._w is not None:
                    self._w = self._shift(self._w, blk, True)
        if self.rti is not None:
            # the preparation phase of the next sample: shift, linearise, condense (no measurement)
            t0 = time.perf_counter()
            self._prepare_next_rti(x_cells)
            info.preparation_time_s = time.perf_counter() - t0
        return u, info

    # ------------------------------------------------------------------ real-time iteration
    def _x0s(self, x_pred, u_prev):
        return np.concatenate([np.asarray(x_pred, float), np.asarray(u_prev, float)]) / self.sx

    def _cells(self, x_cells):
        return np.asarray(x_cells if x_cells is not None else [], float)

    def _prepare_next_rti(self, x_cells):
        """Linearise at the shifted plan (the guess of the next sample). After a failure with no
        plan the next feedback prepares from a cold guess itself."""
        self.rti.lin = None
        if self._w is None:
            return
        w = shift_guess(self, self._w) if self._plan_age == 0 else self._w
        try:
            self.rti.prepare_at(w, self.p_model, self._cells(x_cells))
        except (RuntimeError, np.linalg.LinAlgError) as err:
            log.warning("RTI preparation failed (%s); the next sample prepares again", err)
            self.rti.lin = None

    def _feedback_rti(self, x_pred, x_cells, u_prev, ref):
        """The feedback phase: one QP from the prepared linearisation; never raises."""
        x0s = self._x0s(x_pred, u_prev)
        t0 = time.perf_counter()
        try:
            if self.rti.lin is None:  # nothing prepared (first sample, or after a failure)
                w0 = self._initial_guess(x0s, ref) if self._w is None else self._w.copy()
                w0[:self.nxa] = x0s
                self.rti.prepare_at(w0, self.p_model, self._cells(x_cells))
            wopt, ok, status = self.rti.feedback(x0s, np.asarray(ref, float))
        except (RuntimeError, np.linalg.LinAlgError) as err:
            wopt, ok, status = None, False, f"exception: {err}"
        dt = time.perf_counter() - t0
        self.last_args = {"x0s": x0s, "ref": ref}
        return SolveInfo(ok, dt, 1, f"rti {self.rti.qp_name}: {status}"), wopt

    def _prepare_rti(self, x_pred, x_cells, u_prev, ref, attempts):
        """Cold start for RTI: the fallback NLP solver to convergence (up to ``attempts``
        restarts), then the first linearisation. Without a fallback solver, the Gauss-Newton SQP
        with full steps from the cold guess (which diverges from a cold guess on the built-in
        scenarios: docs/control.md)."""
        t0 = time.perf_counter()
        x0s = self._x0s(x_pred, u_prev)
        if self.fallback is not None:
            w, ok, iters, status = None, False, 0, "no attempt"
            for _ in range(attempts):
                info2, w = self._solve(x_pred, x_cells, u_prev, ref, w, self.fallback)
                iters += info2.iterations
                ok, status = info2.success, f"cold start by {self.fallback_name}: {info2.status}"
                if ok:
                    break
        else:
            w, ok, iters, status = gn_solve(self, x0s, self._cells(x_cells), np.asarray(ref, float),
                                            self._initial_guess(x0s, ref), self.settings.max_iter)
        info = SolveInfo(ok, time.perf_counter() - t0, iters, status)
        if ok:
            self._accept(w)
            # the first feedback comes on the measurement the cold start solved for (the closed loop
            # prepares and steps at one instant): linearise at the cold solution itself, not at its
            # shift one sample ahead. From the shift, straight_offset's first sample (1 m offset, the
            # torques swinging by 4 kN m in the first sample) started 1.9 (scaled) off the measurement
            # and failed (the RTI step and IPOPT's fallback).
            if self.settings.rti_cold_start == "shift":
                self._prepare_next_rti(x_cells)
            else:
                try:
                    self.rti.prepare_at(w, self.p_model, self._cells(x_cells))
                except (RuntimeError, np.linalg.LinAlgError) as err:
                    log.warning("RTI preparation failed (%s); the first sample prepares again", err)
                    self.rti.lin = None
        return info

    def _accept(self, wopt):
        N, blk, nxa, nu = self.N, self.block, self.nxa, self.nu
        self._w = wopt
        self._plan_u = wopt[:N * blk].reshape(N, blk)[:, nxa:nxa + nu] * TORQUE_SCALE_N_M
        self._plan_age = 0

    def _solve(self, x_pred, x_cells, u_prev, ref, w_start, solver=None):
        """One call of the NLP solver; never raises. Returns (SolveInfo, solution or None)."""
        solver = solver or self.solver
        blk, nxa = self.block, self.nxa
        x0s = np.concatenate([np.asarray(x_pred, float), np.asarray(u_prev, float)]) / self.sx
        # ref is (N+1) x 5 row-major: its ravel is the 5 x (N+1) column-major matrix the NLP reads
        par = np.concatenate([np.asarray(ref, float).ravel(), self.p_model,
                              np.asarray(x_cells if x_cells is not None else [], float)])
        if w_start is not None:
            w0 = w_start.copy()
        elif self._w is None:
            w0 = self._initial_guess(x0s, ref)
        else:
            w0 = self._shift(self._w, blk, True)
        w0[:nxa] = x0s
        lbx, ubx = self.lbx0.copy(), self.ubx0.copy()
        lbx[:nxa] = x0s
        ubx[:nxa] = x0s
        args = {"x0": w0, "p": par, "lbx": lbx, "ubx": ubx, "lbg": self.lbg, "ubg": self.ubg}
        self.last_args = args  # for diagnosis (re-run the same NLP with another solver setting)
        t0 = time.perf_counter()
        ok, status, iters, cost, wopt = False, "exception", 0, float("nan"), None
        try:
            sol = solver(**args)
            dt = time.perf_counter() - t0
            st = solver.stats()
            status = str(st.get("return_status", st.get("success")))
            iters = int(st.get("iter_count", 0) or 0)
            wopt = np.array(sol["x"]).ravel()
            cost = float(sol["f"])
            ok = bool(st.get("success", False)) and bool(np.all(np.isfinite(wopt)))
        except RuntimeError as err:  # never crash on a failed solve
            dt = time.perf_counter() - t0
            status = f"exception: {err}"
        return SolveInfo(bool(ok), dt, iters, status, cost), wopt

    def predicted(self):
        """The last accepted plan: (N+1) x nxp states [SI] and N x 2 commands [N m]."""
        if self._w is None:
            return None, None
        N, blk, nxa = self.N, self.block, self.nxa
        X = np.vstack([self._w[k * blk:k * blk + nxa] for k in range(N)] + [self._w[N * blk:]]) * self.sx
        return X[:, self.pred], self._plan_u
