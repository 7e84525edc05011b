"""The files of a run, and the one writer of a run's folder (atomic files: a temporary file in
the same folder, then a rename).

Files of a ``symtrack simulate`` run (schemas documented in docs/outputs.md):

- ``trajectory.csv``: one row per output step; header names carry units (t_s, states, commanded
  torques, then the model outputs);
- ``scenario.resolved.toml``: the scenario with every value after presets and overrides, and the
  ``symtrack_version`` that ran it;
- ``*.png``: plots (the registry of :mod:`symtrack.reports.figures`; the slow ones, the pass
  animations ``*.gif`` and the earlier passes' plots, only with ``run.all_figures``), ``report.html``;
- ``summary.json``: written last, so that its presence means the run finished.

A run commits once: its files, its terrain file's update and its summary become the run's in one
atomic step. :func:`write_folder` writes the files into a staging folder beside the output
(``.<name>.staging-<pid>-*``) and the terrain file (``--terrain-out``, the run in its history) into a
temporary file beside it (``.<file>.<run id>.tmp``); then it writes the folder's journal,
``.symtrack-commit.json`` (schema: ``kind`` "symtrack-commit", ``schema_version`` 1,
``symtrack_version``, ``pid``, ``staging``: the staging folder, ``files``: the names in the order of
writing, ``manifest``: the names the manifest will list, ``clear``, ``terrain``: null, or the terrain
file's ``path``, ``tmp``, the run's ``run_id``, the new ``file_id``, the ``input_file_id`` it started
from, ``scenario``, ``scenario_sha256``, ``passes``). The commit point is the rename of the
temporary terrain file over the terrain file (without a terrain file: the journal's rename). After
it, the earlier run's files are removed, the staged files moved into place (every summary.json after
the files it vouches for, the folder's own last), the staging folder and then the journal removed.

Killed at any step, a run leaves the old state or the new one. Before the commit point the terrain
file and the folder's files are as they were: the next writer of the folder finds a journal whose
run its terrain file does not hold and removes the journal, the staging folder and the temporary
file. After it, the terrain file holds the run: the next writer of the folder (every
:func:`write_folder`, :func:`recover`) takes the journal's remaining steps first, so that the folder
becomes that run's whole folder; ``symtrack simulate`` and ``symtrack mpc`` do this before their
run and, when the journal is that of the same command (the scenario's hash, the terrain file, the file it starts
from), stops there instead of applying the passes again. A journal that names anything but its own
commit's files (a name outside the folder, a staging folder not beside it, a temporary file not the
terrain file's) is removed with a warning and nothing it names is touched. The temporary files of
killed writes (``.<file>.*.tmp`` beside a terrain file or the manifest) are removed by the next
holder of that file's lock. :func:`terrain_lock` keeps two processes from writing one terrain file,
:func:`output_lock` two runs from writing one folder. With :data:`KILL_AT_STEP_ENV` = k in the
environment a process kills itself before the k-th step of its commits (each write, rename and
removal; :data:`COMMIT_STEPS` names them): the tests' fault injection (tests/test_commit_point.py).

A run owns only what it writes: every write records the files it put in the folder in the folder's
manifest, ``.symtrack-manifest.json`` (:func:`read_manifest`; schema: ``kind``
"symtrack-run-manifest", ``schema_version`` 1, ``symtrack_version``, ``written_utc``, ``files``: the
names relative to the folder, sorted). A later run into the folder removes or replaces only the files
an earlier manifest lists (and the ones it writes itself); anything else stays, and a folder holding
such foreign files gets a one-line warning.

:func:`simulation_files` composes the folder of a ``symtrack simulate`` run (one pass, or a
terrain study's passes in ``pass_<k>/``), :func:`write_folder` writes any run's folder
(``simulate``, ``mpc``, a field study's) and :func:`clear_previous_run` removes a previous
run's files (those of its manifest) first.
"""

from __future__ import annotations

import contextlib
import datetime
import glob
import hashlib
import io
import json
import logging
import os
import shutil
import signal
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from ..foundations.config import to_toml, with_version
from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, check_output_file, real_path, write_new_file
from ..foundations.version import __version__
from ..terrain.storage import Terrain, file_bytes, file_identity
from ..toolchain import LockBusy, file_lock
from . import validation
from .html import report_html

__all__ = ["COMMIT_STEPS", "JOURNAL", "KILL_AT_STEP_ENV", "MANIFEST", "MANIFEST_KIND", "MANIFEST_VERSION",
           "OUTPUT_LOCK", "RUN_MARKERS", "TerrainOut", "clear_previous_run", "finished_before", "is_validation",
           "output_lock", "read_manifest", "recover", "run_files", "scenario_sha256", "simulation_files",
           "terrain_lock", "terrain_run", "trajectory_columns", "trajectory_csv", "validation_table", "write_folder"]

