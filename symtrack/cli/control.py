"""The ``symtrack linearize`` and ``symtrack mpc`` commands (registered by :mod:`symtrack.cli.main`)."""

from __future__ import annotations

import contextlib
import json
import logging
from pathlib import Path

__all__ = ["DEFAULT_SOIL", "DEFAULT_VEHICLE", "add_parsers", "linearize_command", "linearize_model_options",
           "mpc_command", "mpc_scenarios_list"]

log = logging.getLogger("symtrack.control")

DEFAULT_SOIL = "sandy_loam_15"
DEFAULT_VEHICLE = "reference_crawler"


def _params(vehicle: str, soil: str) -> dict:
    from ..presets import soil_preset, vehicle_preset

    return {**vehicle_preset(vehicle), **soil_preset(soil)}


def linearize_command(args) -> int:
    from ..foundations.files import check_output_folder
    from ..reports.run_files import output_lock

    opts = linearize_model_options(args.set)
    out = check_output_folder(args.out)  # before the work: outputs checked writable first
    with output_lock(out):  # a second run into the folder fails at once
        return _linearize(args, opts, out)


def _linearize(args, opts, out) -> int:
    from ..control import linearization as L
    from ..control.trim import trim
    from ..model import SystemModel
    from ..reports.run_files import write_folder

    params = _params(args.vehicle, args.soil)
    model = SystemModel(opts)
    tp = trim(model, params, args.speed, args.radius)
    lin = L.linearize(model, tp, path_frame=args.path_frame)
    mode_list = L.modes(lin)
    ctrb = L.controllability(lin)
    d = L.to_dict(lin)
    d["vehicle_preset"], d["soil_preset"] = args.vehicle, args.soil
    d["lateral_law"] = opts.lateral_law
    d["modes"] = mode_list
    d["controllability"] = ctrb
    report = L.report_markdown(lin, mode_list, ctrb)
    # the one writer (all or nothing; linearization.json last: its presence means the folder is whole)
    write_folder(out, {"linearization.npz": L.npz_bytes(lin), "bode.png": L.bode_png(lin), "modes.md": report,
                       "linearization.json": json.dumps(d, indent=1) + "\n"}, clear=False)
    print(report)
    print(f"linearization written to {out} (linearization.json, linearization.npz, modes.md, bode.png)")
    return 0


def linearize_model_options(overrides):
    """The model options of ``symtrack linearize`` from its ``--set model.KEY=VALUE`` overrides (the
    ``[model]`` keys of a scenario: any :class:`~symtrack.model.ModelOptions` field but its build flags, e.g.
    ``model.lateral_law=shear``); the package's defaults for the rest."""
    from ..foundations.config import apply_overrides, check_keys
    from ..foundations.errors import ParameterError, ScenarioError
    from ..model import ModelOptions
    from ..model.options import scenario_keys

    doc = apply_overrides({}, list(overrides or []))
    other = sorted(set(doc) - {"model"})
    if other:
        raise ScenarioError(f"symtrack linearize --set: section(s) {', '.join(other)} not allowed; allowed: model "
                            "(the soil and vehicle are --soil and --vehicle)")
    table = doc.get("model", {})
    check_keys("model", table, scenario_keys())
    try:
        return ModelOptions(**table)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err


def mpc_command(args) -> int:
    from ..foundations.errors import ScenarioError
    from .simulate import check_output_file, check_output_folder, check_terrain_in

    overrides = list(args.set or [])
    if args.solver:
        overrides.append(f"mpc.solver={args.solver}")
    if args.jit:
        overrides.append("mpc.jit=true")
    terrain_in = getattr(args, "terrain_in", None)
    terrain_out = getattr(args, "terrain_out", None)
    plant_kind = getattr(args, "plant", None)
    if plant_kind is None and terrain_in:
        plant_kind = "grid"
    if plant_kind == "homogeneous" and (terrain_in or terrain_out):
        raise ScenarioError("--terrain-in / --terrain-out need the grid plant; drop --plant homogeneous")
    out = check_output_folder(args.out)
    check_terrain_in(terrain_in)
    if terrain_out:
        check_output_file(terrain_out, "--terrain-out")
    from ..reports.run_files import output_lock

    with output_lock(out):  # before any work: a second run into the folder fails at once
        return _mpc(args, overrides, terrain_in, terrain_out, plant_kind, out)


