"""The fleet of a region study: tyres, machines (wheels or tracks) and each machine's quasi-static stress
profile across its path (docs/region.md, "The fleet" and "The fast fidelity").

A machine is a working width (its plan's line spacing), an outer width, a headland turn radius and a
carrier: **wheels** (each a tyre of the catalog at a position in the machine's frame, x ahead, y left,
with its wheel load) or **tracks** (two rubber tracks of contact length l, width b and gauge B carrying the
machine's mass). Every machine and tyre of a catalog has a ``source``: a citation, or a sentence that
starts with ``ASSUMED`` and says why (refused otherwise).

The stress profile (:func:`stress_profile`): the largest vertical stress [Pa] at each depth of a cell at a
lateral distance v from the machine's path line while the machine drives by in a straight line, the
maximum over the positions along its path of the superposed stresses of all its wheels or tracks. It is
built once per machine and concentration factor xi (a soil property), from the package's own stress
models, the same ones the full fidelity uses:

- wheels: Keller's (2005) contact and Söhne / Fröhlich's stress at depth, tabulated by
  :func:`symtrack.vehicles.tyre.footprint_table` (the wheeled pass's tables);
- tracks: the terrain engine's strip tables (:func:`symtrack.soil.subsoil.build_tables`,
  :func:`~symtrack.soil.subsoil.stress_at`) under the static pressure line of a track whose centre of
  gravity is over its contact's centre: p = m g / (2 l b), uniform (the engine's line with no
  acceleration, no drawbar pull and no pitch: the quasi-static part of its load). Where the plan's speed
  changes, the engine's line pitched by the acceleration (:func:`pressure_line`, for a machine whose centre of
  gravity's height is known); on an arc, the rigid contacts turned about the turn's centre
  (:func:`turn_profile`, :func:`arc_bands`, :func:`arc_stays`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ScenarioError
from ..soil import subsoil
from ..toolchain.tables import cached_arrays
from ..vehicles import tyre as tyre_model
from ..vehicles.tyre import (
    FootprintTable,
    Tyre,
    contact,
    footprint_table,
    load_capacity_kN,
    recommended_inflation_kPa,
)

__all__ = ["BUILTIN_FLEET", "COVER_FRACTIONS", "Fleet", "Machine", "StressProfile", "TrackSet", "WheelSpec",
           "PRESSURE_FRACTIONS", "arc_bands", "arc_stays", "first_pass_rut_m", "peak_pressure_factor",
           "pressure_line", "load_fleet", "parse_fleet", "plastic_rut_m", "rut_table_m",
           "stress_profile", "track_machine", "turn_profile"]

BUILTIN_FLEET = "builtin"
GRAVITY_M_S2 = 9.81
FLEET_KEYS = ("schema_version", "tyres", "machines")
TYRE_KEYS = ("width_m", "diameter_m", "rated_load_kN", "rated_inflation_kPa", "source")
MACHINE_KEYS = ("working_width_m", "outer_width_m", "turn_radius_m", "wheels", "tracks", "source")
WHEEL_KEYS = ("name", "x_m", "y_m", "tyre", "load_kN", "inflation_kPa")
TRACK_KEYS = ("contact_length_m", "track_width_m", "track_gauge_m", "mass_kg", "cg_height_m")
# the profile's sampling, lateral and along the path, and the tyre contact's elements (tyre.contact: the forces
# of a square grid of this side): 3 cm. Measured on the combine (the largest loads) against 1 cm: the profile's
# peak +0.6 % and its mean over the strips +0.6 % at 0.1 m depth, below 0.1 % at 0.3-0.8 m; 0.5 s against 52 s
# (tests/test_region.py keeps the bound)
PROFILE_STEP_M = 0.03
# how far beside and ahead of a wheel or track its stress is kept (vehicles/wheeled.py's reach: below 1 % of the
# peak 1.5 m beside a contact at 0.1-0.8 m depth for xi >= 3)
PROFILE_REACH_M = 1.5
TYRE_ELEMENT_M = 0.03


@dataclass(frozen=True)
class WheelSpec:
    name: str
    x_m: float
    y_m: float
    tyre: Tyre
    tyre_name: str
    load_kN: float
    inflation_kPa: float

    @property
    def width_m(self) -> float:
        return self.tyre.width_m


@dataclass(frozen=True)
class TrackSet:
    contact_length_m: float
    track_width_m: float
    track_gauge_m: float
    mass_kg: float

    @property
    def pressure_Pa(self) -> float:
        """The static contact pressure m g / (2 l b) (module doc)."""
        return self.mass_kg * GRAVITY_M_S2 / (2.0 * self.contact_length_m * self.track_width_m)


@dataclass(frozen=True)
class Machine:
    """A machine of the fleet (module doc): ``wheels`` (tuple of :class:`WheelSpec`) or ``tracks``."""

    name: str
    working_width_m: float
    outer_width_m: float
    turn_radius_m: float
    wheels: tuple = ()
    tracks: TrackSet | None = None
    source: str = ""
    # a tracked machine's centre of gravity's height [m] (the pitch of its pressure line where it accelerates:
    # pressure_line); None: not given (a fleet catalog's machine without tracks.cg_height_m), its line static
    # everywhere
    cg_height_m: float | None = None

    def strips(self) -> tuple:
        """The strips its tyres or tracks run on: ((lateral_m, width_m), ...), left positive."""
        if self.tracks is not None:
            t = self.tracks
            return ((0.5 * t.track_gauge_m, t.track_width_m), (-0.5 * t.track_gauge_m, t.track_width_m))
        return tuple((w.y_m, w.width_m) for w in self.wheels)

    @property
    def reach_m(self) -> float:
        return max(abs(lat) + 0.5 * b for lat, b in self.strips())

    @property
    def mass_kg(self) -> float:
        if self.tracks is not None:
            return self.tracks.mass_kg
        return sum(w.load_kN for w in self.wheels) * 1e3 / GRAVITY_M_S2

    def key(self) -> tuple:
        """What its stress profile depends on (for the tables' cache)."""
        if self.tracks is not None:
            t = self.tracks
            return ("tracks", t.contact_length_m, t.track_width_m, t.track_gauge_m, t.mass_kg)
        return ("wheels",) + tuple((w.x_m, w.y_m, w.tyre, w.load_kN, w.inflation_kPa) for w in self.wheels)


@dataclass(frozen=True)
class Fleet:
    machines: dict  # name -> Machine
    tyres: dict  # name -> Tyre
    label: str


def _source(where: str, t: dict) -> str:
    s = t.get("source")
    if not isinstance(s, str) or not s.strip():
        raise ScenarioError(f"{where}.source is required: a citation of where its numbers come from, or a sentence "
                            "starting with \"ASSUMED\" that says why they are taken as they are")
    return s.strip()


def _tyre(where: str, t) -> Tyre:
    if not isinstance(t, dict):
        raise ScenarioError(f"{where} = {t!r} must be a table of {', '.join(TYRE_KEYS)}")
    check_keys(where, t, TYRE_KEYS)
    _source(where, t)
    vals = {}
    for k, lo, hi in (("width_m", 0.1, 1.2), ("diameter_m", 0.3, 3.0), ("rated_load_kN", 0.0, 500.0),
                      ("rated_inflation_kPa", 0.0, 1000.0)):
        if k not in t:
            raise ScenarioError(f"{where}.{k} is required")
        vals[k] = number(f"{where}.{k}", t[k], lo, hi, low_open=True)
    return Tyre(**vals)


def _machine(name: str, t, tyres: dict) -> Machine:
    where = f"machines.{name}"
    if not isinstance(t, dict):
        raise ScenarioError(f"{where} = {t!r} must be a table of {', '.join(MACHINE_KEYS)}")
    check_keys(where, t, MACHINE_KEYS)
    src = _source(where, t)
    if "working_width_m" not in t:
        raise ScenarioError(f"{where}.working_width_m is required")
    w = number(f"{where}.working_width_m", t["working_width_m"], 0.0, 100.0, low_open=True)
    outer = number(f"{where}.outer_width_m", t.get("outer_width_m", w), 0.0, 100.0, low_open=True)
    radius = number(f"{where}.turn_radius_m", t.get("turn_radius_m", 5.0), 0.5, 100.0)
    has_w, has_t = "wheels" in t, "tracks" in t
    if has_w == has_t:
        raise ScenarioError(f"{where}: give either wheels (a list of wheel tables) or tracks (a table of "
                            f"{', '.join(TRACK_KEYS)}), not {'both' if has_w else 'neither'}")
    if has_t:
        tt = t["tracks"]
        if not isinstance(tt, dict):
            raise ScenarioError(f"{where}.tracks = {tt!r} must be a table of {', '.join(TRACK_KEYS)}")
        check_keys(f"{where}.tracks", tt, TRACK_KEYS)
        vals = {}
        for k, lo, hi in (("contact_length_m", 0.0, 20.0), ("track_width_m", 0.0, 5.0), ("track_gauge_m", 0.0, 10.0),
                          ("mass_kg", 0.0, 2e5)):
            if k not in tt:
                raise ScenarioError(f"{where}.tracks.{k} is required")
            vals[k] = number(f"{where}.tracks.{k}", tt[k], lo, hi, low_open=True)
        ts = TrackSet(**vals)
        if ts.track_gauge_m < ts.track_width_m:
            raise ScenarioError(f"{where}.tracks.track_gauge_m = {ts.track_gauge_m:g} is outside the allowed range "
                                f"[{ts.track_width_m:g}, 10] m (at least the track width: the tracks would overlap)")
        # optional: the centre of gravity's height above the ground, for the pitched pressure line where the plan's
        # speed changes (pressure_line), in the vehicle parameter's range (vehicles/planar.py, VEHICLE_PARAMS)
        h = None
        if "cg_height_m" in tt:
            from ..vehicles.planar import VEHICLE_PARAMS

            spec_h = next(q for q in VEHICLE_PARAMS if q.name == "cg_height_m")
            h = number(f"{where}.tracks.cg_height_m", tt["cg_height_m"], spec_h.low, spec_h.high, low_open=True)
        m = Machine(name, w, outer, radius, (), ts, src, h)
    else:
        wl = t["wheels"]
        if not isinstance(wl, list) or not wl:
            raise ScenarioError(f"{where}.wheels = {wl!r} must be a non-empty list of wheel tables")
        wheels = []
        for i, wt in enumerate(wl):
            wh = f"{where}.wheels[{i}]"
            if not isinstance(wt, dict):
                raise ScenarioError(f"{wh} = {wt!r} must be a table of {', '.join(WHEEL_KEYS)}")
            check_keys(wh, wt, WHEEL_KEYS)
            for k in ("x_m", "y_m", "tyre", "load_kN"):
                if k not in wt:
                    raise ScenarioError(f"{wh}.{k} is required")
            tn = wt["tyre"]
            if tn not in tyres:
                raise ScenarioError(f"{wh}.tyre = {tn!r} is not a tyre of the catalog ({', '.join(tyres)})")
            ty = tyres[tn]
            x = number(f"{wh}.x_m", wt["x_m"], -30.0, 30.0)
            y = number(f"{wh}.y_m", wt["y_m"], -0.5 * outer + 0.5 * ty.width_m, 0.5 * outer - 0.5 * ty.width_m) \
                if outer >= ty.width_m else None
            if y is None:
                raise ScenarioError(f"{wh}.tyre = {tn!r}: its width {ty.width_m:g} m is wider than "
                                    f"{where}.outer_width_m "
                                    f"= {outer:g}")
            if radius < abs(y) + 0.5 * ty.width_m:
                raise ScenarioError(f"{where}.turn_radius_m = {radius:g} is outside the allowed range "
                                    f"[{abs(y) + 0.5 * ty.width_m:g}, 100] m: the wheel {wh} would cross the turn's "
                                    "centre")
            p_rated = ty.rated_inflation_kPa
            cap = load_capacity_kN(ty, p_rated)
            load = number(f"{wh}.load_kN", wt["load_kN"], 0.0, cap, low_open=True)
            infl = wt.get("inflation_kPa", "recommended")
            if infl == "recommended":
                infl = recommended_inflation_kPa(ty, load)
            else:
                lo = recommended_inflation_kPa(ty, load)
                infl = number(f"{wh}.inflation_kPa", infl, lo, p_rated)
            wheels.append(WheelSpec(str(wt.get("name", f"wheel{i}")), x, y, ty, tn, load, infl))
        m = Machine(name, w, outer, radius, tuple(wheels), None, src)
    return m


def parse_fleet(doc: dict, label: str = "fleet") -> Fleet:
    """A fleet catalog document -> :class:`Fleet`, every tyre and machine checked (module doc)."""
    if not isinstance(doc, dict):
        raise ScenarioError(f"{label}: a fleet catalog is a TOML document with [tyres] and [machines]")
    check_keys(label, doc, FLEET_KEYS)
    tt = doc.get("tyres", {})
    if not isinstance(tt, dict):
        raise ScenarioError(f"{label}: tyres must be a table of tyre tables")
    tyres = {str(k): _tyre(f"tyres.{k!r}" if "/" in str(k) else f"tyres.{k}", v) for k, v in tt.items()}
    mm = doc.get("machines")
    if not isinstance(mm, dict) or not mm:
        raise ScenarioError(f"{label}: machines must be a non-empty table of machine tables")
    machines = {str(k): _machine(str(k), v, tyres) for k, v in mm.items()}
    return Fleet(machines, tyres, label)


def load_fleet(name_or_path) -> Fleet:
    """The built-in fleet (``"builtin"``) or a fleet catalog TOML file."""
    from pathlib import Path

    from ..foundations.files import read_text

    if name_or_path in (None, BUILTIN_FLEET):
        text = resources.files("symtrack.region").joinpath("data/fleet.toml").read_text()
        label = "the built-in fleet"
    else:
        p = Path(name_or_path)
        if not p.is_file():
            raise ScenarioError(f"fleet = {str(name_or_path)!r}: no such file (or \"builtin\")")
        text, label = read_text(p, "fleet catalog"), str(p)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"fleet {label}: not valid TOML: {err}") from err
    return parse_fleet(doc, label)


