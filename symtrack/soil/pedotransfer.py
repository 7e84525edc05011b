"""One soil description and the pedotransfer functions (PTFs) that derive the model's parameters
from it (docs/subsoil.md, "One soil").

A soil is described by what an agronomist knows:

- its texture, the mineral fractions ``clay_kg_per_kg``, ``silt_kg_per_kg``, ``sand_kg_per_kg``
  (mass fractions of the fine earth, summing to 1);
- its dry bulk density before any traffic, ``bulk_density_initial_Mg_per_m3``, and its particle
  density ``particle_density_Mg_per_m3``;
- its moisture as the matric suction ``matric_suction_kPa`` (or, on a day of a study, the
  ``[soil.moisture]`` water content: symtrack/soil/moisture.py).

From these, :func:`derive_soil` gives every compression and strength parameter that the parameter
set does not give itself (a value given always wins, except the virgin line's N, which is never an
input: it follows from the others):

================================  ==========================================================
``precompression_stress_Pa``      Schjønning & Lamandé (2018): bulk density, clay, suction
``compression_index_lambda``      Keller & Arvidsson (2007): the initial specific volume
``recompression_index_kappa``     Keller & Arvidsson (2007): one value for all their soils
``virgin_line_N``                 the one strength: the virgin line passes through the
                                  initial recompression line at the precompression stress,
                                  N = v0 + (lambda - kappa) ln(sigma_pc / kPa), v0 = rho_s / rho_b
``yield_compression_index_k2``    O'Sullivan & Robertson's yield line: k2 at the position
                                  between kappa and lambda of their published parameter set
================================  ==========================================================

So the density model yields exactly where the risk grades a stress as reaching the soil's
strength: one precompression stress, not two. Bekker's k_c, k_phi, n and Janosi's c, phi, K have
no pedotransfer function from texture, density and suction that this package adopts (the published
relations start from a cone index or a plate test): they stay measured inputs of each soil.

The stress that loads the soil at a depth is the traffic's vertical stress plus the soil's own
weight above that depth, :func:`geostatic_vertical_stress_Pa` (the moist bulk density: the dry
density plus the water the suction leaves in the pores, on the van Genuchten curve of Severiano et
al.'s clay class).
"""

from __future__ import annotations

import math

import numpy as np

from ..foundations.errors import ParameterError

__all__ = ["DESCRIPTION_KEYS", "GRAVITY_M_S2", "K2_POSITION_OSR", "LAYER_COMPRESSION_KEYS", "SEVERIANO_2013_CLASSES",
           "SUBSOIL_KEYS", "SUBSOIL_TOP_DEFAULT_M", "TEXTURE_KEYS", "TEXTURE_SUM_TOLERANCE", "clay_class",
           "derive_soil", "geostatic_profile_Pa", "geostatic_vertical_stress_Pa", "is_layered", "layer_sets",
           "subsoil_set",
           "keller_arvidsson_2007", "moist_bulk_density_Mg_per_m3", "precompression_from_virgin_line_kPa",
           "precompression_ptf_kPa", "severiano_2013_kPa", "suction_from_water_content_kPa",
           "schjonning_lamande_2018_kPa", "van_genuchten_water_content", "virgin_line_N_from_precompression"]

GRAVITY_M_S2 = 9.81
WATER_DENSITY_MG_PER_M3 = 1.0
TEXTURE_KEYS = ("clay_kg_per_kg", "silt_kg_per_kg", "sand_kg_per_kg")
DESCRIPTION_KEYS = TEXTURE_KEYS + ("matric_suction_kPa",)
# A soil of two layers: a topsoil to the tillage depth and the subsoil below it (SoilFlex, Keller et al.
# 2007, takes a profile of layers, each with its own compression properties; two is the profile an
# agronomist describes from a tilled field): the soil's description is the topsoil's; these keys describe
# the subsoil below ``subsoil_top_m``. Each is the topsoil's value unless given (then the soil is one layer).
SUBSOIL_KEYS = {"bulk_density_initial_Mg_per_m3": "subsoil_bulk_density_initial_Mg_per_m3",
                "clay_kg_per_kg": "subsoil_clay_kg_per_kg", "silt_kg_per_kg": "subsoil_silt_kg_per_kg",
                "sand_kg_per_kg": "subsoil_sand_kg_per_kg", "matric_suction_kPa": "subsoil_matric_suction_kPa"}
