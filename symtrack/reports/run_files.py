"""The files of a run, written atomically (temporary file in the same folder, then rename).

Files of a ``symtrack simulate`` run (schemas documented in the README):

- ``trajectory.csv``: one row per output step; header names carry units (t_s, states, commanded
  torques, then the model outputs);
- ``scenario.resolved.toml``: the scenario with every value after presets and overrides;
- ``*.png``: plots;
- ``summary.json``: written last, so that its presence means the run finished.
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np

from ..foundations.config import to_toml
from ..foundations.files import atomic_write_bytes, atomic_write_text

__all__ = ["RUN_MARKERS", "clear_previous_run", "trajectory_columns", "trajectory_csv", "write_run"]

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


def write_run(out_dir: Path, res, summary: dict, plots: dict[str, bytes]) -> None:
    """Write all files of a run; summary.json last."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "trajectory.csv", trajectory_csv(res))
    atomic_write_text(out_dir / "scenario.resolved.toml", to_toml(res.scenario.to_dict()))
    for name, data in plots.items():
        atomic_write_bytes(out_dir / name, data)
    atomic_write_text(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")


def clear_previous_run(out_dir: Path) -> list[Path]:
    """Remove the files of a previous run from ``out_dir`` (a folder holding one of
    :data:`RUN_MARKERS`): its result files (:data:`RUN_SUFFIXES`) and its ``pass_<k>/`` folders,
    so that a reused ``--out`` never mixes two runs' files. Anything else is left alone; a
    folder that is no run's is not touched. Returns what was removed."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir() or not any((out_dir / m).exists() for m in RUN_MARKERS):
        return []
    removed = []
    for p in sorted(out_dir.iterdir()):
        if p.is_dir() and p.name.startswith("pass_") and p.name[5:].isdigit():
            shutil.rmtree(p)
            removed.append(p)
        elif p.is_file() and p.suffix in RUN_SUFFIXES:
            p.unlink()
            removed.append(p)
    return removed