def track_machine(name: str, params: dict, working_width_m: float, turn_radius_m: float) -> Machine:
    """A tracked machine from a vehicle parameter set (a preset's contact length, track width, gauge and
    mass): the full fidelity's crawler as the fast one sees it."""
    ts = TrackSet(float(params["contact_length_m"]), float(params["track_width_m"]), float(params["track_gauge_m"]),
                  float(params["mass_kg"]))
    h = params.get("cg_height_m")
    return Machine(name, float(working_width_m), float(params["track_gauge_m"]) + float(params["track_width_m"]),
                   float(turn_radius_m), (), ts, "the vehicle preset's own parameters",
                   None if h is None else float(h))


# ---- the stress profile ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StressProfile:
    """sigma_z [Pa] (n_v, n_depths) at lateral offsets ``v_m`` (n_v,) from the path line: the largest
    vertical stress a straight pass gives (module doc)."""

    v_m: np.ndarray
    sigma_Pa: np.ndarray
    depths_m: tuple
    xi: float

    def at(self, v) -> np.ndarray:
        """Linear interpolation in v (0 beyond the table): (n, n_depths)."""
        v = np.asarray(v, dtype=float)
        x = (v - self.v_m[0]) / (self.v_m[1] - self.v_m[0])
        n = self.v_m.size
        inside = (x >= 0) & (x <= n - 1)
        i = np.clip(np.floor(x).astype(np.int64), 0, n - 2)
        f = np.clip(x - i, 0.0, 1.0)[:, None]
        out = (1 - f) * self.sigma_Pa[i] + f * self.sigma_Pa[i + 1]
        return np.where(inside[:, None], out, 0.0)


