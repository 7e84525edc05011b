"""The physics fuzzer: random but plausible homogeneous scenarios, each run and checked against
properties that any correct run has (docs/model.md, "Integrators", "The physics fuzzer").

A case is a scenario document (:func:`case_document`): a soil preset with each Bekker and
Mohr-Coulomb value perturbed, a crawler whose mass and geometry stay inside the plausibility rules
(:mod:`symtrack.model.plausibility`: no refusal, no warning), a torque programme (a step, a
staircase ramp, a reversal, a turn, a drive then a coast, zero torque, or the exact holding torque
on a ramp), one of the lateral laws ("creep", "shear") and one of the vehicle variants of
:data:`VARIANTS` (the planar model, the 3D hull on flat ground, across a side slope or on a ramp),
simulated for 1-3 s. The variants are few on purpose: each is one compiled model (tens of seconds
to build once, cached on disk), while the soil, the vehicle and the programme are parameters.

Each case runs on the default compiled Rosenbrock (10 ms steps with error control) and on the
reference, CVODES at reltol 1e-8 (:data:`REFERENCE`), and is checked (:func:`check_case`):

- ``finite``: every integrator completes with finite and bounded states (:data:`TREAD_SPEED_MAX_M_S`,
  :data:`TILT_MAX_DEG`) within :data:`RUN_TIMEOUT_S` of CPU (the model built and compiled before the
  clock starts), or the scenario is refused on load with the package's own error, or the 3D vehicle's
  start finds no static rest that the model carries (:data:`ACCEPTED_REFUSALS`; both acceptable outcomes,
  counted as ``refused``), or the package stops a run on one of :data:`ACCEPTED_STOPS`: a
  sprocket's tread speed past :data:`~symtrack.model.plausibility.MAX_TREAD_SPEED_M_S`, the
  programme's torque spinning the tracks faster than any drive turns them, the 3D hull turned over
  (:func:`~symtrack.model.plausibility.check_tilt`), or a track end sunk deeper than the CG's height
  (:func:`~symtrack.model.plausibility.check_sinkage`), with the package's message
  (:class:`~symtrack.foundations.errors.ImplausibleRunError`; an acceptable outcome, counted as
  ``stopped``, where the other integrator's run stops too or comes within :data:`STOP_AGREEMENT` of the
  limit; an accuracy failure where it does not);
- ``accuracy``: the Rosenbrock run's summary figures (:data:`FIGURES`) within
  :data:`ACCURACY_RTOL` of the reference plus each figure's absolute floor, or the run's own error
  estimate flags it (``fixed_step_error_max`` above 1: the run warned that a step was kept above its
  tolerance);
- ``symmetry`` (flat ground): the programme mirrored (left and right swapped) gives the mirrored
  run: yaw and lateral deviation with the sign flipped, the other figures equal, within
  :data:`SYMMETRY_RTOL` and floors 1000 x finer than the accuracy's;
- ``energy`` (flat ground, a programme that ends with zero torque): from the release on, the mechanical
  energy never rises by more than the motors' work plus the elastic energy the tracks' shear
  displacement held (:func:`_elastic`), within :data:`ENERGY_RTOL` of the kinetic energy (both
  integrators). The mechanical energy is the kinetic energy of the body, its yaw and the running gears
  (:func:`_kinetic`) and on the 3D vehicle the hull's heave, pitch and roll too, the hull's potential
  energy (:func:`_potential`) and the soil's normal elastic energy under it (:func:`_normal_elastic`):
  the whole balance;
- ``rest`` (flat ground, zero torque throughout): the vehicle at rest stays at rest: speed, travel
  and yaw below :data:`REST_SPEED_M_S`, :data:`REST_TRAVEL_M`, :data:`REST_YAW_RAD` (both
  integrators).

``python -m symtrack.bench.fuzz --budget N [--seed S] --out DIR`` draws N cases (from S),
prints one progress line per case, writes ``DIR/cases.csv`` (:data:`CSV_COLUMNS`) and
``DIR/failures.json`` (each failure with its scenario document, reproducible with
``symtrack simulate``), prints the counts of ok, refused, stopped and failed cases and exits 1 if any
property failed. The test suite runs the same checks
through hypothesis with a small budget (tests/test_physics_fuzz.py).
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import math
import random
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from ..api import IncompleteSimulation, build, simulate
from ..foundations.errors import ImplausibleRunError, SymtrackError
from ..model.plausibility import (
    GROUND_PRESSURE_RANGE_KPA,
    MAX_TREAD_SPEED_M_S,
    SINKAGE_OVER_CG_HEIGHT_MAX,
    bekker_k_eq,
    bekker_pressure_limit_Pa,
    leaning_sinkage_limit_m,
    sinkage_columns,
    tilt_over_tipping,
)
from ..presets.soils import SOILS
from ..simulation.scenario import scenario_from_dict
from ..soil import law as soil_law
from ..vehicles.planar import GRAVITY_M_S2
from ..vehicles.vehicle3d import PITCH_INERTIA_PER_YAW, ROLL_INERTIA_PER_YAW, running_gear_momentum_ratio

__all__ = ["ACCURACY_RTOL", "CSV_COLUMNS", "ENERGY_RTOL", "FIGURES", "PROPERTIES", "REFERENCE",
           "REST_SPEED_M_S", "REST_TRAVEL_M", "REST_YAW_RAD", "SYMMETRY_RTOL", "VARIANTS", "CaseOutcome",
           "RandomDraw", "case_document", "check_case", "main", "mirrored", "run_fuzz", "shrink"]

log = logging.getLogger("symtrack.bench.fuzz")

# ---- what a case may be ----------------------------------------------------------------------------------
# name -> ([model] table, [terrain.surface] table or None). Each is one compiled model (the surface is
# part of the 3D model's expressions): few variants, so that a long run compiles each once.
VARIANTS: dict[str, tuple[dict, dict | None]] = {
    "planar-creep": ({"lateral_law": "creep"}, None),
    "planar-shear": ({"lateral_law": "shear"}, None),
    "3d-creep": ({"lateral_law": "creep", "vehicle": "3d"}, None),
    "3d-shear": ({"lateral_law": "shear", "vehicle": "3d"}, None),
    "3d-creep-side8": ({"lateral_law": "creep", "vehicle": "3d"}, {"slope_y_deg": 8.0}),
    "3d-shear-side8": ({"lateral_law": "shear", "vehicle": "3d"}, {"slope_y_deg": 8.0}),
    "3d-creep-ramp8": ({"lateral_law": "creep", "vehicle": "3d"}, {"slope_x_deg": 8.0}),
}
PROGRAMMES = ("step", "ramp", "reversal", "turn", "coast", "zero", "hold")
# Soil values perturbed by a factor in [1 / SOIL_FACTOR, SOIL_FACTOR] (log-uniform) around a preset: the
# spread of Wong's Table 2.3 between soils of one kind, without leaving the kind (a stiff sand's n on a
# soft clay's k_phi is no soil).
SOIL_FACTOR = 1.3
SOIL_PERTURBED = ("bekker_n", "k_c_N_per_m_n1", "k_phi_N_per_m_n2", "cohesion_Pa", "friction_angle_rad",
                  "shear_modulus_K_m")
# Vehicle ranges: medium agricultural and construction crawlers (the reference crawler's comments in
# symtrack/presets/vehicles.py give its ranges); the mean ground pressure is kept inside
# VEHICLE_PRESSURE_KPA, within the plausibility rule's range, and l / B inside 0.9-1.8 (Wong's range for
# steerable tracked vehicles, inside the rule's warning range).
VEHICLE_PRESSURE_KPA = (15.0, 120.0)
assert GROUND_PRESSURE_RANGE_KPA[0] < VEHICLE_PRESSURE_KPA[0] < VEHICLE_PRESSURE_KPA[1] < GROUND_PRESSURE_RANGE_KPA[1]
# The generator keeps the static sinkage z = (p / k)^(1/n) of the mean ground pressure below this: a
# crawler's ground clearance. (The plausibility rules bound the pressure alone: on the WES heavy clay,
# n = 0.11, a 122 kPa crawler sinks tens of metres; docs/model.md, "The physics fuzzer".)
STATIC_SINKAGE_MAX_M = 0.2
# The generator keeps Bekker's loading stiffness at the static sinkage at most this times the soil's elastic
# stiffness: the physical bound (no soil loads plastically stiffer than it reloads), tighter than the package's
# refusal (plausibility.BEKKER_STIFFNESS_OVER_ELASTIC_MAX, which allows for the assumed K_e of the Wong soils).
SOIL_CONTACT_RATIO_MAX = 1.0
# The static sinkage is kept below the leaning limit (plausibility.check_leaning) divided by this: the
# rule's onset is a mean; the loaded end of a track sinks deeper.
LEANING_MARGIN_FUZZ = 2.0
# The largest torque of a programme as a fraction of the torque whose thrust 2 T / r equals the weight
# (the plausibility rule warns above 2): from gentle driving to what spins the tracks on soft soil.
TORQUE_FRACTION = (0.03, 0.6)
DURATION_S = (1.0, 3.0)

# ---- the reference and the tolerances ----------------------------------------------------------------------
# CVODES at tight tolerances: its own error is some 1e-6 relative, far below the tolerance it checks.
REFERENCE = {"integrator": "cvodes", "reltol": 1e-8, "abstol": 1e-10, "compiled": True}
# Summary figures compared, each with its absolute floor: well below what a user reads from the figure,
# and what keeps a figure that is nearly zero (the yaw of a straight run, 1e-4 deg) from failing on
# a relative difference of two tiny numbers.
FIGURES = {"distance_m": 1e-3, "lateral_deviation_signed_m": 1e-3, "yaw_final_deg": 0.01, "sinkage_sprocket_mm": 0.01,
           "sinkage_idler_mm": 0.01, "speed_final_m_s": 1e-3}
# The fixed step against the reference: the target for the drive-and-coast case (every summary
# figure within 2 % of CVODES). The error control's tolerance (1e-3 per step) leaves a run's figures
# within some 1e-4 where it holds; 2 % is what the user is promised.
ACCURACY_RTOL = 0.02
# Mirror symmetry: the equations are exactly symmetric; a mirrored run differs by rounding (sums taken
# in the other order, 1e-16) amplified over some thousands of steps, and by the odd step-halving
# decision that rounding tips at the error control's threshold (a local error below 1e-3 of a state).
# 1e-4 relative and floors 1000 x finer than the accuracy's are far above the first and below any
# error a user would see.
SYMMETRY_RTOL = 1e-4
SYMMETRY_FLOOR = 1e-3
# Energy: the motors' work after the release is integrated by trapezoids over the 10 ms outputs, whose
# error while the actuators' torque decays (tau_T >= 0.05 s) is some 1e-4 of the kinetic energy;
# ENERGY_RTOL of the largest kinetic energy of the coast, plus ENERGY_ATOL_J for a vehicle nearly at rest.
ENERGY_RTOL = 1e-3
ENERGY_ATOL_J = 1e-2
# At rest: the soil settles under the tracks (mm of sinkage, no travel). A speed of 0.1 mm/s or a
# travel of 0.1 mm over 3 s is no visible motion; anything a drift would give exceeds it.
REST_SPEED_M_S = 1e-4
REST_TRAVEL_M = 1e-4
REST_YAW_RAD = 1e-5

# A run (one integrator) that takes more CPU than this is stopped and fails ``finite``: a 1-3 s run takes
# well under 2 s of CPU on every integrator here; 30 s is an integrator that is stuck (a fixed step halved
# to its limit at every step, CVODES creeping). CPU, not wall time: a loaded machine does not stop a sound
# run, and the model's compile (before the clock starts) is not counted.
RUN_TIMEOUT_S = 30.0

# Bounded: a run reported complete stays where a crawler can be. The run itself stops where a sprocket's
# tread speed r |omega| passes plausibility.MAX_TREAD_SPEED_M_S (no drive turns a track faster: its sources
# there), so a complete run above it is the package's defect; on the 8 deg slopes here, or on flat ground,
# the hull does not pitch or roll 45 deg (it would have turned over). Beyond either a run has diverged,
# whatever its figures say.
TREAD_SPEED_MAX_M_S = MAX_TREAD_SPEED_M_S
TILT_MAX_DEG = 45.0

PROPERTIES = ("finite", "accuracy", "symmetry", "energy", "rest")
# The plausibility stops (ImplausibleRunError's quantity) that count as a refusal, not a failure: the tread
# speed, where the programme's torque spins the tracks faster than any drive turns them (the model's torque
# has no power limit; the generator's torques reach 0.6 of the weight's thrust, which spins the tracks on
# soft soil, on purpose: the package must say so), the tilt, where the 3D hull turns over (a tall crawler
# on a short track sinking at its rear on a soft ramp: the model's answer, beyond which it has no hull), and the
# sinkage, where a track end sinks deeper than the CG's height (the hull in the soil, which the model does not
# carry: the generator keeps the static sinkage within the clearance, but a crawler turning on the side slope of
# the WES heavy clay's nearly flat law digs its loaded track in: seed 37's case 362 sinks 0.93 m in 2.1 s on
# CVODES and the Rosenbrock alike). Each is accepted only where the other integrator agrees (STOP_AGREEMENT). A
# stop on the body's speed is not accepted: the generator stays far inside it, so such a stop is a run that
# diverged.
ACCEPTED_STOPS = ("tread_speed", "tilt", "sinkage")
# The start's refusal that counts as a refusal on load does (``refused``): the 3D vehicle's start finds no static
# rest that the model carries (model.static: ImplausibleRunError "rest", raised before the first step; the start
# is the same for every integrator, so the reference refuses the case in the same words). The generator keeps a
# rigid track's most loaded end within the clearance (case_document), but at the edge of rest (a crawler with its
# CG well behind the contact's centre on the WES heavy clay's nearly flat law: seed 37's case 381, where a rigid
# track rests with the soil's moment 2 % above the weight's) the 3D contact's segments find none.
ACCEPTED_REFUSALS = ("rest",)
CSV_COLUMNS = ("case", "seed", "variant", "programme", "soil", "duration_s", "mass_kg", "ground_pressure_kPa",
               "torque_max_N_m", "outcome", "failed", *PROPERTIES, "worst_figure", "worst_ratio",
               "fixed_step_error_max", "fixed_step_steps_halved", "energy_rise_J", "distance_m", "wall_s", "message")


# ---- drawing ---------------------------------------------------------------------------------------------------
class RandomDraw:
    """The draws of :func:`case_document` from a seeded :class:`random.Random` (the CLI); the test
    suite passes an object with the same two methods that draws through hypothesis."""

    def __init__(self, seed: int):
        self.rng = random.Random(seed)

    def uniform(self, lo: float, hi: float) -> float:
        return self.rng.uniform(lo, hi)

    def choice(self, seq):
        return seq[self.rng.randrange(len(seq))]


def _round(x: float, digits: int = 5) -> float:
    """A drawn value to ``digits`` significant digits: the documents read well and reproduce exactly."""
    return 0.0 if x == 0 else float(f"{x:.{digits}g}")


def _log_uniform(draw, lo: float, hi: float) -> float:
    return math.exp(draw.uniform(math.log(lo), math.log(hi)))


def _soil(draw, soils=None) -> dict:
    preset = draw.choice(sorted(soils or SOILS))
    base = SOILS[preset]
    out = {"preset": preset}
    for k in SOIL_PERTURBED:
        v = base[k] * _log_uniform(draw, 1 / SOIL_FACTOR, SOIL_FACTOR)
        if k == "bekker_n":
            v = min(v, 1.4)
        if k == "friction_angle_rad":
            v = min(v, math.radians(40.0))
        if base[k] > 0:
            out[k] = _round(v)
    return out


def _vehicle(draw, soil: dict, slope_deg: float = 0.0) -> dict:
    gauge = draw.uniform(1.1, 2.2)
    width = draw.uniform(0.3, min(0.75, 0.45 * gauge))
    length = gauge * draw.uniform(0.9, 1.8)
    pressure = _log_uniform(draw, *VEHICLE_PRESSURE_KPA) * 1e3
    iz_factor = draw.uniform(0.8, 1.2)
    radius, cg_h, cg_e = draw.uniform(0.25, 0.45), draw.uniform(0.5, 1.1), draw.uniform(-0.06, 0.06) * length
    # no deeper than STATIC_SINKAGE_MAX_M at rest on this soil (Bekker: z = (p / k)^(1/n), k = k_c / b + k_phi),
    # at the most loaded track end too: a rigid track's linear pressure under the CG's offset and, on a slope
    # (``slope_deg``, along and across), the weight's moment h tan(a) about the contact. (On the WES heavy
    # clay's nearly flat law the loaded end sinks without bound where the mean sinks millimetres: the 3D
    # hull on its 8 deg ramp has no static start, it tips into the soil.)
    s = {**SOILS[soil["preset"]], **soil}
    k = bekker_k_eq(s, width)
    tilt = math.tan(math.radians(slope_deg))
    peak = (1 + 6 * (abs(cg_e) + cg_h * tilt) / length) * (1 + 2 * cg_h * tilt / gauge)
    pressure = min(pressure, k * STATIC_SINKAGE_MAX_M ** s["bekker_n"] / peak)
    # and no deeper than the 3D hull leans over at (plausibility.check_leaning, with a margin for the load's
    # distribution along the track): the same sinkage bound, n min(l^2 / 12, B^2 / 4) / h
    lean = leaning_sinkage_limit_m({"contact_length_m": length, "track_gauge_m": gauge, "cg_height_m": cg_h}, s)
    pressure = min(pressure, k * (lean / (LEANING_MARGIN_FUZZ * peak)) ** s["bekker_n"])
    # and inside the rule that Bekker's law is no stiffer than the soil's elastic reloading at that sinkage
    # (plausibility.check_soil_contact: a nearly flat law, the WES heavy clay's, under a light crawler)
    lo, hi = bekker_pressure_limit_Pa({"track_width_m": width}, s, SOIL_CONTACT_RATIO_MAX)
    pressure = min(max(pressure, 1.01 * lo), 0.99 * hi)
    mass = pressure * 2 * width * length / GRAVITY_M_S2
    hull_l, hull_w = 1.4 * length, gauge + width
    v = {"preset": "reference_crawler",
         "mass_kg": mass, "track_gauge_m": gauge, "track_width_m": width, "contact_length_m": length,
         "yaw_inertia_kg_m2": mass * (hull_l ** 2 + hull_w ** 2) / 12 * iz_factor,
         "sprocket_radius_m": radius, "cg_height_m": cg_h, "cg_ahead_of_contact_centre_m": cg_e,
         "sprocket_inertia_kg_m2": draw.uniform(10.0, 60.0), "torque_time_constant_s": draw.uniform(0.05, 0.2),
         "lateral_friction_coeff": draw.uniform(0.5, 0.65), "lateral_creep_speed_m_s": draw.uniform(0.005, 0.02)}
    return {k: (x if isinstance(x, str) else _round(x)) for k, x in v.items()}


def _programme(draw, kind: str, vehicle: dict, duration: float, ramp_deg: float,
               torque_fraction=TORQUE_FRACTION) -> list[dict]:
    """The [[torque]] entries of a programme kind."""
    r, m = vehicle["sprocket_radius_m"], vehicle["mass_kg"]
    full = m * GRAVITY_M_S2 * r / 2  # each sprocket's torque whose thrust, both together, is the weight
    top = full * draw.uniform(*torque_fraction)

    def e(t, left, right):
        return {"t_s": _round(t, 4), "left_N_m": _round(left), "right_N_m": _round(right)}

    if kind == "zero":
        return [e(0.0, 0.0, 0.0)]
    if kind == "hold":  # the exact holding torque on the ramp: W sin(t) / 2 of thrust per track at rest
        hold = m * GRAVITY_M_S2 * math.sin(math.radians(ramp_deg)) * r / 2
        return [e(0.0, hold, hold)]
    if kind == "step":
        return [e(0.0, top, top * draw.uniform(0.8, 1.0))]
    if kind == "turn":
        return [e(0.0, top, top), e(duration * draw.uniform(0.2, 0.6), top * draw.uniform(-0.3, 0.5), top)]
    if kind == "ramp":  # a staircase of n steps up to the top (the programme is piecewise constant)
        n = int(draw.uniform(3, 9))
        dt = duration * draw.uniform(0.4, 0.9) / n
        ratio = draw.uniform(0.7, 1.0)
        return [e(i * dt, top * (i + 1) / n, top * ratio * (i + 1) / n) for i in range(n)]
    if kind == "reversal":
        t1 = duration * draw.uniform(0.2, 0.6)
        return [e(0.0, top, top), e(t1, -top * draw.uniform(0.5, 1.0), -top * draw.uniform(0.5, 1.0))]
    if kind == "coast":
        t1 = duration * draw.uniform(0.2, 0.5)
        return [e(0.0, top, top * draw.uniform(0.6, 1.0)), {**e(t1, 0.0, 0.0), "event": "coast"}]
    raise ValueError(kind)


def case_document(draw, variants=None, programmes=None, duration_s=DURATION_S, soils=None,
                  torque_fraction=TORQUE_FRACTION) -> tuple[dict, dict]:
    """``(document, meta)``: a scenario document drawn with ``draw`` (:class:`RandomDraw` or the test
    suite's hypothesis draw) and what the checks need to know of it (``variant``, ``programme``,
    ``flat``). ``variants``, ``programmes``, ``soils``: the names to draw from (default all; "hold" only
    on a ramp, where it is the programme drawn half of the time); ``torque_fraction``: the range of the
    largest torque over the one whose thrust is the weight."""
    variant = draw.choice(list(variants or VARIANTS))
    model, surface = VARIANTS[variant]
    ramp_deg = (surface or {}).get("slope_x_deg", 0.0)
    kinds = [k for k in (programmes or PROGRAMMES) if k != "hold" or ramp_deg]
    if ramp_deg and "hold" in kinds and draw.uniform(0.0, 1.0) < 0.5:
        kind = "hold"
    else:
        kind = draw.choice([k for k in kinds if k != "hold"] or kinds)
    duration = _round(draw.uniform(*duration_s), 3)
    soil = _soil(draw, soils)
    vehicle = _vehicle(draw, soil, max((surface or {}).values(), default=0.0))
    flat = surface is None
    start_yaw = 0.0 if flat else _round(draw.choice([0.0, 30.0, 90.0, 180.0, -90.0]))
    if kind == "hold":  # facing up the ramp, where the programme's torque holds the vehicle
        start_yaw = 0.0
    doc = {"name": f"fuzz-{variant}-{kind}", "description": "a physics-fuzzer case (symtrack.bench.fuzz)",
           "run": {"duration_s": duration, "output_dt_s": 0.01, "integrator": "rosenbrock"},
           "model": dict(model), "vehicle": vehicle, "soil": soil,
           "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": start_yaw},
           "torque": _programme(draw, kind, vehicle, duration, ramp_deg, torque_fraction)}
    if surface is not None:
        doc["terrain"] = {"surface": dict(surface)}
    return doc, {"variant": variant, "programme": kind, "flat": flat}


def mirrored(doc: dict) -> dict:
    """The document with left and right swapped: torques exchanged, the start mirrored about the x axis."""
    out = json.loads(json.dumps(doc))
    out["name"] = doc["name"] + "-mirrored"
    out["torque"] = [{**e, "left_N_m": e["right_N_m"], "right_N_m": e["left_N_m"]} for e in doc["torque"]]
    st = out.get("start", {})
    out["start"] = {**st, "y_m": -st.get("y_m", 0.0), "yaw_deg": -st.get("yaw_deg", 0.0)}
    return out


# ---- checking ----------------------------------------------------------------------------------------------------
@dataclass
class CaseOutcome:
    """What one case gave: ``outcome`` "ok", "refused" (the scenario was refused on load, or the start of every
    run on one of :data:`ACCEPTED_REFUSALS`: acceptable),
    "stopped" (a run was stopped by the package on a limit of :data:`ACCEPTED_STOPS`, with its message:
    acceptable) or "failed"; ``status`` per property of :data:`PROPERTIES` ("pass", "fail", "flagged": outside the
    tolerance but the run's error estimate said so, or "n/a"); ``messages`` per failed property."""

    document: dict
    meta: dict
    outcome: str = "ok"
    status: dict = field(default_factory=lambda: dict.fromkeys(PROPERTIES, "n/a"))
    messages: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)
    worst: tuple = ("", 0.0)
    wall_s: float = 0.0
    stops: dict = field(default_factory=dict)  # label -> the message of a run stopped on an ACCEPTED_STOPS limit
    stop_kinds: dict = field(default_factory=dict)  # label -> the quantity of that limit
    refusals: dict = field(default_factory=dict)  # label -> the message of a start refused (ACCEPTED_REFUSALS)
    near: dict = field(default_factory=dict)  # label -> {quantity: the largest value over its limit} of a complete run

    @property
    def failed(self) -> list[str]:
        return [p for p in PROPERTIES if self.status[p] == "fail"]

    def fail(self, prop: str, message: str) -> None:
        self.status[prop] = "fail"
        self.messages[prop] = f"{self.messages[prop]}; {message}" if prop in self.messages else message
        self.outcome = "failed"


