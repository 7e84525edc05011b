"""A Rosenbrock step for a semi-explicit index-1 DAE, unrolled into one CasADi SX expression.

The method is the one of CasADi's ``rosenbrock`` integrator plugin (CasADi 3.8): 8 stages,
order 5, L-stable and stiffly accurate; its tableau is copied below from the C code that
CasADi 3.8.2 generates for that plugin (``gamma``, ``a``, ``c``, ``m``). For the DAE
x' = f(x, z), 0 = g(x, z) with y = (x, z) and the mass matrix M = diag(I, 0):

    W = M / (h gamma) - J,  J = d(f, g)/d(x, z) at the step's start (one factorisation per step)
    W U_i = F(y0 + sum_j a_ij U_j) + M sum_j (c_ij / h) U_j,  F = (f, g)
    y1 = y0 + sum_i m_i U_i

(written here with the time-scaled F = (h f, g) and unit step, exactly as the plugin does). Unlike
the plugin, the step does not first re-solve g(x0, z0) = 0 for z0 by Newton iterations: the
incoming z0 is the previous step's z1 (consistent to the method's accuracy).

Why unrolled: the plugin's generated C is a general-purpose state machine (error estimates,
tapes, events, a general sparse QR) and cost 8.7 us per step of the 20-state homogeneous model;
this step is plain straight-line code with a sparse LU without pivoting (as KPP does for
Rosenbrock methods: W = M/(h gamma) - J has a structurally non-zero diagonal), ordered so that
the rows with fewest couplings are eliminated first (the terrain cells before the vehicle:
no fill-in for the arrow-shaped coupled system).
"""

from __future__ import annotations

import casadi as ca

__all__ = ["A", "C", "FIXED_STEP_ATOL", "FIXED_STEP_MAX_HALVINGS", "GAMMA", "M", "N_STAGES", "SparseLU",
           "consistent_z_expressions", "plugin_step", "step_and_error_expressions", "step_expressions"]

N_STAGES = 8
# The error control of the compiled step (symtrack.native.generate.controlled_chunks, FixedStepper): the
# absolute part of a step's tolerance, in the SI unit of each differential state (m, rad, m/s, rad/s, N m;
# the terrain cells' sinkage in m and its rate in m/s): 1 um, below every figure the validation reports (as
# the terrain engine's VEHICLE_ATOL); and how many times a step is halved at most: to 1/256 of it, 39 us of the
# 10 ms step. Calibrated against CVODES on the physics fuzzer's seed 37, case 1708 (a ramp programme across an
# 8 deg side slope on the "shear" law): where a sprocket passes through standstill the shear law's field turns
# from the elements that entered at the rear to those that entered at the front within omega_smoothing_rad_s,
# and the model's thrust falls with omega there (dF/domega -4.5e5 N s, CVODES alike): a sprocket mode that
# grows at lambda up to 1e4-2e4 1/s while it crosses. The linearly implicit step follows it only where
# gamma h lambda is well below 1 (its stability function has its pole at gamma h lambda = 1): at 1/64 of the
# step (gamma h lambda 0.5-1) the sprocket spun up to 4700 m/s of tread in one step; at 1/256 the run keeps
# CVODES's states within 0.1 %. The halvings cost only where they are taken.
FIXED_STEP_ATOL = 1e-6
FIXED_STEP_MAX_HALVINGS = 8
GAMMA = 3.3233404432797148e-01
# a[i][j], c[i][j] (j < i) and m[i] of CasADi 3.8.2's rosenbrock plugin (generated C: p.a, pe.c, p.m)
A = (
    (),
    (3.0,),
    (2.2625164943195855e+00, 4.8957172492036455e-01),
    (1.8207298690090707e+00, 4.0238620105337081e-01, 2.2899906791553759e-01),
    (3.0949770951948423e+00, 2.3318620904471848e-01, 2.2882530454677346e+00, -3.0431549865184486e+00),
    (1.8075057891143271e+00, 2.0382295206887675e+00, 4.4375312323485314e+00, -1.8088576582430580e+01,
     -2.0138808247906564e+01),
    (1.8075057891143271e+00, 2.0382295206887675e+00, 4.4375312323485314e+00, -1.8088576582430580e+01,
     -2.0138808247906564e+01, 1.0),
    (1.8075057891143271e+00, 2.0382295206887675e+00, 4.4375312323485314e+00, -1.8088576582430580e+01,
     -2.0138808247906564e+01, 1.0, 1.0),
)
C = (
    (),
    (-9.0270619312157532e+00,),
    (-8.8560840994530796e+00, -1.7882276209139916e+00),
    (-9.0660549343524455e+00, -1.7859491524370121e+00, -1.6720322375886090e+00),
    (4.3063482984545489e+00, 2.1398710905230973e+00, -6.6811409408378060e+00, 2.0333495199209175e+01),
    (5.6716132795043608e+00, -6.0091983028643243e+00, 5.7821308594141052e-01, 3.9400706737727639e+01,
     6.7176510116084671e+01),
    (3.0943231619834628e+00, -1.0241950938386370e+01, -2.0311448845569808e+00, 5.3557473269782115e+01,
     1.0044521201470502e+02, -4.5946077266680447e+00),
    (1.1967285645452388e+00, -1.3360299428961955e+01, -3.9288791627929323e+00, 6.3946513156950708e+01,
     1.2493956307678002e+02, -5.7673811200668839e+00, -4.7365886307319425e+00),
)
M = (1.8075057891143271e+00, 2.0382295206887675e+00, 4.4375312323485314e+00, -1.8088576582430580e+01,
     -2.0138808247906564e+01, 1.0, 1.0, 1.0)


