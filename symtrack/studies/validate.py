"""The validation gallery: published measurements of real soil under real machines, each reproduced
by the package's own models (docs/validation.md; ``symtrack validate``).

A **case** is a TOML file in ``symtrack/studies/validation_cases/`` (or any file given by path):

- ``title``, ``model`` (a name of :data:`MODELS`), ``kind`` (the kind of quantity the summary groups
  errors by; a kind ending in ``_empirical`` compares with a published empirical relation, not a
  measurement), ``calibration`` (true when a parameter was fitted to this case's own data),
  ``findings`` (what the comparison shows: where it misses by more than the spread and the band,
  whether the physics or an assumption seems at fault), ``line_points`` (optional: the points of
  the figure's prediction line, :data:`LINE_POINTS` unless given; fewer for a costly model);
- ``[source]``: ``citation``, ``page``, ``table`` and ``measured_as`` (what the number is);
- ``[measured]``: ``quantity``, ``unit``, ``x_name`` (what the points are taken at, with its unit),
  ``x`` and ``values`` (the measured points), ``spread`` (one per point where the source gives
  one, else empty) and, for points that are categories, ``x_labels`` (their names; x then 1, 2, ...);
- ``[reference.NAME]``: other models' predictions printed beside the measurements (``x``, ``values``
  in the measured unit), shown, never used;
- ``[setup]``: the values the source gives (the model's fixed inputs);
- ``[assumptions.NAME]``: every value the source does not give, with ``value``, ``reason`` and
  either ``range = [low, high]`` and ``unit`` (a number) or ``choices`` and
  ``alternatives.CHOICE`` (a named alternative: a table of setup values it replaces).

:func:`run_case` runs the model once with every assumption at its value (the prediction), then once
at each end of each range and once per alternative, the others at their values: the **band** is the
smallest and largest of those runs at each point, and each run's prediction is kept (what each
assumption does). Nothing is fitted here: a model takes its setup and assumptions as they are.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import math
import tomllib
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..foundations import caches
from ..foundations.config import check_keys, number
from ..foundations.errors import ScenarioError
from ..foundations.files import read_text
from ..soil import density, subsoil
from ..soil.pedotransfer import GRAVITY_M_S2, WATER_DENSITY_MG_PER_M3
from ..vehicles import tyre
from . import traffic_seasons, validate_vehicle

__all__ = ["CASES_DIR", "CSV_COLUMNS", "LINE_POINTS", "MODELS", "SCHEMA_VERSION", "SENSITIVITY_COLUMNS", "Case",
           "CaseResult", "case_names", "density_change_vs_contact_pressure", "load_case", "markdown_tables",
           "resolve_cases",
           "run_case", "sensitivity_csv", "summary_rows", "track_stress_by_depth", "traffic_shares",
           "tyre_stress_by_depth", "validation_csv"]

SCHEMA_VERSION = 1
CASES_DIR = Path(__file__).resolve().parent / "validation_cases"

# validation.csv: one row per measured point (docs/validation.md, "validation.csv"); then one
# ref_<NAME> column per reference model that any case prints (empty where a case has none)
CSV_COLUMNS = ("case", "quantity", "depth_or_pass", "x_name", "measured", "predicted", "error", "relative_error",
               "band_low", "band_high", "unit", "kind", "calibration")
SENSITIVITY_COLUMNS = ("case", "assumption", "end", "assumed", "depth_or_pass", "predicted", "unit")

CASE_KEYS = ("title", "model", "kind", "calibration", "findings", "line_points", "source", "measured", "reference",
             "setup", "assumptions")
SOURCE_KEYS = ("citation", "page", "table", "measured_as")
MEASURED_KEYS = ("quantity", "unit", "x_name", "x", "x_labels", "values", "spread")
ASSUMPTION_KEYS = ("value", "range", "unit", "reason", "choices", "alternatives")
# the points a prediction line is drawn through (figures), per case
LINE_POINTS = 25
KPA = 1e3
# the side of the square elements a uniform rectangular contact is cut into (density cases)
FOOTPRINT_ELEMENT_M = 0.02


# ---------------------------------------------------------------------------------------------
# the models: each takes the setup (source values and the alternatives' replacements), the
# assumptions' values and the points x, and returns the prediction at x in the measured unit

def _track_frame_points(length_m, fraction, n=80):
    """Midpoints of n equal steps over the window [-fraction l/2, fraction l/2] along the driving direction."""
    half = 0.5 * fraction * length_m
    edges = np.linspace(-half, half, n + 1)
    return 0.5 * (edges[:-1] + edges[1:])


def _value(setup: dict, a: dict, name: str, default=None):
    """An input a case gives as an assumption or, failing that, in its setup (else the default)."""
    return a.get(name, setup.get(name, default))


def _rigid_base(setup: dict, a: dict):
    """The rigid base under the soil layer: (``rigid_base_depth_m`` or None for a half-space,
    ``rigid_base_interface``), each an assumption or a setup value."""
    H = _value(setup, a, "rigid_base_depth_m")
    return (None if H is None else float(H)), str(_value(setup, a, "rigid_base_interface", "rough"))


def _face_points(diameter_m: float):
    """Offsets (dx, dy) [m] and weights (sum 1) over a disc of diameter_m, the transducer's face over
    which its reading averages the vertical stress: Radon's seven-point rule, exact for polynomials
    of degree 5 (the centre 1/4; six points at sqrt(2/3) of the radius, 1/8 each;
    Radon 1948). One point when the diameter is 0."""
    if diameter_m <= 0.0:
        return np.zeros(1), np.zeros(1), np.ones(1)
    r = 0.5 * diameter_m * math.sqrt(2.0 / 3.0)
    th = np.pi / 3.0 * np.arange(6)
    return (np.concatenate([[0.0], r * np.cos(th)]), np.concatenate([[0.0], r * np.sin(th)]),
            np.array([0.25] + [0.125] * 6))


def _fold_y(dx, dy, w):
    """The face's points for a field symmetric in y about the points' line: each (dx, -dy) merged
    into (dx, dy), its weight added."""
    keys = [(round(float(x), 12), round(abs(float(y)), 12)) for x, y in zip(dx, dy, strict=True)]
    merged: dict = {}
    for k, wk in zip(keys, w, strict=True):
        merged[k] = merged.get(k, 0.0) + float(wk)
    return (np.array([k[0] for k in merged]), np.array([k[1] for k in merged]), np.array(list(merged.values())))


def _in_layer(depths_m, base_m):
    """The depths as an array and the mask of those in the soil layer (all without a base)."""
    d = np.atleast_1d(np.asarray(depths_m, dtype=float))
    return d, (np.ones(d.shape, bool) if base_m is None else d <= base_m * (1.0 + 1e-12))


def track_stress_by_depth(setup: dict, a: dict, depths_m) -> np.ndarray:
    """Vertical stress [kPa] at ``depths_m`` below the middle of one rigid track unit of length
    ``a["contact_length_m"]`` and width ``a["track_width_m"]`` carrying ``setup["load_kN"]`` at uniform
    pressure, averaged over the passage window (``a["averaging_window_fraction"]`` of the contact
    length, centred on the track): :func:`symtrack.soil.subsoil.stress_at` on the engine's tables
    (concentration factor ``a["xi"]``); the second track of the tables is left unloaded. Optional
    inputs (assumptions or setup values): ``rigid_base_depth_m`` and ``rigid_base_interface``, a
    rigid base under the soil (NaN below it); ``transducer_face_diameter_m``, the stress averaged
    over the transducer's face (:func:`_face_points`)."""
    l_m, b_m = float(a["contact_length_m"]), float(a["track_width_m"])
    p_Pa = float(setup["load_kN"]) * KPA / (l_m * b_m)
    gauge_m = b_m  # the unloaded second track beside it: nothing of it enters the sum
    base_m, interface = _rigid_base(setup, a)
    depths, inside = _in_layer(depths_m, base_m)
    out = np.full(depths.shape, np.nan)
    if not inside.any():
        return out
    T = subsoil.build_tables(tuple(float(d) for d in depths[inside]), float(a["xi"]), l_m, b_m, gauge_m,
                             rigid_base_depth_m=base_m, rigid_base_interface=interface)
    pose = (0.0, 0.0, 1.0, 0.0, p_Pa, 0.0, 0.0, 0.0)  # left track loaded, uniform; right track unloaded
    geo = (l_m, b_m, gauge_m, 0.0, 0.1, 0.0)
    px = _track_frame_points(l_m, float(a["averaging_window_fraction"]))
    py = np.full(px.shape, gauge_m / 2 + float(setup.get("lateral_offset_m", 0.0)))
    face = float(_value(setup, a, "transducer_face_diameter_m", 0.0))
    if face > 0.0:
        dx, dy, w = _face_points(face)
        s = subsoil.stress_at(T, (px[:, None] + dx).ravel(), (py[:, None] + dy).ravel(), pose, geo)
        out[inside] = np.einsum("pfk,f->pk", s.reshape(px.size, w.size, -1), w).mean(axis=0) / KPA
    else:
        out[inside] = subsoil.stress_at(T, px, py, pose, geo).mean(axis=0) / KPA
    return out


