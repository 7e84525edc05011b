"""Parameter sweeps on Dask distributed: the design, its validation, the runs on a cluster, the
sweep folder (docs/studies.md).

    from symtrack import studies
    res = studies.sweep("validation", {"vehicle.mass_kg": [5000, 6000], "soil.bekker_n": [0.6, 0.8]},
                        out="out/sweep", overrides={"run.integrator": "rosenbrock"}, workers=2)
    res.rows          # the rows of results.csv (dicts); res.ok: every run succeeded

The folder (schema version :data:`SCHEMA_VERSION`)::

    DIR/sweep.json            the design: scenario, kind, fixed overrides, axes, every run's id and values
    DIR/comparison.png        each figure against each varied key (symtrack.studies.plots)
    DIR/results.csv           one row per run: the varied keys, run_id, status, error, run_wall_time_s,
                              every scalar figure of the run's summary.json
    DIR/runs/<id>/            the files of a single run, committed once (staged, then put in place with
                              summary.json last: it means the run finished), and their manifest
    DIR/runs/<id>/run.json    the run's record: status, error, overrides, worker host, wall time

A rerun into the same folder skips the runs whose ``summary.json`` is there and redoes the rest
(a run's folder is replaced whole: nothing of a failed or killed attempt is left beside the new
files). The folder is locked while the sweep runs: a second sweep into it is refused at once.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..foundations.errors import ScenarioError, SymtrackError
from ..foundations.files import atomic_write_bytes, atomic_write_text, check_output_folder
from ..foundations.progress import Progress
from ..reports.html import report_html
from ..reports.run_files import output_lock, write_folder
from .design import Axis, axes_from, design_runs, normalise_overrides, run_id
from .runfile import Kind, register_kind, sweep_arguments, worker_modules
from .runs import Source, load, resolve_source, run_one

__all__ = ["SCHEMA_VERSION", "STATUSES", "SweepResult", "check_scheduler_address", "dask_client", "plan",
           "results_csv", "scalar_figures", "sweep"]

log = logging.getLogger("symtrack.studies")

SCHEMA_VERSION = 1
# ok: summary.json written; failed: the run raised (its message in error); not_run: not reached
# (the sweep was interrupted)
STATUSES = ("ok", "failed", "not_run")
# run_wall_time_s: the run on its worker, model build and file rendering included (the summary's
# wall_time_s is the time loop's alone)
FIXED_COLUMNS = ("run_id", "status", "error", "run_wall_time_s")


@dataclass
class Plan:
    """A validated sweep: its scenario, axes and runs (id -> overrides), nothing run yet."""

    source: Source
    fixed: dict
    axes: list[Axis]
    samples: int | None
    seed: int
    runs: list[dict]  # {"id", "values", "overrides"}

    def describe(self) -> dict:
        return {"schema_version": SCHEMA_VERSION, "kind": self.source.kind, "scenario": self.source.label,
                "scenario_name": self.source.name, "overrides": self.fixed,
                "axes": [a.describe() for a in self.axes], "samples": self.samples, "seed": self.seed,
                "runs": [{"id": r["id"], "values": r["values"]} for r in self.runs]}


@dataclass
class SweepResult:
    """What :func:`sweep` returns: the rows of results.csv and the counts."""

    out: Path
    rows: list[dict]
    ran: int = 0
    skipped: int = 0
    wall_time_s: float = 0.0
    failed: list[dict] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when every run of the sweep succeeded."""
        return all(r["status"] == "ok" for r in self.rows)

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.rows)

    SHOWN_ROWS = 12
    SHOWN_COLUMNS = 8

    def _figures(self) -> dict:
        return {"runs": len(self.rows), "runs_ok": self.count("ok"), "runs_failed": self.count("failed"),
                "ran": self.ran, "skipped": self.skipped, "wall_time_s": self.wall_time_s}

    def __repr__(self) -> str:
        from ..reports.html import short_repr

        return short_repr("SweepResult", str(self.out), self._figures(),
                          ("runs", "runs_ok", "runs_failed", "wall_time_s"))

    def _repr_html_(self) -> str:
        """The view in a notebook: the folder, the counts of runs and the run time, then the first rows of
        results.csv (its first columns; the file has them all)."""
        from ..reports.html import notebook_html

        columns = list(self.rows[0])[:self.SHOWN_COLUMNS] if self.rows else []
        rows = [[r.get(c) for c in columns] for r in self.rows[:self.SHOWN_ROWS]]
        more = len(self.rows) - len(rows)
        facts = [("sweep", str(self.out)), ("table", str(Path(self.out) / "results.csv"))]
        if more > 0:
            facts.append(("rows not shown", more))
        return notebook_html(f"sweep in {str(self.out)!r}", self._figures(), facts, rows=rows or None,
                             row_header=columns)


