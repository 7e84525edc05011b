"""``python -m codegen`` / ``symtrack codegen``: write the generated C sources.

Writes, for the homogeneous-terrain system of the validation scenario's model options (the creep
law it declares), the files listed in
:mod:`symtrack.native.generate` plus ``homogeneous_validation.h`` (the numbers of the built-in validation
scenario for the standalone C program), and the grid validation's standalone program's
``engine_gen.inc``, ``engine_soils.inc`` and ``grid_validation.h`` (:mod:`symtrack.codegen.grid_standalone`)
into ``generated/`` (or ``--out``). Files are written
atomically and only when their content changed; ``--check`` writes nothing and exits with 1 when
the folder is out of date.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
from pathlib import Path

__all__ = ["REPO_GENERATED", "add_arguments", "check", "main", "render_all", "run", "write"]

log = logging.getLogger("symtrack.codegen")

# the checkout's generated/ (symtrack.native.cache.REPO_GENERATED; spelled here so that the
# argument parser needs no CasADi import)
REPO_GENERATED = Path(__file__).resolve().parents[2] / "generated"


def render_all(scratch: Path, overrides=()) -> dict[str, bytes]:
    """Every file of generated/ as name -> bytes; ``overrides``: ``--set`` items applied to the
    validation scenarios (for example ``model.lateral_law=shear``: the standalone programs on the
    package's default law, into a folder of their own)."""
    from symtrack.model import SystemModel
    from symtrack.native.generate import model_functions, render
    from symtrack.simulation.scenario import load_scenario

    from . import grid_standalone, standalone

    # the validation scenario's model (its declared lateral law, creep), which the standalone
    # program runs; other options are generated afresh into the cache (native.cache.generated_sources)
    sc = load_scenario("validation", list(overrides))
    model = SystemModel(sc.model)
    gen = model_functions(model, model.terrain.name)
    files = render(gen, scratch)
    files[f"{gen.prefix}_validation.h"] = standalone.validation_header(model, gen, sc)
    files.update(grid_standalone.render(scratch, overrides))  # the grid validation's standalone program
    return files


def write(out_dir: Path, overrides=()) -> list[str]:
    """Generate into out_dir; returns the names of the files that changed."""
    from symtrack.foundations.files import atomic_write_bytes

    with tempfile.TemporaryDirectory(prefix="symtrack-codegen-") as scratch:
        files = render_all(Path(scratch), overrides)
    changed = []
    for name, data in sorted(files.items()):
        path = out_dir / name
        if not path.exists() or path.read_bytes() != data:
            atomic_write_bytes(path, data)
            path.chmod(0o644)
            changed.append(name)
    return changed


def check(out_dir: Path) -> list[str]:
    """Names of the files in out_dir that differ from a fresh generation (or are missing)."""
    with tempfile.TemporaryDirectory(prefix="symtrack-codegen-") as scratch:
        files = render_all(Path(scratch))
    return [n for n, d in sorted(files.items()) if not (out_dir / n).exists() or (out_dir / n).read_bytes() != d]


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("target", nargs="?", metavar="mpc",
                    help="mpc NAME: the MPC scenario NAME's real-time iteration and closed loop as C (docs/codegen.md)")
    ap.add_argument("name", nargs="?", help="with mpc: a built-in MPC scenario or a TOML file")
    ap.add_argument("--out", default=None, help="output folder (default: the repository's generated/; "
                    "required with mpc)")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if the folder is out of date")
    ap.add_argument("--solver", choices=("rti",), help="mpc: the controller (only rti: the real-time iteration)")
    ap.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                    help="override a scenario value (mpc: of the MPC scenario; else: of the validation scenarios "
                    "the standalone programs run, for example model.lateral_law=shear; needs --out)")
    ap.add_argument("--no-run", action="store_true", help="mpc: generate and build, do not run the program")
    ap.add_argument("--compare", action="store_true",
                    help="mpc: also run the Python closed loop of the same configuration and print the agreement")


def run(args) -> int:
    target = getattr(args, "target", None)
    if target is not None:
        if target != "mpc":
            from symtrack.foundations.errors import ScenarioError

            raise ScenarioError(f"symtrack codegen {target!r}: unknown target (known: mpc)")
        from . import mpc

        return mpc.command(args)
    overrides = tuple(getattr(args, "set", None) or ())
    if overrides and not args.out:
        from symtrack.foundations.errors import ScenarioError

        raise ScenarioError("symtrack codegen --set: generated/ holds the validation scenarios as they are; "
                            "give --out DIR for the programs of a changed scenario")
    out = Path(args.out) if args.out else REPO_GENERATED
    if args.check:
        stale = check(out)
        if stale:
            log.error("out of date in %s: %s (run python -m codegen)", out, ", ".join(stale))
            return 1
        log.info("%s is up to date", out)
        return 0
    out.mkdir(parents=True, exist_ok=True)
    changed = write(out, overrides)
    log.info("wrote %d changed file(s) into %s%s", len(changed), out, (": " + ", ".join(changed)) if changed else "")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m codegen", description="Generate symtrack's C sources.")
    add_arguments(ap)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    from symtrack.foundations.errors import SymtrackError

    try:
        return run(args)
    except SymtrackError as err:
        print(f"python -m codegen: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