log = logging.getLogger("symtrack.files")

# files whose presence marks a folder as a previous run's (symtrack simulate / mpc)
RUN_MARKERS = ("summary.json", "scenario.resolved.toml", "scenario.resolved.json")
# the manifest of a run's folder (module doc): the files symtrack wrote there
MANIFEST = ".symtrack-manifest.json"
MANIFEST_KIND = "symtrack-run-manifest"
MANIFEST_VERSION = 1
# the lock of a run's folder (output_lock), inside the folder while a run writes it
OUTPUT_LOCK = ".symtrack.lock"
# the journal of a run's commit (module doc), in the folder from just before the commit point until the
# run's files are in place
JOURNAL = ".symtrack-commit.json"
JOURNAL_KIND = "symtrack-commit"
JOURNAL_VERSION = 1
# fault injection (the tests): with this variable = k in the environment, the process kills itself
# (SIGKILL) at the k-th step of its commits (:func:`_step`); COMMIT_STEPS names the steps taken so far
KILL_AT_STEP_ENV = "SYMTRACK_KILL_AT_COMMIT_STEP"
COMMIT_STEPS: list[str] = []
_step_count = 0


def trajectory_columns(res) -> tuple[list[str], np.ndarray]:
    names = ["t_s"] + list(res.state_names) + ["torque_cmd_left_N_m", "torque_cmd_right_N_m"]
    cols = [res.t[:, None], res.X, res.U]
    extra = [i for i, n in enumerate(res.output_names) if n not in names]
    names += [res.output_names[i] for i in extra]
    cols.append(res.Y[:, extra])
    return names, np.hstack(cols)


