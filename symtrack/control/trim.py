"""Trim points (steady motions) of the model, solved on the model's own ``ode`` Function.

A trim point is a state x and a constant command u at which every state derivative except
those of the position states is zero:

- straight running at speed V: u_m_s = V, yaw_rate_rad_s = 0;
- a steady turn of radius R (positive: left, counter-clockwise) at speed V:
  u_m_s = V, yaw_rate_rad_s = V / R.

X, Y and yaw are not equilibrium coordinates (on a turn they keep changing; on a straight the
dynamics do not depend on them): they are set to 0 and their derivatives are not equations.
Unknowns: every other state except u_m_s and yaw_rate_rad_s (fixed by the specification) plus the
two commanded torques; equations: the derivatives of every state except X, Y, yaw (the torque-lag
rows give command = actual torque). Same count, so a Newton root-finder (CasADi ``rootfinder``)
solves it.

The lagged lateral shear states of the "shear" law (symtrack.vehicles.planar.LATERAL_STATES) are
eliminated from the continuation (set to the solution of their own steady equations, which are affine
in them) and then solved with every other state by a last Newton (:class:`_TrimProblem`); the
``residual_norm`` of a :class:`TrimPoint` is the largest state derivative except the positions' there.

A steady turn is found by continuation in curvature from the straight trim at the same speed;
when Newton stops converging before the requested curvature, the last converged point tells which
physical limit was reached (:func:`trim`): the lateral resistance (the tracks cannot carry the
centripetal force m V^2 / R) or the traction (the yaw moment the tracks' tractive forces can make,
(B/2) (F_outer - F_inner), cannot overcome the turning resistance of the soil).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError, SymtrackError
from ..model import SystemModel
from ..model.static import static_state
from ..vehicles.planar import GRAVITY_M_S2, LATERAL_STATES, lateral_resistance_max_N

__all__ = ["POSITION_STATES", "SPECIFIED_STATES", "TrimError", "TrimPoint", "TrimSettings", "limit_usage", "trim"]

POSITION_STATES = ("x_m", "y_m", "yaw_rad")
SPECIFIED_STATES = ("u_m_s", "yaw_rate_rad_s")


class TrimError(SymtrackError, RuntimeError):
    """No steady motion exists (or none was found) for the requested speed, radius and soil."""


@dataclass(frozen=True)
class TrimSettings:
    """Numerical settings of the trim solver.

    abstol: Newton tolerance on the residual (state derivatives, SI units).
    max_iter: Newton iterations per solve.
    continuation_steps: initial number of curvature steps from straight running to 1/R.
    min_step_fraction: the continuation gives up (and reports a limit) when the step it needs is
        smaller than this fraction of the full curvature.
    """

    abstol: float = 1e-9
    max_iter: int = 60
    continuation_steps: int = 8
    min_step_fraction: float = 1e-3

    def __post_init__(self):
        if not (isinstance(self.abstol, (int, float)) and 0 < self.abstol <= 1e-2):
            raise ParameterError(f"trim.abstol = {self.abstol!r} is outside the allowed range (0, 1e-2]")
        if not (isinstance(self.max_iter, int) and 1 <= self.max_iter <= 1000):
            raise ParameterError(f"trim.max_iter = {self.max_iter!r} must be an integer in [1, 1000]")
        if not (isinstance(self.continuation_steps, int) and 1 <= self.continuation_steps <= 1000):
            raise ParameterError(
                f"trim.continuation_steps = {self.continuation_steps!r} must be an integer in [1, 1000]")
        if not (isinstance(self.min_step_fraction, (int, float)) and 0 < self.min_step_fraction < 1):
            raise ParameterError(
                f"trim.min_step_fraction = {self.min_step_fraction!r} is outside the allowed range (0, 1)")


@dataclass(frozen=True)
class TrimPoint:
    """A steady motion: full state x (positions 0), command u, parameter vector p, and the model
    outputs there (named). ``radius_m`` is None for straight running."""

    speed_m_s: float
    radius_m: float | None
    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    state_names: tuple
    input_names: tuple
    outputs: dict = field(default_factory=dict)
    residual_norm: float = 0.0
    limits: dict = field(default_factory=dict)

    @property
    def yaw_rate_rad_s(self) -> float:
        return 0.0 if self.radius_m is None else self.speed_m_s / self.radius_m

    def state(self, name: str) -> float:
        return float(self.x[self.state_names.index(name)])

    def __repr__(self) -> str:
        """The motion, the commands and the states by name with their units (the names carry them);
        the arrays themselves are ``x``, ``u`` and ``p``."""
        motion = (f"straight running at {self.speed_m_s:g} m/s" if self.radius_m is None else
                  f"a turn of radius {self.radius_m:g} m at {self.speed_m_s:g} m/s "
                  f"(yaw rate {self.yaw_rate_rad_s:.4g} rad/s)")
        inputs = ", ".join(f"{n} = {float(v):.6g}" for n, v in zip(self.input_names, self.u, strict=True))
        states = "\n".join(f"    {n} = {float(v):.6g}" for n, v in zip(self.state_names, self.x, strict=True))
        usage = {k: float(v) for k, v in self.limits.items() if k.endswith("usage") or "usage_" in k}
        limits = (", ".join(f"{k} = {v:.3g}" for k, v in usage.items())) if usage else "n/a"
        return (f"TrimPoint: {motion}, residual {self.residual_norm:.2g}\n  inputs: {inputs}\n"
                f"  share of the soil's strength used: {limits}\n  states:\n{states}")

    def to_dict(self) -> dict:
        return {
            "speed_m_s": self.speed_m_s,
            "radius_m": self.radius_m,
            "yaw_rate_rad_s": self.yaw_rate_rad_s,
            "state": {n: float(v) for n, v in zip(self.state_names, self.x, strict=True)},
            "input": {n: float(v) for n, v in zip(self.input_names, self.u, strict=True)},
            "outputs": {k: float(v) for k, v in self.outputs.items()},
            "limits": dict(self.limits),
            "residual_norm": self.residual_norm,
        }


class _TrimProblem:
    """The root-finding problem on model.ode, parametrised by (speed, yaw rate).

    States whose own equations are affine in them (the lagged lateral shear states of the "shear"
    law, :data:`~symtrack.vehicles.planar.LATERAL_STATES`: relaxations towards the current slips) are
    eliminated from the continuation: they are set to the exact solution of their steady equations
    for the other states (a linear solve in closed form), so the continuation's unknowns and
    equations are those of the quasi-static law. Starting them at zero instead, Newton does not reach
    them (the lagged slips set the sliding direction). :meth:`polish` then runs a Newton on every
    state and equation from that point.
    """

    def __init__(self, model: SystemModel, p, settings: TrimSettings):
        self.model, self.p, self.settings = model, ca.DM(p), settings
        names = model.state_names
        self.fixed = [names.index(n) for n in POSITION_STATES + SPECIFIED_STATES]
        self.free_all = [i for i in range(model.nx) if i not in self.fixed]
        self.lagged = [i for i in self.free_all if names[i] in LATERAL_STATES]
        self.free = [i for i in self.free_all if i not in self.lagged]  # the continuation's unknowns
        self.eq_rows_all = [i for i in range(model.nx) if names[i] not in POSITION_STATES]
        self.eq_rows = [i for i in self.eq_rows_all if i not in self.lagged]
        nf, nu = len(self.free), model.u.numel()
        w = ca.SX.sym("w", nf + nu)
        spec = ca.SX.sym("spec", 2)  # speed, yaw rate
        lag = ca.SX.sym("lag", len(self.lagged))
        x = [ca.SX(0)] * model.nx
        for k, i in enumerate(self.free):
            x[i] = w[k]
        for k, i in enumerate(self.lagged):
            x[i] = lag[k]
        x[names.index("u_m_s")] = spec[0]
        x[names.index("yaw_rate_rad_s")] = spec[1]
        x = ca.vertcat(*x)
        u = w[nf:]
        ode = model.ode(x, u, self.p)
        if self.lagged:
            # the lagged states' rows are affine in them: f = J lag + f0, steady lag = -J^-1 f0
            f_lag = ode[self.lagged]
            J = ca.jacobian(f_lag, lag)
            if ca.depends_on(J, lag):
                raise SymtrackError("trim: the lagged lateral shear states' equations are not affine in them; "
                                    "their elimination (symtrack.control.trim) does not apply")
            f0 = ca.substitute(f_lag, lag, ca.SX.zeros(lag.shape))
            lag_steady = -ca.solve(J, f0)
            x = ca.substitute(x, lag, lag_steady)
            res = ca.substitute(ode[self.eq_rows], lag, lag_steady)
        else:
            res = ode[self.eq_rows]
        g = ca.Function("trim_residual", [w, spec], [res])
        self.residual = g
        # the tangent of the solution path in the yaw rate, dw/dr_z = -(dg/dw)^-1 dg/dr_z (the predictor)
        self.tangent = ca.Function("trim_tangent", [w, spec],
                                   [-ca.solve(ca.jacobian(res, w), ca.jacobian(res, spec[1]))])
        self.assemble = ca.Function("trim_assemble", [w, spec], [x, u])
        self.rf = ca.rootfinder("trim", "newton", g, {"abstol": settings.abstol, "max_iter": settings.max_iter,
                                                      "error_on_fail": True})
        # fallback: KINSOL's Newton with a line search, for the first curvature steps from straight
        # running, where the combined-slip lateral law is strongly nonlinear at near-zero track slip
        self.rf_safe = ca.rootfinder("trim_ls", "kinsol", g, {
            "abstol": settings.abstol, "max_iter": settings.max_iter, "error_on_fail": True,
            "strategy": "linesearch", "disable_internal_warnings": True})
        # the full problem (every free state and every equation), for the polish
        wa = ca.SX.sym("wa", len(self.free_all) + nu)
        xa = [ca.SX(0)] * model.nx
        for k, i in enumerate(self.free_all):
            xa[i] = wa[k]
        xa[names.index("u_m_s")] = spec[0]
        xa[names.index("yaw_rate_rad_s")] = spec[1]
        xa = ca.vertcat(*xa)
        self.residual_all = ca.Function("trim_residual_all", [wa, spec],
                                        [model.ode(xa, wa[len(self.free_all):], self.p)[self.eq_rows_all]])
        self.rf_all = ca.rootfinder("trim_all", "newton", self.residual_all, {
            "abstol": settings.abstol, "max_iter": settings.max_iter, "error_on_fail": True})

    def solve(self, w0, speed, yaw_rate):
        spec = ca.DM([speed, yaw_rate])
        try:
            w = self.rf(w0, spec)
        except RuntimeError:
            try:
                w = self.rf_safe(w0, spec)
            except RuntimeError:
                return None
        w = np.array(w).ravel()
        if not np.all(np.isfinite(w)):
            return None
        res = float(np.linalg.norm(np.array(self.residual(w, spec)).ravel(), np.inf))
        if res > 1e3 * self.settings.abstol:
            return None
        return w, res

    def predict(self, w, speed, yaw_rate, yaw_rate_next):
        """The continuation's predictor: w moved along the solution path's tangent to yaw_rate_next."""
        d = np.array(self.tangent(w, ca.DM([speed, yaw_rate]))).ravel()
        if not np.all(np.isfinite(d)):
            return w
        wp = w + d * (yaw_rate_next - yaw_rate)
        ok = np.all(np.isfinite(np.array(self.residual(wp, ca.DM([speed, yaw_rate_next])))))
        return wp if ok else w

    def point(self, w, speed, yaw_rate):
        x, u = self.assemble(w, ca.DM([speed, yaw_rate]))
        return np.array(x).ravel(), np.array(u).ravel()

    def polish(self, w, speed, yaw_rate):
        """Newton on every free state (the eliminated ones too) and every equation, from the
        continuation's solution w; returns (x, u, residual) with the residual over all the
        equations (the largest state derivative except the positions'), or None if it fails."""
        x, u = self.point(w, speed, yaw_rate)
        spec = ca.DM([speed, yaw_rate])
        wa0 = np.concatenate([x[self.free_all], u])
        if self.lagged:
            try:
                wa = np.array(self.rf_all(wa0, spec)).ravel()
            except RuntimeError:
                return None
            if not np.all(np.isfinite(wa)):
                return None
        else:
            wa = wa0
        res = float(np.linalg.norm(np.array(self.residual_all(wa, spec)).ravel(), np.inf))
        if res > 1e3 * self.settings.abstol:
            return None
        x = x.copy()
        x[self.free_all] = wa[:len(self.free_all)]
        return x, wa[len(self.free_all):], res


# the problems built (their Functions and rootfinders: about 0.3 s each), per model, parameter vector and settings:
# the trims of one steering map or continuation on one soil share one (symtrack.foundations.caches)
_PROBLEMS = caches.cache("trim_problems", 8)


def _problem(model: SystemModel, p: np.ndarray, settings: TrimSettings) -> _TrimProblem:
    key = (id(model), p.tobytes(), settings)
    hit = _PROBLEMS.get(key)
    if hit is not None and hit.model is model:  # (an id is reused only after its model is gone)
        return hit
    return _PROBLEMS.put(key, _TrimProblem(model, p, settings))


def _outputs(model, x, u, p) -> dict:
    y = np.array(model.outputs(x, u, p)).ravel()
    return dict(zip(model.output_names, y, strict=True))


def limit_usage(model: SystemModel, params: dict, x, u, p) -> dict:
    """How much of the soil's traction and lateral resistance a state uses (1 = all of it).

    traction_usage_{left,right}: |F_k| / F_max,k, with F_max,k = b l c + N_k tan(phi) the
    fully-developed shear strength of the contact patch (N_k from the model's output).
    lateral_usage: |sum F_y| over the largest lateral resistance the tracks can give
    (:func:`symtrack.vehicles.planar.lateral_resistance_max_N`: the soil's shear strength for the
    "shear" law, mu_t W for the "creep" law).
    """
    y = _outputs(model, x, u, p)
    out = {}
    for k in ("left", "right"):
        fmax = params["track_width_m"] * params["contact_length_m"] * params["cohesion_Pa"] \
            + y[f"normal_load_{k}_N"] * math.tan(params["friction_angle_rad"])
        out[f"tractive_{k}_N"] = y[f"tractive_{k}_N"]
        out[f"traction_max_{k}_N"] = fmax
        out[f"traction_usage_{k}"] = abs(y[f"tractive_{k}_N"]) / fmax
    out["lateral_force_N"] = y["lateral_force_left_N"] + y["lateral_force_right_N"]
    out["lateral_resistance_max_N"] = lateral_resistance_max_N(params, model.opts)
    out["lateral_usage"] = abs(out["lateral_force_N"]) / out["lateral_resistance_max_N"]
    return out


def _straight_guess(model: SystemModel, params: dict, problem: _TrimProblem, speed: float,
                    pose=(0.0, 0.0, 0.0)) -> np.ndarray:
    x0 = static_state(model, params, *pose)
    names = model.state_names
    r = params["sprocket_radius_m"]
    W = params["mass_kg"] * GRAVITY_M_S2
    # running-gear resistance at this speed (Wong), carried by the torques; a small slip
    res_per_track = 0.5 * W * (params["internal_resistance_const"]
                               + params["internal_resistance_per_km_h"] * 3.6 * abs(speed))
    torque = math.copysign(r * res_per_track, speed) if speed != 0 else 0.0
    x0[names.index("omega_left_rad_s")] = x0[names.index("omega_right_rad_s")] = speed / r * 1.01
    x0[names.index("shear_left_m")] = x0[names.index("shear_right_m")] = 0.005 * params["contact_length_m"] * (
        1 if speed >= 0 else -1)
    x0[names.index("torque_left_N_m")] = x0[names.index("torque_right_N_m")] = torque
    return np.concatenate([x0[problem.free], [torque, torque]])


def trim(model: SystemModel, params: dict, speed_m_s: float, radius_m: float | None = None,
         settings: TrimSettings | None = None, pose=(0.0, 0.0, 0.0)) -> TrimPoint:
    """Steady straight running (radius_m None or infinite) or a steady turn at radius_m
    (positive: left turn) at speed_m_s, on the soil in params. Raises :class:`TrimError` when no
    steady motion exists, naming the limit.

    ``pose``: (x_m, y_m, yaw_rad) at which the trim is taken (X, Y and yaw are not unknowns: they
    stay there). The planar vehicle's trim does not depend on it; the 3D vehicle's hull is settled
    on the ground under that pose (on a side slope the straight trim is the instantaneous
    equilibrium there: its drift downhill, v_m_s, is one of the unknowns)."""
    settings = settings or TrimSettings()
    if isinstance(speed_m_s, bool) or not isinstance(speed_m_s, (int, float)) or not math.isfinite(speed_m_s):
        raise ParameterError(f"trim speed_m_s = {speed_m_s!r} must be a finite number")
    if abs(speed_m_s) < 0.05 or abs(speed_m_s) > 20.0:
        raise ParameterError(f"trim speed_m_s = {speed_m_s!r} is outside the allowed range 0.05 <= |V| <= 20 m/s")
    if radius_m is not None:
        if isinstance(radius_m, bool) or not isinstance(radius_m, (int, float)) or math.isnan(radius_m):
            raise ParameterError(f"trim radius_m = {radius_m!r} must be a number (or None for straight running)")
        if math.isinf(radius_m):
            radius_m = None
        elif abs(radius_m) <= 0.5 * params["track_gauge_m"]:
            raise ParameterError(
                f"trim radius_m = {radius_m!r}: |R| must exceed half the track gauge "
                f"({0.5 * params['track_gauge_m']:g} m); turning on the spot has no steady forward speed")
    p = np.asarray(model.param_vector(params), dtype=float)
    problem = _problem(model, p, settings)
    w0 = _straight_guess(model, params, problem, speed_m_s, tuple(float(v) for v in pose))
    sol = problem.solve(w0, speed_m_s, 0.0)
    if sol is None:
        raise TrimError(f"no steady straight running found at speed_m_s = {speed_m_s:g} on this soil "
                        "(Newton did not converge from the rolling-resistance guess)")
    w, res = sol
    if radius_m is not None:
        # the centripetal force cannot exceed the lateral resistance (a necessary condition)
        need = params["mass_kg"] * speed_m_s**2 / abs(radius_m)
        have = lateral_resistance_max_N(params, model.opts)
        if need >= have:
            raise TrimError(
                f"no steady turn at radius_m = {radius_m:g}, speed_m_s = {speed_m_s:g}: lateral resistance limit, "
                f"the centripetal force m V^2/R = {need:.0f} N exceeds the largest lateral resistance "
                f"{have:.0f} N (the vehicle slides out); use a larger radius or a lower speed")
        target = speed_m_s / radius_m
        frac, step = 0.0, 1.0 / settings.continuation_steps
        last_x, last_u = problem.point(w, speed_m_s, 0.0)
        while frac < 1.0 - 1e-12:
            nxt = min(1.0, frac + step)
            # from the tangent predictor, else from the last point (corrector: Newton, then KINSOL)
            sol = problem.solve(problem.predict(w, speed_m_s, frac * target, nxt * target), speed_m_s, nxt * target)
            if sol is None:
                sol = problem.solve(w, speed_m_s, nxt * target)
            if sol is None:
                step *= 0.5
                if step < settings.min_step_fraction:
                    usage = limit_usage(model, params, last_x, last_u, p)
                    raise TrimError(_limit_message(radius_m, speed_m_s, frac, usage))
                continue
            w, res = sol
            frac = nxt
            last_x, last_u = problem.point(w, speed_m_s, frac * target)
            step = min(2 * step, 1.0 / settings.continuation_steps * 4)
    yaw_rate = 0.0 if radius_m is None else speed_m_s / radius_m
    polished = problem.polish(w, speed_m_s, yaw_rate)
    if polished is None:
        raise TrimError(f"trim at speed_m_s = {speed_m_s:g}, radius_m = {radius_m!r}: the Newton on every state "
                        "(the lagged lateral shear states included) did not converge from the continuation's point")
    x, u, res = polished
    usage = limit_usage(model, params, x, u, p)
    for k in ("left", "right"):
        om = x[model.state_index(f"omega_{k}_rad_s")]
        if om * speed_m_s <= 0:
            raise TrimError(
                f"no steady turn at radius_m = {radius_m:g}, speed_m_s = {speed_m_s:g}: traction limit, the {k} "
                "sprocket would have to stop or reverse (the soil's shear strength cannot hold the turn)")
    return TrimPoint(float(speed_m_s), None if radius_m is None else float(radius_m), x, u, p,
                     tuple(model.state_names), tuple(model.input_names), _outputs(model, x, u, p), res, usage)


def _limit_message(radius_m, speed_m_s, frac, usage) -> str:
    reached = f"{abs(radius_m) / frac:.3g} m" if frac > 0 else "none (not even a slight curve)"
    trac = max(usage["traction_usage_left"], usage["traction_usage_right"])
    lat = usage["lateral_usage"]
    if trac >= lat:
        why = (f"traction limit: the tracks use {100 * trac:.0f} % of the soil's shear strength "
               f"(left {usage['tractive_left_N']:.0f} of {usage['traction_max_left_N']:.0f} N, right "
               f"{usage['tractive_right_N']:.0f} of {usage['traction_max_right_N']:.0f} N), so the yaw moment "
               "(B/2)(F_outer - F_inner) cannot grow to overcome the soil's turning resistance")
    else:
        why = (f"lateral resistance limit: the tracks carry {100 * lat:.0f} % of the largest lateral "
               f"resistance {usage['lateral_resistance_max_N']:.0f} N")
    return (f"no steady turn at radius_m = {radius_m:g}, speed_m_s = {speed_m_s:g} on this soil: {why}; "
            f"the tightest steady radius reached by continuation was {reached}")
