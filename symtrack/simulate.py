"""Time integration of a :class:`SystemModel` with CasADi's CVODES or IDAS (exact Jacobians).

The integrators are built once on a time-scaled system, d x / d s = h f(x, u, p) on s in [0, 1]
with the step length h as a parameter, so that one integrator object serves every step length
(the output step and the shortened last step that stops a run at an exact distance).
CVODES integrates the ODE form (the load-transfer loop closed by fixed-point iterations), IDAS
the DAE form (the loop closed exactly by algebraic variables). Both get the exact sparse
Jacobian from CasADi's automatic differentiation.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .errors import SimulationError
from .model import SystemModel
from .model.cell import k_eq
from .model.vehicle import GRAVITY_M_S2, VEHICLE_STATES

INTEGRATORS = ("cvodes", "idas")


@dataclass(frozen=True)
class IntegratorSettings:
    method: str = "cvodes"
    reltol: float = 1e-7
    abstol: float = 1e-9
    max_num_steps: int = 200000


class Stepper:
    """Advances the state of a model over one step of given length with fixed inputs."""

    def __init__(self, model: SystemModel, settings: IntegratorSettings):
        if settings.method not in INTEGRATORS:
            raise SimulationError(f"run.integrator = {settings.method!r} is not one of {', '.join(INTEGRATORS)}")
        self.model, self.settings = model, settings
        h = ca.SX.sym("step_s")
        opts = {"abstol": settings.abstol, "reltol": settings.reltol, "max_num_steps": settings.max_num_steps}
        if settings.method == "cvodes":
            dae = {"x": model.x, "u": model.u, "p": ca.vertcat(model.p, h), "ode": h * model.ode_expr}
        else:
            dae = {"x": model.x, "z": model.z, "u": model.u, "p": ca.vertcat(model.p, h),
                   "ode": h * model.ode_dae_expr, "alg": model.alg_expr}
            opts["calc_ic"] = True
        self.F = ca.integrator("step_" + settings.method, settings.method, dae, 0.0, 1.0, opts)
        self.z = None

    def reset(self):
        """Forget the algebraic guess (IDAS) after a jump of the state."""
        self.z = None

    def step(self, x, u, p, dt: float):
        """Integrate from state x over dt [s] with inputs u and parameter vector p held fixed."""
        args = {"x0": x, "u": u, "p": ca.vertcat(p, dt)}
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
        return xf

    def stats(self) -> dict:
        st = self.F.stats()
        return {k: st[k] for k in ("n_call_jacF", "nsteps") if k in st} if isinstance(st, dict) else {}


def static_state(model: SystemModel, params: dict, x_m=0.0, y_m=0.0, yaw_rad=0.0) -> np.ndarray:
    """The vehicle at rest at the given pose with its terrain cells in static equilibrium.

    Solved with a CasADi Newton root-finder on the model's own cell equations (rates zero).
    """
    nv = len(VEHICLE_STATES)
    x = np.zeros(model.nx)
    x[0], x[1], x[2] = x_m, y_m, yaw_rad
    cell_idx = list(range(nv, model.nx, 2))
    rate_idx = [i + 1 for i in cell_idx]
    zc = ca.SX.sym("zc", len(cell_idx))
    xs = ca.SX(ca.DM(x))
    for k, i in enumerate(cell_idx):
        xs[i] = zc[k]
    p = model.param_vector(params)
    resid = model.ode(xs, ca.DM.zeros(2), p)[rate_idx]
    rf = ca.rootfinder("static", "newton", ca.Function("g", [zc], [resid]), {"abstol": 1e-12, "max_iter": 200})
    keq = k_eq(params["k_c_N_per_m_n1"], params["k_phi_N_per_m_n2"], params["track_width_m"])
    p_mean = params["mass_kg"] * GRAVITY_M_S2 / (2 * params["track_width_m"] * params["contact_length_m"])
    z_guess = (p_mean / keq) ** (1 / params["bekker_n"])
    try:
        sol = np.array(rf(np.full(len(cell_idx), z_guess))).ravel()
    except RuntimeError as err:
        raise SimulationError(f"no static equilibrium of the terrain cells: {err}") from err
    x[cell_idx] = sol
    return x