# the usual depth of primary tillage (mouldboard ploughing to 0.25-0.30 m): an assumption where a layered
# soil gives no depth of its own
SUBSOIL_TOP_DEFAULT_M = 0.3
# the parameters a layer derives from its own description (the layer's compression line and strength)
LAYER_COMPRESSION_KEYS = ("precompression_stress_Pa", "compression_index_lambda", "recompression_index_kappa",
                          "virgin_line_N", "yield_compression_index_k2")
# Schjønning & Lamandé's strength is taken where it carries the soil's own weight down to this depth
# (the deepest subsoil records are at 0.8 m); below that, Severiano et al.'s (precompression_ptf_kPa)
GEOSTATIC_CHECK_DEPTH_M = 1.0
# the suction of a soil whose water content is at the van Genuchten curve's saturation: 0.1 kPa (pF 0)
SUCTION_WET_KPA = 0.1
# the fractions are given to a few digits: a sum within 0.5 % of 1 is taken as 1
TEXTURE_SUM_TOLERANCE = 5e-3

# Keller & Arvidsson (2007), Eur. J. Soil Sci. 58, 1373-1381, as the soilphysics R package's
# compressive_properties2 codes it: N and lambda linear in the initial specific volume v, kappa one
# value for all their soils (uniaxial confined compression of structured Swedish and Danish soils)
KA2007_N = (-0.007, 1.196)
KA2007_LAMBDA = (-0.182, 0.212)
KA2007_KAPPA = 0.042

# Schjønning & Lamandé (2018), Geoderma 320, as soilphysics' soilStrength2 codes it:
# sqrt(sigma_pc / kPa) = c0 + c_rho rho_b + c_clay clay + c_clay_pF clay pF, pF = log10(h / hPa)
SL2018 = {"c0": -26.51, "c_rho": 25.57, "c_clay": -20.40, "c_clay_pF": 10.26}
# the inputs the PTF is used for here: the soils a crawler drives on (the paper's calibration range
# could not be read; docs/subsoil.md): pF 1 (field-wet) to 4.2 (wilting point), clay up to 0.6
SL2018_PF_RANGE = (1.0, 4.2)
SL2018_CLAY_RANGE = (0.0, 0.6)
SL2018_DENSITY_RANGE_MG_PER_M3 = (0.8, 2.0)

# O'Sullivan & Robertson's (1996) yield line: the one complete published parameter set found (the
# soilphysics R package's soilDeformation example: lambda 0.06037, kappa 0.00608, k2 0.01916, m 1.3)
# puts k2 at this fraction of the way from kappa to lambda; a soil without its own k2 takes the same
# position between its own kappa and lambda (an assumption, docs/subsoil.md "Repeated passes")
K2_POSITION_OSR = (0.01916 - 0.00608) / (0.06037 - 0.00608)

# Severiano et al. (2013) by clay class, as soilphysics' soilStrength (PredComp.R) codes it:
# (upper clay bound %, a, b of sigma_pc = a h^b, theta_s, theta_r, alpha [1/kPa], n) -- the van
# Genuchten curves give the water content at a suction (soil/moisture.py uses the whole rows)
SEVERIANO_2013_CLASSES = (
    (20.0, 129.0, 0.15, 0.42, 0.049356, 0.79, 1.72),
    (31.0, 123.3, 0.13, 0.45, 0.08689, 0.72, 1.56),
    (37.0, 85.0, 0.17, 0.46, 0.10696, 1.66, 1.52),
    (52.0, 70.1, 0.16, 0.50, 0.125941, 2.04, 1.47),
    (100.0, 62.7, 0.15, 0.51, 0.139358, 2.27, 1.38),
)


def _num(name, value, lo, hi, lo_open=False, why=""):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{name} = {value!r} is not a number")
    v = float(value)
    if not math.isfinite(v) or (v <= lo if lo_open else v < lo) or v > hi:
        lb = "(" if lo_open else "["
        raise ParameterError(f"{name} = {value!r} is outside the allowed range {lb}{lo:g}, {hi:g}]{why}")
    return v