def trajectory_csv(res) -> str:
    names, data = trajectory_columns(res)
    buf = io.StringIO()
    np.savetxt(buf, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    return buf.getvalue()


def run_files(res, summary: dict, plots: dict[str, bytes]) -> dict[str, bytes | str]:
    """The files of one run: trajectory.csv, scenario.resolved.toml, ``plots`` (any further
    files, in order), summary.json."""
    return {"trajectory.csv": trajectory_csv(res),
            "scenario.resolved.toml": to_toml(with_version(res.scenario.to_dict())), **plots,
            "summary.json": json.dumps(summary, indent=2) + "\n"}


def is_validation(scenario) -> bool:
    """Whether ``scenario`` is a run of the validation manoeuvre (a scenario named after it that stops
    counting from its idle event): its folder gets ``validation_table.md``."""
    return scenario.run.stop_distance_event == "idle" and "validation" in scenario.name


def validation_differences(scenario, summary: dict) -> list[str]:
    """What sets this run apart from the validation case as published: its settings
    (:func:`symtrack.reports.validation.differences`) and a run that ended before its distance stop."""
    differ = validation.differences(scenario)
    if summary.get("distance_stop_reached") is False:  # stopped by run.duration_s (or an error) first
        differ.append(f"the run ended by {summary.get('stopped_by', 'its duration')} before its distance "
                      f"stop (published: {scenario.run.stop_after_distance_m} m after the idle event)")
    return differ


def validation_table(scenario, summary: dict) -> str | None:
    """The reported-vs-simulated table (Markdown) of a validation scenario, else None. A run that
    differs from the case as published (:func:`validation_differences`) gets the table with those
    differences named first, and no grade."""
    if is_validation(scenario):
        return validation.table_markdown(summary, validation_differences(scenario, summary))
    return None


def validation_rows(scenario, summary: dict) -> list | None:
    """The graded (quantity, reported, simulated, within) rows of a run of the validation case as
    published, else None (another scenario, or a run that differs from the case: it is compared, not
    graded; :func:`validation_table`)."""
    if is_validation(scenario) and not validation_differences(scenario, summary):
        return validation.check(summary)
    return None


def figures(kinds, source, all_figures: bool = True) -> dict[str, bytes]:
    """:func:`symtrack.reports.figures.figures`, imported when first drawn: the plotting modules (matplotlib,
    a second of import) are not loaded by a command that only reads its run file or fails early."""
    from . import figures as registry

    return registry.figures(kinds, source, all_figures)


def extras(kinds) -> list[str]:
    """:func:`symtrack.reports.figures.extras` (imported when first asked, as :func:`figures`)."""
    from . import figures as registry

    return registry.extras(kinds)


def what_ran(scenario, summary: dict, ground: str | None = None, integrator: str | None = None) -> str:
    """One sentence of a run's report: the machine with the mass it ran with, the soil, the terrain (or
    ``ground``, e.g. an MPC's plant) and the integrator (``integrator``, else the summary's or the
    scenario's; an empty string leaves it out). The resolved scenario at the page's end has every value."""
    from .html import machine_facts

    (_, vehicle), (_, soil) = machine_facts(scenario.vehicle_preset, scenario.soil_preset,
                                            getattr(scenario, "params", None))
    if ground is None:
        ground = "the homogeneous terrain" if scenario.terrain is None else "the grid terrain"
    if integrator is None:
        integrator = summary.get("integrator", scenario.run.integrator)
    return f"Ran: {vehicle} on {soil}, {ground}" + (f", integrator {integrator}." if integrator else ".")


def simulation_files(scenario, runs: list, summary: dict, pass_summaries: list[dict],
                     study=None) -> dict[str, bytes | str]:
    """The folder of a ``symtrack simulate`` run (docs/outputs.md): the run's files with its
    trajectory figures; on the grid terrain the terrain and subsoil figures of its passes (a
    :class:`~symtrack.simulation.passes.PassStudy`), and for several passes each pass's run
    files in ``pass_<k>/``; ``validation_table.md`` for a validation scenario; ``report.html``
    with the figures. Names relative to the folder, in the order of writing.

    Without ``run.all_figures`` (the default) the slow figures are left out and report.html says
    which: the pass animations and, of several passes, the earlier passes' sinkage maps and
    trajectory plots (their ``pass_<k>/`` keep trajectory.csv, the resolved scenario and the
    summary); docs/terrain.md, "What the outputs cost"."""
    from .figures import TerrainRun

    table = validation_table(scenario, summary)
    every = scenario.run.all_figures
    draw = scenario.run.figures  # false: no figure at all (report.html says so)

    def figures_of(kinds, source, *every_):
        return figures(kinds, source, *every_) if draw else {}

    top: dict[str, bytes] = {}  # the files of the folder's top, besides the run files
    shown: dict[str, bytes] = {}  # the images of report.html
    passes = {}  # the files of each pass's folder (several passes)
    left_out: list[str] = []  # what report.html says was not drawn
    if study is None:
        run = runs[0]
        top.update(figures_of("trajectory", run))
        shown.update(top)
    else:
        src = TerrainRun(scenario, study, every)
        top.update(figures_of(("terrain", "subsoil"), src, every))
        left_out += [] if every else extras(("terrain", "subsoil"))
        if src.multi:
            last = len(study.runs) - 1
            for k, (res, summ) in enumerate(zip(study.runs, pass_summaries, strict=True)):
                figs = figures_of("trajectory", res) if every or k == last else {}
                passes.update({f"pass_{k + 1}/{n}": d for n, d in run_files(res, summ, figs).items()})
            if not every:
                left_out.append(f"the sinkage maps and the trajectory plots of passes 1 to {last} "
                                f"(sinkage_map_pass_<k>.png, pass_<k>/*.png; pass_{last + 1}/ has its plots)")
            shown.update(top)
            shown.update({f"pass_{len(study.runs)}/{n}": d for n, d in figs.items()})
        else:
            top.update(figures_of("trajectory", study.runs[0]))
            shown.update(top)
        run = None if src.multi else study.runs[0]
    if table is not None:
        top["validation_table.md"] = table.encode()
    omitted = ""
    if not draw:
        omitted = ("No figures drawn (run.figures = false). Run the scenario again with run.figures = true "
                   "(--set run.figures=true) to draw them.")
    elif left_out:
        omitted = (f"Not drawn (run.all_figures = false, the default: the slow figures): {'; '.join(left_out)}. "
                   "Set run.all_figures = true (--set run.all_figures=true) to write them too.")
    top["report.html"] = report_html(
        f"symtrack: {scenario.name}", summary, shown, to_toml(scenario.to_dict()),
        validation_rows(scenario, summary),
        summary.get("passes"),
        " ".join(filter(None, [scenario.description, what_ran(scenario, summary)])), omitted=omitted).encode()
    if run is not None:
        return run_files(run, summary, top)
    return {**passes, **top, "summary.json": json.dumps(summary, indent=2) + "\n"}


@dataclass(frozen=True)
class TerrainOut:
    """A terrain file a run writes (``--terrain-out``): ``path``, the terrain, its soil parameters,
    and ``run``, the history entry of the run (:func:`terrain_run`); ``lock``: hold the file's
    :func:`terrain_lock` while writing it (not for a file inside the run's own folder, as a field
    study's field.npz, which no other run writes)."""

    path: Path
    terrain: Terrain
    soil: dict
    run: dict
    lock: bool = True


def scenario_sha256(scenario) -> str:
    """SHA-256 (hexadecimal) of the scenario's resolved TOML (scenario.resolved.toml without its
    ``symtrack_version`` line: the same scenario hashes the same under every version)."""
    return hashlib.sha256(to_toml(scenario.to_dict()).encode()).hexdigest()


def terrain_run(scenario, passes: int) -> dict:
    """A new run's entry of a terrain file's history (:mod:`symtrack.terrain.storage`): a new run
    id, the time now (UTC), the scenario's name and hash, its passes."""
    return {"run_id": uuid.uuid4().hex, "time_utc": datetime.datetime.now(datetime.UTC).isoformat(
        timespec="seconds"), "scenario": scenario.name, "scenario_sha256": scenario_sha256(scenario),
        "passes": int(passes)}


_HELD: set[str] = set()  # the terrain files whose lock this process holds


@contextlib.contextmanager
def terrain_lock(path, option: str = "--terrain-out"):
    """Hold ``<terrain file>.lock`` (beside the file, on its real path: links resolved) while a
    process reads and writes the terrain file ``path`` (a run, ``symtrack terrain convert``): a second
    process that would write the same file, under any name, fails at once with a message naming the
    holder, instead of the two writers' results mixing. The lock goes with its holder, killed or not;
    the ``.lock`` file is removed on every exit but a kill (a killed holder's is taken over by the next)."""
    path = Path(path)
    real = real_path(path)
    real.parent.mkdir(parents=True, exist_ok=True)
    key = str(real)
    if key in _HELD:  # this process holds it already (the CLI around Result.write): re-entrant
        yield path
        return
    try:
        with file_lock(real.with_name(real.name + ".lock"), wait=False, remove=True):
            _remove_stale_tmp(real)  # a killed writer's temporary files: no other writer now
            _HELD.add(key)
            try:
                yield path
            finally:
                _HELD.discard(key)
    except LockBusy as err:
        where = "" if real == path.absolute() else f" ({real})"
        raise ScenarioError(f"{option} {str(path)!r}{where}: another symtrack process (pid {err.holder or 'unknown'}) "
                            "is writing this terrain file; wait for it to finish, or give another file") from None


@contextlib.contextmanager
def output_lock(out_dir, option: str = "--out"):
    """Hold the lock of the run's folder ``out_dir`` (``<folder>/.symtrack.lock`` on its real path, links
    resolved; the folder is created) from before a run's work until its files are in place: a second run
    into the same folder fails at once with a ScenarioError naming the folder and the holder's process
    id, instead of the two runs' files mixing. The lock file is removed on every exit but a kill (a
    killed holder's lock is free: flock); a folder this lock created and nothing was written into is
    removed with it. Re-entrant within a process (the CLI around :func:`write_folder`)."""
    out = Path(out_dir)
    real = out.expanduser().resolve()
    key = "folder:" + str(real)
    if key in _HELD:
        yield out
        return
    created = not real.exists()
    real.mkdir(parents=True, exist_ok=True)
    try:
        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(file_lock(real / OUTPUT_LOCK, wait=False, remove=True))
            except LockBusy as err:
                raise ScenarioError(f"{option} {str(out)!r}: another symtrack run (pid {err.holder or 'unknown'}) is "
                                    f"writing into this folder ({real}); wait for it to finish, or give another "
                                    f"{option}") from None
            _HELD.add(key)
            try:
                yield out
            finally:
                _HELD.discard(key)
    finally:
        if created:
            with contextlib.suppress(OSError):
                real.rmdir()  # only when empty: a run that wrote nothing leaves no folder


def _safe_name(name) -> str | None:
    """A manifest's file name as a relative POSIX path inside the folder, or None (absolute, ``..``, empty)."""
    if not isinstance(name, str) or not name or "\\" in name:
        return None
    p = PurePosixPath(name)
    if p.is_absolute() or any(part in ("", ".", "..") for part in p.parts) or p.as_posix() != name:
        return None
    return name


def read_manifest(folder) -> list[str] | None:
    """The files an earlier symtrack run recorded in ``folder``'s manifest (:data:`MANIFEST`, module
    doc), names relative to the folder; None when the folder has none, or a file of that name that is
    no symtrack manifest (a warning). Names that would leave the folder are dropped."""
    path = Path(folder) / MANIFEST
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as err:
        log.warning("%s: not a symtrack manifest (%s); the files in %s are taken as someone else's", path, err,
                    folder)
        return None
    if not (isinstance(doc, dict) and doc.get("kind") == MANIFEST_KIND and isinstance(doc.get("files"), list)
            and isinstance(doc.get("schema_version"), int) and 1 <= doc["schema_version"] <= MANIFEST_VERSION):
        log.warning("%s: not a symtrack manifest of schema_version 1 to %d; the files in %s are taken as someone "
                    "else's", path, MANIFEST_VERSION, folder)
        return None
    return sorted({n for n in map(_safe_name, doc["files"]) if n is not None})


def _write_manifest(folder: Path, names) -> None:
    """Record ``names`` (relative to ``folder``) as the files symtrack wrote there (none: no manifest)."""
    path = folder / MANIFEST
    names = sorted(set(names))
    if not names:
        if path.exists():
            _step("removed the manifest")
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        return
    doc = {"kind": MANIFEST_KIND, "schema_version": MANIFEST_VERSION, "symtrack_version": __version__,
           "written_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"), "files": names}
    atomic_write_bytes(path, (json.dumps(doc, indent=1) + "\n").encode(),
                       before_rename=lambda: _step("manifest written, not yet renamed"))


