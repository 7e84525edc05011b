"""Time integration of a :class:`SystemModel` with CasADi's CVODES or IDAS (exact Jacobians).

The integrators are built once on a time-scaled system, d x / d s = h f(x, u, p) on s in [0, 1]
with the step length h as a parameter, so that one integrator object serves every step length
(the output step and the shortened last step that stops a run at an exact distance).
CVODES integrates the ODE form (the load-transfer loop closed by fixed-point iterations), IDAS
the DAE form (the loop closed exactly by algebraic variables). Both get the exact sparse
Jacobian from CasADi's automatic differentiation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..foundations.errors import SimulationError
from ..model import SystemModel
from ..native.cache import library
from .settings import IntegratorSettings

__all__ = ["SundialsStepper", "compiled_dae"]

METHODS = ("cvodes", "idas")


class SundialsStepper:
    """CVODES or IDAS: advances the state of a model over one step of given length with fixed
    inputs (the :class:`~symtrack.integrators.settings.Stepper` interface)."""

    def __init__(self, model: SystemModel, settings: IntegratorSettings):
        if settings.method not in METHODS:
            raise SimulationError(f"SundialsStepper: method {settings.method!r} is not one of {', '.join(METHODS)}")
        self.model, self.settings = model, settings
        self.z = None
        # optional state permutation of the integrator (x_integrator = x[perm]); see
        # symtrack/integrators/grid_idas.py, which orders the channel states first
        self.perm = self.inv = None
        h = ca.SX.sym("step_s")
        opts = {"abstol": settings.abstol, "reltol": settings.reltol, "max_num_steps": settings.max_num_steps}
        if settings.method == "cvodes":
            dae = {"x": model.x, "u": model.u, "p": ca.vertcat(model.p, h), "ode": h * model.ode_expr}
        else:
            dae = {"x": model.x, "z": model.z, "u": model.u, "p": ca.vertcat(model.p, h),
                   "ode": h * model.ode_dae_expr, "alg": model.alg_expr}
            opts["calc_ic"] = True
        if settings.compiled:
            dae = compiled_dae(model, settings.method)
        self.F = ca.integrator("step_" + settings.method, settings.method, dae, 0.0, 1.0, opts)
        self.last_quad = None

    def reset(self):
        """Forget the algebraic guess (IDAS) after a jump of the state."""
        self.z = None

    def step(self, x, u, p, dt: float):
        """Integrate from state x over dt [s] with inputs u and parameter vector p held fixed."""
        x = np.asarray(x, dtype=float)
        args = {"x0": x if self.perm is None else x[self.perm], "u": u, "p": ca.vertcat(p, dt)}
        if self.settings.method == "idas":
            args["z0"] = self.model.accel(x, u, p) if self.z is None else self.z
        try:
            r = self.F(**args)
        except RuntimeError as err:
            raise SimulationError(f"{self.settings.method} failed: {err}") from err
        xf = np.array(r["xf"]).ravel()
        if not np.all(np.isfinite(xf)):
            raise SimulationError(f"{self.settings.method} returned a non-finite state")
        if self.settings.method == "idas":
            self.z = r["zf"]
        self.last_quad = np.array(r["qf"]).ravel()  # the quadratures over this step (empty: none)
        return xf if self.inv is None else xf[self.inv]

    def stats(self) -> dict:
        st = self.F.stats()
        return {k: st[k] for k in ("n_call_jacF", "nsteps") if k in st} if isinstance(st, dict) else {}


def compiled_dae(model, method: str) -> dict:
    """The time-scaled DAE dict of :class:`SundialsStepper` on the compiled dynamics (exact
    Jacobian from ``jac_<name>`` in the library)."""
    lib = library(model)
    X, U = ca.MX.sym("x", model.x.sparsity()), ca.MX.sym("u", model.u.sparsity())
    P, H = ca.MX.sym("p", model.p.sparsity()), ca.MX.sym("step_s")
    if method == "cvodes":
        return {"x": X, "u": U, "p": ca.vertcat(P, H), "ode": H * lib.f("ode")(X, U, P)}
    Z = ca.MX.sym("z", model.z.sparsity())
    ode, alg = lib.f("dae")(X, Z, U, P)
    return {"x": X, "z": Z, "u": U, "p": ca.vertcat(P, H), "ode": H * ode, "alg": alg}