def tyre_stress_by_depth(setup: dict, a: dict, depths_m) -> np.ndarray:
    """Vertical stress [kPa] at ``depths_m`` below the middle of a tyre (Keller's 2005 contact,
    :func:`symtrack.vehicles.tyre.contact`; Söhne / Fröhlich summed over it with concentration factor
    ``a["xi"]``), averaged over the passage window (``a["averaging_window_fraction"]`` of the contact
    length). The tyre is rated so that ``a["recommended_inflation_kPa"]`` is its recommended pressure at
    the wheel load. The optional inputs of :func:`track_stress_by_depth` (a rigid base, the
    transducer's face) act the same way."""
    W = float(setup["wheel_load_kN"])
    p_i, p_rec = float(setup["inflation_kPa"]), float(a["recommended_inflation_kPa"])
    # the package's inflation rule p = p_max (W / W_max)^1.25 gives p_rec at W for the rated load
    t = validate_vehicle.rated_tyre(float(setup["tyre_width_m"]), float(a["tyre_diameter_m"]), W, p_i, p_rec)
    c = tyre.contact(t, W, p_i)
    px = _track_frame_points(c.length_m, float(a["averaging_window_fraction"]), n=40)
    py = np.full(px.shape, float(setup.get("lateral_offset_m", 0.0)))
    base_m, interface = _rigid_base(setup, a)
    depths, inside = _in_layer(depths_m, base_m)
    out = np.full(depths.shape, np.nan)
    if not inside.any():
        return out
    dx, dy, w = _face_points(float(_value(setup, a, "transducer_face_diameter_m", 0.0)))
    if float(setup.get("lateral_offset_m", 0.0)) == 0.0:  # Keller's contact is symmetric in y: fold the face
        dx, dy, w = _fold_y(dx, dy, w)
    sz, _ = tyre.footprint_stress_at_depth(c.x_m, c.y_m, c.force_kN, (px[:, None] + dx).ravel(),
                                           (py[:, None] + dy).ravel(), tuple(float(d) for d in depths[inside]),
                                           float(a["xi"]), rigid_base_depth_m=base_m, rigid_base_interface=interface,
                                           mean_stress=False)
    out[inside] = np.einsum("pfk,f->pk", sz.reshape(px.size, w.size, -1), w).mean(axis=0)
    return out


