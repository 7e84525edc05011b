"""Plausibility of a vehicle and of a run: what no agricultural or construction crawler has.

The parameter registry (:mod:`symtrack.model.parameters`) bounds each value on its own (a mass
above 0, a radius below 5 m). The rules here bound what a value means together with the others,
so that a unit typed wrong (tonnes where kg are meant: ``mass_kg = 7.0``) or a geometry no
crawler has is caught before a run reports it as complete. Each rule's numbers live here, with
their reasoning; the scenario checks (:mod:`symtrack.simulation.scenario`,
:mod:`symtrack.control.scenario`) call :func:`check_vehicle` and :func:`check_torque`, the time loop
(:mod:`symtrack.simulation.loop`) :func:`check_speed`.

Refused (:class:`~symtrack.foundations.errors.ParameterError`, named as the registry's messages:
the key, the value, the allowed range):

- mean ground pressure m g / (2 b l) outside :data:`GROUND_PRESSURE_RANGE_KPA`;
- a track as wide as the gauge or wider (:data:`TRACK_WIDTH_OVER_GAUGE_MAX`): the tracks overlap;
- a static sinkage where Bekker's law is more than :data:`BEKKER_STIFFNESS_OVER_ELASTIC_MAX` times stiffer than
  the soil's elastic stiffness (:func:`check_soil_contact`): the law used outside its range;
- a 3D vehicle whose static sinkage makes it lean over at rest (:func:`check_leaning`).

Warned (one line, the run goes on): a contact length outside :data:`CONTACT_LENGTH_OVER_GAUGE_RANGE`
times the gauge, and a torque programme that pushes more than :data:`TRACTION_OVER_WEIGHT_MAX`
times the vehicle's weight.

Stopped (:class:`~symtrack.foundations.errors.ImplausibleRunError`, a
:class:`~symtrack.foundations.errors.SimulationError` whose ``quantity`` names the limit): a run whose speed exceeds
:data:`MAX_SPEED_M_S`, whose sprockets' tread speed exceeds :data:`MAX_TREAD_SPEED_M_S`, or whose
track sinks deeper than :data:`SINKAGE_OVER_CG_HEIGHT_MAX` times the CG height, or whose 3D hull pitches or rolls
beyond its static tipping angle (:func:`check_tilt`: turned over).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..foundations.errors import ImplausibleRunError, ParameterError
from ..vehicles.planar import GRAVITY_M_S2, mean_ground_pressure_Pa

__all__ = ["BEKKER_STIFFNESS_OVER_ELASTIC_MAX", "CONTACT_LENGTH_OVER_GAUGE_RANGE", "GROUND_PRESSURE_RANGE_KPA",
           "MAX_SPEED_M_S", "MAX_TREAD_SPEED_M_S", "SINKAGE_OVER_CG_HEIGHT_MAX", "TRACK_WIDTH_OVER_GAUGE_MAX",
           "TRACTION_OVER_WEIGHT_MAX", "bekker_k_eq", "bekker_pressure_limit_Pa", "bekker_stiffness_ratio",
           "check_sinkage", "check_soil_contact", "is_sinkage_name", "sinkage_columns", "check_speed", "check_tilt",
           "check_leaning", "check_torque", "check_tread_speed", "check_vehicle", "ground_pressure_kPa",
           "leaning_sinkage_limit_m", "tilt_over_tipping", "tipping_angles_rad", "LEANING_MARGIN"]

log = logging.getLogger("symtrack.plausibility")

# The mean ground pressure m g / (2 b l) of a crawler. Typical published values: the reference
# crawler 25 kPa, rubber-tracked farm tractors and crawler dozers some tens of kPa to about 150 kPa,
# low-ground-pressure (swamp) machines down to about 15-20 kPa. 5 and 300 kPa lie well outside what
# any agricultural or construction crawler has: below 5 kPa is a mass typed in
# tonnes (7 kg on the reference tracks: 0.03 kPa), above 300 kPa a contact typed too small.
GROUND_PRESSURE_RANGE_KPA = (5.0, 300.0)
# track_gauge_m is the distance between the track centre-lines: the tracks are apart only while
# the width b is below the gauge B (the gap between them is B - b).
TRACK_WIDTH_OVER_GAUGE_MAX = 1.0
# Contact length over gauge, l / B: Wong (Theory of Ground Vehicles) gives about 0.9-1.8 for
# steerable tracked vehicles (the reference crawler 1.6). Outside 0.5-3 a skid-steered crawler
# turns badly or not at all: warned, not refused (a study may explore it on purpose).
CONTACT_LENGTH_OVER_GAUGE_RANGE = (0.5, 3.0)
# The commanded thrust 2 |T| / r of both sprockets over the weight m g. The soil carries at most
# about its friction and cohesion times the load (a drawbar pull near the weight on firm soil);
# a torque programme asking more than twice the weight spins the tracks or, with a light mass,
# accelerates the vehicle to speeds no crawler reaches: warned.
TRACTION_OVER_WEIGHT_MAX = 2.0
# The fastest tracked vehicles run at about 20 m/s (70 km/h, military); agricultural crawlers
# 11 m/s (40 km/h) at most. A run faster than 30 m/s (108 km/h) is an implausible input (the mass
# in tonnes, a torque in the wrong unit) or a numerical failure: it is stopped.
MAX_SPEED_M_S = 30.0
# A sprocket's tread speed r |omega| above 30 m/s: stopped. The tread speed is what the drive turns the
# track at, and a real drive bounds it: the engine's governed speed in the top gear gives the vehicle's top
# speed on firm ground, where the slip is a few per cent, so the tread runs at most about that top speed.
# Published top speeds of the fastest tracked vehicles: the M1 Abrams 72 km/h (governed), the Leopard 2
# 68-72 km/h, the FV101 Scorpion 72-80 km/h (about 20-22 m/s); rubber-tracked farm tractors 40 km/h
# (11 m/s, the road limit for tractors in the EU). 30 m/s (108 km/h) is above all of them. The model's
# sprocket torque is a torque source with no speed limit of its own (no engine map, no power limit): where
# a torque programme asks more than the soil carries, the tracks spin up without bound, and a run there
# is one no drive can give, whatever its figures say. It stops, keeping its trajectory up to the last
# output within the limit, with a message that says so (a refusal of the programme, not a complete run).
MAX_TREAD_SPEED_M_S = 30.0
# Bekker's loading stiffness dp/dz = n p / z at the static sinkage z = (p / k_eq)^(1/n) of the mean ground
# pressure, over the soil's elastic (unloading/reloading) stiffness K_e: refused above this. A soil's virgin
# (plastic) loading is softer than its elastic unloading and reloading (Wong, Theory of Ground Vehicles: the
# response to repetitive loading, the unloading-reloading line much steeper than the loading curve), so a
# loading curve stiffer than K_e is the Bekker fit used outside the sinkages its plate tests measured
# (centimetres). It happens with a nearly flat law: the WES heavy clay's n = 0.11 puts a 25 kPa crawler at a
# static sinkage of micrometres (n p / z some 40 x K_e), where the integrators stall on the stiffness (the
# physics fuzzer's CVODES runs: too much work, or minutes for a 3 s run). Every other preset carries 15-120
# kPa at 0.03-0.53 of K_e. Refused above 10, not 1: the Wong soils' K_e is not measured but assumed, Chrono
# SCM's soft value at the lower end of SCM's range 4e7-4e8 Pa/m (symtrack/presets/soils.py), so a ratio up to
# 10 may be a soil whose true K_e is higher (the default clay with its k_phi doubled, a sweep's point, is at 1);
# the fuzzer's stalling cases were at 40 and above. (The fuzzer draws its soils at 1 or below.)
BEKKER_STIFFNESS_OVER_ELASTIC_MAX = 10.0
# The 3D vehicle's leaning stability: its tracks' rotational stiffness on the soil, with Bekker's tangent
# n p / z at the static sinkage as the subgrade modulus, (n p / z) b l^3 / 6 about the pitch axis and
# (n p / z) b l B^2 / 2 about the roll axis, must exceed the weight's overturning moment per radian W h (the
# leaning instability of a tall structure on soft soil: E. C. Hambly, "Soil buckling and the leaning
# instability of tall structures", The Structural Engineer 63A(3), 1985). With W = 2 p b l both come to a
# static sinkage below n l^2 / (12 h) and n B^2 / (4 h); refused beyond (at a margin of 1: the onset). Found
# by the physics fuzzer: a 10.4 t crawler on the WES heavy clay (n = 0.11, 12 cm of static sinkage, its pitch
# stiffness 0.23 W h) had no static start on flat ground.
LEANING_MARGIN = 1.0
# A track end sunk deeper than the CG's height above the ground: the hull would be in the soil, and the
# model has no hull contact (no belly drag), so its figures have left its domain: stopped. (Found by the
# physics fuzzer: a 16 t crawler on a very soft clay ran "complete" with 93 m of sinkage.)
SINKAGE_OVER_CG_HEIGHT_MAX = 1.0


def ground_pressure_kPa(vehicle: dict) -> float:
    """The mean ground pressure m g / (2 b l) [kPa] of a vehicle parameter set."""
    return mean_ground_pressure_Pa(vehicle) / 1e3


def check_vehicle(vehicle: dict, where: str = "vehicle") -> None:
    """Refuse (ParameterError) or warn (one log line) where ``vehicle`` (a checked parameter set)
    is outside what any agricultural or construction crawler has (module doc)."""
    m, b, B, l = (float(vehicle[k]) for k in ("mass_kg", "track_width_m", "track_gauge_m", "contact_length_m"))
    p = ground_pressure_kPa(vehicle)
    lo, hi = GROUND_PRESSURE_RANGE_KPA
    if not lo <= p <= hi:
        hint = ""
        if p < lo and lo <= 1e3 * p <= hi:
            hint = f"; {where}.mass_kg is in kg ({m:g} t is mass_kg = {1e3 * m:g})"
        elif p > hi:
            hint = f"; {where}.track_width_m and {where}.contact_length_m are in m"
        raise ParameterError(
            f"{where}: mean ground pressure m g / (2 b l) = {p:.3g} kPa (mass_kg = {m:g}, track_width_m = {b:g}, "
            f"contact_length_m = {l:g}) is outside the allowed range [{lo:g}, {hi:g}] kPa (no agricultural or "
            f"construction crawler has it){hint}")
    if b >= TRACK_WIDTH_OVER_GAUGE_MAX * B:
        raise ParameterError(
            f"{where}.track_width_m = {b:g} is outside the allowed range (0, {where}.track_gauge_m = {B:g}) "
            f"(the gauge is the distance between the track centre-lines: the tracks would overlap)")
    lo, hi = CONTACT_LENGTH_OVER_GAUGE_RANGE
    if not lo <= l / B <= hi:
        log.warning("%s: contact_length_m / track_gauge_m = %.3g is outside [%g, %g] (crawlers: about 0.9-1.8); "
                    "the run goes on", where, l / B, lo, hi)


def bekker_k_eq(soil: dict, track_width_m: float) -> float:
    """Bekker's modulus of p = k z^n for a track of ``track_width_m``: k_eq = k_c / b + k_phi [N/m^(n+2)]."""
    return float(soil["k_c_N_per_m_n1"]) / float(track_width_m) + float(soil["k_phi_N_per_m_n2"])