def _mpc(args, overrides, terrain_in, terrain_out, plant_kind, out) -> int:
    from ..foundations import progress

    # loading the modules, the run file and the vehicle model is seconds of its own, after the seconds of
    # starting Python: said once it passes half a second
    with progress.timed_step(f"loading {args.scenario} and building its vehicle model", slow_s=0.5):
        from ..control import closedloop, scenario
        from ..foundations.errors import ScenarioError

        sc = scenario.load(args.scenario, overrides, plant_kind)
        if terrain_out and sc.terrain is None:
            raise ScenarioError(f"--terrain-out: scenario {sc.name!r} runs on the homogeneous plant (no [terrain] "
                                "section); add --plant grid")
        from ..simulation.builder import system_model

        model = system_model(sc.model)  # the cached build (symtrack.simulation.builder)
    from ..foundations.interrupt import InterruptWatch
    from ..reports.run_files import finished_before, terrain_lock

    # the terrain file is locked from before it is read until it is replaced (as symtrack simulate)
    with terrain_lock(terrain_out) if terrain_out else contextlib.nullcontext():
        done = finished_before(out, sc, terrain_in, terrain_out or None)
        if done is not None:  # the same run, killed after its commit point: completed, not run again
            print(f"{sc.name}: this run (run id {done['run_id']}) was stopped after it had updated {terrain_out}; "
                  f"its files are now complete and it was not run again; results in {args.out}")
            return 0
        with progress.timed_step(f"building the {sc.plant} plant"):
            plant = closedloop.make_plant(sc, model, terrain_in)
        try:
            with InterruptWatch():  # also when CasADi turns the interrupt into a solver/integrator error
                res = closedloop.run(sc, plant=plant, model=model, progress=not args.quiet)
        except KeyboardInterrupt:  # Ctrl-C stops at once, nothing written
            import sys

            print("\nsymtrack mpc: interrupted; nothing written", file=sys.stderr)
            return 130
        if terrain_in:
            res.summary["terrain_in"] = str(terrain_in)
        with progress.timed_step(f"writing the results and drawing the figures into {out}"):
            closedloop.write(out, res, terrain_out=terrain_out or None, plant=plant)
    s = res.summary
    rms = s["rms_lateral_error_m"]
    print(f"{sc.name}: rms lateral error on straights "
          f"{'n/a' if rms is None else f'{100 * rms:.2f} cm'}, max {100 * s['max_lateral_error_m']:.1f} cm; "
          f"solve time median {s['solve_time_median_ms']:.1f} ms, p95 {s['solve_time_p95_ms']:.1f} ms, "
          f"max {s['solve_time_max_ms']:.1f} ms; failed solves {s['failed_solves']}; "
          f"over the sample time {s['overrun_samples']}; plant {s['plant']} "
          f"{s['plant_wall_time_s']:.1f} s, solver {s['solver_wall_time_s']:.1f} s of wall time; results in {args.out}")
    return 0


def mpc_scenarios_list() -> list[str]:
    """The built-in MPC scenarios, read from the folder (importing symtrack.control would load
    CasADi and python-control just to print --help)."""
    folder = Path(__file__).resolve().parents[1] / "control" / "scenarios"
    return sorted(p.stem for p in folder.glob("*.toml"))


def add_parsers(sub) -> None:
    """Register the control subcommands on the argparse subparsers of symtrack.cli."""
    lz = sub.add_parser("linearize", help="trim point + exact linearization (A, B, C, D, modes, Bode plots)")
    lz.add_argument("--speed", type=float, required=True, help="speed V [m/s]")
    lz.add_argument("--radius", type=float, default=None, help="turn radius R [m], positive = left (default: straight)")
    lz.add_argument("--soil", default=DEFAULT_SOIL, help=f"soil preset (default {DEFAULT_SOIL})")
    lz.add_argument("--vehicle", default=DEFAULT_VEHICLE, help=f"vehicle preset (default {DEFAULT_VEHICLE})")
    lz.add_argument("--path-frame", action="store_true",
                    help="straight running only: keep y_m and yaw_rad (lateral offset, heading error)")
    lz.add_argument("--set", action="append", metavar="model.KEY=VALUE",
                    help="a model option, e.g. model.lateral_law=shear (any [model] key of a scenario)")
    lz.add_argument("--out", required=True, help="output folder")
    lz.set_defaults(func=linearize_command)
    mp = sub.add_parser("mpc", help="closed-loop MPC path tracking (built-in name or TOML file); "
                        f"built-in: {', '.join(mpc_scenarios_list())}")
    mp.add_argument("scenario")
    mp.add_argument("--out", required=True, help="output folder")
    mp.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="override a scenario value")
    mp.add_argument("--solver", choices=("ipopt", "fatrop", "rti"),
                    help="shorthand for --set mpc.solver=... (default rti, the real-time iteration; ipopt and fatrop "
                    "solve the NLP to convergence, not in real time: docs/control.md)")
    mp.add_argument("--jit", action="store_true",
                    help="compile the solver's functions (gcc; cached across runs under ~/.cache/symtrack)")
    mp.add_argument("--plant", choices=("homogeneous", "grid"),
                    help="the plant: homogeneous terrain, or the persistent grid terrain (default: grid when the "
                    "scenario has a [terrain] section; --plant grid adds cell_m = 0.25 m, the field covering the path)")
    mp.add_argument("--terrain-in", metavar="FILE", help="grid plant: start from a saved terrain (docs/terrain.md)")
    mp.add_argument("--terrain-out", metavar="FILE", help="grid plant: save the final terrain (docs/terrain.md)")
    mp.add_argument("--quiet", action="store_true", help="no progress bar")
    mp.set_defaults(func=mpc_command)
