"""One run of a sweep, as a worker does it: from the scenario's text and overrides (plain data a
Dask worker receives, never CasADi objects) to the files a single run writes.

A worker builds the model itself; the compiled libraries come from that machine's hash-keyed
cache (``$SYMTRACK_CACHE``, :mod:`symtrack.toolchain`), compiled there once when missing. The
files come back to the client as bytes, so the client alone writes the sweep folder (a cluster
needs no shared file system).
"""

from __future__ import annotations

import os
import socket
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..foundations.config import apply_overrides
from ..foundations.config import builtin_names as package_names
from ..foundations.errors import ScenarioError
from ..foundations.files import read_text

__all__ = ["KINDS", "Source", "load", "resolve_source", "run_one", "scenario_text"]

# the scenario kinds a sweep runs: those of `symtrack simulate`, `symtrack mpc` and `symtrack field`
KINDS = ("simulate", "mpc", "field")
PACKAGES = {"simulate": "symtrack.simulation.scenarios", "mpc": "symtrack.control.scenarios",
            "field": "symtrack.studies.fields"}


@dataclass(frozen=True)
class Source:
    """The scenario of a sweep as workers receive it: its kind, its TOML text and its default name."""

    kind: str
    text: str
    name: str
    label: str  # what the user gave (a built-in name or a path)


def scenario_text(name_or_path, package: str) -> tuple[str, str] | None:
    """(TOML text, default name) of a built-in scenario of ``package`` or of a TOML file; None
    when it is neither."""
    from importlib import resources

    s = str(name_or_path)
    p = Path(s)
    if p.suffix == ".toml" or (s not in package_names(package) and p.exists()):
        if not p.is_file():
            raise ScenarioError(f"scenario file {s!r} does not exist")
        return read_text(p, "scenario file"), p.stem
    if s in package_names(package):
        return resources.files(package).joinpath(s + ".toml").read_text(), s
    return None


def load(kind: str, text: str, name: str, overrides: dict | None = None):
    """The validated scenario of ``kind`` from its text and overrides (``{"section.key": value}``):
    a :class:`symtrack.Scenario`, a :class:`symtrack.control.MPCScenario` or a
    :class:`symtrack.studies.field.FieldSpec`."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{name}: not valid TOML: {err}") from err
    apply_overrides(doc, overrides or {})
    if kind == "simulate":
        from ..simulation.scenario import scenario_from_dict

        return scenario_from_dict(doc, name)
    if kind == "mpc":
        from ..control.scenario import scenario_from_dict as mpc_from_dict

        return mpc_from_dict(doc, name)
    if kind == "field":
        from .operations import is_operation_doc, operation_spec_from_dict

        if is_operation_doc(doc):  # a field operation or a season (docs/studies.md, "Field operations")
            return operation_spec_from_dict(doc, name)
        from .field import field_spec_from_dict

        return field_spec_from_dict(doc, name)
    raise ScenarioError(f"kind = {kind!r} is not one of {', '.join(KINDS)}")


def resolve_source(name_or_path, kind: str = "auto") -> Source:
    """The scenario of a sweep: a built-in name (of ``symtrack scenarios`` or of ``symtrack mpc``)
    or a TOML file. ``kind`` "auto" takes the kind whose loader accepts the scenario."""
    if kind not in ("auto", *KINDS):
        raise ScenarioError(f"--kind {kind!r} is not one of auto, {', '.join(KINDS)}")
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise ScenarioError(f"scenario {name_or_path!r}: give a built-in name or a TOML file path")
    kinds = KINDS if kind == "auto" else (kind,)
    errors = []
    for k in kinds:
        found = scenario_text(name_or_path, PACKAGES[k])
        if found is None:
            errors.append(f"not a built-in {k} scenario ({', '.join(package_names(PACKAGES[k]))})")
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
    and ``overrides``. Returns ``{"id", "status": "ok" | "failed", "error", "files": {relative
    path: bytes}, "wall_time_s", "cpu_time_s", "host", "pid"}``; any exception of the run is a failed run with
    its message (the sweep goes on), an interrupt is not caught."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = {"id": task["id"], "status": "ok", "error": "", "files": {}, "host": socket.gethostname(),
           "pid": os.getpid()}
    try:
        sc = load(task["kind"], task["text"], task["name"], task["overrides"])
        with tempfile.TemporaryDirectory(prefix="symtrack-sweep-run-") as scratch:
            folder = Path(scratch)
            if task["kind"] == "simulate":
                from ..api import simulate

                simulate(sc, progress=False).write(folder)
            elif task["kind"] == "field":
                from .operations import OperationSpec, run_season

                if isinstance(sc, OperationSpec):  # a field operation or a season (one traffic system)
                    if sc.compare:
                        raise ScenarioError("season.compare: a traffic comparison is a sweep of its own "
                                            "(symtrack field ... --workers N, or vary season.tracks); "
                                            "a sweep run drives one system: set season.tracks")
                    run_season(sc, out=folder)
                else:
                    from .field import run_field_study

                    run_field_study(sc, out=folder)
            else:
                from ..control.closedloop import run, write

                write(folder, run(sc))
            out["files"] = _files(folder)
    except Exception as err:  # noqa: BLE001 - a failed run is recorded with its message; the others go on
        out.update(status="failed", error=f"{type(err).__name__}: {err}".strip(), files={})
    out["wall_time_s"] = time.perf_counter() - t0
    out["cpu_time_s"] = time.process_time() - c0
    return out
