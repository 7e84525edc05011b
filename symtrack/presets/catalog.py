"""What ``symtrack presets`` shows: every parameter of a preset with its value, unit, meaning and
source. The sources are the comments written above each entry of :mod:`.vehicles` and
:mod:`.soils` (their one home), read from the source text; a soil built by ``_wong``/``_chrono``
has one comment for the preset, and its module constants (cell mass and damping, the elastic
stiffness and the unloading floor) have theirs above their definitions.

User preset files (``[vehicle] preset = "my_crawler.toml"``): a TOML file with an optional
``base`` (a built-in preset the file starts from), an optional ``description``, any parameters
(SI values, names with units as in ``symtrack presets``) and an optional ``[sources]`` table
(parameter -> where the value comes from); the format is documented in docs/scenarios.md ("Preset
files"). :func:`preset_file_kind` tells a vehicle file from a soil file by its keys.
"""

from __future__ import annotations

import ast
import inspect
import io
import math
import textwrap
import tokenize
import tomllib
from pathlib import Path

from ..foundations.config import key_hints
from ..foundations.errors import ParameterError
from ..foundations.files import read_text
from ..foundations.params import unit_of_name
from ..model.parameters import SOIL_PARAMS, VEHICLE_PARAMS, ParamSet, check_set, known_soil_names, spec
from ..soil.pedotransfer import derivation_note
from . import soils, vehicles

__all__ = ["PRESET_FILE_KEYS", "describe", "format_preset", "preset_file_kind", "preset_names", "preset_sources",
           "read_preset_file", "unit_of"]

PRESET_FILE_KEYS = ("base", "description", "sources")


def unit_of(name: str) -> str:
    """The unit of the parameter ``name`` (its declaration's; "-" for a dimensionless one)."""
    try:
        return spec(name).unit
    except KeyError:
        return unit_of_name(name)


def _comments_above(module) -> dict[int, str]:
    """line number -> the comment block that ends on the line above it."""
    src = inspect.getsource(module)
    blocks, cur, last = {}, [], -10
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.COMMENT:
            line = tok.start[0]
            cur = cur + [tok.string.lstrip("# ")] if line == last + 1 else [tok.string.lstrip("# ")]
            last = line
            blocks[line + 1] = " ".join(cur)
    return blocks


def preset_sources(kind: str, name: str) -> dict[str, str]:
    """parameter -> the source comment of its value in the preset ``name`` ("" when none)."""
    module, table = (vehicles, "VEHICLES") if kind == "vehicle" else (soils, "SOILS")
    comments = _comments_above(module)
    tree = ast.parse(inspect.getsource(module))
    out: dict[str, str] = {}
    for node in ast.walk(tree):
        target = node.target if isinstance(node, ast.AnnAssign) else None
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
        if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(target, ast.Name):
            if target.id == table and isinstance(node.value, ast.Dict):
                for key, value in zip(node.value.keys, node.value.values, strict=True):
                    if not (isinstance(key, ast.Constant) and key.value == name):
                        continue
                    preset_note = comments.get(key.lineno, "")
                    if isinstance(value, ast.Dict):
                        for k, _ in zip(value.keys, value.values, strict=True):
                            out[k.value] = comments.get(k.lineno, preset_note)
                    else:  # a soil built by _wong/_chrono: the preset's note
                        out["*"] = preset_note
            elif target.id.isupper():
                out.setdefault("#" + target.id, comments.get(node.lineno, ""))
    return out


def preset_names(kind: str) -> list[str]:
    return sorted(vehicles.VEHICLES if kind == "vehicle" else soils.SOILS)


