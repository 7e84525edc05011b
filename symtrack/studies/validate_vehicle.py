"""The vehicle's models of the validation gallery (docs/validation.md): a track's tractive
performance in straight running against slip, its motion resistance, and the turning resistance of
the crawler in steady turns. Each is a model of :data:`symtrack.studies.validate.MODELS`: it takes
a case's setup, its assumptions' values and the measured points' x, and returns the prediction in
the measured unit.

The track's forces are the package's own (:mod:`symtrack.vehicles.planar`): the tractive force of the
default lateral law (``shear_forces``, no lateral sliding, the steady shear displacement
j = i l / 2, so Ferretti & Girelli's tractive effort with the Janosi-Hanamoto shear law), Wong's
internal resistance of the running gear (``internal_resistance_N``) and Bekker's compaction
resistance of the soil law (``compaction_work`` at the static sinkage of the mean pressure). The
turns are the trim points of :func:`symtrack.control.trim.trim`.

**The soil from a cone index (reconstruction).** The traction cases give the soil by its cone index
only; no published relation from a cone index to Janosi-Hanamoto's c, phi, K and Bekker's k, n was
retrieved (docs/validation.md, "Measured data not yet cases, and what could not be retrieved").
:func:`cone_index_soil` reads the cone index instead as two things a cone measures, each with its
assumptions:

- the **bearing capacity** of the cone: CI = s (c N_c + sigma_v N_q), the bearing-capacity
  equation (Terzaghi 1943) with Prandtl's (1921) and Reissner's (1924) closed-form factors of a strip
  footing, N_q = e^(pi tan phi) tan^2(45 deg + phi/2), N_c = (N_q - 1) cot phi; s a multiplier for
  the cone's shape and depth over the strip footing and sigma_v the overburden where the index is
  read; with phi assumed from the texture, this gives c (at least 0);
- a **point of the pressure-sinkage curve**: Bekker's k_eq z^n passes through the cone index at a
  sinkage z_CI, k_eq = CI / z_CI^n, n assumed.

K is Wong's guidance for the soil's kind, an assumption with its range.
"""

from __future__ import annotations

import functools
import math

import casadi as ca
import numpy as np

from ..control.trim import TrimError, trim
from ..foundations import caches
from ..model import ModelOptions, SystemModel
from ..presets import soil_preset, vehicle_preset
from ..presets.soils import UNLOADING_STIFFNESS_FLOOR, WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M
from ..region.fleet import plastic_rut_m
from ..soil import law as soil_laws
from ..vehicles import planar as veh
from ..vehicles import tyre

__all__ = ["REFINE_POINTS", "TRACTION_SLIPS", "combine_rut_depth", "cone_index_sinkage_law", "cone_index_soil",
           "density_table_soil", "rated_tyre", "sinkage_m", "steady_turn_resistance_ratio",
           "straight_track_performance", "track_motion_resistance", "track_traction_at_max_efficiency",
           "track_traction_at_slip", "track_unit_sinkage", "turning_resistance_coefficient"]

KPA = 1e3
# the slips (travel reductions) of the steady sweep, geometric; the maximum of the tractive efficiency is
# then refined on REFINE_POINTS equal steps between the neighbours of the sweep's best slip
TRACTION_SLIPS = np.geomspace(0.002, 0.45, 160)
REFINE_POINTS = 81
# the sprocket radius of the straight-track function: only the tread speed r omega enters the forces
_SPROCKET_RADIUS_M = 0.1
_QUANTITIES = ("tractive_efficiency_pct", "travel_reduction", "net_traction_ratio")