def _bekker(vehicle: dict, soil: dict, elastic: bool = True) -> tuple[float, float, float] | None:
    """(n, k_eq, K_e) of ``soil`` under the vehicle's tracks (K_e nan when ``elastic`` is false), or None for a
    soil without these values or with one not positive."""
    keys = ("bekker_n", "k_c_N_per_m_n1", "k_phi_N_per_m_n2") + (("elastic_stiffness_Pa_per_m",) if elastic else ())
    if not all(k in soil for k in keys):
        return None
    n, k_eq = float(soil["bekker_n"]), bekker_k_eq(soil, vehicle["track_width_m"])
    k_e = float(soil["elastic_stiffness_Pa_per_m"]) if elastic else math.nan
    return None if n <= 0 or k_eq <= 0 or (elastic and k_e <= 0) else (n, k_eq, k_e)


def _log_static_sinkage(p: float, n: float, k_eq: float) -> float:
    """ln z of the static sinkage z = (p / k_eq)^(1/n), in logarithms (z underflows for n = 0.1 and a light
    crawler)."""
    return (math.log(p) - math.log(k_eq)) / n


def bekker_stiffness_ratio(vehicle: dict, soil: dict) -> float | None:
    """Bekker's loading stiffness n p / z at the static sinkage z = (p / k_eq)^(1/n) of the mean ground pressure
    p, over the soil's elastic (unloading/reloading) stiffness K_e; None for a soil without these values."""
    b, p = _bekker(vehicle, soil), mean_ground_pressure_Pa(vehicle)
    if b is None or p <= 0:
        return None
    n, k_eq, k_e = b
    return math.exp(math.log(n * p) - _log_static_sinkage(p, n, k_eq) - math.log(k_e))


