"""One run of a sweep, as a worker does it: from the scenario's text and overrides (plain data a
Dask worker receives, never CasADi objects) to the files a single run writes.

A worker builds the model itself; the compiled libraries come from that machine's hash-keyed
cache (``$SYMTRACK_CACHE``, :mod:`symtrack.toolchain`), compiled there once when missing. The
files come back to the client as bytes, so the client alone writes the sweep folder (a cluster
needs no shared file system).
"""

from __future__ import annotations

import importlib
import os
import socket
import tempfile
import time
import tomllib
from pathlib import Path

from ..foundations.config import apply_overrides
from ..foundations.config import builtin_names as package_names
from ..foundations.errors import ScenarioError
from ..foundations.files import read_text
from .runfile import Kind, RunFile, Source, sweep_kind, sweep_kinds

__all__ = ["Source", "load", "resolve_source", "run_one", "scenario_text"]


def scenario_text(name_or_path, package: str | None) -> tuple[str, str] | None:
    """(TOML text, default name) of a built-in scenario of ``package`` (None: a kind without built-ins)
    or of a TOML file; None when it is neither."""
    from importlib import resources

    s = str(name_or_path)
    p = Path(s)
    names = package_names(package) if package else []
    if p.suffix == ".toml" or (s not in names and p.exists()):
        if not p.is_file():
            raise ScenarioError(f"scenario file {s!r} does not exist")
        return read_text(p, "scenario file"), p.stem
    if s in names:
        return resources.files(package).joinpath(s + ".toml").read_text(), s
    return None


def _load(kind: str, text: str, name: str, overrides: dict | None) -> tuple[Kind, object]:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{name}: not valid TOML: {err}") from err
    apply_overrides(doc, overrides or {})
    k = sweep_kind(kind, doc)
    return k, k.load(RunFile(k.name, doc, None, name, overrides or {}, doc))


def load(kind: str, text: str, name: str, overrides: dict | None = None):
    """The validated spec of a sweep's scenario of ``kind`` (its sweep name) from its text and
    overrides (``{"section.key": value}``), by the loader of its registered kind
    (:data:`symtrack.studies.runfile.KINDS`): a :class:`symtrack.Scenario`, a
    :class:`symtrack.control.MPCScenario`, a :class:`symtrack.studies.field.FieldSpec`, ..."""
    return _load(kind, text, name, overrides)[1]


def resolve_source(name_or_path, kind: str = "auto") -> Source:
    """The scenario of a sweep: a built-in name (of ``symtrack scenarios`` or of ``symtrack mpc``)
    or a TOML file. ``kind`` "auto" takes the kind whose loader accepts the scenario."""
    kinds = sweep_kinds()
    if kind not in ("auto", *kinds):
        raise ScenarioError(f"--kind {kind!r} is not one of auto, {', '.join(kinds)}")
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise ScenarioError(f"scenario {name_or_path!r}: give a built-in name or a TOML file path")
    errors = []
    for k in (kinds if kind == "auto" else (kind,)):
        package = kinds[k].package
        found = scenario_text(name_or_path, package)
        if found is None:
            errors.append(f"not a built-in {k} scenario ({', '.join(package_names(package)) if package else 'none'})")
            continue
        text, name = found
        try:
            load(k, text, name)
        except ScenarioError as err:
            errors.append(f"as a {k} scenario: {err}")
            continue
        return Source(k, text, name, str(name_or_path))
    raise ScenarioError(f"scenario {str(name_or_path)!r}: " + "; ".join(errors))


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def run_one(task: dict) -> dict:
    """Run one task of a sweep (on a worker): ``task`` has ``id``, ``kind``, ``text``, ``name``
    and ``overrides`` (and ``modules``, imported first: :func:`symtrack.studies.runfile.worker_modules`);
    the spec is run by its kind's ``sweep_run`` or ``run``. Returns ``{"id", "status": "ok" | "failed",
    "error", "files": {relative path: bytes}, "wall_time_s", "cpu_time_s", "host", "pid"}``; any
    exception of the run is a failed run with its message (the sweep goes on), an interrupt is not caught."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = {"id": task["id"], "status": "ok", "error": "", "files": {}, "host": socket.gethostname(),
           "pid": os.getpid()}
    try:
        for module in task.get("modules", ()):  # a kind registered by a plug-in: its registration
            importlib.import_module(module)
        kind, spec = _load(task["kind"], task["text"], task["name"], task["overrides"])
        with tempfile.TemporaryDirectory(prefix="symtrack-sweep-run-") as scratch:
            folder = Path(scratch)
            (kind.sweep_run or kind.run)(spec, folder, False)
            out["files"] = _files(folder)
    except Exception as err:  # noqa: BLE001 - a failed run is recorded with its message; the others go on
        out.update(status="failed", error=f"{type(err).__name__}: {err}".strip(), files={})
    out["wall_time_s"] = time.perf_counter() - t0
    out["cpu_time_s"] = time.process_time() - c0
    return out