def _profile_from(stress_fn, x_lo, x_hi, v_lo, v_hi, step):
    v = np.arange(math.floor(v_lo / step), math.ceil(v_hi / step) + 1) * step
    u = np.arange(math.floor(x_lo / step), math.ceil(x_hi / step) + 1) * step
    best = None
    for uu in u:  # one row of points along v at each position along the path
        s = stress_fn(np.full(v.size, uu), v)
        best = s if best is None else np.maximum(best, s)
    return v, best


@functools.lru_cache(maxsize=32)
def footprint_table_cached(tyre: Tyre, wheel_load_kN: float, inflation_kPa: float, element_m: float, depths_m: tuple,
                           xi: float, reach_m: float, step_m: float | None = None):
    """:func:`symtrack.vehicles.tyre.footprint_table`'s (contact, table), the table computed once for the
    machine's cache and read there by every other process (symtrack/toolchain/tables.py): a region study's
    workers, and the next study, build each tyre's table once instead of once per process (seconds each)."""
    args = repr((dataclasses.astuple(tyre), float(wheel_load_kN), float(inflation_kPa), float(element_m),
                 tuple(float(d) for d in depths_m), float(xi), float(reach_m),
                 None if step_m is None else float(step_m)))

    def compute():
        _, tb = footprint_table(tyre, wheel_load_kN, inflation_kPa, element_m, depths_m, xi, reach_m, step_m)
        return {"sz": tb.sz, "pm": tb.pm, "step_m": np.array(tb.step_m)}

    a = cached_arrays("footprint", args, compute, ("sz", "pm", "step_m"), modules=(tyre_model, subsoil))
    return (contact(tyre, wheel_load_kN, inflation_kPa, element_m),
            FootprintTable(float(a["step_m"]), tuple(float(d) for d in depths_m), float(xi), a["sz"], a["pm"]))