class SparseLU:
    """LU factors (no pivoting) of a square SX matrix with structurally non-zero diagonal, as SX
    expressions, eliminating in a fixed symmetric order (fewest couplings first)."""

    def __init__(self, W: ca.SX):
        n = W.size1()
        sp = W.sparsity()
        rows, cols = sp.get_triplet()
        entries = {(r, c): W.nz[k] for k, (r, c) in enumerate(zip(rows, cols, strict=True))}
        for i in range(n):
            if (i, i) not in entries:
                raise ValueError(f"W has a structurally zero diagonal entry at {i}: cannot factorise without pivoting")
        degree = [0] * n
        for r, c in entries:
            if r != c:
                degree[r] += 1
                degree[c] += 1
        self.order = sorted(range(n), key=lambda i: (degree[i], i))
        pos = {v: k for k, v in enumerate(self.order)}
        a = {}
        for (r, c), v in entries.items():
            if not (v.is_constant() and float(v) == 0.0):
                a[(pos[r], pos[c])] = v
        row_nz = [set() for _ in range(n)]  # columns > k present in row k (upper part)
        col_nz = [set() for _ in range(n)]  # rows > k present in column k (lower part)
        for (r, c) in a:
            if c > r:
                row_nz[r].add(c)
            elif r > c:
                col_nz[c].add(r)
        for k in range(n):
            piv = a[(k, k)]
            for i in sorted(col_nz[k]):
                lik = a[(i, k)] / piv
                a[(i, k)] = lik
                for j in sorted(row_nz[k]):
                    if (i, j) in a:
                        a[(i, j)] = a[(i, j)] - lik * a[(k, j)]
                    else:
                        a[(i, j)] = -lik * a[(k, j)]
                        if j > i:
                            row_nz[i].add(j)
                        elif i > j:
                            col_nz[j].add(i)
        self.n, self.a, self.row_nz, self.col_nz = n, a, row_nz, col_nz
        self.fill = len(a) - len(entries)

    def solve(self, b: ca.SX) -> ca.SX:
        n, a = self.n, self.a
        y = [b[i] for i in self.order]
        for k in range(n):  # L y = P b (unit lower)
            for i in self.col_nz[k]:
                y[i] = y[i] - a[(i, k)] * y[k]
        for k in reversed(range(n)):  # U x = y
            s = y[k]
            for j in self.row_nz[k]:
                s = s - a[(k, j)] * y[j]
            y[k] = s / a[(k, k)]
        x = [None] * n
        for k, i in enumerate(self.order):
            x[i] = y[k]
        return ca.vertcat(*x)