@functools.lru_cache(maxsize=1)
def _straight_track() -> ca.Function:
    """(slip, speed, N, b, l, c, phi, K, c0, c1) -> (F, R_in) of one track running straight at a
    steady slip: the package's tractive force (``shear_forces`` of the default lateral law, no lateral
    sliding, j = i l / 2) and its internal resistance (``internal_resistance_N``)."""
    opts = ModelOptions()
    names = ("slip", "speed", "N", "b", "l", "c", "phi", "K", "c0", "c1")
    s = {k: ca.SX.sym(k) for k in names}
    r = _SPROCKET_RADIUS_M
    omega = s["speed"] / ((1 - s["slip"]) * r)
    abs_om = veh.sprocket_speed_abs(omega, opts)
    dist = veh.PressureDistribution(s["N"], 0.0, s["b"], s["l"])
    F, _, _ = veh.shear_forces(s["slip"] * s["l"] / 2, omega, abs_om, s["speed"], 0.0, 0.0, s["l"] / 2, dist, s["N"],
                               s["b"], s["l"], r, s["c"], s["phi"], s["K"], opts)
    R_in = veh.internal_resistance_N(s["N"], omega, abs_om, r, {"internal_resistance_const": s["c0"],
                                                                "internal_resistance_per_km_h": s["c1"]}, opts)
    return ca.Function("straight_track", [s[k] for k in names], [F, R_in])


@functools.lru_cache(maxsize=8)
def _straight_track_map(n: int) -> ca.Function:
    """:func:`_straight_track` mapped over n slips (the other inputs shared)."""
    return _straight_track().map(n)


def _track_forces(slips, *args) -> tuple[np.ndarray, np.ndarray]:
    """(F, R_in) [N] at each slip of the 1-D array ``slips``; args as :func:`_straight_track`'s after the slip."""
    slips = np.atleast_1d(np.asarray(slips, dtype=float))
    F, R_in = _straight_track_map(slips.size)(slips[None, :], *(float(v) for v in args))
    return np.asarray(F).ravel(), np.asarray(R_in).ravel()


def cone_index_soil(a: dict, cone_index_kPa: float, setup: dict | None = None) -> dict:
    """The soil of a cone index (module doc): cohesion_Pa, friction_angle_rad, shear_modulus_K_m,
    bekker_n and k_eq (Bekker's k_c / b + k_phi together, N/m^(n+2)), from the assumptions
    ``friction_angle_deg``, ``cone_factor_multiplier``, ``overburden_kPa``, ``shear_modulus_K_m``,
    ``bekker_n`` and ``cone_index_sinkage_m``. With ``setup["strength_relation"] = "fixed"`` (a case's
    alternative) c and phi are instead the setup's ``fixed_cohesion_kPa`` and ``fixed_friction_angle_deg``,
    whatever the cone index."""
    if setup is not None and setup.get("strength_relation", "cone_bearing") == "fixed":
        return {"cohesion_Pa": float(setup["fixed_cohesion_kPa"]) * KPA,
                "friction_angle_rad": math.radians(float(setup["fixed_friction_angle_deg"])),
                "shear_modulus_K_m": float(a["shear_modulus_K_m"]), **cone_index_sinkage_law(a, cone_index_kPa)}
    phi = math.radians(float(a["friction_angle_deg"]))
    tan_phi = math.tan(phi)
    n_q = math.exp(math.pi * tan_phi) * math.tan(math.pi / 4 + phi / 2) ** 2
    n_c = (n_q - 1.0) / tan_phi
    ci_Pa = float(cone_index_kPa) * KPA
    c_Pa = max(0.0, (ci_Pa / float(a["cone_factor_multiplier"]) - float(a["overburden_kPa"]) * KPA * n_q) / n_c)
    return {"cohesion_Pa": c_Pa, "friction_angle_rad": phi, "shear_modulus_K_m": float(a["shear_modulus_K_m"]),
            **cone_index_sinkage_law(a, cone_index_kPa)}


def cone_index_sinkage_law(a: dict, cone_index_kPa: float) -> dict:
    """Bekker's n (``a["bekker_n"]``) and k_eq = CI / z_CI^n (z_CI = ``a["cone_index_sinkage_m"]``):
    the pressure-sinkage curve through the cone index at the sinkage z_CI (module doc)."""
    n = float(a["bekker_n"])
    return {"bekker_n": n, "k_eq": float(cone_index_kPa) * KPA / float(a["cone_index_sinkage_m"]) ** n}