def plan(scenario, vary=None, *, ranges=None, samples: int | None = None, seed: int = 0, overrides=None,
         kind: str = "auto") -> Plan:
    """Build and validate a sweep without running it: every value of every axis, then every
    run's scenario, is checked by the scenario's loader; the first error is raised as a
    :class:`ScenarioError` naming the key and the value."""
    source = scenario if isinstance(scenario, Source) else resolve_source(scenario, kind)
    fixed = normalise_overrides(overrides)
    axes = axes_from(vary, ranges)
    for a in axes:
        if a.key in fixed:
            raise ScenarioError(f"{a.key} is both varied and set (--set {a.key}={fixed[a.key]!r}); drop one")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ScenarioError(f"--seed {seed!r} must be an integer")
    if not source.text.strip():
        raise ScenarioError(f"scenario {source.label!r} is empty")
    # each value alone first: the message names the key and the value
    for a in axes:
        for v in (a.values if not a.sampled else (a.low, a.high)):
            try:
                load(source.kind, source.text, source.name, {**fixed, a.key: v})
            except ScenarioError as err:
                raise ScenarioError(f"--vary {a.key}={v!r}: {err}") from err
    runs = []
    seen = set()
    for values in design_runs(axes, samples, seed):
        ov = {**fixed, **values}
        try:
            load(source.kind, source.text, source.name, ov)
        except ScenarioError as err:
            which = ", ".join(f"{k}={v!r}" for k, v in values.items())
            raise ScenarioError(f"the run with {which}: {err}") from err
        rid = run_id(source.kind, source.text, ov)
        if rid in seen:
            continue  # integer sampling can give the same point twice
        seen.add(rid)
        runs.append({"id": rid, "values": values, "overrides": ov})
    return Plan(source, fixed, axes, samples, seed, runs)


def scalar_figures(summary: dict) -> dict:
    """The scalar figures of a summary.json (numbers, booleans, strings, nulls; notes and nested
    tables left out), for a row of results.csv."""
    return {k: v for k, v in summary.items()
            if k != "schema_version" and not k.endswith("_note")
            and (v is None or isinstance(v, (bool, int, float, str)))}


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return str(v)


def results_csv(rows: list[dict], keys: list[str]) -> str:
    """results.csv from rows: the varied keys, the fixed columns, then every figure in order of
    first appearance."""
    figures: list[str] = []
    for r in rows:
        figures += [k for k in r if k not in figures and k not in keys and k not in FIXED_COLUMNS]
    cols = [*keys, *FIXED_COLUMNS, *figures]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    return buf.getvalue()


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _row(run: dict, summary: dict | None, record: dict) -> dict:
    """The row of a run: ok when its summary is there, else failed or not_run from its record."""
    row = dict(run["values"])
    row["run_id"] = run["id"]
    if summary is not None:
        row.update(status="ok", error="", run_wall_time_s=record.get("wall_time_s"))
        row.update(scalar_figures(summary))
    elif record.get("status") == "failed":
        row.update(status="failed", error=record.get("error", ""), run_wall_time_s=record.get("wall_time_s"))
    else:
        row.update(status="not_run", error="", run_wall_time_s=None)
    return row


def _row_on_disk(out: Path, run: dict) -> dict:
    folder = out / "runs" / run["id"]
    return _row(run, _read_json(folder / "summary.json"), _read_json(folder / "run.json") or {})


def _write_table(out: Path, p: Plan, rows: dict) -> list[dict]:
    """results.csv (atomically) from the rows by run id, in the order of the design."""
    table = [rows[r["id"]] for r in p.runs]
    atomic_write_text(out / "results.csv", results_csv(table, [a.key for a in p.axes]))
    return table


