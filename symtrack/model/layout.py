"""The named state layout: the one place that knows where each state sits in a state vector.

A :class:`StateLayout` is an ordered list of *blocks* (name -> state names): a vehicle model's
own blocks (the planar vehicle: ``pose``, ``velocity``, ``sprockets``, ``shear``, ``torque``), then,
in a :class:`~symtrack.model.SystemModel`, the terrain's ``cells``. Two further names are blocks
too: ``vehicle`` (every block before ``cells``) and ``cells``. The terrain's cells have
:attr:`StateLayout.cell_width` states each, stored cell by cell (sinkage, then its rate: both
terrains of the project), so a cell's field is a strided slice (:meth:`StateLayout.cell_field`).

Everything outside this module reads positions through a layout (``model.layout``,
``vehicle.layout``): ``x[layout.block("vehicle")]``, ``x[layout.index("yaw_rad")]``,
``x[layout.cell_field("rate")]``, ``layout.cell_index(ch, "sinkage")``; a vehicle model with more
states (heave, pitch, roll) moves no index elsewhere. tests/test_architecture.py checks that no
positional slicing of the state is left outside it.

:class:`ContactPose` is the pose a vehicle hands to the terrain's geometry: x, y, yaw, and
optionally z, pitch and roll (a body that heaves, pitches and rolls; ``None`` for the planar
vehicle). The channel geometry reads x, y and yaw only (flat field).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

__all__ = ["CELL_FIELDS", "POSE_NAMES", "ContactPose", "StateLayout", "VehicleState"]

# The states of one terrain cell, in storage order (both terrains: sinkage, then its rate).
CELL_FIELDS = ("sinkage", "rate")

# The planar pose's states, which every vehicle model has (a 3D body adds its own: z, pitch, roll).
POSE_NAMES = ("x_m", "y_m", "yaw_rad")

_VEHICLE, _CELLS = "vehicle", "cells"


@dataclasses.dataclass(frozen=True)
class ContactPose:
    """The pose of the vehicle's body handed to the terrain (numbers or CasADi expressions).

    ``x_m``, ``y_m``: the CG's position in the field frame; ``yaw_rad``: heading, counter-clockwise
    from the field's x axis; ``z_m``, ``pitch_rad``, ``roll_rad``: the body's height and attitude
    (``None``: the vehicle does not have them; a planar vehicle rides the surface).
    """

    x_m: Any
    y_m: Any
    yaw_rad: Any
    z_m: Any = None
    pitch_rad: Any = None
    roll_rad: Any = None

    @property
    def planar(self) -> tuple:
        """(x_m, y_m, yaw_rad): what the flat field's channel geometry reads."""
        return self.x_m, self.y_m, self.yaw_rad

    @property
    def is_planar(self) -> bool:
        """True when the pose has no heave, pitch or roll."""
        return self.z_m is None and self.pitch_rad is None and self.roll_rad is None


