"""The ``symtrack`` command line."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from .errors import SymtrackError

log = logging.getLogger("symtrack")


def _simulate(args) -> int:
    from . import output, plots, runner, validation
    from .scenario import load_scenario

    sc = load_scenario(args.scenario, args.set or [])
    res = runner.run(sc, progress=not args.quiet)
    summary = runner.summarise(res)
    figs = plots.all_plots(res)
    output.write_run(Path(args.out), res, summary, figs)
    if sc.run.stop_distance_event == "idle" and "validation" in sc.name:
        table = validation.table_markdown(summary)
        output.atomic_write_text(Path(args.out) / "validation_table.md", table)
        print(table)
    print(f"{sc.name}: {summary['sim_time_s']:.2f} s simulated in {summary['wall_time_s']:.2f} s "
          f"({summary['real_time_factor']:.1f} x real time); results in {args.out}")
    return 0


def _scenarios(args) -> int:
    from .scenario import builtin_names

    print("\n".join(builtin_names()))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="symtrack", description="Tracked vehicle on soil that remembers.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("simulate", help="run a scenario (built-in name or TOML file)")
    s.add_argument("scenario")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a scenario value")
    s.add_argument("--integrator", choices=("cvodes", "idas"), help="shorthand for --set run.integrator=...")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_simulate)
    ls = sub.add_parser("scenarios", help="list the built-in scenarios")
    ls.set_defaults(func=_scenarios)
    args = ap.parse_args(argv)
    if getattr(args, "integrator", None):
        args.set = (args.set or []) + [f"run.integrator={args.integrator}"]
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        return args.func(args)
    except SymtrackError as err:
        print(f"symtrack: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
