"""symtrack sweep (docs/studies.md): the grid on a local Dask cluster and its table against a
single run, a failing value among good ones, reruns that redo only what is missing, refusal of
invalid sweeps before anything runs, the Latin hypercube, an MPC sweep on a scheduler started
here."""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
import tomllib

import numpy as np
import pytest

import symtrack
from symtrack import studies
from symtrack.cli import main
from symtrack.foundations.errors import ScenarioError, SymtrackError
from symtrack.reports.run_files import read_manifest
from symtrack.studies import design, latin_hypercube, plan
from symtrack.studies import engine as sweep_module

# a short homogeneous run: 0.6 s of the validation's torque programme, compiled Rosenbrock
FAST = ["run.integrator=rosenbrock", "run.stop_after_distance_m=none", "run.duration_s=0.6",
        "run.output_dt_s=0.05"]


def _sets(items):
    return [a for s in items for a in ("--set", s)]


def _table(path):
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def grid_sweep(tmp_path_factory):
    """A 2 x 2 sweep run by the command line on 2 local workers."""
    out = tmp_path_factory.mktemp("sweep") / "grid"
    code = main(["sweep", "validation", "--vary", "vehicle.mass_kg=5000,6500", "--vary",
                 "soil.k_phi_N_per_m_n2=6e5,1.2e6", "--out", str(out), "--workers", "2", "--quiet", *_sets(FAST)])
    return out, code


def test_grid_sweep_writes_a_row_and_a_run_folder_per_combination(grid_sweep):
    out, code = grid_sweep
    assert code == 0
    rows = _table(out / "results.csv")
    assert [(float(r["vehicle.mass_kg"]), float(r["soil.k_phi_N_per_m_n2"])) for r in rows] == [
        (5000, 6e5), (5000, 1.2e6), (6500, 6e5), (6500, 1.2e6)]
    assert {r["status"] for r in rows} == {"ok"} and {r["error"] for r in rows} == {""}
    assert (out / "comparison.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "report.html").read_text()  # one report: the table and the comparison plot
    assert page.count("data:image/png;base64,") == 1 and all(r["run_id"] in page for r in rows)
    design_doc = json.loads((out / "sweep.json").read_text())
    assert design_doc["schema_version"] == 1 and design_doc["kind"] == "simulate"
    assert [r["id"] for r in design_doc["runs"]] == [r["run_id"] for r in rows]
    for r in rows:
        folder = out / "runs" / r["run_id"]
        summary = json.loads((folder / "summary.json").read_text())
        for name in ("trajectory.csv", "scenario.resolved.toml", "path.png", "sinkage.png"):
            assert (folder / name).is_file(), name
        resolved = tomllib.loads((folder / "scenario.resolved.toml").read_text())
        assert resolved["vehicle"]["mass_kg"] == float(r["vehicle.mass_kg"])
        assert resolved["soil"]["k_phi_N_per_m_n2"] == float(r["soil.k_phi_N_per_m_n2"])
        # every scalar figure of the summary is a column, with the summary's value
        for key in ("distance_m", "sinkage_sprocket_mm", "yaw_final_deg", "sim_time_s", "stopped_by"):
            assert r[key] == (str(summary[key]) if isinstance(summary[key], str) else repr(summary[key]))
        assert json.loads((folder / "run.json").read_text())["status"] == "ok"
    # heavier vehicle, softer soil: more sinkage (the values really reached the runs)
    sink = {(float(r["vehicle.mass_kg"]), float(r["soil.k_phi_N_per_m_n2"])): float(r["sinkage_sprocket_mm"])
            for r in rows}
    assert sink[(6500, 6e5)] > sink[(5000, 6e5)] > sink[(5000, 1.2e6)]


def test_grid_sweep_rows_agree_with_single_runs(grid_sweep, tmp_path):
    out, _ = grid_sweep
    for row in _table(out / "results.csv"):
        sc = symtrack.load_scenario("validation", FAST + [f"vehicle.mass_kg={row['vehicle.mass_kg']}",
                                                          f"soil.k_phi_N_per_m_n2={row['soil.k_phi_N_per_m_n2']}"])
        res = symtrack.simulate(sc)
        single = res.summary
        for key in ("distance_m", "sinkage_sprocket_mm", "sinkage_idler_mm", "shear_driven_max_m",
                    "speed_final_m_s"):
            assert float(row[key]) == pytest.approx(single[key], rel=1e-9, abs=1e-12), (row["run_id"], key)
        # the run's folder: the files of the single run (and run.json), the same trajectory, the same
        # summary but for the machine's timings
        res.write(tmp_path / row["run_id"])
        folder, alone = out / "runs" / row["run_id"], tmp_path / row["run_id"]
        assert {p.name for p in folder.iterdir()} == {p.name for p in alone.iterdir()} | {"run.json"}
        assert (folder / "trajectory.csv").read_bytes() == (alone / "trajectory.csv").read_bytes()
        timings = ("wall_time_s", "real_time_factor")
        swept, written = (json.loads((f / "summary.json").read_text()) for f in (folder, alone))
        assert {k: v for k, v in swept.items() if k not in timings} == {
            k: v for k, v in written.items() if k not in timings}


def test_rerun_of_a_finished_sweep_redoes_nothing(grid_sweep, monkeypatch, capsys):
    out, _ = grid_sweep
    mtimes = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("summary.json")}
    assert len(mtimes) == 4

    def no_cluster(*a, **k):
        raise AssertionError("a finished sweep started a cluster")

    monkeypatch.setattr(sweep_module, "_client", no_cluster)
    code = main(["sweep", "validation", "--vary", "vehicle.mass_kg=5000,6500", "--vary",
                 "soil.k_phi_N_per_m_n2=6e5,1.2e6", "--out", str(out), "--quiet", *_sets(FAST)])
    assert code == 0
    assert "0 run now, 4 finished before" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("summary.json")} == mtimes
    assert [r["status"] for r in _table(out / "results.csv")] == ["ok"] * 4


