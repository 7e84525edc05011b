"""The design of a sweep: which keys vary, over which values, and the runs that follow.

A sweep varies any key of ``--set`` (``section.key``). Each axis is either

- a list of values (``--vary vehicle.mass_kg=5000,6000,7000``): the sweep takes the full grid
  (every combination of the listed values), or
- a range (``--vary soil.bekker_n=0.6:1.1`` with ``--sample N``): the sweep takes N points of a Latin
  hypercube over all the ranges (each range cut into N equal strata, each stratum hit by exactly
  one point, the strata of different keys paired at random with a fixed seed).

Lists and ranges combine: every grid point is crossed with the N sampled points. Values are read
as ``--set`` reads them (TOML: ``2000``, ``0.5``, ``true``, ``"idas"`` or a bare word ``idas``);
a value cannot contain a comma. A range whose two ends are written as integers (``3:12``) samples
integers (for integer keys such as ``mpc.horizon_steps``).

Each run has an id (:func:`run_id`): a hash of the scenario text, its kind and all its overrides,
so the same run of a rerun (or of a larger sweep into the same folder) finds its finished folder.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..foundations.config import parse_override
from ..foundations.errors import ScenarioError

__all__ = ["MAX_RUNS", "Axis", "design_runs", "latin_hypercube", "normalise_overrides", "parse_vary", "run_id"]

# a sweep larger than this is refused (a typo in --sample, or a grid that multiplies out)
MAX_RUNS = 100_000
# sampled values are rounded to this many significant digits (readable tables, stable run ids)
SAMPLE_DIGITS = 10


@dataclass(frozen=True)
class Axis:
    """One varied key: a list of ``values`` (grid), or a range ``low``..``high`` (sampled)."""

    key: str
    values: tuple | None = None
    low: float | None = None
    high: float | None = None
    integer: bool = False

    @property
    def sampled(self) -> bool:
        return self.values is None

    def describe(self) -> dict:
        if self.sampled:
            return {"key": self.key, "low": self.low, "high": self.high, "integer": self.integer}
        return {"key": self.key, "values": list(self.values)}


def _key(where: str, key: str) -> str:
    """A ``section.key`` name, normalised (stripped)."""
    if not isinstance(key, str) or "." not in key or not all(p.strip() for p in key.split(".", 1)):
        raise ScenarioError(f"{where} {key!r}: the key must be a 'section.key' name, e.g. vehicle.mass_kg")
    section, name = key.split(".", 1)
    return f"{section.strip()}.{name.strip()}"


def _value(key: str, raw: str):
    return parse_override(f"{key}={raw}")[2]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _range_axis(where: str, key: str, low, high) -> Axis:
    if not (_is_number(low) and _is_number(high)):
        raise ScenarioError(f"{where}: the range {low!r}:{high!r} of {key} must have two finite numbers")
    if not low < high:
        raise ScenarioError(f"{where}: the range of {key} must have LO < HI, got {low!r}:{high!r}")
    integer = isinstance(low, int) and isinstance(high, int)
    return Axis(key, None, low, high, integer)


def _grid_axis(where: str, key: str, values) -> Axis:
    values = tuple(values)
    if not values:
        raise ScenarioError(f"{where}: the list of values of {key} is empty; give one or more values V1,V2,...")
    seen = []
    for v in values:
        if isinstance(v, str) and not v.strip():
            raise ScenarioError(f"{where}: {key} has an empty value in its list {values!r}")
        if v in seen:
            raise ScenarioError(f"{where}: the value {v!r} of {key} is listed twice")
        seen.append(v)
    return Axis(key, values)


def parse_vary(item: str) -> Axis:
    """One ``--vary`` argument: ``KEY=V1,V2,...`` (a grid axis) or ``KEY=LO:HI`` (a sampled range)."""
    where = f"--vary {item!r}"
    if not isinstance(item, str) or "=" not in item:
        raise ScenarioError(f"{where}: expected KEY=V1,V2,... or KEY=LO:HI, e.g. vehicle.mass_kg=5000,6000")
    key, raw = item.split("=", 1)
    key = _key(where, key.strip())
    raw = raw.strip()
    if not raw:
        raise ScenarioError(f"{where}: the list of values of {key} is empty; give one or more values V1,V2,...")
    if ":" in raw and "," not in raw:
        lo, _, hi = raw.partition(":")
        return _range_axis(where, key, _value(key, lo), _value(key, hi))
    parts = [p.strip() for p in raw.split(",")]
    if any(not p for p in parts):
        raise ScenarioError(f"{where}: {key} has an empty value in its list {raw!r}")
    return _grid_axis(where, key, [_value(key, p) for p in parts])


def axes_from(vary, ranges=None) -> list[Axis]:
    """The axes of a sweep from the Python API's arguments: ``vary`` is a list of ``--vary``
    strings (``"KEY=V1,V2"``, ``"KEY=LO:HI"``) or a mapping key -> list of values (grid axes);
    ``ranges`` a mapping key -> (low, high) (sampled axes)."""
    axes: list[Axis] = []
    if vary is None:
        vary = []
    if isinstance(vary, str):
        raise ScenarioError(f"vary = {vary!r}: give a list of 'KEY=V1,V2' strings or a dict key -> values")
    if isinstance(vary, Mapping):
        for key, values in vary.items():
            k = _key("vary", key)
            if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
                raise ScenarioError(f"vary[{key!r}] = {values!r}: give a list of values")
            axes.append(_grid_axis(f"vary[{key!r}]", k, values))
    else:
        axes += [parse_vary(item) for item in vary]
    for key, bounds in (ranges or {}).items():
        k = _key("ranges", key)
        if isinstance(bounds, (str, bytes)) or not isinstance(bounds, Sequence) or len(bounds) != 2:
            raise ScenarioError(f"ranges[{key!r}] = {bounds!r}: give (low, high)")
        axes.append(_range_axis(f"ranges[{key!r}]", k, bounds[0], bounds[1]))
    keys = [a.key for a in axes]
    for k in keys:
        if keys.count(k) > 1:
            raise ScenarioError(f"the key {k} is varied twice; give all its values in one --vary")
    if not axes:
        raise ScenarioError("a sweep needs at least one --vary KEY=V1,V2,... (or KEY=LO:HI with --sample N)")
    return axes


def latin_hypercube(n: int, d: int, seed: int = 0) -> np.ndarray:
    """``n`` points of a Latin hypercube in [0, 1)^d: in every dimension each of the n strata
    [k/n, (k+1)/n) holds exactly one point, uniformly placed within it; the strata of different
    dimensions are paired by independent random permutations (numpy's default generator, ``seed``)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ScenarioError(f"--sample {n!r} must be a positive integer")
    rng = np.random.default_rng(seed)
    strata = np.column_stack([rng.permutation(n) for _ in range(d)]) if d else np.zeros((n, 0))
    return (strata + rng.random((n, d))) / n


def _scale(axis: Axis, u: float):
    if axis.integer:
        return int(min(axis.high, math.floor(axis.low + u * (axis.high - axis.low + 1))))
    return float(f"{axis.low + u * (axis.high - axis.low):.{SAMPLE_DIGITS}g}")


def design_runs(axes: list[Axis], samples: int | None = None, seed: int = 0) -> list[dict]:
    """The runs of a sweep, in order: each a dict key -> value (the axes' keys, in their order)."""
    grid = [a for a in axes if not a.sampled]
    ranged = [a for a in axes if a.sampled]
    if ranged and samples is None:
        raise ScenarioError(f"{ranged[0].key} is given as a range LO:HI: add --sample N (the number of "
                            "Latin hypercube points), or list its values V1,V2,...")
    if samples is not None and not ranged:
        raise ScenarioError(f"--sample {samples} needs at least one --vary KEY=LO:HI range")
    n_grid = math.prod(len(a.values) for a in grid)
    total = n_grid * (samples or 1)
    if total > MAX_RUNS:
        raise ScenarioError(f"the sweep has {total} runs, more than the {MAX_RUNS} allowed")
    points = [{}]
    if ranged:
        u = latin_hypercube(samples, len(ranged), seed)
        points = [{a.key: _scale(a, u[i, j]) for j, a in enumerate(ranged)} for i in range(samples)]
    out = []
    for combo in itertools.product(*(a.values for a in grid)):
        g = dict(zip((a.key for a in grid), combo, strict=True))
        for p in points:
            merged = {**g, **p}
            out.append({a.key: merged[a.key] for a in axes})
    return out


def normalise_overrides(overrides) -> dict:
    """``--set`` overrides (strings or a mapping) -> a dict ``{"section.key": value}``."""
    if overrides is None:
        return {}
    if isinstance(overrides, Mapping):
        return {_key("override", k): v for k, v in overrides.items()}
    if isinstance(overrides, str):
        raise ScenarioError(f"overrides = {overrides!r}: give a list of 'section.key=value' strings or a dict")
    out = {}
    for item in overrides:
        section, name, value = parse_override(item)
        out[f"{section}.{name}"] = value
    return out


def run_id(kind: str, text: str, overrides: dict) -> str:
    """The id of a run: 12 hex digits of the SHA-256 of its kind, scenario text and overrides."""
    blob = json.dumps({"kind": kind, "text": text, "overrides": sorted(overrides.items())}, sort_keys=True,
                      default=repr)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]