def _with_run(doc: dict, **run) -> dict:
    return {**doc, "run": {**doc["run"], **run}}


class _RunTimeout(BaseException):
    """Raised by the alarm in :func:`_run` (a BaseException: the package's own handlers do not take it)."""


_EXPIRED: list = []  # the alarm went off (casadi may turn the exception into a solver failure of its own)


def _alarm(signum, frame):
    _EXPIRED.append(signum)
    raise _RunTimeout


def _stop_limit(err: BaseException) -> str | None:
    """The plausibility limit (:class:`ImplausibleRunError`'s ``quantity``) that stopped a run, found along the
    chain of causes of ``err``, or None."""
    seen = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        if isinstance(err, ImplausibleRunError):
            return err.quantity
        err = err.__cause__ or err.__context__
    return None


def _run(doc: dict, out: CaseOutcome, label: str):
    """The Result of the document's scenario, or None after recording a failure of ``finite`` (also when it
    takes more than :data:`RUN_TIMEOUT_S` of CPU) or a stop on an :data:`ACCEPTED_STOPS` limit (``out.stops``).
    The model is built and compiled before the clock starts (a first compile is tens of seconds and is
    cached on disk: not the integrator's time)."""
    timeout_s = RUN_TIMEOUT_S
    timed = timeout_s is not None and threading.current_thread() is threading.main_thread()
    _EXPIRED.clear()
    built = None
    try:
        built = build(scenario_from_dict(doc, doc.get("name", "fuzz")))
        built.plant()  # compiles (or loads) the model: outside the clock
        if timed:
            prev = signal.signal(signal.SIGPROF, _alarm)
            signal.setitimer(signal.ITIMER_PROF, timeout_s)
        try:
            res = simulate(built, progress=False)
        finally:
            if timed:
                signal.setitimer(signal.ITIMER_PROF, 0.0)
                signal.signal(signal.SIGPROF, prev)
    except BaseException as err:
        if _EXPIRED:  # casadi may have turned the alarm into a solver failure of its own
            out.fail("finite", f"{label}: did not finish within {timeout_s:g} s of CPU")
            return None
        if not isinstance(err, Exception):
            raise  # Ctrl-C
        limit = _stop_limit(err)
        if limit in ACCEPTED_REFUSALS:
            out.refusals[label] = str(err)  # the start refused the scenario with the package's reason: acceptable
            return None
        if isinstance(err, IncompleteSimulation) and limit in ACCEPTED_STOPS:
            out.stops[label] = str(err)  # the package refused the programme part of the way: acceptable
            out.stop_kinds[label] = limit
            return None
        if isinstance(err, IncompleteSimulation):
            out.fail("finite", f"{label}: {err}")
        elif isinstance(err, SymtrackError):
            out.fail("finite", f"{label}: {type(err).__name__}: {err}")
        else:  # a traceback of any other kind is what the property forbids
            out.fail("finite", f"{label}: traceback {type(err).__name__}: {err}")
        return None
    run = res.runs[-1]
    if not (np.all(np.isfinite(run.X)) and np.all(np.isfinite(run.Y))):
        out.fail("finite", f"{label}: a non-finite state or output in a run reported complete")
        return None
    r = doc["vehicle"].get("sprocket_radius_m", res.scenario.vehicle["sprocket_radius_m"])
    tread = r * float(np.max(np.abs(run.X[:, [run.state_names.index(f"omega_{k}_rad_s") for k in ("left", "right")]])))
    tilt = max((float(np.max(np.abs(run.state(k)))) for k in ("pitch_rad", "roll_rad") if k in run.state_names),
               default=0.0)
    if tread > TREAD_SPEED_MAX_M_S or tilt > math.radians(TILT_MAX_DEG):
        out.fail("finite", f"{label}: a run reported complete left what any crawler does: tread speed up to "
                           f"{tread:.4g} m/s (allowed {TREAD_SPEED_MAX_M_S:g}), pitch or roll up to "
                           f"{math.degrees(tilt):.4g} deg (allowed {TILT_MAX_DEG:g}; fixed_step_error_max "
                           f"{res.summary.get('fixed_step_error_max', float('nan')):.3g})")
        return None
    params = res.scenario.params
    sk_from, isk = sinkage_columns(run.state_names, run.output_names)
    h = float(params.get("cg_height_m", 0.0))
    out.near[label] = {"sinkage": float(np.max((run.X if sk_from == "x" else run.Y)[:, isk]))
                       / (SINKAGE_OVER_CG_HEIGHT_MAX * h) if isk and h > 0 else 0.0,
                       "tread_speed": tread / TREAD_SPEED_MAX_M_S,
                       "tilt": float(np.max(tilt_over_tipping(run.state("pitch_rad"), run.state("roll_rad"), params)))
                       if "pitch_rad" in run.state_names else 0.0}
    return res


