"""What a run's outputs cost: ``symtrack simulate`` end to end against its
simulation, with the default figures and with ``run.all_figures = true``.

Each case runs twice in fresh processes: the real command (``python -m symtrack simulate NAME
--out TMP --quiet``, its wall time from outside: the figure a user waits for) and the same run
through :func:`phases`, which times its parts:

- ``import_s``: importing symtrack's API (CasADi, NumPy, matplotlib) and loading the scenario;
- ``simulate_s``: :func:`symtrack.simulate`, the simulation: the plant built (the field, the
  compiled engine loaded from its cache), every pass (set-down, time loop, lift-off, its records);
- ``time_loop_s``: of that, the passes' time loops (``wall_time_s`` of the runs);
- ``figures_s``: the files composed (:func:`~symtrack.reports.run_files.simulation_files`: the
  figures, report.html, trajectory.csv);
- ``write_s``: the folder written (:func:`~symtrack.reports.run_files.write_folder`).

The rows print the ratio of the command's wall time to its simulation and the figures' share; a
bench prints ratios taken in one run and asserts no wall time (load-dependent: the JSON records
the load average). ``python -m symtrack.bench.outputs [--quick]`` prints these rows alone.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["CASES", "bench_rows", "main", "phases"]

# (case, scenario, overrides): the multipass study and one short pass, each with the default
# figures and with all of them
CASES = (
    ("multipass, 3 passes x 4 m", "multipass", []),
    ("multipass, 3 passes x 4 m, all_figures", "multipass", ["run.all_figures=true"]),
    ("one pass x 0.5 m", "multipass", ["terrain.passes=1", "run.stop_after_distance_m=0.5"]),
    ("one pass x 0.5 m, all_figures", "multipass", ["terrain.passes=1", "run.stop_after_distance_m=0.5",
                                                    "run.all_figures=true"]),
)


_CHILD = ("import time; t0 = time.perf_counter(); import json, sys; from symtrack.bench.outputs import phases; "
          "print(json.dumps(phases(sys.argv[1], sys.argv[2:-1], sys.argv[-1], t0)))")


def phases(name: str, overrides: list[str], out: str, t0: float) -> dict:
    """One run's parts (module doc), in this process, from ``t0`` (``time.perf_counter()`` before
    symtrack was imported): call it in a fresh process (:data:`_CHILD`)."""
    from ..api import simulate  # CasADi, NumPy, matplotlib (symtrack imports them on first use)
    from ..reports.run_files import simulation_files, write_folder
    from ..simulation.scenario import load_scenario

    sc = load_scenario(name, overrides)
    t2 = time.perf_counter()
    res = simulate(sc, progress=False)
    t3 = time.perf_counter()
    files = simulation_files(res.scenario, res.runs, res.summary, res.pass_summaries, res._study)
    t4 = time.perf_counter()
    write_folder(out, files)
    t5 = time.perf_counter()
    return {"import_s": t2 - t0, "simulate_s": t3 - t2,
            "time_loop_s": sum(r.wall_time_s for r in res.runs), "sim_time_s": sum(float(r.t[-1]) for r in res.runs),
            "figures_s": t4 - t3, "write_s": t5 - t4,
            "files": len(files), "images": sum(n.endswith((".png", ".gif")) for n in files)}


def _python(args: list[str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, *args], capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({r.returncode}): {r.stderr[-2000:]}")
    return wall, r.stdout


def case_row(case: str, name: str, overrides: list[str]) -> dict:
    """One row: the command's wall time and the parts of the same run (module doc)."""
    sets = [a for o in overrides for a in ("--set", o)]
    with tempfile.TemporaryDirectory(prefix="symtrack-bench-outputs-") as tmp:
        load0 = os.getloadavg()
        wall, _ = _python(["-m", "symtrack", "simulate", name, *sets, "--out", str(Path(tmp) / "cmd"), "--quiet"])
        child, text = _python(["-c", _CHILD, name, *overrides, str(Path(tmp) / "p")])
        load1 = os.getloadavg()
    p = json.loads(text.strip().splitlines()[-1])
    # the start-up: the interpreter, the imports and the scenario loaded (the child's wall time but
    # its simulation and outputs)
    start = child - p["simulate_s"] - p["figures_s"] - p["write_s"]
    outputs = p["figures_s"] + p["write_s"]
    return {"group": "outputs of symtrack simulate", "case": case, "integrator": "grid_fast",
            "sim_time_s": p["sim_time_s"], "wall_time_s": wall, "real_time_factor": p["sim_time_s"] / wall,
            "command_wall_s": wall, "timed_run_wall_s": child, **p, "start_up_s": start,
            "outputs_over_simulate": outputs / p["simulate_s"],
            "beyond_start_up_over_simulate": (child - start) / p["simulate_s"], "load_average_before": load0,
            "load_average_after": load1,
            "note": (f"command {wall:.2f} s; timed {child:.2f} s = start-up {start:.2f} (imports and scenario "
                     f"{p['import_s']:.2f}) + simulate {p['simulate_s']:.2f} (time loops {p['time_loop_s']:.2f}) + "
                     f"figures and report {p['figures_s']:.2f} ({p['images']} images) + write {p['write_s']:.2f}: "
                     f"outputs {outputs / p['simulate_s']:.1f} x the simulation; load {load0[0]:.1f} -> "
                     f"{load1[0]:.1f}")}


def bench_rows(quick: bool = False) -> list[dict]:
    """The rows of ``symtrack bench`` (symtrack/bench/homogeneous.py): every case, or with
    ``quick`` the default figures only."""
    return [case_row(*c) for c in CASES if not (quick and any("all_figures" in o for o in c[2]))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m symtrack.bench.outputs")
    ap.add_argument("--quick", action="store_true", help="the default figures only")
    args = ap.parse_args(argv)
    for r in bench_rows(args.quick):
        print(f"{r['case']}: {r['note']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