def density_change_vs_contact_pressure(setup: dict, a: dict, pressures_kPa) -> np.ndarray:
    """Mean increase in dry bulk density [%] over the profile [profile_top_m, a["profile_bottom_m"]]
    below the middle of a uniform rectangular contact of ``a["load_kN"]`` at each mean contact
    pressure (width ``a["footprint_width_m"]``, length load / (pressure width)), after one pass:
    the mean normal stress below the contact's centre (the largest of the pass; Fröhlich's radial
    stress, :func:`symtrack.vehicles.tyre.footprint_stress_at_depth` over the contact cut into
    ``FOOTPRINT_ELEMENT_M`` squares) plus the soil's own weight, folded into O'Sullivan & Robertson's
    compression model (:func:`symtrack.soil.density.pass_update`) of the soil given by the virgin
    line (``virgin_line_N``, ``compression_index_lambda``), kappa, the particle and initial densities,
    the saturation bound of the water content, and the yield line of the package's defaults (or the
    setup's ``yield_line_offset_ln_p``)."""
    rho0 = float(a["bulk_density_initial_Mg_per_m3"])
    w = float(setup["gravimetric_water_content"])
    soil = density_soil(setup, a)
    depths = profile_depths(setup, a)
    geostatic_Pa = rho0 * (1.0 + w) * KPA * GRAVITY_M_S2 * depths  # the moist soil above each depth
    b_m, load_kN = float(a["footprint_width_m"]), float(a["load_kN"])
    out = []
    for p_kPa in np.atleast_1d(np.asarray(pressures_kPa, dtype=float)):
        l_m = load_kN / (p_kPa * b_m)
        nx, ny = (max(2, int(math.ceil(s / FOOTPRINT_ELEMENT_M))) for s in (l_m, b_m))
        xc = (np.arange(nx) + 0.5) * (l_m / nx) - l_m / 2
        yc = (np.arange(ny) + 0.5) * (b_m / ny) - b_m / 2
        X, Y = np.meshgrid(xc, yc, indexing="ij")
        force_kN = np.full(X.size, load_kN / X.size)
        _, pm_kPa = tyre.footprint_stress_at_depth(X.ravel(), Y.ravel(), force_kN, [0.0], [0.0], tuple(depths),
                                                   float(a["xi"]))
        v = np.zeros((1, depths.size), dtype=np.float32)
        density.pass_update(v, pm_kPa * KPA, np.zeros(1, dtype=np.int64), [soil], geostatic_Pa=geostatic_Pa[None, :])
        rho = density.bulk_density(v, np.zeros(1, dtype=np.int64), [soil])[0]
        increase = 100.0 * (rho / rho0 - 1.0)
        out.append(float(np.trapezoid(increase, depths) / (depths[-1] - depths[0])))
    return np.array(out)


