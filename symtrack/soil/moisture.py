"""The soil's moisture on the day: its compression parameters and strength from pedotransfer
functions of water content and texture (docs/subsoil.md, "Moisture").

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
  ``recompression_index_kappa`` (symtrack/soil/density.py). Chosen because it is the one PTF
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

A moisture raster (``[terrain.moisture]``: ``raster`` a .npy file of floats (nx, ny) or a GeoTIFF,
each cell the pixel holding its centre, plus ``compression_ptf`` / ``clay_percent`` as above) gives
each cell its own water content on a new field: every distinct (soil, water content) pair becomes a
soil of the field's soil map (at most soil_map.MAX_SOILS), a uniform raster one soil, equal bit for
bit to the same value given in ``[soil.moisture]`` (folded into soil 0). A raster of more distinct
pairs than a soil map holds gives each cell its own day parameters instead
(:func:`cell_day_parameters`: N, lambda, kappa and sigma_pc per cell, float64, in the world, not in
the terrain file): the PTFs set only parameters the terrain engine never reads (the compression
update and the risk figures run in Python at the pass end), so the engine's soils stay the field's
soils and its speed is unchanged (docs/subsoil.md, "Moisture maps of many values"). Up to
MAX_SOILS - 1 pairs the soil-map path is kept (:func:`split_soils`).
"""

from __future__ import annotations

import dataclasses
import math
import operator

import numpy as np

from ..foundations.errors import ParameterError, ScenarioError
from ..model.parameters import DERIVED_SOIL_PARAM_NAMES, SOIL_PARAMS
from ..terrain import gis
from .pedotransfer import (
    DESCRIPTION_KEYS,
    SEVERIANO_2013_CLASSES,
    clay_class,
    derive_soil,
    precompression_from_virgin_line_kPa,
    virgin_line_N_from_precompression,
)

