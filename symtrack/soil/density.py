"""Bulk density by depth from the stress history: O'Sullivan & Robertson's (1996) compression
model as SoilFlex (Keller et al. 2007) and COMPSOIL use it (docs/subsoil.md, "Bulk density").

The soil's state at a depth is its specific volume v = 1 + e = rho_s / rho_b (rho_s the particle
density, rho_b the dry bulk density). Against ln p (p the mean normal stress in kPa):

- the virgin compression line (VCL)   v = N - lambda ln p,
- a recompression line (RCL)          v = v1 - kappa ln p, v1 the line's specific volume at
  p = 1 kPa (ln p = 0),

the precompression stress p_c where the current RCL meets the VCL: ln p_c = (N - v1) / (lambda - kappa).
A load to p > p_c moves the soil down the VCL to p and its RCL to v1 = N - (lambda - kappa) ln p;
a load to p <= p_c moves it along its RCL and back (no change). So the whole state is v1, and
a pass that loads the soil to at most p_pass does

    v1 <- min(v1, N - (lambda - kappa) ln p_pass).

The density reported is the soil's after the load, back at the reference stress of the lines,
p = 1 kPa (ln p = 0): rho_b = rho_s / v1, as soilphysics' ``soilDeformation`` (the O'Sullivan &
Robertson model's R implementation; its yield-line parameters m and k2 are left out, i.e. m = 0:
the RCL meets the VCL directly). The initial state: v1 = rho_s / rho_initial (the soil's
``bulk_density_initial_Mg_per_m3``); the terrain stores v1 = 0 for "still the initial state"
(a cell never loaded beyond its initial precompression stress keeps 0 bit for bit; a field's
soils may differ: each cell's initial v1 is its soil's).

**The yield line (repeated passes).** O'Sullivan & Robertson's model has a third line, the yield
line (YL) v = N - lambda m - lambda ln p (the VCL moved by m along ln p, to lower stress), and a
steeper recompression slope k2 (kappa < k2 < lambda): an element on its RCL yields where the RCL meets
the YL, ln p_y = (N - lambda m - v1) / (lambda - kappa) (below the precompression stress p_c), and then
follows the k2 line from there, v = v1 - kappa ln p_y - k2 (ln p - ln p_y), until that meets the VCL
(beyond, the VCL). soilphysics' ``soilDeformation`` codes this for one load from the initial state
(parameters ``m``, ``k2``); here every load starts from the current RCL (the state is still v1 alone),
so a load to the same p again yields again at the new p_y: after a load to ln p = x,

    v1 <- v1 - (k2 - kappa) (x - ln p_y)     (ln p_y < x, on the k2 line),

and with d = v1 - v1_YL(x), v1_YL(x) = N - lambda m - (lambda - kappa) x (the RCL through the YL at x),
each pass at x multiplies d by r = (lambda - k2) / (lambda - kappa): n passes at a constant stress give
v1_n = v1_YL(x) + d_0 r^n (d_0 the initial state's, or lambda m after a first pass onto the VCL),
approaching the YL's density geometrically. m = 0 is the model without the yield line (the default;
the same numbers bit for bit). ln p_y is taken >= 0 (loads below the lines' reference stress of 1 kPa
change nothing, as without the yield line).

**The saturation bound.** Under load the soil cannot be denser than at zero air-filled porosity
(its water stays in it over a pass): v - kappa ln p >= v_min, v_min = 1 + w rho_s / rho_w for the
day's gravimetric water content w (``specific_volume_min``, set by [soil.moisture]; 1, zero
porosity, when the day's water content is not known), i.e. rho_b <= rho_s / (1 + w rho_s / rho_w)
under the load (after it, the recompression line's rebound).

p is the traffic's mean normal stress (symtrack/soil/subsoil.py: the trace of Soehne's
radial stress over 3) plus the soil's own weight above the depth (:func:`geostatic_table`), and the
rut bounds the column's compression (:func:`cap_to_rut`).

**Layers.** A soil with a subsoil described apart from its topsoil (``subsoil_*`` keys below
``subsoil_top_m``; symtrack/soil/pedotransfer.py) has at each depth its layer's lines, initial state
and strength (:func:`soil_arrays` with the depths): the state v1 = 0 stands for each depth's own
initial state, and the own weight sums the layers above.

Parameters per soil (symtrack/model/parameters.py, defaults with sources): ``virgin_line_N``,
``compression_index_lambda``, ``recompression_index_kappa``, ``particle_density_Mg_per_m3``,
``bulk_density_initial_Mg_per_m3``, ``yield_line_offset_ln_p`` (m; 0: no yield line, the default),
``yield_compression_index_k2``, ``specific_volume_min`` (the saturation bound; 1 by default);
:func:`keller_arvidsson_2007` is the pedotransfer function
of N and lambda from the initial specific volume the defaults come from.
"""

