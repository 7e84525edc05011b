"""Compiled model functions: generated C -> shared library in the cache -> ``casadi.external``.

For a :class:`~symtrack.model.SystemModel` (any terrain), :func:`library` builds the Functions
of :mod:`symtrack.native.generate`, hashes them (SHA-256 of the serialised Functions, the manifest's
``model_hash``), and has :func:`symtrack.toolchain.build` compile each file into
``<cache>/<prefix>_<file>-<hash>-b<BUILD_VERSION>/lib<prefix>_<file>.so`` once (the cache, its lock,
its atomic writes and the compiler are :mod:`symtrack.toolchain`'s). The sources are taken from the
repository's ``generated/`` if its manifest has the same hash, or generated afresh (an installed
package, or a model that differs from the committed sources). ``library(model, quadrature_call=True)``
(the compiled Rosenbrock's) compiles a model whose tracks' quadrature is large from its
:attr:`~symtrack.model.SystemModel.codegen_twin`, which sums that quadrature by one call node
(``ModelOptions.quadrature_call``; docs/codegen.md, "Large quadratures"): seconds of gcc instead of
minutes. The compiled CVODES/IDAS (``run.compiled``) keep the expanded form: their Jacobian of the
call node, evaluated at every Newton setup, made the 64 x 5 validation run 1.8 x slower than on the
interpreter. The key hashes the serialised Functions, so the two forms never share a library.

Without a C compiler everything runs on CasADi's interpreter with the same Functions (a warning
once; an error with ``--require-compiled``: :func:`symtrack.toolchain.set_require_compiled`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import tempfile
from pathlib import Path

import casadi as ca

from ..foundations import caches
from ..toolchain import BuildSpec, build, compiler
from .generate import GROUP_OF, model_functions, render

log = logging.getLogger("symtrack.native")

__all__ = ["BUILD_VERSION", "LIBRARIES", "REPO_GENERATED", "Library", "generated_sources", "interpreter_only",
           "library"]

# bump when the compile flags or the library layout change (part of the cache folder's name)
BUILD_VERSION = 2
REPO_GENERATED = Path(__file__).resolve().parents[2] / "generated"

_force_interpreter = False
# the libraries of the most recently used models (symtrack.foundations.caches): a library holds its model,
# so the bound frees the models the build cache let go of
MAX_LIBRARIES = 8
LIBRARIES = caches.cache("model_libraries", MAX_LIBRARIES)


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


class Library:
    """The generated Functions of one model (prefix = its terrain's name), built, compiled and
    loaded file by file (symtrack.native.generate.GROUPS) on first use, so that a simulation pays only
    for what it calls; interpreted when compiled code is not wanted or there is no compiler.
    ``quadrature_call``: compile from the model's ``codegen_twin`` (:attr:`source`; the interpreted
    fallback without a compiler stays on the expanded model, where a call node would be slow;
    ``interpreted_f`` of a compiled twin evaluates its call node on CasADi's interpreter)."""

    def __init__(self, model, compiled: bool = True, quadrature_call: bool = False):
        self.model, self.prefix, self.want_compiled = model, model.terrain.name, compiled
        self.quadrature_call = quadrature_call
        self.functions: dict[str, ca.Function] = {}  # what f() returns: external or interpreted
        self.interpreted: dict[str, ca.Function] = {}
        self.paths: dict[str, Path | None] = {}  # group -> shared library (None: interpreted)
        self.gens: dict = {}  # group -> symtrack.native.generate.Generated

    @property
    def source(self):
        """The model whose Functions are compiled: the model, or (``quadrature_call``) its
        ``codegen_twin`` (the model itself unless its quadrature is large)."""
        return self.model.codegen_twin if self.quadrature_call else self.model

    @property
    def compiled(self) -> bool:
        return bool(self.paths) and all(p is not None for p in self.paths.values())

    def load(self, group: str) -> None:
        if group in self.paths:
            return
        cc = compiler() if self.want_compiled else None
        gen = model_functions(self.model if cc is None else self.source, self.prefix, (group,))
        stem = f"{self.prefix}_{group}"
        interp = {f.name(): f for f in gen.functions()}
        path = None
        if cc is not None:
            path = build(BuildSpec(kind=stem, key=gen.file_hash(stem), output=f"lib{stem}.so",
                                   sources=lambda: generated_sources(gen, stem), what=f"the model functions {stem}",
                                   suffix=f"-b{BUILD_VERSION}"), cc)
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
            log.info("generating the C of this %s model (generated/%s.c holds the validation scenario's model, "
                     "with other options; after a change of that model: python -m codegen)", gen.prefix, stem)
    with tempfile.TemporaryDirectory(prefix="symtrack-codegen-") as scratch:
        files = render(gen, Path(scratch))
    files.pop("manifest.json")
    return files


def library(model, compiled: bool = True, quadrature_call: bool = False) -> Library:
    """The generated Functions of ``model`` (one Library per model object and mode);
    ``quadrature_call``: a large track quadrature compiled as one call node (:class:`Library`)."""
    compiled = compiled and not _force_interpreter
    key = (id(model), compiled, quadrature_call)
    hit = LIBRARIES.get(key)
    if hit is not None and hit.model is model:
        return hit
    lib = Library(model, compiled, quadrature_call)
    if hit is not None:  # another model at the same id (the first one freed): replace its entry
        LIBRARIES.drop(key)
    return LIBRARIES.put(key, lib)
