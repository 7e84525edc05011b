"""The vehicle at rest: the static equilibrium of a model's terrain cells at a given pose."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..foundations.errors import ImplausibleRunError, SimulationError
from ..soil.law import make as make_soil_law
from ..vehicles.base import CONTACT_HULL
from ..vehicles.planar import mean_ground_pressure_Pa
from .system import SystemModel

__all__ = ["static_state"]


# the soil memory's fixed point at the 3D hull's start (static_state): at most this many settlings, until the
# memory moves less than HISTORY_TOL_M between two
HISTORY_ITERATIONS = 20
HISTORY_TOL_M = 1e-10


def static_state(model: SystemModel, params: dict, x_m=0.0, y_m=0.0, yaw_rad=0.0) -> np.ndarray:
    """The vehicle at rest at the given pose with its terrain cells in static equilibrium.

    Solved with a CasADi Newton root-finder on the model's own cell equations (rates zero), from
    the sinkage at which the model's soil law carries the vehicle's mean pressure (its static inverse).
    The 3D hull on the homogeneous terrain starts with the soil's memory under its segments
    (:class:`~symtrack.vehicles.vehicle3d.ContactTerrain`) at its steady state for the start pose (the soil
    as a run at that pose leaves it: each segment's soil pressed to the deepest sinkage ahead of it), found
    with the pose by fixed-point iteration.
    """
    x = _static_state(model, params, x_m, y_m, yaw_rad)
    hidx = _history_indices(model)
    if not hidx:
        return x
    p = model.param_vector(params)
    for _ in range(HISTORY_ITERATIONS):
        h = _steady_history(model, x, p, hidx)
        if np.max(np.abs(h - x[hidx])) <= HISTORY_TOL_M:
            break
        x = _static_state(model, params, x_m, y_m, yaw_rad, history=h)
    return x


def _history_indices(model) -> list:
    """The positions of the soil memory's states of a 3D hull's homogeneous terrain (none on other terrains)."""
    if model.vehicle.contact != CONTACT_HULL or not getattr(model.terrain, "memory", False):
        return []
    return model.layout.indices(model.terrain.state_names)


def _steady_history(model, x, p, hidx) -> np.ndarray:
    """The soil memory's steady state at the pose of ``x``: each track's chain H_i = T_i(H_(i-1)) of
    :func:`~symtrack.vehicles.vehicle3d.segment_history_rates`, read from the model's own rates with the hull
    moving forward at 1 m/s (the rates are c (T_i - H_i), c the track's speed over a segment length: found from
    H_1, whose target does not depend on the memory), one pass per segment."""
    xm = np.array(x, dtype=float)
    xm[model.layout.index("u_m_s")] = 1.0
    n = model.opts.contact_segments - 1
    h = xm[hidx].copy()

    def rates(hv):
        xt = xm.copy()
        xt[hidx] = hv
        return np.array(model.ode(xt, ca.DM.zeros(len(model.input_names)), p)).ravel()[hidx]

    for _ in range(n):
        r0 = rates(h)
        shifted = h.copy()
        shifted[0::n] += 1e-3  # each track's H_1
        c = np.repeat(-(rates(shifted)[0::n] - r0[0::n]) / 1e-3, n)
        h = h + r0 / c
    return h


def _static_state(model: SystemModel, params: dict, x_m=0.0, y_m=0.0, yaw_rad=0.0, history=None) -> np.ndarray:
    """:func:`static_state` at a given soil memory ``history`` of the 3D hull (zero: virgin soil)."""
    lay = model.layout
    x = np.zeros(model.nx)
    if history is not None:
        x[_history_indices(model)] = history
    x[lay.indices(("x_m", "y_m", "yaw_rad"))] = x_m, y_m, yaw_rad
    cell_idx = lay.cell_indices("sinkage")
    rate_idx = lay.cell_indices("rate")
    law = make_soil_law(model.opts)
    p_mean = mean_ground_pressure_Pa(params)
    z_guess = float(law.static_sinkage(p_mean, law.values(params)))
    hull = model.vehicle.contact == CONTACT_HULL
    if hull:
        model.vehicle.check_ground(model.opts, model.vehicle.surface, params)
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
        if not hull:
            raise SimulationError(f"no static equilibrium of the terrain cells: {err}") from err
        sol = None
    if hull:
        x[cell_idx] = guess if sol is None else sol
        if sol is None or not np.all(np.abs(np.array(model.ode(x, ca.DM.zeros(2), p)).ravel()[rate_idx]) < 1e-4):
            # uneven ground (a rigid track on a furrow's ridge): let the hull down, then Newton again
            sol = _settle_hull(model, x, p, cell_idx, rate_idx, guess)
            try:
                sol = np.array(rf(sol)).ravel()
            except RuntimeError:
                pass  # the settled hull (checked below)
    x[cell_idx] = sol
    if hull:
        resid_v = np.array(model.ode(x, ca.DM.zeros(2), p)).ravel()[rate_idx]
        if not np.all(np.abs(resid_v) < 1e-4):
            raise ImplausibleRunError(
                f"no static equilibrium of the 3D vehicle's hull at x, y = {x_m:g}, {y_m:g} m: the damped settling "
                f"and Newton found no rest (its heave, pitch and roll accelerations "
                f"{np.array2string(resid_v, precision=3)} m/s^2, rad/s^2 there): {_NO_REST}", "rest")
        # a rest of the equations with the hull in the soil is none the model can carry (no hull contact): a
        # track end deeper than the CG's height, as the run is stopped for (plausibility.check_sinkage)
        from .plausibility import SINKAGE_OVER_CG_HEIGHT_MAX, sinkage_columns

        sk_from, isk = sinkage_columns(model.state_names, model.output_names)
        values = x if sk_from == "x" else np.array(model.outputs(x, ca.DM.zeros(2), p)).ravel()
        sink = max(float(values[i]) for i in isk)
        h = float(params["cg_height_m"])
        if sink > SINKAGE_OVER_CG_HEIGHT_MAX * h:
            raise ImplausibleRunError(
                f"no static equilibrium of the 3D vehicle's hull at x, y = {x_m:g}, {y_m:g} m that the model carries: "
                f"the one Newton found has a track end {sink:.3g} m deep, deeper than the CG's height "
                f"vehicle.cg_height_m = {h:g} m (the hull would be in the soil), at a pitch of "
                f"{np.degrees(float(x[cell_idx[1]])):.3g} deg: {_NO_REST}", "rest")
    return x


# the artificial damping of the hull's settling [1/s] and its duration (only the start state's search):
# about critical for a rocking mode of 2 rad/s (a rigid track on a furrow's ridge), the heave's 60 rad/s
# decaying at 2 /s. CVODES may take up to 200,000 steps for it: a nearly flat pressure-sinkage law (the WES
# heavy clay, n = 0.11) is stiff at the micrometre sinkage of its static state (the 10,000 of CasADi's
# default gave up there; tests/test_physics_fuzz.py)
SETTLE_DAMPING_PER_S = 4.0
SETTLE_TIME_S = 8.0


# what the two failures of the 3D hull's start search say: the same cause, found at one step or the other
_NO_REST = ("the soil may not carry the vehicle at rest here (a nearly flat pressure-sinkage law, a small "
            "soil.bekker_n, sinks the most loaded track end without bound when the CG is off the contact's centre "
            "or the ground slopes: the hull pitches or rolls towards it at every attitude; the start is searched "
            "with no traction); check the soil, vehicle.cg_ahead_of_contact_centre_m and the slope")


def _settle_hull(model, x, p, pos_idx, acc_idx, guess):
    """The 3D hull let down from ``guess`` (heave, pitch, roll) with its planar states frozen and an
    artificial damping on its three rates, CVODES for SETTLE_TIME_S: a start for Newton that is in
    contact however uneven the ground (a rigid track resting on a furrow's ridge)."""
    q = ca.SX.sym("q", 3)
    w = ca.SX.sym("w", 3)
    xs = ca.SX(ca.DM(x))
    for k, i in enumerate(pos_idx):
        xs[i] = q[k]
    rate_idx = [model.layout.index(n) for n in ("heave_rate_m_s", "pitch_rate_rad_s", "roll_rate_rad_s")]
    for k, i in enumerate(rate_idx):
        xs[i] = w[k]
    acc = model.ode(xs, ca.DM.zeros(2), p)[acc_idx] - SETTLE_DAMPING_PER_S * w
    F = ca.integrator("settle", "cvodes", {"x": ca.vertcat(q, w), "ode": ca.vertcat(w, acc)}, 0.0, SETTLE_TIME_S,
                      {"abstol": 1e-10, "reltol": 1e-8, "max_num_steps": 200000})
    try:
        return np.array(F(x0=np.concatenate([guess, np.zeros(3)]))["xf"]).ravel()[:3]
    except RuntimeError as err:  # CVODES gave up (a soil too stiff for its step budget): the package's error
        raise ImplausibleRunError(f"the 3D vehicle's hull could not be settled on the ground to find its static "
                                  f"start (CVODES over {SETTLE_TIME_S:g} s of damped settling: "
                                  f"{str(err).splitlines()[-1]}); Newton found no rest either: {_NO_REST}",
                                  "rest") from err