from __future__ import annotations

import math

import numpy as np

from ..foundations.errors import ParameterError
from ..model.parameters import SOIL_PARAMS, SPECIFIC_VOLUME_MIN_DEFAULT, YIELD_LINE_OFFSET_DEFAULT
from .pedotransfer import K2_POSITION_OSR, geostatic_profile_Pa, is_layered, layer_sets
from .pedotransfer import keller_arvidsson_2007 as keller_arvidsson_2007

__all__ = ["COMPRESSION_PARAM_NAMES", "bulk_density", "cap_to_rut", "column_compression_m", "field_max",
           "geostatic_table", "initial_specific_volume", "keller_arvidsson_2007", "layered", "load_update",
           "pass_update", "passes_at_constant_stress", "precompression_stress_kPa", "precompression_table",
           "soil_arrays", "specific_volume_after"]

COMPRESSION_PARAM_NAMES = ("virgin_line_N", "compression_index_lambda", "recompression_index_kappa",
                           "particle_density_Mg_per_m3", "bulk_density_initial_Mg_per_m3", "yield_line_offset_ln_p",
                           "yield_compression_index_k2", "specific_volume_min")

def initial_specific_volume(soil: dict) -> float:
    """rho_s / rho_initial of a soil's parameter set."""
    return float(soil["particle_density_Mg_per_m3"]) / float(soil["bulk_density_initial_Mg_per_m3"])


def _yield_params(soil: dict) -> tuple[float, float, float]:
    """(m, k2, v_min) of a soil (the registry's defaults where a parameter set lacks them)."""
    lam, kap = float(soil["compression_index_lambda"]), float(soil["recompression_index_kappa"])
    return (float(soil.get("yield_line_offset_ln_p", YIELD_LINE_OFFSET_DEFAULT)),
            float(soil.get("yield_compression_index_k2", kap + K2_POSITION_OSR * (lam - kap))),
            float(soil.get("specific_volume_min", SPECIFIC_VOLUME_MIN_DEFAULT)))


def _check_soil(soil: dict) -> None:
    lam, kap = float(soil["compression_index_lambda"]), float(soil["recompression_index_kappa"])
    if not kap < lam:
        raise ParameterError(f"recompression_index_kappa = {kap!r} must be below compression_index_lambda = "
                             f"{lam!r} (the recompression line is flatter than the virgin line)")
    m, k2, vmin = _yield_params(soil)
    if m > 0 and not kap < k2 < lam:
        raise ParameterError(f"yield_compression_index_k2 = {k2!r} is outside the allowed range ({kap!r}, {lam!r}) "
                             f"(between recompression_index_kappa and compression_index_lambda) with "
                             f"yield_line_offset_ln_p = {m!r} > 0")
    v0 = initial_specific_volume(soil)
    if not vmin <= v0:
        raise ParameterError(f"specific_volume_min = {vmin!r} is above the initial specific volume {v0!r} "
                             f"(rho_s / bulk_density_initial_Mg_per_m3): the soil would start beyond saturation")
    if not float(soil["bulk_density_initial_Mg_per_m3"]) < float(soil["particle_density_Mg_per_m3"]):
        raise ParameterError(f"bulk_density_initial_Mg_per_m3 = {soil['bulk_density_initial_Mg_per_m3']!r} must "
                             f"be below particle_density_Mg_per_m3 = {soil['particle_density_Mg_per_m3']!r}")


