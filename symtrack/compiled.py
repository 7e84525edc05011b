"""Compiled model functions: generated C -> shared library in a cache -> ``casadi.external``.

For a :class:`~symtrack.model.SystemModel` (any terrain), :func:`library` builds the Functions
of :mod:`codegen.generate`, hashes them (SHA-256 of the serialised Functions, the manifest's
``model_hash``), and looks for ``<cache>/<prefix>-<hash>/lib<prefix>.so``, where ``<cache>`` is
``$SYMTRACK_CACHE`` or ``~/.cache/symtrack``. When it is missing, the sources are taken from the
repository's ``generated/`` if its manifest has the same hash, or generated afresh (an installed
package, or a model that differs from the committed sources), compiled with the C compiler
(``$CC``, default ``cc``/``gcc``) and linked into the cache atomically (temporary name, rename).

Without a C compiler the module says so once (logging) and everything runs on CasADi's
interpreter with the same Functions; with :func:`set_require_compiled` (``--require-compiled``)
or ``SYMTRACK_REQUIRE_COMPILED=1`` that is an error instead.

Also here: the DAE of CVODES/IDAS on the compiled dynamics (:func:`compiled_dae`), the
fixed-step integrator per step (:class:`FixedStepper`) and the whole time loop of a scenario with
the fixed-step integrator (:func:`run_fixed_step`), which advances up to 256 steps per call.
"""

from __future__ import annotations

import contextlib
import json
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

from .errors import SimulationError

log = logging.getLogger("symtrack.compiled")

# bump when the compile flags or the library layout change (part of the cache key)
BUILD_VERSION = 2
# the large straight-line Jacobian files take 2x longer to compile at -O2 for little gain
BIG_FILE_BYTES = 600_000
CFLAGS_SMALL = ("-O2",)
CFLAGS_BIG = ("-O1",)
# Only the CASADI_SYMBOL_EXPORT functions are exported: the generated helpers then are not
# interposable, which lets the compiler call them directly (-fPIC alone made the integrator
# 20 % slower than in the standalone program).
CFLAGS_SHARED = ("-fPIC", "-fvisibility=hidden", "-DGCC_HASCLASSVISIBILITY")
REPO_GENERATED = Path(__file__).resolve().parent.parent / "generated"

_require = os.environ.get("SYMTRACK_REQUIRE_COMPILED", "") not in ("", "0")
_warned_no_compiler = False
_force_interpreter = False
_cache: dict[tuple[int, bool], tuple[object, Library]] = {}


def set_require_compiled(flag: bool = True) -> None:
    """Make a missing C compiler an error instead of a fallback to the interpreter."""
    global _require
    _require = bool(flag)


@contextlib.contextmanager
def interpreter_only():
    """Within this block :func:`library` gives the interpreted Functions (for comparisons and the
    benchmark), without the no-compiler warning."""
    global _force_interpreter
    saved, _force_interpreter = _force_interpreter, True
    try:
        yield
    finally:
        _force_interpreter = saved