def _track_stress_fn(machine: Machine, depths: tuple, xi: float, step: float, reach: float, accel: float = 0.0):
    """The vertical stress [Pa] (n, n_depths) at points (u ahead, v left) of a tracked machine's frame, its
    contact centre at the origin: the terrain engine's strip tables under the pressure line of
    :func:`pressure_line` (the static one at ``accel`` = 0: module doc)."""
    t = machine.tracks
    T = _track_tables(depths, xi, t.contact_length_m, t.track_width_m, t.track_gauge_m, reach)
    alpha, beta = pressure_line(machine, accel)
    a = np.array([0.0, 0.0, 1.0, 0.0, alpha, beta, alpha, beta])
    geo = np.array([t.contact_length_m, t.track_width_m, t.track_gauge_m, 0.0, step, 0.0])

    def fn(uu, vv):
        return subsoil.stress_at(T, uu, vv, a, geo)

    return fn


@functools.lru_cache(maxsize=16)
def _track_tables(depths: tuple, xi: float, length: float, width: float, gauge: float, reach: float):
    """The terrain engine's strip tables of a track geometry (one build for a machine's static, pitched and
    turned profiles)."""
    return subsoil.build_tables(np.asarray(depths, dtype=float), xi, length, width, gauge, reach)


@functools.lru_cache(maxsize=64)
def _profile_cached(key, machine: Machine, depths: tuple, xi: float, step: float, reach: float,
                    accel: float = 0.0) -> StressProfile:
    if machine.tracks is not None:
        t = machine.tracks
        fn = _track_stress_fn(machine, depths, xi, step, reach, accel)
        half_l = 0.5 * t.contact_length_m
        v, s = _profile_from(fn, -half_l, half_l, -machine.reach_m, machine.reach_m, step)
        return StressProfile(v, s, depths, xi)
    tables = []
    for w in machine.wheels:
        _, tb = footprint_table_cached(w.tyre, w.load_kN, w.inflation_kPa, TYRE_ELEMENT_M, depths, xi, reach, step)
        tables.append(tb)

    def fn(uu, vv):
        s = np.zeros((uu.size, len(depths)))
        for w, tb in zip(machine.wheels, tables, strict=True):
            s += tb.sigma_z(uu - w.x_m, vv - w.y_m)
        return 1e3 * s  # kPa -> Pa

    xs = [w.x_m for w in machine.wheels]
    half_len = max(0.5 * w.tyre.diameter_m for w in machine.wheels)
    v, s = _profile_from(fn, min(xs) - half_len, max(xs) + half_len, -machine.reach_m, machine.reach_m, step)
    return StressProfile(v, s, depths, xi)


