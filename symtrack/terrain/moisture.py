"""The soil's moisture on the day: its compression parameters and strength from pedotransfer
functions of water content and texture (issue 24 item 2; docs/subsoil.md, "Moisture").

Two pedotransfer functions (PTFs), both as the soilphysics R package (de Lima, da Silva & da Silva;
github.com/arsilva87/soilphysics, ``R/PredComp.R``) codes them; the papers themselves were not read:

- **Défossez et al. (2003)** (Soil Till. Res. 69, as soilphysics cites it; its comment: "water
  content range from 5 to 30 %"): the O'Sullivan & Robertson compression parameters of two French
  soils, a loess and a calcareous soil, as polynomials of the gravimetric water content w [%]:

      loess       N = 1.9997 + 0.2629 w - 0.02753 w^2 + 0.00111 w^3 - 1.6e-5 w^4
                  lambda = 0.1402 + 0.00192 w + 0.00021 w^2 - 1.3e-5 w^3
      calcareous  N = 2.4196 + 0.13767 w - 0.02035 w^2 + 0.00121 w^3 - 2.4e-5 w^4
                  lambda = 0.08051 + 0.03131 w - 0.00502 w^2 + 0.00031 w^3 - 6e-6 w^4
      kappa = 0.0058 (both)

  They set the bulk-density model's ``virgin_line_N``, ``compression_index_lambda`` and
  ``recompression_index_kappa`` (symtrack/terrain/density.py). Chosen because it is the one PTF
  found whose output is the compression model's own parameters (N, lambda, kappa) as a function of
  water content: the wetter soil has the lower virgin line, so the same stress compacts it more.
  Its classes are the two soils: any other texture is refused, as is w outside 5-30 %.

- **Severiano et al. (2013)** by clay class (soilphysics' ``soilStrength``): the precompression
  stress from the matric suction h [kPa], sigma_pc = a h^b kPa, with (a, b) per clay class
  (< 20 %, 20-31, 31-37, 37-52, > 52 %); from a volumetric water content through each class's
  van Genuchten curve (theta_s, theta_r, alpha [1/kPa], n; m = 1 - 1/n), the parameters listed in
  the same code. It sets ``precompression_stress_Pa`` (the risk classes' strength). The suction
  unit kPa is read from the code (its app divides an hPa input by 10 before the PTF), not the paper.

The moisture input is a soil's table ``moisture`` (``[soil.moisture]``, or ``moisture = {...}`` in a
soil map's soil)::

    [soil.moisture]
    water_content_kg_per_kg = 0.22            # gravimetric, on the day of the traffic
    compression_ptf = "defossez_2003_loess"   # or "defossez_2003_calcareous"; N, lambda, kappa
    clay_percent = 25.0                       # optional: Severiano et al. 2013's sigma_pc

The volumetric water content is w rho_b / rho_w with the soil's initial bulk density; saturation
is its porosity, w_sat = (1 / rho_b - 1 / rho_s) rho_w. Moisture is the day's, not the field's
state: it is not stored in the terrain file (the soil parameters it gives are, with a soil map).
"""

from __future__ import annotations

import math

from ..foundations.errors import ParameterError

__all__ = ["COMPRESSION_PTFS", "MOISTURE_KEYS", "SEVERIANO_2013_CLASSES", "apply_moisture", "clay_class",
           "defossez_2003", "saturation_water_content_kg_per_kg", "severiano_2013_precompression_kPa",
           "severiano_2013_suction_kPa"]

WATER_DENSITY_MG_PER_M3 = 1.0
MOISTURE_KEYS = ("water_content_kg_per_kg", "compression_ptf", "clay_percent")

