"""The ``symtrack`` command line: argument parsing only; every command is a thin call into the
layers below (:mod:`symtrack.api`, :mod:`symtrack.control`, :mod:`symtrack.studies`,
:mod:`symtrack.bench`, ``codegen``).

Heavy packages (CasADi, matplotlib, python-control) are imported by the commands, not here, so
that ``symtrack --help`` answers at once.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tomllib
from pathlib import Path

from .. import __version__
from ..foundations.errors import SymtrackError

__all__ = ["main"]

log = logging.getLogger("symtrack")

def simulate_command(args) -> int:
    from .simulate import simulate_command as run

    return run(args)


def _described(folder: Path) -> list[tuple[str, str]]:
    out = []
    for f in sorted(folder.glob("*.toml")):
        try:
            desc = tomllib.loads(f.read_text()).get("description", "")
        except tomllib.TOMLDecodeError:
            desc = "(not valid TOML)"
        out.append((f.stem, desc))
    return out


def scenarios_command(args) -> int:
    """The built-in scenarios with their descriptions (read from the package's TOML files)."""
    here = Path(__file__).resolve().parents[1]
    for title, command, folder in (("simulation scenarios", "symtrack simulate NAME", "simulation/scenarios"),
                                   ("MPC scenarios", "symtrack mpc NAME", "control/scenarios"),
                                   ("field studies", "symtrack field NAME", "studies/fields")):
        print(f"{title} ({command}):")
        rows = _described(here / folder)
        width = max(len(n) for n, _ in rows)
        for name, desc in rows:
            print(f"  {name:<{width}}  {desc}")
    print("symtrack run NAME (or FILE.toml) runs any of them; symtrack new KIND writes a starting file of a kind")
    return 0


def presets_command(args) -> int:
    """The built-in presets, or one preset's parameters with units, meaning and source."""
    from ..presets.catalog import format_preset, preset_file_kind, preset_names

    if args.name is None:
        for kind in ("vehicle", "soil"):
            print(f"{kind} presets ([{kind}] preset = NAME): {', '.join(preset_names(kind))}")
        print("symtrack presets NAME shows one; a preset file (*.toml) is shown the same way")
        return 0
    kind = args.kind
    if kind is None and args.name.endswith(".toml"):
        kind = preset_file_kind(args.name)  # a preset file says by its keys which kind it is
    if kind is None:
        kind = "vehicle" if args.name in preset_names("vehicle") else "soil"
    print(format_preset(kind, args.name, wide=args.wide), end="")
    return 0


def codegen_command(args) -> int:
    from ..codegen import cli as codegen_cli

    return codegen_cli.run(args)


def bench_command(args) -> int:
    from ..bench.homogeneous import run_cli

    return run_cli(args)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="symtrack", description="Tracked vehicle on soil that remembers.")
    ap.add_argument("--version", action="version", version=f"symtrack {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    from .run import add_parsers as add_run_parsers

    add_run_parsers(sub)  # symtrack run FILE, symtrack new KIND: the front door (docs/scenarios.md)
    s = sub.add_parser("simulate", help="run a scenario (built-in name or TOML file)")
    s.add_argument("scenario")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a scenario value")
    s.add_argument("--integrator", metavar="NAME",
                   help="shorthand for --set run.integrator=NAME, a name of the integrator registry: cvodes, idas, "
                   "rosenbrock (compiled fixed-step, docs/codegen.md)")
    s.add_argument("--compiled", action="store_true",
                   help="cvodes/idas on the compiled model (--set run.compiled=true)")
    s.add_argument("--require-compiled", action="store_true",
                   help="fail instead of falling back to the interpreter when no C compiler is found")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--terrain-in", metavar="FILE", help="continue from a saved grid terrain (docs/terrain.md)")
    s.add_argument("--terrain-out", metavar="FILE", help="save the grid terrain at the end (docs/terrain.md)")
    s.set_defaults(func=simulate_command)
    ls = sub.add_parser("scenarios", help="list the built-in simulation and MPC scenarios and field studies with their "
                        "descriptions")
    ls.set_defaults(func=scenarios_command)
    pr = sub.add_parser("presets", help="list the vehicle and soil presets, or one preset's parameters with sources")
    pr.add_argument("name", nargs="?", help="a preset name or a preset file (*.toml)")
    pr.add_argument("--kind", choices=("vehicle", "soil"), help="for a preset file: which kind it is")
    pr.add_argument("--wide", action="store_true", help="a Markdown table with each parameter's meaning and its "
                    "source in full (the default view fits 100 columns, the sources listed once below it)")
    pr.set_defaults(func=presets_command)
    cg = sub.add_parser("codegen", help="write the generated C sources (as python -m codegen)")
    from ..codegen.cli import add_arguments as codegen_arguments

    codegen_arguments(cg)
    cg.set_defaults(func=codegen_command)
    bn = sub.add_parser("bench", help="real-time factors of every integrator, in one process (docs/codegen.md)")
    from ..bench.homogeneous import add_arguments as bench_arguments

    bench_arguments(bn)
    bn.set_defaults(func=bench_command)
    from .control import add_parsers

    add_parsers(sub)  # symtrack linearize, symtrack mpc (docs/control.md)
    from .sweep import add_parser as add_sweep_parser

    add_sweep_parser(sub)  # symtrack sweep (docs/studies.md)
    from .field import add_parser as add_field_parser

    add_field_parser(sub)  # symtrack field (docs/studies.md, "Whole-field traffic study")
    from .region import add_parser as add_region_parser

    add_region_parser(sub)  # symtrack region (docs/region.md)
    from .export import add_parser as add_export_parser

    add_export_parser(sub)  # symtrack export fmu (docs/codegen.md, "The FMU")

    from .terrain import add_parser as add_terrain_parser

    add_terrain_parser(sub)  # symtrack terrain export (docs/terrain.md, "GIS rasters")
    from .validate import add_parser as add_validate_parser

    add_validate_parser(sub)  # symtrack validate (docs/validation.md)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "integrator", None):
        args.set = (args.set or []) + [f"run.integrator={args.integrator}"]
    if getattr(args, "compiled", False):
        args.set = (args.set or []) + ["run.compiled=true"]
    if getattr(args, "require_compiled", False):
        from ..toolchain import set_require_compiled

        set_require_compiled(True)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    # matplotlib's own INFO lines ("Animation.save using ...") are no message of symtrack's (--quiet too)
    logging.getLogger("matplotlib").setLevel(logging.WARNING)
    try:
        return args.func(args)
    except SymtrackError as err:
        print(f"symtrack: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("symtrack: interrupted (Ctrl-C); the results of this run were not written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the output was piped into a reader that stopped (| head)
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (closed at exit)
        return 0


if __name__ == "__main__":
    sys.exit(main())