def preset_file_kind(path) -> str:
    """"vehicle" or "soil": the kind of a user preset file, read from its keys (the parameters it
    sets, the built-in preset its ``base`` names); a ParameterError when they do not tell."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"preset file {str(path)!r}: no such file")
    try:
        d = tomllib.loads(read_text(path, "preset file", ParameterError))
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: not valid TOML: {err}") from err
    kinds = set()
    for kind, specs, table in (("vehicle", VEHICLE_PARAMS, vehicles.VEHICLES), ("soil", SOIL_PARAMS, soils.SOILS)):
        if d.get("base") in table or any(s.name in d for s in specs):
            kinds.add(kind)
    if len(kinds) != 1:
        raise ParameterError(f"{path}: cannot tell whether this is a vehicle or a soil preset file (its base and "
                             "parameters name " + (" and ".join(sorted(kinds)) or "neither") + "); give --kind")
    return kinds.pop()


def _file_specs(kind: str, d=()) -> tuple:
    """The parameters a user preset file of ``kind`` holds: the default model's, and for a soil file the
    coefficients of another registered soil law (or vehicle) it sets (a plug-in's, declared in its module)."""
    if kind == "vehicle":
        return VEHICLE_PARAMS
    own = {s.name for s in SOIL_PARAMS}
    return SOIL_PARAMS + tuple(spec(n) for n in known_soil_names() if n in d and n not in own)


def _preset_file_doc(path, kind: str) -> dict:
    """A user preset file's TOML document, its keys checked."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"{kind}.preset = {str(path)!r}: no such preset file")
    try:
        d = tomllib.loads(read_text(path, f"{kind}.preset file", ParameterError))
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: not valid TOML: {err}") from err
    names = [s.name for s in _file_specs(kind, d)]
    unknown = sorted(set(d) - set(names) - set(PRESET_FILE_KEYS))
    if unknown:
        raise ParameterError(f"{path}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(PRESET_FILE_KEYS)} "
                             f"and the {kind} parameters ({', '.join(names)}){key_hints(unknown, names)}")
    sources = d.get("sources", {})
    if not isinstance(sources, dict) or set(sources) - set(names):
        raise ParameterError(f"{path}: [sources] must map {kind} parameter names to text")
    return d


def read_preset_file(path, kind: str) -> tuple[dict[str, float], dict[str, str], str]:
    """A user preset file -> (values, sources, description), checked as a complete set."""
    d = _preset_file_doc(path, kind)
    specs = _file_specs(kind, d)
    names = [s.name for s in specs]
    values = ParamSet()
    base = d.get("base")
    if base is not None:  # (the base's set as it is: what its description derived is derived again)
        values = vehicles.vehicle_preset(base) if kind == "vehicle" else soils.soil_preset(base)
    values = values.with_given({k: v for k, v in d.items() if k in names})
    return (check_set(values, specs, f"{kind} preset file {str(path)!r}"), dict(d.get("sources", {})),
            str(d.get("description", "")))


_CONSTS = {"cell_areal_mass_kg_per_m2": "#CELL_AREAL_MASS_KG_PER_M2",
           "cell_damping_Pa_s_per_m": "#CELL_DAMPING_PA_S_PER_M",
           "elastic_stiffness_Pa_per_m": "#WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M",
           "unloading_stiffness_floor": "#UNLOADING_STIFFNESS_FLOOR"}


def _default_note(spec) -> str:
    return f"default: {spec.default_source}" if spec.default_source else "default"


def describe(kind: str, name: str) -> list[tuple[str, float, str, str, str]]:
    """(parameter, value, unit, meaning, source) of every parameter of a built-in preset or a
    user preset file. The source says where the value comes from: a built-in preset's source; in a
    preset file "set in FILE" (with the file's own [sources] entry), "from BASE: ..." (the base's
    source) for a value the file inherits; "derived ..." (how) for a value derived from the soil's
    description; "default: ..." for the registry's default."""
    specs = VEHICLE_PARAMS if kind == "vehicle" else SOIL_PARAMS
    if str(name).endswith(".toml"):
        return _describe_file(kind, name, _file_specs(kind, _preset_file_doc(name, kind)))
    values = vehicles.vehicle_preset(name) if kind == "vehicle" else soils.soil_preset(name)
    notes = preset_sources(kind, name)
    raw = vehicles.VEHICLES[name] if kind == "vehicle" else soils.SOILS[name]
    derived = getattr(values, "derived", {})
    rows = []
    for s in specs:
        if s.name in derived:
            src = derivation_note(s.name, values)
        elif s.name not in raw and s.default is not None:
            src = _default_note(s)
        else:
            src = notes.get(s.name) or notes.get(_CONSTS.get(s.name, ""), "") or notes.get("*", "")
        rows.append((s.name, values[s.name], s.unit, s.description, src))
    return rows


def _describe_file(kind: str, path, specs) -> list[tuple[str, float, str, str, str]]:
    d = _preset_file_doc(path, kind)
    values, sources, _ = read_preset_file(path, kind)
    base = d.get("base")
    base_rows = {r[0]: r for r in describe(kind, base)} if base is not None else {}
    derived = getattr(values, "derived", {})
    label = Path(path).name
    rows = []
    for s in specs:
        if s.name in d:
            src = f"set in {label}" + (f": {sources[s.name]}" if sources.get(s.name) else "")
        elif sources.get(s.name):
            src = sources[s.name]
        elif s.name in derived:
            src = derivation_note(s.name, values)
        elif s.name in base_rows:
            src = f"from {base}: {base_rows[s.name][4]}" if base_rows[s.name][4] else f"from {base}"
        elif s.default is not None:
            src = _default_note(s)
        else:
            src = ""
        rows.append((s.name, values[s.name], s.unit, s.description, src))
    return rows


def _value_text(name: str, value: float) -> str:
    """A value as symtrack presets prints it; an angle also in degrees."""
    text = f"{value:.6g}"
    return f"{text} ({math.degrees(value):.4g} deg)" if name.endswith("_rad") else text


def format_preset(kind: str, name: str, wide: bool = False, width: int = 100) -> str:
    """What ``symtrack presets NAME`` prints. The default view fits ``width`` columns: parameter, value
    (angles also in degrees), unit and a footnote number per row, each source written once below the table,
    wrapped. ``wide``: the Markdown table with every row's meaning and source in full."""
    rows = describe(kind, name)
    head = f"{kind} preset {name}:"
    if wide:
        lines = [head, "| parameter | value | unit | meaning | source |", "|---|---|---|---|---|"]
        lines += [f"| {n} | {_value_text(n, v)} | {u} | {m} | {src or 'n/a'} |" for n, v, u, m, src in rows]
        return "\n".join(lines) + "\n"
    notes: dict[str, int] = {}
    for *_, src in rows:
        if src and src not in notes:
            notes[src] = len(notes) + 1
    cells = [(n, _value_text(n, v), u, f"[{notes[src]}]" if src else "-") for n, v, u, _, src in rows]
    w = [max(len(c[i]) for c in [("parameter", "value", "unit", "source"), *cells]) for i in range(3)]
    lines = [head] + [f"{a:<{w[0]}}  {b:<{w[1]}}  {c:<{w[2]}}  {d}".rstrip()
                      for a, b, c, d in [("parameter", "value", "unit", "source"), *cells]]
    lines += ["", "sources:"]
    for src, k in notes.items():
        lines += textwrap.wrap(src, width, initial_indent=f"[{k}] ", subsequent_indent=" " * (len(str(k)) + 3))
    lines += ["", "--wide: the table with each parameter's meaning and its source in full"]
    return "\n".join(lines) + "\n"