def _compaction_N(soil: dict, load_N: float, width_m: float, length_m: float) -> tuple[float, float]:
    """(sinkage [m], compaction resistance [N]) of a track of load_N at uniform pressure on virgin
    soil: the soil law's static sinkage of the mean pressure and its work per metre to press that rut."""
    law = soil_laws.make(ModelOptions())
    vec = [soil["k_eq"], soil["bekker_n"]]
    z = float(law.static_sinkage(load_N / (width_m * length_m), vec))
    return z, float(law.compaction_work(z, vec, width_m))


def straight_track_performance(setup: dict, a: dict, cone_index_kPa: float, slips=TRACTION_SLIPS) -> dict:
    """One track running straight at each slip (travel reduction) on the soil of the cone index: the
    gross traction ratio (sprocket torque / (r N): tractive force plus internal resistance, as the
    sprocket's steady equation gives it), the net traction ratio ((tractive force - compaction
    resistance) / N, the pull of the body's steady equation) and the tractive efficiency
    NTR / GTR (1 - slip), with the soil's sinkage."""
    soil = cone_index_soil(a, cone_index_kPa, setup)
    N, b, l = float(a["normal_load_N"]), float(setup["track_width_m"]), float(setup["contact_length_m"])
    F, R_in = _track_forces(slips, float(a["speed_m_s"]), N, b, l, soil["cohesion_Pa"], soil["friction_angle_rad"],
                            soil["shear_modulus_K_m"], float(setup["internal_resistance_const"]),
                            float(setup["internal_resistance_per_km_h"]))
    z, R_c = _compaction_N(soil, N, b, l)
    ntr = (F - R_c) / N
    gtr = (F + R_in) / N
    return {"slip": np.asarray(slips, dtype=float), "net_traction_ratio": ntr, "gross_traction_ratio": gtr,
            "tractive_efficiency": ntr / gtr * (1 - np.asarray(slips, dtype=float)), "sinkage_m": z, "soil": soil}


def track_traction_at_max_efficiency(setup: dict, a: dict, cone_indices_kPa) -> np.ndarray:
    """At the largest tractive efficiency of the slip sweep (:func:`straight_track_performance`), for
    each cone index: ``setup["quantity_at_max"]`` = "tractive_efficiency_pct" (that efficiency, %),
    "travel_reduction" (the slip there) or "net_traction_ratio" (the net traction ratio there)."""
    what = setup["quantity_at_max"]
    if what not in _QUANTITIES:
        raise ValueError(f"quantity_at_max = {what!r} is not one of {_QUANTITIES}")
    out = []
    for ci in np.atleast_1d(np.asarray(cone_indices_kPa, dtype=float)):
        perf = straight_track_performance(setup, a, float(ci))
        k = int(np.argmax(perf["tractive_efficiency"]))
        lo, hi = TRACTION_SLIPS[max(k - 1, 0)], TRACTION_SLIPS[min(k + 1, TRACTION_SLIPS.size - 1)]
        perf = straight_track_performance(setup, a, float(ci), np.linspace(lo, hi, REFINE_POINTS))
        k = int(np.argmax(perf["tractive_efficiency"]))
        out.append({"tractive_efficiency_pct": 100.0 * perf["tractive_efficiency"][k],
                    "travel_reduction": perf["slip"][k], "net_traction_ratio": perf["net_traction_ratio"][k]}[what])
    return np.array(out, dtype=float)


def track_traction_at_slip(setup: dict, a: dict, points) -> np.ndarray:
    """At the measured points 1, 2, ... (categories): ``setup["quantity_at_slip"]`` =
    "tractive_efficiency_pct" or "net_traction_ratio" of the slip sweep
    (:func:`straight_track_performance`) at the travel reduction ``setup["travel_reduction"][k - 1]``
    on the soil of the cone index ``setup["cone_index_kPa"][k - 1]``."""
    what = setup["quantity_at_slip"]
    if what not in ("tractive_efficiency_pct", "net_traction_ratio"):
        raise ValueError(f"quantity_at_slip = {what!r} is not tractive_efficiency_pct or net_traction_ratio")
    out = []
    for k in np.atleast_1d(points):
        i = int(round(float(k))) - 1
        perf = straight_track_performance(setup, a, float(setup["cone_index_kPa"][i]),
                                          [float(setup["travel_reduction"][i])])
        out.append(100.0 * perf["tractive_efficiency"][0] if what == "tractive_efficiency_pct"
                   else perf["net_traction_ratio"][0])
    return np.array(out, dtype=float)


