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
    if "terrain" in sc.extra or getattr(args, "terrain_in", None) or getattr(args, "terrain_out", None):
        from .terrain.study import simulate_cli  # the grid terrain (docs/terrain.md)

        return simulate_cli(args, sc)
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
    try:
        return _main(argv)
    except KeyboardInterrupt:  # issue 13: Ctrl-C in any phase of any command: exit 130
        print("\nsymtrack: interrupted", file=sys.stderr)
        return 130


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="symtrack", description="Tracked vehicle on soil that remembers.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("simulate", help="run a scenario (built-in name or TOML file)")
    s.add_argument("scenario")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a scenario value")
    s.add_argument("--integrator", choices=("cvodes", "idas", "rosenbrock"),
                   help="shorthand for --set run.integrator=... (rosenbrock: compiled fixed-step, docs/codegen.md)")
    s.add_argument("--compiled", action="store_true",
                   help="cvodes/idas on the compiled model (--set run.compiled=true)")
    s.add_argument("--require-compiled", action="store_true",
                   help="fail instead of falling back to the interpreter when no C compiler is found")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--terrain-in", metavar="FILE", help="continue from a saved grid terrain (docs/terrain.md)")
    s.add_argument("--terrain-out", metavar="FILE", help="save the grid terrain at the end (docs/terrain.md)")
    s.set_defaults(func=_simulate)
    ls = sub.add_parser("scenarios", help="list the built-in scenarios")
    ls.set_defaults(func=_scenarios)
    from codegen import cli as codegen_cli

    cg = sub.add_parser("codegen", help="write the generated C sources (as python -m codegen)")
    codegen_cli.add_arguments(cg)
    cg.set_defaults(func=codegen_cli.run)
    from . import bench

    bn = sub.add_parser("bench", help="real-time factors of every integrator, in one process (docs/codegen.md)")
    bench.add_arguments(bn)
    bn.set_defaults(func=bench.run_cli)
    from .control import cli as control_cli

    control_cli.add_parsers(sub)  # symtrack linearize, symtrack mpc (docs/control.md)
    args = ap.parse_args(argv)
    if getattr(args, "integrator", None):
        args.set = (args.set or []) + [f"run.integrator={args.integrator}"]
    if getattr(args, "compiled", False):
        args.set = (args.set or []) + ["run.compiled=true"]
    if getattr(args, "require_compiled", False):
        from .compiled import set_require_compiled

        set_require_compiled(True)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        return args.func(args)
    except SymtrackError as err:
        print(f"symtrack: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
