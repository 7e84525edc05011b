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

import json
import logging
import math
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .errors import SimulationError

log = logging.getLogger("symtrack.compiled")

# bump when the compile flags or the library layout change (part of the cache key)
BUILD_VERSION = 2
# the large straight-line Jacobian files take 2x longer to compile at -O2 for little gain
BIG_FILE_BYTES = 400_000
CFLAGS_SMALL = ("-O2",)
CFLAGS_BIG = ("-O1",)
# Only the CASADI_SYMBOL_EXPORT functions are exported: the generated helpers then are not
# interposable, which lets the compiler call them directly (-fPIC alone made the integrator
# 20 % slower than in the standalone program).
CFLAGS_SHARED = ("-fPIC", "-fvisibility=hidden", "-DGCC_HASCLASSVISIBILITY")
REPO_GENERATED = Path(__file__).resolve().parent.parent / "generated"

_require = os.environ.get("SYMTRACK_REQUIRE_COMPILED", "") not in ("", "0")
_warned_no_compiler = False
_cache: dict[int, tuple[object, Library]] = {}


def set_require_compiled(flag: bool = True) -> None:
    """Make a missing C compiler an error instead of a fallback to the interpreter."""
    global _require
    _require = bool(flag)


def cache_root() -> Path:
    env = os.environ.get("SYMTRACK_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "symtrack"


def find_compiler() -> str | None:
    for cc in (os.environ.get("CC"), "cc", "gcc"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


@dataclass
class Library:
    """The generated Functions of one model, compiled (``compiled`` True) or interpreted."""

    prefix: str
    gen: object  # codegen.generate.Generated
    path: Path | None
    functions: dict

    @property
    def compiled(self) -> bool:
        return self.path is not None

    def f(self, short: str) -> ca.Function:
        """A Function by its short name: ode, dae, outputs, accel, linearise, ..."""
        return self.functions[f"{self.prefix}_{short}"]


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


def _sources(gen) -> dict[str, bytes]:
    """The C sources of gen: from the repository's generated/ when it matches, else fresh."""
    from codegen.generate import render

    manifest = REPO_GENERATED / "manifest.json"
    if manifest.exists():
        m = json.loads(manifest.read_text())
        if m.get("model_hash") == gen.model_hash:
            files = {n: (REPO_GENERATED / n).read_bytes() for n in m["files"] if (REPO_GENERATED / n).exists()}
            if len(files) == len(m["files"]):
                return files
        log.info("generated/ does not match the %s model (run python -m codegen); generating its sources afresh",
                 gen.prefix)
    with tempfile.TemporaryDirectory(prefix="symtrack-codegen-") as scratch:
        files = render(gen, Path(scratch))
    files.pop("manifest.json")
    return files


def library(model, compiled: bool = True) -> Library:
    """The generated Functions of ``model``: compiled and loaded from the cache when possible."""
    global _warned_no_compiler
    key = id(model)
    hit = _cache.get(key)
    if hit is not None and hit[0] is model and (hit[1].compiled or not compiled):
        return hit[1]
    from codegen.generate import build

    prefix = model.terrain.name
    gen = build(model, prefix)
    interpreted = {f.name(): f for f in gen.functions()}
    lib = Library(prefix, gen, None, interpreted)
    if compiled:
        cc = find_compiler()
        if cc is None:
            if _require:
                raise SimulationError("no C compiler found (looked for $CC, cc, gcc) and compiled code is required "
                                      "(--require-compiled); install gcc or drop --require-compiled")
            if not _warned_no_compiler:
                log.warning("no C compiler found (looked for $CC, cc, gcc): running the generated functions "
                            "on CasADi's interpreter instead (slower)")
                _warned_no_compiler = True
        else:
            so = cache_root() / f"{prefix}-{gen.model_hash[:16]}-b{BUILD_VERSION}" / f"lib{prefix}.so"
            if not so.exists():
                t0 = time.perf_counter()
                log.info("compiling the %s model into %s (once; cached)", prefix, so.parent)
                _compile(_sources(gen), so, cc)
                log.info("compiled in %.1f s", time.perf_counter() - t0)
            funcs = {name: ca.external(name, str(so)) for name in interpreted}
            lib = Library(prefix, gen, so, funcs)
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


class FixedStepper:
    """simulate.Stepper's interface for the fixed-step integrator (one Python call per 16 steps)."""

    def __init__(self, model, settings):
        self.model, self.settings = model, settings
        self.lib = library(model)
        from codegen.generate import CHUNK_SIZES, FIXED_STEP_METHOD

        self.method = FIXED_STEP_METHOD
        self.sizes = CHUNK_SIZES
        self.chunk = {n: self.lib.f(f"{FIXED_STEP_METHOD}_chunk{n}") for n in CHUNK_SIZES}
        self.z = None
        self.nsteps = 0
        self.ncalls = 0

    def reset(self):
        self.z = None

    def advance(self, x, z, u, p, length_s):
        """State and algebraic state after length_s [s] with input u (equal steps)."""
        n = substeps(length_s, self.settings.fixed_step_s)
        h = length_s / n
        short = min(self.sizes)
        x, z = ca.DM(x), ca.DM(z)
        while n > 0:
            k = min(n, short)
            H = np.zeros((1, short))
            H[0, :k] = h
            X, Z, _ = self.chunk[short](x, z, np.tile(np.reshape(u, (-1, 1)), (1, short)), H, p)
            x, z = X[:, k - 1], Z[:, k - 1]
            n -= k
            self.nsteps += k
            self.ncalls += 1
        return x, z

    def step(self, x, u, p, dt: float):
        z0 = self.lib.f("accel")(x, u, p) if self.z is None else self.z
        xf, self.z = self.advance(x, z0, u, p, dt)
        xf = np.array(xf).ravel()
        if not np.all(np.isfinite(xf)):
            raise SimulationError(f"{self.method} returned a non-finite state")
        return xf

    def stats(self) -> dict:
        return {"nsteps": self.nsteps, "n_calls": self.ncalls, "compiled": self.lib.compiled}


def _intervals(scenario):
    """The output intervals of runner.run, in order: (t, t_next, u)."""
    run_cfg = scenario.run
    change_times = [e.t_s for e in scenario.torque[1:]]
    t = 0.0
    while t < run_cfg.duration_s - 1e-12:
        t_next = min(t + run_cfg.output_dt_s, run_cfg.duration_s)
        for tc in change_times:
            if t + 1e-12 < tc < t_next - 1e-12:
                t_next = tc
        yield t, t_next, np.array(scenario.torque_at(t), dtype=float)
        t = t_next


def run_fixed_step(scenario, model, settings, progress: bool = True):
    """runner.run for the fixed-step integrator: the same output grid, torque schedule and
    stop-at-distance rule (two secant refinements of the last step), with the steps advanced in
    chunks of up to 256 per call of the generated C."""
    from .progress import Progress
    from .runner import Result
    from .simulate import static_state

    stepper = FixedStepper(model, settings)
    lib, fs = stepper.lib, settings.fixed_step_s
    big, short = max(stepper.sizes), min(stepper.sizes)
    params = scenario.params
    p = ca.DM(model.param_vector(params))
    st = scenario.start
    x = static_state(model, params, st.x_m, st.y_m, np.radians(st.yaw_deg))
    run_cfg = scenario.run
    dist_from = None
    if run_cfg.stop_after_distance_m is not None:
        dist_from = scenario.event_time(run_cfg.stop_distance_event) if run_cfg.stop_distance_event else 0.0
    target = run_cfg.stop_after_distance_m
    outputs = lib.f("outputs")
    u0 = np.array(scenario.torque_at(0.0), dtype=float)
    ts, xs, us, ys = [0.0], [x], [u0], [np.array(outputs(x, u0, p)).ravel()]
    z = np.array(lib.f("accel")(x, u0, p)).ravel()
    xk, zk = x, z  # state at the last output point
    xc, zc = xk, zk  # state at the end of the last chunk (an output interval may span two chunks)
    dist, stopped_by, done = 0.0, "duration", False
    ivals = _intervals(scenario)
    pending = []  # (t, t_next, u, n) intervals not yet advanced
    bar = Progress(1.0, scenario.name, enabled=progress)
    wall0 = time.perf_counter()
    exhausted = False
    while not done:
        # choose the chunk: a short one near the stopping distance
        n_cols = big
        if dist_from is not None and ts[-1] >= dist_from:
            speed = float(np.hypot(xs[-1][3], xs[-1][4]))
            est = (target - dist) / max(speed, 1e-3) / fs
            n_cols = big if est > 1.2 * big else short
        cols_u, cols_h, ends = [], [], []
        while len(cols_h) < n_cols:
            if not pending:
                nxt = next(ivals, None)
                if nxt is None:
                    exhausted = True
                    break
                t0_, t1_, u_ = nxt
                pending.append([t0_, t1_, u_, substeps(t1_ - t0_, fs), 0])
            iv = pending[0]
            t0_, t1_, u_, n, used = iv
            take = min(n - used, n_cols - len(cols_h))
            cols_u += [u_] * take
            cols_h += [(t1_ - t0_) / n] * take
            iv[4] += take
            if iv[4] == n:
                ends.append((len(cols_h) - 1, t0_, t1_, u_))
                pending.pop(0)
        if not cols_h:
            break
        k = len(cols_h)
        U = np.zeros((model.u.numel(), n_cols))
        U[:, :k] = np.array(cols_u).T
        H = np.zeros((1, n_cols))
        H[0, :k] = cols_h
        X, Z, Y = (np.array(a) for a in stepper.chunk[n_cols](xc, zc, U, H, p))
        xc, zc = X[:, k - 1], Z[:, k - 1]
        stepper.nsteps += k
        stepper.ncalls += 1
        for j, t0_, t1_, u_ in ends:
            x_new = X[:, j]
            if dist_from is not None and t1_ > dist_from + 1e-12:
                d_step = float(np.hypot(x_new[0] - xs[-1][0], x_new[1] - xs[-1][1]))
                if dist + d_step >= target:
                    # shorten the last step so the run ends at the distance (secant refinements)
                    h = t1_ - t0_
                    for _ in range(3):
                        if d_step <= 0:
                            break
                        h *= (target - dist) / d_step
                        xn, _z = stepper.advance(xk, zk, u_, p, h)
                        x_new = np.array(xn).ravel()
                        d_step = float(np.hypot(x_new[0] - xs[-1][0], x_new[1] - xs[-1][1]))
                    t1_ = t0_ + h
                    done = True
                    y_new = np.array(outputs(x_new, u_, p)).ravel()
                dist += d_step
            if not done:
                y_new = Y[:, j]
            ts.append(t1_)
            xs.append(x_new)
            us.append(u_)
            ys.append(y_new)
            xk, zk = x_new, Z[:, j]
            if done:
                stopped_by = "distance"
                break
        frac = ts[-1] / run_cfg.duration_s
        if dist_from is not None:
            frac = max(frac, dist / target)
        bar.update(frac, f"t={ts[-1]:.2f} s" + (f" d={dist:.2f} m" if dist_from is not None else ""))
        if exhausted and not pending:
            break
    bar.close()
    wall = time.perf_counter() - wall0
    if dist_from is not None and stopped_by != "distance":
        raise SimulationError(
            f"the run reached run.duration_s = {run_cfg.duration_s} s before covering "
            f"run.stop_after_distance_m = {target} m (covered {dist:.2f} m); raise duration_s")
    X = np.array(xs)
    if not np.all(np.isfinite(X)):
        raise SimulationError(f"{stepper.method} returned a non-finite state")
    return Result(scenario, np.array(ts), X, np.array(us), np.array(ys), model.state_names,
                  model.output_names, wall, stopped_by, stepper.stats())
