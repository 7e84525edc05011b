"""Scenarios: TOML files validated on load.

Schema (every key optional unless marked required; unknown keys are errors)::

    name = "validation"            # defaults to the file name
    description = "..."
    [run]
    duration_s = 30.0              # (0, 1e6]      simulated time limit
    output_dt_s = 0.01             # (0, duration] output (and macro) step
    integrator = "cvodes"          # cvodes | idas | rosenbrock (compiled fixed-step, docs/codegen.md)
    fixed_step_s = 0.01            # [1e-5, 0.1] rosenbrock: each output step is split into equal steps <= this
    compiled = false               # cvodes/idas on the compiled dynamics and Jacobian (docs/codegen.md)
    reltol = 1e-7                  # (0, 1e-2]
    abstol = 1e-9                  # (0, 1e-2]
    stop_after_distance_m = 20.0   # (0, 1e6]  stop once the CG has covered this path length ...
    stop_distance_event = "idle"   # ... counted from this [[torque]] event (default: from t = 0)
    [model]                        # numerical/structural options, see symtrack.model.ModelOptions
    traction_sign = "smooth"       # smooth | tanh | sign
    tanh_steepness_per_m = 1000.0
    [vehicle]
    preset = "reference_crawler"   # required; any vehicle parameter may follow as an override
    [soil]
    preset = "clayey_soil_thailand_38"   # required; any soil parameter may follow
    [start]
    x_m = 0.0
    y_m = 0.0
    yaw_deg = 0.0                  # [-360, 360]
    [[torque]]                     # required, at least one; held piecewise constant
    t_s = 0.0                      # the first entry at 0, then strictly increasing
    left_N_m = 2000.0              # [-1e6, 1e6]
    right_N_m = 2000.0
    event = "idle"                 # optional name, unique
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from .errors import ParameterError, ScenarioError
from .model.options import ModelOptions
from .parameters import SOIL_PARAMS, VEHICLE_PARAMS, check_set
from .presets import soil_preset, vehicle_preset
from .simulate import INTEGRATORS

TOP_KEYS = ("name", "description", "run", "model", "vehicle", "soil", "start", "torque")


@dataclass(frozen=True)
class TorqueEntry:
    t_s: float
    left_N_m: float
    right_N_m: float
    event: str | None = None


@dataclass(frozen=True)
class RunSettings:
    duration_s: float = 30.0
    output_dt_s: float = 0.01
    integrator: str = "cvodes"
    reltol: float = 1e-7
    abstol: float = 1e-9
    stop_after_distance_m: float | None = None
    stop_distance_event: str | None = None
    fixed_step_s: float = 0.01
    compiled: bool = False


@dataclass(frozen=True)
class Start:
    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    run: RunSettings
    model: ModelOptions
    vehicle_preset: str
    vehicle: dict
    soil_preset: str
    soil: dict
    start: Start
    torque: tuple[TorqueEntry, ...]
    extra: dict = field(default_factory=dict)

    @property
    def params(self) -> dict:
        return {**self.vehicle, **self.soil}

    def event_time(self, name: str) -> float:
        for e in self.torque:
            if e.event == name:
                return e.t_s
        raise ScenarioError(f"no [[torque]] entry has event = {name!r}")

    def torque_at(self, t: float) -> tuple[float, float]:
        cur = self.torque[0]
        for e in self.torque:
            if e.t_s <= t + 1e-12:
                cur = e
        return cur.left_N_m, cur.right_N_m

    def to_dict(self) -> dict:
        d = {"name": self.name, "description": self.description,
             "run": {k: v for k, v in dataclasses.asdict(self.run).items() if v is not None},
             "model": dataclasses.asdict(self.model),
             "vehicle": {"preset": self.vehicle_preset, **self.vehicle},
             "soil": {"preset": self.soil_preset, **self.soil},
             "start": dataclasses.asdict(self.start),
             "torque": [{k: v for k, v in dataclasses.asdict(e).items() if v is not None} for e in self.torque]}
        d.update(self.extra)
        return d


def number(where: str, value, low: float, high: float, low_open: bool = False) -> float:
    """A finite number in [low, high] (or (low, high]); the error names where, the value and the range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{where} = {value!r} must be a number")
    v = float(value)
    ok = (v > low if low_open else v >= low) and v <= high and math.isfinite(v)
    if not ok:
        lb = "(" if low_open else "["
        raise ScenarioError(f"{where} = {value!r} is outside the allowed range {lb}{low:g}, {high:g}]")
    return v


