"""Real-time iteration (RTI) of the path-tracking MPC: one Gauss-Newton SQP iteration per sample.

The problem is the NLP of :class:`symtrack.control.mpc.PathTrackingMPC`, unchanged: the same
stage-ordered variables w = [x_k, u_k, K_k] (K_k the Radau collocation states and algebraic
accelerations of stage k), the same collocation equations, bounds and cost. Each sample takes one
SQP step on it from the shifted previous solution, with

- the **Gauss-Newton Hessian** of the cost written as least squares (``PathTrackingMPC.res_fn``:
  the residuals are affine in the states for a given reference, so GN is the exact Hessian of the
  cost; only the curvature of the collocation equations is dropped);
- the collocation variables **eliminated stage by stage** from the linearised collocation
  equations (dK = -G_K^-1 (G + G_x dx + G_u du); G_K is the Newton matrix of one implicit Radau
  step, invertible for any step small against the model's time constants). Because the cost does
  not depend on K, this gives exactly the step of the full QP in (x, u, K). What remains is a
  multiple-shooting QP in (dx_k, du_k) with dx_{k+1} = A_k dx_k + B_k du_k + c_k, which is then
  condensed (dx_0 is the measured state minus the guess: the initial-value embedding) to a dense
  QP in the 2 N torque steps with the torque bounds and the torque-rate constraints, solved with
  one of CasADi's conic solvers (``rti_qp_solver``, default ``qrqp``; measured in docs/control.md).

Preparation / feedback split. After the command of a sample has been returned, the guess is
shifted by one stage and the dynamics are linearised and condensed there (:meth:`RTI.prepare_next`,
the "preparation" phase, which needs no measurement). When the next measurement and reference
arrive, the feedback phase (:meth:`RTI.feedback`) only evaluates the cost residuals against the
new reference, forms the dense QP, solves it and expands the step. ``solve_time_s`` of the
returned :class:`~symtrack.control.mpc.SolveInfo` is the feedback time (the latency from the
measurement to the command); ``preparation_time_s`` is the rest of the sample's computation.

Why Gauss-Newton "hit the iteration limit" before (measured with :func:`gn_solve`; details in
docs/control.md): not the scaling, the algebraic variables or a missing regularisation. The
linearisation is right (A, B against finite differences of the converged collocation step: 8e-8),
Newton on the collocation equations alone converges quadratically, and a Levenberg-Marquardt term
(1e-3 ... 1 on the torque steps) does not stop the divergence. The cause is the curvature that GN
drops: the lateral resistance is a sum over 12 Gauss points of tanh((v_y + r x_i) / eps_v) with
eps_v = 9 mm/s, a staircase in (v_y, r) as soon as the vehicle yaws, so after a step the
first-order model of the dynamics is far off and the steps grow (GN from the IPOPT optimum of the
1 m offset: step norms x4-20 per iteration; with eps_v = 0.3 m/s in the prediction it contracts
by 0.2 from a cold guess). How hard the plan yaws decides it: with the pseudo-Huber lateral penalty
(0.2 m) and a x5 terminal lateral weight the same GN contracts by about 2e-3 per iteration there.
Hence: the step halving on the collocation residual (``max_defect``), the NLP fallback beyond it,
and :data:`symtrack.control.bench.RTI_CONFIG`.
"""

from __future__ import annotations

import logging

import casadi as ca
import numpy as np

from .solver_cache import compiled_function

log = logging.getLogger("symtrack.control.rti")

# CasADi conic solvers measured on the condensed (dense) QP. hpipm is not among them: it needs
# the stage structure (N, nx, nu, ng) of an uncondensed QP and rejects the dense one ("HPIPM:
# specified structure of A does not correspond to what the interface can handle").
QP_SOLVERS = ("qrqp", "osqp", "daqp", "piqp")
# the return status of every successful solve, for a solver whose CasADi interface has one
# (DAQP: success is exit flag 1, EXIT_OPTIMAL, only; the others report several)
QP_SUCCESS_STATUS = {"daqp": "1"}