def stress_profile(machine: Machine, depths_m, xi: float, step_m: float = PROFILE_STEP_M,
                   reach_m: float = PROFILE_REACH_M, accel_m_s2: float = 0.0) -> StressProfile:
    """The machine's stress profile (module doc) at ``depths_m`` for concentration factor ``xi``, built once
    per process for these arguments. ``accel_m_s2``: a tracked machine's profile while it speeds up or slows
    down at that rate, under its pitched pressure line (:func:`pressure_line`; the same for either sign: the
    largest stress over the positions along the path); 0, and for wheels, the static profile."""
    depths = tuple(float(d) for d in depths_m)
    accel = abs(float(accel_m_s2)) if machine.tracks is not None and machine.cg_height_m is not None else 0.0
    return _profile_cached(machine.key(), machine, depths, float(xi), float(step_m), float(reach_m), accel)


def pressure_line(machine: Machine, accel_m_s2: float = 0.0) -> tuple:
    """(alpha, beta) of each track's pressure line p(s) = max(0, alpha + beta s) [Pa], s from the contact's
    front end, of a tracked machine speeding up at ``accel_m_s2`` (< 0: slowing down) on level ground: the
    terrain engine's quasi-static line (symtrack/vehicles/planar.py, PressureDistribution: each track's normal
    load N = m g / 2 and its share of the pitching moment about the contact's centre, M = -m a h / 2, the
    inertial force m a at the centre of gravity's height h = ``cg_height_m``; the centre of gravity over the
    contact's centre and no drawbar pull, as the static profile): linear, p = N / (b l) + 12 M / (b l^3)
    (l / 2 - s), while the resultant's offset e = M / N = -a h / g stays within l / 6; beyond it triangular over
    3 (l / 2 - |e|) from the loaded end: evaluated from PressureDistribution itself, the line through two points
    of its loaded end. a = 0, or no ``cg_height_m``: the static p = m g / (2 l b)."""
    import casadi as ca

    from ..vehicles.planar import PressureDistribution

    t = machine.tracks
    if machine.cg_height_m is None or accel_m_s2 == 0.0:
        return t.pressure_Pa, 0.0
    l = t.contact_length_m
    N = 0.5 * t.mass_kg * GRAVITY_M_S2
    pd = PressureDistribution(ca.DM(N), ca.DM(-N * float(accel_m_s2) * machine.cg_height_m / GRAVITY_M_S2),
                              t.track_width_m, l)
    front, rear = float(pd.at(0.0)), float(pd.at(l))
    # two points within the loaded part (a triangle's is at least 3 (l/2 - 0.45 l) = 0.15 l long)
    s0, p_0, s1 = (0.0, front, 0.1 * l) if front >= rear else (l, rear, 0.9 * l)
    beta = (float(pd.at(s1)) - p_0) / (s1 - s0)
    return p_0 - beta * s0, beta


