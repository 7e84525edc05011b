"""``symtrack bench --sweep``: the overhead of a sweep on Dask against the same runs one after
another in one process (the target: 8 validation runs on 2 workers in at most 0.65 x the
serial time, the model build counted).

Both sides do the same work per run: load the scenario, build the model (compiled libraries from
the warm cache), simulate, write the files of a single run (plots included). The sweep's wall
time counts the local cluster's start and stop; the 2-worker sweep runs first, so it also pays
what a process pays once (importing distributed, starting the fork server that imports symtrack
for the workers: symtrack.studies.engine); the 1-worker sweep after it finds both done. A last
row runs the same sweep on a cluster started before and warmed by one run (``--scheduler``),
which leaves out the cluster's start, stop and imports. Measured in one process, one after
another, so the ratios compare like with like on a shared machine. A row after the serial one
splits the same runs over plain processes (no Dask, imports done before the clock starts): the
machine's own bound for any process-parallel sweep at that moment (on a machine whose cores other
jobs keep busy, it is near 1 x: Linux shares the CPU between sessions, not processes).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["SWEEP_MASSES_KG", "bench_rows", "plain_processes_wall_time", "serial_wall_time", "sweep_wall_time"]

# 8 vehicle masses around the reference crawler's 5500 kg: 8 validation runs that all finish
SWEEP_MASSES_KG = (5000.0, 5150.0, 5300.0, 5450.0, 5600.0, 5750.0, 5900.0, 6050.0)


def serial_wall_time(scenario: str, key: str, values, overrides: list[str], out: Path) -> tuple[float, float]:
    """(wall time, simulated time) of the runs one after another in this process."""
    from ..api import simulate
    from ..simulation.scenario import load_scenario

    t0 = time.perf_counter()
    sim = 0.0
    for k, v in enumerate(values):
        res = simulate(load_scenario(scenario, [*overrides, f"{key}={v!r}"]), progress=False)
        res.write(out / f"run_{k}")
        sim += res.summary["sim_time_s"]
    return time.perf_counter() - t0, sim


# one plain process of plain_processes_wall_time: warms up as the serial loop does (imports, one run),
# says ready, waits for a line, runs its share
_PLAIN_PROCESS = """
import sys
from pathlib import Path
from symtrack.bench.sweep import serial_wall_time
out, key, values = Path(sys.argv[1]), sys.argv[2], [float(v) for v in sys.argv[3].split(",")]
serial_wall_time(sys.argv[4], key, values[:1], sys.argv[5:], out / "warm")
print("ready", flush=True)
sys.stdin.readline()
serial_wall_time(sys.argv[4], key, values, sys.argv[5:], out)
print("done", flush=True)
"""


def plain_processes_wall_time(scenario: str, key: str, values, overrides: list[str], out: Path,
                              processes: int) -> float:
    """Wall time of the same runs split over ``processes`` plain Python processes (no Dask), timed
    from when all of them are warm (imports and one run done, as the serial loop's warm-up) to
    when the last one is done: what the machine gives a process-parallel sweep at best, with no
    start, stop or imports counted."""
    shares = [list(values)[k::processes] for k in range(processes)]
    procs = [subprocess.Popen([sys.executable, "-c", _PLAIN_PROCESS, str(out / f"process_{k}"), key,
                               ",".join(repr(float(v)) for v in share), scenario, *overrides],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for k, share in enumerate(shares) if share]
    try:
        for p in procs:
            if p.stdout.readline().strip() != "ready":
                raise RuntimeError("a plain process of the sweep bench did not start")
        t0 = time.perf_counter()
        for p in procs:
            p.stdin.write("go\n")
            p.stdin.flush()
        for p in procs:
            if p.stdout.readline().strip() != "done":
                raise RuntimeError("a plain process of the sweep bench failed")
        return time.perf_counter() - t0
    finally:
        for p in procs:
            p.stdin.close()
            p.wait()


def sweep_wall_time(scenario: str, key: str, values, overrides: list[str], out: Path, workers: int,
                    scheduler: str | None = None) -> float:
    """Wall time of the same runs as one sweep on a new local cluster of ``workers`` processes
    (or on the running cluster of ``scheduler``)."""
    from ..studies import sweep

    t0 = time.perf_counter()
    res = sweep(scenario, {key: list(values)}, out=out, overrides=overrides, workers=workers, scheduler=scheduler,
                progress=False)
    wall = time.perf_counter() - t0
    if not res.ok:
        raise RuntimeError(f"the benchmark sweep had failed runs: {res.failed}")
    return wall


def bench_rows(quick: bool = False, workers=(2, 1)) -> list[dict]:
    """Rows of the sweep overhead: serial, then a sweep on each number of workers (in that order:
    the first pays the process's one-off costs)."""
    values = SWEEP_MASSES_KG[:4] if quick else SWEEP_MASSES_KG
    key, scenario, overrides = "vehicle.mass_kg", "validation", []
    n = len(values)
    with tempfile.TemporaryDirectory(prefix="symtrack-bench-sweep-") as scratch:
        tmp = Path(scratch)
        # warm-up: the compiled libraries are in the cache before anything is timed
        serial_wall_time(scenario, key, values[:1], overrides, tmp / "warm")
        serial, sim = serial_wall_time(scenario, key, values, overrides, tmp / "serial")
        rows = [{"group": "sweep overhead", "case": f"{n} validation runs one after another, one process",
                 "integrator": "cvodes", "sim_time_s": sim, "wall_time_s": serial, "real_time_factor": sim / serial,
                 "note": "load, model build, simulate, write (plots) per run"}]
        plain = plain_processes_wall_time(scenario, key, values, overrides, tmp / "plain", max(workers))
        rows.append({"group": "sweep overhead",
                     "case": f"the {n} runs split over {max(workers)} plain processes (no Dask)",
                     "integrator": "cvodes", "sim_time_s": sim, "wall_time_s": plain,
                     "real_time_factor": sim / plain, "ratio_to_serial": plain / serial,
                     "note": f"{plain / serial:.2f} x the serial time: the machine's bound for a sweep "
                     "(imports before the clock, no start or stop)"})
        for w in workers:
            wall = sweep_wall_time(scenario, key, values, overrides, tmp / f"sweep_{w}", w)
            rows.append({"group": "sweep overhead", "case": f"symtrack sweep of the {n} runs, {w} local worker(s)",
                         "integrator": "cvodes", "sim_time_s": sim, "wall_time_s": wall,
                         "real_time_factor": sim / wall, "ratio_to_serial": wall / serial,
                         "note": f"{wall / serial:.2f} x the serial time (cluster start and stop counted)"})
        rows.append(_running_cluster_row(scenario, key, values, overrides, tmp, serial, sim, max(workers)))
    return rows


def _running_cluster_row(scenario, key, values, overrides, tmp: Path, serial: float, sim: float, workers: int):
    """The same sweep on a cluster that is already running and has run once (imports done): what
    Dask itself costs per sweep, without the cluster's start and stop."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.CRITICAL) as cluster:
        address = cluster.scheduler_address
        sweep_wall_time(scenario, key, [values[0] * 1.01], overrides, tmp / "cluster_warm", workers, address)
        wall = sweep_wall_time(scenario, key, values, overrides, tmp / "cluster", workers, address)
    return {"group": "sweep overhead", "case": f"symtrack sweep of the {len(values)} runs, --scheduler of a running "
            f"{workers}-worker cluster", "integrator": "cvodes", "sim_time_s": sim, "wall_time_s": wall,
            "real_time_factor": sim / wall, "ratio_to_serial": wall / serial,
            "note": f"{wall / serial:.2f} x the serial time (cluster started before, workers warm)"}