def clay_class(clay_percent) -> int:
    """Severiano et al.'s clay class (0..4) of a clay content in %: < 20, 20-31, 31-37, 37-52, > 52."""
    c = _num("clay_percent", clay_percent, 0.0, 100.0, why=" (%)")
    if c < SEVERIANO_2013_CLASSES[0][0]:
        return 0
    for k, row in enumerate(SEVERIANO_2013_CLASSES[1:], start=1):
        if c <= row[0]:
            return k
    return len(SEVERIANO_2013_CLASSES) - 1


def keller_arvidsson_2007(particle_density_Mg_per_m3, bulk_density_Mg_per_m3) -> tuple[float, float, float]:
    """(N, lambda, kappa) of Keller & Arvidsson's (2007) pedotransfer function at the specific
    volume v = rho_s / rho_b: N = -0.007 + 1.196 v, lambda = -0.182 + 0.212 v, kappa = 0.042."""
    rho_s, rho_b = float(particle_density_Mg_per_m3), float(bulk_density_Mg_per_m3)
    if not (0.0 < rho_b < rho_s):
        raise ParameterError(f"bulk_density_Mg_per_m3 = {bulk_density_Mg_per_m3!r} must be in (0, "
                             f"particle_density_Mg_per_m3 = {rho_s!r})")
    v = rho_s / rho_b
    return KA2007_N[0] + KA2007_N[1] * v, KA2007_LAMBDA[0] + KA2007_LAMBDA[1] * v, KA2007_KAPPA


def schjonning_lamande_2018_kPa(bulk_density_Mg_per_m3, matric_suction_kPa, clay_kg_per_kg) -> float:
    """Precompression stress [kPa] of Schjønning & Lamandé (2018): (-26.51 + 25.57 rho_b - 20.40 clay
    + 10.26 clay pF)^2, pF = log10(suction / hPa). Refuses inputs outside the range it is used for and
    a soil for which it gives no strength (a negative bracket)."""
    rho = _num("bulk_density_initial_Mg_per_m3", bulk_density_Mg_per_m3, *SL2018_DENSITY_RANGE_MG_PER_M3,
               why=" (the bulk densities the Schjønning & Lamandé 2018 PTF is used for)")
    h = _num("matric_suction_kPa", matric_suction_kPa, 0.0, 1e6, lo_open=True)
    pf = math.log10(10.0 * h)
    if not SL2018_PF_RANGE[0] <= pf <= SL2018_PF_RANGE[1]:
        lo, hi = (10 ** p / 10.0 for p in SL2018_PF_RANGE)
        raise ParameterError(f"matric_suction_kPa = {matric_suction_kPa!r} is outside the allowed range [{lo:g}, "
                             f"{hi:g}] (pF {SL2018_PF_RANGE[0]}-{SL2018_PF_RANGE[1]}, the suctions the Schjønning & "
                             f"Lamandé 2018 PTF is used for); give precompression_stress_Pa instead")
    clay = _num("clay_kg_per_kg", clay_kg_per_kg, *SL2018_CLAY_RANGE, why=" (Schjønning & Lamandé 2018)")
    c = SL2018
    root = c["c0"] + c["c_rho"] * rho + c["c_clay"] * clay + c["c_clay_pF"] * clay * pf
    if not root > 1.0:
        raise ParameterError(f"the Schjønning & Lamandé 2018 PTF gives this soil no strength (bulk density {rho}, clay "
                             f"{clay}, pF {pf:.3g}: sqrt(sigma_pc / kPa) = {root:.3g}): give precompression_stress_Pa")
    return root * root


def severiano_2013_kPa(clay_kg_per_kg, matric_suction_kPa) -> float:
    """sigma_pc = a h^b [kPa] of Severiano et al. (2013) for the clay class, h the suction in kPa (> 0)."""
    _, a, b, *_ = SEVERIANO_2013_CLASSES[clay_class(100.0 * float(clay_kg_per_kg))]
    h = _num("matric_suction_kPa", matric_suction_kPa, 0.0, 1e6, lo_open=True)
    return a * h**b