def peak_pressure_factor(machine: Machine, accel_m_s2: float) -> float:
    """The largest pressure of :func:`pressure_line` over the static pressure (1 at rest or at constant speed,
    and for wheels): what a cell a track passes over carries at most (the whole contact passes over it)."""
    if machine.tracks is None:
        return 1.0
    alpha, beta = pressure_line(machine, accel_m_s2)
    return max(alpha, alpha + beta * machine.tracks.contact_length_m) / machine.tracks.pressure_Pa


def arc_bands(machine: Machine, radius_m: float) -> tuple:
    """The band each strip of the machine sweeps on an arc of signed radius ``radius_m`` (> 0: a left turn,
    its centre on the left), as ((v_lo, v_hi), ...) in the arc's lateral coordinate v = sign(R) (|R| - r)
    (r the distance from the turn's centre; left of the path line positive, as on a straight).

    A track is a rigid l x b rectangle whose contact centre is on the path line and whose axis is the path's
    tangent (the full fidelity's vehicle: the engine's contact rectangle at each pose, symtrack/terrain/
    channels.py). Turned about the centre, its points (x along, y across, in the machine's frame) lie at
    r = sqrt(x^2 + rho^2), rho = |R| - sign(R) y the radius of its centre line's point: the smallest radius is its
    inner edge's at x = 0, rho_in, the largest its outer edge's at its ends, sqrt(rho_out^2 + (l/2)^2). On the
    2 m turns of the reference crawler (l = 2.4 m, b = 0.45 m, B = 1.5 m) the inner track sweeps 1.03-1.90 m
    (0.45 m wider than its width) and the outer track 2.53-3.21 m (0.23 m wider): the straight strip's band
    misses the ends' sweep (plane geometry). Wheels keep their strips (each tyre at its lateral offset, rigidly:
    the module doc of symtrack.region.fast)."""
    if machine.tracks is None:
        return tuple((lat - 0.5 * b, lat + 0.5 * b) for lat, b in machine.strips())
    R, sg = abs(float(radius_m)), (1.0 if radius_m > 0 else -1.0)
    half_l = 0.5 * machine.tracks.contact_length_m
    out = []
    for lat, b in machine.strips():
        rho_in, rho_out = R - sg * lat - 0.5 * b, R - sg * lat + 0.5 * b
        # (a turn tighter than the track's inner edge: the track spans the centre, its nearest point is on it)
        r_lo = max(rho_in, 0.0) if rho_out > 0 else -rho_out
        r_hi = math.hypot(max(abs(rho_in), abs(rho_out)), half_l)
        lo, hi = sorted((sg * (R - r_lo), sg * (R - r_hi)))
        out.append((lo, hi))
    return tuple(out)


