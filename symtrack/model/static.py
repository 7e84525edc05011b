"""The vehicle at rest: the static equilibrium of a model's terrain cells at a given pose."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..foundations.errors import SimulationError
from .soil_law import make as make_soil_law
from .system import SystemModel
from .vehicle import GRAVITY_M_S2
from .vehicle3d import check_contact

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
        check_contact(model.opts, model.vehicle.surface, params)
        # the 3D vehicle: its hull settled on the ground (heave, pitch and roll at rest), from the
        # ground's plane at the CG sunk by the static sinkage of the mean pressure
        cell_idx = lay.indices(("z_m", "pitch_rad", "roll_rad"))
        rate_idx = lay.indices(("heave_rate_m_s", "pitch_rate_rad_s", "roll_rate_rad_s"))
        z0, gx, gy = (float(v) for v in model.vehicle.ground(ca.DM(x_m), ca.DM(y_m)))
        g_along = gx * np.cos(yaw_rad) + gy * np.sin(yaw_rad)
        g_across = -gx * np.sin(yaw_rad) + gy * np.cos(yaw_rad)
        pitch0, roll0 = np.arctan(g_along), np.arctan(g_across)
        # the CG h above the ground plane along its normal: h sqrt(1 + |grad z0|^2) above it vertically
        # on uneven ground (furrows), from the highest point under the tracks: in contact, not in the air
        l, e, B = params["contact_length_m"], params["cg_ahead_of_contact_centre_m"], params["track_gauge_m"]
        xb, yb = np.meshgrid(np.linspace(l / 2 - e, -l / 2 - e, 4 * model.opts.contact_segments + 1), (-B / 2, B / 2))
        xw = x_m + xb * np.cos(yaw_rad) - yb * np.sin(yaw_rad)
        yw = y_m + xb * np.sin(yaw_rad) + yb * np.cos(yaw_rad)
        plane = z0 + g_along * xb + g_across * yb
        bump = max(0.0, max(float(model.vehicle.ground(ca.DM(a), ca.DM(c))[0]) - pl
                            for a, c, pl in zip(xw.ravel(), yw.ravel(), plane.ravel(), strict=True)))
        guess = np.array([z0 + bump + (params["cg_height_m"] - z_guess) * np.hypot(1.0, np.hypot(gx, gy)),
                          pitch0, roll0])
        # the heave alone first, by bisection (its acceleration falls monotonically as the hull sinks),
        # so that Newton starts in contact
        xt = x.copy()
        xt[cell_idx[1:]] = pitch0, roll0

        def heave_acc(zc):
            xt[cell_idx[0]] = zc
            return float(np.array(model.ode(xt, ca.DM.zeros(2), p_num)).ravel()[rate_idx[0]])

        p_num = model.param_vector(params)
        lo, hi = guess[0] - 0.5, guess[0] + 0.05
        if heave_acc(lo) > 0 > heave_acc(hi):
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if heave_acc(mid) > 0 else (lo, mid)
            guess[0] = 0.5 * (lo + hi)
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