def step_expressions(dae: ca.Function, x0, z0, u, p, h):
    """(x1, z1) after one step of length h from (x0, z0): SX expressions.

    dae(x, z, u, p) -> (ode, alg) is an SX Function of the semi-explicit DAE."""
    x1, z1, _ = step_and_error_expressions(dae, x0, z0, u, p, h)
    return x1, z1


def step_and_error_expressions(dae: ca.Function, x0, z0, u, p, h, reverse: bool = False):
    """(x1, z1, e1): :func:`step_expressions` and the step's local error estimate e1 of the
    differential states, in their units. ``reverse``: the Jacobian J in CasADi's reverse mode (a model on
    an elevation raster, ``SystemModel.reverse_jacobians``), else in its default choice.

    The method is stiffly accurate with an embedded solution: its last stage's argument
    y0 + sum_{j<8} a_8j U_j (order 4) is the step's result without the last increment, since
    m_i = a_8i for i < 8 and m_8 = 1. So e1 = U_8 (its differential part) is the difference between
    the order-5 result and the embedded order-4 one (as in Hairer & Wanner's RODAS), computed with
    the step at no extra cost."""
    nx = x0.numel()

    def F(y):
        ode, alg = dae(y[:nx], y[nx:], u, p)
        return ca.vertcat(h * ode, alg)

    y0 = ca.vertcat(x0, z0)
    ny = y0.numel()
    J = ca.jacobian(F(y0), y0, {"allow_forward": False}) if reverse else ca.jacobian(F(y0), y0)
    mass = ca.DM.zeros(ny)
    mass[:nx] = 1.0
    W = ca.diag(mass / GAMMA) - J
    lu = SparseLU(W)
    U = []
    for i in range(N_STAGES):
        yi = y0
        for j, aij in enumerate(A[i]):
            if aij != 0.0:
                yi = yi + aij * U[j]
        rhs = F(yi)
        corr = 0
        for j, cij in enumerate(C[i]):
            if cij != 0.0:
                corr = corr + cij * U[j][:nx]
        if i > 0:
            rhs = rhs + ca.vertcat(corr, ca.SX.zeros(ny - nx))
        U.append(lu.solve(rhs))
    y1 = y0
    for mi, Ui in zip(M, U, strict=True):
        y1 = y1 + mi * Ui
    return y1[:nx], y1[nx:], U[-1][:nx]


def consistent_z_expressions(dae: ca.Function, x, z0, u, p, iterations: int = 2):
    """z with g(x, z) = 0 by Newton steps from z0 (the step itself starts from the z it is given:
    call this after anything that moved x, u or p away from the previous step's end)."""
    nz = z0.numel()
    xs, zs, us, ps = (ca.SX.sym(n, v.numel()) for n, v in (("x", x), ("z", z0), ("u", u), ("p", p)))
    g = dae(xs, zs, us, ps)[1]
    G = ca.Function("g_and_dg_dz", [xs, zs, us, ps], [g, ca.jacobian(g, zs)])
    z = z0
    for _ in range(iterations):
        gz, dg = G(x, z, u, p)
        z = z - SparseLU(dg).solve(gz) if nz else z
    return z


def plugin_step(model) -> ca.Function:
    """The same step through CasADi's own ``rosenbrock`` plugin (fixed step, time-scaled): the
    reference the unrolled step is tested against (it re-solves g(x0, z0) = 0 first)."""
    h = ca.SX.sym("step_s")
    dae = {"x": model.x, "z": model.z, "u": model.u, "p": ca.vertcat(model.p, h),
           "ode": h * model.ode_dae_expr, "alg": model.alg_expr}
    integ = ca.integrator("rosenbrock_plugin", "rosenbrock", dae, 0.0, 1.0, {"step_size": 1.0})
    X0, Z0 = ca.MX.sym("x0", model.x.sparsity()), ca.MX.sym("z0", model.z.sparsity())
    U, P, H = ca.MX.sym("u", model.u.sparsity()), ca.MX.sym("p", model.p.sparsity()), ca.MX.sym("h")
    r = integ(x0=X0, z0=Z0, u=U, p=ca.vertcat(P, H))
    return ca.Function("rosenbrock_plugin_step", [X0, Z0, U, P, H], [r["xf"], r["zf"]],
                       ["x0", "z0", "u", "p", "h"], ["xf", "zf"])
