"""``symtrack bench``: real-time factors measured in one process, printed and written as JSON.

Rows of the homogeneous validation scenario (simulated seconds per wall second of the time
loop, model construction and compilation excluded, best of ``--repeats`` runs after a warm-up):
CVODES and IDAS on CasADi's interpreter and on the compiled model, the compiled fixed-step
``rosenbrock`` integrator (and the same on the interpreter, for scale), and the standalone C
program (symtrack/codegen/standalone_main.c; best of its own repeats).

Extensible: every module of :data:`PROVIDERS` that can be imported and has
``bench_rows(quick: bool) -> list[dict]`` adds its rows (the grid terrain and the MPC). A row is
a dict with at least ``group`` and ``case``; the usual keys are ``integrator``, ``sim_time_s``,
``wall_time_s``, ``real_time_factor`` and ``note``; any other keys go to the JSON only.
Wall-clock numbers are machine- and load-dependent: the JSON records the load average.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import platform
import time
from pathlib import Path

__all__ = ["BENCH_SCHEMA_VERSION", "COLUMNS", "PROVIDERS", "add_arguments", "collect", "homogeneous_rows", "report",
           "run_cli", "standalone_row", "table"]

log = logging.getLogger("symtrack.bench")

BENCH_SCHEMA_VERSION = 1
PROVIDERS = ("symtrack.bench.terrain", "symtrack.bench.laws", "symtrack.control.bench", "symtrack.bench.mpc_c",
             "symtrack.bench.outputs")
COLUMNS = (("group", "{}"), ("case", "{}"), ("integrator", "{}"), ("sim_time_s", "{:.2f}"),
           ("wall_time_s", "{:.4f}"), ("real_time_factor", "{:.0f}"), ("note", "{}"))


def _validation_row(case, integrator, overrides, repeats, note=""):
    from ..simulation import loop
    from ..simulation.plants import make_plant
    from ..simulation.scenario import load_scenario

    sc = load_scenario("validation", [f"run.integrator={integrator}", *overrides])
    plant = make_plant(sc)
    loop.run(sc, plant)  # warm-up: builds (and compiles) once
    best, cpu_best, res = None, None, None
    for _ in range(repeats):
        c0 = time.process_time()
        r = loop.run(sc, plant)
        cpu = time.process_time() - c0
        if best is None or r.wall_time_s < best:
            best, res = r.wall_time_s, r
        cpu_best = cpu if cpu_best is None else min(cpu_best, cpu)
    sim = float(res.t[-1])
    return {"group": "homogeneous validation", "case": case, "integrator": integrator, "sim_time_s": sim,
            "wall_time_s": best, "real_time_factor": sim / best, "cpu_time_s_incl_setup": cpu_best,
            "note": note, "stats": res.stats}


def homogeneous_rows(quick: bool = False, repeats: int = 3) -> list[dict]:
    from ..native import cache

    rows = [
        _validation_row("interpreted", "cvodes", [], repeats),
        _validation_row("interpreted", "idas", [], repeats),
        _validation_row("compiled", "cvodes", ["run.compiled=true"], repeats),
        _validation_row("compiled", "idas", ["run.compiled=true"], repeats),
        _validation_row("compiled, 256 steps per call", "rosenbrock", [], repeats, "fixed step 10 ms"),
    ]
    if not quick:
        # the same integrator on CasADi's interpreter, for scale
        with cache.interpreter_only():
            rows.append(_validation_row("interpreted (same Functions)", "rosenbrock", [], 1, "fixed step 10 ms"))
    rows.append(standalone_row())
    return rows


def standalone_row(repeats: int = 20) -> dict:
    from ..codegen.standalone import build_standalone, run_standalone

    binary = build_standalone()
    s = run_standalone(binary, repeats)
    return {"group": "homogeneous validation", "case": "standalone C program", "integrator": "rosenbrock",
            "sim_time_s": s["sim_time_s"], "wall_time_s": s["wall_time_s"],
            "real_time_factor": s["real_time_factor"], "note": f"best of {repeats}, no Python"}


def collect(quick: bool = False, repeats: int = 3) -> list[dict]:
    # each provider measures for a while (minutes for the grids): it says what it measures first, and the
    # table is printed once every row is in
    log.info("measuring the homogeneous terrain's integrators (%d repeats) ...", repeats)
    rows = homogeneous_rows(quick, repeats)
    for name in PROVIDERS:
        log.info("measuring the rows of %s ... (%d row(s) so far; the table comes at the end)", name, len(rows))
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name is not None and name.startswith(err.name):
                log.info("%s is not available: skipped", name)
                continue
            raise
        fn = getattr(mod, "bench_rows", None)
        if fn is None:
            log.info("%s has no bench_rows(): skipped", name)
            continue
        rows += fn(quick)
    return rows


def table(rows: list[dict]) -> str:
    def cell(row, key, fmt):
        v = row.get(key)
        if v is None:
            return ""
        try:
            return fmt.format(v)
        except (ValueError, TypeError):
            return str(v)

    header = "| " + " | ".join(k for k, _ in COLUMNS) + " |"
    lines = [header, "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(cell(r, k, f) for k, f in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def report(rows: list[dict]) -> dict:
    import casadi

    return {"schema_version": BENCH_SCHEMA_VERSION, "casadi_version": casadi.__version__,
            "machine": platform.machine(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": list(os.getloadavg()), "rows": rows}


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("what", nargs="?", choices=("region",),
                    help="region: the region study's fast fidelity against the full one on the built-in seasons, "
                    "the cost per hectare-season and 1 against 2 workers (docs/region.md; --quick: operation_small "
                    "only; --large: and a 1,000 ha region)")
    ap.add_argument("--out", default="out/bench.json", help="JSON file to write (default out/bench.json)")
    ap.add_argument("--large", action="store_true", help="bench region: also a generated 1,000 ha region, one season")
    ap.add_argument("--workers", action="store_true", help="bench region: only 1 against 2 workers on 24 generated "
                    "fields, --repeats pairs alternated, the median ratio (about 70 s a pair)")
    ap.add_argument("--keep", metavar="DIR", help="bench region: keep the full fidelity's runs in DIR/<case> and "
                    "reuse them when their inputs are the same (they take minutes)")
    ap.add_argument("--quick", action="store_true", help="fewer rows and sizes (providers decide what to skip)")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per row after a warm-up (best is kept); "
                    "bench region --workers: the alternated pairs (the median is kept)")
    ap.add_argument("--sweep", action="store_true",
                    help="only the sweep overhead: 8 validation runs one after another vs symtrack sweep on 1 and 2 "
                    "workers (docs/studies.md; --quick: 4 runs)")


def run_cli(args) -> int:
    from ..foundations.errors import ScenarioError
    from ..foundations.files import atomic_write_text

    if args.repeats < 1:
        raise ScenarioError(f"--repeats = {args.repeats} must be >= 1")
    if getattr(args, "workers", False) and getattr(args, "what", None) != "region":
        raise ScenarioError("--workers is an option of `symtrack bench region` (1 against 2 workers of a region)")
    if getattr(args, "what", None) == "region":
        import os

        from ..region.check import bench_rows as region_rows
        from ..region.check import bench_table as region_table

        rep = region_rows(args.quick, args.large, keep=args.keep, workers_only=args.workers, repeats=args.repeats)
        rep.update(load_average=list(os.getloadavg()), cpus=os.cpu_count())
        atomic_write_text(Path(args.out), json.dumps(rep, indent=2, default=str) + "\n")
        print(region_table(rep))
        print(f"load average {rep['load_average'][0]:.2f} on {rep['cpus']} CPUs; JSON in {args.out}")
        return 0
    if getattr(args, "sweep", False):
        from .sweep import bench_rows as sweep_rows

        rows = sweep_rows(args.quick)
    else:
        rows = collect(args.quick, args.repeats)
    rep = report(rows)
    atomic_write_text(Path(args.out), json.dumps(rep, indent=2, default=str) + "\n")
    print(table(rows))
    print(f"load average {rep['load_average'][0]:.2f} on {rep['cpus']} CPUs; JSON in {args.out}")
    return 0
