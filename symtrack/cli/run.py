"""``symtrack run FILE.toml``: the one front door, any run file (its kind told by its sections:
:mod:`symtrack.studies.runfile`), run by the command of its kind (``symtrack simulate``, ``mpc``,
``field``, ``sweep`` stay as shortcuts); ``symtrack new KIND``: a commented starting file of each
kind (``symtrack/cli/templates/``) that runs as written."""

from __future__ import annotations

import argparse
from importlib import resources
from pathlib import Path

from ..foundations.errors import ScenarioError

__all__ = ["NEW_KINDS", "add_parsers", "new_command", "run_command", "template_text"]

TEMPLATES = "symtrack.cli.templates"
# the kinds of symtrack new, in the order of symtrack.studies.runfile.KINDS (read without importing it:
# `symtrack --help` stays free of heavy packages)
NEW_KINDS = ("simulation", "mpc", "field", "operation", "season", "sweep")


def template_text(kind: str, file: str | Path | None = None) -> str:
    """The starting file of ``kind`` (one of :data:`NEW_KINDS`), its header's command naming ``file``
    (the file it is written to; default ``KIND.toml``)."""
    if kind not in NEW_KINDS:
        raise ScenarioError(f"symtrack new {kind!r}: the kinds are {', '.join(NEW_KINDS)}")
    file = Path(file if file is not None else f"{kind}.toml")
    text = resources.files(TEMPLATES).joinpath(f"{kind}.toml").read_text()
    return text.replace("@FILE@", str(file)).replace("@STEM@", file.stem)


def new_command(args) -> int:
    from ..foundations.files import atomic_write_text, check_output_file

    out = Path(args.out or f"{args.kind}.toml")
    text = template_text(args.kind, out)
    if out.exists():  # a file of the user's is never replaced
        raise ScenarioError(f"--out {str(out)!r} exists; give another file name (symtrack new never replaces a file)")
    check_output_file(str(out), "--out")
    atomic_write_text(out, text)
    print(f"wrote {out}, {args.kind} run file; run it with: symtrack run {out} --out out/{out.stem}")
    return 0


def _namespace(args, **kw) -> argparse.Namespace:
    base = {"out": args.out, "set": list(args.set or []), "quiet": args.quiet, "terrain_in": None, "terrain_out": None}
    return argparse.Namespace(**{**base, **kw})


def run_command(args) -> int:
    from ..studies.runfile import read_run_file

    rf = read_run_file(args.file, args.set or [])  # the kind, before any work (one line when it cannot be told)
    if rf.kind == "simulation":
        from .simulate import simulate_command

        return simulate_command(_namespace(args, scenario=args.file))
    if rf.kind == "mpc":
        from .control import mpc_command

        return mpc_command(_namespace(args, scenario=args.file, solver=None, jit=False, plant=None))
    if rf.kind in ("field", "operation", "season"):
        from .field import field_command

        return field_command(_namespace(args, scenario=args.file, pattern=None, workers=2, scheduler=None))
    if rf.kind == "sweep":
        return _sweep(args, rf)
    from ..studies.runfile import KINDS, run  # a kind registered by a plug-in: its own run

    run(args.file, args.out, overrides=args.set or [], progress=not args.quiet)
    print(f"{rf.name}: {KINDS[rf.kind].what}; results in {args.out}")
    return 0


def _sweep(args, rf) -> int:
    from ..studies.runfile import sweep_arguments
    from .sweep import run_sweep

    return run_sweep(args.out, args.quiet, **sweep_arguments(rf))


def add_parsers(sub) -> None:
    """Register ``symtrack run`` and ``symtrack new`` on the argparse subparsers of symtrack.cli."""
    r = sub.add_parser(
        "run", help="run any run file: a simulation, an MPC run, a field study, an operation, a season or a sweep",
        description="Run a run file; its kind follows from its sections: [[torque]] a simulation, [path] or [mpc] "
        "an MPC run, [field] a field study, [operation] a field operation, [season] a season, [sweep] a sweep. "
        "The same as symtrack simulate, mpc, field or sweep with that file. symtrack new KIND writes a starting "
        "file of each kind.")
    r.add_argument("file", help="a run file (*.toml) or a built-in name (symtrack scenarios)")
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a value of the file")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=run_command)
    n = sub.add_parser("new", help="write a commented starting run file of a kind, which runs as written",
                       description="Write a commented run file of KIND that runs as written (in a few seconds); "
                       "edit it and run it with symtrack run FILE --out DIR.")
    n.add_argument("kind", choices=NEW_KINDS, help="the kind of run file")
    n.add_argument("--out", metavar="FILE", help="the file to write (default KIND.toml; an existing file is refused)")
    n.set_defaults(func=new_command)
