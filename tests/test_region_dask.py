"""The region study on Dask: the folder, the resume after a rerun, a killed client and a killed worker (the
outputs bit for bit those of an uninterrupted run), the report and the maps (docs/region.md)."""

from __future__ import annotations

import hashlib
import json
import math
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
    """The field-seasons' maps (maps.npz and the per-field COGs)."""
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((out / "fields").rglob("*")) if p.suffix in (".npz", ".tif")}


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


def _field_layers(season: Path) -> dict:
    """A field-season's maps.npz layers by their file's name."""
    from symtrack.region.outputs import FIELD_ARRAYS

    with np.load(season / "maps.npz") as z:
        return {name: z[key] for name, key in FIELD_ARRAYS.items()} | {"field_mask": z["field_mask"]}


def _agree(region: dict, rt, files: dict, mask: np.ndarray, transform) -> tuple:
    """The region map cells (rows, columns) whose centres fall in the field's polygon's cells through the field
    COGs' ``transform``, and how many values the field's COGs (``files``: {layer: (bands, transform)}) give
    them unlike the region's maps (``region``: {layer: bands}, transform ``rt``)."""
    from rasterio.transform import rowcol

    R, C = np.nonzero(region["risk_class"][0] != 255)
    X, Y = rt @ (C + 0.5, R + 0.5)
    rows, cols = (np.asarray(a) for a in rowcol(transform, X, Y))  # the cell each centre falls in (floor)
    ok = (rows >= 0) & (cols >= 0) & (rows < mask.shape[0]) & (cols < mask.shape[1])
    ok[ok] = mask[rows[ok], cols[ok]]
    bad = 0
    for name, (data, _) in files.items():
        a, b = data[:, rows[ok], cols[ok]], region[name][:, R[ok], C[ok]]
        bad += int(np.count_nonzero(~((a == b) | ((a != a) & (b != b)))))  # NaN equals NaN
    return R[ok], C[ok], bad


def test_each_field_seasons_cogs_are_its_maps_on_its_own_grid_and_agree_with_the_region_maps(reference):
    import rasterio
    from affine import Affine

    from symtrack.region.outputs import LAYERS, field_band, field_transform

    inp, out, _ = reference
    spec = load_region(inp / "region_demo.toml")
    assert spec.field_maps
    c = spec.map_cell_m
    for y in spec.years:
        region = {}
        for name in LAYERS:
            with rasterio.open(out / "maps" / str(y) / f"{name}.tif") as ds:
                region[name] = ds.read()
                rt = ds.transform
        checked = np.zeros(region["risk_class"].shape[1:], dtype=bool)
        for f in spec.fields:
            season = out / "fields" / f.field_id / str(y)
            arrays = _field_layers(season)
            shape = arrays["trafficked_count"].shape
            files = {}
            for name, (dtype, nodata, per_depth, unit, _) in LAYERS.items():
                with rasterio.open(season / f"{name}.tif") as ds:
                    # Cloud-Optimized (GDAL's COG driver's layout, tiled), the region maps' types and bands
                    assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG" and ds.profile["tiled"]
                    assert ds.dtypes[0] == dtype and ds.crs.to_epsg() == 32633
                    assert ds.nodata == nodata or (np.isnan(nodata) and np.isnan(ds.nodata))
                    assert ds.count == (len(spec.depths_m) if per_depth else 1)
                    assert (ds.width, ds.height) == shape[:2]
                    if per_depth:
                        assert ds.descriptions == tuple(f"{name} at {d:g} m [{unit}]" for d in spec.depths_m)
                    assert ds.transform.almost_equals(field_transform(f, spec.cell_m, shape), precision=1e-9)
                    data = ds.read()
                    files[name] = (data, ds.transform)
                src = arrays[name]
                for b in range(data.shape[0]):  # bit for bit the field's maps.npz (in the layer's type: lossless)
                    want = field_band(src, b if per_depth else None)
                    assert np.array_equal(want.astype(dtype), want, equal_nan=want.dtype.kind == "f")
                    assert want.astype(dtype).tobytes() == data[b].tobytes(), (f.field_id, y, name, b)
            mask = field_band(arrays["field_mask"])

            T = files["risk_class"][1]
            R, C, bad = _agree(region, rt, files, mask, T)
            assert len(R) > 0.8 * f.area_m2 / c ** 2 and bad == 0, (f.field_id, y, bad)
            checked[R, C] = True
            # one cell off along either of the grid's axes: the region maps disagree
            for shift in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                assert _agree(region, rt, files, mask, T @ Affine.translation(*shift))[2] > 0.01 * len(R), \
                    (f.field_id, y, shift)
        assert np.array_equal(checked, region["risk_class"][0] != 255)  # every region cell is a field's