def _store(out: Path, run: dict, result: dict, kind: str) -> dict:
    """The files of a finished run into DIR/runs/<id>/, committed once (:func:`symtrack.reports.run_files.
    write_folder`: staged beside the folder, then put in place, summary.json last, with the folder's
    manifest; a kill leaves the earlier attempt's folder or the whole new one, never a mix), with its
    record run.json; returns its row of results.csv."""
    folder = out / "runs" / run["id"]
    files = dict(result.get("files") or {})
    summary = files.pop("summary.json", None)
    record = {"schema_version": SCHEMA_VERSION, "id": run["id"], "kind": kind, "values": run["values"],
              "overrides": run["overrides"], "status": result["status"], "error": result["error"],
              "wall_time_s": result.get("wall_time_s"), "cpu_time_s": result.get("cpu_time_s"),
              "host": result.get("host"), "pid": result.get("pid")}
    files["run.json"] = json.dumps(record, indent=2, default=repr) + "\n"
    ok = summary is not None and result["status"] == "ok"
    if ok:
        files["summary.json"] = summary
    write_folder(folder, files, clear=True)
    return _row(run, json.loads(summary), record) if ok else _row(run, None, record)


# the modules a worker needs for the tasks of :func:`dask_client` other than a sweep's runs (those of a
# sweep's runs: their kind's, :func:`symtrack.studies.runfile.worker_modules`), imported once by the fork
# server of the local cluster's workers (:func:`_start_fork_server`), never by each worker
WORKER_MODULES = {"validate": ("symtrack.studies.validate",)}
MP_METHOD_KEY = "distributed.worker.multiprocessing-method"
# Dask's defaults of distributed.nanny.pre-spawn-environ: what a nanny sets before it spawns a worker
WORKER_ENVIRON = {"MALLOC_TRIM_THRESHOLD_": 65536, "OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1,
                  "OPENBLAS_NUM_THREADS": 1}


def _start_fork_server(modules: tuple[str, ...]) -> bool:
    """Start the fork server of the local cluster's workers (multiprocessing's forkserver method),
    if it is not running yet: a fresh single-threaded process that imports distributed, symtrack,
    CasADi, matplotlib and the ``modules`` of the tasks once. Each worker is then a fork of it:
    no import of its own (2-3 s a worker when spawned), and it exits without an interpreter's
    teardown (most of the 1.7 s that a cluster of spawned workers took to stop). Returns before
    the server's imports are done, so they overlap the client's own start; a worker's start waits
    for them. False where the platform has no forkserver (the workers are then spawned)."""
    import multiprocessing
    from multiprocessing import forkserver

    import dask

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    multiprocessing.get_context("forkserver").set_forkserver_preload(
        ["distributed", "numpy", "symtrack.studies.runs", *modules])
    # the variables a nanny sets before it spawns a worker (one thread for OpenMP, OpenBLAS, MKL) must
    # be there before the server imports numpy; the nanny writes them into this process's environment
    # the same way. Dask's config has them once distributed is imported (not yet, on a first sweep)
    env = dask.config.get("distributed.nanny.pre-spawn-environ", default=None)
    env = WORKER_ENVIRON if env is None else env
    os.environ.update({k: str(v) for k, v in env.items() if v is not None})
    forkserver.ensure_running()
    return True


def _worker_start(modules: tuple[str, ...]):
    """Dask's settings of a new local cluster's workers, for as long as the cluster runs (a nanny
    that restarts a dead worker starts it the same way): forked from the fork server
    (:func:`_start_fork_server`, started here) in place of Dask's default start method (spawn),
    and without the workers' statistical profiler (it samples the running task's stack every
    10 ms, for a dashboard that a local sweep does not open: 0.23-0.26 s of CPU per run against
    0.07-0.13 s without it). A start method that the user's Dask config names otherwise
    (``distributed.worker.multiprocessing-method``: fork, forkserver) is kept as it is. A
    context manager."""
    import dask

    # read before distributed is imported (its import is what the fork server's imports overlap): the
    # user's config files and DASK_* variables only, spawn when they say nothing
    forked = dask.config.get(MP_METHOD_KEY, default="spawn") == "spawn" and _start_fork_server(modules)
    import distributed  # noqa: F401 - its defaults in Dask's config first: leaving the setting removes what it added

    return dask.config.set({"distributed.worker.profile.enabled": False,
                            **({MP_METHOD_KEY: "forkserver"} if forked else {})})


