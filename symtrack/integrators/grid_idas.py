"""IDAS for the vehicle + channel pool, with the channel states ordered first.

The coupled system's Jacobian is an arrowhead: each channel couples only to itself, the pose
and the two algebraic accelerations, while the vehicle's rows and the algebraic rows see every
channel (the compaction resistance). Eliminated in the model's order (vehicle states first),
the dense rows and columns fill the whole factor: measured on a 662-state system, one sparse
LU (csparse) took 48 ms and CasADi's default QR 120 ms. With the channels first and the
vehicle and algebraic variables last there is no fill: 0.16 ms (csparse). This stepper builds
the integrator on that permuted state vector and maps states in and out, so callers keep the
model's state order.
"""

from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np

from ..foundations import caches
from ..foundations.errors import SimulationError
from .settings import IntegratorSettings
from .sundials import SundialsStepper

__all__ = ["ChannelStepper", "channel_dae"]

# the IDAS integrators built in this process, by the system's expressions and the options
# (ChannelStepper; symtrack.foundations.caches): a second plant of the same field, vehicle and soil law
# (the parameters are the integrator's input) reuses the first's instead of building it again (about
# 4 s of CPU on a 12 m x 4 m field at 0.25 m, of which the Jacobian's blocks and their common
# subexpressions most; the key's serialisation 0.1 s)
_INTEGRATORS = caches.cache("idas_channel_integrators", 4)

# CasADi's cse over the DAE and its Jacobian (channel_dae): 23 % fewer operations per evaluation, for a
# build whose common-subexpression search grows with the channels (about 17 s of CPU on a 12 m x 4 m field
# at 0.25 m with every cell a channel). Without it the numbers are the same to the last bit (the same
# operations on the same operands, some repeated), each step about 30 % slower: a test hook for the
# tests' short IDAS references, whose build costs more than their steps.
CSE = True

DYN_IN = ("t", "x", "z", "p", "u")
DYN_OUT = ("ode", "alg", "quad", "zero")