def cache_root() -> Path:
    env = os.environ.get("SYMTRACK_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "symtrack"


def find_compiler() -> str | None:
    for cc in (os.environ.get("CC"), "cc", "gcc"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def _compiler() -> str | None:
    """The C compiler, or None after saying once that there is none (an error when required)."""
    global _warned_no_compiler
    cc = find_compiler()
    if cc is None:
        if _require:
            raise SimulationError("no C compiler found (looked for $CC, cc, gcc) and compiled code is required "
                                  "(--require-compiled); install gcc or drop --require-compiled")
        if not _warned_no_compiler:
            log.warning("no C compiler found (looked for $CC, cc, gcc): running the generated functions "
                        "on CasADi's interpreter instead (slower)")
            _warned_no_compiler = True
    return cc


class Library:
    """The generated Functions of one model (prefix = its terrain's name), built, compiled and
    loaded file by file (codegen.generate.GROUPS) on first use, so that a simulation pays only
    for what it calls; interpreted when compiled code is not wanted or there is no compiler."""

    def __init__(self, model, compiled: bool = True):
        self.model, self.prefix, self.want_compiled = model, model.terrain.name, compiled
        self.functions: dict[str, ca.Function] = {}  # what f() returns: external or interpreted
        self.interpreted: dict[str, ca.Function] = {}
        self.paths: dict[str, Path | None] = {}  # group -> shared library (None: interpreted)
        self.gens: dict = {}  # group -> codegen.generate.Generated

    @property
    def compiled(self) -> bool:
        return bool(self.paths) and all(p is not None for p in self.paths.values())

    def load(self, group: str) -> None:
        if group in self.paths:
            return
        from codegen.generate import build

        gen = build(self.model, self.prefix, (group,))
        stem = f"{self.prefix}_{group}"
        interp = {f.name(): f for f in gen.functions()}
        path = None
        cc = _compiler() if self.want_compiled else None
        if cc is not None:
            path = cache_root() / f"{stem}-{gen.file_hash(stem)[:16]}-b{BUILD_VERSION}" / f"lib{stem}.so"
            if not path.exists():
                t0 = time.perf_counter()
                log.info("compiling %s into %s (once; cached)", stem, path.parent)
                _compile(_sources(gen, stem), path, cc)
                log.info("compiled %s in %.1f s", stem, time.perf_counter() - t0)
        self.interpreted.update(interp)
        self.functions.update(interp if path is None else {n: ca.external(n, str(path)) for n in interp})
        self.paths[group], self.gens[group] = path, gen

    def _name(self, short: str) -> str:
        from codegen.generate import GROUP_OF

        if short not in GROUP_OF:
            raise KeyError(f"no generated function {short!r}; known: {', '.join(GROUP_OF)}")
        self.load(GROUP_OF[short])
        return f"{self.prefix}_{short}"

    def f(self, short: str) -> ca.Function:
        """A Function by its short name: ode, dae, outputs, accel, linearise, rosenbrock_step, ..."""
        return self.functions[self._name(short)]

    def interpreted_f(self, short: str) -> ca.Function:
        """The same Function on CasADi's interpreter."""
        return self.interpreted[self._name(short)]


def _compile(sources: dict[str, bytes], out_so: Path, cc: str) -> None:
    """Compile the .c files of sources into out_so, atomically."""
    out_so.parent.mkdir(parents=True, exist_ok=True)
    build = Path(tempfile.mkdtemp(prefix=".build-", dir=out_so.parent))
    try:
        for name, data in sources.items():
            (build / name).write_bytes(data)
        cfiles = sorted(n for n in sources if n.endswith(".c"))
        jobs, objs = [], []
        # biggest first, at most two compilers at a time (2-core machines)
        pending = sorted(cfiles, key=lambda n: -len(sources[n]))
        while pending or jobs:
            while pending and len(jobs) < 2:
                name = pending.pop(0)
                flags = CFLAGS_BIG if len(sources[name]) > BIG_FILE_BYTES else CFLAGS_SMALL
                obj = name[:-2] + ".o"
                cmd = [cc, *flags, *CFLAGS_SHARED, "-c", name, "-o", obj]
                jobs.append((name, subprocess.Popen(cmd, cwd=build, stdout=subprocess.PIPE,
                                                    stderr=subprocess.STDOUT)))
                objs.append(obj)
            name, proc = jobs.pop(0)
            out, _ = proc.communicate()
            if proc.returncode != 0:
                for _, other in jobs:
                    other.kill()
                    other.wait()
                raise SimulationError(f"compiling {name} failed ({cc}):\n{out.decode(errors='replace')[-2000:]}")
        tmp_so = build / out_so.name
        res = subprocess.run([cc, "-shared", "-o", tmp_so.name, *objs, "-lm"], cwd=build,
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise SimulationError(f"linking {out_so.name} failed: {res.stderr[-2000:]}")
        os.replace(tmp_so, out_so)
    finally:
        shutil.rmtree(build, ignore_errors=True)


def _sources(gen, stem: str) -> dict[str, bytes]:
    """The C sources of one file of gen: from the repository's generated/ when it matches, else
    generated afresh (an installed package, other model options, or a stale generated/)."""
    from codegen.generate import render

    manifest = REPO_GENERATED / "manifest.json"
    if manifest.exists():
        m = json.loads(manifest.read_text())
        if m.get("model_hash_by_file", {}).get(stem + ".c") == gen.file_hash(stem):
            names = (stem + ".c", stem + ".h")
            if all((REPO_GENERATED / n).exists() for n in names):
                return {n: (REPO_GENERATED / n).read_bytes() for n in names}
        elif m.get("model") == gen.prefix:
            log.info("generated/%s.c does not match this %s model (other options, or stale: python -m codegen); "
                     "generating it afresh", stem, gen.prefix)
    with tempfile.TemporaryDirectory(prefix="symtrack-codegen-") as scratch:
        files = render(gen, Path(scratch))
    files.pop("manifest.json")
    return files


def library(model, compiled: bool = True) -> Library:
    """The generated Functions of ``model`` (one Library per model object and mode)."""
    compiled = compiled and not _force_interpreter
    key = (id(model), compiled)
    hit = _cache.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    lib = Library(model, compiled)
    _cache[key] = (model, lib)
    return lib


def compiled_dae(model, method: str) -> dict:
    """The time-scaled DAE dict of simulate.Stepper on the compiled dynamics (exact Jacobian from
    ``jac_<name>`` in the library)."""
    lib = library(model)
    X, U = ca.MX.sym("x", model.x.sparsity()), ca.MX.sym("u", model.u.sparsity())
    P, H = ca.MX.sym("p", model.p.sparsity()), ca.MX.sym("step_s")
    if method == "cvodes":
        return {"x": X, "u": U, "p": ca.vertcat(P, H), "ode": H * lib.f("ode")(X, U, P)}
    Z = ca.MX.sym("z", model.z.sparsity())
    ode, alg = lib.f("dae")(X, Z, U, P)
    return {"x": X, "z": Z, "u": U, "p": ca.vertcat(P, H), "ode": H * ode, "alg": alg}


def substeps(length_s: float, fixed_step_s: float) -> int:
    """Number of equal steps of at most fixed_step_s that cover length_s (the C driver mirrors it)."""
    return max(1, math.ceil(length_s / fixed_step_s - 1e-9))


class _Chunk:
    """A chunk Function (x0, z0, U, H, p) -> (X, Z, Y) called through CasADi's zero-copy buffer
    interface on numpy arrays that are allocated once (the columns of a CasADi matrix are the
    rows of these C-ordered arrays): no conversion of the 256 x (nx + nz + ny) results per call."""

    def __init__(self, f: ca.Function, n: int, model):
        nx, nz, nu, ny = model.nx, model.z.numel(), model.u.numel(), len(model.output_names)
        self.n = n
        self.x0, self.z0, self.p = np.zeros(nx), np.zeros(nz), np.zeros(model.p.numel())
        self.U, self.H = np.zeros((n, nu)), np.zeros(n)
        self.X, self.Z, self.Y = np.zeros((n, nx)), np.zeros((n, nz)), np.zeros((n, ny))
        self.f = f
        self.buf, self._eval = f.buffer()
        for i, a in enumerate((self.x0, self.z0, self.U, self.H, self.p)):
            self.buf.set_arg(i, memoryview(a))
        for i, a in enumerate((self.X, self.Z, self.Y)):
            self.buf.set_res(i, memoryview(a))

    def __call__(self):
        self._eval()
        if self.buf.ret() != 0:
            raise SimulationError(f"{self.f.name()} failed (status {self.buf.ret()})")


class FixedStepper:
    """simulate.Stepper's interface for the fixed-step integrator (one call per 16 steps)."""

    def __init__(self, model, settings):
        from codegen.generate import CHUNK_SIZES, FIXED_STEP_METHOD

        self.model, self.settings = model, settings
        self.lib = library(model)
        self.method = FIXED_STEP_METHOD
        self.sizes = CHUNK_SIZES
        self.chunk = {n: _Chunk(self.lib.f(f"{FIXED_STEP_METHOD}_chunk{n}"), n, model) for n in CHUNK_SIZES}
        self.z = None
        self._end = None  # (x, u, p) at the end of the last step: z is consistent there
        self.nsteps = 0
        self.ncalls = 0

    def reset(self):
        self.z = None

    def consistent_z(self, x, u, p, z_guess=None):
        """The algebraic state consistent with (x, u, p) (Newton steps from z_guess or accel)."""
        if z_guess is None:
            z_guess = self.lib.f("accel")(x, u, p)
        return np.array(self.lib.f("consistent_z")(x, z_guess, u, p)).ravel()

    def run_chunk(self, n_cols, x, z, U, H, p):
        """Advance len(H) <= n_cols steps (column k: input U[k], length H[k]) from (x, z); returns
        the chunk's arrays X, Z, Y (row k: after step k; rows beyond len(H) are left unchanged)."""
        c = self.chunk[n_cols]
        k = len(H)
        c.x0[:], c.z0[:], c.p[:] = x, z, p
        c.U[:k], c.U[k:] = U, 0.0
        c.H[:k], c.H[k:] = H, 0.0
        c()
        self.nsteps += k
        self.ncalls += 1
        if not np.all(np.isfinite(c.X[k - 1])):
            raise SimulationError(f"{self.method} returned a non-finite state")
        return c.X, c.Z, c.Y

    def advance(self, x, z, u, p, length_s):
        """State and algebraic state after length_s [s] with input u (equal steps)."""
        n = substeps(length_s, self.settings.fixed_step_s)
        h = length_s / n
        short = min(self.sizes)
        x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
        while n > 0:
            k = min(n, short)
            X, Z, _ = self.run_chunk(short, x, z, np.tile(u, (k, 1)), np.full(k, h), p)
            x, z = X[k - 1].copy(), Z[k - 1].copy()
            n -= k
        return x, z

    def step(self, x, u, p, dt: float):
        x, u, p = (np.asarray(a, dtype=float) for a in (x, u, p))
        z0 = self.z
        if z0 is None or self._end is None or not all(np.array_equal(a, b) for a, b in zip((x, u, p), self._end,
                                                                                          strict=True)):
            # a new start, a shortened step repeated from an earlier state, new inputs or new
            # parameters (the grid world's channels): re-solve z for this (x, u, p)
            z0 = self.consistent_z(x, u, p, z0)
        xf, self.z = self.advance(x, z0, u, p, dt)
        self._end = (xf.copy(), u.copy(), p.copy())
        return xf

    def stats(self) -> dict:
        return {"nsteps": self.nsteps, "n_calls": self.ncalls, "compiled": self.lib.compiled}


class _Grid:
    """The output intervals of runner.run (output_dt_s steps, split at the torque changes, up to
    duration_s), cut into equal steps of at most fixed_step_s and handed out as chunk columns.
    Written as a lean loop: it runs in the timed loop, once per step."""

    def __init__(self, scenario, fixed_step_s: float):
        run = scenario.run
        self.dt, self.duration, self.fs = run.output_dt_s, run.duration_s, fixed_step_s
        self.t_s = [e.t_s for e in scenario.torque]
        self.torque = np.array([[e.left_N_m, e.right_N_m] for e in scenario.torque], dtype=float)
        self.t = 0.0
        self.cur = 0  # torque entry in force
        self.nxt = 1  # first change time not yet passed
        self.left = 0  # steps of the current interval still to hand out
        self.h = self.t0 = self.t1 = 0.0

    def fill(self, n_cols: int):
        """Up to n_cols columns: (step lengths, torque entry per column, [(column, t0, t1) of the
        columns that end an output interval]). Empty when the grid is exhausted."""
        hs, ui, ends = [], [], []
        t_s, dt, duration, fs = self.t_s, self.dt, self.duration, self.fs
        while len(hs) < n_cols:
            if self.left == 0:
                t = self.t
                if not t < duration - 1e-12:
                    break
                t_next = min(t + dt, duration)
                while self.nxt < len(t_s) and not t + 1e-12 < t_s[self.nxt]:
                    self.nxt += 1
                if self.nxt < len(t_s) and t_s[self.nxt] < t_next - 1e-12:
                    t_next = t_s[self.nxt]
                while self.cur + 1 < len(t_s) and t_s[self.cur + 1] <= t + 1e-12:
                    self.cur += 1
                n = substeps(t_next - t, fs)
                self.left, self.h, self.t0, self.t1 = n, (t_next - t) / n, t, t_next
                self.t = t_next
            take = min(self.left, n_cols - len(hs))
            hs += [self.h] * take
            ui += [self.cur] * take
            self.left -= take
            if self.left == 0:
                ends.append((len(hs) - 1, self.t0, self.t1))
        return hs, ui, ends


def run_fixed_step(scenario, model, settings, progress: bool = True):
    """runner.run for the fixed-step integrator: the same output grid, torque schedule and
    stop-at-distance rule (three secant refinements of the last output step), with the steps
    advanced in chunks of up to 256 per call of the generated C (a short chunk of 16 near the
    stopping distance, so that little is computed past it)."""
    from .progress import Progress
    from .runner import Result
    from .simulate import static_state

    stepper = FixedStepper(model, settings)
    lib, fs = stepper.lib, settings.fixed_step_s
    big, short = max(stepper.sizes), min(stepper.sizes)
    params = scenario.params
    p = np.array(model.param_vector(params), dtype=float)
    st = scenario.start
    x = static_state(model, params, st.x_m, st.y_m, np.radians(st.yaw_deg))
    run_cfg = scenario.run
    dist_from = None
    if run_cfg.stop_after_distance_m is not None:
        dist_from = scenario.event_time(run_cfg.stop_distance_event) if run_cfg.stop_distance_event else 0.0
    target = run_cfg.stop_after_distance_m
    outputs = lib.f("outputs")
    u0 = np.array(scenario.torque_at(0.0), dtype=float)
    z = stepper.consistent_z(x, u0, p)
    # the trajectory as blocks of rows (one block per chunk)
    tb, xb, ub, yb = [np.zeros(1)], [x[None, :]], [u0[None, :]], [np.array(outputs(x, u0, p)).T]
    t_last = 0.0
    xk, zk = x, z  # state at the last output point
    xc, zc = x, z  # state at the end of the last chunk (an output interval may span two chunks)
    dist, stopped_by, done = 0.0, "duration", False
    grid = _Grid(scenario, fs)
    bar = Progress(1.0, scenario.name, enabled=progress)
    wall0 = time.perf_counter()
    while not done:
        n_cols = big
        if dist_from is not None and t_last >= dist_from:
            speed = float(np.hypot(xk[3], xk[4]))
            est = (target - dist) / max(speed, 1e-3) / fs  # steps left, roughly
            n_cols = big if est > 1.2 * big else short
        cols_h, cols_u, ends = grid.fill(n_cols)
        if not cols_h:
            break
        k = len(cols_h)
        U = grid.torque[cols_u]
        X, Z, Y = stepper.run_chunk(n_cols, xc, zc, U, np.array(cols_h), p)
        xc, zc = X[k - 1].copy(), Z[k - 1].copy()
        if not ends:
            continue
        jj = np.array([e[0] for e in ends])
        t1s = np.array([e[2] for e in ends])
        Xe = X[jj]
        m = len(jj)  # output points of this chunk that are kept
        if dist_from is not None:
            prev = np.vstack([xk[None, :2], Xe[:-1, :2]])
            d = np.hypot(Xe[:, 0] - prev[:, 0], Xe[:, 1] - prev[:, 1])
            active = t1s > dist_from + 1e-12
            # the same sequential sums as runner.run: dist_i = dist_(i-1) + d_i
            cum = np.cumsum(np.concatenate(([dist], np.where(active, d, 0.0))))[1:]
            hit = np.flatnonzero(active & (cum >= target))
            if hit.size:
                m = int(hit[0])
                dist = float(cum[m - 1]) if m > 0 else dist
            else:
                dist = float(cum[-1])
        tb.append(t1s[:m])
        xb.append(Xe[:m])
        ub.append(U[jj[:m]])
        yb.append(Y[jj[:m]].copy())
        if m > 0:
            t_last, xk, zk = float(t1s[m - 1]), Xe[m - 1], Z[jj[m - 1]].copy()
        if m < len(jj):
            # shorten the last step so the run ends at the distance (as runner.run)
            t0_, u_ = ends[m][1], U[jj[m]]
            x_new = Xe[m]
            d_step = float(np.hypot(x_new[0] - xk[0], x_new[1] - xk[1]))
            h = t1s[m] - t0_
            for _ in range(3):
                if d_step <= 0:
                    break
                h *= (target - dist) / d_step
                x_new, _z = stepper.advance(xk, zk, u_, p, h)
                d_step = float(np.hypot(x_new[0] - xk[0], x_new[1] - xk[1]))
            dist += d_step
            t_last = t0_ + h
            tb.append(np.array([t_last]))
            xb.append(x_new[None, :])
            ub.append(u_[None, :])
            yb.append(np.array(outputs(x_new, u_, p)).T)
            done = True
            stopped_by = "distance"
        frac = t_last / run_cfg.duration_s
        if dist_from is not None:
            frac = max(frac, dist / target)
        bar.update(frac, f"t={t_last:.2f} s" + (f" d={dist:.2f} m" if dist_from is not None else ""))
    bar.close()
    wall = time.perf_counter() - wall0
    if dist_from is not None and stopped_by != "distance":
        raise SimulationError(
            f"the run reached run.duration_s = {run_cfg.duration_s} s before covering "
            f"run.stop_after_distance_m = {target} m (covered {dist:.2f} m); raise duration_s")
    return Result(scenario, np.concatenate(tb), np.vstack(xb), np.vstack(ub), np.vstack(yb), model.state_names,
                  model.output_names, wall, stopped_by, stepper.stats())