def _qp_options(name: str) -> dict:
    base = {"error_on_fail": False, "print_time": False}
    if name == "qrqp":
        base.update({"print_iter": False, "print_header": False, "print_info": False, "max_iter": 200})
    elif name == "osqp":
        base["osqp"] = {"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8, "max_iter": 20000, "polish": False}
    elif name == "piqp":
        base["piqp"] = {"verbose": False}
    return base


class _Buffered:
    """A CasADi Function with dense outputs called through its zero-copy buffer interface
    (``Function.buffer``, as :class:`symtrack.integrators.fixed_step.Chunk`): the arguments are
    C-ordered numpy arrays (a matrix argument n x m given as its transpose, m x n, whose rows
    are the matrix's columns) and the outputs are numpy arrays allocated once, each the transpose
    of the output matrix (size2 x size1), overwritten by the next call. Converting the sparse DM
    results of the collocation Jacobians cost about 1 ms of the 1.9 ms preparation (measured,
    clay U-turn, jit)."""

    def __init__(self, f: ca.Function):
        self.f = f
        self.out = [np.zeros((f.size2_out(i), f.size1_out(i))) for i in range(f.n_out())]
        self.nnz_in = [f.nnz_in(i) for i in range(f.n_in())]
        self.buf, self._eval = f.buffer()
        for i, a in enumerate(self.out):
            self.buf.set_res(i, memoryview(a))

    def __getattr__(self, name):  # class_name(), name(), ... of the Function
        return getattr(self.f, name)

    def __call__(self, *args):
        keep = []
        for i, a in enumerate(args):
            a = np.ascontiguousarray(a, dtype=float)
            if a.size != self.nnz_in[i]:
                raise RuntimeError(f"{self.f.name()}: argument {i} has {a.size} values, expected {self.nnz_in[i]}")
            if a.size == 0:
                a = np.zeros(1)  # a valid buffer for an empty argument (nothing is read)
            keep.append(a)
            self.buf.set_arg(i, memoryview(a))
        self._eval()
        if self.buf.ret() != 0:
            raise RuntimeError(f"{self.f.name()} failed (status {self.buf.ret()})")
        return self.out


class RTI:
    """The real-time iteration of one :class:`PathTrackingMPC` (``mpc``): its dimensions,
    Functions and bounds. ``compiled`` compiles the mapped linearisation and residual Functions
    (cached across processes by :mod:`symtrack.control.solver_cache`)."""

    def __init__(self, mpc, qp_solver: str = "qrqp", compiled: bool = False, regularisation: float = 1e-8,
                 max_defect: float = 0.1, halvings: int = 3, cache=None, relinearisations: int = 1):
        self.m = mpc
        self.max_defect, self.halvings, self.relinearisations = max_defect, halvings, relinearisations
        self.last_alpha, self.last_defect = 1.0, 0.0
        self._xc = np.zeros(0)
        N = mpc.N
        self.N, self.nxa, self.nu, self.nk, self.nxp = N, mpc.nxa, mpc.nu, mpc.nk, mpc.nxp
        self.reg = regularisation
        fns = {"mpc_rti_coll": mpc.coll_fn.map(N), "mpc_rti_res": mpc.res_fn.map(N),
               "mpc_rti_res_term": mpc.res_term_fn, "mpc_rti_coll_res": mpc.coll_res_fn}
        calls = []
        for name, f in fns.items():
            # dense outputs, so that the buffer interface fills whole numpy arrays (_Buffered), and the
            # model's parameters and the frozen cells as one column (the buffer does not broadcast)
            ins, args = [], []
            for i in range(f.n_in()):
                one = f.name_in(i) in ("p", "xc")
                sym = ca.MX.sym(f.name_in(i), f.size1_in(i), 1 if one else f.size2_in(i))
                ins.append(sym)
                args.append(ca.repmat(sym, 1, f.size2_in(i)) if one else sym)
            f = ca.Function(name, ins, [ca.densify(o) for o in f.call(args)], f.name_in(), f.name_out())
            if compiled:
                f = compiled_function(f, root=cache)
            calls.append(_Buffered(f))
        self.coll, self.res, self.resN, self.collg = calls
        # the collocation residual of a whole w (RTI.defect): its last stage's, then the others'
        # unless the last one's exceeds a bound (a rejected step is nearly always rejected by its
        # last stage, the turn entering the horizon: RTI._defect_upto). One Function (the stage
        # Function mapped by CasADi's interpreted MX, the stage blocks cut out of w inside) whose
        # arguments are arrays bound once (w copied in, the parameters and cells bound by
        # prepare_at): each call of CasADi's Python interface cost 10-15 us in the closed loop
        # (cold caches between samples, measured)
        nxa, nu, blk = self.nxa, self.nu, self.nxa + self.nu + self.nk
        stage = self.collg.f
        ws = ca.MX.sym("w", N * blk + nxa)
        ps, xcs = ca.MX.sym("p", stage.size1_in(3)), ca.MX.sym("xc", stage.size1_in(4))
        W = ca.reshape(ws[:N * blk], blk, N)
        tail = stage(W[:nxa, N - 1], W[nxa:nxa + nu, N - 1], W[nxa + nu:, N - 1], ps, xcs)
        bound = ca.MX.sym("bound")
        cut = ca.mmax(ca.fabs(tail)) > bound
        others = stage.map(N - 1)(W[:nxa, :N - 1], W[nxa:nxa + nu, :N - 1], W[nxa + nu:, :N - 1], ps, xcs)
        head = ca.if_else(cut, ca.DM.zeros(self.nk, N - 1), others, True)
        fn = ca.Function("mpc_rti_coll_res_w", [ws, ps, xcs, bound], [tail, head, cut], ["w", "p", "xc", "bound"],
                         ["g_last", "g_others", "cut"])
        self._w_in, self._bound_in = np.zeros(N * blk + nxa), np.zeros(1)
        self._g_out = [np.zeros(self.nk), np.zeros((N - 1, self.nk)), np.zeros(1)]
        self._coll_fn = fn
        self._coll_buf, self._coll_call = fn.buffer()
        self._coll_buf.set_arg(0, memoryview(self._w_in))
        self._coll_buf.set_arg(3, memoryview(self._bound_in))
        for i, a in enumerate(self._g_out):
            self._coll_buf.set_res(i, memoryview(a))
        self._bound_p = None  # (p, xc) bound to the defect Functions
        self.nr = mpc.res_fn.size1_out(0)
        self.nrN = mpc.res_term_fn.size1_out(0)
        nz = self.nu * N
        # the dense QP: H (2N x 2N) and the rate rows A (2N x 2N, dense after condensing)
        self.qp_name = qp_solver
        # A solver whose interface reports success for one return status only (CasADi's DAQP: exit
        # flag 1, EXIT_OPTIMAL) raises on failure instead (error_on_fail), so that a successful
        # solve needs no stats(): that call took 25-50 us in the closed loop, the solve 30-60 us
        self._qp_success_status = QP_SUCCESS_STATUS.get(qp_solver)
        opts = _qp_options(qp_solver)
        if self._qp_success_status is not None:
            opts["error_on_fail"] = True
        self.qp = ca.conic("mpc_rti_qp", qp_solver, {"h": ca.Sparsity.dense(nz, nz), "a": ca.Sparsity.dense(nz, nz)},
                           opts)
        # ... called through its buffer interface on arrays allocated here (each dense matrix as its
        # column-major values): converting the numpy arguments to DM took 0.4-0.5 ms of a feedback
        # whose QP solve takes 0.03-0.1 ms (measured, headland_uturn, DAQP)
        self._qp_in = {n: np.zeros(max(1, self.qp.nnz_in(i))) for i, n in enumerate(self.qp.name_in())}
        self._qp_out = [np.zeros(max(1, self.qp.nnz_out(i))) for i in range(self.qp.n_out())]
        self._qp_buf, self._qp_eval = self.qp.buffer()
        self._qp_arg = {n: i for i, n in enumerate(self.qp.name_in())}
        for i, n in enumerate(self.qp.name_in()):
            self._qp_buf.set_arg(i, memoryview(self._qp_in[n]))
        for i, a in enumerate(self._qp_out):
            self._qp_buf.set_res(i, memoryview(a))
        # the feedback's dense algebra on preallocated arrays: the residual rows of the condensed
        # least squares (stage k's nr rows, then the terminal rows) and the constant regularisation
        self._Mall = np.zeros((N * self.nr + self.nrN, nz))
        self._reg2 = 2.0 * self.reg * np.eye(nz)
        # ... of which the stages' rx_k Gam_k (without the stage's own ru_k du_k), a Function writing
        # them into those rows: only the structural nonzeros of rx_k and the first k nu columns of
        # Gam_k (the steps of the stages before k) enter, and each product accumulates over the
        # states in order as numpy's einsum did, so the values are the same to the bit (the terms
        # left out are zeros, which add nothing to sums that start at +0, while Gam is finite:
        # prepare_at checks; the einsum took 0.2 ms of the feedback)
        nr, nxa, nu = self.nr, self.nxa, self.nu
        rx, gam = ca.MX.sym("rx", nr, N * nxa), ca.MX.sym("gam_t", nxa, N * nz)
        rx_sp = mpc.res_fn.sparsity_out(1)
        blocks = [ca.MX(nz, nr)]
        for k in range(1, N):
            mk = ca.mtimes(ca.project(rx[:, k * nxa:(k + 1) * nxa], rx_sp), gam[:, k * nz:k * nz + k * nu])
            blocks.append(ca.horzcat(mk, ca.MX(nr, nz - k * nu)).T)
        rows = ca.Function("mpc_rti_rows", [rx, gam], [ca.densify(ca.horzcat(*blocks))], ["rx", "gam_t"], ["rows_t"])
        if compiled:
            rows = compiled_function(rows, flags=("-O3",), root=cache)
        # ... evaluated with the cost residuals against the reference in one call: the residuals r,
        # their Jacobians rx, ru, the terminal ones and the rows, into arrays allocated here (each the
        # transpose of the output matrix, as _Buffered's), its arguments bound by prepare_at (the
        # guess's X, U and GamT) and here (the reference, copied in by the feedback)
        Xs, Us = ca.MX.sym("X", nxa, N + 1), ca.MX.sym("U", nu, N)
        refs = ca.MX.sym("ref", self.res.f.size1_in(2), N + 1)
        gs = ca.MX.sym("gam_t", nxa, N * nz)
        r, r_x, r_u = self.res.f(Xs[:, :N], Us, refs[:, :N])
        rN, rN_x = self.resN.f(Xs[:, N], refs[:, N])
        fn = ca.Function("mpc_rti_residual_rows", [Xs, Us, refs, gs], [r, r_x, r_u, rN, rN_x, rows(r_x, gs)],
                         ["X", "U", "ref", "gam_t"], ["r", "r_x", "r_u", "rN", "rN_x", "rows_t"])
        self._ref_in = np.zeros((N + 1, refs.size1()))
        self._res_out = [np.zeros((fn.size2_out(i), fn.size1_out(i))) for i in range(5)] + [self._Mall[:N * nr]]
        self._res_buf, self._res_call = fn.buffer()
        self._res_fn = fn
        self._res_buf.set_arg(2, memoryview(self._ref_in))
        for i, a in enumerate(self._res_out):
            self._res_buf.set_res(i, memoryview(a))
        # the flat indices in _Mall of the stages' own ru_k (stage k's rows, du_k's columns), in the
        # order of the residual Function's output (N nu x nr: [k, a, i] -> row k nr + i, column k nu + a)
        k, a, i = np.meshgrid(np.arange(N), np.arange(nu), np.arange(nr), indexing="ij")
        self._ru_at = ((k * nr + i) * nz + k * nu + a).ravel()
        self.lin = None  # the prepared linearisation (dict), or None

    # ------------------------------------------------------------------ preparation
    def prepare_at(self, w: np.ndarray, p_model: np.ndarray, x_cells: np.ndarray) -> None:
        """Linearise the collocation at the guess w and condense the dynamics (no measurement)."""
        N, nxa, nu, nk, nxp = self.N, self.nxa, self.nu, self.nk, self.nxp
        blk = nxa + nu + nk
        W = w[:N * blk].reshape(N, blk)
        Xk, Uk, Kk = W[:, :nxa], W[:, nxa:nxa + nu], W[:, nxa + nu:]
        xc = np.asarray(x_cells, float)
        self._xc = xc
        # (_Buffered returns each output transposed: the N x nk stage values, the mapped Jacobians'
        # nk x (N n) blocks as N n x nk)
        g, gk, gx, gu = self.coll(Xk, Uk, Kk, p_model, xc)
        gk = gk.reshape(N, nk, nk).transpose(0, 2, 1)
        gx = gx.reshape(N, nxa, nk).transpose(0, 2, 1)
        gu = gu.reshape(N, nu, nk).transpose(0, 2, 1)
        rhs = np.concatenate([g[:, :, None], gx, gu], axis=2)  # N x nk x (1 + nxa + nu)
        Msol = np.linalg.solve(gk, rhs)  # dK = -(M0 + Mx dx + Mu du)
        # x_{k+1} = [states of the last collocation point; u_k]
        last = slice(nk - self.m.nc, nk - self.m.nc + nxp)
        A = np.zeros((N, nxa, nxa))
        B = np.zeros((N, nxa, nu))
        c = np.zeros((N, nxa))
        A[:, :nxp, :] = -Msol[:, last, 1:1 + nxa]
        B[:, :nxp, :] = -Msol[:, last, 1 + nxa:]
        B[:, nxp:, :] = np.eye(nu)
        xnext_guess = np.vstack([W[1:, :nxa], w[N * blk:][None, :]])
        c[:, :nxp] = Kk[:, last] - Msol[:, last, 0] - xnext_guess[:, :nxp]
        c[:, nxp:] = Uk - xnext_guess[:, nxp:]
        # condensing: dx_k = Phi_k dx0 + Gam_k dU + xi_k
        nzu = nu * N
        Phi = np.zeros((N + 1, nxa, nxa))
        Gam = np.zeros((N + 1, nxa, nzu))
        xi = np.zeros((N + 1, nxa))
        Phi[0] = np.eye(nxa)
        for k in range(N):
            Phi[k + 1] = A[k] @ Phi[k]
            Gam[k + 1] = A[k] @ Gam[k]
            Gam[k + 1][:, k * nu:(k + 1) * nu] += B[k]
            xi[k + 1] = A[k] @ xi[k] + c[k]
        X = np.vstack([Xk, w[N * blk:]])
        U = Uk.copy()
        # what the feedback needs that does not depend on the measurement or the reference: the
        # rate rows (u_k - prev_k, prev_k = state entries nxp: of x_k, in the steps dU) as their
        # column-major values (the QP's buffer), the guess's own rates and torque bounds, the
        # stages' Gam_k, each as its column-major values (the rows of mpc_rti_residual_rows)
        Arate = -Gam[:N, nxp:, :].reshape(N * nu, nzu) + np.eye(nzu)
        tmax = self.m.tmax_scaled
        ug = U.ravel()
        L = {"w": w.copy(), "M": Msol, "Phi": Phi, "Gam": Gam, "xi": xi, "X": X, "U": U,
             "AT": np.ascontiguousarray(Arate.T), "rate_guess": (U - X[:N, nxp:]).ravel(),
             "lbx": -tmax - ug, "ubx": tmax - ug, "GamT": np.ascontiguousarray(Gam[:N].transpose(0, 2, 1)),
             "finite": bool(np.isfinite(Gam).all())}
        # bound to the feedback's Functions (kept alive by self._bound while bound)
        for i, a in enumerate((X, U)):
            self._res_buf.set_arg(i, memoryview(a))
        self._res_buf.set_arg(3, memoryview(L["GamT"]))
        for n in ("lbx", "ubx"):
            self._qp_buf.set_arg(self._qp_arg[n], memoryview(L[n]))
        self._qp_buf.set_arg(self._qp_arg["a"], memoryview(L["AT"]))
        self._bound = L
        self._bind_p(p_model, xc)
        self.lin = L

    def _bind_p(self, p_model, xc) -> None:
        """Bind the model's parameters and the frozen cells to the defect Functions (copies)."""
        p = np.array(p_model, dtype=float).ravel()
        c = np.array(xc, dtype=float).ravel()
        self._bound_p = (p, c if c.size else np.zeros(1), p_model, xc)
        self._coll_buf.set_arg(1, memoryview(self._bound_p[0]))
        self._coll_buf.set_arg(2, memoryview(self._bound_p[1]))

    # ------------------------------------------------------------------ feedback
    def feedback(self, x0s: np.ndarray, ref: np.ndarray, relinearisations: int | None = None):
        """The QP step from the prepared linearisation for the measured (scaled) x0 and the
        reference: returns (new w, ok, status). A step rejected after the halvings is followed by
        up to ``relinearisations`` (default: the RTI's) Gauss-Newton iterations, each linearised
        at the shortest step of the one before (see the safeguard below)."""
        if relinearisations is None:
            relinearisations = self.relinearisations
        L = self.lin
        N, nxa, nxp, nr = self.N, self.nxa, self.nxp, self.nr
        X, Phi, Gam, xi = L["X"], L["Phi"], L["Gam"], L["xi"]
        dx0 = x0s - X[0]
        ref = np.asarray(ref, float)  # (N+1) x 5
        # the residuals, their Jacobians and the stages' rx_k Gam_k rows (into _Mall) in one call
        self._ref_in[...] = ref
        self._res_call()
        if self._res_buf.ret() != 0:
            raise RuntimeError(f"mpc_rti_residual_rows failed (status {self._res_buf.ret()})")
        r, rx, ru, rN, rxN, _ = self._res_out  # r: N x nr
        rx = rx.reshape(N, nxa, nr).transpose(0, 2, 1)
        if not L["finite"]:  # (a linearisation gone non-finite: the products in full, NaN where they give it)
            self._Mall[:N * nr] = np.einsum("kij,kjl->kil", rx, Gam[:N]).reshape(N * nr, -1)
        rN = rN.ravel()
        rxN = rxN.T
        dxa = np.einsum("kij,j->ki", Phi, dx0) + xi  # (N+1) x nxa: the state steps without dU
        # residual rows: r_k + rx_k dx_k + ru_k du_k, dx_k = dxa_k + Gam_k dU; to the stages' rx_k
        # Gam_k each stage's own du_k
        Mall = self._Mall
        Mall.reshape(-1)[self._ru_at] += ru.reshape(-1)  # ru: N nu x nr, as _ru_at
        vk = r + np.einsum("kij,kj->ki", rx, dxa[:N])
        np.matmul(rxN, Gam[N], out=Mall[N * nr:])
        vN = rN + rxN @ dxa[N]
        vall = np.concatenate([vk.ravel(), vN])
        H = 2.0 * (Mall.T @ Mall) + self._reg2
        # the QP (column-major values into the buffer's arrays)
        q = self._qp_in
        q["h"].reshape(H.shape)[:] = H.T
        q["g"][:] = 2.0 * (Mall.T @ vall)
        rate_now = L["rate_guess"] - dxa[:N, nxp:].ravel()
        rate = self.m.rate_scaled
        q["lba"][:] = -rate - rate_now
        q["uba"][:] = rate - rate_now
        try:
            self._qp_eval()
        except RuntimeError as err:  # (error_on_fail: the failed solve's return status from its stats)
            if self._qp_success_status is None or "conic process failed" not in str(err):
                raise
            return None, False, str(self._qp_buf.stats().get("return_status", False))
        if self._qp_buf.ret() != 0:
            raise RuntimeError(f"mpc_rti_qp failed (status {self._qp_buf.ret()})")
        if self._qp_success_status is None:
            st = self._qp_buf.stats()
            success, status = bool(st.get("success", False)), str(st.get("return_status", st.get("success")))
        else:
            success, status = True, self._qp_success_status
        dU = self._qp_out[0].copy()
        ok = success and bool(np.isfinite(dU).all())
        if not ok:
            return None, False, status
        # Safeguard: the collocation residual at the new point (the linearisation's error). A
        # step whose residual exceeds max_defect is halved (at most ``halvings`` times): the
        # Gauss-Newton step overshoots where the lateral resistance changes regime
        # (docs/control.md). Only the QP's torque step is scaled; the response to the measured
        # state (dx0) and the closing of the guess's gaps are always applied in full, so that a
        # short step stays consistent with the measurement.
        GdU = np.einsum("kij,j->ki", Gam, dU)
        Msol = L["M"]
        alpha = 1.0
        for _ in range(self.halvings + 1):
            full = alpha == 1.0  # (1.0 x is x)
            w = self._point(L, x0s, dxa, GdU if full else alpha * GdU, dU if full else alpha * dU, Msol)
            if not np.isfinite(w).all():
                return None, False, "non-finite step"
            # (a step that is not the shortest only needs to be known to exceed the bound)
            defect = self._defect_upto(w, None if alpha <= 0.5 ** self.halvings else self.max_defect)
            if defect <= self.max_defect:
                break
            if alpha <= 0.5 ** self.halvings:
                break
            alpha *= 0.5
        if defect > self.max_defect:
            # the shortest step still leaves a large residual: accept it when that residual is
            # the measurement's (the response to dx0 alone, alpha = 0, is as far off: model
            # mismatch at a turn entry), else the QP step is not trusted (fallback)
            base = self._point(L, x0s, dxa, 0.0 * GdU, 0.0 * dU, Msol)
            defect0 = self.defect(base)
            # ... but never a large residual: accepted steps with large residuals let the
            # iteration drift off the dynamics (measured on field_pattern before this bound)
            if defect > 2.0 * defect0 + self.max_defect or defect0 > 10.0 * self.max_defect:
                why = (f"{status}; defect {defect:.2g} > {self.max_defect:g} after {self.halvings} halvings "
                       f"(measurement alone: {defect0:.2g})")
                if relinearisations <= 0:
                    return None, False, why
                # Rejected: the linearisation does not describe the dynamics over the step. Where
                # this happens (the lagged shear law at exactly symmetric straight running, the
                # turn's curvature entering the horizon: docs/control.md) the defect grows
                # linearly with the step length (measured 0.92 alpha): the guess sits at the apex
                # of the law's cone (slips inside sliding_smoothing), where the Jacobian is not
                # the slope of the forces over the step. One more Gauss-Newton iteration,
                # linearised at the shortest step (off the apex; x0 already the measurement),
                # takes the step instead of the NLP fallback.
                self.prepare_at(w, self.m.p_model, self._xc)
                w2, ok2, st2 = self.feedback(x0s, ref, relinearisations - 1)
                return w2, ok2, f"{why}; re-linearised at step {alpha:g}: {st2}"
        self.last_alpha, self.last_defect = alpha, defect
        return w, True, status if alpha == 1.0 else f"{status}; step {alpha:g}"

    def _point(self, L, x0s, dxa, GdU, dU, Msol):
        """The guess plus a step: state steps dxa + GdU, torque steps dU, collocation steps from
        the eliminated linearised collocation equations."""
        N, nxa, nu, nk = self.N, self.nxa, self.nu, self.nk
        blk = nxa + nu + nk
        dX = dxa + GdU
        dUk = dU.reshape(N, nu)
        minus_dK = (Msol[:, :, 0] + np.einsum("kij,kj->ki", Msol[:, :, 1:1 + nxa], dX[:N])
                    + np.einsum("kij,kj->ki", Msol[:, :, 1 + nxa:], dUk))
        w = L["w"].copy()
        Wv = w[:N * blk].reshape(N, blk)
        Wv[:, :nxa] += dX[:N]
        Wv[:, nxa:nxa + nu] += dUk
        Wv[:, nxa + nu:] -= minus_dK  # (a - b is a + (-b))
        w[N * blk:] += dX[N]
        w[:nxa] = x0s  # dX[0] = dx0: no round-off in the fixed initial state
        return w

    def defect(self, w: np.ndarray) -> float:
        """Largest collocation residual (scaled rows) of w: how far it is from the dynamics."""
        if self._bound_p is None or self._bound_p[2] is not self.m.p_model or self._bound_p[3] is not self._xc:
            self._bind_p(self.m.p_model, self._xc)
        return self._defect_upto(w, None)

    def _defect_upto(self, w: np.ndarray, bound: float | None) -> float:
        """The largest collocation residual of w; with a ``bound``, the last stage's alone when
        that one exceeds it (then so does w's: enough to reject w). The model's parameters and
        cells are those bound by prepare_at (the MPC's p_model and the prepared cells)."""
        self._w_in[:] = w
        self._bound_in[0] = np.inf if bound is None else bound
        self._coll_call()
        if self._coll_buf.ret() != 0:
            raise RuntimeError(f"mpc_rti_coll_res_w failed (status {self._coll_buf.ret()})")
        g_last, g_others, cut = self._g_out
        last = float(np.max(np.abs(g_last)))
        if cut[0]:  # (some residual of the last stage above the bound: the others were not evaluated)
            return last
        return float(np.max((last, np.max(np.abs(g_others)))))  # (NaN as np.max of all would give it)


def shift_guess(mpc, w: np.ndarray) -> np.ndarray:
    """The guess of the next sample: every stage moved one ahead; the new last stage starts at
    the old end state and is the old last stage translated by its own state change (so that the
    tail is nearly consistent with the dynamics in steady motion, instead of a repeated stage
    whose gap is a whole sample's travel)."""
    N, blk, nxa, nu, nxp, nc, d = mpc.N, mpc.block, mpc.nxa, mpc.nu, mpc.nxp, mpc.nc, mpc.d
    out = w.copy()
    out[:(N - 1) * blk] = w[blk:N * blk]
    last = w[(N - 1) * blk:N * blk]
    xN = w[N * blk:]
    delta = xN - last[:nxa]
    o = (N - 1) * blk
    out[o:o + nxa] = xN
    out[o + nxa:o + nxa + nu] = last[nxa:nxa + nu]
    for j in range(d):
        a = o + nxa + nu + j * nc
        out[a:a + nxp] = last[nxa + nu + j * nc:nxa + nu + j * nc + nxp] + delta[mpc.pred]
    out[N * blk:N * blk + nxp] = xN[mpc.pred] + delta[mpc.pred]
    out[N * blk + nxp:] = last[nxa:nxa + nu]
    return out


def gn_solve(mpc, x0s, x_cells, ref, w0, max_iter: int = 60, tol: float = 1e-8, steps: list | None = None):
    """The Gauss-Newton SQP with full steps on one fixed problem (repeated RTI steps without a
    shift: a stationary reference). Stops when the step norm (scaled variables) is below tol.
    Returns (w, converged, iterations, status); ``steps`` (a list) receives the step norms, whose
    ratios are the measured linear contraction factor of GN on this NLP."""
    rti = mpc.rti
    w = np.asarray(w0, float).copy()
    w[:mpc.nxa] = x0s
    for it in range(1, max_iter + 1):
        try:
            rti.prepare_at(w, mpc.p_model, x_cells)
            wn, ok, status = rti.feedback(x0s, ref, relinearisations=0)
        except (RuntimeError, np.linalg.LinAlgError) as err:
            return w, False, it, f"gauss-newton: exception {err}"
        if not ok:
            return w, False, it, f"gauss-newton: QP failed at iteration {it}: {status}"
        step = float(np.linalg.norm(wn - w))
        if steps is not None:
            steps.append(step)
        w = wn
        if step < tol:
            return w, True, it, f"gauss-newton converged in {it} iterations"
    return w, False, max_iter, f"gauss-newton: step {step:.2e} after {max_iter} iterations"