def _inside(folder: Path, name: str) -> bool:
    """``folder/name`` is in ``folder`` once links are resolved (a manifest never reaches outside)."""
    try:
        return (folder / name).resolve().is_relative_to(folder.resolve())
    except OSError:
        return False


def _foreign(folder: Path, owned) -> list[str]:
    """The top-level entries of ``folder`` that no symtrack manifest lists (nor its manifest and lock)."""
    ours = {PurePosixPath(n).parts[0] for n in owned} | {MANIFEST, OUTPUT_LOCK, JOURNAL}
    try:
        return sorted(p.name for p in folder.iterdir() if p.name not in ours)
    except OSError:
        return []


def _warn_foreign(folder: Path, foreign: list[str], writing) -> None:
    if not foreign:
        return
    tops = {PurePosixPath(n).parts[0] for n in writing}
    replaced = [n for n in foreign if n in tops]
    kept = [n for n in foreign if n not in tops]

    def names(xs):
        return ", ".join(xs[:5]) + (f" and {len(xs) - 5} more" if len(xs) > 5 else "")

    parts = []
    if kept:
        parts.append(f"left as they are: {names(kept)}")
    if replaced:
        parts.append(f"replaced by this run's file of the same name: {names(replaced)}")
    log.warning("%s holds %d file(s) that no symtrack run recorded as its own (in %s); %s", folder.resolve(),
                len(foreign),
                MANIFEST, "; ".join(parts))