def bekker_pressure_limit_Pa(vehicle: dict, soil: dict,
                             ratio_max: float = BEKKER_STIFFNESS_OVER_ELASTIC_MAX) -> tuple[float, float]:
    """(lowest, highest) mean ground pressure [Pa] that :func:`check_soil_contact` accepts for ``soil`` and the
    vehicle's track width (0 and inf where it bounds none): n p^(1 - 1/n) k_eq^(1/n) = ``ratio_max`` x K_e
    (default the rule's limit)."""
    b = _bekker(vehicle, soil)
    if b is None or b[0] == 1:
        return 0.0, math.inf
    n, k_eq, k_e = b
    log_p = (math.log(ratio_max * k_e) - math.log(n) - math.log(k_eq) / n) / (1 - 1 / n)
    p = math.inf if log_p > 700 else math.exp(max(log_p, -700.0))  # (n near 1: the bound is far or none)
    return (p, math.inf) if n < 1 else (0.0, p)


def check_soil_contact(vehicle: dict, soil: dict, where: str = "soil") -> None:
    """Refuse (ParameterError) a vehicle and soil whose static sinkage is where Bekker's law is stiffer than the
    soil's elastic stiffness (:data:`BEKKER_STIFFNESS_OVER_ELASTIC_MAX`)."""
    ratio = bekker_stiffness_ratio(vehicle, soil)
    if ratio is None or ratio <= BEKKER_STIFFNESS_OVER_ELASTIC_MAX:
        return
    n, k_eq, k_e = _bekker(vehicle, soil)
    p = mean_ground_pressure_Pa(vehicle)
    z_log10 = _log_static_sinkage(p, n, k_eq) / math.log(10)
    lo, hi = bekker_pressure_limit_Pa(vehicle, soil)
    bound = ""
    if n != 1:
        p_lim = lo if n < 1 else hi
        bound = (f"; a mean ground pressure {'above' if n < 1 else 'below'} {p_lim / 1e3:.3g} kPa (mass_kg, "
                 f"track_width_m, contact_length_m) or a soil with a larger {where}.bekker_n would be inside")
    raise ParameterError(
        f"{where}: Bekker's loading stiffness n p / z = {ratio * k_e:.3g} Pa/m at the static sinkage z = (p / k)^(1/n) "
        f"= {10 ** z_log10:.3g} m of the mean ground pressure p = {p / 1e3:.3g} kPa ({where}.bekker_n = {n:g}) is "
        f"outside the allowed range (0, {BEKKER_STIFFNESS_OVER_ELASTIC_MAX:g} x {where}.elastic_stiffness_Pa_per_m "
        f"= {BEKKER_STIFFNESS_OVER_ELASTIC_MAX * k_e:.3g}] Pa/m: the pressure-sinkage law is used far below the "
        f"sinkages its plate tests measured, where it is stiffer than the soil's elastic reloading (no soil "
        f"loads plastically stiffer than it reloads elastically){bound}")