@contextlib.contextmanager
def dask_client(kind: str, workers: int = 2, scheduler: str | None = None):
    """A Dask client for tasks of ``kind`` (a key of :data:`WORKER_MODULES`) other than a sweep's
    runs (``symtrack validate --dask``): on the scheduler at ``scheduler``, or on a new local cluster
    of ``workers`` processes started as a sweep's are (:func:`_worker_start`, :func:`_client`).
    Closed, and the local cluster stopped, on leaving."""
    if scheduler:
        _check_scheduler_address(scheduler)
    with _worker_start(WORKER_MODULES.get(kind, ())) if not scheduler else contextlib.nullcontext():
        client, cluster = _client(workers, scheduler)
        try:
            yield client
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def check_scheduler_address(address: str) -> None:
    """Refuse a scheduler address that is not ``[protocol://]host:port`` (:func:`_check_scheduler_address`),
    before anything runs."""
    _check_scheduler_address(address)


def _check_scheduler_address(address: str) -> None:
    """A scheduler address is ``[protocol://]host:port`` (Dask's ``tcp://127.0.0.1:8786``): refused
    before anything runs otherwise."""
    rest = address.split("://", 1)[-1]
    host, sep, port = rest.rpartition(":")
    if not (sep and host and port.isdigit() and 1 <= int(port) <= 65535):
        raise ScenarioError(f"--scheduler {address!r} must be an address with a port, [tcp://]HOST:PORT "
                            "(e.g. tcp://127.0.0.1:8786, the address `dask scheduler` prints)")


def _check_same_sweep(out: Path, p: Plan) -> None:
    """A folder holding another sweep's sweep.json is refused (its results.csv would be replaced);
    the same sweep (the same runs: scenario, fixed overrides and values) resumes."""
    try:
        old = json.loads((out / "sweep.json").read_text())
    except FileNotFoundError:
        return
    except (OSError, ValueError) as err:
        raise ScenarioError(f"--out {str(out)!r}: its sweep.json cannot be read ({err}); give another folder") from err
    old_ids = [r.get("id") for r in old.get("runs", [])] if isinstance(old, dict) else None
    if old_ids == [r["id"] for r in p.runs]:
        return
    what = (f"{old.get('scenario')!r}, {len(old_ids)} runs, varied "
            f"{', '.join(a.get('key', '?') for a in old.get('axes', [])) or 'nothing'}") if isinstance(old, dict) \
        and old_ids is not None else "an unreadable design"
    raise ScenarioError(f"--out {str(out)!r} holds another sweep ({what}); this one ({p.source.label!r}, "
                        f"{len(p.runs)} runs, varied {', '.join(a.key for a in p.axes) or 'nothing'}) would replace "
                        "its results.csv. To resume that sweep, rerun its own command (sweep.json holds its design); "
                        "for this one, give another --out")


def _client(workers: int, scheduler: str | None):
    """A Dask client: on the scheduler at ``scheduler`` or on a new local cluster of ``workers``
    processes (one thread each: CasADi's integrators hold the GIL; started the way
    :func:`_worker_start` sets). Returns (client, cluster)."""
    from distributed import Client, LocalCluster

    # the scheduler of a local cluster runs in this process: its INFO lines are not ours to show
    logging.getLogger("distributed").setLevel(logging.WARNING)
    # the client's own errors (a lost scheduler: a traceback per reconnection attempt) are the sweep's
    # to report, in one message (_run_all)
    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)
    if scheduler:
        try:
            return Client(scheduler, timeout="15s"), None
        except (OSError, TimeoutError) as err:
            raise SymtrackError(f"--scheduler {scheduler!r}: cannot connect ({err}); start one with "
                                "`dask scheduler` and workers with `dask worker ADDRESS`") from err
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
    except RuntimeError as err:  # Dask's "Nanny failed to start": its worker process died while it started
        raise SymtrackError(
            f"the local Dask cluster's {workers} worker process(es) did not start ({err}); a worker process imports "
            "the script that started it: a script that runs a sweep or a region study on a local cluster must make "
            "that call under `if __name__ == \"__main__\":` (docs/studies.md); the worker's own error is printed "
            "above") from err
    return Client(cluster), cluster


