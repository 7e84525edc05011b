"""The symbolic model: the options (:mod:`.options`), the state layout (:mod:`.layout`), the
parameter set (:mod:`.parameters`), the homogeneous terrain (:mod:`.homogeneous`), the static start
(:mod:`.static`) and :class:`SystemModel` (:mod:`.system`), a vehicle of :mod:`symtrack.vehicles` on a
terrain as named CasADi Functions."""

from __future__ import annotations

import importlib

__all__ = ["ModelOptions", "PARAM_NAMES", "SystemModel"]

_LAZY = {"ModelOptions": "options", "PARAM_NAMES": "system", "SystemModel": "system"}


def __getattr__(name: str):
    # imported on first use, so that a module of a room below (a vehicle, a soil law) may import one
    # module of this package without running the whole of it
    if name in _LAZY:
        value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
