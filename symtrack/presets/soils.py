"""Soil parameter sets (SI units; converted once, here, never in the equations).

Sources:
- Wong, J.Y., *Theory of Ground Vehicles*, Table 2.3 (Bekker n, k_c, k_phi, c, phi), quoted in
  docs/model.md, "Soil parameter sets". The table gives k_c in kN/m^(n+1), k_phi in kN/m^(n+2) and c in
  kPa; the ``* 1e3`` below is that conversion.
- Janosi-Hanamoto K is not in that table: LETE sand 1.2 cm (Wong); "typical" clay 0.6 cm and
  loose sand 2.5 cm (Wong's guidance). Where a soil has no measured K, the guidance value is
  used and marked so.
- Project Chrono SCM terrain presets ("soft", "hard") for comparison: k_phi, n, phi, K, the
  elastic (unloading) stiffness K_e and the damping 3e4 Pa s/m.

- The cycle law's exponent ``repeated_loading_exponent`` beta (rut after N passes = first rut
  N^beta, symtrack/soil/cell.py): Li, D. & Selig, E.T. (1996), "Cumulative plastic deformation
  for fine-grained subgrade soils", J. Geotech. Eng. 122(12), 1006-1013, who fitted
  eps_p = a (sigma_d / sigma_s)^m N^b to repeated-load triaxial tests and give b by soil group:
  0.10 (ML, silt), 0.13 (MH), 0.16 (CL, lean clay), 0.18 (CH, fat clay). The power law in N is
  Monismith, Ogawa & Freeme (1975), Transp. Res. Rec. 537. Each soil below takes the group it
  is closest to; for sands (not fine-grained, outside Li & Selig's data) the lowest, ML's 0.10,
  is used and marked so.

- The subsoil stress's concentration factor ``stress_concentration_factor`` xi (Froehlich): Soehne
  (1953, Grundlagen der Landtechnik 5), as quoted by Keller et al. (2007), Soil Till. Res. 93,
  391-411: 4 for hard (dry) soil, 5 for firm (medium), 6 for soft (wet). No preset has a
  measured xi: each takes Soehne's class from its description (dry sand hard, wet soils soft),
  a judgement, marked so. (A second-hand source, the soilphysics R package's documentation,
  states the opposite order; docs/subsoil.md.)
- The soil's description (symtrack/soil/pedotransfer.py, docs/subsoil.md "One soil"): texture
  (clay, silt, sand mass fractions), dry bulk density before traffic and matric suction. Wong's
  table gives the soils' names and moisture contents only, so each preset's texture is the centre
  of the texture class its name gives (USDA texture triangle; "clayey soil" and "heavy clay" taken
  as clay, "clayey loam" as clay loam) and its bulk density a typical value for that texture
  (USDA-NRCS Soil Quality Indicators, "Bulk Density" (2008): ideal below 1.60 Mg/m^3 for sands,
  1.40 for silt loams, 1.10 for clays; restrictive above 1.80, 1.65, 1.47), kept below the
  saturation density of the named moisture content. ASSUMED, not measured with Wong's data.
  Where the name gives a moisture content w (dry basis), the suction is w's on the van Genuchten
  curve of the clay class (Severiano et al. 2013; ``suction_from_water_content_kPa``); the dry sands
  and Chrono's soils take an ASSUMED suction (dry: 100 kPa, pF 3; moist: 10-30 kPa). The saturation
  bound (``specific_volume_min``) is left to a ``[soil.moisture]`` day: with the assumed densities
  the named water contents put the wet soils at 90-100 % saturation, where the bound would forbid
  any compaction and rest on the assumed density alone.
- From the description the pedotransfer functions derive the precompression stress, the
  compression lines and the yield line's k2 (symtrack/soil/pedotransfer.py; ``symtrack presets
  NAME`` shows each derived value with its function): no two presets share a strength.

Terrain-cell dynamics (docs/model.md, "Cell dynamics") need an areal mass tau_z and an areal damping c'' that no
table gives; see the two module constants below.
"""

from __future__ import annotations

import math