def _staging_prefix(out: Path) -> str:
    return f".{out.name}.staging-"


def _remove_dead_staging(out: Path) -> None:
    """Remove the staging folders of ``out`` whose process is gone (a killed writer's)."""
    if not out.parent.is_dir():
        return
    for p in out.parent.glob(_staging_prefix(out) + "*"):
        pid = p.name[len(_staging_prefix(out)):].split("-")[0]
        if pid.isdigit() and int(pid) != os.getpid():
            try:
                os.kill(int(pid), 0)
                continue  # alive: another writer's
            except ProcessLookupError:
                pass
            except PermissionError:
                continue
            shutil.rmtree(p, ignore_errors=True)


def _step(what: str) -> None:
    """One step of a commit (a write, a rename, a removal), about to be taken: counted, and with
    :data:`KILL_AT_STEP_ENV` = k in the environment the k-th step of the process kills it (SIGKILL)
    before it is taken (the tests' fault injection; module doc)."""
    global _step_count
    _step_count += 1
    if len(COMMIT_STEPS) < 100_000:
        COMMIT_STEPS.append(what)
    at = os.environ.get(KILL_AT_STEP_ENV, "")
    if at.isdigit() and int(at) == _step_count:
        os.kill(os.getpid(), signal.SIGKILL)


def _remove_stale_tmp(path: Path) -> None:
    """Remove the temporary files beside the file ``path`` that a killed writer left
    (``.<name>.*.tmp``: a terrain file's at a run's commit, :func:`atomic_write_bytes`'s); called by the
    holder of its lock (the file's own, or the run folder's), so no writer is using them."""
    with contextlib.suppress(OSError):
        for p in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
            with contextlib.suppress(OSError):
                p.unlink()


def _terrain_committed(record: dict) -> bool:
    """Whether the terrain file of a journal's ``record`` holds its run (the run's commit point passed)."""
    file_id, runs = file_identity(record["path"])
    return file_id == record["file_id"] or record["run_id"] in runs


def _read_journal(out: Path) -> dict | None:
    """The journal of an interrupted commit in ``out`` (module doc), or None; a damaged one is removed
    with a warning (it was written atomically: only someone else's file of that name can be damaged)."""
    path = out / JOURNAL
    try:
        j = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as err:
        log.warning("%s: not a symtrack commit journal (%s); removed", path, err)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    if not _journal_ok(out, j):
        log.warning("%s: not a symtrack commit journal of schema_version 1 for this folder; removed", path)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    return j


