"""A run's memory against its own estimate: ``symtrack simulate ARGS`` in a fresh process, the
estimate its summary records (``terrain_memory_estimate_MB``) and the peak resident set the process
reached (Linux's VmHWM, read by the process itself from /proc/self/status as it ends: the forking
process's pages, which getrusage's ru_maxrss of a child would count, are not its own).

Used by the memory test (tests/test_memory_refusal.py) and the memory-peaks table of docs/terrain.md
(docs/figures.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["simulate_peak"]

# the child: the CLI, then its own high-water mark in kB into the file argv[1]
_HWM = """
import sys
from symtrack.cli import main
code = main(sys.argv[2:])
with open("/proc/self/status") as f:
    kb = next(line.split()[1] for line in f if line.startswith("VmHWM:"))
with open(sys.argv[1], "w") as f:
    f.write(kb)
sys.exit(code)
"""


def simulate_peak(args: list[str], out: Path, cwd: Path | None = None) -> tuple[float, float]:
    """(the run's own memory estimate, its process's peak resident set), bytes, of
    ``symtrack simulate ARGS --out OUT --quiet`` in a fresh Python process. The package is imported from
    where this one was (its folder first on PYTHONPATH). A run that fails is a RuntimeError with its
    exit code and the end of its error output."""
    if not sys.platform.startswith("linux"):
        raise RuntimeError("the peak resident set is read from /proc/self/status: Linux only")
    out = Path(out)
    hwm = out.with_name(out.name + ".hwm")
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", _HWM, str(hwm), "simulate", *args, "--out", str(out), "--quiet"],
                          cwd=cwd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"symtrack simulate {' '.join(args)}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    estimate = json.loads((out / "summary.json").read_text())["terrain_memory_estimate_MB"] * 1e6
    peak = float(hwm.read_text()) * 1024.0
    hwm.unlink()
    return estimate, peak