from ..foundations.errors import ParameterError
from ..model.parameters import SOIL_PARAMS, check_set
from ..soil.pedotransfer import suction_from_water_content_kPa

# Areal damping c'' of a cell: Project Chrono SCM's default damping (3e4 Pa s/m).
CELL_DAMPING_PA_S_PER_M = 3.0e4
# Areal mass tau_z of a cell: calibrated for a natural frequency of a cell of 200-1500 rad/s
# (docs/model.md, "Cell dynamics"): at the validation load (about 28 kPa, 1.5 mm on clayey soil, dp/dz ~ 9e6 Pa/m)
# 50 kg/m^2 gives about 430 rad/s and, with c'' above, a damping ratio of about 0.7.
CELL_AREAL_MASS_KG_PER_M2 = 50.0
# Unloading/reloading stiffness for the Wong soils, which have no measured K_e: Chrono SCM's
# "soft" elastic stiffness (4e7 Pa/m), the lower end of SCM's range (4e7-4e8 Pa/m).
WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M = 4.0e7
# Floor of the unloading slope, k_u >= kappa * p_max / z_max (docs/model.md, "Pressure-sinkage"; 2-5):
# keeps millimetre-sinkage unloading lines from rebounding above the original surface.
UNLOADING_STIFFNESS_FLOOR = 3.0


# beta of the cycle law by Li & Selig's (1996) soil groups (module doc)
BETA_ML, BETA_MH, BETA_CL, BETA_CH = 0.10, 0.13, 0.16, 0.18
# xi of the subsoil stress by Soehne's classes (module doc)
XI_HARD, XI_FIRM, XI_SOFT = 4.0, 5.0, 6.0


def _describe(clay, silt, sand, rho_b, *, w=None, suction_kPa=None):
    """The description keys of a preset: texture, bulk density, and the suction given or that of the
    moisture content w (with w also the saturation bound; module doc)."""
    out = {"clay_kg_per_kg": clay, "silt_kg_per_kg": silt, "sand_kg_per_kg": sand,
           "bulk_density_initial_Mg_per_m3": rho_b}
    if w is not None:
        out["matric_suction_kPa"] = suction_from_water_content_kPa(w, rho_b, clay)
    else:
        out["matric_suction_kPa"] = suction_kPa
    return out


def _wong(n, k_c_kN, k_phi_kN, c_kPa, phi_deg, K_m, beta, xi, description):
    return {**description,
        "bekker_n": n,
        "k_c_N_per_m_n1": k_c_kN * 1e3,
        "k_phi_N_per_m_n2": k_phi_kN * 1e3,
        "cohesion_Pa": c_kPa * 1e3,
        "friction_angle_rad": math.radians(phi_deg),
        "shear_modulus_K_m": K_m,
        "elastic_stiffness_Pa_per_m": WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M,
        "unloading_stiffness_floor": UNLOADING_STIFFNESS_FLOOR,
        "cell_areal_mass_kg_per_m2": CELL_AREAL_MASS_KG_PER_M2,
        "cell_damping_Pa_s_per_m": CELL_DAMPING_PA_S_PER_M,
        "repeated_loading_exponent": beta,
        "stress_concentration_factor": xi,
    }


def _chrono(k_phi, n, phi_deg, K_m, K_e, beta, xi, description):
    return {**description,
        "bekker_n": n,
        "k_c_N_per_m_n1": 0.0,
        "k_phi_N_per_m_n2": k_phi,
        "cohesion_Pa": 0.0,
        "friction_angle_rad": math.radians(phi_deg),
        "shear_modulus_K_m": K_m,
        "elastic_stiffness_Pa_per_m": K_e,
        "unloading_stiffness_floor": UNLOADING_STIFFNESS_FLOOR,
        "cell_areal_mass_kg_per_m2": CELL_AREAL_MASS_KG_PER_M2,
        "cell_damping_Pa_s_per_m": CELL_DAMPING_PA_S_PER_M,
        "repeated_loading_exponent": beta,
        "stress_concentration_factor": xi,
    }


