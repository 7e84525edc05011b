"""``symtrack export fmu SCENARIO --out FILE.fmu``: the scenario's vehicle on the homogeneous terrain, or on
the terrain engine for a grid scenario, as an FMI 2.0 co-simulation FMU (docs/codegen.md, "The FMU");
argument parsing only, the export is :mod:`symtrack.codegen.fmu` (and :mod:`symtrack.codegen.engine_fmu`).
CasADi is imported by the command, not here, so that ``symtrack --help`` answers at once."""

from __future__ import annotations

from ..foundations.files import check_output_file

__all__ = ["add_parser", "export_command"]


def export_command(args) -> int:
    check_output_file(args.out, "--out")  # before anything is loaded or built
    from ..codegen import fmu

    return fmu.command(args)


def add_parser(sub) -> None:
    ex = sub.add_parser("export", help="export a scenario for other tools: fmu (an FMI 2.0 co-simulation FMU, "
                        "docs/codegen.md)")
    ex.add_argument("format", choices=("fmu",), help="fmu: FMI 2.0 co-simulation, linux64 binary and C sources")
    ex.add_argument("scenario", help="a built-in simulation scenario or a TOML file: the homogeneous terrain with "
                    "run.integrator = rosenbrock, or a grid scenario with run.integrator = grid_fast (the terrain "
                    "engine; subsoil stress off, one soil, one pass)")
    ex.add_argument("--out", required=True, help="the FMU file to write (FILE.fmu)")
    ex.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a scenario value")
    ex.set_defaults(func=export_command)