def test_a_field_cog_larger_than_a_tile_has_overviews_and_a_rotated_transform():
    from rasterio.io import MemoryFile

    from symtrack.region.inputs import FieldShape, field_frame
    from symtrack.region.outputs import field_band, field_cogs

    ring = [(500000.0, 6000000.0), (500300.0, 6000150.0), (500240.0, 6000270.0), (499940.0, 6000120.0)]
    theta = math.atan2(150.0, 300.0)
    f = FieldShape("big", 0, "s", "x", 1.0, tuple(ring), **field_frame(ring, theta, 8.0))
    spec = type("Spec", (), {"cell_m": 0.5, "depths_m": (0.1, 0.3), "crs": "EPSG:32633"})()
    shape = (math.ceil(f.size_m[0] / 0.5), math.ceil(f.size_m[1] / 0.5))
    assert shape[0] > 512
    rng = np.random.default_rng(3)
    arrays = {"counts": rng.integers(0, 5, shape).astype(np.uint16),
              "sigma_max_kPa": rng.random((*shape, 2), dtype=np.float32),
              "density_change_Mg_per_m3": rng.random((*shape, 2), dtype=np.float32),
              "risk_class": rng.integers(0, 3, (*shape, 2)).astype(np.uint8)}
    files = field_cogs(spec, f, arrays)
    assert files == field_cogs(spec, f, arrays)  # the same bytes each time
    with MemoryFile(files["stress_max_kPa.tif"]) as m, m.open() as ds:
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG" and ds.profile["tiled"]
        assert ds.overviews(1) and ds.block_shapes[0] == (512, 512)
        assert ds.read(2).tobytes() == field_band(arrays["sigma_max_kPa"], 1).tobytes()
        # the field's cell (i, j) centre, in the region's CRS, is in the raster's row shape[1]-1-j, column i
        for i, j in ((0, 0), (shape[0] - 1, 3), (17, shape[1] - 1)):
            assert ds.index(*f.to_world((i + 0.5) * 0.5, (j + 0.5) * 0.5)) == (shape[1] - 1 - j, i)
        assert ds.transform.b != 0 and ds.transform.d != 0  # rotated: the field's lines are not east-west


def test_the_field_cogs_can_be_switched_off(reference, tmp_path):
    from symtrack.region.study import build_context, field_season

    inp, _, _ = reference
    text = (inp / "region_demo.toml").read_text()
    p = inp / "no_field_maps.toml"
    p.write_text(text + "\n[outputs]\nfield_maps = false\n")
    spec = load_region(p)
    assert not spec.field_maps
    res = field_season(build_context(spec), 0, spec.years[0], None)
    assert sorted(res["files"]) == ["maps.npz", "summary.json"]
    p.write_text(text + "\n[outputs]\nfield_map = false\n")
    with pytest.raises(ScenarioError, match=r"unknown key\(s\) in \[outputs\]: field_map; allowed: field_maps"):
        load_region(p)
    p.write_text(text + "\n[outputs]\nfield_maps = 1\n")
    with pytest.raises(ScenarioError, match="outputs.field_maps = 1 must be true or false"):
        load_region(p)
    p.unlink()


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


# ---- the study's top-level outputs, committed once ---------------------------------------------------------------
OUTPUTS = ("region.json", "fields.csv", "fields.gpkg", "summary.json", "report.html")


