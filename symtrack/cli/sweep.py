"""``symtrack sweep``: a parameter sweep on Dask distributed (docs/studies.md); argument parsing
only, the engine is :mod:`symtrack.studies`. Dask and CasADi are imported by the command, not
here, so that ``symtrack --help`` answers at once."""

from __future__ import annotations

import sys

__all__ = ["add_parser", "report", "sweep_command"]


def sweep_command(args) -> int:
    return run_sweep(args.out, args.quiet, scenario=args.scenario, vary=args.vary, samples=args.sample,
                     seed=args.seed, overrides=args.set or [], kind=args.kind, workers=args.workers,
                     scheduler=args.scheduler)


def run_sweep(out, quiet: bool, **kw) -> int:
    """Run a sweep (symtrack.studies.sweep with ``kw``) into ``out``: its report and exit code; Ctrl-C
    exits 130 saying what is kept (symtrack sweep, and symtrack run of a sweep file)."""
    from ..studies import sweep

    try:
        res = sweep(out=out, progress=not quiet, **kw)
    except KeyboardInterrupt:
        print(f"symtrack: interrupted (Ctrl-C); the runs in flight were cancelled, the finished ones are kept "
              f"in {out} (results.csv); run the same command again to do the rest", file=sys.stderr)
        return 130
    return report(res)


def report(res) -> int:
    """Print a finished sweep's failed runs and its one-line summary; the exit code."""
    for f in res.failed:
        values = ", ".join(f"{k}={v!r}" for k, v in f["values"].items())
        print(f"failed: run {f['id']} ({values}): {f['error']}", file=sys.stderr)
    print(f"sweep: {len(res.rows)} runs, {res.count('ok')} ok, {res.count('failed')} failed "
          f"({res.ran} run now, {res.skipped} finished before) in {res.wall_time_s:.1f} s; "
          f"table in {res.out / 'results.csv'}")
    return 0 if res.ok else 1


def add_parser(sub) -> None:
    """Register ``symtrack sweep`` on the argparse subparsers of symtrack.cli."""
    sw = sub.add_parser(
        "sweep", help="a parameter sweep (full grid or Latin hypercube) on Dask distributed (docs/studies.md)",
        description="Run a scenario (of `symtrack simulate`, `symtrack mpc` or `symtrack field`) for every "
        "combination of the varied values, on a local Dask cluster or an existing scheduler. Writes "
        "DIR/results.csv (one row per run), DIR/sweep.json and DIR/runs/<id>/. Exit code 0 when every run "
        "succeeded, 1 when some failed, 2 for an invalid sweep (nothing run), 130 on Ctrl-C (finished runs "
        "kept). A rerun into the same DIR redoes only what failed or is missing.")
    sw.add_argument("scenario", help="built-in scenario name (symtrack scenarios, symtrack mpc --help, "
                    "symtrack field --help) or TOML file")
    sw.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2,...",
                    help="a varied key (any --set key) and its values; or KEY=LO:HI, a range sampled by --sample")
    sw.add_argument("--sample", type=int, metavar="N",
                    help="N points of a Latin hypercube over the KEY=LO:HI ranges (crossed with the listed values)")
    sw.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube (default 0)")
    sw.add_argument("--out", required=True, help="the sweep folder")
    sw.add_argument("--workers", type=int, default=2,
                    help="worker processes of the local Dask cluster (default 2; ignored with --scheduler)")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running Dask scheduler, e.g. tcp://127.0.0.1:8786 (instead of a local cluster)")
    # checked by the sweep against the kinds of symtrack.studies.runfile (not imported here: its package
    # imports numpy and CasADi)
    sw.add_argument("--kind", default="auto",
                    help="the scenario kind: a sweep name of the run-file kinds (simulate, mpc, field and any "
                    "registered) or auto (default: the first kind whose loader accepts the scenario)")
    sw.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="a fixed override of every run")
    sw.add_argument("--quiet", action="store_true", help="no progress bar or log lines")
    sw.set_defaults(func=sweep_command)
