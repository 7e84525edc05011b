"""The vehicle at rest: the static equilibrium of a model's terrain cells at a given pose."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..foundations.errors import SimulationError
from .soil_law import make as make_soil_law
from .system import SystemModel
from .vehicle import GRAVITY_M_S2

__all__ = ["static_state"]


def static_state(model: SystemModel, params: dict, x_m=0.0, y_m=0.0, yaw_rad=0.0) -> np.ndarray:
    """The vehicle at rest at the given pose with its terrain cells in static equilibrium.

    Solved with a CasADi Newton root-finder on the model's own cell equations (rates zero), from
    the sinkage at which the model's soil law carries the vehicle's mean pressure (its static inverse).
    """
    lay = model.layout
    x = np.zeros(model.nx)
    x[lay.indices(("x_m", "y_m", "yaw_rad"))] = x_m, y_m, yaw_rad
    cell_idx = lay.cell_indices("sinkage")
    rate_idx = lay.cell_indices("rate")
    law = make_soil_law(model.opts)
    p_mean = params["mass_kg"] * GRAVITY_M_S2 / (2 * params["track_width_m"] * params["contact_length_m"])
    z_guess = float(law.static_sinkage(p_mean, law.values(params)))
    hull = getattr(model.vehicle, "own_contact", False)
    if hull:
        # the 3D vehicle: its hull settled on the ground (heave, pitch and roll at rest), from the
        # ground's plane at the CG sunk by the static sinkage of the mean pressure
        cell_idx = lay.indices(("z_m", "pitch_rad", "roll_rad"))
        rate_idx = lay.indices(("heave_rate_m_s", "pitch_rate_rad_s", "roll_rate_rad_s"))
        z0, gx, gy = (float(v) for v in model.vehicle.ground(ca.DM(x_m), ca.DM(y_m)))
        g_along = gx * np.cos(yaw_rad) + gy * np.sin(yaw_rad)
        g_across = -gx * np.sin(yaw_rad) + gy * np.cos(yaw_rad)
        pitch0, roll0 = np.arctan(g_along), np.arctan(g_across)
        # the CG h above the ground plane along its normal: h sqrt(1 + |grad z0|^2) above it vertically
        guess = np.array([z0 + (params["cg_height_m"] - z_guess) * np.hypot(1.0, np.hypot(gx, gy)), pitch0, roll0])
    zc = ca.SX.sym("zc", len(cell_idx))
    xs = ca.SX(ca.DM(x))
    for k, i in enumerate(cell_idx):
        xs[i] = zc[k]
    p = model.param_vector(params)
    resid = model.ode(xs, ca.DM.zeros(2), p)[rate_idx]
    rf = ca.rootfinder("static", "newton", ca.Function("g", [zc], [resid]), {"abstol": 1e-12 if not hull else 1e-6,
                                                                               "max_iter": 200})
    try:
        sol = np.array(rf(guess if hull else np.full(len(cell_idx), z_guess))).ravel()
    except RuntimeError as err:
        raise SimulationError(f"no static equilibrium of the terrain cells: {err}") from err
    x[cell_idx] = sol
    if hull:
        resid_v = np.array(model.ode(x, ca.DM.zeros(2), p)).ravel()[rate_idx]
        if not np.all(np.abs(resid_v) < 1e-4):
            raise SimulationError(f"no static equilibrium of the 3D vehicle's hull at x, y = {x_m:g}, {y_m:g} m "
                                  f"(heave, pitch and roll accelerations {resid_v} after Newton)")
    return x
