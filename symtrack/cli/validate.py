"""``symtrack validate``: the gallery of published measurements against the package's models
(docs/validation.md); argument parsing only, the cases are :mod:`symtrack.studies.validate`."""

from __future__ import annotations

from ..foundations.errors import ScenarioError
from ..foundations.files import check_output_folder

__all__ = ["add_parser", "validate_command"]


def validate_command(args) -> int:
    if args.list:
        from ..studies.validate_report import list_cases

        for name, title, source in list_cases(args.cases):
            print(f"{name}\n    {title}\n    {source}")
        return 0
    if not args.out:
        raise ScenarioError("symtrack validate needs --out DIR (or --list)")
    if args.workers < 1:
        raise ScenarioError(f"--workers {args.workers} must be at least 1")
    if args.scheduler:
        from ..studies.engine import check_scheduler_address

        check_scheduler_address(args.scheduler)
    out = check_output_folder(args.out)  # before any case is loaded or run
    from ..studies.validate_report import run_validation, summary_table

    run = run_validation(args.cases, out, progress=not args.quiet, dask=args.dask, workers=args.workers,
                         scheduler=args.scheduler)
    print(summary_table(run.summary))
    print(f"{len(run.results)} case(s) in {run.wall_time_s:.1f} s; validation.csv, sensitivity.csv, validation.md, "
          f"report.html and one figure per case in {out}")
    return 0


def add_parser(sub) -> None:
    """Register ``symtrack validate`` on the argparse subparsers of symtrack.cli."""
    v = sub.add_parser(
        "validate", help="run the gallery of published measurements against the models (docs/validation.md)",
        description="Run validation cases (built-in names or case files; none: every built-in case): each is "
        "measured data from a publication, its setup and its assumptions with their ranges. Writes "
        "DIR/validation.csv (measured, predicted, error per point), DIR/sensitivity.csv (each assumption at the "
        "ends of its range), DIR/validation.md (the same as Markdown tables), one figure per case, "
        "DIR/report.html and DIR/summary.json, and prints the mean "
        "absolute and the worst relative error per kind of quantity.")
    v.add_argument("cases", nargs="*", metavar="CASE", help="a built-in case name (symtrack validate --list) or a "
                   "case file (*.toml); none: every built-in case")
    v.add_argument("--out", help="the output folder")
    v.add_argument("--list", action="store_true", help="list the cases with their sources and exit")
    v.add_argument("--dask", action="store_true", help="run the cases on Dask, one task per case, on a local cluster "
                   "of --workers processes (or on --scheduler), as symtrack sweep runs its runs")
    v.add_argument("--workers", type=int, default=2,
                   help="worker processes of the local Dask cluster (default 2; with --dask, ignored with --scheduler)")
    v.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler, e.g. tcp://127.0.0.1:8786 (implies --dask)")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(func=validate_command)