# Défossez et al. (2003) as soilphysics' compressive.properties1 codes it: polynomial coefficients
# in w [%] (ascending powers) of N and lambda; kappa one value
_DEFOSSEZ = {
    "defossez_2003_loess": ((1.9997, 0.2629, -0.02753, 0.00111, -1.6e-5), (0.1402, 0.00192, 0.00021, -1.3e-5)),
    "defossez_2003_calcareous": ((2.4196, 0.13767, -0.02035, 0.00121, -2.4e-5),
                                 (0.08051, 0.03131, -0.00502, 0.00031, -6e-6)),
}
_DEFOSSEZ_KAPPA = 0.0058
DEFOSSEZ_RANGE_PERCENT = (5.0, 30.0)
COMPRESSION_PTFS = tuple(_DEFOSSEZ)

# Severiano et al. (2013) as soilphysics' soilStrength (PredComp.R) codes it, per clay class:
# (upper clay bound %, a, b of sigma_pc = a h^b, theta_s, theta_r, alpha [1/kPa], n)
SEVERIANO_2013_CLASSES = (
    (20.0, 129.0, 0.15, 0.42, 0.049356, 0.79, 1.72),
    (31.0, 123.3, 0.13, 0.45, 0.08689, 0.72, 1.56),
    (37.0, 85.0, 0.17, 0.46, 0.10696, 1.66, 1.52),
    (52.0, 70.1, 0.16, 0.50, 0.125941, 2.04, 1.47),
    (100.0, 62.7, 0.15, 0.51, 0.139358, 2.27, 1.38),
)


def _poly(c, x):
    return sum(ci * x**i for i, ci in enumerate(c))


def defossez_2003(water_content_kg_per_kg, compression_ptf: str) -> tuple[float, float, float]:
    """(N, lambda, kappa) of Défossez et al. (2003) at the gravimetric water content (module doc)."""
    if compression_ptf not in _DEFOSSEZ:
        raise ParameterError(f"compression_ptf = {compression_ptf!r} is not one of the PTF's texture classes "
                             f"({', '.join(COMPRESSION_PTFS)}): Défossez et al. (2003) fitted a loess and a "
                             f"calcareous soil only")
    w = 100.0 * float(water_content_kg_per_kg)
    lo, hi = DEFOSSEZ_RANGE_PERCENT
    if not (math.isfinite(w) and lo <= w <= hi):
        raise ParameterError(f"water_content_kg_per_kg = {water_content_kg_per_kg!r} is outside the range of "
                             f"{compression_ptf} [{lo / 100}, {hi / 100}] (Défossez et al. 2003: 5-30 %)")
    cN, cL = _DEFOSSEZ[compression_ptf]
    return _poly(cN, w), _poly(cL, w), _DEFOSSEZ_KAPPA


def clay_class(clay_percent) -> int:
    """Severiano et al.'s clay class (0..4) of a clay content in %: < 20, 20-31, 31-37, 37-52, > 52."""
    c = float(clay_percent)
    if not (math.isfinite(c) and 0.0 <= c <= 100.0):
        raise ParameterError(f"clay_percent = {clay_percent!r} is outside the allowed range [0, 100] (%)")
    if c < SEVERIANO_2013_CLASSES[0][0]:
        return 0
    for k, row in enumerate(SEVERIANO_2013_CLASSES[1:], start=1):
        if c <= row[0]:
            return k
    return len(SEVERIANO_2013_CLASSES) - 1


def severiano_2013_suction_kPa(theta_m3_per_m3, clay_percent) -> float:
    """Matric suction [kPa] of a volumetric water content on the clay class's van Genuchten curve;
    theta must lie strictly between the class's residual and saturated water contents."""
    _, _, _, ts, tr, alpha, n = SEVERIANO_2013_CLASSES[clay_class(clay_percent)]
    th = float(theta_m3_per_m3)
    if not (math.isfinite(th) and tr < th < ts):
        raise ParameterError(f"volumetric water content = {theta_m3_per_m3!r} is outside ({tr}, {ts}) of the "
                             f"van Genuchten curve of Severiano et al.'s clay class for {clay_percent} % clay")
    m = 1.0 - 1.0 / n
    se = (th - tr) / (ts - tr)
    return (se ** (-1.0 / m) - 1.0) ** (1.0 / n) / alpha


