"""The configuration grammar shared by every scenario kind: TOML documents, ``--set`` overrides,
number and key checks, and writing a document back as TOML.

A scenario document is read once, by :func:`read_document` (a built-in name of a scenario
package or a file path, then the overrides), and its sections are checked by the schema of
its kind (:mod:`symtrack.simulation.scenario`, :mod:`symtrack.control.scenario`) with the
helpers here, so that every error names the key, the value and the allowed range.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from .errors import ScenarioError
from .files import read_text

__all__ = ["Key", "number", "integer", "check_document", "check_keys", "key_table", "parse_override", "apply_overrides",
           "short_number", "key_hints", "list_hint", "builtin_names", "read_document", "resolve_file_paths",
           "resolve_paths", "to_toml"]


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


@dataclass(frozen=True)
class Key:
    """One key of a scenario section as the loader checks it and the documentation's key tables show it
    (docs/scenarios.md, "Keys of a simulation"; :func:`key_table`): its meaning, and for a number its
    range ([low, high], or (low, high] with ``low_open``) or for a choice its ``choices``; ``allowed``
    replaces the range's text where the check is more than a range (a bound that depends on another key)."""

    name: str
    meaning: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple = ()
    allowed: str = ""
    integer: bool = False

    def check(self, section: str, value):
        """The value checked against the declared range (an error names the key, the value and the range)."""
        if self.integer:
            return integer(f"{section}.{self.name}", value, int(self.low), int(self.high))
        return number(f"{section}.{self.name}", value, self.low, self.high, self.low_open)

    def range_text(self) -> str:
        if self.allowed:
            return self.allowed
        if self.choices:
            return " or ".join(_default_text(c) for c in self.choices)
        if self.low is not None:
            if self.integer:
                return f"integer in [{short_number(self.low)}, {short_number(self.high)}]"
            return f"{'(' if self.low_open else '['}{short_number(self.low)}, {short_number(self.high)}]"
        return ""


def short_number(v: float) -> str:
    """A number as the key tables write it: 1e6, not 1e+06."""
    return f"{v:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")


def _default_text(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "`true`" if value else "`false`"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, (tuple, list)):
        return "`[" + ", ".join(short_number(v) if isinstance(v, float) else str(v) for v in value) + "]`"
    if isinstance(value, float):
        return f"`{short_number(value)}`"
    return f"`{value}`"