def soil_arrays(soils, depths_m=None) -> dict:
    """Per soil (index 0, 1, ... as the terrain's soil_index): arrays of N, lambda - kappa, lambda,
    kappa, m, k2, v_min, rho_s, the initial specific volume v1_0 (``v0``) and the precompression
    stress [Pa] (``pc``). Without ``depths_m`` one value per soil (n_soils,), its topsoil's; with them
    (n_soils, n_depths), each depth's layer (symtrack/soil/pedotransfer.py, ``layer_sets``), and
    ``top`` (bool): the depths in the soil's topsoil (every depth of a soil of one layer)."""
    if depths_m is None:
        sets = [[sp] for sp in soils]
    else:
        sets = [layer_sets(sp, depths_m) for sp in soils]
    for layers in sets:
        for sp in {id(x): x for x in layers}.values():
            _check_soil(sp)

    def table(f):
        t = np.array([[f(x) for x in layers] for layers in sets], dtype=np.float64).reshape(len(sets), -1)
        return t[:, 0] if depths_m is None else t

    lam = table(lambda x: float(x["compression_index_lambda"]))
    kap = table(lambda x: float(x["recompression_index_kappa"]))
    out = {"N": table(lambda x: float(x["virgin_line_N"])),
           "lambda_minus_kappa": table(lambda x: float(x["compression_index_lambda"])
                                       - float(x["recompression_index_kappa"])),
           "rho_s": table(lambda x: float(x["particle_density_Mg_per_m3"])), "v0": table(initial_specific_volume),
           "lambda": lam, "kappa": kap, "m": table(lambda x: _yield_params(x)[0]),
           "k2": table(lambda x: _yield_params(x)[1]), "v_min": table(lambda x: _yield_params(x)[2]),
           "pc": table(lambda x: float(x.get("precompression_stress_Pa", np.nan)))}
    if depths_m is not None:
        out["top"] = np.array([[x is sp for x in layers] for sp, layers in zip(soils, sets, strict=True)],
                              dtype=bool).reshape(len(sets), -1)
    return out


def layered(soils) -> bool:
    """True when any of the soils has a subsoil layer of its own."""
    return any(is_layered(sp) for sp in soils)


def load_update(v_old, ln_p, N, lam, kap, lk, m, k2, v_min):
    """The new v1 (float64 arrays, broadcast) after a load to ln(p / kPa) = ``ln_p`` from v1 = ``v_old``
    (module doc): the virgin line's N - (lambda - kappa) ln p, with m > 0 the yield line's k2 path, the
    saturation bound v_min + kappa ln p, and never above v_old. Where m == 0 and the bound is not
    reached, exactly the model without them (the same operations)."""
    cand = N - lk * ln_p
    if np.any(np.asarray(m) > 0):  # (without a yield line anywhere, skip its arithmetic: the same result)
        with np.errstate(invalid="ignore"):
            xy = np.maximum((N - lam * m - v_old) / lk, 0.0)
            k2line = v_old - (k2 - kap) * (ln_p - xy)
        yl = np.where(ln_p > xy, np.minimum(cand, k2line), v_old)
        cand = np.where(m > 0, yl, cand)
    cand = np.maximum(cand, v_min + kap * ln_p)
    return np.minimum(cand, v_old)


def specific_volume_after(v1, N, lambda_minus_kappa, p_kPa):
    """v1 after a load to mean normal stress p_kPa (> 0): min(v1, N - (lambda - kappa) ln p)."""
    return np.minimum(v1, N - lambda_minus_kappa * np.log(p_kPa))


def precompression_stress_kPa(v1, N, lambda_minus_kappa):
    """The mean normal stress where the recompression line of v1 meets the virgin line [kPa]."""
    return np.exp((np.asarray(N) - np.asarray(v1)) / np.asarray(lambda_minus_kappa))


