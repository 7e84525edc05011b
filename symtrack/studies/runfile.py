"""One front door: any run file of symtrack (a simulation, an MPC run, a field study, a field
operation, a season or a sweep), its kind told by its sections, run by one call
(``symtrack run FILE.toml``; :func:`symtrack.run` from Python).

The sections that decide the kind (:data:`KINDS`)::

    [[torque]]          a simulation      (as symtrack simulate; symtrack/simulation/scenario.py)
    [path] or [mpc]     an MPC run        (as symtrack mpc; symtrack/control/scenario.py)
    [field]             a field study     (as symtrack field; symtrack/studies/field.py)
    [operation]         a field operation (as symtrack field; symtrack/studies/operations/)
    [season]            a season of operations over an [operation] section (as symtrack field)
    [sweep]             a sweep of any of the above (as symtrack sweep; symtrack/studies/engine.py)

Each kind is one registration (:class:`Kind`, :func:`register_kind`): its deciding sections, its
loader and how it runs into a folder; ``symtrack run``, :func:`run` and a sweep's runs
(:mod:`symtrack.studies.runs`) take every kind from there, a kind registered by a plug-in too.

A file with sections of two kinds, or of none, is refused in one line naming these sections.
Every other section ([run], [vehicle], [soil], [model], [terrain], ...) belongs to the kind's
own schema and is checked by its loader, with the loader's messages.

A sweep file holds the ``[sweep]`` section::

    [sweep]
    scenario = "validation"       # optional: a built-in name or a run file (relative to this file);
                                  # without it the sweep's scenario is the rest of this file
    workers = 2                   # processes of the local Dask cluster (docs/studies.md)
    scheduler = "tcp://HOST:8786" # optional: a running Dask scheduler instead
    samples = 8                   # optional: Latin hypercube points over [sweep.ranges]
    seed = 0
    [sweep.vary]                  # the full grid of these values ("KEY" = [values])
    "vehicle.mass_kg" = [5000.0, 6000.0]
    [sweep.ranges]                # optional: "KEY" = [low, high], sampled by the Latin hypercube
    "soil.bekker_n" = [0.6, 1.1]
"""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..foundations.config import apply_overrides, builtin_names, check_keys, integer, read_document, to_toml
from ..foundations.errors import ScenarioError
from ..foundations.files import read_text

__all__ = ["KINDS", "Kind", "RunFile", "SWEEP_KEYS", "detect_kind", "kind_rules", "read_run_file", "register_kind",
           "run", "split_overrides", "sweep_arguments", "sweep_kind", "sweep_kinds", "worker_modules"]


@dataclass(frozen=True)
class Source:
    """The scenario of a sweep as workers receive it: its kind (its sweep name, :func:`sweep_kinds`), its
    TOML text and its default name (:mod:`symtrack.studies.runs` runs it)."""

    kind: str
    text: str
    name: str
    label: str  # what the user gave (a built-in name or a path)


@dataclass(frozen=True)
class Kind:
    """A kind of run file: the sections that decide it, what it is, the command it shares its schema
    with, the package of its built-in files, and how it runs: ``load(run_file)`` its spec from a
    :class:`RunFile` (a file's path, or a document), ``run(spec, out, progress)`` the spec into the
    folder ``out`` (and its result). Registered once (:func:`register_kind`), it is a kind of
    ``symtrack run`` and, with a ``sweep`` name, of a sweep's scenario.

    ``sweep``: its name in a sweep (``--kind``, sweep.json, and the hash of every run id:
    :func:`symtrack.studies.design.run_id`; the names of earlier versions, so that a sweep folder
    resumes); kinds may share one, their documents then told apart by their sections; None: not run
    by a sweep. ``sweep_run``: how a sweep's run runs the spec into its folder, when not as ``run``.
    ``needs_out``: the kind writes its folder as it goes (``out`` required). ``modules``: what a
    sweep's worker imports for its runs (a kind registered by a plug-in: its module)."""

    name: str
    sections: tuple[str, ...]
    what: str
    command: str
    package: str | None
    load: Callable[[RunFile], Any]
    run: Callable[[Any, Any, bool | None], Any]
    sweep: str | None = None
    sweep_run: Callable[[Any, Any, bool | None], Any] | None = None
    needs_out: bool = False
    modules: tuple[str, ...] = ()


