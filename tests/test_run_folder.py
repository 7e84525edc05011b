"""A run's folder holds the user's files too (issue 38, items 1, 4 and 5): a run removes or replaces
only the files an earlier symtrack run recorded in the folder's manifest (``.symtrack-manifest.json``),
anything else stays with a one-line warning; two runs into one folder are refused at once by a lock
on the folder's real path that is removed on every exit; a terrain file replaced in place keeps its
mode and owner, and a read-only one is refused before any work."""

from __future__ import annotations

import json
import logging
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.cli.main import main
from symtrack.foundations.errors import ScenarioError
from symtrack.foundations.files import atomic_write_bytes
from symtrack.reports import run_files
from symtrack.reports.run_files import MANIFEST, OUTPUT_LOCK, output_lock, read_manifest, write_folder

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["--set", "run.duration_s=0.5", "--quiet"]  # the validation scenario, half a second of it


def test_a_run_into_a_folder_of_the_users_files_leaves_them(tmp_path, monkeypatch, caplog):
    # the reproduction: README.md and survey.csv stay, the stray summary.json is replaced
    (tmp_path / "README.md").write_text("# thesis\n")
    (tmp_path / "survey.csv").write_text("x,y\n")
    (tmp_path / "summary.json").write_text("{}\n")
    monkeypatch.chdir(tmp_path)
    with caplog.at_level(logging.WARNING, logger="symtrack.files"):
        assert main(["simulate", "validation", "--out", ".", *SHORT]) == 0
    assert (tmp_path / "README.md").read_text() == "# thesis\n"
    assert (tmp_path / "survey.csv").read_text() == "x,y\n"
    assert json.loads((tmp_path / "summary.json").read_text())["scenario"] == "validation"
    warnings = [r.getMessage() for r in caplog.records if r.name == "symtrack.files"]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert "README.md, survey.csv" in warnings[0] and "summary.json" in warnings[0]
    doc = json.loads((tmp_path / MANIFEST).read_text())
    assert doc["kind"] == "symtrack-run-manifest" and doc["schema_version"] == 1 and doc["symtrack_version"]
    assert "README.md" not in doc["files"] and {"summary.json", "trajectory.csv", "report.html"} <= set(doc["files"])
    # the second run into the same folder: the user's files (a pyproject.toml too) stay again
    (tmp_path / "pyproject.toml").write_text("[project]\n")
    assert main(["simulate", "validation", "--out", ".", *SHORT]) == 0
    assert {"README.md", "survey.csv", "pyproject.toml"} <= {p.name for p in tmp_path.iterdir()}
    assert not list(tmp_path.glob(".*staging*")) and not (tmp_path / OUTPUT_LOCK).exists()


def test_a_run_removes_only_what_an_earlier_run_recorded(tmp_path, caplog):
    write_folder(tmp_path, {"pass_1/summary.json": "{}", "pass_2/summary.json": "{}", "old.png": b"png",
                            "summary.json": "{}"})
    (tmp_path / "pass_2" / "my_notes.txt").write_text("mine")  # the user's, in a folder the run made
    (tmp_path / "survey.csv").write_text("x,y\n")
    with caplog.at_level(logging.WARNING, logger="symtrack.files"):
        write_folder(tmp_path, {"pass_1/summary.json": "{}", "summary.json": "{}"})
    assert not (tmp_path / "old.png").exists() and not (tmp_path / "pass_2" / "summary.json").exists()
    assert (tmp_path / "pass_2" / "my_notes.txt").read_text() == "mine"  # so pass_2/ stays
    assert (tmp_path / "survey.csv").exists()
    assert read_manifest(tmp_path) == ["pass_1/summary.json", "summary.json"]
    assert "survey.csv" in caplog.text and "pass_2" not in caplog.text.split("left as they are")[0]
    # writes without clearing (a field study's) add to the manifest
    write_folder(tmp_path, {"extra.md": "x"}, clear=False)
    assert read_manifest(tmp_path) == ["extra.md", "pass_1/summary.json", "summary.json"]


def test_a_finished_file_is_moved_in_as_a_staged_one(tmp_path):
    """A Path value (a large file the caller wrote, a region's map): moved into the staging folder, then into
    place with the others; the caller's file is gone, no copy held in memory."""
    big = tmp_path / "scratch" / "map.tif"
    big.parent.mkdir()
    big.write_bytes(b"tif" * 1000)
    out = tmp_path / "out"
    write_folder(out, {"maps/2021/map.tif": big, "summary.json": "{}"}, clear=False)
    assert (out / "maps" / "2021" / "map.tif").read_bytes() == b"tif" * 1000 and not big.exists()
    assert read_manifest(out) == ["maps/2021/map.tif", "summary.json"]
    assert not list(tmp_path.glob(".out.staging-*"))


def test_a_folder_without_a_manifest_is_not_cleared(tmp_path):
    # an older symtrack's folder, or anybody's: summary.json and scenario.resolved.toml do not make it a run's
    for name in ("summary.json", "scenario.resolved.toml", "pyproject.toml", "data.csv", "plot.png"):
        (tmp_path / name).write_text("x")
    assert run_files.clear_previous_run(tmp_path) == []
    write_folder(tmp_path, {"summary.json": "{}"})
    assert {p.name for p in tmp_path.iterdir()} == {"summary.json", "scenario.resolved.toml", "pyproject.toml",
                                                    "data.csv", "plot.png", MANIFEST}