GRID_FAULT = """
name = "grid_fault"
[run]
duration_s = 0.05
integrator = "grid_fast"
figures = false
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[terrain]
size_m = [6.0, 4.0]
origin_m = [-3.0, -2.0]
cell_m = 0.25
settle_s = 0.02
[[torque]]
t_s = 0.0
left_N_m = 2000.0
right_N_m = 2000.0
"""


def test_a_failing_run_is_recorded_and_a_rerun_redoes_only_it(tmp_path, monkeypatch, capsys):
    out = tmp_path / "faults"
    scenario = tmp_path / "grid_fault.toml"
    scenario.write_text(GRID_FAULT)
    # the field spans x in [-3, 3] m: set down at x = 40 m the vehicle is off the field at once

    def args(workers):
        return ["sweep", str(scenario), "--vary", "start.x_m=0.0,40.0,0.25", "--out", str(out), "--workers",
                str(workers), "--quiet"]

    assert main(args(2)) == 1
    assert "left the terrain field" in capsys.readouterr().err
    rows = _table(out / "results.csv")
    assert [r["status"] for r in rows] == ["ok", "failed", "ok"]
    assert "SimulationError" in rows[1]["error"] and "left the terrain field" in rows[1]["error"]
    assert rows[1]["distance_m"] == "" and float(rows[0]["sim_time_s"]) == pytest.approx(0.05)
    assert not (out / "runs" / rows[1]["run_id"] / "summary.json").exists()
    good = {r["run_id"]: (out / "runs" / r["run_id"] / "summary.json").stat().st_mtime_ns for r in rows
            if r["status"] == "ok"}

    submitted = []
    real_client = sweep_module._client

    def counting_client(*a, **k):
        client, cluster = real_client(*a, **k)
        submit = client.submit

        def counted(fn, task, **kw):
            submitted.append(task["id"])
            return submit(fn, task, **kw)

        client.submit = counted
        return client, cluster

    monkeypatch.setattr(sweep_module, "_client", counting_client)
    assert main(args(1)) == 1  # it fails again, and only it was redone
    assert submitted == [rows[1]["run_id"]]
    assert {k: (out / "runs" / k / "summary.json").stat().st_mtime_ns for k in good} == good
    assert [r["status"] for r in _table(out / "results.csv")] == ["ok", "failed", "ok"]
    # each run's folder is committed whole, with the manifest of the files it owns
    failed_folder = out / "runs" / rows[1]["run_id"]
    assert read_manifest(failed_folder) == ["run.json"]
    assert sorted(p.name for p in failed_folder.iterdir()) == [".symtrack-manifest.json", "run.json"]
    ok_folder = out / "runs" / rows[0]["run_id"]
    assert "summary.json" in read_manifest(ok_folder)
    assert not list((out / "runs").glob(".*")), "no staging folder outlives the sweep"