def track_motion_resistance(setup: dict, a: dict, cone_indices_kPa) -> np.ndarray:
    """The motion resistance of a machine towed on its tracks [% of its weight]: per track, the
    compaction resistance (Bekker's rut at the static sinkage of the mean pressure) plus the running
    gear's internal resistance at the towing speed (Wong), on the soil of each cone index; the weight
    ``setup["weight_N"]`` shared by ``setup["tracks"]`` equal tracks."""
    weight = float(setup["weight_N"])
    N = weight / int(setup["tracks"])
    b, l = float(a["track_width_m"]), float(a["contact_length_m"])
    out = []
    for ci in np.atleast_1d(np.asarray(cone_indices_kPa, dtype=float)):
        _, R_c = _compaction_N(cone_index_sinkage_law(a, float(ci)), N, b, l)
        # the internal resistance at the towing speed (the soil's strength does not enter it)
        _, R_in = _track_forces(0.0, float(a["speed_m_s"]), N, b, l, 0.0, 0.5, 0.01,
                                float(setup["internal_resistance_const"]), float(setup["internal_resistance_per_km_h"]))
        out.append(100.0 * (R_c + float(R_in[0])) / N)
    return np.array(out, dtype=float)


# ---------------------------------------------------------------------------------------------
# sinkage and ruts: the soil law's static sinkage (or the rut its unloading leaves) under a track or a tyre

def density_table_soil(setup: dict, density_Mg_per_m3: float, k_reading: str) -> dict:
    """The soil law's parameters (a soil preset's keys) of a soil given as Bekker's n and k by initial dry
    density (the case's ``setup["table_density_Mg_per_m3"]``, ``table_n``, ``table_k``; n and k linear in
    the density between the rows, the end rows beyond them). ``k_reading``: ``"k_eq"`` reads k as Bekker's
    combined modulus k_eq in kN/m^(n+2) (k_phi, k_c = 0), ``"k_c"`` as the cohesive modulus k_c in
    kN/m^(n+1) (k_eq = k_c / b at the contact's width b). The unloading line: the package's values for soils
    without a measured one (:data:`symtrack.presets.soils.WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M`, the floor
    :data:`~symtrack.presets.soils.UNLOADING_STIFFNESS_FLOOR`)."""
    rho = [float(v) for v in setup["table_density_Mg_per_m3"]]
    n = float(np.interp(float(density_Mg_per_m3), rho, [float(v) for v in setup["table_n"]]))
    k = float(np.interp(float(density_Mg_per_m3), rho, [float(v) for v in setup["table_k"]])) * KPA
    if k_reading not in ("k_eq", "k_c"):
        raise ValueError(f"k_reading = {k_reading!r} is not k_eq or k_c")
    return {"bekker_n": n, "k_c_N_per_m_n1": k if k_reading == "k_c" else 0.0,
            "k_phi_N_per_m_n2": k if k_reading == "k_eq" else 0.0,
            "elastic_stiffness_Pa_per_m": WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M,
            "unloading_stiffness_floor": UNLOADING_STIFFNESS_FLOOR}


def sinkage_m(soil: dict, pressure_Pa: float, width_m: float, measured_as: str) -> float:
    """The soil law's response to a contact of ``width_m`` at the mean pressure ``pressure_Pa`` on virgin
    soil: ``measured_as`` = "under_load", the static sinkage (the law's inverse, ``static_sinkage``, at
    k_eq = k_c / b + k_phi), or "rut_after_unloading", the plastic rut its elastic unloading leaves
    (:func:`symtrack.region.fleet.plastic_rut_m`)."""
    if measured_as == "rut_after_unloading":
        return plastic_rut_m(pressure_Pa, soil, width_m)
    if measured_as != "under_load":
        raise ValueError(f"measured_as = {measured_as!r} is not under_load or rut_after_unloading")
    law = soil_laws.make(ModelOptions())
    return float(law.static_sinkage(float(pressure_Pa), law.values({**soil, "track_width_m": float(width_m)})))