def _load_simulation(rf: RunFile):
    from ..simulation.scenario import load_scenario, scenario_from_dict

    return load_scenario(rf.source, rf.overrides) if rf.source is not None else scenario_from_dict(rf.document, rf.name)


def _run_simulation(sc, out, progress):
    from ..api import simulate

    res = simulate(sc, progress=progress)
    if out is not None:
        res.write(out)
    return res


def _load_mpc(rf: RunFile):
    from ..control.scenario import load, scenario_from_dict

    return load(rf.source, rf.overrides) if rf.source is not None else scenario_from_dict(rf.document, rf.name)


def _run_mpc(sc, out, progress):
    from ..control import closedloop

    res = closedloop.run(sc, progress=progress)
    if out is not None:
        closedloop.write(out, res)
    return res


def _load_field(rf: RunFile):
    from .field import field_spec_from_dict, load_field_spec

    return load_field_spec(rf.source, rf.overrides) if rf.source is not None else \
        field_spec_from_dict(rf.document, rf.name)


def _run_field(spec, out, progress):
    from .field import run_field_study

    return run_field_study(spec, out=out, progress=progress)


def _load_operation(rf: RunFile):
    from .operations import load_operation_spec, operation_spec_from_dict

    return load_operation_spec(rf.source, rf.overrides) if rf.source is not None else \
        operation_spec_from_dict(rf.document, rf.name)


def _run_operation(spec, out, progress):
    from .operations import run_season, traffic_comparison

    if spec.compare:
        return traffic_comparison(spec.document, spec.compare, out, progress=progress, name=spec.name)
    return run_season(spec, out, progress=progress)


def _sweep_run_operation(spec, out, progress):
    """A sweep's run of a field operation or a season: one traffic system."""
    if spec.compare:
        raise ScenarioError("season.compare: a traffic comparison is a sweep of its own (symtrack field ... "
                            "--workers N, or vary season.tracks); a sweep run drives one system: set season.tracks")
    return _run_operation(spec, out, progress)


KINDS: dict[str, Kind] = {}


def register_kind(kind: Kind, replace: bool = False) -> Kind:
    """Add a kind of run file (one registration: ``symtrack run``, :func:`run` and a sweep's runs take
    it from here); a name taken already is a ValueError unless ``replace``."""
    if kind.name in KINDS and not replace:
        raise ValueError(f"a kind of run file named {kind.name!r} is registered already")
    KINDS[kind.name] = kind
    return kind


_FIELD = "symtrack.studies.fields"
_OPERATION_MODULES = ("symtrack.studies.field", "symtrack.studies.operations")
for _kind in (
    Kind("simulation", ("[[torque]]",), "a simulation", "symtrack simulate", "symtrack.simulation.scenarios",
         _load_simulation, _run_simulation, sweep="simulate", modules=("symtrack.api",)),
    Kind("mpc", ("[path]", "[mpc]"), "an MPC run", "symtrack mpc", "symtrack.control.scenarios", _load_mpc, _run_mpc,
         sweep="mpc", modules=("symtrack.control.closedloop",)),
    Kind("field", ("[field]",), "a field study", "symtrack field", _FIELD, _load_field, _run_field, sweep="field",
         needs_out=True, modules=_OPERATION_MODULES),
    Kind("operation", ("[operation]",), "a field operation", "symtrack field", _FIELD, _load_operation,
         _run_operation, sweep="field", sweep_run=_sweep_run_operation, needs_out=True, modules=_OPERATION_MODULES),
    Kind("season", ("[season]",), "a season", "symtrack field", _FIELD, _load_operation, _run_operation,
         sweep="field", sweep_run=_sweep_run_operation, needs_out=True, modules=_OPERATION_MODULES),
):
    register_kind(_kind)
