"""The key tables of a simulation's sections, made from the loader's own declarations: the keys, ranges and
meanings it checks (``RUN_KEYS``, ``START_KEYS``, ``TORQUE_KEYS`` of :mod:`.scenario`, ``MODEL_KEYS`` of
:mod:`symtrack.model.options`, ``TERRAIN_KEYS`` of :mod:`symtrack.terrain.settings`, the parameter registry of
:mod:`symtrack.model.parameters`) and the defaults of the settings they fill. docs/scenarios.md ("Keys of a
simulation") holds them between two marker lines; ``python -m symtrack.simulation.keys docs/scenarios.md``
(``make keys``) writes them there, and a test checks that the page holds what this module makes.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from ..foundations.config import key_table, short_number
from ..model.options import MODEL_KEYS, ModelOptions, scenario_keys
from ..model.parameters import SOIL_PARAMS, VEHICLE_PARAMS
from ..presets.catalog import unit_of
from ..terrain.settings import TERRAIN_KEYS, TerrainSettings
from .scenario import RUN_KEYS, SIMULATION_RUN_KEYS, START_KEYS, TORQUE_KEYS, RunSettings, Start

__all__ = ["BEGIN", "END", "key_tables", "write_into"]

BEGIN = "<!-- the key tables: python -m symtrack.simulation.keys docs/scenarios.md writes them -->"
END = "<!-- end of the key tables -->"


def _rows(keys, defaults: dict, names=None):
    return [(k.name, defaults.get(k.name, "- none"), k.range_text(), k.meaning)
            for k in keys.values() if names is None or k.name in names]


def _param_rows(specs):
    rows = []
    for s in specs:
        lb = "[" if s.low_inclusive else "("
        default = s.default if s.default is not None else ("- derived" if s.derived else "- the preset's")
        allowed = f"{lb}{short_number(s.low)}, {short_number(s.high)}] {unit_of(s.name)}".rstrip(" -")
        rows.append((s.name, default, allowed, s.description))
    return rows


def key_tables() -> str:
    """The Markdown of every section's table (what docs/scenarios.md holds between :data:`BEGIN` and :data:`END`)."""
    run = {f.name: getattr(RunSettings(), f.name) for f in dataclasses.fields(RunSettings)}
    model = {f.name: getattr(ModelOptions(), f.name) for f in dataclasses.fields(ModelOptions)}
    terrain = {f.name: getattr(TerrainSettings(), f.name) for f in dataclasses.fields(TerrainSettings)}
    terrain.update({k: "- none" for k in ("origin_m", "initial_state", "soil_map", "surface", "moisture", "towed")})
    start = {f.name: getattr(Start(), f.name) for f in dataclasses.fields(Start)}
    preset = [("preset", "- required", "a built-in preset (symtrack presets) or a preset file `*.toml`",
               "the set of values the section starts from; any key below overrides the preset's value")]
    parts = [
        ("[run]", key_table(_rows(RUN_KEYS, run, SIMULATION_RUN_KEYS))),
        ("[model]", key_table(_rows({k: MODEL_KEYS[k] for k in scenario_keys()}, model))),
        ("[vehicle]", key_table(preset + _param_rows(VEHICLE_PARAMS))),
        ("[soil]", key_table(preset + _param_rows(SOIL_PARAMS))),
        ("[start]", key_table(_rows(START_KEYS, start))),
        ("[[torque]]", key_table([(r[0], "- required" if r[0] != "event" else "- none", *r[2:])
                                  for r in _rows(TORQUE_KEYS, {})])),
        ("[terrain]", key_table(_rows(TERRAIN_KEYS, terrain))),
    ]
    return "\n".join(f"### `{title}`\n\n{table}" for title, table in parts)


def write_into(path) -> bool:
    """Write :func:`key_tables` between the marker lines of ``path``; True when the file changed."""
    path = Path(path)
    text = path.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{path}: the marker lines {BEGIN!r} and {END!r} are missing")
    head, rest = text.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    new = f"{head}{BEGIN}\n\n{key_tables()}\n{END}{tail}"
    if new != text:
        path.write_text(new)
    return new != text


if __name__ == "__main__":
    for arg in sys.argv[1:] or ["docs/scenarios.md"]:
        print(f"{arg}: {'written' if write_into(arg) else 'up to date'}")
