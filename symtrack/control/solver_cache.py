"""Compiled MPC functions cached across processes.

A CasADi Function (the mapped collocation Jacobians and residuals of the real-time iteration, or
the functions an NLP solver calls) is turned into C with CasADi's code generator, compiled into
a shared library by :func:`symtrack.toolchain.build` and loaded with ``casadi.external``. The library
lives in ``<cache>/mpc/<name>-<key>/lib<name>.so`` (``<cache>``: ``$SYMTRACK_CACHE`` or
``~/.cache/symtrack``, as the model libraries; a ``jit_dir`` replaces ``<cache>/mpc``), where
``key`` is the SHA-256 of the serialised Function, the CasADi version, the compile flags and
:data:`BUILD_VERSION`. A second process with the same problem finds the library and calls no
compiler; the first build logs a message with its time. The build API's lock and atomic rename
let two processes build at once without either seeing half a library.

This replaces CasADi's ``jit`` option for the MPC, which compiles in every process into the
current directory (``jit_temp_suffix``) and keeps nothing.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from pathlib import Path

import casadi as ca

from .. import toolchain as cache
from ..toolchain import BuildSpec, digest

__all__ = ["BUILD_VERSION", "DEFAULT_FLAGS", "GROUP", "builds", "compiled_function", "compiled_nlp_library",
           "problem_key"]

log = logging.getLogger("symtrack.control.solver_cache")

# bump when the flags or the layout of the cached libraries change (part of the key)
BUILD_VERSION = 1
DEFAULT_FLAGS = ("-O1",)
GROUP = "mpc"  # the libraries' sub-folder of the cache

# every compilation of this process for the MPC (symtrack.toolchain.Built: kind, what, path, seconds); the tests read it
builds: list = []


def problem_key(payload: bytes, flags=DEFAULT_FLAGS) -> str:
    """SHA-256 of the problem (serialised Functions, options), CasADi's version, flags, layout."""
    return digest(payload, f"casadi {ca.__version__} | flags {' '.join(flags)} | build {BUILD_VERSION}")


def _library(kind: str, key: str, output: str, sources, what: str, flags: tuple[str, ...],
             root: Path | None) -> Path:
    """The cached library (compiled when missing, with the flags of CasADi's jit: ``-O1 -fPIC``,
    every symbol visible, one compiler call); a compilation is noted in :data:`builds`."""
    before = len(cache.builds)
    so = cache.build(BuildSpec(kind=kind, key=key, output=output, sources=sources, what=what, cflags=flags,
                               shared_cflags=("-fPIC",), one_command=True, digits=20, group=GROUP, root=root))
    builds.extend(cache.builds[before:])
    return so


def compiled_function(fn: ca.Function, flags=DEFAULT_FLAGS, root: Path | None = None) -> ca.Function:
    """``fn`` as a cached compiled library (``casadi.external``); same inputs and outputs."""
    flags = tuple(flags)
    name = fn.name()

    def sources():
        with tempfile.TemporaryDirectory(prefix="symtrack-mpcgen-") as scratch:
            cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
            cg.add(fn)
            cg.generate(scratch + os.sep)
            return {f"{name}.c": (Path(scratch) / f"{name}.c").read_bytes()}

    so = _library(name, problem_key(fn.serialize().encode(), flags), f"lib{name}.so", sources,
                  f"MPC function {name}", flags, root)
    return ca.external(name, str(so))


def compiled_nlp_library(solver: ca.Function, payload: bytes, flags=DEFAULT_FLAGS, root: Path | None = None) -> Path:
    """The functions an NLP solver calls (``generate_dependencies``: nlp_f, nlp_g, nlp_grad_f,
    nlp_jac_g, nlp_hess_l, ...) as a cached shared library; ``nlpsol(name, plugin, path, opts)``
    loads it. ``payload`` identifies the problem (the serialised NLP functions and options)."""
    flags = tuple(flags)

    def sources():
        with tempfile.TemporaryDirectory(prefix="symtrack-nlpgen-") as scratch, contextlib.chdir(scratch):
            solver.generate_dependencies("mpc_nlp.c", {"with_header": False})  # into the current folder
            return {"mpc_nlp.c": Path("mpc_nlp.c").read_bytes()}

    return _library("nlp", problem_key(payload, flags), "libmpc_nlp.so", sources,
                    f"MPC NLP functions ({solver.class_name()})", flags, root)