def precompression_ptf_kPa(soil: dict) -> tuple[float, str]:
    """(sigma_pc [kPa], the PTF's name) of a described soil: Schjønning & Lamandé (2018), which knows
    the bulk density, where it applies (suction pF 1-4.2, clay up to 0.6) and gives the soil the
    strength to carry its own weight to GEOSTATIC_CHECK_DEPTH_M; else Severiano et al. (2013), a
    power law of the suction per clay class (fitted to wetter, clayey soils; no bulk density)."""
    rb, h, clay = soil["bulk_density_initial_Mg_per_m3"], soil["matric_suction_kPa"], soil["clay_kg_per_kg"]
    try:
        pc = schjonning_lamande_2018_kPa(rb, h, clay)
        if 1e3 * pc > float(geostatic_vertical_stress_Pa(soil, [GEOSTATIC_CHECK_DEPTH_M])[0]):
            return pc, "Schjønning & Lamandé (2018)"
    except ParameterError:
        pass
    return severiano_2013_kPa(clay, h), "Severiano et al. (2013)"


def suction_from_water_content_kPa(water_content_kg_per_kg, bulk_density_Mg_per_m3, clay_kg_per_kg) -> float:
    """Matric suction [kPa] of a gravimetric water content on the van Genuchten curve of Severiano et
    al.'s clay class (theta = w rho_b / rho_w). A water content at or above the curve's saturated one
    is taken at SUCTION_WET_KPA (the curve gives no suction there)."""
    _, _, _, ts, tr, alpha, n = SEVERIANO_2013_CLASSES[clay_class(100.0 * float(clay_kg_per_kg))]
    th = float(water_content_kg_per_kg) * float(bulk_density_Mg_per_m3) / WATER_DENSITY_MG_PER_M3
    if not th > tr:
        raise ParameterError(f"water content {water_content_kg_per_kg!r} kg/kg is at or below the residual water "
                             f"content of the van Genuchten curve ({tr} m^3/m^3)")
    if th >= ts:
        return SUCTION_WET_KPA
    m = 1.0 - 1.0 / n
    return max(((((th - tr) / (ts - tr)) ** (-1.0 / m) - 1.0) ** (1.0 / n)) / alpha, SUCTION_WET_KPA)


def van_genuchten_water_content(matric_suction_kPa, clay_kg_per_kg) -> float:
    """Volumetric water content [m^3/m^3] at a matric suction on the van Genuchten curve of Severiano
    et al.'s (2013) clay class: theta_r + (theta_s - theta_r) / (1 + (alpha h)^n)^(1 - 1/n)."""
    _, _, _, ts, tr, alpha, n = SEVERIANO_2013_CLASSES[clay_class(100.0 * float(clay_kg_per_kg))]
    h = _num("matric_suction_kPa", matric_suction_kPa, 0.0, 1e6)
    return tr + (ts - tr) / (1.0 + (alpha * h) ** n) ** (1.0 - 1.0 / n)


def moist_bulk_density_Mg_per_m3(soil: dict) -> float:
    """The soil's wet bulk density: its dry bulk density plus the water its suction leaves in the
    pores (the van Genuchten water content, at most the porosity)."""
    rb, rs = float(soil["bulk_density_initial_Mg_per_m3"]), float(soil["particle_density_Mg_per_m3"])
    theta = van_genuchten_water_content(soil["matric_suction_kPa"], soil["clay_kg_per_kg"])
    return rb + WATER_DENSITY_MG_PER_M3 * min(theta, 1.0 - rb / rs)


def geostatic_vertical_stress_Pa(soil: dict, depths_m) -> np.ndarray:
    """The vertical stress of the soil's own weight at each depth [Pa]: rho_moist g z."""
    return 1e3 * moist_bulk_density_Mg_per_m3(soil) * GRAVITY_M_S2 * np.asarray(depths_m, dtype=np.float64)


def is_layered(soil: dict) -> bool:
    """True when the soil's subsoil is described differently from its topsoil (SUBSOIL_KEYS)."""
    return any(soil.get(sub) is not None and float(soil[sub]) != float(soil[top]) for top, sub in SUBSOIL_KEYS.items())


