"""The parameter set: which parameters exist (names with units, meaning, allowed range, default,
source) and which values are legal, so that a misspelt key or a negative mass fails with a message
that names the key, the value and the allowed range.

Each piece of the model declares its own parameters where its equations are
(:class:`~symtrack.foundations.params.ParamSpec`): the vehicle model its body's and the soil
coefficients its traction reads (``params`` and ``soil_params`` of a vehicle of
:mod:`symtrack.vehicles.registry`), the soil law its coefficients (``params`` of a law of
:mod:`symtrack.soil.law`), the cell equation its two (:data:`symtrack.soil.cell.CELL_PARAMS`), and
this module the soil's description, compression and subsoil (:data:`SOIL_TERRAIN_PARAMS`, which
only the grid terrain's cells read). :func:`model_params` joins a vehicle's and a law's into a
model's parameter set and the layout of its parameter vector p; :func:`soil_params` and
:func:`vehicle_params` are the ``[soil]`` and ``[vehicle]`` tables of a model's options. A new law
or vehicle with coefficients of its own needs no edit here.

Values do NOT live here: they live in the parameter sets of :mod:`symtrack.presets`, each with its
source (or in a declaration's default).
"""

from __future__ import annotations

import dataclasses

from ..foundations.config import key_hints
from ..foundations.errors import ParameterError
from ..foundations.params import ParamLayout, ParamSpec, merge_specs, param
from ..soil import law as soil_law
from ..soil.cell import CELL_PARAMS
from ..soil.pedotransfer import SUBSOIL_KEYS, SUBSOIL_TOP_DEFAULT_M, derive_soil
from ..vehicles import registry as vehicle_registry

__all__ = ["ParamLayout", "ParamSet", "ParamSpec", "check_set", "known_soil_names", "model_param_layout",
           "model_params", "soil_params", "spec", "vehicle_params"]


def _spec(name, description, low, high, low_inclusive=True, default=None, derived=False, source=""):
    return param(name, description, low, high, low_inclusive, default=default, derived=derived, source=source)


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
# where each derived parameter comes from (the pedotransfer functions of symtrack/soil/pedotransfer.py)
_DERIVED_SOURCES = {
    "precompression_stress_Pa": "Schjoenning & Lamande (2018), from the soil's description",
    "virgin_line_N": "v0 + (lambda - kappa) ln(sigma_pc / kPa), from the soil's description",
    "compression_index_lambda": "Keller & Arvidsson (2007), from the soil's description",
    "recompression_index_kappa": "Keller & Arvidsson (2007), from the soil's description",
    "yield_compression_index_k2": "O'Sullivan & Robertson (1996): the published set's position between kappa and "
                                  "lambda",
}
SOIL_TERRAIN_PARAMS = tuple(dataclasses.replace(sp, source=DEFAULT_SOURCES[sp.name]) if sp.default is not None
                            else dataclasses.replace(sp, source=_DERIVED_SOURCES.get(sp.name, "the topsoil's value "
                                                     "(a subsoil layer described like its topsoil)"))
                            for sp in SOIL_TERRAIN_PARAMS)

# The order in the parameter vector p and in the terrain files of the soil coefficients the built-in
# models declare (the soil law's, the traction's, the cell equation's): the order of the files and
# generated C written so far. A plug-in's coefficients follow them, in the order declared.
SOIL_MODEL_ORDER = ("bekker_n", "k_c_N_per_m_n1", "k_phi_N_per_m_n2", "cohesion_Pa", "friction_angle_rad",
                    "shear_modulus_K_m", "elastic_stiffness_Pa_per_m", "unloading_stiffness_floor",
                    "cell_areal_mass_kg_per_m2", "cell_damping_Pa_s_per_m")


def _in_soil_order(specs) -> tuple[ParamSpec, ...]:
    rank = {n: i for i, n in enumerate(SOIL_MODEL_ORDER)}
    return tuple(sorted(specs, key=lambda s: rank.get(s.name, len(rank))))  # (stable: the rest as declared)