def leaning_sinkage_limit_m(vehicle: dict, soil: dict) -> float | None:
    """The static sinkage [m] above which a rigid-hulled crawler leans over on its soil (:func:`check_leaning`):
    n min(l^2 / 12, B^2 / 4) / h; None for a soil without a Bekker n."""
    if "bekker_n" not in soil:
        return None
    n, h = float(soil["bekker_n"]), float(vehicle["cg_height_m"])
    l, B = float(vehicle["contact_length_m"]), float(vehicle["track_gauge_m"])
    return n * min(l * l / 12, B * B / 4) / h if h > 0 else None


def check_leaning(vehicle: dict, soil: dict, where: str = "soil") -> None:
    """Refuse (ParameterError) a 3D vehicle that leans over at rest on its soil (:data:`LEANING_MARGIN`)."""
    limit, b = leaning_sinkage_limit_m(vehicle, soil), _bekker(vehicle, soil, elastic=False)
    if limit is None or b is None:
        return
    n, k_eq, _ = b
    p = mean_ground_pressure_Pa(vehicle)
    z_log = _log_static_sinkage(p, n, k_eq)
    if z_log <= math.log(limit / LEANING_MARGIN):
        return
    raise ParameterError(
        f"{where}: the static sinkage z = (p / k)^(1/n) = {math.exp(z_log):.3g} m of the mean ground pressure "
        f"p = {p / 1e3:.3g} kPa ({where}.bekker_n = {n:g}) is outside the allowed range [0, {limit:.3g}] m = n "
        f"min(l^2 / 12, B^2 / 4) / h (vehicle.contact_length_m, track_gauge_m, cg_height_m): the tracks' rotational "
        f"stiffness on the soil, Bekker's n p / z times b l^3 / 6 (pitch) or b l B^2 / 2 (roll), is below the "
        f"weight's overturning moment W h per radian, and the 3D vehicle leans over at rest (the leaning "
        f"instability of a tall structure on soft soil, Hambly 1985); a lighter or lower vehicle, a longer "
        f"contact or a wider gauge would be inside")