def sweep(scenario, vary=None, *, out, ranges=None, samples: int | None = None, seed: int = 0, overrides=None,
          kind: str = "auto", workers: int = 2, scheduler: str | None = None, progress: bool = True) -> SweepResult:
    """Run a sweep on Dask distributed and write its folder.

    Parameters
    ----------
    scenario : str, path or Source
        A built-in scenario (of ``symtrack simulate``, ``symtrack mpc`` or ``symtrack field``) or a TOML
        file; or a :class:`~symtrack.studies.runs.Source` (its kind and TOML text: a sweep file's own
        scenario, :mod:`symtrack.studies.runfile`).
    vary : list of str or dict
        ``["vehicle.mass_kg=5000,6000", "soil.bekker_n=0.6:1.1"]`` as ``--vary`` takes them, or
        ``{"vehicle.mass_kg": [5000, 6000]}``; the full grid of the listed values.
    out : path
        The sweep folder (``results.csv``, ``sweep.json``, ``runs/<id>/``).
    ranges : dict, optional
        ``{"soil.bekker_n": (0.6, 1.1)}``: ranges sampled by a Latin hypercube of ``samples`` points.
    samples : int, optional
        The number of Latin hypercube points (crossed with the grid).
    seed : int
        The seed of the Latin hypercube (the same seed gives the same runs, so a rerun skips them).
    overrides : list of str or dict, optional
        Fixed overrides of every run, as ``--set``.
    kind : "auto", "simulate", "mpc" or "field"
        The scenario kind (a sweep name of :func:`symtrack.studies.runfile.sweep_kinds`); "auto" takes
        the first kind whose loader accepts the scenario.
    workers : int
        Processes of the local cluster (ignored with ``scheduler``).
    scheduler : str, optional
        The address of a running Dask scheduler (``tcp://HOST:PORT``).
    progress : bool
        A progress bar on a terminal, log lines otherwise.

    Returns
    -------
    SweepResult
        ``rows`` (those of results.csv), ``ok``, ``ran``, ``skipped``.

    Raises
    ------
    ScenarioError
        An invalid sweep, before anything runs.
    KeyboardInterrupt
        On Ctrl-C, after cancelling the runs in flight and writing results.csv with the finished ones.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 1024:
        raise ScenarioError(f"--workers {workers!r} must be an integer in [1, 1024]")
    if scheduler:
        _check_scheduler_address(scheduler)
    p = plan(scenario, vary, ranges=ranges, samples=samples, seed=seed, overrides=overrides, kind=kind)
    out = check_output_folder(str(out))
    _check_same_sweep(out, p)
    t0 = time.perf_counter()
    todo = [r for r in p.runs if not (out / "runs" / r["id"] / "summary.json").is_file()]
    skipped = len(p.runs) - len(todo)
    say = log.info if progress else log.debug
    say("sweep of %d runs of %s (%s): %d to run, %d finished before; %s", len(p.runs), p.source.label,
        p.source.kind, len(todo), skipped, f"scheduler {scheduler}" if scheduler else f"{workers} local workers")
    rows = {r["id"]: _row_on_disk(out, r) for r in p.runs}
    for r in todo:
        rows[r["id"]] = _row(r, None, {})  # to be (re)done: not_run until this sweep has run it
    failed = []
    # the folder's lock (a second sweep into it is refused at once), then the cluster: a scheduler that
    # cannot be reached leaves nothing written
    start = _worker_start(worker_modules(p.source.kind)) if todo and not scheduler else contextlib.nullcontext()
    with output_lock(out), start:
        client, cluster = _client(workers, scheduler) if todo else (None, None)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "sweep.json", json.dumps(p.describe(), indent=2, default=repr) + "\n")
        if todo:
            failed = _run_all(out, p, todo, rows, client, cluster, progress)
        table = _write_table(out, p, rows)
        from .plots import comparison_png  # matplotlib: imported when a sweep draws

        png = comparison_png(table, [a.key for a in p.axes])
        if png is not None:
            atomic_write_bytes(out / "comparison.png", png)
        atomic_write_text(out / "report.html", _report(p, table, png))
    return SweepResult(out, table, len(todo), skipped, time.perf_counter() - t0, failed)


def _report(p: Plan, table: list[dict], png: bytes | None) -> str:
    """DIR/report.html: the sweep's table and its comparison plot, one self-contained page."""
    header = list(table[0]) if table else []
    rows = [[r.get(k) for k in header] for r in table]
    counts = {s: sum(r.get("status") == s for r in table) for s in STATUSES}
    summary = {"runs": len(table), **counts, "varied": ", ".join(a.key for a in p.axes)}
    return report_html(f"symtrack sweep: {p.source.name}", summary, {"comparison.png": png} if png else {},
                       p.source.text, tables={"results.csv": (header, rows)},
                       note=f"{p.source.kind} scenario {p.source.label}; fixed overrides {p.fixed or 'none'}")


class SchedulerLost(Exception):
    """The client lost its scheduler: no run of the sweep can finish (not a failure of a run)."""

    def __init__(self, done: int, total: int):
        super().__init__(f"after {done} of {total} runs")
        self.done, self.total = done, total


