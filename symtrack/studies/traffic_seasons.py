"""Seasons of wheeled machines as footprints: the field's trafficked share, geometrically
(docs/studies.md, "Kroulik's three seasons as wheel footprints").

Kroulik, Kumhala, Hula, Honzik (Soil & Tillage Research 2009)
logged every machine of a season by DGPS (every 2 s), marked each machine's tyre widths and wheel
spacing, and reported the share of the field run over at least once: 95.3 % conventional
tillage, 72.8 % minimum tillage, 55.7 % direct seeding, and the "repeated" coverage 145.6 %,
44.8 %, 18.4 %. This module builds comparable seasons without the terrain engine: each machine
is a working width and a set of wheels (lateral position and width), driven along the operation's
plan (:func:`symtrack.studies.operations.plan_operation`: headland rounds, track lines, headland
turns); a cell is trafficked when its centre lies under a wheel's strip.

Geometry. Every wheel follows the machine's path line offset sideways by its ``lateral_m`` (left
positive), rigidly (ASSUMED: a trailed implement's off-tracking in the turns is not modelled). The
plan is straights and arcs (:class:`symtrack.control.path.Segment`); each segment's wheel strip is
rasterised in closed form (a rectangle; an annular sector of radii |R| -/+ lateral about the
arc's centre) on half-open intervals along the path, so that consecutive segments partition the
strip exactly. Passes per cell: one per segment that covers it (the union of the machine's wheels
over that segment: a tractor's front and rear tyres in line are one pass), summed over the
segments, the operations and their repeats.

"Repeated coverage": Kroulik's 18.4 % for direct seeding is below its 55.7 % run over at least
once, so it cannot be passes x area / field (which is at least the share run over once); it is
read here as the passes beyond the first, (sum of passes - cells run over) x cell area / field
(``repeated_excess_fraction``); ``passes_area_fraction`` (passes x area / field, the convention of
operations.field_shares) is given beside it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..foundations.config import check_keys, integer, number
from ..foundations.errors import ScenarioError
from .operations import OperationSettings, parse_operation, plan_operation

__all__ = ["KROULIK_2009", "MACHINES", "Machine", "SEASONS", "SeasonOp", "Wheel", "auto_headland_passes",
           "build_season", "machine_from_dict", "operation_counts", "season_counts", "season_shares", "segment_counts",
           "segment_geometry", "system_table"]

# Kroulik et al. 2009 (Soil & Tillage Research): run over at least once, "repeated coverage" (0-1)
KROULIK_2009 = {"conventional": (0.953, 1.456), "minimum": (0.728, 0.448), "direct": (0.557, 0.184)}
SYSTEM_LABELS = {"conventional": "conventional tillage", "minimum": "minimum tillage", "direct": "direct seeding"}
MACHINE_KEYS = ("name", "working_width_m", "outer_width_m", "turn_radius_m", "wheels")
WHEEL_KEYS = ("name", "lateral_m", "width_m")
OP_KEYS = ("name", "machine", "repeat", "tracks", "random_offset_m", "seed", "headland_passes", "same_lines_as",
           "direction")
DIRECTIONS = ("x", "y")  # the track lines along the field's x (its length) or across, along y


@dataclass(frozen=True)
class Wheel:
    name: str
    lateral_m: float  # the wheel's centre left of the machine's path line
    width_m: float


@dataclass(frozen=True)
class Machine:
    """A tractor with its implement (or a self-propelled machine): the working width (the line
    spacing of its plan), the overall width across (the wheels must lie inside it), the radius of
    its headland turns and corners, and the wheels."""

    name: str
    working_width_m: float
    outer_width_m: float
    turn_radius_m: float
    wheels: tuple

    @property
    def reach_m(self) -> float:
        return max(abs(w.lateral_m) + 0.5 * w.width_m for w in self.wheels)


def machine_from_dict(t: dict, where: str = "machine") -> Machine:
    """A machine table -> :class:`Machine`; bad values refused naming the key, the value and the range."""
    check_keys(where, t, MACHINE_KEYS)
    for k in ("working_width_m", "wheels"):
        if k not in t:
            raise ScenarioError(f"{where}.{k} is required")
    w = number(f"{where}.working_width_m", t["working_width_m"], 0.0, 100.0, low_open=True)
    outer = number(f"{where}.outer_width_m", t.get("outer_width_m", w), 0.0, 100.0, low_open=True)
    radius = number(f"{where}.turn_radius_m", t.get("turn_radius_m", 5.0), 0.5, 100.0)
    wl = t["wheels"]
    if not isinstance(wl, (list, tuple)) or not wl:
        raise ScenarioError(f"{where}.wheels = {wl!r} must be a non-empty list of wheel tables")
    wheels = []
    for i, wt in enumerate(wl):
        wh = f"{where}.wheels[{i}]"
        check_keys(wh, wt, WHEEL_KEYS)
        b = number(f"{wh}.width_m", wt.get("width_m"), 0.0, 3.0, low_open=True)
        half = 0.5 * outer - 0.5 * b
        lat = number(f"{wh}.lateral_m", wt.get("lateral_m"), -half, half) if half >= 0 else None
        if lat is None:
            raise ScenarioError(f"{wh}.width_m = {b:g} is outside the allowed range (0, {outer:g}] m (the machine's "
                                f"{where}.outer_width_m)")
        if radius < abs(lat) + 0.5 * b:
            raise ScenarioError(f"{where}.turn_radius_m = {radius:g} is outside the allowed range "
                                f"[{abs(lat) + 0.5 * b:g}, 100] m: the wheel {wh} would cross the turn's centre")
        wheels.append(Wheel(str(wt.get("name", f"wheel{i}")), lat, b))
    return Machine(str(t.get("name", where)), w, outer, radius, tuple(wheels))


def _pair(name, lateral, width):
    """A left and a right wheel at +-lateral."""
    return [{"name": f"{name} left", "lateral_m": lateral, "width_m": width},
            {"name": f"{name} right", "lateral_m": -lateral, "width_m": width}]


# ---- the machines (every value ASSUMED, typical of the named class: the paper's abstract says each
# machine's tyre widths and wheel spacing were marked, but its table could not be read here). Tyre
# widths are the section widths of common sizes; lateral positions are half the track gauge.
# Implements' packers, rollers and press wheels are not counted (ASSUMED: the paper marked tyres; a
# full-width packer of a 6 m drill would make every direct-seeded field 100 % run over).
_TRACTOR_LARGE = _pair("front 600/70R30", 1.0, 0.60) + _pair("rear 710/70R42", 1.0, 0.71)  # ~200 kW, gauge 2.0 m
_TRACTOR_MEDIUM = _pair("front 480/70R28", 0.9, 0.48) + _pair("rear 580/70R38", 0.9, 0.58)  # ~110 kW, gauge 1.8 m
MACHINES = {
    # a 6-furrow reversible semi-mounted plough, 6 x 0.45 m (the ~200 kW class); the tractor centred on
    # the swath (in-furrow ploughing's offset not modelled), the plough's own depth wheel not counted.
    # Sensitive: a 5 x 0.40 m plough (2.0 m, the tractor's gauge) puts each pass's land wheel in the
    # next pass's furrow-wheel track, and ploughing alone then runs over 41.8 % of the 300 m x 200 m
    # field instead of 53.1 % (measured, headlands included)
    "plough": {"working_width_m": 2.7, "outer_width_m": 2.8, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # a trailed short-disc harrow / stubble cultivator, 6 m (its roller not counted)
    "disc_6m": {"working_width_m": 6.0, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # a mounted chisel cultivator, 4.5 m (minimum tillage's deeper loosening)
    "chisel_4m5": {"working_width_m": 4.5, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # a seedbed combination (harrow, crumbler), 6 m
    "seedbed_6m": {"working_width_m": 6.0, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # conventional tillage's drill: a 4 m pneumatic drill on a rotary harrow, mounted
    "drill_4m": {"working_width_m": 4.0, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # a 6 m trailed drill with its own discs (minimum tillage) or a 6 m direct drill (direct seeding)
    "drill_6m": {"working_width_m": 6.0, "turn_radius_m": 5.0, "wheels": _TRACTOR_LARGE},
    # a trailed 24 m field sprayer (3000 l, tyres 380/90R46 in the tractor's track)
    "sprayer_24m": {"working_width_m": 24.0, "turn_radius_m": 6.0,
                    "wheels": _TRACTOR_MEDIUM + _pair("sprayer 380/90R46", 0.9, 0.38)},
    # a mounted twin-disc fertiliser spreader, 24 m
    "spreader_24m": {"working_width_m": 24.0, "turn_radius_m": 6.0, "wheels": _TRACTOR_MEDIUM},
    # a combine harvester with a 7.5 m header: front 800/65R32 at 2.7 m gauge, rear 500/70R24 at 2.4 m
    "combine_7m5": {"working_width_m": 7.5, "outer_width_m": 7.5, "turn_radius_m": 6.0,
                    "wheels": _pair("front 800/65R32", 1.35, 0.80) + _pair("rear 500/70R24", 1.2, 0.50)},
    # grain transport: a tractor and a two-axle 12 t trailer (500/60R22.5 at 1.9 m gauge) driving
    # beside the combine; one run per two combine swaths (a "working width" of 15 m)
    "grain_trailer": {"working_width_m": 15.0, "turn_radius_m": 6.0,
                      "wheels": _TRACTOR_MEDIUM + _pair("trailer 500/60R22.5", 0.95, 0.50)},
}


@dataclass(frozen=True)
class SeasonOp:
    name: str
    machine: Machine
    settings: OperationSettings
    repeat: int  # how many times this operation is driven on the same plan (tramline operations)
    direction: str = "x"  # "y": planned on the field turned (x and y exchanged), its lines along y


# ---- the three seasons (winter cereal; the sequences ASSUMED as typical Czech practice of the
# three systems, Kroulik et al. name only the systems): random traffic, each operation's AB lines
# moved by up to RANDOM_OFFSET_M (no guidance); the operations after drilling drive the drill's
# tramlines (one plan, seed "tramlines": the same tracks every time).
# ASSUMED: 0.5 m, the field operations' default (operations.OperationSettings.random_offset_m); a
# plough follows its last furrow (0.1 m)
RANDOM_OFFSET_M = 0.5
PLOUGH_OFFSET_M = 0.1
_TRAM = {"machine": "sprayer_24m", "same_lines_as": "tramlines"}
SEASONS = {
    "conventional": [
        {"name": "stubble discing", "machine": "disc_6m", "seed": 11},
        {"name": "P, K spreading", "machine": "spreader_24m", "seed": 12},
        {"name": "ploughing", "machine": "plough", "seed": 13, "random_offset_m": PLOUGH_OFFSET_M},
        {"name": "seedbed preparation", "machine": "seedbed_6m", "seed": 14},
        {"name": "drilling", "machine": "drill_4m", "seed": 15},
        {"name": "N spreading (tramlines)", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2},
        {"name": "spraying (tramlines)", **_TRAM, "repeat": 3},
        {"name": "harvest", "machine": "combine_7m5", "seed": 16},
        {"name": "grain transport", "machine": "grain_trailer", "seed": 17},
    ],
    "minimum": [
        {"name": "stubble discing", "machine": "disc_6m", "seed": 21},
        {"name": "P, K spreading", "machine": "spreader_24m", "seed": 22},
        {"name": "chisel cultivation", "machine": "chisel_4m5", "seed": 23},
        {"name": "drilling", "machine": "drill_6m", "seed": 24},
        {"name": "N spreading (tramlines)", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2},
        {"name": "spraying (tramlines)", **_TRAM, "repeat": 3},
        {"name": "harvest", "machine": "combine_7m5", "seed": 26},
        {"name": "grain transport", "machine": "grain_trailer", "seed": 27},
    ],
    "direct": [
        {"name": "glyphosate spraying", "machine": "sprayer_24m", "seed": 31},
        {"name": "P, K spreading", "machine": "spreader_24m", "seed": 32},
        {"name": "direct drilling", "machine": "drill_6m", "seed": 33},
        {"name": "N spreading (tramlines)", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2},
        {"name": "spraying (tramlines)", **_TRAM, "repeat": 2},
        {"name": "harvest", "machine": "combine_7m5", "seed": 36},
        {"name": "grain transport", "machine": "grain_trailer", "seed": 37},
    ],
}
# the field (ASSUMED: the paper's field sizes not read; a 6 ha rectangle, its 1 ha figure an excerpt)
FIELD_SIZE_M = (300.0, 200.0)
FIELD_CELL_M = 0.1
TRAMLINE_SEED = 99


def auto_headland_passes(machine: Machine, width_m: float) -> int:
    """The fewest headland rounds whose band holds the turns between lines one width apart (a U-turn
    reaches R beyond the line's end, a bulb sqrt(4R^2 - (R + s/2)^2) + R; the wheels' reach besides)."""
    R, s = machine.turn_radius_m, 0.5 * width_m  # random offsets: lines as close as half a width
    ext = R if s >= 2 * R else math.sqrt(max(4 * R * R - (R + 0.5 * s) ** 2, 0.0)) + R
    return max(1, int(math.ceil((ext + machine.reach_m + 0.5) / width_m)))


def build_season(ops, size_m=FIELD_SIZE_M, cell_m=FIELD_CELL_M, machines=None, where: str = "season"):
    """A list of operation tables (``OP_KEYS``) -> [:class:`SeasonOp`], every machine and plan checked
    before anything is rasterised."""
    machines = MACHINES if machines is None else machines
    if not isinstance(ops, (list, tuple)) or not ops:
        raise ScenarioError(f"{where} = {ops!r} must be a non-empty list of operation tables")
    Lx, Ly = (number(f"{where}.size_m[{i}]", v, 5.0, 1e4) for i, v in enumerate(size_m))
    cell = number(f"{where}.cell_m", cell_m, 0.01, 1.0)
    out = []
    shared: dict = {}
    for i, t in enumerate(ops):
        wh = f"{where}[{i}]"
        check_keys(wh, t, OP_KEYS)
        name = t.get("machine")
        if name not in machines:
            raise ScenarioError(f"{wh}.machine = {name!r} is not one of {', '.join(machines)}")
        m = machine_from_dict(machines[name], where=f"machines.{name}")
        m = dataclasses.replace(m, name=name)
        if m.working_width_m > min(Lx, Ly):
            raise ScenarioError(f"machines.{name}.working_width_m = {m.working_width_m:g} is outside the allowed range "
                                f"(0, {min(Lx, Ly):g}] m (the field is {Lx:g} m x {Ly:g} m)")
        repeat = integer(f"{wh}.repeat", t.get("repeat", 1), 1, 100)
        hp = t.get("headland_passes", "auto")
        if hp == "auto":
            hp = auto_headland_passes(m, m.working_width_m)
        else:
            hp = integer(f"{wh}.headland_passes", hp, 1, 20)
        direction = t.get("direction", "x")
        if direction not in DIRECTIONS:
            raise ScenarioError(f"{wh}.direction = {direction!r} is not one of {', '.join(DIRECTIONS)}")
        size = [Lx, Ly] if direction == "x" else [Ly, Lx]
        tracks = t.get("tracks", "random")
        seed = t.get("seed", i + 1)
        key = t.get("same_lines_as")
        if key is not None:
            seed = TRAMLINE_SEED
        doc = {"name": str(t.get("name", name)), "size_m": size, "cell_m": cell,
               "working_width_m": m.working_width_m, "headland_passes": hp, "tracks": tracks,
               "random_offset_m": t.get("random_offset_m", RANDOM_OFFSET_M), "seed": seed, "turn": "auto",
               "turn_radius_m": m.turn_radius_m}
        fs = parse_operation(doc, where=wh)
        if key is not None:
            if key in shared:
                if shared[key].working_width_m != fs.working_width_m or shared[key].size_m != fs.size_m:
                    raise ScenarioError(f"{wh}.same_lines_as = {key!r}: machines.{name}.working_width_m = "
                                        f"{fs.working_width_m:g} or its direction differs from the "
                                        f"first of those lines' ({shared[key].working_width_m:g} m)")
                fs = dataclasses.replace(shared[key], name=fs.name)
            else:
                shared[key] = fs
        plan_operation(fs)  # refuses bad plans (width, headlands, turns) before any raster
        out.append(SeasonOp(fs.name, m, fs, repeat, direction))
    return out


# ---- the raster --------------------------------------------------------------------------------------
def segment_geometry(plan):
    """Per segment of the plan's path: (kind, x0, y0, psi0, length or (centre, radius, sweep))."""
    p = plan.path
    x, y, psi = float(p.x[0]), float(p.y[0]), float(p.psi[0])
    out = []
    for seg in p.segments:
        if seg.kind == "straight":
            out.append(("straight", x, y, psi, seg.length_m))
            x += seg.length_m * math.cos(psi)
            y += seg.length_m * math.sin(psi)
        else:
            R = seg.radius_m
            d = math.radians(seg.angle_deg) * (1.0 if R > 0 else -1.0)
            out.append(("arc", x, y, psi, (R, math.radians(seg.angle_deg))))
            cx, cy = x - R * math.sin(psi), y + R * math.cos(psi)
            psi += d
            x, y = cx + R * math.sin(psi), cy - R * math.cos(psi)
    return out


