"""The symbolic model: the options (:mod:`.options`), the state layout (:mod:`.layout`), the
parameter set (:mod:`.parameters`), the homogeneous terrain (:mod:`.homogeneous`), the static start
(:mod:`.static`) and :class:`SystemModel` (:mod:`.system`), a vehicle of :mod:`symtrack.vehicles` on a
terrain as named CasADi Functions."""

from __future__ import annotations

from ..foundations.lazy import lazy_getattr

__all__ = ["ModelOptions", "PARAM_NAMES", "SystemModel"]

# imported on first use, so that a module of a room below (a vehicle, a soil law) may import one module of
# this package without running the whole of it
__getattr__ = lazy_getattr(__name__, {"ModelOptions": "options", "PARAM_NAMES": "system", "SystemModel": "system"},
                           globals())