def _journal_ok(out: Path, j) -> bool:
    """A journal of this folder's commit: its keys, its names inside the folder, its staging folder beside
    the folder (with the staging prefix) and its temporary terrain file beside the terrain file (with the
    run's name): nothing a journal names outside those is ever moved or removed."""
    keys = ("staging", "files", "manifest", "clear", "terrain")
    if not (isinstance(j, dict) and j.get("kind") == JOURNAL_KIND and all(k in j for k in keys)
            and isinstance(j["files"], list) and isinstance(j["manifest"], list) and isinstance(j["staging"], str)):
        return False
    if any(_safe_name(n) is None for n in (*j["files"], *j["manifest"])):
        return False
    real = out.resolve()
    stage = Path(j["staging"])
    if stage.parent != real.parent or not stage.name.startswith(_staging_prefix(real)):
        return False
    t = j["terrain"]
    if t is None:
        return True
    if not (isinstance(t, dict) and all(isinstance(t.get(k), str) for k in ("path", "tmp", "run_id", "file_id"))):
        return False
    tpath, tmp = Path(t["path"]), Path(t["tmp"])
    return tmp.parent == tpath.parent and tmp.name == f".{tpath.name}.{t['run_id']}.tmp"


def _recover(out: Path) -> dict | None:
    """Finish or undo the commit a killed run left in ``out`` (held by this process's
    :func:`output_lock`; module doc): with a journal whose commit point passed (no terrain file, or the
    terrain file holds the run), its staged files are moved into place and the journal is returned;
    otherwise its staging folder and temporary terrain file are removed (the folder and the terrain file
    are as before that run) and None is returned. The temporary files of killed writes of the folder's
    manifest and journal are removed either way."""
    for name in (MANIFEST, JOURNAL):
        _remove_stale_tmp(out / name)
    j = _read_journal(out)
    if j is None:
        return None
    t = j["terrain"]
    if t is None or _terrain_committed(t):
        log.warning("%s: completing the files of the run that was stopped after its commit point%s", out,
                    f" (run {t['run_id']}; the terrain file {t['path']} holds it)" if t else "")
        _apply(out, j)
        return j
    with contextlib.suppress(OSError):
        Path(t["tmp"]).unlink()
    shutil.rmtree(j["staging"], ignore_errors=True)
    with contextlib.suppress(FileNotFoundError):
        (out / JOURNAL).unlink()
    return None


def recover(out_dir) -> dict | None:
    """Finish or undo the commit of a run killed in ``out_dir`` (module doc), under the folder's lock:
    the journal (a dict; ``terrain``: the terrain file's path, the run's ``run_id``, ``scenario_sha256``,
    ``input_file_id`` and the new ``file_id``) of a run whose files this call completed, else None.
    Every write into the folder does this first; ``symtrack simulate`` does it before its run, to know
    a rerun of a run that was killed after its commit point (it does not apply the passes again)."""
    out = Path(out_dir)
    if not (out / JOURNAL).is_file() and not any(out.glob(f".{glob.escape(MANIFEST)}.*.tmp")):
        return None
    with output_lock(out):
        return _recover(out)


def finished_before(out_dir, scenario, terrain_in, terrain_out) -> dict | None:
    """For a command about to run ``scenario`` from ``terrain_in`` (a terrain file, or None for a new
    field) into ``out_dir`` and ``terrain_out``: :func:`recover` the folder, and when the journal it
    completed is this same run's (the same scenario hash and terrain file, started from the file that
    run started from or wrote: a rerun after a kill past the commit point), that journal's terrain
    record; the command then stops there instead of applying the passes again. None otherwise (the
    run goes ahead)."""
    journal = recover(out_dir)
    t = None if journal is None else journal.get("terrain")
    if t is None or terrain_out is None or Path(t["path"]) != real_path(terrain_out) \
            or t.get("scenario_sha256") != scenario_sha256(scenario):
        return None
    start = file_identity(terrain_in)[0] if terrain_in else None
    return t if start in (t.get("input_file_id"), t["file_id"]) else None