def density_soil(setup: dict, a: dict) -> dict:
    """The density model's soil (:mod:`symtrack.soil.density`) of a density case's setup and assumptions."""
    rho_s = float(a["particle_density_Mg_per_m3"])
    return {"virgin_line_N": float(setup["virgin_line_N"]),
            "compression_index_lambda": float(setup["compression_index_lambda"]),
            "recompression_index_kappa": float(a["recompression_index_kappa"]),
            "particle_density_Mg_per_m3": rho_s,
            "bulk_density_initial_Mg_per_m3": float(a["bulk_density_initial_Mg_per_m3"]),
            "specific_volume_min": 1.0 + float(setup["gravimetric_water_content"]) * rho_s / WATER_DENSITY_MG_PER_M3,
            # O'Sullivan & Robertson's yield line: the package's default (model/parameters.py) unless the setup
            # gives one (a case's alternative)
            **({"yield_line_offset_ln_p": float(setup["yield_line_offset_ln_p"])}
               if "yield_line_offset_ln_p" in setup else {})}


def profile_depths(setup: dict, a: dict) -> np.ndarray:
    """The depths [m] a density case averages over."""
    return np.linspace(float(setup["profile_top_m"]), float(a["profile_bottom_m"]), int(setup["profile_points"]))


@functools.lru_cache(maxsize=16)
def _season_shares(length_m: float, width_m: float, cell_m: float, random_offset_m: float) -> dict:
    """{system: its row of :func:`symtrack.studies.traffic_seasons.system_table`} for one field and
    random offset (the operations that keep their own offset, the plough's, keep it)."""
    systems = {k: [op if "random_offset_m" in op else {**op, "random_offset_m": random_offset_m} for op in ops]
               for k, ops in traffic_seasons.SEASONS.items()}
    rows, _ = traffic_seasons.system_table((length_m, width_m), cell_m, systems)
    return {r["system"]: r for r in rows}


def traffic_shares(setup: dict, a: dict, x) -> np.ndarray:
    """The share of the field [%] a season's wheels run over (``setup["share"]``, a figure of
    :func:`symtrack.studies.traffic_seasons.season_shares`) for the systems ``setup["systems"][x - 1]``:
    the package's seasons of wheeled machines (:data:`traffic_seasons.SEASONS`, every machine and
    sequence assumed there) on a ``a["field_length_m"]`` field, ``setup["field_aspect"]`` times as long as
    wide, with every operation's lines moved by up to ``a["random_offset_m"]``."""
    length = float(a["field_length_m"])
    rows = _season_shares(length, length / float(setup["field_aspect"]), float(setup["cell_m"]),
                          float(a["random_offset_m"]))
    systems = list(setup["systems"])
    return np.array([100.0 * float(rows[systems[int(round(k)) - 1]][setup["share"]]) for k in np.atleast_1d(x)])