del _kind
SWEEP_KEYS = ("scenario", "vary", "ranges", "samples", "seed", "workers", "scheduler")


def sweep_kinds() -> dict[str, Kind]:
    """The kinds a sweep runs, by their sweep name, in the order registered: of kinds sharing a name,
    the first (whose package holds their built-in files)."""
    out: dict[str, Kind] = {}
    for k in KINDS.values():
        if k.sweep is not None:
            out.setdefault(k.sweep, k)
    return out


def worker_modules(sweep_name: str) -> tuple[str, ...]:
    """What a sweep's worker imports for the runs of ``sweep_name`` (of every kind of that name)."""
    return tuple(dict.fromkeys(m for k in KINDS.values() if k.sweep == sweep_name for m in k.modules))


def _held(doc: dict) -> dict[str, list[str]]:
    """kind -> the deciding sections ``doc`` holds, of each kind that has any ("[[torque]]" is the key
    "torque"); a season's [operation] section is its own."""
    found = {}
    for kind in KINDS.values():
        have = [s for s in kind.sections if s.strip("[]") in doc]
        if have:
            found[kind.name] = have
    if "season" in found:  # a season's operations are laid over its [operation] section
        found.pop("operation", None)
    return found


def sweep_kind(sweep_name: str, doc) -> Kind:
    """The registered kind of a sweep's scenario document of ``sweep_name`` (those sharing the name
    told apart by the document's sections; the first of them when it has none of theirs, so that its
    loader says what is missing)."""
    kinds = [k for k in KINDS.values() if k.sweep == sweep_name]
    if not kinds:
        raise ScenarioError(f"kind = {sweep_name!r} is not one of {', '.join(sweep_kinds())}")
    if len(kinds) == 1 or not isinstance(doc, dict):
        return kinds[0]
    held = [k for k in kinds if k.name in _held(doc)]
    if len(held) > 1:
        detect_kind(doc, f"a {sweep_name} scenario")  # several kinds: refused naming their sections
    return held[0] if held else kinds[0]


def kind_rules() -> str:
    """The rule of the kinds in one clause, for messages."""
    return "; ".join(f"{' or '.join(k.sections)} makes {k.what}" for k in KINDS.values())


def detect_kind(doc, label: str = "run file") -> str:
    """The kind of a run document from its sections (:data:`KINDS`); a :class:`ScenarioError` in one
    line naming the deciding sections when it has those of none or of several kinds."""
    if not isinstance(doc, dict):
        raise ScenarioError(f"{label}: a run file is a TOML table of sections, got {type(doc).__name__}")
    if "sweep" in doc:
        return "sweep"
    found = _held(doc)  # kind -> the deciding sections the document holds
    if len(found) == 1:
        return next(iter(found))
    rules = f"a run file has the sections of one kind: {kind_rules()} (symtrack new KIND writes one)"
    if not found:
        raise ScenarioError(f"{label}: none of the sections that decide the kind of run; {rules}")
    both = ", ".join(f"{' and '.join(s)} ({KINDS[k].what})" for k, s in found.items())
    raise ScenarioError(f"{label}: sections of several kinds of run: {both}; {rules}")


@dataclass(frozen=True)
class RunFile:
    """A run file as read: its kind, its document (overrides applied: the kind is that of the
    document that runs), the name or path to hand to the kind's loader, and the overrides."""

    kind: str
    document: dict
    source: object  # a built-in name or a path (str), or None for a document given as a dict
    name: str
    overrides: list | dict
    raw: dict  # the document as written, before the overrides

    @property
    def label(self) -> str:
        return str(self.source) if self.source is not None else self.name


def _builtin(name: str) -> tuple[str, str] | None:
    """(package, name) of a built-in run file of any kind, or None."""
    for kind in KINDS.values():
        if kind.package and name in builtin_names(kind.package):
            return kind.package, name
    return None