def _scheduler_lost(client, err: BaseException) -> bool:
    """Whether a run's error is the loss of the scheduler (Dask cancels every future with the
    reason "scheduler-connection-lost" and the client leaves its running state), not the run's."""
    return "scheduler-connection-lost" in str(err) or \
        getattr(client, "status", "running") not in ("running", "newly-created")


def _run_all(out: Path, p: Plan, todo: list[dict], rows: dict, client, cluster, progress: bool) -> list:
    """The runs of ``todo`` on the client's cluster; each finished run is stored at once and
    results.csv rewritten (at most once a second, and at the end); the client (and a local
    cluster) are closed at the end. Returns the failed runs.

    A worker process that dies (killed, out of memory) loses its run: Dask's scheduler gives the
    run to another worker (a local cluster's nanny restarts the dead one), up to Dask's
    ``distributed.scheduler.allowed-failures`` deaths for one run (3 by default), after which the run
    is failed with Dask's KilledWorker. A scheduler that disappears ends the sweep with
    :class:`SymtrackError`: the finished runs are stored, the rest stay not_run for a rerun."""
    from distributed import as_completed

    futures = {}
    failed = []
    bar = Progress(len(todo), f"sweep {p.source.name}", enabled=progress)
    modules = worker_modules(p.source.kind)
    try:
        by_id = {r["id"]: r for r in todo}
        for r in todo:
            task = {"id": r["id"], "kind": p.source.kind, "text": p.source.text, "name": p.source.name,
                    "overrides": r["overrides"], "modules": modules}
            futures[client.submit(run_one, task, key=f"symtrack-run-{r['id']}-{time.time_ns()}", pure=False)] = r
        done, last_table = 0, time.perf_counter()
        bar.update(0, f"0/{len(todo)} runs")
        for fut in as_completed(list(futures)):
            run = futures[fut]
            try:
                result = fut.result()
            except Exception as err:  # noqa: BLE001 - the run raised, or its worker died SCHEDULER_RETRIES times
                if _scheduler_lost(client, err):
                    raise SchedulerLost(done, len(todo)) from err
                result = {"id": run["id"], "status": "failed", "error": f"{type(err).__name__}: {err}",
                          "files": {}}
            rows[run["id"]] = _store(out, by_id[result["id"]], result, p.source.kind)
            done += 1
            values = ", ".join(f"{k}={v!r}" for k, v in run["values"].items())
            if result["status"] != "ok":
                failed.append({"id": run["id"], "values": run["values"], "error": result["error"]})
                log.warning("run %s (%s) failed: %s", run["id"], values, result["error"])
            elif progress and not bar.enabled:
                log.info("[%d/%d] run %s (%s) ok in %.1f s", done, len(todo), run["id"], values,
                         result.get("wall_time_s") or 0.0)
            bar.update(done, f"{done}/{len(todo)} runs, {len(failed)} failed")
            if time.perf_counter() - last_table > 1.0:
                _write_table(out, p, rows)
                last_table = time.perf_counter()
    except KeyboardInterrupt:
        client.cancel(list(futures), force=True)
        # the rows from the folder: a run whose summary.json was stored when Ctrl-C came (between its store
        # and its row, or inside the store after the summary) is finished, and the table says so
        for r in todo:
            rows[r["id"]] = _row_on_disk(out, r)
        _write_table(out, p, rows)
        raise
    except SchedulerLost as lost:  # the runs not finished stay not_run: a rerun of the command does them
        _write_table(out, p, rows)
        raise SymtrackError(f"the Dask scheduler was lost (connection closed) after {lost.done} of {lost.total} runs; "
                            f"the finished runs are kept in {out} (results.csv; the others are not_run): start the "
                            "scheduler and its workers again and rerun the same command to do the rest") from None
    finally:
        bar.close()
        client.close()
        if cluster is not None:
            cluster.close()
    return failed


def _run_sweep_file(arguments, out, progress):
    return sweep(out=out, progress=progress is not False, **arguments)


# the sweep's own kind of run file, registered here with its runner (symtrack.studies imports this module, so
# it is registered whenever symtrack.studies.runfile is imported; the run-file module does not import the sweep)
register_kind(Kind("sweep", ("[sweep]",), "a sweep", "symtrack sweep", None, sweep_arguments, _run_sweep_file,
                   needs_out=True))