def _within(a: float, b: float, rtol: float, atol: float) -> tuple[bool, float]:
    """(|a - b| <= rtol |b| + atol, that difference over the allowance)."""
    allow = rtol * abs(b) + atol
    d = abs(a - b)
    return d <= allow, d / allow


def _kinetic(res, params: dict) -> np.ndarray:
    """Kinetic energy [J] at the output times: the body's plane motion, its yaw and both running gears, and on
    the 3D vehicle its heave, pitch and roll with the running gear's coupling to the pitch
    (:mod:`symtrack.vehicles.vehicle3d`: the gyrostat's 1/2 I_pitch q^2 + 1/2 J sum omega^2 - kappa J q sum
    omega, omega the sprockets' rates relative to the hull; I_pitch and I_roll the model's ratios of the yaw
    inertia)."""
    run = res.runs[-1]
    s = run.state
    m, iz, j = params["mass_kg"], params["yaw_inertia_kg_m2"], params["sprocket_inertia_kg_m2"]
    e = 0.5 * m * (s("u_m_s") ** 2 + s("v_m_s") ** 2) + 0.5 * iz * s("yaw_rate_rad_s") ** 2
    e = e + 0.5 * j * (s("omega_left_rad_s") ** 2 + s("omega_right_rad_s") ** 2)
    if "heave_rate_m_s" in run.state_names:
        q, omega_sum = s("pitch_rate_rad_s"), s("omega_left_rad_s") + s("omega_right_rad_s")
        kappa = running_gear_momentum_ratio(params["contact_length_m"], params["sprocket_radius_m"])
        e = e + (0.5 * m * s("heave_rate_m_s") ** 2 + 0.5 * PITCH_INERTIA_PER_YAW * iz * q ** 2
                 + 0.5 * ROLL_INERTIA_PER_YAW * iz * s("roll_rate_rad_s") ** 2 - kappa * j * q * omega_sum)
    return e