def read_run_file(spec_or_path, overrides=None) -> RunFile:
    """Read a run file (a path, a built-in name of any kind, or a document as a dict), apply the
    overrides (``["run.duration_s=2"]`` as ``--set``, or a dict) to a copy and tell its kind."""
    overrides = overrides if overrides is not None else []
    if isinstance(spec_or_path, dict):
        doc = apply_overrides(copy.deepcopy(spec_or_path), overrides)
        name = str(doc.get("name", "run"))
        return RunFile(detect_kind(doc, f"run {name!r}"), doc, None, name, overrides, copy.deepcopy(spec_or_path))
    if not isinstance(spec_or_path, (str, Path)):
        raise ScenarioError(f"run file {spec_or_path!r}: give a TOML file path, a built-in name or a document (dict)")
    s = str(spec_or_path)
    path = Path(s)
    found = None if path.suffix == ".toml" or path.exists() else _builtin(s)
    if found is not None:
        from importlib import resources

        package, name = found
        raw = tomllib.loads(resources.files(package).joinpath(name + ".toml").read_text())
    else:
        if not path.is_file():
            every = sorted({n for k in KINDS.values() if k.package for n in builtin_names(k.package)})
            raise ScenarioError(f"run file {s!r} does not exist" + ("" if path.suffix == ".toml" else
                                f" and is no built-in run ({', '.join(every)})"))
        try:
            raw = tomllib.loads(read_text(path, "run file"))
        except tomllib.TOMLDecodeError as err:
            raise ScenarioError(f"{s}: not valid TOML: {err}") from err
        name = path.stem
    doc = apply_overrides(copy.deepcopy(raw), overrides)
    return RunFile(detect_kind(doc, s), doc, s, str(doc.get("name", name)), overrides, raw)


def split_overrides(overrides) -> tuple[list | dict, list | dict]:
    """(the ``sweep.*`` overrides, the others) of a sweep file's ``--set`` list or dict: the first edit
    the [sweep] section, the others are fixed overrides of every run of the sweep."""
    if isinstance(overrides, dict):
        return ({k: v for k, v in overrides.items() if k.startswith("sweep.")},
                {k: v for k, v in overrides.items() if not k.startswith("sweep.")})
    items = list(overrides or [])
    own = [it for it in items if str(it).split("=", 1)[0].strip().startswith("sweep.")]
    return own, [it for it in items if it not in own]


def _sweep_table(t, key: str) -> dict:
    if t is None:
        return {}
    if not isinstance(t, dict) or not t:
        raise ScenarioError(f"sweep.{key} = {t!r} must be a table of \"SECTION.KEY\" = [values]")
    return t