MODELS: dict[str, Callable] = {
    "track_stress_by_depth": track_stress_by_depth,
    "tyre_stress_by_depth": tyre_stress_by_depth,
    "density_change_vs_contact_pressure": density_change_vs_contact_pressure,
    "traffic_shares": traffic_shares,
    "track_traction_at_max_efficiency": validate_vehicle.track_traction_at_max_efficiency,
    "track_traction_at_slip": validate_vehicle.track_traction_at_slip,
    "track_motion_resistance": validate_vehicle.track_motion_resistance,
    "steady_turn_resistance_ratio": validate_vehicle.steady_turn_resistance_ratio,
    "track_unit_sinkage": validate_vehicle.track_unit_sinkage,
    "combine_rut_depth": validate_vehicle.combine_rut_depth,
}


# ---------------------------------------------------------------------------------------------
# the case files

@dataclasses.dataclass(frozen=True)
class Assumption:
    """One assumed value: a number with its range and unit, or a named choice among alternatives."""

    name: str
    value: float | str
    reason: str
    unit: str = ""
    range: tuple[float, float] | None = None
    alternatives: dict | None = None  # choice -> setup values it replaces (the nominal choice: none)

    def ends(self) -> list[tuple[str, float | str]]:
        """The runs of the band: (label, value) at each end of the range, or each other choice."""
        if self.range is not None:
            return [("low", self.range[0]), ("high", self.range[1])]
        return [(c, c) for c in self.alternatives]


@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    path: Path
    title: str
    model: str
    kind: str
    calibration: bool
    findings: str
    source: dict
    quantity: str
    unit: str
    x_name: str
    x: np.ndarray
    measured: np.ndarray
    spread: np.ndarray | None
    x_labels: tuple | None  # names of the points when they are categories (x then 1, 2, ...)
    references: dict  # name -> (x array, values array)
    setup: dict
    assumptions: tuple[Assumption, ...]
    line_points: int = LINE_POINTS

    def nominal(self) -> dict:
        return {a.name: a.value for a in self.assumptions}