def arc_stays(machine: Machine, radius_m: float, sweep_rad: float, r, alpha, half_cell_m: float = 0.0) -> np.ndarray:
    """How many separate times (stays) a track's rigid contact covers a cell whose centre is at distance ``r``
    from the centre of an arc of signed radius ``radius_m`` and sweep ``sweep_rad``, at angle ``alpha`` from the
    arc's start (0 <= alpha < sweep; arrays): 1, or 2 for a cell wholly beyond a track's outer edge (:func:`arc_bands`),
    r - ``half_cell_m`` > rho_out, and r <= sqrt(rho_out^2 + (l/2)^2). Such a cell is under the track where the
    angle of its centre from the machine's axis seen from the turn's centre, phi, has |phi| between phi_lo =
    acos(rho_out / r) (nearer the axis it lies beyond the edge) and phi_hi = min(asin(l / (2 r)), acos(rho_in /
    r)): under the contact's front end, then out of every contact, then under its rear end, two load cycles of
    the soil under it (the terrain engine counts a cycle per stay: symtrack/soil/cell.py; a cell within half a
    cell of the edge stays partly under it in between: one stay). Both stays fall within the arc where phi_lo
    <= alpha <= sweep - phi_lo; nearer the arc's ends one of them is the straight's beyond, which does not reach
    the cell (plane geometry). Wheels: 1."""
    r = np.asarray(r, dtype=float)
    out = np.ones(r.shape, dtype=np.int32)
    if machine.tracks is None:
        return out
    R, sg = abs(float(radius_m)), (1.0 if radius_m > 0 else -1.0)
    half_l = 0.5 * machine.tracks.contact_length_m
    alpha = np.asarray(alpha, dtype=float)
    for lat, b in machine.strips():
        rho_in, rho_out = R - sg * lat - 0.5 * b, R - sg * lat + 0.5 * b
        if rho_in <= 0:  # a track spanning the turn's centre: one stay (its rim's second pass not counted)
            continue
        beyond = (r - half_cell_m > rho_out) & (r <= math.hypot(rho_out, half_l))
        if not beyond.any():
            continue
        phi_lo = np.arccos(np.clip(rho_out / np.where(beyond, r, 1.0), -1.0, 1.0))
        out[beyond & (alpha >= phi_lo) & (alpha <= sweep_rad - phi_lo)] = 2
    return out


def turn_profile(machine: Machine, depths_m, xi: float, radius_m: float, step_m: float = PROFILE_STEP_M,
                 reach_m: float = PROFILE_REACH_M) -> StressProfile | None:
    """A tracked machine's stress profile on an arc of signed radius ``radius_m`` (None for wheels: their
    straight profile serves): at each lateral offset v = sign(R) (|R| - r) from the path's circle, the largest
    vertical stress [Pa] of the rigid tracks (:func:`arc_bands`) turned about the turn's centre, the maximum over
    their poses of the stress the terrain engine's strip tables give under the static pressure line, as
    :func:`stress_profile` is along a straight. Built once per process for these arguments."""
    if machine.tracks is None:
        return None
    depths = tuple(float(d) for d in depths_m)
    prof = _turn_profile_cached(machine.key(), machine, depths, float(xi), round(abs(float(radius_m)), 6),
                                float(step_m), float(reach_m))
    if radius_m > 0:
        return prof
    # a right turn is the left turn's mirror image (the two tracks alike, at +-B/2): v -> -v
    return StressProfile(-prof.v_m[::-1], prof.sigma_Pa[::-1], prof.depths_m, prof.xi)