def sweep_arguments(rf: RunFile) -> dict:
    """The arguments of :func:`symtrack.studies.sweep` from a sweep file (its [sweep] section and,
    without ``sweep.scenario``, the rest of the file as the scenario): ``scenario`` (a name, a
    path or a :class:`~symtrack.studies.runs.Source`), ``vary``, ``ranges``, ``samples``, ``seed``,
    ``overrides``, ``workers``, ``scheduler``, ``kind``."""
    doc = rf.document
    sw = doc["sweep"]
    if not isinstance(sw, dict):
        raise ScenarioError(f"[sweep] = {sw!r} must be a table")
    check_keys("sweep", sw, SWEEP_KEYS)
    vary = _sweep_table(sw.get("vary"), "vary")
    ranges = _sweep_table(sw.get("ranges"), "ranges")
    if not vary and not ranges:
        raise ScenarioError("[sweep] varies nothing: give [sweep.vary] (\"SECTION.KEY\" = [values]) or "
                            "[sweep.ranges] (\"SECTION.KEY\" = [low, high]) with samples")
    for key, v in vary.items():
        if not isinstance(v, list) or not v:
            raise ScenarioError(f"sweep.vary.\"{key}\" = {v!r} must be a non-empty list of values")
    for key, v in ranges.items():
        if not isinstance(v, list) or len(v) != 2:
            raise ScenarioError(f"sweep.ranges.\"{key}\" = {v!r} must be [low, high]")
    samples = sw.get("samples")
    if ranges and samples is None:
        raise ScenarioError("sweep.ranges needs sweep.samples, the number of Latin hypercube points")
    samples = None if samples is None else integer("sweep.samples", samples, 1, 100000)
    seed = integer("sweep.seed", sw.get("seed", 0), 0, 2**31 - 1)
    workers = integer("sweep.workers", sw.get("workers", 2), 1, 1024)
    scheduler = sw.get("scheduler")
    if scheduler is not None and not isinstance(scheduler, str):
        raise ScenarioError(f"sweep.scheduler = {scheduler!r} must be an address, e.g. \"tcp://127.0.0.1:8786\"")
    _, fixed = split_overrides(rf.overrides)
    rest = {k: v for k, v in rf.raw.items() if k != "sweep"}
    if "scenario" in sw:
        scenario = sw["scenario"]
        if not isinstance(scenario, str) or not scenario:
            raise ScenarioError(f"sweep.scenario = {scenario!r} must be a built-in name or a run file path")
        own = {k for k in rest if k not in ("name", "description", "symtrack_version")}
        if own:
            raise ScenarioError(f"{rf.label}: sweep.scenario names the scenario, so the file holds only [sweep] "
                                f"(found {', '.join(sorted(own))}); put those in the scenario, or drop sweep.scenario")
        if scenario.endswith(".toml") and rf.source is not None and not Path(scenario).is_absolute():
            scenario = str(Path(rf.source).resolve().parent / scenario)
        kind = "auto"
    else:
        # the rest of the file is the scenario (the overrides fixed over it, as --set of symtrack sweep)
        if rf.source is not None and Path(str(rf.source)).is_file():
            from ..terrain.settings import PATH_KEYS  # the file paths, relative to the file

            rest, _ = read_document(str(rf.source), "symtrack.simulation.scenarios", "run file",
                                    paths=(*PATH_KEYS, ("operation", "boundary_file")))
            rest.pop("sweep", None)
        base = KINDS[detect_kind(rest, f"{rf.label} (its scenario: the file without [sweep])")]
        if base.sweep is None:
            raise ScenarioError(f"{rf.label}: its scenario is {base.what}, which a sweep does not run")
        scenario = Source(base.sweep, to_toml(rest), rf.name, rf.label)
        kind = base.sweep
    return {"scenario": scenario, "vary": vary, "ranges": {k: tuple(v) for k, v in ranges.items()} or None,
            "samples": samples, "seed": seed, "overrides": fixed, "workers": workers, "scheduler": scheduler,
            "kind": kind}


def run(spec_or_path, out=None, *, overrides=None, progress: bool | None = None):
    """Run any run file and return its result (the kind told by its sections, :data:`KINDS`).

    Parameters
    ----------
    spec_or_path : str, path or dict
        A run file (TOML), a built-in name of any kind (``symtrack scenarios``) or a document.
    out : path, optional
        The folder to write (a simulation and an MPC run: written only when given; a field study,
        an operation, a season and a sweep write their folder as they go and need it).
    overrides : list of str or dict, optional
        ``["vehicle.mass_kg=6000"]`` as ``--set`` takes them, or ``{"vehicle.mass_kg": 6000}``.
    progress : bool or None
        A progress bar: None (the default) once the run has taken 2 s, as :func:`symtrack.simulate`
        (a sweep shows its bar from the start), True from the start, False never.

    Returns
    -------
    The kind's result: :class:`symtrack.Result` (simulation),
    :class:`symtrack.control.closedloop.ClosedLoopResult` (MPC), a field study's
    ``FieldStudyResult``, an operation's or season's ``SeasonResult`` (a traffic comparison: a
    ``TrafficComparison``, its table's rows under ``["rows"]``), a sweep's ``SweepResult``.
    """
    rf = read_run_file(spec_or_path, overrides)
    kind = KINDS[rf.kind]
    if kind.needs_out and out is None:
        raise ScenarioError(f"{rf.label} is {kind.what}, which writes its folder as it goes: give out=")
    return kind.run(kind.load(rf), out, progress)