def _numbers(where: str, v, n: int | None = None) -> np.ndarray:
    if not isinstance(v, list) or not all(isinstance(e, (int, float)) and not isinstance(e, bool) for e in v):
        raise ScenarioError(f"{where} = {v!r} must be a list of numbers")
    if n is not None and len(v) != n:
        raise ScenarioError(f"{where} has {len(v)} values; expected {n} (one per measured point)")
    arr = np.array(v, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ScenarioError(f"{where} = {v!r} must hold finite numbers")
    return arr


def _text(where: str, v) -> str:
    if not isinstance(v, str) or not v.strip():
        raise ScenarioError(f"{where} is required: a non-empty text")
    return v


def _assumption(case: str, name: str, t) -> Assumption:
    where = f"{case}: assumptions.{name}"
    check_keys(f"assumptions.{name}", t, ASSUMPTION_KEYS)
    reason = _text(f"{where}.reason", t.get("reason"))
    if "range" in t:
        r = _numbers(f"{where}.range", t["range"], 2)
        if not r[0] < r[1]:
            raise ScenarioError(f"{where}.range = {t['range']!r} must be [low, high] with low < high")
        v = number(f"{where}.value", t.get("value"), float(r[0]), float(r[1]))
        return Assumption(name, v, reason, _text(f"{where}.unit", t.get("unit")), (float(r[0]), float(r[1])))
    choices = t.get("choices")
    if not isinstance(choices, list) or len(choices) < 2 or not all(isinstance(c, str) for c in choices):
        raise ScenarioError(f"{where} needs range = [low, high] (a number) or choices = [at least two names]")
    if t.get("value") not in choices:
        raise ScenarioError(f"{where}.value = {t.get('value')!r} is not one of its choices {choices!r}")
    alts = t.get("alternatives", {})
    others = [c for c in choices if c != t["value"]]
    if not isinstance(alts, dict) or sorted(alts) != sorted(others):
        raise ScenarioError(f"{where}.alternatives must hold a table for each choice but the value: {others!r}")
    return Assumption(name, t["value"], reason, str(t.get("unit", "")), None, {c: dict(alts[c]) for c in others})


def load_case(path) -> Case:
    """A case file -> :class:`Case`; every missing or bad field raises a one-line ScenarioError."""
    path = Path(path)
    name = path.stem
    try:
        doc = tomllib.loads(read_text(path, "validation case"))
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"validation case {str(path)!r} is not valid TOML: {err}") from None
    check_keys(name, doc, CASE_KEYS)
    title = _text(f"{name}: title", doc.get("title"))
    model = doc.get("model")
    if model not in MODELS:
        raise ScenarioError(f"{name}: model = {model!r} is not one of {', '.join(MODELS)}")
    kind = _text(f"{name}: kind", doc.get("kind"))
    calibration = doc.get("calibration")
    if not isinstance(calibration, bool):
        raise ScenarioError(f"{name}: calibration = {calibration!r} must be true or false (true: a parameter was "
                            "fitted to this case's data)")
    src = doc.get("source", {})
    check_keys("source", src, SOURCE_KEYS)
    for k in SOURCE_KEYS:
        _text(f"{name}: source.{k}", src.get(k))
    m = doc.get("measured", {})
    check_keys("measured", m, MEASURED_KEYS)
    x = _numbers(f"{name}: measured.x", m.get("x"))
    if x.size == 0:
        raise ScenarioError(f"{name}: measured.x is empty")
    values = _numbers(f"{name}: measured.values", m.get("values"), x.size)
    spread = m.get("spread", [])
    spread_arr = _numbers(f"{name}: measured.spread", spread, x.size) if spread else None
    labels = m.get("x_labels")
    if labels is not None and (not isinstance(labels, list) or len(labels) != x.size
                               or not all(isinstance(v, str) for v in labels)):
        raise ScenarioError(f"{name}: measured.x_labels = {labels!r} must be one name per measured point")
    refs = {}
    for rname, rt in doc.get("reference", {}).items():
        check_keys(f"reference.{rname}", rt, ("x", "values"))
        rx = _numbers(f"{name}: reference.{rname}.x", rt.get("x"))
        refs[rname] = (rx, _numbers(f"{name}: reference.{rname}.values", rt.get("values"), rx.size))
    assumptions = tuple(_assumption(name, k, t) for k, t in doc.get("assumptions", {}).items())
    if not assumptions:
        raise ScenarioError(f"{name}: no [assumptions.NAME] table; a case states every value its source does not give")
    setup = doc.get("setup", {})
    if not isinstance(setup, dict):
        raise ScenarioError(f"{name}: [setup] must be a table")
    findings = _text(f"{name}: findings", doc.get("findings"))
    line_points = doc.get("line_points", LINE_POINTS)
    if isinstance(line_points, bool) or not isinstance(line_points, int) or not 2 <= line_points <= 200:
        raise ScenarioError(f"{name}: line_points = {line_points!r} must be a whole number in 2-200")
    return Case(name, path, title, model, kind, calibration, findings, dict(src), _text(f"{name}: measured.quantity",
                m.get("quantity")), _text(f"{name}: measured.unit", m.get("unit")),
                _text(f"{name}: measured.x_name", m.get("x_name")), x, values, spread_arr,
                None if labels is None else tuple(labels), refs, dict(setup),
                assumptions, line_points)


def case_names() -> list[str]:
    """The built-in cases (the files of :data:`CASES_DIR`), sorted."""
    return sorted(p.stem for p in CASES_DIR.glob("*.toml"))


def resolve_cases(names) -> list[Path]:
    """Case names (built-in) or paths to case files -> their files; none given: every built-in case.
    An unknown name raises a one-line ScenarioError listing the built-in ones."""
    if not names:
        return [CASES_DIR / f"{n}.toml" for n in case_names()]
    out = []
    for n in names:
        if n.endswith(".toml"):
            if not Path(n).is_file():
                raise ScenarioError(f"validation case file {n!r} does not exist")
            out.append(Path(n))
        elif n in case_names():
            out.append(CASES_DIR / f"{n}.toml")
        else:
            raise ScenarioError(f"unknown validation case {n!r}; the built-in cases are: {', '.join(case_names())} "
                                "(or give a case file, *.toml)")
    return out


