"""``symtrack codegen mpc NAME --out DIR``: the real-time iteration of an MPC scenario as C.

The RTI of :mod:`symtrack.control.rti` is numpy code between CasADi calls. Here every numpy step
of it is written once more as a CasADi Function (MX graphs over the MPC's own SX Functions, no
model equation repeated) and generated with CasADi's code generator into ``DIR/mpc_rti.c``:

- ``mpc_rti_prepare(w, p, xc) -> (M, Phi, Gam, xi)``: the collocation Jacobians of every stage,
  the elimination dK = -G_K^-1 (G + G_x dx + G_u du) (a sparse QR, CasADi's ``qr`` linear solver)
  and the condensing recursion (``RTI.prepare_at``);
- ``mpc_rti_feedback(w, Phi, Gam, xi, x0s, ref) -> (dU, dxa, GdU)``: the residuals, the dense QP
  and its solution by **qrqp** (CasADi's active-set QP solver, which generates to plain C; the
  Python loop it is compared with runs qrqp too, :func:`load_scenario`); the Function returns a non-zero flag when
  the QP fails (``RTI.feedback`` up to the step);
- ``mpc_rti_point(w, M, x0s, dxa, GdU, dU, alpha) -> w`` and ``mpc_rti_defect(w, p, xc) -> d``: a
  step of length alpha and its largest collocation residual (the step halving of ``RTI.feedback``);
- ``mpc_rti_shift_guess(w)`` / ``mpc_rti_shift_plan(w)``: ``rti.shift_guess`` and the plain shift of
  a failed sample, as the (exact, 0/+-1) sparse linear maps they are;
- ``mpc_plant_accel(x, u, p) -> z``: the first algebraic state of the plant.

The plant is the compiled homogeneous Rosenbrock integrator that ``python -m codegen`` already
writes (``homogeneous_rosenbrock.c``: ``consistent_z`` and ``rosenbrock_controlled_chunk16``), driven as
``FixedStepper.step`` drives it in the Python closed loop (``run.integrator = "rosenbrock"``):
z re-solved when the command changes, each sample cut into equal steps of at most 10 ms, each step
halved where its error estimate exceeds the default ``run.fixed_step_tolerance`` (a step still above
it after the halvings is kept, where the Python loop stops).

``mpc_scenario.h`` carries the numbers: dimensions, scalings, the MPC's and the plant's parameter
vectors, the densely sampled reference path (the arrays of :class:`symtrack.control.path.Path`),
the initial state and command (trim), and the cold start: the solution of the first problem by
the fallback NLP solver (IPOPT), computed here in Python as the Python closed loop computes it
before its loop engages. ``mpc_closed_loop.c`` (copied from ``symtrack/codegen/mpc_main.c``) is the loop
of :func:`symtrack.control.closedloop.run` with the RTI of ``PathTrackingMPC`` (feedback, accept
or the shifted plan, preparation of the next sample) and writes ``closed_loop.csv``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from ..toolchain import require_compiler
from .standalone import c_array, c_literal

__all__ = ["CFLAGS", "CSV_COLUMNS", "MAIN_C", "MAKEFILE", "PLANT_STEM", "SOLVERS", "Problem", "build_program",
           "command", "compare", "load_scenario", "python_closed_loop", "read_csv", "render", "rti_functions",
           "run_program", "scenario_header", "setup", "write"]

log = logging.getLogger("symtrack.codegen.mpc")

MAIN_C = Path(__file__).resolve().parent / "mpc_main.c"
PLANT_STEM = "homogeneous_rosenbrock"
CSV_COLUMNS = ("t_s", "x_m", "y_m", "yaw_rad", "torque_cmd_left_N_m", "torque_cmd_right_N_m", "lateral_error_m",
               "solve_time_us")
CFLAGS = "-O2 -std=c99 -Wall -Wno-unused-variable -Wno-unused-but-set-variable -Wno-maybe-uninitialized"
SOLVERS = ("rti",)


# ---------------------------------------------------------------------------------------- Functions
def _linear_map(fn, n: int) -> ca.DM:
    """The matrix S with fn(w) = S w of a linear map of R^n (fn on numpy vectors)."""
    cols = []
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        cols.append(fn(e))
    return ca.DM(ca.sparsify(ca.DM(np.column_stack(cols))))


def rti_functions(mpc) -> list[ca.Function]:
    """The RTI of ``mpc`` (a PathTrackingMPC with solver "rti") as generatable Functions."""
    from symtrack.control.rti import shift_guess

    rti = mpc.rti
    if rti is None:
        raise ValueError("rti_functions needs a PathTrackingMPC with mpc.solver = 'rti'")
    N, nxa, nu, nk, nxp, nc = mpc.N, mpc.nxa, mpc.nu, mpc.nk, mpc.nxp, mpc.nc
    blk = mpc.block
    nw = N * blk + nxa
    nzu = nu * N
    npar, ncell = len(mpc.p_model), len(mpc.cell_names)
    ncol = 1 + nxa + nu

    # one stage: the eliminated collocation (M) and the stage's affine dynamics (A, B, c)
    xk, uk, kk, xn = (ca.MX.sym(n, m) for n, m in (("x", nxa), ("u", nu), ("k", nk), ("xnext", nxa)))
    P, XC = ca.MX.sym("p", npar), ca.MX.sym("xc", ncell)
    g, gk, gx, gu = mpc.coll_fn(xk, uk, kk, P, XC)
    Msol = ca.solve(gk, ca.horzcat(g, gx, gu), "qr")
    last = slice(nk - nc, nk - nc + nxp)
    A = ca.vertcat(-Msol[last, 1:1 + nxa], ca.MX(nu, nxa))
    B = ca.vertcat(-Msol[last, 1 + nxa:], ca.MX.eye(nu))
    c = ca.vertcat(kk[last] - Msol[last, 0] - xn[mpc.pred], uk - xn[nxp:])
    stage = ca.Function("mpc_rti_stage", [xk, uk, kk, xn, P, XC], [Msol, A, B, c])

    # preparation
    w = ca.MX.sym("w", nw)
    W = ca.reshape(w[:N * blk], blk, N)
    Xk, Uk, Kk = W[:nxa, :], W[nxa:nxa + nu, :], W[nxa + nu:, :]
    Xnext = ca.horzcat(W[:nxa, 1:], w[N * blk:])
    Ms, As, Bs, cs = stage.map(N)(Xk, Uk, Kk, Xnext, P, XC)
    Phi, Gam, xi = [ca.MX.eye(nxa)], [ca.MX(nxa, nzu)], [ca.MX(nxa, 1)]
    for k in range(N):
        Ak, Bk = As[:, k * nxa:(k + 1) * nxa], Bs[:, k * nu:(k + 1) * nu]
        Phi.append(ca.mtimes(Ak, Phi[k]))
        place = ca.horzcat(ca.MX(nxa, k * nu), Bk, ca.MX(nxa, nzu - (k + 1) * nu))
        Gam.append(ca.mtimes(Ak, Gam[k]) + place)
        xi.append(ca.mtimes(Ak, xi[k]) + cs[:, k])
    prepare = ca.Function("mpc_rti_prepare", [w, P, XC],
                          [Ms, ca.densify(ca.horzcat(*Phi)), ca.densify(ca.horzcat(*Gam)),
                           ca.densify(ca.horzcat(*xi))],
                          ["w", "p", "xc"], ["M", "Phi", "Gam", "xi"])

    # feedback: residuals, the dense QP (qrqp), the state steps
    PhiS = ca.MX.sym("Phi", nxa, nxa * (N + 1))
    GamS = ca.MX.sym("Gam", nxa, nzu * (N + 1))
    xiS = ca.MX.sym("xi", nxa, N + 1)
    x0s = ca.MX.sym("x0s", nxa)
    ref = ca.MX.sym("ref", 5, N + 1)  # column k: [x, y, yaw, speed, curvature] of stage k
    Xn = ca.horzcat(Xk, w[N * blk:])  # the horizon's nodes, one per column
    dx0 = x0s - Xn[:, 0]
    dxa = ca.horzcat(*[ca.mtimes(PhiS[:, k * nxa:(k + 1) * nxa], dx0) + xiS[:, k] for k in range(N + 1)])
    r, rx, ru = mpc.res_fn.map(N)(Xn[:, :N], Uk, ref[:, :N])
    rN, rxN = mpc.res_term_fn(Xn[:, N], ref[:, N])
    nr = mpc.res_fn.size1_out(0)
    rows, vals = [], []
    for k in range(N):
        Gk = GamS[:, k * nzu:(k + 1) * nzu]
        rxk, ruk = rx[:, k * nxa:(k + 1) * nxa], ru[:, k * nu:(k + 1) * nu]
        Mk = ca.mtimes(rxk, Gk) + ca.horzcat(ca.MX(nr, k * nu), ruk, ca.MX(nr, nzu - (k + 1) * nu))
        rows.append(Mk)
        vals.append(r[:, k] + ca.mtimes(rxk, dxa[:, k]))
    rows.append(ca.mtimes(rxN, GamS[:, N * nzu:]))
    vals.append(rN + ca.mtimes(rxN, dxa[:, N]))
    Mall, vall = ca.vertcat(*rows), ca.vertcat(*vals)
    H = ca.densify(2.0 * ca.mtimes(Mall.T, Mall) + 2.0 * rti.reg * ca.MX.eye(nzu))
    gvec = 2.0 * ca.mtimes(Mall.T, vall)
    Arate = ca.densify(-ca.vertcat(*[GamS[nxp:, k * nzu:(k + 1) * nzu] for k in range(N)]) + ca.MX.eye(nzu))
    rate_now = ca.vec(Uk - Xk[nxp:, :]) - ca.vec(dxa[nxp:, :N])
    rate, tmax = mpc.rate_scaled, mpc.tmax_scaled
    ug = ca.vec(Uk)
    sol = rti.qp(h=H, g=gvec, a=Arate, lba=-rate - rate_now, uba=rate - rate_now, lbx=-tmax - ug, ubx=tmax - ug)
    dU = sol["x"]
    GdU = ca.horzcat(*[ca.mtimes(GamS[:, k * nzu:(k + 1) * nzu], dU) for k in range(N + 1)])
    feedback = ca.Function("mpc_rti_feedback", [w, PhiS, GamS, xiS, x0s, ref], [dU, dxa, GdU],
                           ["w", "Phi", "Gam", "xi", "x0s", "ref"], ["dU", "dxa", "GdU"])

    # a step of length alpha (RTI._point) and its collocation residual (RTI.defect)
    MS = ca.MX.sym("M", nk, ncol * N)
    dxaS, GdUS = ca.MX.sym("dxa", nxa, N + 1), ca.MX.sym("GdU", nxa, N + 1)
    dUS, alpha = ca.MX.sym("dU", nzu), ca.MX.sym("alpha")
    dX = dxaS + alpha * GdUS
    dUk = ca.reshape(alpha * dUS, nu, N)
    dK = []
    for k in range(N):
        Mk = MS[:, k * ncol:(k + 1) * ncol]
        dK.append(-(Mk[:, 0] + ca.mtimes(Mk[:, 1:1 + nxa], dX[:, k]) + ca.mtimes(Mk[:, 1 + nxa:], dUk[:, k])))
    step = ca.vertcat(ca.vec(ca.vertcat(dX[:, :N], dUk, ca.horzcat(*dK))), dX[:, N])
    wn = w + step
    wn = ca.vertcat(x0s, wn[nxa:])  # dX[0] = dx0: no round-off in the fixed initial state
    point = ca.Function("mpc_rti_point", [w, MS, x0s, dxaS, GdUS, dUS, alpha], [wn],
                        ["w", "M", "x0s", "dxa", "GdU", "dU", "alpha"], ["w_new"])
    gcol = mpc.coll_res_fn.map(N)(Xk, Uk, Kk, P, XC)
    defect = ca.Function("mpc_rti_defect", [w, P, XC], [ca.mmax(ca.fabs(gcol))], ["w", "p", "xc"], ["defect"])

    # the shifts (linear maps of w)
    S1 = _linear_map(lambda v: shift_guess(mpc, v), nw)
    S2 = _linear_map(lambda v: mpc._shift(v, blk, True), nw)
    shift_g = ca.Function("mpc_rti_shift_guess", [w], [ca.mtimes(S1, w)], ["w"], ["w_shifted"])
    shift_p = ca.Function("mpc_rti_shift_plan", [w], [ca.mtimes(S2, w)], ["w"], ["w_shifted"])

    m = mpc.model
    xs, us, ps = ca.MX.sym("x", m.nx), ca.MX.sym("u", m.u.numel()), ca.MX.sym("p", m.p.numel())
    accel = ca.Function("mpc_plant_accel", [xs, us, ps], [m.accel(xs, us, ps)], ["x", "u", "p"], ["z"])
    return [prepare, feedback, point, defect, shift_g, shift_p, accel]


# ---------------------------------------------------------------------------------------- numbers
@dataclasses.dataclass
class Problem:
    """An MPC scenario set up for the C closed loop: the scenario, the model, the RTI controller
    after its cold start (``w_cold``), the initial plant state and command."""

    scenario: object
    model: object
    mpc: object
    x0: np.ndarray
    u0: np.ndarray
    w_cold: np.ndarray
    cold_status: str
    cold_time_s: float


def setup(sc) -> Problem:
    """Build the RTI of the scenario and solve its first problem as the Python closed loop does
    before its loop engages (:meth:`PathTrackingMPC.prepare`: the fallback NLP solver)."""
    from symtrack.control import closedloop
    from symtrack.control.mpc import PathTrackingMPC
    from symtrack.foundations.errors import SimulationError
    from symtrack.model import SystemModel

    model = SystemModel(sc.model)  # the scenario's [model] (its lateral law), as the Python closed loop
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    x0, u0 = closedloop.initial_state(model, sc)
    path = sc.build_path()
    names = model.state_names
    ix, iy, ipsi = (names.index(n) for n in ("x_m", "y_m", "yaw_rad"))
    s0 = path.project(x0[ix], x0[iy])
    ref0 = path.reference(s0, mpc.N, sc.mpc.sample_time_s, x0[ipsi])
    pidx = [names.index(n) for n in mpc.pred_names]
    cidx = [names.index(n) for n in mpc.cell_names]
    t0 = time.perf_counter()
    info = mpc.prepare(x0[pidx], x0[cidx] if cidx else None, u0, ref0)
    dt = time.perf_counter() - t0
    if not info.success:
        raise SimulationError(f"the cold start of {sc.name!r} failed ({info.status}): no first plan for the C loop")
    return Problem(sc, model, mpc, x0, u0, mpc._w.copy(), info.status, dt)


def scenario_header(pb: Problem) -> str:
    sc, model, mpc = pb.scenario, pb.model, pb.mpc
    from symtrack.integrators.settings import FIXED_STEP_TOLERANCE, IntegratorSettings
    from symtrack.native.generate import CHUNK_SIZES

    path = sc.build_path()
    names = model.state_names
    s = sc.mpc
    fixed_step = IntegratorSettings("rosenbrock").fixed_step_s
    max_samples = int(math.ceil(sc.run.duration_s / s.sample_time_s)) + 2
    lines = [
        f"/* mpc_scenario.h: the MPC scenario '{sc.name}' as C constants for mpc_closed_loop.c.",
        " * Written by symtrack codegen mpc; do not edit. */",
        "#ifndef MPC_SCENARIO_H",
        "#define MPC_SCENARIO_H",
        f'#define MPC_SCENARIO "{sc.name}"',
        f'#define MPC_CSV_HEADER "{",".join(CSV_COLUMNS)}"',
        f"#define MPC_N {mpc.N}",
        f"#define MPC_NXA {mpc.nxa}",
        f"#define MPC_NXP {mpc.nxp}",
        f"#define MPC_NU {mpc.nu}",
        f"#define MPC_NK {mpc.nk}",
        f"#define MPC_BLOCK {mpc.block}",
        f"#define MPC_NW {mpc.N * mpc.block + mpc.nxa}",
        f"#define MPC_NZU {mpc.nu * mpc.N}",
        f"#define MPC_NCOL {1 + mpc.nxa + mpc.nu}",
        f"#define MPC_NP {len(mpc.p_model)}",
        f"#define MPC_NCELL {len(mpc.cell_names)}",
        f"#define MPC_DT_S {c_literal(s.sample_time_s)}",
        f"#define MPC_DURATION_S {c_literal(sc.run.duration_s)}",
        f"#define MPC_MAX_SAMPLES {max_samples}",
        f"#define MPC_MAX_DEFECT {c_literal(s.rti_max_defect)}",
        f"#define MPC_HALVINGS {s.rti_step_halvings}",
        f"#define MPC_RELINEARISATIONS {s.rti_relinearisations}",
        f"#define MPC_TORQUE_SCALE_N_M {c_literal(1000.0)}",
        f"#define MPC_TWO_PI {c_literal(2 * math.pi)}",
        f"#define PLANT_NX {model.nx}",
        f"#define PLANT_NZ {model.z.numel()}",
        f"#define PLANT_NU {model.u.numel()}",
        f"#define PLANT_FIXED_STEP_S {c_literal(fixed_step)}",
        f"#define PLANT_CHUNK {min(CHUNK_SIZES)}",
        f"#define PLANT_FIXED_STEP_TOLERANCE {c_literal(FIXED_STEP_TOLERANCE)}",
        f"#define PLANT_I_X_M {names.index('x_m')}",
        f"#define PLANT_I_Y_M {names.index('y_m')}",
        f"#define PLANT_I_YAW_RAD {names.index('yaw_rad')}",
        f"#define PATH_N {len(path.s)}",
        f"#define PATH_LENGTH_M {c_literal(path.length_m)}",
        f"#define PATH_WINDOW_LO_M {c_literal(-3.0)}",
        f"#define PATH_WINDOW_HI_M {c_literal(12.0)}",
    ]
    text = "\n".join(lines) + "\n"
    text += c_array("mpc_sx", mpc.sx) + c_array("mpc_p", mpc.p_model)
    text += c_array("mpc_pred_index", [names.index(n) for n in mpc.pred_names], "int")
    text += c_array("mpc_cell_index", [names.index(n) for n in mpc.cell_names], "int")
    text += c_array("plant_p", model.param_vector(sc.params)) + c_array("plant_x0", pb.x0) + c_array("plant_u0", pb.u0)
    text += c_array("mpc_w_cold", pb.w_cold)
    for nm, arr in (("path_s", path.s), ("path_x", path.x), ("path_y", path.y), ("path_psi", path.psi),
                    ("path_kappa", path.kappa), ("path_speed", path.speed)):
        text += c_array(nm, arr)
    return text + "#endif\n"


# ---------------------------------------------------------------------------------------- files
MAKEFILE = """\
# Written by symtrack codegen mpc: the closed loop of the MPC scenario '{name}' in plain C.
# It links libc and libm only (the QP solver, CasADi's qrqp, is generated C in mpc_rti.c).
#   make            build ./mpc_closed_loop
#   make run        build it and run it: writes closed_loop.csv, prints a JSON summary
CC ?= cc
CFLAGS ?= {cflags}
OBJS = mpc_closed_loop.o mpc_rti.o {plant}.o