def _top(out: Path) -> dict:
    """The study's own files a user sees (not fields/, not the dot files: manifest, journal, lock)."""
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and not any(q.startswith(".") for q in p.relative_to(out).parts)
            and p.relative_to(out).parts[0] != "fields"}


def _fork_region(spec, out: Path, kill_at: int | None = None) -> int:
    """run_region in a forked child (no field-season left to run: no cluster), killed (SIGKILL) at its
    ``kill_at``-th commit step; its exit code, or -signal."""
    from symtrack.reports import run_files

    pid = os.fork()
    if pid == 0:  # the child: no output, no clean-up on exit (as a killed process)
        code = 70
        try:
            run_files._step_count = 0
            if kill_at is not None:
                os.environ[run_files.KILL_AT_STEP_ENV] = str(kill_at)
            res = run_region(spec, out, workers=1, progress=False)
            code = 0 if res.ran == 0 else 72
        except BaseException:  # noqa: BLE001 - the child's exit code tells
            code = 71
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the runs are forked (POSIX)")
def test_the_top_level_outputs_appear_together_when_killed_at_any_commit_step(reference, tmp_path, monkeypatch):
    """The study's outputs killed at the steps of their commit (SYMTRACK_KILL_AT_COMMIT_STEP): the folder
    holds none of them (but region.json, the study's identity, written first) or all of them, or, past the
    commit point, a journal the next run completes; the rerun's outputs are the uninterrupted run's."""
    import shutil

    from symtrack.region import outputs
    from symtrack.reports import run_files

    inp, out, _ = reference
    # the report's images are not what is tested: small stand-ins (the files' names and order kept)
    monkeypatch.setattr(outputs, "_map_png", lambda spec, canv, title: f"PNG {title}".encode())
    monkeypatch.setattr(outputs, "_shares_png", lambda spec, figs: b"PNG shares")
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")  # fields.gpkg's last_change: byte for byte
    spec = load_region(inp / "region_demo.toml")
    base = tmp_path / "base"
    shutil.copytree(out / "fields", base / "fields")
    ref = tmp_path / "ref"
    shutil.copytree(base, ref)
    before = run_files._step_count
    res = run_region(spec, ref, workers=1, progress=False)
    assert res.ran == 0
    steps = run_files.COMMIT_STEPS[before:run_files._step_count]
    new = _top(ref)
    assert set(OUTPUTS) <= set(new) and sum(n.startswith("maps/") for n in new) == 12
    first = steps.index("renamed region.json into place") + 1  # region.json's own commit, first
    start = steps.index("staged region.json", first) + 1  # the outputs' commit, its first step
    commit = steps.index("journal written, not yet renamed", start) + 1  # the outputs' commit point
    last = steps.index("renamed summary.json into place") + 1
    # every step of the outputs' commit: before its journal, the renames, summary.json, the clean-up
    picks = sorted({start, start + 5, commit - 1, commit, commit + 1, commit + 3, (commit + last) // 2, last - 1, last,
                    len(steps)})
    for k in picks:
        case = tmp_path / f"kill_{k}"
        shutil.copytree(base, case)
        assert _fork_region(spec, case, kill_at=k) == -signal.SIGKILL, f"step {k} ({steps[k - 1]})"
        got = _top(case)
        journal = (case / run_files.JOURNAL).is_file()
        if k <= commit:  # before the commit point: none of the outputs but region.json
            assert set(got) == {"region.json"} and not journal, f"step {k} ({steps[k - 1]}): {sorted(got)}"
        elif "summary.json" in got:  # summary.json is the last file moved in: all of them are there
            assert got == new, f"step {k} ({steps[k - 1]})"
        else:  # past the commit point: the journal completes the folder
            assert journal, f"step {k} ({steps[k - 1]})"
        run_files.recover(case)  # what the next writer of the folder does first: the old state or the new one
        assert _top(case) == ({"region.json": new["region.json"]} if k <= commit else new), \
            f"recovered after step {k} ({steps[k - 1]})"
        assert _fork_region(spec, case) == 0
        assert _top(case) == new, f"rerun after step {k} ({steps[k - 1]})"
        assert not list(case.glob(".symtrack-region-scratch-*")) and not list(tmp_path.glob(f".{case.name}.staging-*"))


