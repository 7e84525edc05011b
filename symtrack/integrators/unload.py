"""The integrator of the lift at a pass end: the cells alone, the load falling to zero
(:meth:`symtrack.terrain.world.World.unload_dae`), CVODES at tight tolerances."""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["unloader"]

UNLOAD_ABSTOL = 1e-12
UNLOAD_RELTOL = 1e-9


def unloader(world):
    """``f(xc, par) -> xc`` over one step for ``world.end_pass`` (built once per world)."""
    F = ca.integrator("unload", "cvodes", world.unload_dae(), 0.0, 1.0,
                      {"abstol": UNLOAD_ABSTOL, "reltol": UNLOAD_RELTOL})

    def step(xc, par):
        return np.array(F(x0=xc, p=par)["xf"]).ravel()

    return step