def segment_counts(geometry, machine: Machine, shape, cell_m: float, counts=None) -> np.ndarray:
    """Passes per cell (nx, ny) int32 of the machine driven over the segments ``geometry`` (the
    output of the plan's segments: kind, start pose, length or (signed radius, sweep)); one pass per
    segment covering a cell centre (module doc)."""
    nx, ny = shape
    counts = np.zeros(shape, dtype=np.int32) if counts is None else counts
    reach = machine.reach_m
    for kind, x0, y0, psi0, g in geometry:
        c, s = math.cos(psi0), math.sin(psi0)
        if kind == "straight":
            L = g
            xs = [x0 - reach * s, x0 + reach * s, x0 + L * c - reach * s, x0 + L * c + reach * s]
            ys = [y0 + reach * c, y0 - reach * c, y0 + L * s + reach * c, y0 + L * s - reach * c]
        else:
            R, sweep = g
            cx, cy = x0 - R * s, y0 + R * c
            rr = abs(R) + reach
            xs, ys = [cx - rr, cx + rr], [cy - rr, cy + rr]
        i0 = max(int(math.floor(min(xs) / cell_m)) - 1, 0)
        i1 = min(int(math.ceil(max(xs) / cell_m)) + 1, nx)
        j0 = max(int(math.floor(min(ys) / cell_m)) - 1, 0)
        j1 = min(int(math.ceil(max(ys) / cell_m)) + 1, ny)
        if i1 <= i0 or j1 <= j0:
            continue
        px = (np.arange(i0, i1) + 0.5) * cell_m
        py = (np.arange(j0, j1) + 0.5) * cell_m
        union = np.zeros((i1 - i0, j1 - j0), dtype=bool)
        if kind == "straight":
            u = (px[:, None] - x0) * c + (py[None, :] - y0) * s
            v = -(px[:, None] - x0) * s + (py[None, :] - y0) * c
            along = (u >= 0.0) & (u < g)
            for w in machine.wheels:
                union |= along & (v >= w.lateral_m - 0.5 * w.width_m) & (v < w.lateral_m + 0.5 * w.width_m)
        else:
            R, sweep = g
            sg = 1.0 if R > 0 else -1.0
            dx, dy = px[:, None] - cx, py[None, :] - cy
            r = np.hypot(dx, dy)
            theta0 = math.atan2(y0 - cy, x0 - cx)
            a = np.mod(sg * (np.arctan2(dy, dx) - theta0), 2 * math.pi)
            along = a < sweep
            for w in machine.wheels:
                rw = abs(R) - sg * w.lateral_m  # a wheel to the left is inside a left turn
                union |= along & (r > rw - 0.5 * w.width_m) & (r <= rw + 0.5 * w.width_m)
        counts[i0:i1, j0:j1] += union
    return counts


