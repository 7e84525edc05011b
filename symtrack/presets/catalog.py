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
import tokenize
import tomllib
from pathlib import Path

from ..foundations.errors import ParameterError
from ..foundations.files import read_text
from ..model.parameters import SOIL_PARAMS, VEHICLE_PARAMS, ParamSet, check_set
from ..soil.pedotransfer import derivation_note
from . import soils, vehicles

__all__ = ["PRESET_FILE_KEYS", "describe", "preset_file_kind", "preset_names", "preset_sources", "read_preset_file",
           "unit_of"]

PRESET_FILE_KEYS = ("base", "description", "sources")
_UNITS = (("_kg_per_kg", "kg/kg"), ("_Mg_per_m3", "Mg/m^3"), ("_kPa", "kPa"),
          ("_N_per_m_n1", "N/m^(n+1)"), ("_N_per_m_n2", "N/m^(n+2)"), ("_Pa_s_per_m", "Pa s/m"),
          ("_Pa_per_m", "Pa/m"), ("_kg_per_m2", "kg/m^2"), ("_kg_m2", "kg m^2"), ("_N_m", "N m"),
          ("_m_s", "m/s"), ("_rad", "rad"), ("_kg", "kg"), ("_Pa", "Pa"), ("_N", "N"), ("_s", "s"), ("_m", "m"))


def unit_of(name: str) -> str:
    """The unit a parameter's name carries ("-" for a dimensionless one)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return "-"


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


def read_preset_file(path, kind: str) -> tuple[dict[str, float], dict[str, str], str]:
    """A user preset file -> (values, sources, description), checked as a complete set."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"{kind}.preset = {str(path)!r}: no such preset file")
    try:
        d = tomllib.loads(read_text(path, f"{kind}.preset file", ParameterError))
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: not valid TOML: {err}") from err
    specs = VEHICLE_PARAMS if kind == "vehicle" else SOIL_PARAMS
    names = [s.name for s in specs]
    unknown = sorted(set(d) - set(names) - set(PRESET_FILE_KEYS))
    if unknown:
        raise ParameterError(f"{path}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(PRESET_FILE_KEYS)} "
                             f"and the {kind} parameters ({', '.join(names)})")
    values = ParamSet()
    base = d.get("base")
    if base is not None:  # (the base's set as it is: what its description derived is derived again)
        values = vehicles.vehicle_preset(base) if kind == "vehicle" else soils.soil_preset(base)
    values = values.with_given({k: v for k, v in d.items() if k in names})
    sources = d.get("sources", {})
    if not isinstance(sources, dict) or set(sources) - set(names):
        raise ParameterError(f"{path}: [sources] must map {kind} parameter names to text")
    return check_set(values, specs, f"{kind} preset file {str(path)!r}"), dict(sources), str(d.get("description", ""))


def describe(kind: str, name: str) -> list[tuple[str, float, str, str, str]]:
    """(parameter, value, unit, meaning, source) of every parameter of a built-in preset or a
    user preset file."""
    specs = VEHICLE_PARAMS if kind == "vehicle" else SOIL_PARAMS
    if name.endswith(".toml"):
        values, sources, _ = read_preset_file(name, kind)
        base = {}
    else:
        values = vehicles.vehicle_preset(name) if kind == "vehicle" else soils.soil_preset(name)
        sources = {}
        base = preset_sources(kind, name)
    rows = []
    consts = {"cell_areal_mass_kg_per_m2": "#CELL_AREAL_MASS_KG_PER_M2",
              "cell_damping_Pa_s_per_m": "#CELL_DAMPING_PA_S_PER_M",
              "elastic_stiffness_Pa_per_m": "#WONG_SOILS_ELASTIC_STIFFNESS_PA_PER_M",
              "unloading_stiffness_floor": "#UNLOADING_STIFFNESS_FLOOR"}
    raw = {} if name.endswith(".toml") or kind == "vehicle" else soils.SOILS.get(name, {})
    derived = getattr(values, "derived", {})
    for s in specs:
        src = sources.get(s.name) or base.get(s.name) or base.get(consts.get(s.name, ""), "") or base.get("*", "")
        if s.name in derived:
            rows.append((s.name, values[s.name], unit_of(s.name), s.description, derivation_note(s.name, values)))
            continue
        if s.default is not None and kind == "soil" and s.name not in raw and not sources.get(s.name):
            src = f"the registry's default (symtrack/model/parameters.py): {_default_source(s.name)}"
        rows.append((s.name, values[s.name], unit_of(s.name), s.description, src))
    return rows


def _default_source(name: str) -> str:
    """The comment above the registry's default constant of a parameter (parameters.py)."""
    from ..model import parameters
    from ..soil import pedotransfer

    const = {"repeated_loading_exponent": "REPEATED_LOADING_EXPONENT_DEFAULT",
             "stress_concentration_factor": "STRESS_CONCENTRATION_FACTOR_DEFAULT",
             "yield_line_offset_ln_p": "YIELD_LINE_OFFSET_DEFAULT",
             "specific_volume_min": "SPECIFIC_VOLUME_MIN_DEFAULT",
             "subsoil_top_m": "SUBSOIL_TOP_DEFAULT_M"}.get(name)
    lines = inspect.getsource(parameters).splitlines() + inspect.getsource(pedotransfer).splitlines()
    for k, line in enumerate(lines):
        if const and line.startswith(const):
            notes = []
            j = k - 1
            while j >= 0 and lines[j].lstrip().startswith("#"):
                notes.insert(0, lines[j].lstrip("# ").strip())
                j -= 1
            tail = line.split("#", 1)[1].strip() if "#" in line else ""
            return " ".join(notes + ([tail] if tail else []))
    return ""