def check_torque(vehicle: dict, torque_max_N_m: float, where: str = "torque") -> None:
    """Warn (one log line) when commanded torques of ``torque_max_N_m`` on both sprockets push more
    than :data:`TRACTION_OVER_WEIGHT_MAX` times the vehicle's weight."""
    ratio = 2 * abs(torque_max_N_m) / float(vehicle["sprocket_radius_m"]) / (float(vehicle["mass_kg"]) * GRAVITY_M_S2)
    if ratio > TRACTION_OVER_WEIGHT_MAX:
        log.warning("%s: the largest torque %g N m on both sprockets pushes 2 T / r = %.3g x the weight m g "
                    "(allowed up to %g; mass_kg = %g is in kg, torques in N m); the run goes on",
                    where, torque_max_N_m, ratio, TRACTION_OVER_WEIGHT_MAX, float(vehicle["mass_kg"]))


def check_tread_speed(tread_m_s: float, t_s: float) -> None:
    """Stop (ImplausibleRunError, quantity "tread_speed") a run whose track tread runs faster than
    :data:`MAX_TREAD_SPEED_M_S` (r |omega| of a sprocket: the tracks spin, a torque far above what the soil
    carries, faster than any drive turns them)."""
    if tread_m_s > MAX_TREAD_SPEED_M_S:
        raise ImplausibleRunError(
            f"tread speed = {tread_m_s:.4g} m/s (sprocket_radius_m x |omega|) at t = {t_s:.3f} s is outside the "
            f"allowed range [0, {MAX_TREAD_SPEED_M_S:g}] m/s (the tracks spin: the torque exceeds what the soil "
            f"carries, and no crawler's drive turns its tracks that fast; the model's torque has no power limit: "
            f"lower the torques, which are in N m)", "tread_speed")


def is_sinkage_name(name: str) -> bool:
    """A track end's sinkage [m] among a model's state or output names (not its rate)."""
    return name.startswith("sinkage_") and name.endswith("_m") and "rate" not in name


