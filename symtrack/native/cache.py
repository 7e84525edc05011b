"""Compiled model functions: generated C -> shared library in a cache -> ``casadi.external``.

For a :class:`~symtrack.model.SystemModel` (any terrain), :func:`library` builds the Functions
of :mod:`symtrack.native.generate`, hashes them (SHA-256 of the serialised Functions, the manifest's
``model_hash``), and looks for ``<cache>/<prefix>-<hash>/lib<prefix>.so``, where ``<cache>`` is
``$SYMTRACK_CACHE`` or ``~/.cache/symtrack``. When it is missing, the sources are taken from the
repository's ``generated/`` if its manifest has the same hash, or generated afresh (an installed
package, or a model that differs from the committed sources), compiled with the C compiler
(``$CC``, default ``cc``/``gcc``) and linked into the cache atomically (temporary name, rename).
Processes that build the same entry at once (parallel test workers, sweep workers) take turns on
a lock file beside it: the first compiles, the others find its library and compile nothing.

Without a C compiler the module says so once (logging) and everything runs on CasADi's
interpreter with the same Functions; with :func:`set_require_compiled` (``--require-compiled``)
or ``SYMTRACK_REQUIRE_COMPILED=1`` that is an error instead.

This is the one compile-and-cache API of symtrack: the model libraries (:func:`library`), the
grid integrator (:mod:`symtrack.integrators.grid_rosenbrock`) and the standalone program of
``codegen/`` all compile through :func:`compiler` and :func:`compile_sources`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca

from ..foundations.errors import SimulationError
from .generate import GROUP_OF, build, render

log = logging.getLogger("symtrack.native")

__all__ = ["BUILD_VERSION", "Library", "cache_root", "compile_sources", "compiler", "find_compiler",
           "generated_sources", "interpreter_only", "library", "set_require_compiled"]

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
REPO_GENERATED = Path(__file__).resolve().parents[2] / "generated"

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


def compiler() -> str | None:
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
    loaded file by file (symtrack.native.generate.GROUPS) on first use, so that a simulation pays only
    for what it calls; interpreted when compiled code is not wanted or there is no compiler."""

    def __init__(self, model, compiled: bool = True):
        self.model, self.prefix, self.want_compiled = model, model.terrain.name, compiled
        self.functions: dict[str, ca.Function] = {}  # what f() returns: external or interpreted
        self.interpreted: dict[str, ca.Function] = {}
        self.paths: dict[str, Path | None] = {}  # group -> shared library (None: interpreted)
        self.gens: dict = {}  # group -> symtrack.native.generate.Generated

    @property
    def compiled(self) -> bool:
        return bool(self.paths) and all(p is not None for p in self.paths.values())

    def load(self, group: str) -> None:
        if group in self.paths:
            return
        gen = build(self.model, self.prefix, (group,))
        stem = f"{self.prefix}_{group}"
        interp = {f.name(): f for f in gen.functions()}
        path = None
        cc = compiler() if self.want_compiled else None
        if cc is not None:
            path = cache_root() / f"{stem}-{gen.file_hash(stem)[:16]}-b{BUILD_VERSION}" / f"lib{stem}.so"
            if not path.exists():
                t0 = time.perf_counter()
                log.info("compiling %s into %s (once; cached)", stem, path.parent)
                compile_sources(generated_sources(gen, stem), path, cc)
                log.info("compiled %s in %.1f s", stem, time.perf_counter() - t0)
        self.interpreted.update(interp)
        self.functions.update(interp if path is None else {n: ca.external(n, str(path)) for n in interp})
        self.paths[group], self.gens[group] = path, gen

    def _name(self, short: str) -> str:
        if short not in GROUP_OF:
            raise KeyError(f"no generated function {short!r}; known: {', '.join(GROUP_OF)}")
        self.load(GROUP_OF[short])
        return f"{self.prefix}_{short}"

    def f(self, short: str) -> ca.Function:
        """A Function by its short name: ode, dae, outputs, accel, linearize, rosenbrock_step, ..."""
        return self.functions[self._name(short)]

    def interpreted_f(self, short: str) -> ca.Function:
        """The same Function on CasADi's interpreter."""
        return self.interpreted[self._name(short)]


@contextlib.contextmanager
def _build_lock(folder: Path):
    """An exclusive lock on ``folder/.lock`` (flock; released when the holder exits or dies), so
    that concurrent builds of one cache entry run one at a time; no lock where flock is missing
    (the rename alone keeps the library whole)."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield
        return
    with open(folder / ".lock", "a+b") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def compile_sources(sources: dict[str, bytes], out_so: Path, cc: str) -> None:
    """Compile the .c files of sources into out_so, atomically (a temporary folder beside it, then
    a rename); a process that finds out_so built by another while it waited compiles nothing."""
    out_so.parent.mkdir(parents=True, exist_ok=True)
    with _build_lock(out_so.parent):
        if out_so.exists():  # built by another process while this one waited for the lock
            return
        _compile(sources, out_so, cc)


def _compile(sources: dict[str, bytes], out_so: Path, cc: str) -> None:
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


def generated_sources(gen, stem: str) -> dict[str, bytes]:
    """The C sources of one file of gen: from the repository's generated/ when it matches, else
    generated afresh (an installed package, other model options, or a stale generated/)."""
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
