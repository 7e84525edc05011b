"""The files of a run, and the one writer of a run's folder (atomic files: a temporary file in
the same folder, then a rename).

Files of a ``symtrack simulate`` run (schemas documented in the README):

- ``trajectory.csv``: one row per output step; header names carry units (t_s, states, commanded
  torques, then the model outputs);
- ``scenario.resolved.toml``: the scenario with every value after presets and overrides, and the
  ``symtrack_version`` that ran it;
- ``*.png``: plots (the registry of :mod:`symtrack.reports.figures`; the slow ones, the pass
  animations ``*.gif`` and the earlier passes' plots, only with ``run.all_figures``), ``report.html``;
- ``summary.json``: written last, so that its presence means the run finished.

A run's files appear together or not at all: :func:`write_folder` writes them into a staging
folder beside the output (``.<name>.staging-<pid>-*``), then moves them into place, replaces the
run's terrain file (``--terrain-out``) after them and moves summary.json in last. Killed before the
end, the output has no summary.json and the terrain file is the one it was; a later writer of the
same output removes the staging folders of dead processes. :func:`terrain_lock` keeps two
processes from writing one terrain file, :func:`output_lock` two runs from writing one folder.

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
import hashlib
import io
import json
import logging
import os
import shutil
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from ..foundations.config import to_toml, with_version
from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, check_output_file, keep_mode, real_path
from ..foundations.version import __version__
from ..terrain.storage import Terrain, file_bytes
from ..toolchain import LockBusy, file_lock
from . import validation
from .figures import TerrainRun, extras, figures
from .html import report_html

__all__ = ["MANIFEST", "MANIFEST_KIND", "MANIFEST_VERSION", "OUTPUT_LOCK", "RUN_MARKERS", "TerrainOut",
           "clear_previous_run", "output_lock", "read_manifest", "run_files", "scenario_sha256", "simulation_files",
           "is_validation", "terrain_lock", "terrain_run", "trajectory_columns", "trajectory_csv", "validation_table",
           "write_folder"]

log = logging.getLogger("symtrack.files")

# files whose presence marks a folder as a previous run's (symtrack simulate / mpc)
RUN_MARKERS = ("summary.json", "scenario.resolved.toml", "scenario.resolved.json")
# the manifest of a run's folder (module doc): the files symtrack wrote there
MANIFEST = ".symtrack-manifest.json"
MANIFEST_KIND = "symtrack-run-manifest"
MANIFEST_VERSION = 1
# the lock of a run's folder (output_lock), inside the folder while a run writes it
OUTPUT_LOCK = ".symtrack.lock"


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


def validation_table(scenario, summary: dict) -> str | None:
    """The reported-vs-simulated table (Markdown) of a validation scenario, else None. A run whose
    settings differ from the case as published (:func:`symtrack.reports.validation.differences`) gets
    the table with those settings named first, and no grade."""
    if is_validation(scenario):
        return validation.table_markdown(summary, validation.differences(scenario))
    return None


def simulation_files(scenario, runs: list, summary: dict, pass_summaries: list[dict],
                     study=None) -> dict[str, bytes | str]:
    """The folder of a ``symtrack simulate`` run (README "Output files"): the run's files with its
    trajectory figures; on the grid terrain the terrain and subsoil figures of its passes (a
    :class:`~symtrack.simulation.passes.PassStudy`), and for several passes each pass's run
    files in ``pass_<k>/``; ``validation_table.md`` for a validation scenario; ``report.html``
    with the figures. Names relative to the folder, in the order of writing.

    Without ``run.all_figures`` (the default) the slow figures are left out and report.html says
    which: the pass animations and, of several passes, the earlier passes' sinkage maps and
    trajectory plots (their ``pass_<k>/`` keep trajectory.csv, the resolved scenario and the
    summary); docs/terrain.md, "What the outputs cost"."""
    table = validation_table(scenario, summary)
    every = scenario.run.all_figures
    top: dict[str, bytes] = {}  # the files of the folder's top, besides the run files
    shown: dict[str, bytes] = {}  # the images of report.html
    passes = {}  # the files of each pass's folder (several passes)
    left_out: list[str] = []  # what report.html says was not drawn
    if study is None:
        run = runs[0]
        top.update(figures("trajectory", run))
        shown.update(top)
    else:
        src = TerrainRun(scenario, study, every)
        top.update(figures(("terrain", "subsoil"), src, every))
        left_out += [] if every else extras(("terrain", "subsoil"))
        if src.multi:
            last = len(study.runs) - 1
            for k, (res, summ) in enumerate(zip(study.runs, pass_summaries, strict=True)):
                figs = figures("trajectory", res) if every or k == last else {}
                passes.update({f"pass_{k + 1}/{n}": d for n, d in run_files(res, summ, figs).items()})
            if not every:
                left_out.append(f"the sinkage maps and the trajectory plots of passes 1 to {last} "
                                f"(sinkage_map_pass_<k>.png, pass_<k>/*.png; pass_{last + 1}/ has its plots)")
            shown.update(top)
            shown.update({f"pass_{len(study.runs)}/{n}": d for n, d in figs.items()})
        else:
            top.update(figures("trajectory", study.runs[0]))
            shown.update(top)
        run = None if src.multi else study.runs[0]
    if table is not None:
        top["validation_table.md"] = table.encode()
    omitted = ""
    if left_out:
        omitted = (f"Not drawn (run.all_figures = false, the default: the slow figures): {'; '.join(left_out)}. "
                   "Set run.all_figures = true (--set run.all_figures=true) to write them too.")
    top["report.html"] = report_html(
        f"symtrack: {scenario.name}", summary, shown, to_toml(scenario.to_dict()),
        validation.check(summary) if table is not None and not validation.differences(scenario) else None,
        summary.get("passes"),
        scenario.description, omitted=omitted).encode()
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
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        return
    doc = {"kind": MANIFEST_KIND, "schema_version": MANIFEST_VERSION, "symtrack_version": __version__,
           "written_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"), "files": names}
    atomic_write_bytes(path, (json.dumps(doc, indent=1) + "\n").encode())


def _inside(folder: Path, name: str) -> bool:
    """``folder/name`` is in ``folder`` once links are resolved (a manifest never reaches outside)."""
    try:
        return (folder / name).resolve().is_relative_to(folder.resolve())
    except OSError:
        return False


def _foreign(folder: Path, owned) -> list[str]:
    """The top-level entries of ``folder`` that no symtrack manifest lists (nor its manifest and lock)."""
    ours = {PurePosixPath(n).parts[0] for n in owned} | {MANIFEST, OUTPUT_LOCK}
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


def write_folder(out_dir, files: dict[str, bytes | str], clear: bool = True,
                 terrain: TerrainOut | None = None) -> list[Path]:
    """The one writer of a run's folder, all or nothing: ``files`` (names relative to the folder,
    sub-folders created; str written as UTF-8) are written into a staging folder beside
    ``out_dir``; then, with ``clear``, the files of a previous run are removed
    (:func:`clear_previous_run`: those its manifest lists, its summary.json first; anything else stays,
    a warning names it); the staged files are moved into place,
    every ``summary.json`` after the other files; ``terrain`` (its file, with the run in its
    history) replaces its file next, and the folder's own ``summary.json`` comes last, so that its
    presence means the folder is whole and the terrain file advanced. Interrupted or killed before
    that, the terrain file is untouched. The terrain file's lock (:func:`terrain_lock`) is held
    while it is written (a caller that read it holds it from before), and the folder's
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
        raise ScenarioError(f"cannot write the run's files into {str(out)!r}: {err.strerror or err} ({what}); "
                            "nothing of this run was put in place") from err