def test_a_manifest_never_reaches_outside_its_folder(tmp_path, caplog):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "x.csv").write_text("keep")
    (out / "link").symlink_to(tmp_path / "elsewhere")
    (out / MANIFEST).write_text(json.dumps({"kind": "symtrack-run-manifest", "schema_version": 1, "files": [
        "../victim.txt", str(victim), "link/x.csv", "a/../../victim.txt", "", 3]}))
    write_folder(out, {"summary.json": "{}"})
    assert victim.read_text() == "keep" and (tmp_path / "elsewhere" / "x.csv").read_text() == "keep"
    # a file of that name that is no symtrack manifest: its folder's files are all foreign
    (out / MANIFEST).write_text('{"files": ["summary.json"]}')
    with caplog.at_level(logging.WARNING, logger="symtrack.files"):
        assert run_files.clear_previous_run(out) == []
    assert "not a symtrack manifest" in caplog.text and (out / "summary.json").exists()


_HOLDER = """
import sys
from symtrack.reports.run_files import output_lock
with output_lock(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def test_a_second_run_into_a_folder_is_refused_at_once_through_a_link_too(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    link = tmp_path / "link"
    link.symlink_to(out, target_is_directory=True)
    out.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(out)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, env=env)
    try:
        assert holder.stdout.readline().strip() == b"held"
        import symtrack

        monkeypatch.setattr(symtrack, "simulate", lambda *a, **k: pytest.fail("simulated into a locked folder"))
        for command in (["simulate", "validation"], ["mpc", "straight_offset"],
                        ["linearize", "--speed", "1.0"], ["field", "field_traffic"]):
            assert main([*command, "--out", str(link), "--quiet"] if command[0] != "linearize"
                        else [*command, "--out", str(link)]) == 2
            err = capsys.readouterr().err
            assert len(err.strip().splitlines()) == 1
            assert f"pid {holder.pid}" in err and str(link) in err and str(out.resolve()) in err
        with pytest.raises(ScenarioError, match=f"pid {holder.pid}"):  # the API's writer too
            write_folder(link, {"summary.json": "{}"})
    finally:
        holder.communicate(b"")
    assert holder.returncode == 0
    assert not (out / OUTPUT_LOCK).exists()  # removed by its holder on leaving
    write_folder(link, {"summary.json": "{}"})  # free again
    assert (out / "summary.json").exists() and not (out / OUTPUT_LOCK).exists()


def test_the_folder_lock_is_removed_on_an_error_and_on_ctrl_c(tmp_path):
    out = tmp_path / "out"
    for exc in (ScenarioError("bad"), KeyboardInterrupt()):
        with pytest.raises(type(exc)), output_lock(out):
            assert (out / OUTPUT_LOCK).read_text() == str(os.getpid())
            with output_lock(out):  # re-entrant in this process (the CLI around the writer)
                pass
            raise exc
        assert not out.exists()  # created by the lock, nothing written: removed with it
    out.mkdir()
    with pytest.raises(KeyboardInterrupt), output_lock(out):
        raise KeyboardInterrupt
    assert out.is_dir() and not any(out.iterdir())


TINY = TINY_INPLACE_TOML


@pytest.fixture()
def terrain_file(tmp_path):
    from symtrack.presets import soil_preset
    from symtrack.terrain import storage
    from symtrack.terrain.storage import Grid, Terrain

    f = tmp_path / "F.npz"
    storage.save(f, Terrain(Grid((-2.0, -2.0), 0.25, (32, 16))), soil_preset("clayey_soil_thailand_38"))
    sc = tmp_path / "tiny.toml"
    sc.write_text(TINY)
    return sc, f


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_a_terrain_file_replaced_in_place_keeps_its_mode_and_owner(terrain_file, tmp_path):
    sc, f = terrain_file
    f.chmod(0o640)
    owner = None
    if os.geteuid() == 0:  # root may give the file away: the run gives it back to its owner
        os.chown(f, 12345, 23456)
        owner = (12345, 23456)
    before = f.read_bytes()
    assert main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(f),
                 "--terrain-out", str(f), "--set", "run.figures=false"]) == 0  # (the terrain file is the subject)
    assert f.read_bytes() != before and _mode(f) == 0o640
    if owner is not None:
        assert (f.stat().st_uid, f.stat().st_gid) == owner
    f.chmod(0o600)  # and any atomic write (Terrain.save, terrain convert) keeps it
    atomic_write_bytes(f, before)
    assert _mode(f) == 0o600 and f.read_bytes() == before
    atomic_write_bytes(tmp_path / "new.txt", b"x")  # a new file: the umask's mode
    assert _mode(tmp_path / "new.txt") == 0o666 & ~_umask()


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def test_a_read_only_terrain_file_is_refused_before_any_work(terrain_file, tmp_path, monkeypatch, capsys):
    import symtrack

    sc, f = terrain_file
    f.chmod(0o444)
    before = f.read_bytes()
    monkeypatch.setattr(symtrack, "simulate", lambda *a, **k: pytest.fail("simulated onto a read-only file"))
    for command in (["simulate", str(sc)], ["mpc", "straight_offset", "--plant", "grid"]):
        assert main([*command, "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(f),
                     "--terrain-out", str(f)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--terrain-out {str(f)!r} is read-only (mode 0444)" in err
    assert main(["terrain", "convert", str(f), str(f)]) == 2  # any output file
    assert "is read-only" in capsys.readouterr().err
    assert f.read_bytes() == before and _mode(f) == 0o444 and not (tmp_path / "o").exists()