def track_unit_sinkage(setup: dict, a: dict, points) -> np.ndarray:
    """The sinkage [mm] of each track unit ``setup["units"][k - 1]`` at the measured points 1, 2, ...: a
    rigid track of ``a["<unit>_contact_length_m"]`` x ``a["<unit>_track_width_m"]`` carrying
    ``setup["load_kN"]`` at uniform pressure (the package's track at rest, no moment) on the soil of the
    density table (:func:`density_table_soil` at ``a["bulk_density_initial_Mg_per_m3"]``, k read as
    ``a["k_reading"]``), :func:`sinkage_m` as ``a["sinkage_as"]``."""
    soil = density_table_soil(setup, float(a["bulk_density_initial_Mg_per_m3"]), str(a["k_reading"]))
    out = []
    for k in np.atleast_1d(points):
        unit = setup["units"][int(round(float(k))) - 1]
        l_m, b_m = float(a[f"{unit}_contact_length_m"]), float(a[f"{unit}_track_width_m"])
        p = float(setup["load_kN"]) * KPA / (l_m * b_m)
        out.append(1e3 * sinkage_m(soil, p, b_m, str(a["sinkage_as"])))
    return np.array(out, dtype=float)


def rated_tyre(width_m: float, diameter_m: float, wheel_load_kN: float, inflation_kPa: float,
               recommended_kPa: float) -> tyre.Tyre:
    """A tyre of the given size rated so that ``recommended_kPa`` is its recommended pressure at the wheel load
    by the package's inflation rule p = p_max (W / W_max)^1.25 (:mod:`symtrack.vehicles.tyre`), its rated
    pressure the larger of that and the inflation pressure (the tyre must carry the load at it)."""
    p_max = max(float(inflation_kPa), float(recommended_kPa))
    w_max = float(wheel_load_kN) * (p_max / float(recommended_kPa)) ** (1.0 / tyre.INFLATION_RULE_EXPONENT)
    return tyre.Tyre(float(width_m), float(diameter_m), w_max, p_max)


def _field_soil(setup: dict, a: dict, field: str) -> dict:
    """The soil law's parameters of one field of :func:`combine_rut_depth`."""
    if field == "clay":
        return soil_preset(str(a["clay_soil"]))
    if str(a["sandy_loam_soil"]) != "density_table":
        return soil_preset(str(a["sandy_loam_soil"]))
    return density_table_soil(setup, float(a[f"{field}_density_Mg_per_m3"]), str(a["k_reading"]))


def combine_rut_depth(setup: dict, a: dict, points) -> np.ndarray:
    """The rut depth [mm] of a combine harvester's front tyre or track at the measured points 1, 2, ...
    (field ``setup["fields"][k - 1]``, machine ``setup["machines"][k - 1]``): :func:`sinkage_m` (as
    ``a["sinkage_as"]``) of the mean pressure of the contact, on the field's soil (the sandy loams: the
    density table at ``a["<field>_density_Mg_per_m3"]`` or the preset ``a["sandy_loam_soil"]``; the clay: the
    preset ``a["clay_soil"]``). The track (machine "track"): a rigid track of ``a["track_contact_length_m"]`` x
    ``a["track_width_m"]`` carrying ``a["track_unit_load_kN"]`` at uniform pressure. The tyre ("tyre" at
    ``setup["inflation_kPa"]``, "tyre_high" at ``setup["high_inflation_kPa"]``): Keller's (2005) contact
    (:func:`symtrack.vehicles.tyre.contact`) of a ``a["tyre_width_m"]`` x ``a["tyre_diameter_m"]`` tyre
    (:func:`rated_tyre`, recommended pressure ``a["recommended_inflation_kPa"]``) at ``a["wheel_load_kN"]``,
    its mean pressure the load over Keller's contact area, the soil's k_eq at the tyre's width. The rear
    wheels that follow are not in it."""
    out = []
    for k in np.atleast_1d(points):
        i = int(round(float(k))) - 1
        field, machine = str(setup["fields"][i]), str(setup["machines"][i])
        soil = _field_soil(setup, a, field)
        if machine == "track":
            b_m = float(a["track_width_m"])
            p = float(a["track_unit_load_kN"]) * KPA / (float(a["track_contact_length_m"]) * b_m)
        elif machine in ("tyre", "tyre_high"):
            p_i = float(setup["inflation_kPa" if machine == "tyre" else "high_inflation_kPa"])
            W = float(a["wheel_load_kN"])
            t = rated_tyre(a["tyre_width_m"], a["tyre_diameter_m"], W, p_i, a["recommended_inflation_kPa"])
            c = tyre.contact(t, W, p_i)
            b_m, p = t.width_m, W * KPA / c.area_m2
        else:
            raise ValueError(f"machine = {machine!r} is not track, tyre or tyre_high")
        out.append(1e3 * sinkage_m(soil, p, b_m, str(a["sinkage_as"])))
    return np.array(out, dtype=float)