def sinkage_columns(state_names, output_names) -> tuple[str, list[int]]:
    """Where a model's track-end sinkages [m] are: ("x", their indices among the states), or, where none is a
    state (the 3D hull's contact: its track ends' penetrations are outputs), ("y", their indices among the
    outputs); an empty list where the model has none."""
    isk = [k for k, n in enumerate(state_names) if is_sinkage_name(n)]
    if isk:
        return "x", isk
    return "y", [k for k, n in enumerate(output_names) if is_sinkage_name(n)]


def check_sinkage(sinkage_m: float, cg_height_m: float, t_s: float) -> None:
    """Stop (ImplausibleRunError, quantity "sinkage") a run whose track sinks deeper than
    :data:`SINKAGE_OVER_CG_HEIGHT_MAX` times the CG height (the hull in the soil: the model has no hull contact)."""
    limit = SINKAGE_OVER_CG_HEIGHT_MAX * cg_height_m
    if cg_height_m > 0 and sinkage_m > limit:
        raise ImplausibleRunError(
            f"sinkage = {sinkage_m:.4g} m at t = {t_s:.3f} s is outside the allowed range [0, {limit:.4g}] m (deeper "
            f"than the CG height vehicle.cg_height_m = {cg_height_m:g} m: the hull would be in the soil, which the "
            f"model does not carry; check the soil's Bekker values and the vehicle's mass)", "sinkage")


def tipping_angles_rad(params: dict) -> tuple[float, float, float]:
    """The vehicle's static tipping angles [rad] (:func:`check_tilt`): nose up (the CG over the rear track end),
    nose down (over the front end) and sideways (over a track's outer edge)."""
    l, e, h = (float(params[k]) for k in ("contact_length_m", "cg_ahead_of_contact_centre_m", "cg_height_m"))
    B, b = float(params["track_gauge_m"]), float(params["track_width_m"])
    return math.atan2(l / 2 + e, h), math.atan2(l / 2 - e, h), math.atan2((B + b) / 2, h)


def tilt_over_tipping(pitch_rad, roll_rad, params: dict):
    """The hull's tilt over its tipping angle (:func:`tipping_angles_rad`): above 1 the CG is beyond the
    tracks' footprint (elementwise for arrays)."""
    up, down, side = tipping_angles_rad(params)
    pitch = np.asarray(pitch_rad, dtype=float)
    return np.maximum(np.where(pitch > 0, pitch / up, -pitch / down), np.abs(np.asarray(roll_rad, dtype=float)) / side)


def check_tilt(pitch_rad: float, roll_rad: float, params: dict, t_s: float) -> None:
    """Stop (ImplausibleRunError, quantity "tilt") a 3D run whose hull has turned over: pitched or rolled (from
    the horizontal) beyond its static tipping angle, the CG beyond the tracks' footprint (a track end or
    outer edge); the model's contact has no hull, so that what follows is outside it."""
    if float(tilt_over_tipping(pitch_rad, roll_rad, params)) > 1.0:
        up, down, side = (math.degrees(a) for a in tipping_angles_rad(params))
        raise ImplausibleRunError(
            f"pitch = {math.degrees(pitch_rad):.4g} deg, roll = {math.degrees(roll_rad):.4g} deg at t = {t_s:.3f} s "
            f"are outside the allowed range (pitch in [-{down:.3g}, {up:.3g}] deg, roll in [-{side:.3g}, {side:.3g}] "
            f"deg: the vehicle's static tipping angles, atan of the CG's distance to a track end or outer edge "
            f"over vehicle.cg_height_m): the vehicle has turned over, and the model's contact has no hull", "tilt")


def check_speed(speed_m_s: float, t_s: float) -> None:
    """Stop (ImplausibleRunError, quantity "speed") a run whose speed exceeds :data:`MAX_SPEED_M_S`."""
    if speed_m_s > MAX_SPEED_M_S:
        raise ImplausibleRunError(
            f"speed = {speed_m_s:.4g} m/s ({3.6 * speed_m_s:.4g} km/h) at t = {t_s:.3f} s is outside the allowed range "
            f"[0, {MAX_SPEED_M_S:g}] m/s (faster than any crawler: check that vehicle.mass_kg is in kg and the "
            f"torques in N m)", "speed")