def pass_update(specific_volume: np.ndarray, pass_p_Pa: np.ndarray, soil_index: np.ndarray, soils,
                cells: np.ndarray | None = None, cell_params: dict | None = None,
                geostatic_Pa: np.ndarray | None = None, depths_m=None, arrays: dict | None = None) -> int:
    """Fold one pass into the terrain's state: ``specific_volume`` (n_cells, n_depths) float32
    (0: the soil's initial state), ``pass_p_Pa`` the pass's largest mean normal stress per cell
    and depth (0 where the pass did not load); ``cells``: the cells the pass may have loaded (a
    superset; default: every cell with a stress > 0). In place; returns the number of (cell, depth)
    entries that moved down the virgin line. Cells not loaded are not touched. ``cell_params``: each
    cell's own ``virgin_line_N``, ``compression_index_lambda`` and ``recompression_index_kappa``
    (float64 arrays over all cells: a moisture map of many values, soil/moisture.py) instead of its
    soil's; the initial state (rho_s / rho_initial) stays the soil's. ``geostatic_Pa`` (n_soils,
    n_depths): the soil's own weight at each depth, added to the pass's stress where the pass loaded
    (:func:`geostatic_table`). ``depths_m``: the terrain's subsoil depths, needed for a layered soil
    (each depth's layer's lines; :func:`soil_arrays`); ``arrays``: :func:`soil_arrays` of ``soils`` at the
    depths when the caller keeps them (a world: once per field, not per pass)."""
    if specific_volume.shape != pass_p_Pa.shape:
        raise ParameterError(f"pass_p_Pa has shape {pass_p_Pa.shape}, the terrain's specific volume "
                             f"{specific_volume.shape}")
    if pass_p_Pa.size == 0:
        return 0
    if cells is None:
        cells = np.unique(np.flatnonzero(pass_p_Pa.ravel() > 0) // pass_p_Pa.shape[1])
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return 0
    # per (soil, depth): a layered soil's subsoil has its own lines (depths_m needed then)
    a = arrays if arrays is not None else _depth_arrays(soils, depths_m, pass_p_Pa.shape[1])
    si = soil_index[cells]
    p = pass_p_Pa[cells].astype(np.float64)
    if geostatic_Pa is not None:
        p = np.where(p > 0, p + np.asarray(geostatic_Pa, dtype=np.float64)[si], p)
    old = specific_volume[cells].astype(np.float64)
    v_old = np.where(old > 0, old, a["v0"][si])
    N, lk = a["N"][si], a["lambda_minus_kappa"][si]
    lam, kap, vmin = a["lambda"][si], a["kappa"][si], a["v_min"][si]
    if cell_params is not None:  # the day's values of each cell: its topsoil's depths
        top = a["top"][si]
        N = np.where(top, cell_params["virgin_line_N"][cells][:, None], N)
        lam = np.where(top, cell_params["compression_index_lambda"][cells][:, None], lam)
        kap = np.where(top, cell_params["recompression_index_kappa"][cells][:, None], kap)
        lk = lam - kap
        if "specific_volume_min" in cell_params:
            vmin = np.where(top, cell_params["specific_volume_min"][cells][:, None], vmin)
    with np.errstate(divide="ignore"):
        lnp = np.log(1e-3 * p)
    with np.errstate(invalid="ignore"):
        line = load_update(v_old, lnp, N, lam, kap, lk, a["m"][si], a["k2"][si], vmin)
    yielded = (p > 0) & (line < v_old)
    rows = np.flatnonzero(yielded.any(axis=1))
    if rows.size:  # only the cells that yielded are written (the others keep their bits)
        specific_volume[cells[rows]] = np.where(yielded[rows], line[rows], old[rows]).astype(np.float32)
    return int(np.count_nonzero(yielded))


def _depth_arrays(soils, depths_m, nd: int) -> dict:
    """:func:`soil_arrays` as (n_soils, nd) tables: at ``depths_m`` (each depth's layer), or without depths
    every depth the topsoil's (:func:`_per_depth`)."""
    return soil_arrays(soils, depths_m) if depths_m is not None else _per_depth(soil_arrays(soils), nd, soils)


def _per_depth(a: dict, nd: int, soils) -> dict:
    """:func:`soil_arrays` without depths, spread to (n_soils, nd) (every depth the topsoil's); refuses
    a layered soil (its depths are needed)."""
    if layered(soils):
        raise ParameterError("a soil with a subsoil layer needs the subsoil depths (depths_m) to fold a pass")
    out = {k: np.repeat(v[:, None], nd, axis=1) for k, v in a.items()}
    out["top"] = np.ones((len(soils), nd), dtype=bool)
    return out


def column_compression_m(v1, v0, depths_m) -> np.ndarray:
    """How far each cell's column has shortened [m]: the integral over depth of its vertical strain
    1 - rho0/rho = 1 - v1/v0 (mass conservation of a column that densifies from rho0 to rho), by the
    trapezoid rule over (0, depths), the strain at the surface taken as at the first depth and none
    below the last. ``v1`` (n_cells, n_depths) float64 (the state, the initial v0 where unmoved),
    ``v0`` (n_cells,) or per cell and depth (n_cells, n_depths) (a layered soil)."""
    v0 = np.asarray(v0, dtype=np.float64)
    strain = 1.0 - v1 / (v0 if v0.ndim == 2 else v0[:, None])
    total = strain[:, 0] * float(depths_m[0])
    for k in range(1, len(depths_m)):
        total = total + 0.5 * (strain[:, k - 1] + strain[:, k]) * (float(depths_m[k]) - float(depths_m[k - 1]))
    return total


def cap_to_rut(specific_volume: np.ndarray, cells: np.ndarray, v0: np.ndarray, depths_m, rut_m: np.ndarray,
               before: np.ndarray | None = None) -> int:
    """The rut bounds the compression below it (docs/subsoil.md, "One soil"): a column cannot shorten
    more than its surface sank (nothing heaves under the track; the rest of the rut is soil that flowed
    aside). Where a cell's :func:`column_compression_m` exceeds its plastic rut ``rut_m`` (its stored
    sinkage, >= 0), the compression the pass added is scaled back, at every depth by the same fraction,
    until the column's compression is the rut: from the state ``before`` the pass (the stored values of
    ``cells`` before :func:`pass_update`; None: the initial state), so that what an earlier pass compressed
    is never undone (a depth's density never decreases under a further load; where the column was at its
    rut already, the pass adds nothing). ``cells``, ``v0`` (per cell, or per cell and depth for a layered
    soil), ``rut_m`` and ``before`` aligned. In place; returns the number of cells scaled. A depth at its
    initial state keeps its stored value (0) bit for bit."""
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0 or specific_volume.shape[1] == 0:
        return 0
    old = specific_volume[cells].astype(np.float64)
    v0 = np.asarray(v0, dtype=np.float64)
    v0 = v0 if v0.ndim == 2 else np.repeat(v0[:, None], old.shape[1], axis=1)
    v = np.where(old > 0, old, v0)
    comp = column_compression_m(v, v0, depths_m)
    rut = np.maximum(np.asarray(rut_m, dtype=np.float64), 0.0)
    over = np.flatnonzero(comp > rut)
    if over.size == 0:
        return 0
    if before is None:
        vb, cb = v0[over], np.zeros(over.size)
    else:
        b = np.asarray(before)[over].astype(np.float64)
        vb = np.where(b > 0, b, v0[over])
        cb = column_compression_m(vb, v0[over], depths_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(comp[over] > cb, np.clip((rut[over] - cb) / (comp[over] - cb), 0.0, 1.0), 0.0)
    scaled = vb - f[:, None] * (vb - v[over])
    specific_volume[cells[over]] = np.where(old[over] > 0, scaled, old[over]).astype(np.float32)
    return int(over.size)


def geostatic_table(soils, depths_m) -> np.ndarray:
    """(n_soils, n_depths) float64: each soil's own weight at each depth [Pa] (the vertical stress of
    the moist soil above, through its layers: symtrack/soil/pedotransfer.py), which :func:`pass_update`
    and the risk add to the traffic's vertical stress."""
    defaults = {s.name: s.default for s in SOIL_PARAMS if s.default is not None}
    return np.array([geostatic_profile_Pa({**defaults, **sp}, depths_m) for sp in soils],
                    dtype=np.float64).reshape(len(soils), len(depths_m))


def precompression_table(soils, depths_m) -> np.ndarray:
    """(n_soils, n_depths) float64: each soil's precompression stress at each depth [Pa] (its layer's:
    the strength the risk grades against and where the density model yields)."""
    return soil_arrays(soils, depths_m)["pc"]


def bulk_density(specific_volume: np.ndarray, soil_index: np.ndarray, soils, depths_m=None) -> np.ndarray:
    """Dry bulk density [Mg/m^3] per cell and depth after the loads so far, at the lines' reference
    stress (1 kPa): rho_s / v1, v1 the stored one or the soil's initial one where 0 (at each depth its
    layer's: ``depths_m`` needed for a layered soil)."""
    nd = specific_volume.shape[1]
    a = _depth_arrays(soils, depths_m, nd)
    v = specific_volume.astype(np.float64)
    v = np.where(v > 0, v, a["v0"][soil_index])
    return a["rho_s"][soil_index] / v


def field_max(specific_volume: np.ndarray, soil_index: np.ndarray, soils, depths_m=None) -> list[float]:
    """The field's largest bulk density [Mg/m^3] at each depth: over the cells whose state moved
    (v1 > 0) and the initial density of every soil the field has (without a pass over the whole
    field's densities: a million cells, mostly initial). ``depths_m`` as in :func:`bulk_density`."""
    nd = specific_volume.shape[1]
    a = _depth_arrays(soils, depths_m, nd)
    present = np.flatnonzero(np.bincount(soil_index, minlength=len(soils)) > 0)
    out = ((a["rho_s"][present] / a["v0"][present]).max(axis=0) if present.size else np.zeros(nd))
    moved = np.unique(np.flatnonzero(specific_volume.ravel() > 0) // nd)
    if moved.size:
        rho = bulk_density(specific_volume[moved], soil_index[moved], soils, depths_m)
        out = np.maximum(out, rho.max(axis=0))
    return [float(v) for v in out]



def passes_at_constant_stress(soil: dict, p_kPa: float, n: int) -> list[float]:
    """The closed form of ``n`` loads to the same mean normal stress p from the soil's initial state
    (module doc), float64, without the saturation bound: v1 after each load. The first load by the
    three lines (RCL, k2 line, VCL, as soilphysics' soilDeformation); after it, on the k2 line,
    v1_n = v1_YL + (v1_1 - v1_YL) r^(n - 1), r = (lambda - k2) / (lambda - kappa). Needs the yield
    point of every later load above 1 kPa (ln p_y > 0), which holds for ln p > lambda m / (lambda - kappa)."""
    _check_soil(soil)
    N, lam, kap = (float(soil[k]) for k in ("virgin_line_N", "compression_index_lambda", "recompression_index_kappa"))
    m, k2, _ = _yield_params(soil)
    x, v0 = math.log(p_kPa), initial_specific_volume(soil)
    if m == 0:
        return [min(v0, N - (lam - kap) * x)] * n
    if not x > lam * m / (lam - kap):
        raise ParameterError(f"p_kPa = {p_kPa!r}: the closed form needs ln p > lambda m / (lambda - kappa) = "
                             f"{lam * m / (lam - kap):.6g}")
    xy = (N - lam * m - v0) / (lam - kap)  # the initial RCL meets the YL
    xj = (N - v0 - (k2 - kap) * xy) / (lam - k2)  # the k2 line meets the VCL
    if x <= xy:
        v1 = v0
    elif x <= xj:
        v1 = v0 - (k2 - kap) * (x - xy)
    else:
        v1 = N - (lam - kap) * x
    v_yl = N - lam * m - (lam - kap) * x
    r = (lam - k2) / (lam - kap)
    if v1 == v0:
        return [v0] * n
    return [v_yl + (v1 - v_yl) * r**k for k in range(n)]