mpc_closed_loop: $(OBJS)
\t$(CC) -o $@ $(OBJS) -lm

mpc_closed_loop.o: mpc_closed_loop.c mpc_rti.h mpc_scenario.h {plant}.h
\t$(CC) $(CFLAGS) -c mpc_closed_loop.c -o $@

mpc_rti.o: mpc_rti.c mpc_rti.h
\t$(CC) $(CFLAGS) -c mpc_rti.c -o $@

{plant}.o: {plant}.c {plant}.h
\t$(CC) $(CFLAGS) -c {plant}.c -o $@

run: mpc_closed_loop
\t./mpc_closed_loop

clean:
\trm -f mpc_closed_loop $(OBJS) closed_loop.csv

.PHONY: run clean
"""


def render(pb: Problem) -> dict[str, bytes]:
    """Every file of the C closed loop, name -> bytes."""
    from symtrack.native.cache import generated_sources
    from symtrack.native.generate import FIXED_STEP_METHOD, model_functions

    files: dict[str, bytes] = {}
    with tempfile.TemporaryDirectory(prefix="symtrack-mpcgen-") as scratch:
        cg = ca.CodeGenerator("mpc_rti.c", {"with_header": True})
        for f in rti_functions(pb.mpc):
            cg.add(f)
        cg.generate(str(scratch) + os.sep)
        for n in ("mpc_rti.c", "mpc_rti.h"):
            files[n] = (Path(scratch) / n).read_bytes()
    gen = model_functions(pb.model, pb.model.terrain.name, (FIXED_STEP_METHOD,))
    plant = generated_sources(gen, PLANT_STEM)
    files.update({n: d for n, d in plant.items() if n.startswith(PLANT_STEM)})
    files["mpc_scenario.h"] = scenario_header(pb).encode()
    files["mpc_closed_loop.c"] = MAIN_C.read_bytes()
    files["Makefile"] = MAKEFILE.format(name=pb.scenario.name, cflags=CFLAGS, plant=PLANT_STEM).encode()
    return files


def write(out: Path, files: dict[str, bytes]) -> None:
    from symtrack.foundations.files import atomic_write_bytes

    out.mkdir(parents=True, exist_ok=True)
    for name, data in sorted(files.items()):
        atomic_write_bytes(out / name, data)


def build_program(out: Path, cc: str, cflags: str = CFLAGS) -> float:
    """Compile DIR/mpc_closed_loop (make -j2 when there is make, else the compiler directly);
    returns the build time [s]. ``cflags``: the compiler flags (default CFLAGS, -O2; the tests
    build with -O1, half the compile time of mpc_rti.c)."""
    from symtrack.foundations.errors import SimulationError

    t0 = time.perf_counter()
    make = shutil.which("make")
    if make:
        cmds = [[make, "-s", "-j2", f"CC={cc}", f"CFLAGS={cflags}", "mpc_closed_loop"]]
    else:
        objs = []
        cmds = []
        for stem in ("mpc_closed_loop", "mpc_rti", PLANT_STEM):
            cmds.append([cc, *cflags.split(), "-c", f"{stem}.c", "-o", f"{stem}.o"])
            objs.append(f"{stem}.o")
        cmds.append([cc, "-o", "mpc_closed_loop", *objs, "-lm"])
    for cmd in cmds:
        res = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
        if res.returncode != 0:
            raise SimulationError(f"building {out / 'mpc_closed_loop'} failed:\n{' '.join(cmd)}\n"
                                  f"{(res.stdout + res.stderr)[-3000:]}")
    return time.perf_counter() - t0


def run_program(out: Path) -> dict:
    """Run DIR/mpc_closed_loop; returns its JSON summary (it writes DIR/closed_loop.csv)."""
    import json

    from symtrack.foundations.errors import SimulationError

    res = subprocess.run([str(out / "mpc_closed_loop")], capture_output=True, text=True)
    if res.returncode != 0:
        raise SimulationError(f"{out / 'mpc_closed_loop'} failed ({res.returncode}): {res.stderr.strip()}")
    return json.loads(res.stdout)


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    return header, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


# ---------------------------------------------------------------------------------------- command
def load_scenario(name: str, overrides=(), solver: str = "rti"):
    """The MPC scenario ``name`` (built-in or TOML file) for the C loop: the RTI, on the compiled
    Rosenbrock plant of the homogeneous terrain. Errors name what is wrong."""
    from symtrack.control import scenario
    from symtrack.foundations.errors import ScenarioError
    from symtrack.simulation.scenario import builtin_names as simulation_names

    if solver not in SOLVERS:
        raise ScenarioError(f"--solver {solver!r}: the C closed loop has the real-time iteration only "
                            f"({', '.join(SOLVERS)})")
    mpc_names = scenario.builtin_names()
    if not name.endswith(".toml") and name not in mpc_names and name in simulation_names():
        raise ScenarioError(f"{name!r} is a simulation scenario (symtrack simulate), not an MPC scenario; "
                            f"MPC scenarios: {', '.join(mpc_names)} or a TOML file")
    # the C embeds qrqp (the QP solver CasADi generates plain C for): the Python loop it is compared
    # with runs qrqp too, whatever MPCSettings' default rti_qp_solver is
    sc = scenario.load(name, list(overrides) + [f"mpc.solver={solver}", "run.integrator=rosenbrock"])
    if sc.mpc.rti_qp_solver != "qrqp" and any(o.replace(" ", "").startswith("mpc.rti_qp_solver=") for o in overrides):
        raise ScenarioError(f"mpc.rti_qp_solver = {sc.mpc.rti_qp_solver!r}: the C closed loop embeds qrqp (the QP "
                            "solver CasADi generates dependency-free C for); allowed: qrqp")
    sc = dataclasses.replace(sc, mpc=dataclasses.replace(sc.mpc, rti_qp_solver="qrqp"))
    if sc.terrain is not None:
        raise ScenarioError(f"MPC scenario {sc.name!r} runs on the grid terrain ([terrain] section): the C closed "
                            "loop has the homogeneous plant only (add --set or use a scenario without [terrain])")
    return sc


def python_closed_loop(sc, model=None):
    """The Python closed loop of the same configuration (the RTI on the Rosenbrock plant)."""
    from symtrack.control import closedloop

    return closedloop.run(sc, model=model)


def compare(res, csv_path: Path) -> dict:
    """Agreement of the C loop's CSV with a Python closed-loop result."""
    header, data = read_csv(csv_path)
    col = {n: i for i, n in enumerate(header)}
    names = res.state_names
    ix, iy = names.index("x_m"), names.index("y_m")
    n = min(len(data), len(res.t))
    dU = np.abs(data[:n, [col["torque_cmd_left_N_m"], col["torque_cmd_right_N_m"]]] - res.U[:n])
    return {
        "samples_c": int(len(data) - 1), "samples_python": int(len(res.t) - 1),
        "final_position_difference_m": float(np.hypot(data[-1, col["x_m"]] - res.X[-1, ix],
                                                      data[-1, col["y_m"]] - res.X[-1, iy])),
        "max_position_difference_m": float(np.max(np.hypot(data[:n, col["x_m"]] - res.X[:n, ix],
                                                           data[:n, col["y_m"]] - res.X[:n, iy]))),
        "max_torque_cmd_difference_N_m": float(dU.max()),
        "rms_torque_cmd_difference_N_m": float(np.sqrt(np.mean(dU ** 2))),
        "max_lateral_error_difference_m": float(np.max(np.abs(data[:n, col["lateral_error_m"]] - res.e_lat[:n]))),
    }