def _potential(res, params: dict) -> np.ndarray:
    """Gravity's potential energy m g z [J] of the 3D hull's CG (flat ground: the heave z_m is its height);
    zero on the planar vehicle, which does not heave."""
    run = res.runs[-1]
    if "z_m" not in run.state_names:
        return np.zeros(len(run.t))
    return params["mass_kg"] * GRAVITY_M_S2 * run.state("z_m")


def _normal_elastic(res, sc, points: int = 96, bisections: int = 48) -> np.ndarray:
    """The energy [J] the soil's normal pressure under the 3D hull holds at the output times (flat ground), zero
    on the planar vehicle: sum over the contact's segments of b ds times the integral of the model's own
    pressure p(z) from 0 to the segment's sinkage, on its branch (:mod:`symtrack.vehicles.vehicle3d`: a
    segment's history is the soil's memory under it, the states ``soil_history_{track}_{i}_m`` of
    :class:`~symtrack.vehicles.vehicle3d.ContactTerrain`, the front one's none; the virgin curve is then the
    path back up), by trapezoids on ``points`` points. At a given memory the pressure is a function of the
    segment's sinkage alone: it gives back on the way up what it took on the way down, less the cells'
    damping. The memory changes only as the track moves over the ground (soil from the segment ahead).

    The integral is taken in two parts, each by trapezoids on ``points`` points: the reloading branch below the
    memory, from where its line meets zero (found by ``bisections`` bisections on p > 0) up to the lesser of the
    sinkage and the memory, where the branch is a straight line and the trapezoids are exact; and the virgin
    branch from the memory up to the sinkage, on points graded towards its start (on fresh soil p ~ z^n, whose
    slope is infinite at 0 for n < 1). On one grid over [0, z] the kinks at the line's zero and at the memory
    fell between the points and the trapezoids' error moved from one output to the next: on the WES heavy clay
    (n = 0.11, an unloading stiffness of some 1e8 Pa/m) 13 J at 48 points of a 1000 J store, more than the
    energy check allows (seed 37, case 402; on dry sand, n = 1.29, 5.7 J: case 998). Split, against 2000
    points: 0.04 J at 48 points, 0.011 J at 96 (the default; its change between outputs 0.0008 J, within the
    check's 0.01 J floor)."""
    run = res.runs[-1]
    if "z_m" not in run.state_names:
        return np.zeros(len(run.t))
    P, opts = sc.params, sc.model
    law_obj = soil_law.make(opts)
    law_num = np.array(law_obj.vector(P), dtype=float).ravel()
    z, z_hist, law = ca.SX.sym("z"), ca.SX.sym("z_hist"), ca.SX.sym("law", len(law_num))
    pressure = ca.Function("p", [z, z_hist, law],
                           [law_obj.pressure(z, (z_hist, law_obj.virgin_pressure(z_hist, law), 0, 0, 0), law)])
    B, b, l, h, e = (P[k] for k in ("track_gauge_m", "track_width_m", "contact_length_m", "cg_height_m",
                                    "cg_ahead_of_contact_centre_m"))
    n = opts.contact_segments
    ds = l / n
    x_body = l / 2 - e - (np.arange(n) + 0.5) * ds  # the segments' centres, front first
    Z, pitch, roll = run.state("z_m"), run.state("pitch_rad"), run.state("roll_rad")
    frac = np.linspace(0.0, 1.0, points)
    out = np.zeros(len(Z))

    def p_at(zz, hist):  # the law's pressure at sinkages zz (..., k) under memories hist (...)
        m = zz.size
        return np.array(pressure.map(m)(zz.reshape(1, m), np.repeat(hist.reshape(-1, 1), zz.shape[-1], axis=1)
                                        .reshape(1, m), np.tile(law_num[:, None], (1, m))),
                        dtype=float).reshape(zz.shape)

    for y_body in (B / 2, -B / 2):
        # the segment centre's depth below the flat ground (vehicle3d.hull_rotation's third row)
        depth = -(Z[:, None] + np.sin(pitch)[:, None] * x_body[None, :]
                  + (np.cos(pitch) * np.sin(roll))[:, None] * y_body - (np.cos(pitch) * np.cos(roll))[:, None] * h)
        side = "left" if y_body > 0 else "right"
        hist = np.zeros_like(depth)
        for i in range(1, n):  # the soil's memory under each segment behind the front one (its states)
            hist[:, i] = run.state(f"soil_history_{side}_{i}_m")
        d = np.maximum(depth, 0.0)
        top = np.minimum(d, np.maximum(hist, 0.0))  # the reloading branch's part of [0, d]
        lo, hi = np.zeros_like(top), top.copy()  # where the reloading line meets zero: p = 0 at lo, p > 0 at hi
        for _ in range(bisections):
            mid = 0.5 * (lo + hi)
            pos = p_at(mid[..., None], hist)[..., 0] > 0.0
            hi, lo = np.where(pos, mid, hi), np.where(pos, lo, mid)
        for z0, z1, grid in ((lo, top, frac), (top, d, frac ** 2)):
            zz = z0[..., None] + (z1 - z0)[..., None] * grid
            out += b * ds * np.trapezoid(p_at(zz, hist), zz, axis=-1).sum(axis=1)
    return out