def subsoil_set(soil: dict) -> dict:
    """The parameter set of the soil's subsoil layer: the soil itself when it is one layer; else its
    description with the subsoil's density, texture and suction, and the compression line and strength
    derived from them by the same PTFs (:func:`derive_soil`; a topsoil's given lambda, kappa or
    sigma_pc are the topsoil's, not carried down)."""
    if not is_layered(soil):
        return soil
    sub = {k: v for k, v in soil.items() if k not in LAYER_COMPRESSION_KEYS}
    sub.update({top: soil[s] for top, s in SUBSOIL_KEYS.items()})
    return derive_soil({**sub, **{k: None for k in LAYER_COMPRESSION_KEYS}}, "soil (its subsoil layer)")


def layer_sets(soil: dict, depths_m) -> list[dict]:
    """The parameter set that holds at each depth: the topsoil's above ``subsoil_top_m``, the
    subsoil's (:func:`subsoil_set`) from it down."""
    if not is_layered(soil):
        return [soil] * len(depths_m)
    top_m, sub = float(soil["subsoil_top_m"]), subsoil_set(soil)
    return [sub if float(z) >= top_m else soil for z in depths_m]


def geostatic_profile_Pa(soil: dict, depths_m) -> np.ndarray:
    """The vertical stress of the soil's own weight at each depth [Pa] through its layers: the
    topsoil's moist weight down to ``subsoil_top_m``, the subsoil's below (one layer:
    :func:`geostatic_vertical_stress_Pa`)."""
    z = np.asarray(depths_m, dtype=np.float64)
    if not is_layered(soil):
        return geostatic_vertical_stress_Pa(soil, z)
    top_m = float(soil["subsoil_top_m"])
    g_top = 1e3 * moist_bulk_density_Mg_per_m3(soil) * GRAVITY_M_S2
    g_sub = 1e3 * moist_bulk_density_Mg_per_m3(subsoil_set(soil)) * GRAVITY_M_S2
    return np.where(z < top_m, g_top * z, g_top * top_m + g_sub * (z - top_m))


def virgin_line_N_from_precompression(v0, lambda_, kappa, precompression_stress_Pa):
    """N of the virgin line v = N - lambda ln(p / kPa) that meets the recompression line through the
    initial state (v = v0 - kappa ln p) at the precompression stress: v0 + (lambda - kappa) ln(p_c / kPa).
    Floats or arrays."""
    return v0 + (lambda_ - kappa) * np.log(1e-3 * np.asarray(precompression_stress_Pa, dtype=np.float64))


def precompression_from_virgin_line_kPa(v0, N, lambda_, kappa):
    """The inverse: where the initial recompression line meets a virgin line N [kPa]."""
    return np.exp((np.asarray(N, dtype=np.float64) - v0) / (lambda_ - kappa))


def derivation_note(name: str, soil: dict) -> str:
    """How a derived parameter of a described soil was derived (``symtrack presets`` shows it)."""
    if name == "precompression_stress_Pa":
        ptf = precompression_ptf_kPa(soil)[1]
        inputs = "clay, bulk density and suction" if ptf.startswith("Schj") else "clay class and suction"
        return f"derived from {inputs} by {ptf}"
    if name in ("compression_index_lambda", "recompression_index_kappa"):
        return "derived from the initial specific volume (rho_s / rho_b) by Keller & Arvidsson (2007)"
    if name == "virgin_line_N":
        return "derived: the virgin line through the initial state at the precompression stress (one strength)"
    if name == "yield_compression_index_k2":
        return "derived: kappa + 0.241 (lambda - kappa), the published set's position (O'Sullivan & Robertson 1996)"
    if name.startswith("subsoil_"):
        return "the topsoil's value (the subsoil is given none of its own)"
    return ""