def test_a_second_sweep_into_a_folder_being_written_is_refused(tmp_path, capsys):
    out = tmp_path / "busy"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from symtrack.reports.run_files import output_lock\n"
        f"with output_lock({str(out)!r}):\n    print('held', flush=True); time.sleep(60)")],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        code = main(["sweep", "validation", "--vary", "vehicle.mass_kg=5000,6500", "--out", str(out), "--quiet",
                     *_sets(FAST)])
        err = capsys.readouterr().err
        assert code != 0 and f"pid {holder.pid}" in err and "another symtrack run" in err
        assert not (out / "sweep.json").exists()
    finally:
        holder.kill()
        holder.wait()


@pytest.mark.parametrize("vary, extra, words", [
    (["vehicle.mas_kg=5000,6000"], [], ["vehicle.mas_kg", "5000", "unknown key"]),
    (["vehicle.mass_kg="], [], ["vehicle.mass_kg", "empty"]),
    (["vehicle.mass_kg=5000,,6000"], [], ["vehicle.mass_kg", "empty value"]),
    (["vehicle.mass_kg=5000,-1"], [], ["vehicle.mass_kg", "-1", "allowed range"]),
    (["run.integrator=cvodes,rk99"], [], ["run.integrator", "rk99", "cvodes"]),
    (["vehicle.mass_kg=5000,5000"], [], ["vehicle.mass_kg", "5000", "twice"]),
    (["vehicle.mass_kg=5000,6000"], ["--set", "vehicle.mass_kg=7000"], ["vehicle.mass_kg", "both varied and set"]),
    (["vehicle.mass_kg=5000:6000"], [], ["vehicle.mass_kg", "--sample"]),
    (["vehicle.mass_kg=6000:5000"], ["--sample", "4"], ["vehicle.mass_kg", "LO < HI"]),
    (["soil.bekker_n=0.5:9"], ["--sample", "4"], ["soil.bekker_n", "9", "allowed range"]),
])
def test_an_invalid_sweep_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys, vary, extra, words):
    def no_cluster(*a, **k):
        raise AssertionError("an invalid sweep started a cluster")

    monkeypatch.setattr(sweep_module, "_client", no_cluster)
    out = tmp_path / "refused"
    args = ["sweep", "validation", "--out", str(out), "--quiet", *extra]
    for v in vary:
        args += ["--vary", v]
    assert main(args) == 2
    err = capsys.readouterr().err
    for w in words:
        assert w in err, (w, err)
    assert not out.exists()


def test_an_out_of_range_combination_is_refused_by_the_loader():
    # each value alone is valid; together the output step exceeds the duration
    with pytest.raises(ScenarioError, match=r"run.duration_s=0.1.*run.output_dt_s = 0.5"):
        plan("validation", {"run.duration_s": [0.1, 2.0], "run.output_dt_s": [0.05, 0.5]},
             overrides={"run.stop_after_distance_m": "none"})


def test_latin_hypercube_hits_each_stratum_once():
    n, d = 11, 3
    u = latin_hypercube(n, d, seed=4)
    assert u.shape == (n, d) and (u >= 0).all() and (u < 1).all()
    for j in range(d):
        assert sorted(np.floor(u[:, j] * n).astype(int)) == list(range(n))
    assert np.array_equal(u, latin_hypercube(n, d, seed=4))
    assert not np.array_equal(u, latin_hypercube(n, d, seed=5))
    # the columns are not paired in the same order (independent permutations)
    assert any(not np.array_equal(np.argsort(u[:, 0]), np.argsort(u[:, j])) for j in range(1, d))