def channel_dae(model, quad=None):
    """The time-scaled DAE (channel states first) as a Function with its exact Jacobian built by
    blocks; ``quad``: optional SX expressions in the model's x, z, u, p to integrate alongside (IDAS's
    quadratures, not in its error control; their Jacobian blocks are declared zero: IDAS does not
    use them).

    CasADi's automatic Jacobian of the whole system colours columns (or rows) in one
    direction; the arrowhead has dense rows (yaw rate and longitudinal acceleration: the
    compaction resistance sums over all channels) and dense columns (pose and accelerations:
    every channel's load depends on them), so one-directional colouring needs one sweep per
    channel and the construction time grows like n^2.5 (8.6 s at 400 channels). By blocks it is
    linear: d(channel rows)/d(channel states) is block diagonal (two colours), the channel rows
    against the 14 vehicle and algebraic variables and the 14 vehicle and algebraic rows against
    everything take 14 sweeps each. The blocks are the exact derivatives of the same
    expressions, handed to IDAS through ``custom_jacobian``. Only the Jacobians with respect to
    x and z are given (the ones a forward simulation uses); the blocks for t, p, u are declared
    zero, so this Function is not for parametric sensitivities.
    """
    h = ca.SX.sym("step_s")
    t = ca.SX.sym("t")
    vs, cs = model.layout.block("vehicle"), model.layout.block("cells")
    alg_rows = slice(vs.stop, None)  # the rows of rows_v after the vehicle's: the algebraic equations
    xc, xv, z = model.x[cs], model.x[vs], model.z
    ode = h * model.ode_dae_expr
    fc, fv, alg = ode[cs], ode[vs], model.alg_expr
    rows_v = ca.vertcat(fv, alg)
    xp = ca.vertcat(xc, xv)
    J_cx = ca.horzcat(ca.jacobian(fc, xc), ca.jacobian(fc, xv))
    J_vx = ca.jacobian(rows_v, xp)
    J_cz = ca.jacobian(fc, z)
    J_vz = ca.jacobian(rows_v, z)
    ins = [t, xp, z, ca.vertcat(model.p, h), model.u]
    outs = [ca.vertcat(fc, fv), alg, ca.SX(0, 1) if quad is None else h * ca.vec(quad), ca.SX(0, 1)]
    blocks = {("ode", "x"): ca.vertcat(J_cx, J_vx[vs, :]), ("alg", "x"): J_vx[alg_rows, :],
              ("ode", "z"): ca.vertcat(J_cz, J_vz[vs, :]), ("alg", "z"): J_vz[alg_rows, :]}
    jac, jac_names = [], []
    for o, oe in zip(DYN_OUT, outs, strict=True):
        for i, ie in zip(DYN_IN, ins, strict=True):
            jac.append(blocks.get((o, i), ca.SX(oe.numel(), ie.numel())))
            jac_names.append(f"jac_{o}_{i}")
    nominal = [ca.SX.sym("out_" + n, e.sparsity()) for n, e in zip(DYN_OUT, outs, strict=True)]
    J = ca.Function("jac_channel_dae_sx", ins + nominal, jac, list(DYN_IN) + ["out_" + n for n in DYN_OUT], jac_names,
                    {"cse": CSE})
    F = ca.Function("channel_dae_sx", ins, outs, list(DYN_IN), list(DYN_OUT),
                    {"custom_jacobian": J, "jac_penalty": 0, "cse": CSE})  # cse: 23 % fewer operations (CSE)
    # An MX wrapper: the integrator then differentiates the call node, which uses the custom
    # Jacobian (for an SX Function it would differentiate the expressions again).
    mx = [ca.MX.sym(n, e.sparsity()) for n, e in zip(DYN_IN, ins, strict=True)]
    # max_num_dir: the wrapper's Jacobian is then taken in one batch of directions, so the
    # custom Jacobian is evaluated once per Jacobian call (with CasADi's default batch of 64
    # directions it was evaluated n/64 times).
    return ca.Function("channel_dae", mx, F.call(mx), list(DYN_IN), list(DYN_OUT),
                       {"max_num_dir": max(64, model.nx + len(model.alg_names))})


class ChannelStepper(SundialsStepper):
    """IDAS on the vehicle + channel pool with the channel states ordered first (module doc)."""

    def __init__(self, model, settings: IntegratorSettings, quad=None):
        """quad: optional expressions to integrate over each step (:func:`channel_dae`); their
        integral over the last step is then ``last_quad``."""
        if settings.method != "idas":
            raise SimulationError(f"run.integrator = {settings.method!r}: the grid terrain runs with \"idas\"")
        self.model, self.settings = model, settings
        self.z = None
        nx = model.nx
        nv = model.layout.nv
        self.perm = np.r_[np.arange(nv, nx), np.arange(nv)]
        self.inv = np.argsort(self.perm)
        opts = {"abstol": settings.abstol, "reltol": settings.reltol, "max_num_steps": settings.max_num_steps,
                "calc_ic": True, "linear_solver": "csparse",
                # IDAS restarts at every macro step (time scaled to [0, 1]): a first step of
                # 1e-4 of it took about 10 % fewer internal steps than IDAS's own guess
                "step0": 1e-4}
        vs, cs = model.layout.block("vehicle"), model.layout.block("cells")
        outs = [model.ode_dae_expr, model.alg_expr] + ([] if quad is None else [ca.vec(quad)])
        system = ca.Function("system", [model.x, model.z, model.p, model.u], outs).serialize()
        key = (hashlib.sha256(system.encode()).hexdigest(), (vs.start, vs.stop, cs.start, cs.stop),
               repr(sorted(opts.items())), CSE)
        self.F = _INTEGRATORS.get_or_build(key, lambda: ca.integrator("step_channels_idas", "idas",
                                                                      channel_dae(model, quad), 0.0, 1.0, opts))
        self.last_quad = None