@functools.lru_cache(maxsize=4)
def _turn_model(law: str) -> SystemModel:
    return SystemModel(ModelOptions(lateral_law=law))


@functools.lru_cache(maxsize=512)
def turning_resistance_coefficient(vehicle: str, soil: str, law: str, K_m: float, speed_m_s: float,
                                   radius_over_gauge: float) -> float:
    """Wong's coefficient of lateral resistance of a steady turn, mu_t = 4 M_r / (W l), with the
    turning resistance moment M_r = (B/2) ((F - R_c)_outer - (F - R_c)_inner) that the tracks'
    thrusts balance in the steady turn (the package's trim point, :func:`symtrack.control.trim.trim`)
    at radius R = radius_over_gauge B and speed_m_s, on the soil preset with its K replaced by K_m.
    NaN where no steady turn exists."""
    params = {**vehicle_preset(vehicle), **soil_preset(soil), "shear_modulus_K_m": float(K_m)}
    gauge = params["track_gauge_m"]
    try:
        tp = trim(_turn_model(law), params, float(speed_m_s), float(radius_over_gauge) * gauge)
    except TrimError:
        return math.nan
    y = tp.outputs
    net = {k: float(y[f"tractive_{k}_N"]) - float(y[f"compaction_resistance_{k}_N"]) for k in veh.TRACKS}
    moment = 0.5 * gauge * (net["right"] - net["left"])  # a left turn: the right track is the outer one
    weight = params["mass_kg"] * veh.GRAVITY_M_S2
    return 4.0 * moment / (weight * params["contact_length_m"])


def steady_turn_resistance_ratio(setup: dict, a: dict, radii_over_gauge) -> np.ndarray:
    """The coefficient of lateral resistance of a steady turn at each R/B relative to that at
    R/B = ``setup["reference_radius_over_gauge"]`` (:func:`turning_resistance_coefficient`; the vehicle
    ``setup["vehicle"]``, the soil ``setup["soil"]``, the lateral law ``setup["lateral_law"]``)."""
    key = (str(setup["vehicle"]), str(setup["soil"]), str(setup["lateral_law"]), float(a["shear_modulus_K_m"]),
           float(a["speed_m_s"]))
    ref = turning_resistance_coefficient(*key, float(setup["reference_radius_over_gauge"]))
    return np.array([turning_resistance_coefficient(*key, float(x)) / ref
                     for x in np.atleast_1d(np.asarray(radii_over_gauge, dtype=float))])


# bounded by their maxsize; emptied by symtrack.clear_caches() (symtrack.foundations.caches)
caches.register_clear("validate_vehicle.straight_track", _straight_track)
caches.register_clear("validate_vehicle.straight_track_map", _straight_track_map)
caches.register_clear("validate_vehicle.turn_model", _turn_model)
caches.register_clear("validate_vehicle.turning_resistance_coefficient", turning_resistance_coefficient)