def test_sampled_design_covers_every_stratum_of_each_range_and_crosses_the_grid():
    axes = design.axes_from(["vehicle.mass_kg=5000.0:7000.0", "run.integrator=cvodes,idas"])
    runs = design.design_runs(axes, samples=8, seed=1)
    assert len(runs) == 16
    for integ in ("cvodes", "idas"):
        masses = [r["vehicle.mass_kg"] for r in runs if r["run.integrator"] == integ]
        assert sorted(int((m - 5000.0) / 250.0) for m in masses) == list(range(8))
    ints = design.design_runs(design.axes_from(["mpc.horizon_steps=3:12"]), samples=10, seed=2)
    assert sorted(r["mpc.horizon_steps"] for r in ints) == list(range(3, 13))
    assert all(isinstance(r["mpc.horizon_steps"], int) for r in ints)


def test_plan_of_a_sampled_sweep_is_the_same_on_a_rerun():
    kw = dict(ranges={"vehicle.mass_kg": (5000.0, 7000.0)}, samples=5, seed=3,
              overrides={"run.stop_after_distance_m": "none"})
    a, b = plan("validation", **kw), plan("validation", **kw)
    assert [r["id"] for r in a.runs] == [r["id"] for r in b.runs] and len(a.runs) == 5


@pytest.fixture
def dask_cluster(tmp_path):
    """A scheduler and two workers as a user starts them (`dask scheduler`, `dask worker`), on
    127.0.0.1, stopped at the end. Yields the scheduler's address."""
    from distributed import Client

    info = tmp_path / "scheduler.json"
    common = ["--no-dashboard"]
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--scheduler-file", str(info), *common], start_new_session=True,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        # the scheduler writes its file in more than one step: wait until it reads as JSON (the
        # file existing but still empty failed the setup once under load)
        deadline = time.monotonic() + 60
        address = None
        while address is None and time.monotonic() < deadline:
            try:
                address = json.loads(info.read_text())["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                time.sleep(0.1)
        assert address is not None, "the dask scheduler wrote no scheduler file within 60 s"
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", "2",
                                       "--nthreads", "1", "--host", "127.0.0.1", *common], start_new_session=True,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_mpc_sweep_on_a_scheduler_and_workers_started_here(tmp_path, dask_cluster):
    from distributed import Client

    out = tmp_path / "mpc"
    # (a setting that leaves the compiled solver as it is: one build, not one per row)
    code = main(["sweep", "straight_offset", "--vary", "mpc.rti_relinearisations=1,3", "--set", "run.duration_s=0.4",
                 "--scheduler", dask_cluster, "--out", str(out), "--quiet"])
    assert code == 0
    with Client(dask_cluster, timeout="30s") as client:  # the sweep left the user's cluster running
        assert len(client.scheduler_info()["workers"]) == 2
    rows = _table(out / "results.csv")
    assert [int(r["mpc.rti_relinearisations"]) for r in rows] == [1, 3]
    assert len({r["horizon_steps"] for r in rows}) == 1  # the MPC's own summary field
    assert json.loads((out / "sweep.json").read_text())["kind"] == "mpc"
    pids = set()
    for r in rows:
        folder = out / "runs" / r["run_id"]
        assert {"summary.json", "trajectory.csv", "path.csv", "scenario.resolved.toml"} <= {
            p.name for p in folder.iterdir()}
        assert int(r["solves"]) == 4 and int(r["failed_solves"]) == 0  # the runs ran, and their solves succeeded
        pids.add(json.loads((folder / "run.json").read_text())["pid"])
    assert os.getpid() not in pids  # run by the workers, not here


