"""A Rosenbrock step for the vehicle + channel pool (the grid terrain), built with ``map`` over
the channels and solved through the arrowhead's Schur complement: O(channels) per step.

The method is the one of :mod:`symtrack.native.rosenbrock` (CasADi 3.8's ``rosenbrock`` plugin tableau:
8 stages, order 5, L-stable, stiffly accurate) on the time-scaled DAE F = (h f, g), unit step:

    W U_i = F(y0 + sum_j a_ij U_j) + M sum_j c_ij U_j,   W = M / gamma - J(y0),   y1 = y0 + sum m_i U_i

Structure
---------
The unknowns are the channel states x_c (2 per channel) and w = (x_v, z): the 12 vehicle states
and the 2 algebraic accelerations. The model is split so that no expression is expanded per
channel:

- one channel (an SX Function, mapped over the pool): F_c(x_c, q_c, a) with
  a = (X, Y, cos psi, sin psi, alpha_k, beta_k) -- the pose and each track's pressure line
  p(s) = max(0, alpha + beta s) (the linear and both triangular distributions are of this
  form) -- and the channel's contributions s_c to the 10 sums the vehicle sees (compaction
  power per track; weighted sinkage and weight per track end);
- the vehicle (an SX Function of 14 + 10 inputs): F_w(w, u, p, S) with S = sum_c s_c, and a(w).

The Jacobian is then the arrowhead J_cc (2x2 blocks), J_cw = dF_c/da da/dw, and the vehicle rows
J_ww + dF_w/dS (dS/dx_c, dS/dw). With W_c = I / gamma - dF_c/dx_c (2x2, inverted in closed
form), eliminating the channels gives the 14 x 14 Schur system

    (M_w / gamma - J_ww - dF_w/dS T da/dw) k_w = r_w + dF_w/dS sum_c G_c W_c^-1 r_c,
    T = sum_c (G_c W_c^-1 dF_c/da + ds_c/da),  G_c = ds_c/dx_c,
    k_c = W_c^-1 r_c + W_c^-1 dF_c/da (da/dw k_w)

The per-channel factors (W_c^-1, W_c^-1 dF_c/da, G_c W_c^-1, T_c) are formed once per step;
each stage costs one evaluation of F_c and s_c per channel and a few small products. The 14 x 14
system is solved per stage (its cost does not depend on the pool size).

The algebraic state is first made consistent (two Newton steps on g(w) = 0 at the step start,
the sums S held), so the step accepts the channel resets of the world manager between macro steps.

Each step also gives its error ratio, as the homogeneous terrain's compiled step does
(:func:`symtrack.native.rosenbrock.step_and_error_expressions`): the method is stiffly accurate with an
embedded solution of order 4, so the last stage's increment U_8 is the local error estimate; the ratio is
its largest |U_8,i| / (FIXED_STEP_ATOL + rtol max(|y0,i|, |y1,i|)) over the vehicle's differential states
and the channels' sinkage, rtol an input. Not over the channels' sinkage rate: where a cell starts loading
its rate has a kink (the regularised Bekker slope) that no halving resolves, and in a fast, damped mode
whose error does not carry over. Measured on validation_grid at 0.625 ms with the rate in the ratio:
103,255 steps halved and the run over ten times longer (272 s of wall against 18 s, each compiling its
libraries, the first on a busier machine), for figures within 0.1 % of the run without control
(what halving the step once gives at 2 x); without it: 224 steps halved, 3 % longer, the rut's mean depth
0.030 % -> 0.002 % from IDAS's (docs/terrain.md). The error control itself
(halving the steps of a macro step whose ratio exceeds 1) is the stepper's
(:class:`symtrack.integrators.grid_rosenbrock.GridRosenbrockStepper`).
"""

from __future__ import annotations

import casadi as ca

# NS: the channel sums S (shared with the terrain engine); the vehicle's states and algebraic
# accelerations, w, are sized by the vehicle model the options select (12 + 2 planar, 16 + 2 with the
# "shear" law's lateral shear states)
from .grid_engine_model import NS, SumsTerrain, pressure_line
from .rosenbrock import FIXED_STEP_ATOL, GAMMA, N_STAGES
from .rosenbrock import A as RB_A
from .rosenbrock import C as RB_C
from .rosenbrock import M as RB_M

__all__ = ["NA", "NS", "step_functions"]

NA = 8  # a = (X, Y, cos psi, sin psi, alpha_left, beta_left, alpha_right, beta_right)