def _elastic(res, soil: dict) -> np.ndarray:
    """An upper bound [J] of the energy the tracks' shear displacement holds elastically: |F| min(|j|, K) per
    track and direction (Janosi-Hanamoto's K is the displacement of the soil's elastic build-up; beyond it
    the soil shears plastically and its work is dissipated)."""
    run = res.runs[-1]
    K = soil["shear_modulus_K_m"]
    out = np.zeros(len(run.t))
    for side in ("left", "right"):
        out += np.abs(run.output(f"tractive_{side}_N")) * np.minimum(np.abs(run.state(f"shear_{side}_m")), K)
        if f"lateral_shear_{side}_m" in run.state_names:
            out += (np.abs(run.output(f"lateral_force_{side}_N"))
                    * np.minimum(np.abs(run.state(f"lateral_shear_{side}_m")), K))
    return out


def _check_energy(res, sc, out: CaseOutcome, label: str) -> None:
    run = res.runs[-1]
    t = run.t
    window = t >= sc.torque[-1].t_s - 1e-12
    if window.sum() < 2:
        return
    s = run.state
    power = (s("torque_left_N_m") * s("omega_left_rad_s") + s("torque_right_N_m") * s("omega_right_rad_s"))[window]
    tw = t[window]
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(tw))])
    kin = _kinetic(res, sc.vehicle)[window]
    e = kin + _potential(res, sc.vehicle)[window] + _normal_elastic(res, sc)[window]
    gain = e - e[0] - work  # the mechanical energy gained beyond the motors' work since the release
    # from any t1 to a later t2 the gain may rise by at most the elastic energy held at t1
    rise = gain - np.minimum.accumulate(gain + _elastic(res, sc.soil)[window])
    allow = ENERGY_RTOL * float(kin.max()) + ENERGY_ATOL_J
    k = int(np.argmax(rise))
    if rise[k] > allow:
        out.fail("energy", f"{label}: coasting at zero torque the mechanical energy rose by {rise[k]:.4g} J beyond the "
                           f"motors' work and the shear's elastic energy (allowed {allow:.3g} J) by t = {tw[k]:.3f} s "
                           f"(the release at t = {tw[0]:.3f} s, {kin[0]:.6g} J kinetic)")
    elif out.status["energy"] == "n/a":
        out.status["energy"] = "pass"
    out.figures["energy_rise_J"] = max(float(rise[k]), out.figures.get("energy_rise_J", -np.inf))