def key_table(rows) -> str:
    """A Markdown table of (key, default, allowed, meaning) rows: the default a value (written as TOML
    writes it) or, as a ``str`` starting with "-", a word ("- required"); allowed and meaning text."""
    lines = ["| key | default | allowed | meaning |", "|---|---|---|---|"]
    for name, default, allowed, meaning in rows:
        d = default[2:] if isinstance(default, str) and default.startswith("- ") else _default_text(default)
        cells = (f"`{name}`", d, allowed, meaning)
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def integer(where: str, value, low: int, high: int) -> int:
    """An integer in [low, high] (a float with an integer value is accepted, as TOML writes 3.0)."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ScenarioError(f"{where} = {value!r} must be an integer in [{low}, {high}]")
    return value


def key_hints(unknown: Iterable[str], allowed: Iterable[str]) -> str:
    """What an unknown key was likely meant to be, as text to follow an error ("" when nothing is
    close): a key of the same name in another unit (``friction_angle_deg`` -> ``friction_angle_rad``,
    in radians; ``cohesion_kPa`` -> ``cohesion_Pa``), else a near spelling."""
    allowed = list(allowed)
    hints = []
    for key in unknown:
        stem = key.rsplit("_", 1)[0] if "_" in key else key
        same = [a for a in allowed if "_" in a and a.rsplit("_", 1)[0] == stem and a != key]
        if same:
            unit = same[0].rsplit("_", 1)[1]
            note = {"rad": " (in radians: degrees x pi / 180)"}.get(unit, f" (in {unit})")
            hints.append(f"{key}: did you mean {same[0]}{note}?")
            continue
        close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.75)
        if close:
            hints.append(f"{key}: did you mean {close[0]}?")
    return (". " + "; ".join(hints)) if hints else ""


def list_hint(where: str, value) -> str:
    """What follows an error on a value that should be a list but came as text (a ``--set`` without the
    brackets): how to write it on the command line; "" for any other value."""
    if not isinstance(value, str):
        return ""
    items = [v.strip() for v in value.strip("()").split(",") if v.strip()]
    return f" (on the command line, in brackets: --set '{where}=[{', '.join(items) or '...'}]')"


def check_keys(section: str, table, allowed: Iterable[str]) -> None:
    """Unknown keys of a table are errors that list the allowed ones."""
    allowed = list(allowed)
    if not isinstance(table, dict):
        raise ScenarioError(f"[{section}] must be a table, got {table!r}")
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ScenarioError(
            f"unknown key(s) in [{section}]: {', '.join(unknown)}; allowed: {', '.join(allowed)}"
            f"{key_hints(unknown, allowed)}")


def check_document(kind: str, doc, top_keys: Iterable[str], arrays: Iterable[str] = ()) -> None:
    """A document's top level: a table with only ``top_keys`` (and :data:`VERSION_KEY`, which every
    document may hold); ``name``, ``description`` and the version strings; every other key a table,
    those of ``arrays`` arrays of tables ([[key]])."""
    check_keys(kind, doc, (*top_keys, VERSION_KEY))
    arrays = tuple(arrays)
    for k, v in doc.items():
        if k in ("name", "description", VERSION_KEY):
            if not isinstance(v, str):
                raise ScenarioError(f"{k} = {v!r} must be a string")
        elif k in arrays:
            if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
                raise ScenarioError(f"{k} = {v!r} must be an array of tables ([[{k}]] entries)")
        elif not isinstance(v, dict):
            raise ScenarioError(f"[{k}] must be a table, got {k} = {v!r}")


def parse_override(item: str) -> tuple[str, str, object]:
    """``section.key=value`` -> (section, key, value); the value is read as TOML, else as a string.
    ``key`` may hold dots (``terrain.surface.slope_y_deg=5``: the key ``surface.slope_y_deg`` of
    [terrain], which :func:`apply_overrides` puts into the nested table [terrain.surface])."""
    if not isinstance(item, str) or "=" not in item or "." not in item.split("=", 1)[0]:
        raise ScenarioError(f"--set {item!r}: expected section.key=value, e.g. run.integrator=idas")
    key, raw = item.split("=", 1)
    section, name = key.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return section, name.strip(), value


def apply_overrides(doc: dict, overrides) -> dict:
    """Apply ``--set`` overrides (strings ``section.key=value``, or a mapping ``{"section.key":
    value}`` whose values are Python values) to a document, in place; returns it."""
    if overrides is None:
        return doc
    if isinstance(overrides, Mapping):
        items = []
        for key, value in overrides.items():
            if not isinstance(key, str) or "." not in key:
                raise ScenarioError(f"override {key!r}: expected a 'section.key' name, e.g. 'run.integrator'")
            section, name = key.split(".", 1)
            items.append((f"{key}={value!r}", section.strip(), name.strip(), value))
    else:
        if isinstance(overrides, str):
            raise ScenarioError(f"overrides = {overrides!r}: give a list of 'section.key=value' strings or a dict")
        items = [(item, *parse_override(item)) for item in overrides]
    for item, section, key, value in items:
        if section == "torque":
            raise ScenarioError("--set cannot change [[torque]] entries; write a scenario file instead")
        # section.table.key=value reaches a nested table ([terrain.surface], [terrain.towed], ...),
        # made where it is missing
        path = [section, *(k.strip() for k in key.split("."))]
        if any(not k for k in path):
            raise ScenarioError(f"--set {item!r}: an empty name in {'.'.join(path)!r}")
        table = doc
        for depth, name in enumerate(path[:-1]):
            table.setdefault(name, {})
            if not isinstance(table[name], dict):
                raise ScenarioError(f"--set {item!r}: [{'.'.join(path[:depth + 1])}] is not a table")
            table = table[name]
        table[path[-1]] = value
    return doc


def builtin_names(package: str) -> list[str]:
    """The scenario names (TOML files) of a scenario package."""
    return sorted(p.name[:-5] for p in resources.files(package).iterdir() if p.name.endswith(".toml"))


def resolve_paths(doc: dict, folder: Path, keys=()) -> dict:
    """Resolve the relative file paths of ``doc`` at ``keys`` (tuples of table names ending with the
    key, e.g. ("terrain", "soil_map", "raster")) against ``folder``, in place; returns ``doc``."""
    for key in keys:
        table = doc
        for name in key[:-1]:
            table = table.get(name) if isinstance(table, dict) else None
        if isinstance(table, dict) and isinstance(table.get(key[-1]), str):
            p = Path(table[key[-1]]).expanduser()
            table[key[-1]] = str(p if p.is_absolute() else folder / p)
    return doc


def read_document(name_or_path: str, package: str, kind: str = "scenario", overrides=None,
                  paths=()) -> tuple[dict, str]:
    """A scenario document by built-in name (of ``package``) or by TOML file path, with the
    overrides applied. Returns (document, default name). ``kind`` names the scenario kind in
    messages. ``paths``: the keys holding file paths (:func:`resolve_paths`): in a file, a
    relative path is resolved against the file's folder (an override's stays as given)."""
    if not isinstance(name_or_path, (str, Path)):
        raise ScenarioError(f"{kind} {name_or_path!r}: give a built-in name or a TOML file path")
    name_or_path = str(name_or_path)
    path = Path(name_or_path)
    names = builtin_names(package)
    if path.suffix == ".toml" or (name_or_path not in names and path.exists()):
        if not path.is_file():
            raise ScenarioError(f"{kind} file {str(path)!r} does not exist")
        text, default_name = read_text(path, f"{kind} file"), path.stem
        folder = path.resolve().parent
    elif name_or_path in names:
        text = resources.files(package).joinpath(name_or_path + ".toml").read_text()
        default_name = name_or_path
        folder = None
    else:
        raise ScenarioError(f"{kind} {name_or_path!r} is neither a file nor a built-in {kind}; "
                            f"built-in: {', '.join(names)}")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{name_or_path}: not valid TOML: {err}") from err
    if folder is not None:
        resolve_paths(doc, folder, paths)
        doc = resolve_file_paths(doc, folder)
    return apply_overrides(doc, overrides), default_name


def _relative_to(value, folder: Path, suffixes: tuple[str, ...]):
    if isinstance(value, str) and value and value.endswith(suffixes) and not Path(value).expanduser().is_absolute():
        return str(folder / Path(value).expanduser())
    return value


def resolve_file_paths(doc: dict, folder: Path) -> dict:
    """The file paths inside a scenario document (``vehicle.preset`` and ``soil.preset`` naming a
    preset file, ``terrain.initial_state``, ``terrain.soil_map.raster`` and the preset files among
    ``terrain.soil_map.soils``) taken relative to ``folder``, the scenario file's, not the current
    folder (a copy; absolute paths and built-in names are left alone; ``--set`` values stay relative to
    the current folder, as a shell's arguments are)."""
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in doc.items()}
    for section in ("vehicle", "soil"):
        if isinstance(doc.get(section), dict) and "preset" in doc[section]:
            doc[section]["preset"] = _relative_to(doc[section]["preset"], folder, (".toml",))
    terrain = doc.get("terrain")
    if isinstance(terrain, dict):
        if "initial_state" in terrain:
            terrain["initial_state"] = _relative_to(terrain["initial_state"], folder, ("",))
        sm = terrain.get("soil_map")
        if isinstance(sm, dict):
            sm = terrain["soil_map"] = dict(sm)
            if "raster" in sm:
                sm["raster"] = _relative_to(sm["raster"], folder, (".npy",))
            if isinstance(sm.get("soils"), list):
                sm["soils"] = [
                    {**e, "preset": _relative_to(e["preset"], folder, (".toml",))} if isinstance(e, dict) and
                    "preset" in e else _relative_to(e, folder, (".toml",)) for e in sm["soils"]]
    return doc