# ---------------------------------------------------------------------------------------------
# running a case

@dataclasses.dataclass
class CaseResult:
    case: Case
    predicted: np.ndarray  # at the measured x
    band_low: np.ndarray
    band_high: np.ndarray
    runs: list  # (assumption name, end label, assumed value, prediction at x, prediction on line_x)
    line_x: np.ndarray
    line: np.ndarray
    line_low: np.ndarray
    line_high: np.ndarray

    @property
    def error(self) -> np.ndarray:
        return self.predicted - self.case.measured

    @property
    def relative_error(self) -> np.ndarray:
        return self.error / self.case.measured


def _line_x(case: Case) -> np.ndarray:
    lo, hi = float(case.x.min()), float(case.x.max())
    pad = 0.25 * (hi - lo) if hi > lo else 0.25 * abs(hi)
    return np.linspace(max(lo - pad, 0.4 * lo), hi + pad, case.line_points)


def _evaluate(case: Case, values: dict, xs: np.ndarray) -> np.ndarray:
    setup = dict(case.setup)
    a = {}
    for asm in case.assumptions:
        v = values[asm.name]
        if asm.alternatives is not None:
            setup.update(asm.alternatives.get(v, {}))
        a[asm.name] = v
    return np.asarray(MODELS[case.model](setup, a, xs), dtype=float)


def run_case(case: Case, line: bool = True) -> CaseResult:
    """The prediction at the measured points with every assumption at its value, and the band: the
    same at each end of each assumption's range (or each alternative), the others at their values.
    ``line``: also on :data:`LINE_POINTS` points over the measured range (for the figure)."""
    lx = _line_x(case) if line and case.x_labels is None else case.x[:0]  # categories: no line between them
    xs = np.concatenate([case.x, lx])
    nominal = case.nominal()
    base = _evaluate(case, nominal, xs)
    runs = []
    for asm in case.assumptions:
        for label, v in asm.ends():
            pred = _evaluate(case, {**nominal, asm.name: v}, xs)
            runs.append((asm.name, label, v, pred[:case.x.size], pred[case.x.size:]))
    allp = np.array([base] + [np.concatenate([r[3], r[4]]) for r in runs])
    # a run with no prediction at a point (NaN: e.g. no steady turn there) leaves the band to the others
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        low, high = np.nanmin(allp, axis=0), np.nanmax(allp, axis=0)
    n = case.x.size
    return CaseResult(case, base[:n], low[:n], high[:n], runs, lx, base[n:], low[n:], high[n:])


# ---------------------------------------------------------------------------------------------
# the tables

def _fmt(v) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


def _point(c: Case, i: int) -> str:
    """The i-th measured point as the tables name it: its label, or its x."""
    return c.x_labels[i] if c.x_labels else _fmt(float(c.x[i]))


def reference_names(results) -> list[str]:
    names: list[str] = []
    for r in results:
        names += [n for n in r.case.references if n not in names]
    return names


def validation_csv(results) -> str:
    """validation.csv (module doc, :data:`CSV_COLUMNS`, then ``ref_<NAME>`` per reference model)."""
    refs = reference_names(results)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(CSV_COLUMNS) + [f"ref_{n}" for n in refs])
    for r in results:
        c = r.case
        for i, x in enumerate(c.x):
            row = [c.name, c.quantity, _point(c, i), c.x_name, float(c.measured[i]), float(r.predicted[i]),
                   float(r.error[i]), float(r.relative_error[i]), float(r.band_low[i]), float(r.band_high[i]), c.unit,
                   c.kind, "true" if c.calibration else "false"]
            for n in refs:
                rx, rv = c.references.get(n, (np.array([]), np.array([])))
                hit = np.flatnonzero(np.isclose(rx, x))
                row.append(float(rv[hit[0]]) if hit.size else "")
            w.writerow([_fmt(v) for v in row])
    return buf.getvalue()