def test_ctrl_c_cancels_the_runs_in_flight_and_keeps_the_finished_ones(tmp_path):
    out = tmp_path / "interrupted"
    masses = ",".join(str(5000 + 10 * k) for k in range(60))  # far more than finish before the interrupt
    cmd = [sys.executable, "-m", "symtrack", "sweep", "validation", "--vary", f"vehicle.mass_kg={masses}",
           "--out", str(out), "--workers", "1", "--quiet", *_sets(FAST)]
    # a terminal's default SIGINT disposition, whatever this test process has (an ignored SIGINT is
    # inherited across exec, and in-process clusters of earlier tests may have changed ours)
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 180
        # a committed run: its folder's own name (pathlib's glob also finds a run's staging folder beside it,
        # ".<id>.staging-*", whose summary.json is written before the run is committed)
        while not [p for p in (out / "runs").glob("*/summary.json") if not p.parent.name.startswith(".")] \
                and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C on a terminal signals the whole process group
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "finished ones are kept" in err
    rows = _table(out / "results.csv")
    statuses = [r["status"] for r in rows]
    assert len(rows) == 60 and "ok" in statuses and "not_run" in statuses and "failed" not in statuses
    for r in rows:
        assert (out / "runs" / r["run_id"] / "summary.json").is_file() == (r["status"] == "ok")
    assert not list(out.rglob("*.tmp"))  # nothing half-written


def test_a_killed_worker_has_its_run_redone_on_another(tmp_path):
    from distributed import Client, LocalCluster

    out, box = tmp_path / "killed", []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        pids = client.run(os.getpid)
        th = threading.Thread(target=lambda: box.append(studies.sweep(
            "validation", {"vehicle.mass_kg": [5000, 5500, 6000]}, out=out, overrides=FAST,
            scheduler=cluster.scheduler_address, progress=False)))
        th.start()
        victim = pids[_busy_worker(lambda: cluster)]
        os.kill(victim, signal.SIGKILL)
        th.join(240)
        assert not th.is_alive()
    _assert_redone_elsewhere(box[0], out, victim)


