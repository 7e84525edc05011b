"""Compiled MPC functions cached across processes.

A CasADi Function (the mapped collocation Jacobians and residuals of the real-time iteration, or
the functions an NLP solver calls) is turned into C with CasADi's code generator, compiled into
a shared library and loaded with ``casadi.external``. The library lives in
``<cache>/mpc/<name>-<key>/lib<name>.so`` (``<cache>`` is :func:`symtrack.native.cache.cache_root`:
``$SYMTRACK_CACHE`` or ``~/.cache/symtrack``, as the model libraries), where ``key`` is the
SHA-256 of the serialised Function, the CasADi version, the compile flags and
:data:`BUILD_VERSION`. A second process with the same problem finds the library and calls no
compiler; the first build logs a message with its time. Builds are atomic (temporary folder,
then rename), so two processes building at once do not see half a library.

This replaces CasADi's ``jit`` option for the MPC, which compiles in every process into the
current directory (``jit_temp_suffix``) and keeps nothing.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca

from ..foundations.errors import SimulationError
from ..native.cache import cache_root, find_compiler

log = logging.getLogger("symtrack.control.solver_cache")

# bump when the flags or the layout of the cached libraries change (part of the key)
BUILD_VERSION = 1
DEFAULT_FLAGS = ("-O1",)
_SHARED = ("-fPIC", "-shared")

# every compiler run of this process: (name, seconds); the tests read it
builds: list[tuple[str, float]] = []


def cache_dir() -> Path:
    return cache_root() / "mpc"


def problem_key(payload: bytes, flags=DEFAULT_FLAGS) -> str:
    """SHA-256 of the problem (serialised Functions, options), CasADi's version, flags, layout."""
    h = hashlib.sha256()
    h.update(payload)
    h.update(f"casadi {ca.__version__} | flags {' '.join(flags)} | build {BUILD_VERSION}".encode())
    return h.hexdigest()


def _build(so: Path, write_sources, flags, what: str) -> None:
    """Write the C sources with ``write_sources(folder) -> [c files]`` and compile them into so."""
    cc = find_compiler()
    if cc is None:
        raise SimulationError(f"{what}: no C compiler found (looked for $CC, cc, gcc); install gcc or run "
                              "the MPC interpreted (no jit)")
    so.parent.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=so.parent.parent))
    try:
        t0 = time.perf_counter()
        log.info("compiling %s into %s (once; cached for later runs) ...", what, so.parent)
        cfiles = write_sources(tmp)
        res = subprocess.run([cc, *flags, *_SHARED, *cfiles, "-o", so.name, "-lm"], cwd=tmp,
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise SimulationError(f"compiling {what} failed ({cc}):\n{res.stderr[-2000:]}")
        dt = time.perf_counter() - t0
        builds.append((what, dt))
        log.info("compiled %s in %.1f s", what, dt)
        final = so.parent
        try:
            os.replace(tmp, final)  # atomic: the folder appears complete or not at all
        except OSError:
            if not so.exists():  # not another process's build that won the race
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def compiled_function(fn: ca.Function, flags=DEFAULT_FLAGS, root: Path | None = None) -> ca.Function:
    """``fn`` as a cached compiled library (``casadi.external``); same inputs and outputs."""
    flags = tuple(flags)
    name = fn.name()
    key = problem_key(fn.serialize().encode(), flags)
    so = (root or cache_dir()) / f"{name}-{key[:20]}" / f"lib{name}.so"
    if not so.exists():
        def write(folder: Path):
            cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
            cg.add(fn)
            cg.generate(str(folder) + os.sep)
            return [f"{name}.c"]

        _build(so, write, flags, f"MPC function {name}")
    return ca.external(name, str(so))


def compiled_nlp_library(solver: ca.Function, payload: bytes, flags=DEFAULT_FLAGS, root: Path | None = None) -> Path:
    """The functions an NLP solver calls (``generate_dependencies``: nlp_f, nlp_g, nlp_grad_f,
    nlp_jac_g, nlp_hess_l, ...) as a cached shared library; ``nlpsol(name, plugin, path, opts)``
    loads it. ``payload`` identifies the problem (the serialised NLP functions and options)."""
    flags = tuple(flags)
    key = problem_key(payload, flags)
    so = (root or cache_dir()) / f"nlp-{key[:20]}" / "libmpc_nlp.so"
    if not so.exists():
        def write(folder: Path):
            solver.generate_dependencies("mpc_nlp.c", {"with_header": False})
            shutil.move("mpc_nlp.c", folder / "mpc_nlp.c")
            return ["mpc_nlp.c"]

        with tempfile.TemporaryDirectory(prefix="symtrack-nlpgen-") as scratch:
            old = os.getcwd()
            os.chdir(scratch)
            try:
                _build(so, write, flags, f"MPC NLP functions ({solver.class_name()})")
            finally:
                os.chdir(old)
    return so