def _gpkg_rows(path: Path):
    """fields.gpkg read with sqlite3 (the GeoPackage standard's tables) and shapely (the geometries' WKB)."""
    import sqlite3
    import struct

    import shapely

    con = sqlite3.connect(path)
    try:
        head = (con.execute("PRAGMA application_id").fetchone()[0], con.execute("PRAGMA user_version").fetchone()[0])
        geom_cols = con.execute("SELECT table_name, column_name, geometry_type_name, srs_id FROM "
                                "gpkg_geometry_columns").fetchall()
        srs = {r[0]: r[1:] for r in con.execute("SELECT srs_id, organization, organization_coordsys_id FROM "
                                                "gpkg_spatial_ref_sys")}
        contents = con.execute("SELECT table_name, data_type, srs_id FROM gpkg_contents").fetchall()
        cur = con.execute('SELECT * FROM "fields" ORDER BY fid')
        names = [d[0] for d in cur.description]
        rows = []
        for r in cur.fetchall():
            blob = r[1]
            magic, version, flags, srs_id = blob[:2], blob[2], blob[3], struct.unpack("<i", blob[4:8])[0]
            assert magic == b"GP" and version == 0 and flags == 0b11, blob[:8]
            env = struct.unpack("<4d", blob[8:40])
            g = shapely.from_wkb(blob[40:])
            rows.append((g, env, srs_id, dict(zip(names[2:], r[2:], strict=True))))
    finally:
        con.close()
    return head, geom_cols, srs, contents, names, rows