def sensitivity_csv(results) -> str:
    """sensitivity.csv: the prediction at each measured point with one assumption at one end of its
    range (or one alternative), the others at their values (:data:`SENSITIVITY_COLUMNS`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(SENSITIVITY_COLUMNS)
    for r in results:
        c = r.case
        for i in range(c.x.size):
            w.writerow([c.name, "(all at their values)", "nominal", "", _point(c, i), _fmt(float(r.predicted[i])),
                        c.unit])
        for name, label, v, pred, _ in r.runs:
            for i in range(c.x.size):
                w.writerow([c.name, name, label, _fmt(v if isinstance(v, str) else float(v)), _point(c, i),
                            _fmt(float(pred[i])), c.unit])
    return buf.getvalue()


def summary_rows(results) -> list[dict]:
    """Per kind of quantity: the points, the mean absolute error (in the unit), the worst relative
    error (the largest in magnitude, signed, with its case and point), and how many points lie in
    their case's band."""
    kinds: dict[str, list] = {}
    for r in results:
        kinds.setdefault(r.case.kind, []).append(r)
    out = []
    for kind, rs in kinds.items():
        err = np.concatenate([r.error for r in rs])
        rel = np.concatenate([r.relative_error for r in rs])
        where = [(r.case.name, _point(r.case, i)) for r in rs for i in range(r.case.x.size)]
        k = int(np.argmax(np.abs(rel)))
        inside = sum(int(np.sum((r.case.measured >= r.band_low) & (r.case.measured <= r.band_high))) for r in rs)
        units = sorted({r.case.unit for r in rs})
        out.append({"kind": kind, "unit": "/".join(units), "cases": len(rs), "points": int(err.size),
                    "mean_abs_error": float(np.mean(np.abs(err))), "worst_relative_error": float(rel[k]),
                    "worst_at": f"{where[k][0]} @ {where[k][1]}", "points_in_band": inside,
                    "calibrations": sum(r.case.calibration for r in rs)})
    return out


def _g(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def markdown_tables(results, rows: list[dict]) -> str:
    """validation.md: the tables of docs/validation.md, as the command computed them: every point, the
    errors by kind, and each assumption's effect at the ends of its range."""
    out = ["| case | point | measured | predicted | error | band of the assumptions | unit | calibration |",
           "|---|---|---|---|---|---|---|---|"]
    for r in results:
        c = r.case
        for i in range(c.x.size):
            out.append(f"| {c.name} | {_point(c, i)} | {_g(float(c.measured[i]))} | {_g(float(r.predicted[i]))} | "
                       f"{100 * float(r.relative_error[i]):+.0f} % | {_g(float(r.band_low[i]))} - "
                       f"{_g(float(r.band_high[i]))} | {c.unit} | {'yes' if c.calibration else 'no'} |")
    out += ["", "| kind | cases | points | mean absolute error | worst relative error | measured inside the band |",
            "|---|---|---|---|---|---|"]
    for s in rows:
        out.append(f"| {s['kind']} | {s['cases']} | {s['points']} | {_g(s['mean_abs_error'])} {s['unit']} | "
                   f"{100 * s['worst_relative_error']:+.0f} % ({s['worst_at']}) | {s['points_in_band']} of "
                   f"{s['points']} |")
    out += ["", "| case | assumption | value | range | predicted at the ends (at each measured point) |",
            "|---|---|---|---|---|"]
    for r in results:
        c = r.case
        for a in c.assumptions:
            unit = "" if a.unit == "-" else f" {a.unit}"
            span = (f"{_g(a.range[0])} - {_g(a.range[1])}{unit}" if a.range
                    else " / ".join([a.value, *a.alternatives]))
            ends = "; ".join(f"{label if isinstance(v, str) and label == v else f'{label} ({_g(v)})'}: "
                             + ", ".join(_g(float(p)) for p in pred)
                             for name, label, v, pred, _ in r.runs if name == a.name)
            out.append(f"| {c.name} | {a.name} | {_g(a.value)} | {span} | {ends} |")
    return "\n".join(out) + "\n"


# bounded by their maxsize; emptied by symtrack.clear_caches() (symtrack.foundations.caches)
caches.register_clear("validate.season_shares", _season_shares)