def _check_rest(res, out: CaseOutcome, label: str) -> None:
    run = res.runs[-1]
    s = run.state
    speed = float(np.max(np.hypot(s("u_m_s"), s("v_m_s"))))
    travel = float(np.max(np.hypot(s("x_m") - s("x_m")[0], s("y_m") - s("y_m")[0])))
    yaw = float(np.max(np.abs(s("yaw_rad") - s("yaw_rad")[0])))
    if speed > REST_SPEED_M_S or travel > REST_TRAVEL_M or yaw > REST_YAW_RAD:
        out.fail("rest", f"{label}: at rest with zero torque on flat ground the vehicle moved: speed up to "
                         f"{speed:.3g} m/s (allowed {REST_SPEED_M_S:g}), travel {travel:.3g} m (allowed "
                         f"{REST_TRAVEL_M:g}), yaw {yaw:.3g} rad (allowed {REST_YAW_RAD:g})")
    elif out.status["rest"] == "n/a":
        out.status["rest"] = "pass"


def check_case(doc: dict, meta: dict, reference: dict | None = None, symmetry: bool = True) -> CaseOutcome:
    """Run a case (the document on its own integrator, the compiled Rosenbrock, and on ``reference``,
    default :data:`REFERENCE`; the mirrored document on flat ground) and check the properties of the
    module doc."""
    t_start = time.perf_counter()
    out = CaseOutcome(doc, meta)
    try:
        sc = scenario_from_dict(doc, doc.get("name", "fuzz"))
    except SymtrackError as err:  # a clear refusal is an acceptable outcome
        out.outcome = "refused"
        out.messages["refused"] = str(err)
        out.wall_s = time.perf_counter() - t_start
        return out
    ref_run = {**REFERENCE, **(reference or {})}
    fixed = _run(doc, out, doc["run"]["integrator"])
    ref = _run(_with_run(doc, **ref_run), out, ref_run["integrator"])
    if out.refusals:  # the start refused: acceptable where every run's start refused it (they share the start)
        for res, label in ((fixed, doc["run"]["integrator"]), (ref, ref_run["integrator"])):
            if label not in out.refusals and res is not None:
                out.fail("finite", f"{label} started and completed where {', '.join(out.refusals)} refused the start: "
                                   f"{next(iter(out.refusals.values()))}")
        if not out.failed:
            out.outcome = "refused"
            out.messages["refused"] = next(iter(out.refusals.values()))
        out.wall_s = time.perf_counter() - t_start
        return out
    if out.stops:  # stopped by the package (ACCEPTED_STOPS): no figures to compare
        _check_stops(out, [(fixed, doc["run"]["integrator"]), (ref, ref_run["integrator"])])
        out.wall_s = time.perf_counter() - t_start
        return out
    if fixed is not None and ref is not None:
        out.status["finite"] = "pass"
    if fixed is not None:
        out.figures = {k: fixed.summary.get(k) for k in (*FIGURES, "fixed_step_error_max", "fixed_step_steps_halved")}
    if fixed is not None and ref is not None:
        worst, flagged = ("", 0.0), float(fixed.summary.get("fixed_step_error_max", 0.0)) > 1.0
        bad = []
        for k, atol in FIGURES.items():
            ok, ratio = _within(fixed.summary[k], ref.summary[k], ACCURACY_RTOL, atol)
            if ratio > worst[1]:
                worst = (k, ratio)
            if not ok:
                bad.append(f"{k} {fixed.summary[k]:.6g} against {ref.summary[k]:.6g}")
        out.worst = worst
        if bad and flagged:  # outside the tolerance, and the run's own estimate said so
            out.status["accuracy"] = "flagged"
            out.messages["accuracy (flagged)"] = "; ".join(bad)
        elif bad:
            out.fail("accuracy", f"{doc['run']['integrator']} against {ref_run['integrator']} (reltol "
                                 f"{ref_run['reltol']:g}): {'; '.join(bad)} (allowed {ACCURACY_RTOL:g} relative plus "
                                 f"each figure's floor; fixed_step_error_max "
                                 f"{fixed.summary.get('fixed_step_error_max', 0.0):.3g} did not flag it)")
        else:
            out.status["accuracy"] = "pass"
    if meta.get("flat"):
        if symmetry and fixed is not None and any(e["left_N_m"] != e["right_N_m"] for e in doc["torque"]):
            mir = _run(mirrored(doc), out, "mirrored")
            if mir is not None:
                _check_symmetry(fixed, mir, out)
            elif "mirrored" in out.stops:  # the run completed, its mirror image did not
                out.fail("symmetry", f"the mirrored programme's run stopped where the run completed: "
                                     f"{out.stops.pop('mirrored')}")
        elif symmetry and fixed is not None:
            _check_symmetry(fixed, fixed, out)  # a symmetric programme is its own mirror: straight ahead
        zero_end = sc.torque[-1].left_N_m == 0.0 and sc.torque[-1].right_N_m == 0.0
        if zero_end and len(sc.torque) > 1:
            for res, label in ((fixed, "rosenbrock"), (ref, ref_run["integrator"])):
                if res is not None:
                    _check_energy(res, sc, out, label)
        if zero_end and all(e.left_N_m == 0.0 and e.right_N_m == 0.0 for e in sc.torque):
            for res, label in ((fixed, "rosenbrock"), (ref, ref_run["integrator"])):
                if res is not None:
                    _check_rest(res, out, label)
    out.wall_s = time.perf_counter() - t_start
    return out