def _num(section, key, value, low, high, low_open=False):
    return number(f"{section}.{key}", value, low, high, low_open)


def check_keys(section, table, allowed):
    """Unknown keys of a table are errors that list the allowed ones."""
    if not isinstance(table, dict):
        raise ScenarioError(f"[{section}] must be a table, got {table!r}")
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ScenarioError(
            f"unknown key(s) in [{section}]: {', '.join(unknown)}; allowed: {', '.join(allowed)}")


def _parse_run(t: dict) -> RunSettings:
    fields = [f.name for f in dataclasses.fields(RunSettings)]
    check_keys("run", t, fields)
    d = RunSettings()
    duration = _num("run", "duration_s", t.get("duration_s", d.duration_s), 0, 1e6, True)
    out_dt = _num("run", "output_dt_s", t.get("output_dt_s", d.output_dt_s), 0, duration, True)
    integ = t.get("integrator", d.integrator)
    if integ not in INTEGRATORS:
        raise ScenarioError(f"run.integrator = {integ!r} is not one of {', '.join(INTEGRATORS)}")
    reltol = _num("run", "reltol", t.get("reltol", d.reltol), 0, 1e-2, True)
    abstol = _num("run", "abstol", t.get("abstol", d.abstol), 0, 1e-2, True)
    stop = t.get("stop_after_distance_m")
    if stop is not None:
        stop = _num("run", "stop_after_distance_m", stop, 0, 1e6, True)
    ev = t.get("stop_distance_event")
    if ev is not None and not isinstance(ev, str):
        raise ScenarioError(f"run.stop_distance_event = {ev!r} must be the name of a [[torque]] event")
    if ev is not None and stop is None:
        raise ScenarioError("run.stop_distance_event is set but run.stop_after_distance_m is not")
    fixed = _num("run", "fixed_step_s", t.get("fixed_step_s", d.fixed_step_s), 1e-5, 0.1)
    compiled = t.get("compiled", d.compiled)
    if not isinstance(compiled, bool):
        raise ScenarioError(f"run.compiled = {compiled!r} must be true or false")
    return RunSettings(duration, out_dt, integ, reltol, abstol, stop, ev, fixed, compiled)


def _parse_model(t: dict) -> ModelOptions:
    fields = [f.name for f in dataclasses.fields(ModelOptions)]
    check_keys("model", t, fields)
    try:
        return ModelOptions(**t)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err


def parse_params(section, t, preset_fn, specs, default_preset=None):
    """A [vehicle] or [soil] table: preset plus overrides, validated as a complete set."""
    names = [s.name for s in specs]
    check_keys(section, t, ["preset"] + names)
    preset = t.get("preset", default_preset)
    if not isinstance(preset, str):
        raise ScenarioError(f"{section}.preset is required (a preset name), got {preset!r}")
    try:
        values = preset_fn(preset)
        overrides = {k: v for k, v in t.items() if k != "preset"}
        values.update(overrides)
        values = check_set(values, specs, section)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    return preset, values


def _parse_torque(entries) -> tuple[TorqueEntry, ...]:
    if not isinstance(entries, list) or not entries:
        raise ScenarioError("[[torque]] is required: at least one entry with t_s, left_N_m, right_N_m")
    out, events = [], set()
    for i, e in enumerate(entries):
        sec = f"torque[{i}]"
        check_keys(sec, e, ["t_s", "left_N_m", "right_N_m", "event"])
        for k in ("t_s", "left_N_m", "right_N_m"):
            if k not in e:
                raise ScenarioError(f"{sec}.{k} is required")
        t = _num(sec, "t_s", e["t_s"], 0, 1e6)
        left = _num(sec, "left_N_m", e["left_N_m"], -1e6, 1e6)
        right = _num(sec, "right_N_m", e["right_N_m"], -1e6, 1e6)
        if i == 0 and t != 0.0:
            raise ScenarioError(f"{sec}.t_s = {e['t_s']!r}: the first torque entry must be at t_s = 0")
        if out and t <= out[-1].t_s:
            raise ScenarioError(
                f"{sec}.t_s = {e['t_s']!r} is not after the previous entry's t_s = {out[-1].t_s!r}: "
                "torque entries must be in strictly increasing time order")
        ev = e.get("event")
        if ev is not None:
            if not isinstance(ev, str) or not ev:
                raise ScenarioError(f"{sec}.event = {ev!r} must be a non-empty string")
            if ev in events:
                raise ScenarioError(f"{sec}.event = {ev!r} is used twice")
            events.add(ev)
        out.append(TorqueEntry(t, left, right, ev))
    return tuple(out)