def _write_folder(out: Path, files: dict, clear: bool, terrain: TerrainOut | None) -> list[Path]:
    real = out.resolve()  # the staging folder beside the real folder (``--out .``, a link: its file system)
    real.parent.mkdir(parents=True, exist_ok=True)
    _remove_dead_staging(real)
    stage = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(real)}{os.getpid()}-", dir=real.parent))
    terrain_tmp = None
    names = list(files)
    if terrain is not None and not terrain.lock and Path(terrain.path).resolve().is_relative_to(out.resolve()):
        names.append(Path(terrain.path).resolve().relative_to(out.resolve()).as_posix())  # the run's own file
    try:
        for name, data in files.items():
            atomic_write_bytes(stage / name, data.encode() if isinstance(data, str) else data)
        if terrain is not None:
            data, file_id, history = file_bytes(terrain.terrain, terrain.soil, terrain.run)
            tpath = real_path(terrain.path)  # through a link: its target is replaced, the link stays
            terrain_tmp = tpath.with_name(f".{tpath.name}.{os.getpid()}.tmp")
            atomic_write_bytes(terrain_tmp, data)
            keep_mode(tpath, terrain_tmp)  # replaced in place: the file keeps its mode and owner
        # commit: nothing above touched the output or the terrain file
        owned = read_manifest(out) or []
        if clear:
            _warn_foreign(out, _foreign(out, owned), names)
            # every file owned before stays recorded until it is gone (a kill here: the next run removes it)
            _write_manifest(out, [*owned, *names])
            clear_previous_run(out, keep=names)  # its summary.json first
            _write_manifest(out, names)
        else:
            out.mkdir(parents=True, exist_ok=True)
            _write_manifest(out, [*(n for n in owned if (out / n).exists()), *names])
        for name in (n for n in files if Path(n).name == "summary.json" and (out / n).is_file()):
            (out / name).unlink()  # replaced below, after the files it vouches for
        out.mkdir(parents=True, exist_ok=True)
        last = [n for n in files if Path(n).name == "summary.json"]
        last.sort(key=lambda n: n == "summary.json")
        final = "summary.json" if "summary.json" in files else None
        for name in [n for n in files if n not in last] + [n for n in last if n != final]:
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            os.replace(stage / name, out / name)
        if terrain_tmp is not None:
            os.replace(terrain_tmp, tpath)
            terrain_tmp = None
            terrain.terrain.file_id, terrain.terrain.history = file_id, history
        if final is not None:
            os.replace(stage / final, out / final)
    finally:
        if terrain_tmp is not None and terrain_tmp.exists():
            terrain_tmp.unlink()
        shutil.rmtree(stage, ignore_errors=True)
    return sorted(out / n for n in files)


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