_TOML_ESCAPES = {"\\": "\\\\", '"': '\\"', "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _toml_key(k) -> str:
    """A bare key when TOML allows one, else a quoted key."""
    k = str(k)
    return k if k and all(c.isascii() and (c.isalnum() or c in "_-") for c in k) else _toml_value(k)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):  # a basic string: backslash, quote and every control character escaped (TOML 1.0)
        return '"' + "".join(_TOML_ESCAPES.get(c) or (f"\\u{ord(c):04x}" if ord(c) < 32 or ord(c) == 127 else c)
                             for c in v) + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):  # an inline table
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items() if x is not None) + "}"
    raise TypeError(f"cannot write {v!r} as TOML")


# the key of a resolved scenario that records the symtrack that wrote it (:func:`with_version`); every
# document may hold it (:func:`check_document`) and the loaders ignore it
VERSION_KEY = "symtrack_version"


def with_version(doc: dict) -> dict:
    """``doc`` with the package's version first (:data:`VERSION_KEY`): a resolved scenario's record of
    the symtrack that ran it (scenario.resolved.toml)."""
    from .version import __version__

    return {VERSION_KEY: __version__, **{k: v for k, v in doc.items() if k != VERSION_KEY}}


def to_toml(d: dict) -> str:
    """Write a document (tables, arrays of tables, scalars) as TOML."""
    lines = []
    for k, v in d.items():
        if not isinstance(v, dict) and not _is_table_array(v):
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for k, v in d.items():
        if isinstance(v, dict):
            lines.append(f"\n[{_toml_key(k)}]")
            lines += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in v.items() if vv is not None]
        elif _is_table_array(v):
            for item in v:
                lines.append(f"\n[[{_toml_key(k)}]]")
                lines += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in item.items() if vv is not None]
    return "\n".join(lines) + "\n"