def _parse_start(t) -> Start:
    check_keys("start", t, ["x_m", "y_m", "yaw_deg"])
    return Start(_num("start", "x_m", t.get("x_m", 0.0), -1e7, 1e7),
                 _num("start", "y_m", t.get("y_m", 0.0), -1e7, 1e7),
                 _num("start", "yaw_deg", t.get("yaw_deg", 0.0), -360, 360))


EXTRA_SECTIONS: dict = {}  # section name -> validator(dict) -> dict, registered by extensions


def _register_builtin_sections():
    from .terrain.config import validate_section

    EXTRA_SECTIONS.setdefault("terrain", validate_section)  # [terrain]: symtrack/terrain/config.py


_register_builtin_sections()


def scenario_from_dict(d: dict, default_name: str = "scenario") -> Scenario:
    check_keys("scenario", d, TOP_KEYS + tuple(EXTRA_SECTIONS))
    name = d.get("name", default_name)
    desc = d.get("description", "")
    if not isinstance(name, str) or not isinstance(desc, str):
        raise ScenarioError("name and description must be strings")
    run = _parse_run(d.get("run", {}))
    model = _parse_model(d.get("model", {}))
    vp, vehicle = parse_params("vehicle", d.get("vehicle", {}), vehicle_preset, VEHICLE_PARAMS)
    sp, soil = parse_params("soil", d.get("soil", {}), soil_preset, SOIL_PARAMS)
    start = _parse_start(d.get("start", {}))
    torque = _parse_torque(d.get("torque"))
    extra = {k: EXTRA_SECTIONS[k](d[k]) for k in EXTRA_SECTIONS if k in d}
    sc = Scenario(name, desc, run, model, vp, vehicle, sp, soil, start, torque, extra)
    events = [e.event for e in torque if e.event]
    if run.stop_distance_event is not None and run.stop_distance_event not in events:
        raise ScenarioError(f"run.stop_distance_event = {run.stop_distance_event!r} names no [[torque]] event; "
                            f"events: {', '.join(events) or 'none'}")
    return sc


def builtin_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("symtrack.scenarios").iterdir() if p.name.endswith(".toml"))


def _parse_override(item: str):
    if "=" not in item or "." not in item.split("=", 1)[0]:
        raise ScenarioError(f"--set {item!r}: expected section.key=value, e.g. run.integrator=idas")
    key, raw = item.split("=", 1)
    section, name = key.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return section, name.strip(), value


def load_scenario(name_or_path: str, overrides: list[str] | tuple[str, ...] = ()) -> Scenario:
    """Load a built-in scenario by name or a TOML file by path, apply --set overrides, validate."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ScenarioError(f"scenario file {str(path)!r} does not exist")
        text, default_name = path.read_text(), path.stem
    elif name_or_path in builtin_names():
        text = resources.files("symtrack.scenarios").joinpath(name_or_path + ".toml").read_text()
        default_name = name_or_path
    else:
        known = ", ".join(builtin_names())
        raise ScenarioError(f"scenario {name_or_path!r} is neither a file nor a built-in scenario; built-in: {known}")
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{name_or_path}: not valid TOML: {err}") from err
    for item in overrides:
        section, key, value = _parse_override(item)
        if section == "torque":
            raise ScenarioError("--set cannot change [[torque]] entries; write a scenario file instead")
        d.setdefault(section, {})
        if not isinstance(d[section], dict):
            raise ScenarioError(f"--set {item!r}: [{section}] is not a table")
        d[section][key] = value
    return scenario_from_dict(d, default_name)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def to_toml(d: dict) -> str:
    """Write a scenario dict (tables, arrays of tables, scalars) as TOML."""
    lines = []
    for k, v in d.items():
        if not isinstance(v, (dict, list)) or (isinstance(v, list) and v and not isinstance(v[0], dict)):
            lines.append(f"{k} = {_toml_value(v)}")
    for k, v in d.items():
        if isinstance(v, dict):
            lines.append(f"\n[{k}]")
            lines += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items() if vv is not None]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines.append(f"\n[[{k}]]")
                lines += [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items() if vv is not None]
    return "\n".join(lines) + "\n"