def test_fields_gpkg_is_the_table_with_the_fields_polygons(reference):
    import csv
    import shutil

    inp, out, _ = reference
    head, geom_cols, srs, contents, names, rows = _gpkg_rows(out / "fields.gpkg")
    assert head == (0x47504B47, 10301)  # "GPKG", GeoPackage 1.3.1
    assert geom_cols == [("fields", "geom", "POLYGON", 32633)] and contents == [("fields", "features", 32633)]
    assert srs[32633] == ("EPSG", 32633) and {4326, -1, 0} <= set(srs)
    with open(out / "fields.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert names[:2] == ["fid", "geom"] and names[2:] == list(table[0])  # the columns of fields.csv, in its order
    assert len(rows) == len(table) == 6
    spec = load_region(inp / "region_demo.toml")
    rings = {f.field_id: f for f in spec.fields}
    for (g, env, srs_id, vals), row in zip(rows, table, strict=True):
        f = rings[vals["field_id"]]
        assert srs_id == 32633 and g.geom_type == "Polygon" and g.is_valid
        assert np.allclose(np.asarray(g.exterior.coords)[:-1], np.asarray(f.world_ring))  # the field's own ring
        assert env == (g.bounds[0], g.bounds[2], g.bounds[1], g.bounds[3])
        assert g.area / 1e4 == pytest.approx(float(row["area_ha"]), rel=1e-12)
        for k, v in row.items():  # the same values as the CSV's (the numbers' repr, the text as written)
            x = vals[k]
            assert (x if isinstance(x, str) else repr(x) if isinstance(x, float) else str(x)) == v, (k, v, x)
    if shutil.which("ogrinfo"):  # GDAL's GeoPackage driver, where it is installed: the same features
        r = subprocess.run(["ogrinfo", "-ro", "-so", "-al", str(out / "fields.gpkg")], capture_output=True, text=True)
        assert r.returncode == 0 and "Feature Count: 6" in r.stdout and "Geometry: Polygon" in r.stdout, r.stdout
        assert "ERROR" not in r.stderr and "Warning" not in r.stderr, r.stderr


def test_a_worker_lets_go_of_each_field_season_once_it_is_committed(tmp_path, monkeypatch):
    """A worker's memory does not grow with the region: the client lets go of a field-season's result once it is
    committed (a worker kept every finished field-season's maps and state until the study ended: some 5.5 MB a
    field-season of the demo's, 0.7 GB a worker on a 1,000 ha region). At each commit, every field-season
    committed two or more commits before is gone from the workers (within 10 s: the release is asynchronous)."""
    from distributed import get_client

    from symtrack.region import study

    spec = load_region(demo.write_region(tmp_path / "in", n_fields=4, seed=7, systems=MINI, years={2021: 0.0},
                                         length_m=(90.0, 120.0), width_m=(60.0, 80.0), spacing_m=160.0))
    committed, lingering = [], []
    commit = study._commit

    def spy(out, f, y, res):
        client = get_client()
        old = committed[:-1]
        deadline = time.monotonic() + 10.0
        while True:
            held = set().union(*client.has_what().values())
            stale = [p for p in old if any(str(k).startswith(p) for k in held)]
            if not stale or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        lingering.append(len(stale))
        committed.append(f"symtrack-region-{f.field_id}-{y}-")
        return commit(out, f, y, res)

    monkeypatch.setattr(study, "_commit", spy)
    res = run_region(spec, tmp_path / "out", workers=1, progress=False, outputs=False)
    assert res.ran == 4 and len(lingering) == 4
    assert lingering == [0, 0, 0, 0], lingering


class _Workers:
    """A client's scheduler_info with the given workers' memory limits [bytes] (0: none)."""

    def __init__(self, *limits):
        self.limits = limits

    def scheduler_info(self, n_workers: int = 5):
        assert n_workers == -1  # every worker asked for
        return {"workers": {f"tcp://w{i}": {"memory_limit": m} for i, m in enumerate(self.limits)}}


def test_a_field_too_large_for_a_workers_memory_is_refused_before_any_task(tmp_path):
    """The largest fast field's season against the smallest worker's memory limit times Dask's terminate
    fraction (0.95): refused with the field, its grid, the need and the limit; workers without a limit, or none
    connected yet, are not checked."""
    from symtrack.region import study

    spec = load_region(_small(tmp_path / "in"))
    need = max(study.task_memory_bytes(spec, f) for f in spec.fields)
    study.check_worker_memory(spec, _Workers(int(need / 0.9), 0))  # room enough: nothing raised
    study.check_worker_memory(spec, _Workers(0))
    study.check_worker_memory(spec, _Workers())
    with pytest.raises(ScenarioError, match=r"field '.+': a season on its grid of \d+ x \d+ cells of cell_m = 0.5 m "
                                            r"\(.* ha, 4 depths\) needs about .* GB on a worker, more than the .* GB"):
        study.check_worker_memory(spec, _Workers(int(2 * need), int(need / 0.96)))


_TASK_PEAK = """
import json, sys
from pathlib import Path
from symtrack.region import demo, study
from symtrack.region.inputs import load_region

def status(key):
    with open("/proc/self/status") as f:
        return 1024.0 * float(next(line.split()[1] for line in f if line.startswith(key + ":")))

folder = Path(sys.argv[1])
spec = load_region(demo.write_region(folder, n_fields=1, seed=7, years={2021: 0.0}, length_m=(400.0, 400.0),
                                     width_m=(300.0, 300.0)))
ctx = study.build_context(spec)
before = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
study.field_season(ctx, 0, 2021, None)
print(json.dumps({"before": before, "peak": status("VmHWM"),
                  "estimate": study.task_memory_bytes(spec, spec.fields[0]) - study.WORKER_BASE_BYTES}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the peak is read from /proc/self/status")
def test_the_task_memory_estimate_bounds_a_field_seasons_measured_peak(tmp_path):
    """A process's first field-season (the largest: its per-process tables are built on the way) peaks above what
    the process held before it (VmHWM, a fresh process, a 12 ha field at 0.5 m) by at most the estimate's
    per-cell share and at least 70 % of it (study.TASK_BYTES_PER_CELL_DEPTH: the measured peaks rounded up)."""
    proc = subprocess.run([sys.executable, "-c", _TASK_PEAK, str(tmp_path)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    d = json.loads(proc.stdout.strip().splitlines()[-1])
    grown = d["peak"] - d["before"]
    assert 0.7 * d["estimate"] <= grown <= d["estimate"], (grown / 1e6, d["estimate"] / 1e6)