def severiano_2013_precompression_kPa(clay_percent, suction_kPa) -> float:
    """sigma_pc = a h^b [kPa] of Severiano et al. (2013) for the clay class, h in kPa (> 0)."""
    _, a, b, *_ = SEVERIANO_2013_CLASSES[clay_class(clay_percent)]
    h = float(suction_kPa)
    if not (math.isfinite(h) and h > 0.0):
        raise ParameterError(f"suction_kPa = {suction_kPa!r} must be > 0")
    return a * h**b


def saturation_water_content_kg_per_kg(bulk_density_Mg_per_m3, particle_density_Mg_per_m3) -> float:
    """The gravimetric water content of the saturated soil: porosity rho_w / rho_b."""
    rb, rs = float(bulk_density_Mg_per_m3), float(particle_density_Mg_per_m3)
    return (1.0 / rb - 1.0 / rs) * WATER_DENSITY_MG_PER_M3


def apply_moisture(soil: dict, moisture, where: str = "soil.moisture") -> dict:
    """The soil's parameter set on the day of ``moisture`` (module doc): a new dict with N, lambda,
    kappa (``compression_ptf``) and ``precompression_stress_Pa`` (``clay_percent``) replaced.
    Every value is checked before anything is computed; the errors name ``where``'s key."""
    if not isinstance(moisture, dict):
        raise ParameterError(f"{where} = {moisture!r} must be a table ({', '.join(MOISTURE_KEYS)})")
    unknown = sorted(set(moisture) - set(MOISTURE_KEYS))
    if unknown:
        raise ParameterError(f"unknown key(s) in {where}: {', '.join(unknown)}; allowed: {', '.join(MOISTURE_KEYS)}")
    if "water_content_kg_per_kg" not in moisture:
        raise ParameterError(f"{where}.water_content_kg_per_kg is required")
    w = moisture["water_content_kg_per_kg"]
    if isinstance(w, bool) or not isinstance(w, (int, float)):
        raise ParameterError(f"{where}.water_content_kg_per_kg = {w!r} is not a number")
    rb, rs = float(soil["bulk_density_initial_Mg_per_m3"]), float(soil["particle_density_Mg_per_m3"])
    w_sat = saturation_water_content_kg_per_kg(rb, rs)
    if not (math.isfinite(float(w)) and 0.0 <= float(w) <= w_sat):
        raise ParameterError(f"{where}.water_content_kg_per_kg = {w!r} is outside [0, {w_sat:.4g}] (0 to saturation: "
                             f"the porosity of bulk density {rb} in particle density {rs})")
    ptf = moisture.get("compression_ptf")
    clay = moisture.get("clay_percent")
    if ptf is None and clay is None:
        raise ParameterError(f"{where} needs compression_ptf ({', '.join(COMPRESSION_PTFS)}) or clay_percent "
                             "(or both): without a pedotransfer function the water content changes nothing")
    out = dict(soil)
    try:
        if ptf is not None:
            if not isinstance(ptf, str):
                raise ParameterError(f"compression_ptf = {ptf!r} must be a string ({', '.join(COMPRESSION_PTFS)})")
            N, lam, kap = defossez_2003(w, ptf)
            out.update(virgin_line_N=N, compression_index_lambda=lam, recompression_index_kappa=kap)
        if clay is not None:
            if isinstance(clay, bool) or not isinstance(clay, (int, float)):
                raise ParameterError(f"clay_percent = {clay!r} is not a number")
            theta = float(w) * rb / WATER_DENSITY_MG_PER_M3
            h = severiano_2013_suction_kPa(theta, clay)
            out["precompression_stress_Pa"] = 1e3 * severiano_2013_precompression_kPa(clay, h)
    except ParameterError as err:
        raise ParameterError(f"{where}: {err}") from err
    return out