# name -> (values, source note)
SOILS: dict[str, dict[str, float]] = {
    # Wong Table 2.3; K: Wong's guidance for sand (2.5 cm); beta: ML's, extrapolated to sand
    "dry_sand": _wong(1.10, 0.99, 1528.43, 1.04, 28.0, 0.025, BETA_ML, XI_HARD,
                      _describe(0.03, 0.05, 0.92, 1.60, suction_kPa=100.0)),
    # Wong Table 2.3; K: guidance value between clay and sand (1.2 cm, as LETE sand)
    # beta: Li & Selig's silt (ML)
    "sandy_loam_15": _wong(0.70, 5.27, 1515.04, 1.72, 29.0, 0.012, BETA_ML, XI_FIRM,
                           _describe(0.10, 0.25, 0.65, 1.55, w=0.15)),
    # Wong Table 2.3; K = 1.5 cm calibrated against Ferretti & Girelli's (1999) validation table
    # (within Wong's 0.6-2.5 cm): gives a driven-track shear of order 1 cm at 2000 N m.
    # beta: Li & Selig's lean clay (CL); xi: firm (its sinkage under the crawler is millimetres)
    "clayey_soil_thailand_38": _wong(0.50, 13.19, 692.15, 4.14, 13.0, 0.015, BETA_CL, XI_FIRM,
                                     _describe(0.45, 0.30, 0.25, 1.25, w=0.38)),
    # Wong Table 2.3; K: Wong's guidance for clay (0.6 cm)
    # beta: Li & Selig's lean clay (CL)
    "clayey_soil_thailand_55": _wong(0.70, 16.03, 1262.53, 2.07, 10.0, 0.006, BETA_CL, XI_SOFT,
                                     _describe(0.55, 0.30, 0.15, 1.00, w=0.55)),
    # Wong Table 2.3; K: Wong's guidance for clay (0.6 cm)
    # beta: Li & Selig's fat clay (CH)
    "heavy_clay_wes_40": _wong(0.11, 1.84, 103.27, 20.69, 6.0, 0.006, BETA_CH, XI_SOFT,
                               _describe(0.60, 0.25, 0.15, 1.20, w=0.40)),
    # Wong Table 2.3; K = 1.2 cm measured for LETE sand (Wong)
    # beta: ML's, extrapolated to sand
    "lete_sand": _wong(0.79, 102.0, 5301.0, 1.3, 31.1, 0.012, BETA_ML, XI_HARD,
                       _describe(0.03, 0.05, 0.92, 1.65, suction_kPa=20.0)),
    # Wong Table 2.3; K: Wong's guidance for clay (0.6 cm)
    # beta: Li & Selig's lean clay (CL)
    "north_gower_clayey_loam_46": _wong(0.73, 41.6, 2471.0, 6.1, 26.6, 0.006, BETA_CL, XI_SOFT,
                                        _describe(0.35, 0.35, 0.30, 1.15, w=0.46)),
    # Wong Table 2.3; K: guidance value between clay and sand (1.2 cm)
    # beta: Li & Selig's silt (ML)
    "upland_sandy_loam_51": _wong(1.10, 74.6, 2080.0, 3.3, 33.7, 0.012, BETA_ML, XI_SOFT,
                                  _describe(0.15, 0.25, 0.60, 1.10, w=0.51)),
    # Project Chrono SCM demo presets; beta: no source for these generic soils, Li & Selig's lean
    # clay (CL) as the registry's default
    "chrono_soft": _chrono(2e6, 1.1, 30.0, 0.01, 4e7, BETA_CL, XI_SOFT,
                           _describe(0.20, 0.40, 0.40, 1.30, suction_kPa=10.0)),
    "chrono_hard": _chrono(2e7, 1.1, 20.0, 0.01, 2e8, BETA_CL, XI_HARD,
                           _describe(0.20, 0.40, 0.40, 1.60, suction_kPa=30.0)),
}


def soil_preset(name: str) -> dict[str, float]:
    if name not in SOILS:
        raise ParameterError(f"soil.preset = {name!r} is not a known soil; known: {', '.join(SOILS)}")
    return check_set(dict(SOILS[name]), SOIL_PARAMS, f"soil preset {name!r}")
