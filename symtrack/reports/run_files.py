"""The files of a run, and the one writer of a run's folder (atomic files: a temporary file in
the same folder, then a rename).

Files of a ``symtrack simulate`` run (schemas documented in the README):

- ``trajectory.csv``: one row per output step; header names carry units (t_s, states, commanded
  torques, then the model outputs);
- ``scenario.resolved.toml``: the scenario with every value after presets and overrides;
- ``*.png``: plots (the registry of :mod:`symtrack.reports.figures`), ``report.html``;
- ``summary.json``: written last, so that its presence means the run finished.

:func:`simulation_files` composes the folder of a ``symtrack simulate`` run (one pass, or a
terrain study's passes in ``pass_<k>/``), :func:`write_folder` writes any run's folder
(``simulate``, ``mpc``, a field study's) and :func:`clear_previous_run` removes a previous
run's files first.
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np

from ..foundations.config import to_toml
from ..foundations.files import atomic_write_bytes
from . import validation
from .figures import TerrainRun, figures
from .html import report_html

__all__ = ["RUN_MARKERS", "RUN_SUFFIXES", "clear_previous_run", "run_files", "simulation_files", "trajectory_columns",
           "trajectory_csv", "validation_table", "write_folder"]

# files whose presence marks a folder as a previous run's (symtrack simulate / mpc)
RUN_MARKERS = ("summary.json", "scenario.resolved.toml", "scenario.resolved.json")
# what a run writes into its folder (and what clear_previous_run removes)
RUN_SUFFIXES = (".csv", ".png", ".json", ".toml", ".md", ".html", ".gif", ".mp4")


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
    return {"trajectory.csv": trajectory_csv(res), "scenario.resolved.toml": to_toml(res.scenario.to_dict()),
            **plots, "summary.json": json.dumps(summary, indent=2) + "\n"}


def validation_table(scenario, summary: dict) -> str | None:
    """The reported-vs-simulated table (Markdown) of a validation scenario, else None."""
    if scenario.run.stop_distance_event == "idle" and "validation" in scenario.name:
        return validation.table_markdown(summary)
    return None


def simulation_files(scenario, runs: list, summary: dict, pass_summaries: list[dict],
                     study=None) -> dict[str, bytes | str]:
    """The folder of a ``symtrack simulate`` run (README "Output files"): the run's files with its
    trajectory figures; on the grid terrain the terrain and subsoil figures of its passes (a
    :class:`~symtrack.simulation.passes.PassStudy`), and for several passes each pass's run
    files in ``pass_<k>/``; ``validation_table.md`` for a validation scenario; ``report.html``
    with the figures. Names relative to the folder, in the order of writing."""
    table = validation_table(scenario, summary)
    top: dict[str, bytes] = {}  # the files of the folder's top, besides the run files
    shown: dict[str, bytes] = {}  # the images of report.html
    passes = {}  # the files of each pass's folder (several passes)
    if study is None:
        run = runs[0]
        top.update(figures("trajectory", run))
        shown.update(top)
    else:
        src = TerrainRun(scenario, study)
        top.update(figures(("terrain", "subsoil"), src))
        if src.multi:
            for k, (res, summ) in enumerate(zip(study.runs, pass_summaries, strict=True)):
                figs = figures("trajectory", res)
                passes.update({f"pass_{k + 1}/{n}": d for n, d in run_files(res, summ, figs).items()})
            shown.update(top)
            shown.update({f"pass_{len(study.runs)}/{n}": d for n, d in figs.items()})
        else:
            top.update(figures("trajectory", study.runs[0]))
            shown.update(top)
        run = None if src.multi else study.runs[0]
    if table is not None:
        top["validation_table.md"] = table.encode()
    top["report.html"] = report_html(
        f"symtrack: {scenario.name}", summary, shown, to_toml(scenario.to_dict()),
        validation.check(summary) if table is not None else None, summary.get("passes"),
        scenario.description).encode()
    if run is not None:
        return run_files(run, summary, top)
    return {**passes, **top, "summary.json": json.dumps(summary, indent=2) + "\n"}


def write_folder(out_dir, files: dict[str, bytes | str], clear: bool = True) -> list[Path]:
    """The one writer of a run's folder: with ``clear``, the files of a previous run are removed
    first (:func:`clear_previous_run`); then ``files`` (names relative to the folder, sub-folders
    created; str written as UTF-8) in their order, every ``summary.json`` after the other files
    and the folder's own ``summary.json`` last, so that its presence means the folder is whole.
    Returns the paths written, sorted."""
    out = Path(out_dir)
    if clear:
        clear_previous_run(out)
    out.mkdir(parents=True, exist_ok=True)
    last = [n for n in files if Path(n).name == "summary.json"]
    last.sort(key=lambda n: n == "summary.json")
    for name in [n for n in files if n not in last] + last:
        data = files[name]
        atomic_write_bytes(out / name, data.encode() if isinstance(data, str) else data)
    return sorted(out / n for n in files)


def clear_previous_run(out_dir, files=None, kind: str | None = None) -> list[Path]:
    """Remove the files of a previous run from ``out_dir``, so that a reused ``--out`` never
    mixes two runs' files; anything else is left alone, and a folder that is no run's is not
    touched. Returns what was removed.

    A run's folder holds one of :data:`RUN_MARKERS` (with ``kind``: a summary.json whose
    ``"kind"`` is ``kind``, e.g. a field study's). Without ``files`` its result files
    (:data:`RUN_SUFFIXES`) and its ``pass_<k>/`` folders are removed; with ``files`` (names
    relative to the folder) exactly those, sub-folders' first, then the top's with summary.json
    last (an interrupted clean-up is still recognised), and sub-folders left empty."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return []
    if kind is not None:
        try:
            old = json.loads((out_dir / "summary.json").read_text())
        except (OSError, ValueError):
            return []
        if not isinstance(old, dict) or old.get("kind") != kind:
            return []
    elif not any((out_dir / m).exists() for m in RUN_MARKERS):
        return []
    removed = []
    if files is not None:
        names = sorted(files, key=lambda n: (Path(n).parent == Path("."), Path(n).name == "summary.json"))
        subs = []
        for name in names:
            p = out_dir / name
            if p.is_file():
                p.unlink()
                removed.append(p)
            if p.parent != out_dir and p.parent not in subs:
                subs.append(p.parent)
        for sub in subs:
            if sub.is_dir() and not any(sub.iterdir()):
                sub.rmdir()
        return removed
    for p in sorted(out_dir.iterdir()):
        if p.is_dir() and p.name.startswith("pass_") and p.name[5:].isdigit():
            shutil.rmtree(p)
            removed.append(p)
        elif p.is_file() and p.suffix in RUN_SUFFIXES:
            p.unlink()
            removed.append(p)
    return removed