def _parts(opts=None, vehicle=None, law=None):
    """The vehicle model and the soil-law class of model options ``opts`` (None: the default model)
    unless given."""
    if vehicle is None:
        vehicle = vehicle_registry.for_options(opts)
    if law is None:
        law = soil_law.get(opts.soil_law if opts is not None else soil_law.DEFAULT)
    return vehicle, law


def model_params(opts=None, *, vehicle=None, law=None) -> tuple[ParamSpec, ...]:
    """The parameters of the model of options ``opts`` (its vehicle and soil law, or ``vehicle`` and the
    law class ``law``): the vehicle's own, then the soil coefficients (the traction's, the law's, the
    cell equation's: :data:`SOIL_MODEL_ORDER`, then a plug-in's): the layout of the parameter vector p."""
    vehicle, law = _parts(opts, vehicle, law)
    return merge_specs(vehicle.params, _in_soil_order(merge_specs(vehicle.soil_params, law.params, CELL_PARAMS)))


def model_param_layout(opts=None, *, vehicle=None, law=None) -> ParamLayout:
    """The layout of the parameter vector p of :func:`model_params`."""
    return ParamLayout(s.name for s in model_params(opts, vehicle=vehicle, law=law))


def vehicle_params(opts=None, *, vehicle=None) -> tuple[ParamSpec, ...]:
    """The ``[vehicle]`` table of the model of options ``opts``: its vehicle's own parameters."""
    return tuple(_parts(opts, vehicle, soil_law.BekkerWong)[0].params)


def soil_params(opts=None, *, vehicle=None, law=None) -> tuple[ParamSpec, ...]:
    """The ``[soil]`` table of the model of options ``opts``: the soil coefficients of
    :func:`model_params` and the soil's description, compression and subsoil (:data:`SOIL_TERRAIN_PARAMS`)."""
    vehicle, law = _parts(opts, vehicle, law)
    own = {s.name for s in vehicle.params}
    return tuple(s for s in model_params(vehicle=vehicle, law=law) if s.name not in own) + SOIL_TERRAIN_PARAMS


def known_soil_names() -> tuple[str, ...]:
    """Every soil parameter some registered vehicle or soil law declares (a ``[soil]`` table or a preset
    may carry another law's coefficients: a model that does not read them leaves them out)."""
    groups = [v.soil_params for v in vehicle_registry.REGISTRY.values()]
    groups += [law.params for law in soil_law.REGISTRY.values()]
    return tuple(s.name for s in _in_soil_order(merge_specs(*groups, CELL_PARAMS))) + \
        tuple(s.name for s in SOIL_TERRAIN_PARAMS)


# the parameter set of the default model (the planar vehicle on the Bekker/Wong law): the presets'
VEHICLE_PARAMS: tuple[ParamSpec, ...] = vehicle_params()
SOIL_MODEL_PARAMS: tuple[ParamSpec, ...] = tuple(s for s in model_params() if s not in VEHICLE_PARAMS)
SOIL_PARAMS: tuple[ParamSpec, ...] = soil_params()
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
    """The declaration of the parameter ``name`` (the default model's, or any registered vehicle's or
    soil law's)."""
    if name in _ALL:
        return _ALL[name]
    groups = [(*v.params, *v.soil_params) for v in vehicle_registry.REGISTRY.values()]
    groups += [law.params for law in soil_law.REGISTRY.values()]
    for group in groups:
        for s in group:
            if s.name == name:
                return s
    raise KeyError(name)


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


def check_set(values: dict, specs: tuple[ParamSpec, ...], where: str, known: tuple[str, ...] = ()) -> ParamSet:
    """Validate a complete parameter set: no unknown key, no missing key, every value in range. A soil
    set gets its derived parameters from its description (symtrack/soil/pedotransfer.py). ``known``:
    names a set may carry that ``specs`` do not read (another soil law's coefficients,
    :func:`known_soil_names`): left out of the result."""
    names = [s.name for s in specs]
    earlier = getattr(values, "derived", {})
    values = {k: v for k, v in values.items() if k in names or k not in known}
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ParameterError(
            f"unknown parameter(s) in {where}: {', '.join(unknown)}; allowed: {', '.join(names)}"
            f"{key_hints(unknown, names)}"
        )
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