__all__ = ["COMPRESSION_PTFS", "DAY_KEYS", "MOISTURE_KEYS", "SEVERIANO_2013_CLASSES", "MoistureMap", "apply_moisture",
           "cell_day_parameters", "clay_class", "distinct_pairs", "parse_moisture_map", "read_moisture", "split_soils",
           "defossez_2003", "saturation_specific_volume", "saturation_water_content_kg_per_kg",
           "severiano_2013_precompression_kPa",
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

# Severiano et al.'s (2013) table per clay class (a, b of sigma_pc = a h^b, the van Genuchten curve):
# its one home is symtrack/soil/pedotransfer.py (SEVERIANO_2013_CLASSES, clay_class)


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


def saturation_specific_volume(water_content_kg_per_kg, particle_density_Mg_per_m3):
    """The specific volume at zero air-filled porosity (saturation) of a gravimetric water content w:
    v_sat = 1 + e_sat = 1 + w rho_s / rho_w (every pore full of the water w). The bound of the
    compression model under load (soil/density.py, ``specific_volume_min``): the densest the soil
    can be made by a pass, rho_max = rho_s / (1 + w rho_s / rho_w) (the zero-air-voids line of the
    Proctor test). Works on floats and arrays (the same operations)."""
    return 1.0 + water_content_kg_per_kg * particle_density_Mg_per_m3 / WATER_DENSITY_MG_PER_M3


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
    derived = getattr(soil, "derived", {})
    # what the soil's PTFs derived is derived again from the day's values (the k2 of new lines)
    out = {k: v for k, v in soil.items() if not (k in derived and v == derived[k])}
    out.pop("virgin_line_N", None)  # follows from the day's strength (symtrack/soil/pedotransfer.py)
    out["specific_volume_min"] = saturation_specific_volume(float(w), rs)
    try:
        if ptf is not None:
            if not isinstance(ptf, str):
                raise ParameterError(f"compression_ptf = {ptf!r} must be a string ({', '.join(COMPRESSION_PTFS)})")
            N, lam, kap = defossez_2003(w, ptf)
            out.update(compression_index_lambda=lam, recompression_index_kappa=kap)
            if clay is None:  # Défossez's virgin line sets the day's strength
                out["precompression_stress_Pa"] = 1e3 * float(precompression_from_virgin_line_kPa(rs / rb, N, lam, kap))
        if clay is not None:
            if isinstance(clay, bool) or not isinstance(clay, (int, float)):
                raise ParameterError(f"clay_percent = {clay!r} is not a number")
            theta = float(w) * rb / WATER_DENSITY_MG_PER_M3
            h = severiano_2013_suction_kPa(theta, clay)
            out["precompression_stress_Pa"] = 1e3 * severiano_2013_precompression_kPa(clay, h)
        # the derived parameters from the day's values (the description's defaults where the set has none)
        desc = {s.name: s.default for s in SOIL_PARAMS if s.name in DESCRIPTION_KEYS}
        full = derive_soil({**desc, **{n: None for n in DERIVED_SOIL_PARAM_NAMES}, **out}, where)
        return {k: v for k, v in full.items() if k in out or k in DERIVED_SOIL_PARAM_NAMES}
    except ParameterError as err:
        raise ParameterError(f"{where}: {err}") from err


MAP_KEYS = ("raster", "compression_ptf", "clay_percent")
PATH_KEYS = (("terrain", "moisture", "raster"),)


@dataclasses.dataclass(frozen=True)
class MoistureMap:
    """The parsed ``[terrain.moisture]``: the raster's path and the PTF choices (module doc)."""

    raster: str
    ptf: dict
    raw: dict = dataclasses.field(compare=False, repr=False, default_factory=dict)


def parse_moisture_map(t) -> MoistureMap:
    """``[terrain.moisture]`` -> :class:`MoistureMap` (unknown keys and bad values raise)."""
    if not isinstance(t, dict):
        raise ScenarioError(f"terrain.moisture = {t!r} must be a table ({', '.join(MAP_KEYS)})")
    unknown = sorted(set(t) - set(MAP_KEYS))
    if unknown:
        raise ScenarioError(f"unknown key(s) in [terrain.moisture]: {', '.join(unknown)}; allowed: "
                            f"{', '.join(MAP_KEYS)}")
    r = t.get("raster")
    if not isinstance(r, str) or not (r.endswith(".npy") or gis.is_geotiff(r)):
        raise ScenarioError(f"terrain.moisture.raster = {r!r} must be the path of a .npy file of water contents "
                            f"(kg/kg) or of a GeoTIFF ({', '.join(gis.GEOTIFF_SUFFIXES)})")
    ptf = {k: t[k] for k in ("compression_ptf", "clay_percent") if k in t}
    if not ptf:
        raise ScenarioError("terrain.moisture needs compression_ptf or clay_percent (the pedotransfer functions)")
    return MoistureMap(r, ptf, dict(t))


def read_moisture(grid, mm: MoistureMap) -> np.ndarray:
    """The water content [kg/kg] of every cell (flat, i * ny + j): the .npy array (nx, ny) or the
    GeoTIFF's pixel holding each cell's centre; the raster must cover the field."""
    nx, ny = grid.shape
    where = "terrain.moisture.raster"
    if gis.is_geotiff(mm.raster):
        h = gis.read_header(mm.raster, where, values="real")
        gis.check_covers(h, grid, where)
        data = gis.read_band(mm.raster, where)
        xc, yc = grid.centres(np.arange(nx), np.arange(ny))
        col = np.clip(np.floor((xc - h.left_m) / h.pixel_x_m).astype(np.int64), 0, h.width - 1)
        row = np.clip(np.floor((h.top_m - yc) / h.pixel_y_m).astype(np.int64), 0, h.height - 1)
        w = data[row[None, :], col[:, None]].astype(np.float64)
        if h.nodata is not None and np.any(w == h.nodata):
            raise ScenarioError(f"{where} = {mm.raster!r}: {int(np.count_nonzero(w == h.nodata))} cell(s) of the "
                                f"field lie on nodata pixels: the raster must cover the field")
    else:
        w = gis.read_npy(mm.raster, where)
        if w.shape != (nx, ny) or w.dtype.kind not in "iuf":
            raise ScenarioError(f"{where} = {mm.raster!r}: an array of water contents of shape {(nx, ny)} (the "
                                f"field's cells along x, y) is needed, the file holds {w.dtype} {w.shape}: the "
                                f"raster must cover the field")
        w = w.astype(np.float64)
    if not np.all(np.isfinite(w)):
        raise ScenarioError(f"{where} = {mm.raster!r}: water contents must be finite")
    return w.ravel()


DAY_KEYS = ("virgin_line_N", "compression_index_lambda", "recompression_index_kappa", "precompression_stress_Pa",
            "specific_volume_min")


def distinct_pairs(index: np.ndarray, water: np.ndarray):
    """(the distinct (soil, water content) pairs (n, 2), each cell's row in them)."""
    pairs, inverse = np.unique(np.column_stack([index.astype(np.float64), water]), axis=0, return_inverse=True)
    return pairs, inverse.ravel()


# Python's float power elementwise: numpy's own pow differs from the C library's in the last bit for
# a few % of values (measured: numpy 2.4, x**3 on 1e5 values in [5, 30]: 5 % differ), and the per-cell
# parameters must equal apply_moisture's scalar ones bit for bit
_POW = np.frompyfunc(operator.pow, 2, 1)


def _pow(x, e):
    return _POW(np.asarray(x, dtype=np.float64), e).astype(np.float64)


def _poly_array(c, x):
    """:func:`_poly` over an array, in the same order of operations (the same numbers bit for bit)."""
    acc = 0.0
    for i, ci in enumerate(c):
        acc = acc + ci * _pow(x, i)
    return acc


def _day_arrays(soil: dict, w: np.ndarray, ptf: dict, where) -> dict:
    """:func:`apply_moisture`'s five day parameters over an array of water contents of one soil,
    vectorised in apply_moisture's order of operations. A value apply_moisture refuses is refused by
    it (called on the first such value, so the message is the same)."""
    rb, rs = float(soil["bulk_density_initial_Mg_per_m3"]), float(soil["particle_density_Mg_per_m3"])
    w_sat = saturation_water_content_kg_per_kg(rb, rs)
    name, clay = ptf.get("compression_ptf"), ptf.get("clay_percent")
    ok = np.isfinite(w) & (w >= 0.0) & (w <= w_sat)
    known = (name is None or name in _DEFOSSEZ) and (clay is None or (isinstance(clay, (int, float))
                                                                     and not isinstance(clay, bool)))
    out = {"specific_volume_min": saturation_specific_volume(w, rs)}
    if known and name is not None:
        lo, hi = DEFOSSEZ_RANGE_PERCENT
        wp = 100.0 * w
        ok &= (wp >= lo) & (wp <= hi)
        cN, cL = _DEFOSSEZ[name]
        out.update(virgin_line_N=_poly_array(cN, wp), compression_index_lambda=_poly_array(cL, wp),
                   recompression_index_kappa=np.full(w.shape, _DEFOSSEZ_KAPPA))
    if known and clay is not None:
        _, a, b, ts, tr, alpha, n = SEVERIANO_2013_CLASSES[clay_class(clay)]
        theta = w * rb / WATER_DENSITY_MG_PER_M3
        ok &= (theta > tr) & (theta < ts)
        m = 1.0 - 1.0 / n
        with np.errstate(all="ignore"):
            se = (theta - tr) / (ts - tr)
            se = np.where(ok, se, 0.5)  # (refused below; a value the power takes)
            h = _pow(_pow(se, -1.0 / m) - 1.0, 1.0 / n) / alpha
            ok &= np.isfinite(h) & (h > 0.0)
            out["precompression_stress_Pa"] = 1e3 * (a * _pow(np.where(ok, h, 1.0), b))
    bad = np.flatnonzero(~ok)
    if not known or bad.size:
        k = int(bad[0]) if bad.size else 0
        apply_moisture(soil, {**ptf, "water_content_kg_per_kg": float(w[k])}, where(float(w[k])))
        raise ParameterError(f"{where(float(w[k]))}: refused")  # (apply_moisture refuses it first)
    for k in DAY_KEYS:
        if k not in out:
            out[k] = np.full(w.shape, float(soil[k]))
    # the one strength (apply_moisture's order): Défossez's virgin line sets it where no clay_percent
    # does, and the virgin line always follows from it
    v0 = rs / rb
    lam, kap = out["compression_index_lambda"], out["recompression_index_kappa"]
    if name is not None and clay is None:
        out["precompression_stress_Pa"] = 1e3 * precompression_from_virgin_line_kPa(v0, out["virgin_line_N"], lam, kap)
    out["virgin_line_N"] = virgin_line_N_from_precompression(v0, lam, kap, out["precompression_stress_Pa"])
    return out


def cell_day_parameters(soils, index: np.ndarray, water: np.ndarray, mm: MoistureMap, pairs=None) -> dict:
    """Each cell's parameters on the day (``DAY_KEYS``, float64 arrays over the cells): the PTFs of
    ``mm`` at each distinct (soil, water content) pair, vectorised in :func:`apply_moisture`'s order of
    operations, so that a cell has bit for bit the numbers a soil of its pair would have
    (tests/test_moisture.py). ``soils``: the field's soils before (0 the scenario's), ``index`` each
    cell's; ``pairs``: :func:`distinct_pairs`' result if already made."""
    pairs, inverse = distinct_pairs(index, water) if pairs is None else pairs
    vals = {k: np.empty(len(pairs)) for k in DAY_KEYS}
    for si in np.unique(pairs[:, 0]):
        rows = np.flatnonzero(pairs[:, 0] == si)

        def where(w, si=si):
            return f"terrain.moisture (soil {int(si)}, cell water content {w!r})"

        try:
            day = _day_arrays(soils[int(si)], pairs[rows, 1], mm.ptf, where)
        except ParameterError as err:
            raise ScenarioError(str(err)) from err
        for k in DAY_KEYS:
            vals[k][rows] = day[k]
    bad = np.flatnonzero(~(vals["recompression_index_kappa"] < vals["compression_index_lambda"]))
    if bad.size:
        si, w = pairs[bad[0]]
        raise ScenarioError(f"terrain.moisture (soil {int(si)}, cell water content {float(w)!r}): kappa >= lambda")
    return {k: v[inverse] for k, v in vals.items()}


def split_soils(soils, labels, index: np.ndarray, water: np.ndarray, mm: MoistureMap, max_soils: int):
    """Every distinct (soil, water content) pair of the cells as a soil on its day: (labels, soil
    parameter sets, 1-based index of every cell into them). ``soils``/``labels``: the field's soils
    before (0 the scenario's), ``index`` each cell's. Refuses more than ``max_soils - 1`` pairs."""
    pairs, inverse = distinct_pairs(index, water)
    if len(pairs) > max_soils - 1:
        raise ScenarioError(f"terrain.moisture.raster = {mm.raster!r}: {len(pairs)} distinct (soil, water content) "
                            f"pairs; a field has at most {max_soils - 1} besides [soil]: round the raster's values "
                            "(e.g. to 0.01 kg/kg)")
    out_soils, out_labels = [], []
    for si, w in pairs:
        where = f"terrain.moisture (soil {int(si)}, cell water content {float(w)!r})"
        try:
            out_soils.append(apply_moisture(soils[int(si)], {**mm.ptf, "water_content_kg_per_kg": float(w)}, where))
        except ParameterError as err:
            raise ScenarioError(str(err)) from err
        out_labels.append(f"{labels[int(si)]} at w = {float(w):g}")
    return tuple(out_labels), tuple(out_soils), (inverse.ravel() + 1).astype(np.uint8)