def command(args) -> int:
    """``symtrack codegen mpc NAME [--solver rti] --out DIR [--set ...] [--no-run] [--compare]``."""
    from symtrack.foundations.errors import ScenarioError
    from symtrack.foundations.files import check_output_folder
    if not args.name:
        raise ScenarioError("symtrack codegen mpc NAME --out DIR: give an MPC scenario (built-in name or TOML file)")
    if args.out is None:
        raise ScenarioError("symtrack codegen mpc: --out DIR is required (the generated files do not go into "
                            "the repository's generated/)")
    sc = load_scenario(args.name, args.set or [], args.solver or "rti")
    out = check_output_folder(args.out)
    cc = require_compiler("mpc_closed_loop")
    t0 = time.perf_counter()
    # every wait of more than a couple of seconds says first what it waits for
    log.info("generating the C code of %s's MPC: the model, the real-time iteration's functions and the cold "
             "start's solve (several seconds) ...", sc.name)
    pb = setup(sc)
    files = render(pb)
    write(out, files)
    t_gen = time.perf_counter() - t0
    log.info("wrote %s into %s in %.1f s (cold start %.2f s: %s)", ", ".join(sorted(files)), out, t_gen,
             pb.cold_time_s, pb.cold_status)
    log.info("compiling %s with %s (mpc_rti.c is large: about half a minute on two cores) ...",
             out / "mpc_closed_loop", cc)
    t_build = build_program(out, cc)
    log.info("built %s in %.1f s", out / "mpc_closed_loop", t_build)
    if args.no_run:
        return 0
    log.info("running %s ...", out / "mpc_closed_loop")
    summary = run_program(out)
    ms = {k: 1e-3 * summary[f"solve_time_{k}_us"] for k in ("median", "p95", "max")}
    print(f"C closed loop ({sc.name}, {summary['samples']} samples): solve median {ms['median']:.3f} / p95 "
          f"{ms['p95']:.3f} / max {ms['max']:.3f} ms; failed {summary['failed_solves']}; final position "
          f"({summary['final_x_m']:.4f}, {summary['final_y_m']:.4f}) m; build {t_build:.1f} s; "
          f"{out / 'closed_loop.csv'}")
    if summary["failed_solves"]:
        log.warning("%d of %d samples of the C loop failed (QP failure or rejected step) and applied the previous "
                    "plan: the C loop has no NLP fallback (docs/codegen.md; with the defaults, one re-linearised "
                    "Gauss-Newton iteration after a rejected step, the built-in U-turn needs none)",
                    summary["failed_solves"], summary["samples"])
    if args.compare:
        log.info("running the Python closed loop of the same configuration, to compare ...")
        res = python_closed_loop(sc, pb.model)
        s = res.summary
        agree = compare(res, out / "closed_loop.csv")
        print(f"Python closed loop (same RTI, Rosenbrock plant{', jit' if sc.mpc.uses_jit else ''}): solve median "
              f"{s['solve_time_median_ms']:.3f} / p95 {s['solve_time_p95_ms']:.3f} / max "
              f"{s['solve_time_max_ms']:.3f} ms; failed {s['failed_solves']}, fallbacks {s['fallback_solves']}")
        print("agreement: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                        for k, v in agree.items()))
    return 0