def operation_counts(op: SeasonOp, shape=None, counts=None) -> np.ndarray:
    """Passes per cell (the field's (nx, ny)) of one season operation (its plan, its repeats)."""
    fs = op.settings
    turned = op.direction == "y"
    if shape is None:
        n0, n1 = int(round(fs.size_m[0] / fs.cell_m)), int(round(fs.size_m[1] / fs.cell_m))
        shape = (n1, n0) if turned else (n0, n1)
    counts = np.zeros(shape, dtype=np.int32) if counts is None else counts
    geo = segment_geometry(plan_operation(fs))
    one = segment_counts(geo, op.machine, (shape[1], shape[0]) if turned else shape, fs.cell_m)
    counts += op.repeat * (one.T if turned else one)  # turned: the plan's x is the field's y and back
    return counts


def season_counts(ops) -> np.ndarray:
    fs, op0 = ops[0].settings, ops[0]
    n0, n1 = int(round(fs.size_m[0] / fs.cell_m)), int(round(fs.size_m[1] / fs.cell_m))
    shape = (n1, n0) if op0.direction == "y" else (n0, n1)
    counts = np.zeros(shape, dtype=np.int32)
    for op in ops:
        operation_counts(op, shape, counts)
    return counts


def season_shares(counts: np.ndarray, cell_m: float, border_m: float = 30.0) -> dict:
    """The season's figures: share run over at least once (the field; its interior ``border_m`` from
    every edge), repeated coverage both ways (module doc), area run over once / twice / 3 or more."""
    c = counts.astype(np.int64)
    run = c > 0
    k = int(round(border_m / cell_m))
    inner = run[k:-k, k:-k] if k > 0 and 2 * k < min(c.shape) else run
    area = cell_m ** 2
    return {"trafficked_fraction": float(run.mean()), "interior_trafficked_fraction": float(inner.mean()),
            "repeated_excess_fraction": float((c.sum() - run.sum()) / c.size),
            "passes_area_fraction": float(c.sum() / c.size),
            "area_once_m2": float((c == 1).sum() * area), "area_twice_m2": float((c == 2).sum() * area),
            "area_3_or_more_m2": float((c >= 3).sum() * area), "passes_max": int(c.max())}


def system_table(size_m=FIELD_SIZE_M, cell_m=FIELD_CELL_M, systems=None) -> tuple[list, dict]:
    """The three seasons: rows (system, figures, Kroulik's) and the passes maps {system: counts}."""
    systems = SEASONS if systems is None else systems
    built = {k: build_season(v, size_m, cell_m, where=f"seasons.{k}") for k, v in systems.items()}  # all checked first
    rows, maps = [], {}
    for k, ops in built.items():
        counts = season_counts(ops)
        sh = season_shares(counts, cell_m)
        pub = KROULIK_2009.get(k, (float("nan"), float("nan")))
        rows.append({"system": k, "operations": sum(o.repeat for o in ops), **sh,
                     "kroulik_trafficked_fraction": pub[0], "kroulik_repeated_fraction": pub[1]})
        maps[k] = counts
    return rows, maps