class StateLayout:
    """Names -> positions of a state vector, in blocks (module doc).

    Parameters
    ----------
    blocks : sequence of (block name, state names)
        In storage order. A block named ``cells`` holds the terrain's cells (``cell_width``
        states each, :data:`CELL_FIELDS`); every block before it belongs to the vehicle.
    cell_width : int
        The states of one terrain cell (2).
    """

    def __init__(self, blocks: Sequence[tuple[str, Sequence[str]]], cell_width: int = len(CELL_FIELDS)):
        self.names: tuple[str, ...] = ()
        self._blocks: dict[str, slice] = {}
        for block, names in blocks:
            if block in self._blocks or block == _VEHICLE:
                raise ValueError(f"state layout: the block name {block!r} is used twice or reserved")
            if block != _CELLS and _CELLS in self._blocks:
                raise ValueError(f"state layout: the block {block!r} follows the terrain's cells")
            start = len(self.names)
            self.names += tuple(names)
            self._blocks[block] = slice(start, len(self.names))
        if len(set(self.names)) != len(self.names):
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ValueError(f"state layout: the state names {dup} appear more than once")
        self._index = {n: i for i, n in enumerate(self.names)}
        self.cell_width = int(cell_width)
        self.nv = self._blocks[_CELLS].start if _CELLS in self._blocks else len(self.names)
        self._blocks[_VEHICLE] = slice(0, self.nv)
        if _CELLS not in self._blocks:
            self._blocks[_CELLS] = slice(self.nv, self.nv)
        n_cell_states = self._blocks[_CELLS].stop - self.nv
        if n_cell_states % self.cell_width:
            raise ValueError(f"state layout: {n_cell_states} cell states are not a multiple of {self.cell_width}")

    def __repr__(self) -> str:
        blocks = ", ".join(f"{b}={s.stop - s.start}" for b, s in self._blocks.items())
        return f"StateLayout({blocks})"

    def __len__(self) -> int:
        return len(self.names)

    @property
    def size(self) -> int:
        """The length of the state vector."""
        return len(self.names)

    @property
    def vehicle_names(self) -> tuple[str, ...]:
        """The vehicle's state names (the ``vehicle`` block)."""
        return self.names[: self.nv]

    @property
    def cell_names(self) -> tuple[str, ...]:
        """The terrain's state names (the ``cells`` block)."""
        return self.names[self.nv:]

    @property
    def n_cells(self) -> int:
        """How many terrain cells the layout holds."""
        return (len(self.names) - self.nv) // self.cell_width

    @property
    def block_names(self) -> tuple[str, ...]:
        return tuple(self._blocks)

    def index(self, name: str) -> int:
        """The position of the state ``name``."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"no state named {name!r} in the layout (states: {', '.join(self.names)})") from None

    def indices(self, names: Sequence[str]) -> list[int]:
        """The positions of several states."""
        return [self.index(n) for n in names]

    @property
    def pose_index(self) -> list[int]:
        """The positions of x, y and yaw (:data:`POSE_NAMES`)."""
        return self.indices(POSE_NAMES)

    def block(self, name: str) -> slice:
        """The slice of block ``name`` (``vehicle``, ``cells`` or one of the vehicle's blocks)."""
        try:
            return self._blocks[name]
        except KeyError:
            raise KeyError(f"no block named {name!r} in the layout (blocks: {', '.join(self._blocks)})") from None

    def block_names_of(self, name: str) -> tuple[str, ...]:
        """The state names of block ``name``."""
        return self.names[self.block(name)]

    def cell_field(self, field: str) -> slice:
        """The strided slice of one field (:data:`CELL_FIELDS`) of every terrain cell."""
        return slice(self.nv + self._field(field), None, self.cell_width)

    def cell_index(self, cell, field: str):
        """The position of ``field`` of terrain cell ``cell`` (an int or an integer array)."""
        return self.nv + self.cell_width * cell + self._field(field)

    def cell_indices(self, field: str) -> list[int]:
        """The positions of ``field`` of every terrain cell, as a list."""
        return list(range(self.nv + self._field(field), len(self.names), self.cell_width))

    def _field(self, field: str) -> int:
        if field not in CELL_FIELDS[: self.cell_width]:
            raise KeyError(f"no cell field {field!r} (fields: {', '.join(CELL_FIELDS[:self.cell_width])})")
        return CELL_FIELDS.index(field)

    def with_cells(self, cell_names: Sequence[str]) -> StateLayout:
        """This (vehicle) layout followed by the terrain's ``cells`` block."""
        blocks = [(b, self.names[s]) for b, s in self._blocks.items() if b not in (_VEHICLE, _CELLS)]
        return StateLayout(blocks + [(_CELLS, tuple(cell_names))], self.cell_width)

    def view(self, x) -> VehicleState:
        """A named view of the state vector ``x`` (numbers or a CasADi vector)."""
        return VehicleState(x, self)


@dataclasses.dataclass(frozen=True)
class VehicleState:
    """A state vector seen by name: ``s["u_m_s"]``, ``s.block("pose")``; ``pose``: the vehicle's
    contact pose, when the vehicle model set it (what the terrain's geometry reads)."""

    x: Any
    layout: StateLayout
    pose: ContactPose | None = None

    def __getitem__(self, name: str):
        return self.x[self.layout.index(name)]

    def block(self, name: str):
        return self.x[self.layout.block(name)]