# A run stopped on an accepted limit while the other integrator's run of the same case completed: that run
# must have come near the limit too (its largest tread speed or tilt at least this fraction of it), or the
# stop is the stopped integrator's error, not the programme's.
STOP_AGREEMENT = 0.9


def _check_stops(out: CaseOutcome, runs) -> None:
    """A case where a run was stopped on an accepted limit: "stopped" (acceptable) when every other run of it
    was stopped so too or completed with a tread speed near the limit; ``accuracy`` fails otherwise."""
    for res, label in runs:
        for kind in sorted(set(out.stop_kinds.values())):
            if res is not None and out.near[label][kind] < STOP_AGREEMENT:
                out.fail("accuracy", f"{label} completed with its {kind} up to {out.near[label][kind]:.3g} of the "
                                     f"limit where {', '.join(out.stops)} stopped on it ({STOP_AGREEMENT:g} of it "
                                     f"allowed)")
    if not out.failed:
        out.outcome = "stopped"
        out.messages["stopped"] = "; ".join(f"{k}: {m}" for k, m in out.stops.items())


SIGNED = ("lateral_deviation_signed_m", "yaw_final_deg")


def _check_symmetry(run, mir, out: CaseOutcome) -> None:
    flagged = max(float(r.summary.get("fixed_step_error_max", 0.0)) for r in (run, mir)) > 1.0
    bad = []
    for k, atol in FIGURES.items():
        a, b = run.summary[k], mir.summary[k]
        if k in SIGNED:
            b = -b
        ok, _ = _within(a, b, SYMMETRY_RTOL, SYMMETRY_FLOOR * atol)
        if not ok:
            bad.append(f"{k} {a:.9g} against {'-' if k in SIGNED else ''}({mir.summary[k]:.9g}) mirrored")
    if bad and flagged:  # the run said it is wrong there (a step kept above its tolerance)
        out.status["symmetry"] = "flagged"
        out.messages["symmetry (flagged)"] = "; ".join(bad)
    elif bad:
        out.fail("symmetry", "the mirrored programme's run is not the mirror image: " + "; ".join(bad) +
                 f" (allowed {SYMMETRY_RTOL:g} relative plus {SYMMETRY_FLOOR:g} of the accuracy's floors)")
    else:
        out.status["symmetry"] = "pass"


# ---- shrinking ----------------------------------------------------------------------------------------------------
def _simpler(doc: dict):
    """Candidate simplifications of a document, simplest first: the soil's and the vehicle's drawn values
    back to their preset's, the duration halved, torques rounded to 2 significant digits."""
    for section in ("soil", "vehicle"):
        for key in [k for k in doc[section] if k != "preset"]:
            out = json.loads(json.dumps(doc))
            del out[section][key]
            yield f"{section}.{key} as the preset's", out
    if doc["run"]["duration_s"] > 0.2:
        last = doc["torque"][-1]["t_s"]
        d = _round(max(doc["run"]["duration_s"] / 2, last + 0.1), 3)
        if d < doc["run"]["duration_s"]:
            yield f"run.duration_s = {d:g}", _with_run(doc, duration_s=d)
    for section in ("soil", "vehicle"):
        for key, v in doc[section].items():
            if key != "preset" and _round(v, 2) != v:
                out = json.loads(json.dumps(doc))
                out[section][key] = _round(v, 2)
                yield f"{section}.{key} = {_round(v, 2):g}", out
    for i, e in enumerate(doc["torque"]):
        for side in ("left_N_m", "right_N_m"):
            r = _round(e[side], 2)
            if r != e[side]:
                out = json.loads(json.dumps(doc))
                out["torque"][i][side] = r
                yield f"torque[{i}].{side} = {r:g}", out


def shrink(doc: dict, meta: dict, properties, max_checks: int = 200, time_limit_s: float = 120.0,
           stream=None) -> tuple[dict, list[str]]:
    """A simpler document that still fails one of ``properties`` (greedy: each simplification of
    :func:`_simpler` is kept when the case still fails so), and the simplifications kept; at most
    ``max_checks`` checks and ``time_limit_s`` seconds."""
    kept, checks, changed = [], 0, True
    t0 = time.perf_counter()
    while changed and checks < max_checks and time.perf_counter() - t0 < time_limit_s:
        changed = False
        for what, cand in _simpler(doc):
            checks += 1
            try:
                fails = set(check_case(cand, meta).failed)
            except Exception:  # noqa: BLE001 -- a candidate that the checks cannot even run is not simpler
                fails = set()
            if fails & set(properties):
                doc, changed = cand, True
                kept.append(what)
                if stream is not None:
                    print(f"  shrink: {what}", file=stream, flush=True)
                break
            if checks >= max_checks or time.perf_counter() - t0 > time_limit_s:
                break
    return doc, kept


