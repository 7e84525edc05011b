"""``symtrack simulate``: load, check the outputs can be written, simulate, write, report."""

from __future__ import annotations

import contextlib

from ..foundations.errors import ScenarioError, SimulationError
from ..foundations.files import check_output_file, check_output_folder

__all__ = ["check_output_file", "check_output_folder", "check_terrain_in", "simulate_command"]


def check_terrain_in(path) -> None:
    """A ``--terrain-in`` file that is not there is refused before any work, naming the option typed."""
    from pathlib import Path

    if path and not Path(path).is_file():
        what = "is a folder" if Path(path).is_dir() else "does not exist"
        raise ScenarioError(f"--terrain-in {str(path)!r} {what}: give a terrain file (the .npz that --terrain-out "
                            "writes)")


def simulate_command(args) -> int:
    # the outputs first: a bad --out fails at once, before CasADi is even imported
    out = check_output_folder(args.out)
    check_terrain_in(args.terrain_in)
    terrain_out = check_output_file(args.terrain_out, "--terrain-out") if args.terrain_out else None
    from ..reports.run_files import output_lock

    # the folder is locked before any work: a second run into it fails at once (it names this one's pid)
    with output_lock(out):
        return _simulate(args, out, terrain_out)


def _simulate(args, out, terrain_out) -> int:
    from ..api import IncompleteSimulation, simulate
    from ..foundations import progress
    from ..reports.run_files import finished_before, terrain_lock
    from ..simulation.scenario import load_scenario

    sc = load_scenario(args.scenario, args.set or [])
    if terrain_out is not None and sc.terrain is None:
        raise ScenarioError(f"--terrain-out: scenario {sc.name!r} has no [terrain] section (it runs on the "
                            "homogeneous terrain, which has no field to save)")
    # the terrain file is locked from before it is read (--terrain-in F --terrain-out F) until the
    # run's files and it are in place: a second writer fails at once, the two never mix
    with terrain_lock(terrain_out) if terrain_out is not None else contextlib.nullcontext():
        done = finished_before(out, sc, args.terrain_in, terrain_out)
        if done is not None:
            print(f"{sc.name}: this run (run id {done['run_id']}) was stopped after it had updated {terrain_out}; "
                  f"its files are now complete and its passes were not applied again; results in {out}")
            return 0
        try:
            res = simulate(sc, terrain=args.terrain_in, progress=not args.quiet)
        except IncompleteSimulation as err:
            # keep what was computed: the files of the run up to the failure, marked incomplete
            err.result.write(out)
            raise SimulationError(f"{err}; what was computed up to there is in {out} (summary.json: "
                                  "complete = false); no terrain file was written") from err
        with progress.timed_step(f"writing the results and drawing the figures into {out}"):
            res.write(out, terrain_out=terrain_out)
    table = res.validation_table
    if table is not None:
        print(table)
    summ = res.summary
    if res.terrain is not None:
        for k, f in enumerate(summ["passes"]):
            print(f"pass {k + 1}: rut max {f['rut_max_depth_mm']:.3f} mm, mean {f['rut_mean_depth_mm']:.3f} mm, "
                  f"new sinkage {f['new_sinkage_mean_mm']:.4f} mm, compaction resistance "
                  f"{f['compaction_resistance_mean_N']:.1f} N")
        runs = res.runs
        g = res.terrain.grid
        print(f"{sc.name}: {sum(r.t[-1] for r in runs):.2f} s simulated in {sum(r.wall_time_s for r in runs):.2f} s "
              f"on {g.n_cells} cells through {summ['terrain_channels']} channels (peak "
              f"{max(r.terrain['terrain_peak_active_cells'] for r in runs)} active); results in {out}")
    else:
        print(f"{sc.name}: {summ['sim_time_s']:.2f} s simulated in {summ['wall_time_s']:.2f} s "
              f"({summ['real_time_factor']:.1f} x real time); results in {out}")
    return 0

