"""The registry of model parameters: names (with units), meaning and allowed range.

Values do NOT live here: they live in the parameter sets of :mod:`symtrack.presets`, each
with its source. This module only says which parameters exist and which values are legal,
so that a misspelt key or a negative mass fails with a message that names the key, the value
and the allowed range.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from ..foundations.errors import ParameterError
from ..soil.pedotransfer import SUBSOIL_KEYS, SUBSOIL_TOP_DEFAULT_M, derive_soil


@dataclass(frozen=True)
class ParamSpec:
    name: str
    description: str
    low: float
    high: float
    low_inclusive: bool = True
    default: float | None = None  # used when a parameter set leaves it out (terrain-only soil parameters)
    derived: bool = False  # filled by the soil's pedotransfer functions when a set leaves it out
    default_source: str = ""  # where the default comes from (symtrack presets shows it)

    def check(self, value: object, where: str = "") -> float:
        label = f"{where}.{self.name}" if where else self.name
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{label} = {value!r} is not a number ({self.description})")
        v = float(value)
        ok_low = v >= self.low if self.low_inclusive else v > self.low
        if not math.isfinite(v) or not ok_low or v > self.high:
            lb = "[" if self.low_inclusive else "("
            raise ParameterError(
                f"{label} = {value!r} is outside the allowed range {lb}{self.low:g}, {self.high:g}] "
                f"({self.description})"
            )
        return v


def _spec(name, description, low, high, low_inclusive=True, default=None, derived=False, default_source=""):
    return ParamSpec(name, description, low, high, low_inclusive, default, derived, default_source)


# where each default of the registry comes from, for a reader of symtrack presets (the reasoning in full is in
# the comments above the constants below)
_LOAM = "a loam (USDA texture triangle: 20 % clay, 40 % silt, 40 % sand), the description of a soil that gives none"
DEFAULT_SOURCES = {
    "repeated_loading_exponent": "Li & Selig (1996), lean clay (CL)",
    "stress_concentration_factor": "Soehne's concentration factor of a \"medium\" soil",
    "particle_density_Mg_per_m3": "the usual particle density of mineral soils",
    "bulk_density_initial_Mg_per_m3": f"{_LOAM}, at 1.5 Mg/m^3",
    "yield_line_offset_ln_p": "O'Sullivan & Robertson (1996): m = 1.3, the one complete published set (soilphysics' "
                              "soilDeformation example)",
    "specific_volume_min": "zero porosity (the day's saturation with [soil.moisture])",
    "clay_kg_per_kg": _LOAM, "silt_kg_per_kg": _LOAM, "sand_kg_per_kg": _LOAM,
    "matric_suction_kPa": "field capacity (pF 2, 10 kPa)",
    "subsoil_top_m": "the usual depth of primary tillage (mouldboard ploughing to 0.25-0.30 m), an assumption where a "
                     "layered soil gives no depth",
}


VEHICLE_PARAMS: tuple[ParamSpec, ...] = (
    _spec("mass_kg", "vehicle mass", 0.0, 1e6, False),
    _spec("yaw_inertia_kg_m2", "yaw moment of inertia about the CG", 0.0, 1e8, False),
    _spec("track_gauge_m", "distance B between the track centre-lines", 0.0, 20.0, False),
    _spec("track_width_m", "track width b", 0.0, 5.0, False),
    _spec("contact_length_m", "track contact length l", 0.0, 20.0, False),
    _spec("sprocket_radius_m", "sprocket pitch radius r", 0.0, 5.0, False),
    _spec("cg_height_m", "CG height h above the ground", 0.0, 10.0),
    _spec("cg_ahead_of_contact_centre_m", "CG offset e ahead of the contact centre", -5.0, 5.0),
    _spec("sprocket_inertia_kg_m2", "equivalent inertia J_eq per side (sprocket, idler, rollers, track)",
          0.0, 1e5, False),
    _spec("torque_time_constant_s", "time constant tau_T of the first-order torque actuator", 0.0, 100.0, False),
    _spec("internal_resistance_const", "Wong's internal resistance R_in/W_k, speed-independent part", 0.0, 1.0),
    _spec("internal_resistance_per_km_h", "Wong's internal resistance R_in/W_k per km/h of track speed",
          0.0, 0.1),
    _spec("lateral_friction_coeff", "lateral friction coefficient mu_t between track and soil "
          "(lateral_law = \"creep\" only)", 0.0, 5.0),
    _spec("lateral_creep_speed_m_s", "lateral slip speed eps_v at which friction reaches tanh(1) of mu_t "
          "(lateral_law = \"creep\" only)", 0.0, 10.0, False),
    _spec("drawbar_pull_N", "drawbar pull P (external resistance at the hitch)", 0.0, 1e7),
    _spec("hitch_height_m", "height h_d of the drawbar hitch", 0.0, 10.0),
)

SOIL_MODEL_PARAMS: tuple[ParamSpec, ...] = (
    _spec("bekker_n", "Bekker sinkage exponent n", 0.0, 3.0, False),
    _spec("k_c_N_per_m_n1", "Bekker cohesive modulus k_c [N/m^(n+1)]", 0.0, 1e9),
    _spec("k_phi_N_per_m_n2", "Bekker frictional modulus k_phi [N/m^(n+2)]", 0.0, 1e12),
    _spec("cohesion_Pa", "Mohr-Coulomb cohesion c", 0.0, 1e7),
    _spec("friction_angle_rad", "Mohr-Coulomb internal friction angle phi", 0.0, 1.5),
    _spec("shear_modulus_K_m", "Janosi-Hanamoto shear deformation modulus K", 0.0, 1.0, False),
    _spec("elastic_stiffness_Pa_per_m", "unloading/reloading stiffness K_e (Chrono SCM's elastic stiffness)",
          0.0, 1e12, False),
    _spec("unloading_stiffness_floor", "kappa: the unloading slope is at least kappa * p_max / z_max",
          1.0, 100.0),
    _spec("cell_areal_mass_kg_per_m2", "tau_z of the cell equation: areal mass of a terrain cell", 0.0, 1e5, False),
    _spec("cell_damping_Pa_s_per_m", "c'' of the cell equation: areal damping of a terrain cell", 0.0, 1e9),
)

# Soil parameters only the grid terrain's cells use (its world manager and engine): not in the
# vehicle model's parameter vector. A parameter set may leave them out: a registry default (its source
# here) or, for the compression and strength parameters marked derived, the pedotransfer functions of
# the soil's description (symtrack/soil/pedotransfer.py, docs/subsoil.md "One soil") fill them.
REPEATED_LOADING_EXPONENT_DEFAULT = 0.16  # Li & Selig 1996, lean clay (CL): see presets/soils.py
STRESS_CONCENTRATION_FACTOR_DEFAULT = 5.0  # Soehne's "medium" soil: see presets/soils.py
# The soil's description when a parameter set gives none (a user preset file with Bekker values only):
# a loam (USDA texture triangle: 20 % clay, 40 % silt, 40 % sand) at field capacity (pF 2, 10 kPa), with
# a bulk density of 1.5 Mg/m^3 and the usual particle density of mineral soils, 2.65 Mg/m^3. At these
# inputs the Schjoenning & Lamande (2018) PTF gives sigma_pc = 141 kPa.
CLAY_DEFAULT_KG_PER_KG = 0.20
SILT_DEFAULT_KG_PER_KG = 0.40
SAND_DEFAULT_KG_PER_KG = 0.40
MATRIC_SUCTION_DEFAULT_KPA = 10.0
PARTICLE_DENSITY_DEFAULT_MG_PER_M3 = 2.65
BULK_DENSITY_INITIAL_DEFAULT_MG_PER_M3 = 1.5
# O'Sullivan & Robertson's (1996, Soil Till. Res. 39, 161-173) yield line, as SoilFlex (Keller et al.
# 2007) and soilphysics' soilDeformation code it (soil/density.py): m = 1.3, the value of the one
# complete published set found (soilphysics' soilDeformation example, docs/subsoil.md "Repeated
# passes"); with it every pass at a stress above the yield line's (about 0.2 of the precompression
# stress) adds a little density, less each time. 0 switches the yield line off.
YIELD_LINE_OFFSET_DEFAULT = 1.3
# the smallest specific volume the soil reaches under load: 1 (zero porosity, rho_b = rho_s) unless the
# day's water content w is known ([soil.moisture]), then 1 + w rho_s / rho_w, the specific volume at zero
# air-filled porosity (saturation; soil/moisture.py)
SPECIFIC_VOLUME_MIN_DEFAULT = 1.0
SOIL_TERRAIN_PARAMS: tuple[ParamSpec, ...] = (
    _spec("repeated_loading_exponent", "beta of the cycle law: the rut after N passes is the first pass's N^beta",
          0.0, 1.0, default=REPEATED_LOADING_EXPONENT_DEFAULT),
    _spec("stress_concentration_factor", "Froehlich's concentration factor xi of the subsoil stress (3: Boussinesq)",
          1.0, 10.0, default=STRESS_CONCENTRATION_FACTOR_DEFAULT),
    _spec("precompression_stress_Pa", "the soil's strength against compaction sigma_pc: where the density model "
          "yields and what the risk classes grade against (derived: Schjoenning & Lamande 2018)", 0.0, 1e7, False,
          derived=True),
    _spec("virgin_line_N", "specific volume of the virgin compression line at a vertical stress of 1 kPa (derived, "
          "never given: v0 + (lambda - kappa) ln(sigma_pc / kPa))", 1.0, 5.0, False, derived=True),
    _spec("compression_index_lambda", "slope lambda of the virgin compression line v = N - lambda ln(p / kPa) "
          "(derived: Keller & Arvidsson 2007)", 0.0, 1.0, False, derived=True),
    _spec("recompression_index_kappa", "slope kappa of the recompression lines, below lambda (derived: Keller & "
          "Arvidsson 2007)", 0.0, 1.0, False, derived=True),
    _spec("particle_density_Mg_per_m3", "the soil's particle density rho_s", 1.0, 5.0, False,
          default=PARTICLE_DENSITY_DEFAULT_MG_PER_M3),
    _spec("bulk_density_initial_Mg_per_m3", "the soil's dry bulk density before any traffic (below rho_s)",
          0.1, 5.0, False, default=BULK_DENSITY_INITIAL_DEFAULT_MG_PER_M3),
    _spec("yield_line_offset_ln_p", "O'Sullivan & Robertson's m: the yield line is the virgin line moved by m "
          "along ln(p / kPa) (0: no yield line)", 0.0, 10.0, default=YIELD_LINE_OFFSET_DEFAULT),
    _spec("yield_compression_index_k2", "slope k2 of the line from the yield line to the virgin line (with "
          "m > 0: in (kappa, lambda); derived: the published set's position between kappa and lambda)",
          0.0, 1.0, False, derived=True),
    _spec("specific_volume_min", "the smallest specific volume under load (1: zero porosity; the day's "
          "saturation 1 + w rho_s / rho_w with [soil.moisture])", 1.0, 5.0, default=SPECIFIC_VOLUME_MIN_DEFAULT),
    _spec("clay_kg_per_kg", "clay fraction of the fine earth (< 2 um; mass fraction)", 0.0, 1.0,
          default=CLAY_DEFAULT_KG_PER_KG),
    _spec("silt_kg_per_kg", "silt fraction of the fine earth (2-50 um; mass fraction)", 0.0, 1.0,
          default=SILT_DEFAULT_KG_PER_KG),
    _spec("sand_kg_per_kg", "sand fraction of the fine earth (50-2000 um; mass fraction)", 0.0, 1.0,
          default=SAND_DEFAULT_KG_PER_KG),
    _spec("matric_suction_kPa", "the soil water's matric suction (10 kPa: field capacity, pF 2)", 0.0, 1e6, False,
          default=MATRIC_SUCTION_DEFAULT_KPA),
    # the subsoil layer (symtrack/soil/pedotransfer.py, SUBSOIL_KEYS): each the topsoil's unless given
    _spec("subsoil_top_m", "depth where the subsoil layer begins (the tillage depth; with a subsoil described "
          "differently from the topsoil)", 0.0, 5.0, False, default=SUBSOIL_TOP_DEFAULT_M),
)
# the subsoil's description: the topsoil's keys' ranges, each the topsoil's value unless given (derived)
_TOPSOIL = {s.name: s for s in SOIL_TERRAIN_PARAMS}
SOIL_TERRAIN_PARAMS += tuple(
    _spec(sub, f"subsoil layer: {_TOPSOIL[top].description} (the topsoil's unless given)", _TOPSOIL[top].low,
          _TOPSOIL[top].high, _TOPSOIL[top].low_inclusive, derived=True) for top, sub in SUBSOIL_KEYS.items())
SOIL_TERRAIN_PARAMS = tuple(dataclasses.replace(sp, default_source=DEFAULT_SOURCES[sp.name])
                            if sp.default is not None else sp for sp in SOIL_TERRAIN_PARAMS)
SOIL_PARAMS: tuple[ParamSpec, ...] = SOIL_MODEL_PARAMS + SOIL_TERRAIN_PARAMS
# the soil parameters the day's moisture sets (symtrack/soil/moisture.py): a terrain file made on
# another day continues with the scenario's values of these (the compression state carries over)
SOIL_DAY_PARAM_NAMES = ("virgin_line_N", "compression_index_lambda", "recompression_index_kappa",
                        "precompression_stress_Pa", "specific_volume_min", "yield_compression_index_k2",
                        "matric_suction_kPa")

VEHICLE_PARAM_NAMES = tuple(s.name for s in VEHICLE_PARAMS)
SOIL_PARAM_NAMES = tuple(s.name for s in SOIL_PARAMS)
SOIL_MODEL_PARAM_NAMES = tuple(s.name for s in SOIL_MODEL_PARAMS)
_ALL = {s.name: s for s in VEHICLE_PARAMS + SOIL_PARAMS}


def spec(name: str) -> ParamSpec:
    return _ALL[name]


class ParamSet(dict):
    """A complete, checked parameter set that remembers which values the soil's pedotransfer functions
    derived (``derived``: name -> value). A copy updated with new values and checked again re-derives
    every derived value that was not replaced, so that changing a soil's texture or density moves its
    strength and compression lines with it."""

    derived: dict

    def __init__(self, *args, derived=None, **kw):
        super().__init__(*args, **kw)
        self.derived = dict(derived or {})

    def with_given(self, values: dict) -> ParamSet:
        """A copy with ``values`` set as given: each no longer counts as derived, even where it equals the
        value derived before (a preset file's or a scenario's subsoil density equal to its base's topsoil
        density is the user's, not re-derived), and the rest as it was (checked again by :func:`check_set`)."""
        out = ParamSet(self, derived={k: v for k, v in self.derived.items() if k not in values})
        out.update(values)
        return out


DERIVED_SOIL_PARAM_NAMES = tuple(s.name for s in SOIL_PARAMS if s.derived)


def check_set(values: dict, specs: tuple[ParamSpec, ...], where: str) -> ParamSet:
    """Validate a complete parameter set: no unknown key, no missing key, every value in range. A soil
    set gets its derived parameters from its description (symtrack/soil/pedotransfer.py)."""
    names = [s.name for s in specs]
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ParameterError(
            f"unknown parameter(s) in {where}: {', '.join(unknown)}; allowed: {', '.join(names)}"
        )
    earlier = getattr(values, "derived", {})
    values = {k: v for k, v in values.items() if not (k in earlier and v == earlier[k])}
    for s in specs:
        if s.name not in values and s.default is not None:
            values[s.name] = s.default
    derived = [s.name for s in specs if s.derived]
    missing_before = {n for n in derived if n not in values}
    if derived:
        values = derive_soil({**{n: None for n in derived}, **values}, where)
    missing = [n for n in names if n not in values]
    if missing:
        raise ParameterError(f"missing parameter(s) in {where}: {', '.join(missing)}")
    out = {s.name: s.check(values[s.name], where) for s in specs}
    return ParamSet(out, derived={n: out[n] for n in derived if n in missing_before or n == "virgin_line_N"})