# ---- the long run ----------------------------------------------------------------------------------------------
def _row(i: int, seed: int, out: CaseOutcome) -> dict:
    d, m = out.document, out.meta
    v = d["vehicle"]
    p = v["mass_kg"] * GRAVITY_M_S2 / (2 * v["track_width_m"] * v["contact_length_m"]) / 1e3
    tmax = max(max(abs(e["left_N_m"]), abs(e["right_N_m"])) for e in d["torque"])
    msg = " | ".join(f"{k}: {x}" for k, x in out.messages.items())
    return {"case": i, "seed": seed, "variant": m["variant"], "programme": m["programme"], "soil": d["soil"]["preset"],
            "duration_s": d["run"]["duration_s"], "mass_kg": v["mass_kg"], "ground_pressure_kPa": round(p, 2),
            "torque_max_N_m": tmax, "outcome": out.outcome, "failed": " ".join(out.failed), **out.status,
            "worst_figure": out.worst[0], "worst_ratio": round(out.worst[1], 4),
            "fixed_step_error_max": out.figures.get("fixed_step_error_max"),
            "fixed_step_steps_halved": out.figures.get("fixed_step_steps_halved"),
            "energy_rise_J": out.figures.get("energy_rise_J"), "distance_m": out.figures.get("distance_m"),
            "wall_s": round(out.wall_s, 3), "message": msg}


SHRINK_PER_CLASS = 2


def _quiet_worker() -> None:
    """A worker's logging as :func:`main` sets the process's: the runs' own warnings go to the CSV's columns."""
    logging.getLogger("symtrack").setLevel(logging.ERROR)


def _draw_and_check(task: tuple) -> tuple:
    """One case of :func:`run_fuzz` (in its process or a worker's): (i, seed, document, meta, outcome)."""
    i, case_seed, variants = task
    doc, meta = case_document(RandomDraw(case_seed), variants)
    doc["name"] = f"fuzz-{case_seed}"
    return i, case_seed, doc, meta, check_case(doc, meta)


def run_fuzz(budget: int, seed: int, out_dir, time_limit_s: float | None = None, variants=None,
             stream=sys.stdout, shrink_failures: bool = True, jobs: int = 1) -> int:
    """Draw and check ``budget`` cases (case i from its own seed ``seed * 1_000_003 + i``, so that a case is
    redrawn alone by its seed); write ``cases.csv`` and ``failures.json`` into ``out_dir`` as it goes.
    Stops early after ``time_limit_s``. ``jobs`` > 1: the cases checked by that many worker processes, written
    in the cases' order (the same rows as one process: each case depends on its seed alone, and its CPU limit
    is its own process's). Returns the number of cases with a failed property."""
    if not (isinstance(jobs, int) and 1 <= jobs <= 64):
        raise ValueError(f"jobs = {jobs!r} is outside the allowed range [1, 64]")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    failures, counts = [], {p: 0 for p in PROPERTIES}
    outcomes = {"ok": 0, "refused": 0, "stopped": 0, "failed": 0}
    t0 = time.perf_counter()
    tasks = ((i, seed * 1_000_003 + i, variants) for i in range(budget))
    pool = None
    if jobs > 1:
        import multiprocessing

        # spawn: each worker imports the package afresh (no CasADi or compiled library state shared by a fork)
        pool = multiprocessing.get_context("spawn").Pool(jobs, initializer=_quiet_worker)
        results = pool.imap(_draw_and_check, tasks, chunksize=1)
    else:
        results = map(_draw_and_check, tasks)
    with open(out_dir / "cases.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for i in range(budget):
            if time_limit_s is not None and time.perf_counter() - t0 > time_limit_s:
                print(f"time limit of {time_limit_s:g} s reached after {i} cases", file=stream, flush=True)
                break
            try:
                _, case_seed, doc, meta, out = next(results)
            except BaseException:
                if pool is not None:
                    pool.terminate()
                raise
            outcomes[out.outcome] += 1
            for p in out.failed:
                counts[p] += 1
            writer.writerow(_row(i, case_seed, out))
            fh.flush()
            if out.failed:
                failures.append({"case": i, "seed": case_seed, "variant": meta["variant"],
                                 "programme": meta["programme"], "failed": out.failed, "messages": out.messages,
                                 "scenario": doc})
                (out_dir / "failures.json").write_text(json.dumps(failures, indent=1))
            print(f"[{i + 1}/{budget}] {meta['variant']:15s} {meta['programme']:8s} {out.outcome:7s} "
                  f"{' '.join(out.failed) or '-':20s} {out.wall_s:6.2f} s  "
                  f"({time.perf_counter() - t0:.0f} s; failures {sum(counts.values())})", file=stream, flush=True)
    if pool is not None:
        pool.terminate()  # the workers of cases drawn beyond a time limit are not waited for
        pool.join()
    if shrink_failures:
        seen: dict = {}
        for f in failures:  # the first SHRINK_PER_CLASS of each class (variant and failed properties)
            cls = (f["variant"], tuple(f["failed"]))
            seen[cls] = seen.get(cls, 0) + 1
            if seen[cls] > SHRINK_PER_CLASS:
                continue
            print(f"shrinking case {f['case']} ({' '.join(f['failed'])})", file=stream, flush=True)
            meta = {"variant": f["variant"], "programme": f["programme"], "flat": VARIANTS[f["variant"]][1] is None}
            small, kept = shrink(f["scenario"], meta, f["failed"], stream=stream)
            redo = check_case(small, meta)
            f["shrunk"] = {"scenario": small, "simplified": kept, "failed": redo.failed, "messages": redo.messages}
            (out_dir / "failures.json").write_text(json.dumps(failures, indent=1))
    (out_dir / "failures.json").write_text(json.dumps(failures, indent=1))
    print(f"cases: {sum(outcomes.values())} ({outcomes['ok']} ok, {outcomes['refused']} refused, "
          f"{outcomes['stopped']} stopped, {outcomes['failed']} failed); failures by property: "
          + ", ".join(f"{p} {n}" for p, n in counts.items()), file=stream, flush=True)
    return outcomes["failed"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m symtrack.bench.fuzz", description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", type=int, required=True, help="number of cases to draw and check")
    ap.add_argument("--seed", type=int, default=0, help="the seed of the draws (default 0)")
    ap.add_argument("--out", required=True, help="folder for cases.csv and failures.json")
    ap.add_argument("--time-limit", type=float, default=None, help="stop after this many seconds (wall)")
    ap.add_argument("--no-shrink", action="store_true", help="do not shrink the failures at the end")
    ap.add_argument("--variants", default=None, help=f"comma-separated subset of {', '.join(VARIANTS)}")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes that check cases side by side (default 1; "
                                                        "the rows are the same and in the same order)")
    args = ap.parse_args(argv)
    variants = None if args.variants is None else [v.strip() for v in args.variants.split(",")]
    unknown = [v for v in variants or [] if v not in VARIANTS]
    if unknown:
        ap.error(f"--variants: unknown {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    # the runs' own warnings (a step kept above its tolerance, an implausible input) go to the CSV's
    # columns; stderr keeps the progress readable
    logging.getLogger("symtrack").setLevel(logging.ERROR)
    if not 1 <= args.jobs <= 64:
        ap.error(f"--jobs {args.jobs} is outside the allowed range [1, 64]")
    failed = run_fuzz(args.budget, args.seed, args.out, args.time_limit, variants,
                      shrink_failures=not args.no_shrink, jobs=args.jobs)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