@functools.lru_cache(maxsize=64)
def _turn_profile_cached(key, machine: Machine, depths: tuple, xi: float, radius: float, step: float,
                         reach: float) -> StressProfile:
    R, sg = abs(radius), (1.0 if radius > 0 else -1.0)
    bands = arc_bands(machine, radius)
    lo = min(b[0] for b in bands) - reach
    hi = max(b[1] for b in bands) + reach
    if sg > 0:  # the cells between the turn's centre and the path: r = R - v >= 0
        hi = min(hi, R)
    else:
        lo = max(lo, -R)
    v = np.arange(math.floor(lo / step), math.ceil(hi / step) + 1) * step
    r = R - sg * v
    # the poses, as the cell's angle phi from the machine's axis seen from the centre: steps of at most `step`
    # along the outermost circle, over the half-turn in which the machine's frame holds the cell (|phi| <= 90 deg)
    # (all round when the machine reaches across the centre: a turn tighter than its half-width)
    half_turn = 0.5 * math.pi if R > machine.reach_m else math.pi
    n_phi = int(math.ceil(2 * half_turn * max(r.max(), step) / step)) + 1
    phi = np.linspace(-half_turn, half_turn, n_phi)
    fn = _track_stress_fn(machine, depths, xi, step, reach)
    uu = (r[None, :] * np.sin(phi)[:, None]).ravel()
    yy = (sg * (R - r[None, :] * np.cos(phi)[:, None])).ravel()
    s = fn(uu, yy).reshape(n_phi, v.size, len(depths)).max(axis=0)
    return StressProfile(v, s, depths, xi)


def first_pass_rut_m(machine: Machine, soil: dict, pressure_fraction: float = 1.0) -> float | None:
    """The plastic rut a tracked machine's first quasi-static pass leaves [m] (None for wheels: the package's
    wheeled pass leaves no rut, vehicles/wheeled.py): :func:`plastic_rut_m` of the track's static pressure
    and width. After N passes the terrain engine's rut is this N^beta (the soil's
    ``repeated_loading_exponent``); the density fold's column compression is bounded by it as the world bounds
    it (soil/density.py, cap_to_rut). ``pressure_fraction``: of a cell the track covers in part, the share of
    its area under the track (the terrain engine's channel weight: the cell carries that share of the
    pressure)."""
    if machine.tracks is None:
        return None
    return plastic_rut_m(machine.tracks.pressure_Pa * float(pressure_fraction), soil, machine.tracks.track_width_m)


def plastic_rut_m(pressure_Pa: float, soil: dict, width_m: float) -> float:
    """The plastic rut [m] one quasi-static loading to ``pressure_Pa`` leaves on virgin soil: the package's soil
    law (symtrack.soil.law, Bekker's virgin loading with k_eq = k_c / b + k_phi at b = ``width_m``) loaded to p,
    z_max = (p / k_eq)^(1/n), then unloaded on its elastic line, k_u = max(K_e, kappa p / z_max)
    (symtrack.soil.cell.unloading_slope): z_max - p / k_u. ``soil``: the law's parameters (a soil preset's
    keys: k_c, k_phi, n, K_e, kappa)."""
    from ..model.options import ModelOptions
    from ..soil import law as soil_law

    law_obj = soil_law.make(ModelOptions())
    law = law_obj.values({**soil, "track_width_m": float(width_m)})
    p = float(pressure_Pa)
    if p <= 0:
        return 0.0
    z_max = float(law_obj.static_sinkage(p, law))
    named = law_obj.named(law)
    k_e, kappa = float(named["elastic_stiffness_Pa_per_m"]), float(named["kappa"])
    k_u = max(k_e, kappa * p / max(z_max, 1e-12))
    return max(z_max - p / k_u, 0.0)


# the shares of a cell under a track at which the first-pass rut is tabulated (linear in between)
COVER_FRACTIONS = tuple(k / 20 for k in range(21))
# and beyond the static pressure, up to twice it (the peak of an accelerating track's pitched line:
# peak_pressure_factor; 1.06 at the operations' 0.4 m/s^2 for the reference crawler): the shares at which the
# rut table is tabulated (fast.fold_operation interpolates it at each cell's largest share)
PRESSURE_FRACTIONS = COVER_FRACTIONS + tuple(1 + k / 20 for k in range(1, 21))


def rut_table_m(machine: Machine, soil: dict) -> tuple | None:
    """:func:`first_pass_rut_m` at each share of the static pressure of :data:`PRESSURE_FRACTIONS` (None for
    wheels)."""
    if machine.tracks is None:
        return None
    return tuple(first_pass_rut_m(machine, soil, f) for f in PRESSURE_FRACTIONS)