def write_folder(out_dir, files: dict[str, bytes | str | Path], clear: bool = True,
                 terrain: TerrainOut | None = None) -> list[Path]:
    """The one writer of a run's folder, committed once (module doc): ``files`` (names relative to
    the folder, sub-folders created; str written as UTF-8) are written into a staging folder beside
    ``out_dir`` (a :class:`~pathlib.Path` value: a finished file the caller wrote, moved into the staging
    folder, so that a large file, a region's map, is not held in memory; the caller gives up the file) and
    ``terrain`` (its file, with the run in its history) into a temporary file beside
    its file; then the journal; then the commit point: the terrain file's rename (without ``terrain``,
    the journal's); then, with ``clear``, the files of a previous run are removed
    (:func:`clear_previous_run`: those its manifest lists, its summary.json first; anything else stays,
    a warning names it); the staged files are moved into place, every ``summary.json`` after the other
    files and the folder's own last; the journal goes last of all. Interrupted or killed before the
    commit point, the folder and the terrain file are as they were; after it, the next writer of the
    folder (or :func:`recover`) completes the files. The terrain file's lock (:func:`terrain_lock`) is
    held while it is written (a caller that read it holds it from before), and the folder's
    (:func:`output_lock`) while it is written. The folder's manifest records the files written (with
    ``clear``: this write's; without: added to those of the earlier writes still there; and a
    ``terrain`` file inside the folder that is the run's own, ``lock=False``). Returns the paths
    written, sorted."""
    out = Path(out_dir)
    if terrain is not None:
        check_output_file(str(terrain.path), "terrain_out")  # a read-only file is refused, not replaced
    try:
        with (output_lock(out), terrain_lock(terrain.path) if terrain is not None and terrain.lock
              else contextlib.nullcontext()):
            return _write_folder(out, files, clear, terrain)
    except OSError as err:  # a folder made read-only, a full disk: an error naming the file, no traceback
        what = err.filename if err.filename is not None else out
        done = ("the run's commit point had passed: the next symtrack run into this folder completes its files"
                if (out / JOURNAL).is_file() else "nothing of this run was put in place")
        raise ScenarioError(f"cannot write the run's files into {str(out)!r}: {err.strerror or err} ({what}); "
                            f"{done}") from err


