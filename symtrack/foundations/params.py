"""A parameter's declaration and the packing of declared parameters into a vector.

Each model piece declares the parameters it brings (:class:`ParamSpec`: name with its unit, meaning,
allowed range, default and source) where its equations are: the vehicles in
:mod:`symtrack.vehicles` (the body, the traction's soil coefficients), a soil law in its own
module (:mod:`symtrack.soil.law`), the cell equation in :mod:`symtrack.soil.cell`, the soil's
description and compression in :mod:`symtrack.model.parameters`, which joins them into the
parameter set of a model (:func:`symtrack.model.parameters.model_params`).

A :class:`ParamLayout` is the packing of named values into a flat vector (the model's parameter
vector p, the terrain engine's ``geo`` and track-soil vectors): the offset of each name, the
vector from a mapping, and the offsets as C defines, so that C reads an entry by its name.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from .errors import ParameterError
from .units import unit_of_suffix

__all__ = ["ParamLayout", "ParamSpec", "merge_specs", "param", "unit_of_name"]

def unit_of_name(name: str) -> str:
    """The unit a parameter's name carries ("-" for a dimensionless one; :func:`.units.unit_of_suffix`)."""
    return unit_of_suffix(name, "-")


@dataclass(frozen=True)
class ParamSpec:
    """One parameter's declaration: ``name`` (its unit in its suffix), ``description``, the allowed
    range [``low``, ``high``] (``low`` excluded unless ``low_inclusive``), ``default`` (None: a
    parameter set must give it), ``derived`` (filled by the soil's pedotransfer functions when a set
    leaves it out), ``source`` (where its equation, or its default, comes from) and ``unit`` (the
    name's suffix's unless given)."""

    name: str
    description: str
    low: float
    high: float
    low_inclusive: bool = True
    default: float | None = None
    derived: bool = False
    source: str = ""
    unit: str = ""

    def __post_init__(self):
        if not self.unit:
            object.__setattr__(self, "unit", unit_of_name(self.name))

    @property
    def default_source(self) -> str:
        """Where the default comes from ("" for a parameter without one)."""
        return self.source if self.default is not None else ""

    def check(self, value: object, where: str = "") -> float:
        label = f"{where}.{self.name}" if where else self.name
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{label} = {value!r} is not a number ({self.description})")
        v = float(value)
        ok_low = v >= self.low if self.low_inclusive else v > self.low
        if not math.isfinite(v) or not ok_low or v > self.high:
            lb = "[" if self.low_inclusive else "("
            raise ParameterError(
                f"{label} = {value!r} is outside the allowed range {lb}{self.low:g}, {self.high:g}] "
                f"({self.description})"
            )
        return v


def param(name, description, low, high, low_inclusive=True, *, default=None, derived=False, source="",
          unit="") -> ParamSpec:
    """A :class:`ParamSpec` (the declarations' shorthand)."""
    return ParamSpec(name, description, low, high, low_inclusive, default, derived, source, unit)


def merge_specs(*groups: Iterable[ParamSpec]) -> tuple[ParamSpec, ...]:
    """The declarations of ``groups`` in order, each name once: a name declared twice must be declared
    the same (a ValueError naming it otherwise)."""
    out: dict[str, ParamSpec] = {}
    for group in groups:
        for s in group:
            if s.name in out and out[s.name] != s:
                raise ValueError(f"parameter {s.name!r} is declared twice, differently: {out[s.name]} and {s}")
            out.setdefault(s.name, s)
    return tuple(out.values())


class ParamLayout:
    """The packing of named values into a flat vector: ``names`` in order, each at its offset."""

    def __init__(self, names: Iterable[str]):
        self.names = tuple(names)
        self.offsets = {n: i for i, n in enumerate(self.names)}
        if len(self.offsets) != len(self.names):
            raise ValueError(f"a parameter layout names an entry twice: {self.names}")

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self):
        return iter(self.names)

    def __eq__(self, other) -> bool:
        return isinstance(other, ParamLayout) and other.names == self.names

    def __hash__(self) -> int:
        return hash(self.names)

    def __repr__(self) -> str:
        return f"ParamLayout({self.names})"

    def offset(self, name: str) -> int:
        return self.offsets[name]

    def pack(self, values: Mapping) -> list[float]:
        """The vector of ``values`` (name -> number) in this layout's order."""
        return [float(values[n]) for n in self.names]

    def unpack(self, vector) -> dict:
        """name -> entry of ``vector`` (a sequence, or a CasADi vector)."""
        return {n: vector[i] for i, n in enumerate(self.names)}

    def c_defines(self, prefix: str, size_name: str | None = None) -> list[str]:
        """``#define <prefix>_<NAME> offset`` for every entry (the name in capitals, its characters
        other than letters and digits as ``_``), and ``#define <size_name> len`` when given."""
        lines = [f"#define {prefix}_{re.sub(r'[^0-9A-Za-z]', '_', n).upper()} {i} /* {n} */"
                 for i, n in enumerate(self.names)]
        if size_name:
            lines.append(f"#define {size_name} {len(self.names)}")
        return lines