def _busy_worker(get_cluster, timeout_s=120):
    """The address of a worker that is running a task of the cluster get_cluster() gives (None
    until it exists), waited for up to timeout_s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        cluster = get_cluster()
        if cluster is not None:
            busy = [ws.address for ws in list(cluster.scheduler.workers.values()) if ws.processing]
            if busy:
                return busy[0]
        time.sleep(0.05)
    raise AssertionError("no run started")


def _assert_redone_elsewhere(res, out, victim):
    """Every run of the sweep ok, none of them in the killed process."""
    assert res.ok and [r["status"] for r in res.rows] == ["ok"] * 3
    ran_on = {json.loads((out / "runs" / r["run_id"] / "run.json").read_text())["pid"] for r in res.rows}
    assert victim not in ran_on


@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="no forkserver here")
def test_a_killed_worker_of_the_local_cluster_is_forked_anew_and_its_run_redone(tmp_path, monkeypatch):
    # the local cluster's workers are forks of the fork server (which imported symtrack once); a nanny
    # whose worker dies forks a new one the same way, and the run is redone there
    import psutil

    out, box, seen = tmp_path / "local_killed", [], {}
    real_client = sweep_module._client

    def capturing_client(*a, **k):
        client, cluster = real_client(*a, **k)
        seen["cluster"] = cluster
        return client, cluster

    monkeypatch.setattr(sweep_module, "_client", capturing_client)
    th = threading.Thread(target=lambda: box.append(studies.sweep(
        "validation", {"vehicle.mass_kg": [5000, 5500, 6000]}, out=out, overrides=FAST, workers=2, progress=False)))
    th.start()
    try:
        busy = _busy_worker(lambda: seen.get("cluster"))
        cluster = seen["cluster"]
        nannies = {n.worker_address: n for n in cluster.workers.values()}
        # no statistical profiler in the workers (no dashboard to show it)
        assert all(n.config["distributed"]["worker"]["profile"]["enabled"] is False for n in nannies.values())
        victim = nannies[busy].process.pid
        parent = psutil.Process(victim).parent()  # the fork server, not this process
        assert parent.pid != os.getpid() and "multiprocessing.forkserver" in " ".join(parent.cmdline())
        # one thread for numpy's BLAS, as Dask's nanny sets it for the workers it spawns
        assert parent.environ().get("OPENBLAS_NUM_THREADS") == "1"
        os.kill(victim, signal.SIGKILL)
    finally:
        th.join(240)
    assert not th.is_alive()
    _assert_redone_elsewhere(box[0], out, victim)


def test_a_lost_scheduler_ends_the_sweep_with_a_message_and_a_rerun_resumes(tmp_path):
    """The scheduler stops while runs are in flight: the sweep ends with SymtrackError (no run is
    marked failed: the rest are not_run), the finished runs are kept, and the same sweep rerun on
    another cluster does only the rest."""
    from distributed import LocalCluster

    out, box = tmp_path / "lost", []
    vary = {"vehicle.mass_kg": [5000 + 100 * k for k in range(4)]}

    def run():
        try:
            box.append(studies.sweep("validation", vary, out=out, overrides=FAST, scheduler=cluster.scheduler_address,
                                     progress=False))
        except Exception as err:  # noqa: BLE001 - the test inspects it
            box.append(err)

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None)
    th = threading.Thread(target=run)
    th.start()
    try:
        deadline = time.monotonic() + 180
        # a committed run: its folder's own name (pathlib's glob also finds a run's staging folder beside it,
        # ".<id>.staging-*", whose summary.json is written before the run is committed)
        while not [p for p in (out / "runs").glob("*/summary.json") if not p.parent.name.startswith(".")] \
                and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        cluster.close()
        th.join(240)
    assert not th.is_alive()
    err = box[0]
    assert isinstance(err, SymtrackError) and "the Dask scheduler was lost" in str(err), err
    assert "rerun the same command" in str(err)
    rows = _table(out / "results.csv")
    statuses = [r["status"] for r in rows]
    assert len(rows) == 4 and "ok" in statuses and "not_run" in statuses and "failed" not in statuses
    for r in rows:
        assert (out / "runs" / r["run_id"] / "summary.json").is_file() == (r["status"] == "ok")
    res = studies.sweep("validation", vary, out=out, overrides=FAST, workers=1, progress=False)
    assert res.ok and res.skipped == statuses.count("ok") and res.ran == 4 - res.skipped


def test_ctrl_c_as_a_run_is_stored_leaves_it_ok_in_the_table(tmp_path, monkeypatch):
    """Ctrl-C that lands in the store of a finished run after its folder (summary.json last) is in place: the
    table written on the interrupt says the run is ok, as its folder does (the interrupt's table comes from
    the folder, not from the rows the sweep had reached)."""
    real = sweep_module.write_folder

    def store_then_interrupt(folder, files, **kw):
        real(folder, files, **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "write_folder", store_then_interrupt)
    out = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        studies.sweep("validation", ["vehicle.mass_kg=5000,5010"], out=out, overrides=FAST, workers=1,
                      progress=False)
    rows = _table(out / "results.csv")
    done = [r for r in rows if (out / "runs" / r["run_id"] / "summary.json").is_file()]
    assert len(done) == 1 and done[0]["status"] == "ok"
    assert [r["status"] for r in rows if r is not done[0]] == ["not_run"]


_NO_MAIN_GUARD = """
import sys
from symtrack.foundations.errors import SymtrackError
from symtrack.studies.engine import dask_client

try:
    with dask_client("sweep", 1, None):
        pass
except SymtrackError as err:
    print("ERROR:", err)
    sys.exit(3)
"""


def test_a_script_that_starts_a_local_cluster_without_the_main_guard_is_told_so(tmp_path):
    """A local cluster's worker process imports the script that started it: a script that starts one at its top
    level (no ``if __name__ == "__main__":``) kills its workers as they start, and Dask says only "Nanny failed to
    start". The package's error says what to change."""
    script = tmp_path / "no_guard.py"
    script.write_text(_NO_MAIN_GUARD, encoding="utf-8")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 3, (proc.stdout[-2000:], proc.stderr[-2000:])
    assert "did not start" in proc.stdout and 'under `if __name__ == "__main__":`' in proc.stdout, proc.stdout