def _write_folder(out: Path, files: dict, clear: bool, terrain: TerrainOut | None) -> list[Path]:
    real = out.resolve()  # the staging folder beside the real folder (``--out .``, a link: its file system)
    real.parent.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    _recover(out)  # a killed run's commit: completed or undone first
    _remove_dead_staging(real)
    stage = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(real)}{os.getpid()}-", dir=real.parent))
    terrain_tmp = None
    committed = False
    names = list(files)
    if terrain is not None and not terrain.lock and Path(terrain.path).resolve().is_relative_to(out.resolve()):
        names.append(Path(terrain.path).resolve().relative_to(out.resolve()).as_posix())  # the run's own file
    try:
        for name, data in files.items():
            if isinstance(data, Path):  # a finished file of this writer's: moved in (renamed on one file system)
                (stage / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.move(data, stage / name)
            else:
                atomic_write_bytes(stage / name, data.encode() if isinstance(data, str) else data)
            _step(f"staged {name}")
        record = None
        if terrain is not None:
            data, file_id, history = file_bytes(terrain.terrain, terrain.soil, terrain.run)
            tpath = real_path(terrain.path)  # through a link: its target is replaced, the link stays
            _remove_stale_tmp(tpath)  # a killed writer's (this process holds the file's lock, or its folder's)
            terrain_tmp = tpath.with_name(f".{tpath.name}.{terrain.run['run_id']}.tmp")
            write_new_file(terrain_tmp, data, mode_of=tpath)  # replaced in place: it keeps its mode and owner
            _step("terrain file written to its temporary file")
            record = {"path": str(tpath), "tmp": str(terrain_tmp), "run_id": terrain.run["run_id"],
                      "file_id": file_id, "input_file_id": terrain.terrain.file_id,
                      "scenario": terrain.run.get("scenario"), "scenario_sha256": terrain.run.get("scenario_sha256"),
                      "passes": terrain.run.get("passes")}
        # nothing above touched the folder or the terrain file
        if clear:
            _warn_foreign(out, _foreign(out, read_manifest(out) or []), names)
        journal = {"kind": JOURNAL_KIND, "schema_version": JOURNAL_VERSION, "symtrack_version": __version__,
                   "pid": os.getpid(), "staging": str(stage), "files": list(files), "manifest": names,
                   "clear": bool(clear), "terrain": record}
        atomic_write_bytes(out / JOURNAL, (json.dumps(journal, indent=1) + "\n").encode(),
                           before_rename=lambda: _step("journal written, not yet renamed"))
        committed = terrain is None
        if terrain_tmp is not None:
            _step("terrain file renamed into place (the commit point)")
            os.replace(terrain_tmp, tpath)
            committed = True
            terrain_tmp = None
            terrain.terrain.file_id, terrain.terrain.history = file_id, history
        _apply(out, journal)
    finally:
        if not committed:  # stopped before the commit point: nothing of this run stays
            if terrain_tmp is not None:
                with contextlib.suppress(OSError):
                    terrain_tmp.unlink()
            with contextlib.suppress(OSError, ValueError, AttributeError):
                if json.loads((out / JOURNAL).read_text()).get("staging") == str(stage):  # this write's
                    (out / JOURNAL).unlink()
            shutil.rmtree(stage, ignore_errors=True)
    return sorted(out / n for n in files)


def _apply(out: Path, journal: dict) -> None:
    """The commit's second half, from the journal (module doc): the previous run's files removed
    (``clear``), the manifest written, the staged files moved into place (every summary.json after the
    others, the folder's own last), the staging folder and the journal removed. Taken again from any
    point it was stopped at, it gives the same folder (a file staged and not yet moved is moved; one
    moved is left)."""
    stage = Path(journal["staging"])
    files, names = list(journal["files"]), list(journal["manifest"])
    owned = read_manifest(out) or []
    if journal["clear"]:
        # every file owned before stays recorded until it is gone (stopped here: the next write removes it)
        _write_manifest(out, [*owned, *names])
        clear_previous_run(out, keep=names)  # its summary.json first
        _write_manifest(out, names)
    else:
        _write_manifest(out, [*(n for n in owned if (out / n).exists()), *names])
    last = [n for n in files if Path(n).name == "summary.json"]
    last.sort(key=lambda n: n == "summary.json")
    final = "summary.json" if "summary.json" in files else None
    for name in last:  # an earlier summary.json goes before the files it would vouch for change
        if (stage / name).is_file() and (out / name).is_file():
            _step(f"removed the earlier {name}")
            (out / name).unlink()
    for name in [n for n in files if n not in last] + [n for n in last if n != final] + ([final] if final else []):
        if (stage / name).is_file():
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            _step(f"renamed {name} into place")
            os.replace(stage / name, out / name)
    missing = [n for n in files if not (out / n).is_file()]
    if missing:
        log.warning("%s: the staged files of its last run are gone (%s ...); the folder lacks them", out, missing[0])
    _step("removed the staging folder")
    shutil.rmtree(stage, ignore_errors=True)
    _step("removed the journal")
    with contextlib.suppress(FileNotFoundError):
        (out / JOURNAL).unlink()


def clear_previous_run(out_dir, files=None, kind: str | None = None, keep=()) -> list[Path]:
    """Remove the files of a previous run from ``out_dir``, so that a reused ``--out`` never
    mixes two runs' files; anything else is left alone. Returns what was removed.

    Without ``files``: the files the folder's manifest lists (:func:`read_manifest`; a folder without
    one is not touched), but those in ``keep`` (the files a run is about to replace), summary.json
    first, sub-folders left empty removed; the manifest then lists what is left of them (``keep``).
    With ``files`` (names relative to the folder) and ``kind`` (a summary.json whose ``"kind"`` is
    ``kind``, e.g. a field study's; without ``kind`` one of :data:`RUN_MARKERS` must be there)
    exactly those, sub-folders' first, then the top's with summary.json last (an interrupted clean-up
    is still recognised), and sub-folders left empty (or holding only their manifest)."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return []
    removed = []
    if files is None:
        owned = read_manifest(out_dir)
        if owned is None:
            return []
        keep = set(keep)
        # the summary first: a clean-up stopped half-way leaves no summary.json claiming a whole run
        gone = sorted((n for n in owned if n not in keep and _inside(out_dir, n)),
                      key=lambda n: (Path(n).name != "summary.json", n.count("/"), n))
        for name in gone:
            p = out_dir / name
            if p.is_file() or p.is_symlink():
                _step(f"removed the earlier run's {name}")
                p.unlink()
                removed.append(p)
        _remove_empty_parents(out_dir, gone)
        _write_manifest(out_dir, [n for n in owned if n in keep])
        return removed
    if kind is not None:
        try:
            old = json.loads((out_dir / "summary.json").read_text())
        except (OSError, ValueError):
            return []
        if not isinstance(old, dict) or old.get("kind") != kind:
            return []
    elif not any((out_dir / m).exists() for m in RUN_MARKERS):
        return []
    names = sorted(files, key=lambda n: (Path(n).parent == Path("."), Path(n).name == "summary.json"))
    for name in names:
        p = out_dir / name
        if p.is_file():
            p.unlink()
            removed.append(p)
    _remove_empty_parents(out_dir, names)
    return removed


def _remove_empty_parents(out_dir: Path, names) -> None:
    """Remove the sub-folders of ``names`` (deepest first) that are empty, or hold only their manifest."""
    subs = sorted({out_dir / q for n in names for q in PurePosixPath(n).parents if str(q) != "."},
                  key=lambda p: -len(p.parts))
    for sub in subs:
        if not sub.is_dir() or sub.is_symlink():
            continue
        left = [p.name for p in sub.iterdir()]
        if left == [MANIFEST]:
            (sub / MANIFEST).unlink()
            left = []
        if not left:
            sub.rmdir()