def step_functions(opts, n_channels: int, n_steps: int, name: str = "grid_rosenbrock") -> dict[str, ca.Function]:
    """The Functions of the grid Rosenbrock integrator for a pool of n_channels channels.

    ``<name>``: (xc[2n], w[nw], u[2], p[np], h, rtol) -> (xc, w, r) after n_steps steps of length h (s),
    w the vehicle's states and its algebraic accelerations (nw = 14 for the planar vehicle, 18 for the
    "shear" law's), p being the grid model's parameter vector (vehicle and soil parameters, then the
    terrain's Q), r the largest error ratio of the steps at the relative tolerance rtol (module doc).
    """
    from symtrack.foundations.params import ParamLayout
    from symtrack.model import SystemModel
    from symtrack.soil.cell import CELL_PARAMS
    from symtrack.soil.law import make as make_soil_law
    from symtrack.terrain.channels import GEO_LAYOUT, HIST_ROWS, NF, NG, build_cell_functions
    from symtrack.vehicles.planar import ENDS, TRACKS

    agg = SumsTerrain()
    veh = SystemModel(opts, agg)
    npv = len(veh.model_param_names)
    xv, z, u, pv = veh.x, veh.z, veh.u, veh.p  # pv = (P, Q globals, S)
    NW = xv.numel() + z.numel()
    h = ca.SX.sym("h")
    w = ca.vertcat(xv, z)
    Sv = pv[npv + NG:]
    D = []
    for k in TRACKS:
        D += list(pressure_line(agg.dist_dae[k]))
    pose = veh.vehicle.contact_pose(xv[veh.layout.block("vehicle")])
    a = ca.vertcat(pose.x_m, pose.y_m, ca.cos(pose.yaw_rad), ca.sin(pose.yaw_rad), *D)
    if ca.depends_on(a, Sv):
        raise RuntimeError("the pressure distributions depend on the channel sums: the Schur form does not hold")
    Fw = ca.vertcat(h * veh.ode_dae_expr, veh.alg_expr)
    fo = {"cse": True}
    vehicle_F = ca.Function("grid_vehicle_F", [w, u, pv, h], [Fw, a], ["w", "u", "pv", "h"], ["Fw", "a"], fo)
    vehicle_J = ca.Function("grid_vehicle_J", [w, u, pv, h],
                            [Fw, a, ca.jacobian(Fw, w), ca.jacobian(Fw, Sv), ca.jacobian(a, w)],
                            ["w", "u", "pv", "h"], ["Fw", "a", "Jww", "JwS", "Aw"], fo)
    g = veh.alg_expr
    zn = z
    for _ in range(2):
        gz = ca.substitute(g, z, zn)
        zn = zn - ca.solve(ca.substitute(ca.jacobian(g, z), z, zn), gz)
    consistent = ca.Function("grid_consistent_z", [w, u, pv], [ca.vertcat(xv, zn)], ["w", "u", "pv"],
                             ["w_consistent"], fo)

    # ---- one channel -------------------------------------------------------------------------------
    fn = build_cell_functions(opts)
    xc = ca.SX.sym("xc", 2)
    q = ca.SX.sym("q", NF)
    av = ca.SX.sym("a", NA)
    sl = make_soil_law(opts)
    # a channel's constants c: the geometry's geo (without 1 / cell size), the soil law's vector, the cell
    # equation's parameters, the step h and an unused entry
    geo_names, cell_names = GEO_LAYOUT.names[:6], tuple(sp.name for sp in CELL_PARAMS)
    consts = ParamLayout((*geo_names, *(f"law.{n}" for n in sl.vector_names), *cell_names, "h_s", "unused"))
    cst = ca.SX.sym("c", len(consts))
    law_at = consts.offset(f"law.{sl.vector_names[0]}")
    geo = ca.vertcat(*(cst[consts.offset(n)] for n in geo_names))
    law = cst[law_at:law_at + sl.size]
    cellpar = ca.vertcat(*(cst[consts.offset(n)] for n in cell_names))
    hh = cst[consts.offset("h_s")]
    # the cell centre in the body frame here (cos, sin of the yaw computed once per stage, not per
    # channel), then the channel's own geometry at the zero pose (cos 0 = 1 folds away)
    ddx, ddy = q[0] - av[0], q[1] - av[1]
    qb = ca.vertcat(av[2] * ddx + av[3] * ddy, -av[3] * ddx + av[2] * ddy, q[2:])
    gvec = fn["geometry"](qb, ca.DM.zeros(3), geo)
    p_soil = fn["soil"](xc[0], ca.vertcat(*(q[r] for r in HIST_ROWS)), law)
    p_load = 0
    for i in range(2):
        p_load = p_load + gvec[i] * ca.fmax(0, av[4 + 2 * i] + av[5 + 2 * i] * gvec[2 + i])
    Fc = hh * fn["dynamics"](xc[1], p_load, p_soil, q[4], cellpar)
    power = p_soil * ca.fmax(xc[1], 0)
    rows = [gvec[4 + r] for r in range(len(TRACKS) * len(ENDS))]
    s = ca.vertcat(gvec[0] * power, gvec[1] * power, *(r * xc[0] for r in rows), *rows)
    chan_F = ca.Function("grid_channel_F", [xc, q, av, cst], [Fc, s], ["xc", "q", "a", "c"], ["Fc", "s"], fo)
    Wc = ca.DM.eye(2) / GAMMA - ca.jacobian(Fc, xc)
    det = Wc[0, 0] * Wc[1, 1] - Wc[0, 1] * Wc[1, 0]
    Winv = ca.vertcat(ca.horzcat(Wc[1, 1], -Wc[0, 1]), ca.horzcat(-Wc[1, 0], Wc[0, 0])) / det
    G = ca.jacobian(s, xc)
    Pm = Winv @ ca.jacobian(Fc, av)  # 2 x 7
    GW = G @ Winv  # 10 x 2
    T = G @ Pm + ca.jacobian(s, av)  # 10 x 7
    chan_J = ca.Function("grid_channel_J", [xc, q, av, cst],
                         [Fc, s, ca.vec(Winv), ca.vec(Pm), ca.vec(GW), ca.vec(T)],
                         ["xc", "q", "a", "c"], ["Fc", "s", "Winv", "Pm", "GW", "T"], fo)
    r_c, Wv, GWv = ca.SX.sym("r", 2), ca.SX.sym("Winv", 4), ca.SX.sym("GW", 20)
    chan_solve = ca.Function("grid_channel_solve", [r_c, Wv, GWv],
                             [ca.reshape(Wv, 2, 2) @ r_c, ca.reshape(GWv, NS, 2) @ r_c],
                             ["r", "Winv", "GW"], ["v", "Gv"], fo)
    v_c, Pmv, da = ca.SX.sym("v", 2), ca.SX.sym("Pm", 2 * NA), ca.SX.sym("da", NA)
    chan_back = ca.Function("grid_channel_back", [v_c, Pmv, da], [v_c + ca.reshape(Pmv, 2, NA) @ da],
                            ["v", "Pm", "da"], ["k"], fo)
    Ks, rs = ca.SX.sym("K", NW, NW), ca.SX.sym("rhs", NW)
    small_solve = ca.Function("grid_schur_solve", [Ks, rs], [ca.solve(Ks, rs)], ["K", "rhs"], ["k"], fo)

    n = n_channels
    mF = chan_F.map("grid_channels_F", "serial", n, [3], [])
    mJ = chan_J.map("grid_channels_J", "serial", n, [3], [])
    mS = chan_solve.map("grid_channels_solve", "serial", n, [], [])
    mB = chan_back.map("grid_channels_back", "serial", n, [2], [])

    # ---- one step (MX: the mapped calls stay loops) --------------------------------------------------
    XC, Wm, U, PV, Qg, QC, H = (ca.MX.sym("xc", 2, n), ca.MX.sym("w", NW), ca.MX.sym("u", 2),
                                ca.MX.sym("pv", npv), ca.MX.sym("qg", NG), ca.MX.sym("qc", NF, n), ca.MX.sym("h"))
    Pm_ = [PV[i] for i in range(npv)]
    Pd = veh.model_layout.unpack(Pm_)
    law_mx = sl.vector(Pd)
    # c in the order of consts: the vehicle's contact, the terrain's globals (cell size, end strip), the law's
    # vector (one block), the cell equation's parameters, h, 0
    C_MX = ca.vertcat(*(Pd[n] for n in GEO_LAYOUT.names[:4]), Qg[0], Qg[1], law_mx, *(Pd[n] for n in cell_names),
                      H, 0)
    if C_MX.numel() != len(consts):
        raise RuntimeError(f"the channel constants: {C_MX.numel()} entries built, the layout has {len(consts)}")
    mass_w = ca.DM.zeros(NW)
    mass_w[veh.layout.block("vehicle")] = 1.0

    def pvec(S):
        return ca.vertcat(PV, Qg, S)

    zeroS = ca.MX.zeros(NS)

    def stage_F(XCi, Wi):
        a_i = vehicle_F(Wi, U, pvec(zeroS), H)[1]
        Fci, si = mF(XCi, QC, a_i, C_MX)
        S = ca.sum2(si)
        Fwi = vehicle_F(Wi, U, pvec(S), H)[0]
        return Fci, Fwi

    a0 = vehicle_F(Wm, U, pvec(zeroS), H)[1]
    Fc0, s0, Winv_m, Pm_m, GW_m, T_m = mJ(XC, QC, a0, C_MX)
    S0 = ca.sum2(s0)
    Fw0, _, Jww, JwS, Aw = vehicle_J(Wm, U, pvec(S0), H)
    Tsum = ca.reshape(ca.sum2(T_m), NS, NA)
    K = ca.diag(mass_w / GAMMA) - Jww - JwS @ (Tsum @ Aw)
    Uc, Uw = [], []
    for i in range(N_STAGES):
        if i == 0:
            Fci, Fwi = Fc0, Fw0
        else:
            XCi, Wi = XC, Wm
            for j, aij in enumerate(RB_A[i]):
                if aij != 0.0:
                    XCi = XCi + aij * Uc[j]
                    Wi = Wi + aij * Uw[j]
            Fci, Fwi = stage_F(XCi, Wi)
        rc, rw = Fci, Fwi
        for j, cij in enumerate(RB_C[i]):
            if cij != 0.0:
                rc = rc + cij * Uc[j]
                rw = rw + cij * (mass_w * Uw[j])
        v, Gv = mS(rc, Winv_m, GW_m)
        kw = small_solve(K, rw + JwS @ ca.sum2(Gv))
        kc = mB(v, Pm_m, Aw @ kw)
        Uc.append(kc)
        Uw.append(kw)
    XC1, W1 = XC, Wm
    for mi, ci, wi in zip(RB_M, Uc, Uw, strict=True):
        XC1 = XC1 + mi * ci
        W1 = W1 + mi * wi
    # the error ratio: the last stage's increment over the tolerance, the vehicle's differential states and the
    # channels' sinkage (row 0; not its rate, row 1: module doc); an idle slot's zeros give 0
    RT = ca.MX.sym("rtol")
    ratio_c = ca.fabs(Uc[-1][0, :]) / (FIXED_STEP_ATOL + RT * ca.fmax(ca.fabs(XC[0, :]), ca.fabs(XC1[0, :])))
    ratio_w = mass_w * ca.fabs(Uw[-1]) / (FIXED_STEP_ATOL + RT * ca.fmax(ca.fabs(Wm), ca.fabs(W1)))
    ratio = ca.fmax(ca.mmax(ratio_c), ca.mmax(ratio_w))
    step = ca.Function(name + "_step", [XC, Wm, U, PV, Qg, QC, H, RT], [XC1, W1, ratio],
                       ["xc", "w", "u", "pv", "qg", "qc", "h", "rtol"], ["xc1", "w1", "r"])

    # ---- n_steps steps per call, on the model's vectors ----------------------------------------------
    xcv, w0 = ca.MX.sym("xc", 2 * n), ca.MX.sym("w", NW)
    u0, p0, h0, rt0 = ca.MX.sym("u", 2), ca.MX.sym("p", npv + NG + NF * n), ca.MX.sym("h"), ca.MX.sym("rtol")
    PV0, Qg0 = p0[:npv], p0[npv:npv + NG]
    QC0 = ca.reshape(p0[npv + NG:], NF, n)
    Xc = ca.reshape(xcv, 2, n)
    a_s = vehicle_F(w0, u0, ca.vertcat(PV0, Qg0, zeroS), h0)[1]
    S_start = ca.sum2(mF(Xc, QC0, a_s, ca.substitute(C_MX, ca.vertcat(PV, Qg, H), ca.vertcat(PV0, Qg0, h0)))[1])
    Wc = consistent(w0, u0, ca.vertcat(PV0, Qg0, S_start))
    r_max = 0
    for _ in range(n_steps):
        Xc, Wc, r = step(Xc, Wc, u0, PV0, Qg0, QC0, h0, rt0)
        r_max = ca.fmax(r_max, r)
    multi = ca.Function(name, [xcv, w0, u0, p0, h0, rt0], [ca.reshape(Xc, 2 * n, 1), Wc, r_max],
                        ["xc", "w", "u", "p", "h", "rtol"], ["xc1", "w1", "r"])
    return {"step": step, "multi": multi, "vehicle_F": vehicle_F, "channel_F": chan_F, "channel_J": chan_J}
