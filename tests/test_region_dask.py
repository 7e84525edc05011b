"""The region study on Dask: the folder, the resume after a rerun, a killed client and a killed worker (the
outputs bit for bit those of an uninterrupted run), the report and the maps (docs/region.md)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.region import demo
from symtrack.region.inputs import load_region
from symtrack.region.study import run_region

# a small calendar: three machines, one tillage (the maps and the resume do not need a whole season)
MINI = {"mini": [
    {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]},
    {"name": "stubble discing", "machine": "disc_6m", "window": [222, 240], "loosens_to_m": 0.08},
    {"name": "drilling", "machine": "drill_6m", "window": [262, 292]},
]}


def _small(folder: Path, n: int = 3) -> Path:
    return demo.write_region(folder, n_fields=n, seed=7, systems=MINI, length_m=(90.0, 120.0), width_m=(60.0, 80.0),
                             spacing_m=160.0)


def _hashes(out: Path) -> dict:
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((out / "fields").rglob("*.npz"))}


def _figures(out: Path) -> dict:
    """Every field-season's summary without its timings."""
    res = {}
    for p in sorted((out / "fields").rglob("summary.json")):
        s = json.loads(p.read_text())
        s.pop("wall_time_s")
        s.pop("cpu_time_s")
        for o in s["operations"]:
            o.pop("wall_time_s")
        res[str(p.relative_to(out))] = s
    return res


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run on two workers."""
    folder = tmp_path_factory.mktemp("region_ref")
    spec = load_region(_small(folder / "in"))
    res = run_region(spec, folder / "out", workers=2, progress=False)
    return folder / "in", folder / "out", res


def test_the_folder_table_maps_and_report(reference):
    _, out, res = reference
    assert res.ran == 6 and res.skipped == 0
    for name in ("region.json", "fields.csv", "summary.json", "report.html"):
        assert (out / name).is_file(), name
    lines = (out / "fields.csv").read_text().splitlines()
    assert len(lines) == 1 + 6 and lines[0].startswith("field_id,soil,system,year,area_ha")
    import rasterio

    with rasterio.open(out / "maps" / "2021" / "risk_class.tif") as ds:
        assert ds.count == 4 and ds.crs.to_epsg() == 32633 and ds.nodata == 255
        # Cloud-Optimized: GDAL's COG driver's layout (tiled; overviews where a map is larger than a tile)
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG" and ds.profile["tiled"]
        risk = ds.read(2)
    with rasterio.open(out / "maps" / "2021" / "trafficked_count.tif") as ds:
        count = ds.read(1)
    inside = risk != 255
    assert inside.any() and np.array_equal(inside, count != 65535)
    # the map's share of medium and high risk at 0.3 m equals the fields' own (area-weighted) within the
    # resampling of 0.5 m cells onto 1 m ones
    s = json.loads((out / "summary.json").read_text())["by_year"]["2021"]
    share = float((risk[inside] >= 1).mean())
    ref = s["risk_medium_fraction_0.3m"] + s["risk_high_fraction_0.3m"]
    assert abs(share - ref) < 0.02 + 0.05 * ref, (share, ref)
    html = (out / "report.html").read_text()
    assert "Share of the area at each risk class" in html and "The worst fields" in html
    assert html.count("data:image/png;base64,") >= 3


def test_a_rerun_skips_the_finished_and_redoes_the_rest_bit_for_bit(reference, tmp_path):
    inp, out, _ = reference
    import shutil

    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    spec = load_region(inp / "region_demo.toml")
    f = spec.fields[1]
    # a field's second season lost (as a kill between its two files leaves it: maps.npz without summary.json)
    (copy / "fields" / f.field_id / "2022" / "summary.json").unlink()
    res = run_region(spec, copy, workers=1, progress=False)
    assert res.ran == 1 and res.skipped == 5
    assert _hashes(copy) == _hashes(out)
    assert _figures(copy) == _figures(out)


def test_a_field_season_killed_past_its_commit_point_is_completed_not_run_again(reference, tmp_path, monkeypatch):
    inp, out, _ = reference
    import shutil

    from symtrack.reports import run_files

    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    spec = load_region(inp / "region_demo.toml")
    season = copy / "fields" / spec.fields[2].field_id / "2021"
    files = {p.relative_to(season).as_posix(): p.read_bytes() for p in season.rglob("*")
             if p.is_file() and not p.name.startswith(".symtrack")}
    shutil.rmtree(season)

    def killed(*a, **k):  # the process stops after the journal (the commit point), before a file is moved in
        raise KeyboardInterrupt

    monkeypatch.setattr(run_files, "_apply", killed)
    with pytest.raises(KeyboardInterrupt):
        run_files.write_folder(season, files)
    monkeypatch.undo()
    assert (season / run_files.JOURNAL).is_file() and not (season / "summary.json").exists()
    res = run_region(spec, copy, workers=1, progress=False)
    assert res.ran == 0 and res.skipped == 6
    assert not (season / run_files.JOURNAL).exists() and not list(season.parent.glob(".2021.staging-*"))
    assert _hashes(copy) == _hashes(out)
    assert _figures(copy) == _figures(out)


def test_another_study_in_the_folder_is_refused(reference, tmp_path):
    inp, out, _ = reference
    text = (inp / "region_demo.toml").read_text().replace("seed = 7", "seed = 8")
    other = tmp_path / "other.toml"
    other.write_text(text.replace('"fields.geojson"', json.dumps(str(inp / "fields.geojson")))
                     .replace('"suction_', f'"{inp}/suction_'))
    with pytest.raises(ScenarioError, match="holds another region study"):
        run_region(load_region(other), out, workers=1, progress=False)


def _in_place(out: Path, name: str) -> int:
    """The field-seasons in place holding ``name`` (not a staged copy beside one: fields/F/.YEAR.staging-*/)."""
    return len(list((out / "fields").glob(f"*/[0-9][0-9][0-9][0-9]/{name}")))


def _wait_for(pred, timeout_s, what):
    t0 = time.perf_counter()
    while not pred():
        if time.perf_counter() - t0 > timeout_s:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.mark.slow
def test_a_killed_client_then_a_rerun_gives_the_uninterrupted_outputs(reference, tmp_path):
    inp, out, _ = reference
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "symtrack", "region", str(inp / "region_demo.toml"), "--out", str(tmp_path / "o"),
           "--workers", "1", "--quiet"]
    p = subprocess.Popen(cmd, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _wait_for(lambda: _in_place(tmp_path / "o", "summary.json") >= 2 or p.poll() is not None, 300,
                  "the first commits")
        assert p.poll() is None, p.stderr.read().decode()
        os.killpg(p.pid, signal.SIGKILL)  # the client and its local cluster, mid-run
        p.wait(30)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    # the field-seasons in place (not a staged copy beside one: fields/F/.YEAR.staging-*/summary.json);
    # one killed past its commit point (its journal written, its files not yet all moved in) is completed
    # by the rerun, not run again: it counts as finished before
    done = _in_place(tmp_path / "o", "summary.json")
    past_commit = _in_place(tmp_path / "o", ".symtrack-commit.json")
    assert 2 <= done < 6 and past_commit <= 1
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    m = re.search(r"\((\d+) run, (\d+) finished before\)", r.stdout)
    assert m, r.stdout
    ran, before = int(m[1]), int(m[2])
    assert ran + before == 6 and done <= before <= done + past_commit, (ran, before, done, past_commit)
    assert before == done or "completing the files of the run that was stopped after its commit point" in r.stderr
    assert _hashes(tmp_path / "o") == _hashes(out)
    assert _figures(tmp_path / "o") == _figures(out)


@pytest.mark.slow
def test_a_killed_worker_loses_no_field_season(reference, tmp_path):
    inp, out, _ = reference
    from distributed import Client, LocalCluster

    spec = load_region(inp / "region_demo.toml")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        errors = []

        def run():
            try:
                run_region(spec, tmp_path / "o", scheduler=cluster.scheduler_address, progress=False)
            except Exception as err:  # noqa: BLE001 - reported by the test below
                errors.append(err)

        t = threading.Thread(target=run)
        t.start()
        _wait_for(lambda: len(list((tmp_path / "o" / "fields").rglob("summary.json"))) >= 1 or not t.is_alive(), 300,
                  "the first commit")
        pids = client.run(os.getpid)
        os.kill(sorted(pids.values())[0], signal.SIGKILL)  # one worker, mid-run (its nanny starts another)
        t.join(600)
        assert not errors, errors
    assert _hashes(tmp_path / "o") == _hashes(out)
    assert _figures(tmp_path / "o") == _figures(out)


def test_the_command_refuses_bad_inputs_before_any_work(tmp_path, capsys):
    from symtrack.cli.main import main

    p = _small(tmp_path / "in", n=2)
    p.write_text(p.read_text().replace('machine = "disc_6m"', 'machine = "disc_9m"'))
    assert main(["region", str(p), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "systems.mini.operations[1].machine = 'disc_9m' is not a machine of the built-in fleet" in err
    assert not (tmp_path / "o" / "fields").exists()


def test_a_field_no_plan_fits_is_refused_or_left_out(tmp_path):
    p = _small(tmp_path / "in", n=2)
    geo = json.loads((tmp_path / "in" / "fields.geojson").read_text())
    x, y = 600_000.0, 5_600_000.0  # a strip 12 m wide: no headland round of a 7.5 m header fits in it
    strip = [[x, y], [x + 200.0, y], [x + 200.0, y + 12.0], [x, y + 12.0], [x, y]]
    geo["features"].append({"type": "Feature", "properties": {"field_id": "strip", "soil": "silt_loam",
                                                              "system": "mini"},
                            "geometry": {"type": "Polygon", "coordinates": [strip]}})
    (tmp_path / "in" / "fields.geojson").write_text(json.dumps(geo))
    from symtrack.region.study import check_plans

    spec = load_region(p)
    with pytest.raises(ScenarioError, match=r"field 'strip' \(system 'mini'\): no direction of the track lines fits"):
        check_plans(spec)
    p.write_text(p.read_text().replace("seed = 7", 'seed = 7\nunplannable_fields = "skip"'))
    spec = load_region(p)
    check_plans(spec)
    assert [f.field_id for f in spec.fields] == ["F001", "F002"]
    assert spec.skipped[0]["field_id"] == "strip" and "operation.headland_passes" in spec.skipped[0]["reason"]