def _check_subsoil(out: dict, where: str) -> None:
    """Fill the subsoil's description with the topsoil's where not given; check a given one (its
    texture, density and suction as the topsoil's, and its derived strength) before any work."""
    for top, sub in SUBSOIL_KEYS.items():
        if out.get(sub) is None:
            out[sub] = out[top]
    if not is_layered(out):
        return
    _num(f"{where}.subsoil_top_m", out["subsoil_top_m"], 0.0, 5.0, lo_open=True)
    tex = [_num(f"{where}.{SUBSOIL_KEYS[k]}", out[SUBSOIL_KEYS[k]], 0.0, 1.0, why=" (a mass fraction, not %)")
           for k in TEXTURE_KEYS]
    if abs(sum(tex) - 1.0) > TEXTURE_SUM_TOLERANCE:
        raise ParameterError(f"{where}: subsoil_clay_kg_per_kg + subsoil_silt_kg_per_kg + subsoil_sand_kg_per_kg = "
                             f"{sum(tex):.4g}; the subsoil's texture fractions must sum to 1 (within "
                             f"{TEXTURE_SUM_TOLERANCE:g})")
    rb, rs = float(out["subsoil_bulk_density_initial_Mg_per_m3"]), float(out["particle_density_Mg_per_m3"])
    if not 0.0 < rb < rs:
        raise ParameterError(f"{where}.subsoil_bulk_density_initial_Mg_per_m3 = {rb!r} must be in (0, "
                             f"particle_density_Mg_per_m3 = {rs!r})")
    _num(f"{where}.subsoil_matric_suction_kPa", out["subsoil_matric_suction_kPa"], 0.0, 1e6, lo_open=True,
         why=" (suction is > 0 in an unsaturated soil)")


def derive_soil(values: dict, where: str = "soil") -> dict:
    """The soil's derived parameters (module doc) filled into a copy of ``values``, which holds the
    description (texture, bulk density, particle density, suction) and any given values; the virgin
    line's N is always derived. Bad input raises a ParameterError naming ``where``'s key."""
    out = dict(values)
    tex = [_num(f"{where}.{k}", out[k], 0.0, 1.0, why=" (a mass fraction, not %)") for k in TEXTURE_KEYS]
    if abs(sum(tex) - 1.0) > TEXTURE_SUM_TOLERANCE:
        raise ParameterError(f"{where}: clay_kg_per_kg + silt_kg_per_kg + sand_kg_per_kg = {sum(tex):.4g}; the "
                             f"texture fractions must sum to 1 (within {TEXTURE_SUM_TOLERANCE:g})")
    if "subsoil_top_m" in out:  # a parameter set of the registry: the subsoil layer's description
        _check_subsoil(out, where)
    rb = float(out["bulk_density_initial_Mg_per_m3"])
    rs = float(out["particle_density_Mg_per_m3"])
    if not rb < rs:
        raise ParameterError(f"{where}.bulk_density_initial_Mg_per_m3 = {rb!r} must be below "
                             f"particle_density_Mg_per_m3 = {rs!r} (a soil with no pores)")
    _num(f"{where}.matric_suction_kPa", out["matric_suction_kPa"], 0.0, 1e6, lo_open=True,
         why=" (suction is > 0 in an unsaturated soil)")
    v0 = rs / rb
    ka = keller_arvidsson_2007(rs, rb)
    for key, value in (("compression_index_lambda", ka[1]), ("recompression_index_kappa", ka[2])):
        if out.get(key) is None:
            out[key] = value
    lam, kap = float(out["compression_index_lambda"]), float(out["recompression_index_kappa"])
    if not 0.0 < kap < lam:
        raise ParameterError(f"{where}.recompression_index_kappa = {kap!r} must be in (0, compression_index_lambda = "
                             f"{lam!r}) (the recompression line is flatter than the virgin line)")
    if out.get("precompression_stress_Pa") is None:
        out["precompression_stress_Pa"] = 1e3 * precompression_ptf_kPa(out)[0]
    pc = _num(f"{where}.precompression_stress_Pa", out["precompression_stress_Pa"], 0.0, 1e7, lo_open=True)
    N = float(virgin_line_N_from_precompression(v0, lam, kap, pc))
    given = out.get("virgin_line_N")
    if given is not None and abs(float(given) - N) > 1e-9 * abs(N):
        pc_given = float(precompression_from_virgin_line_kPa(v0, float(given), lam, kap))
        raise ParameterError(f"{where}.virgin_line_N = {given!r} cannot be given: it follows from the soil's one "
                             f"strength (N = v0 + (lambda - kappa) ln(sigma_pc / kPa) = {N:.6g}); to move the virgin "
                             f"line give precompression_stress_Pa (this N is sigma_pc = {1e3 * pc_given:.6g} Pa)")
    out["virgin_line_N"] = N
    if out.get("yield_compression_index_k2") is None:
        out["yield_compression_index_k2"] = kap + K2_POSITION_OSR * (lam - kap)
    return out
