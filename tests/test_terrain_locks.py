"""Every writer of a terrain file takes its lock, on the file's real path (issue 38, item 3):
``symtrack terrain convert`` is refused while a run holds the file, under its own name or a link's; a
run through a symbolic link (``--terrain-in link.npz --terrain-out link.npz``) advances the link's
target and leaves the link a link; no ``.lock`` file stays beside the terrain file after a run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.cli.main import main
from symtrack.foundations.errors import ScenarioError
from symtrack.presets import soil_preset
from symtrack.reports.run_files import terrain_lock
from symtrack.terrain import fieldfile, storage
from symtrack.terrain.storage import Grid, Terrain

ROOT = Path(__file__).resolve().parent.parent
SOIL = "clayey_soil_thailand_38"

TINY = TINY_INPLACE_TOML

_HOLDER = """
import sys
from symtrack.reports.run_files import terrain_lock
with terrain_lock(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def _new_field(path: Path) -> None:
    storage.save(path, Terrain(Grid((-2.0, -2.0), 0.25, (32, 16))), soil_preset(SOIL))


def _locks(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".lock"))


def test_terrain_convert_is_refused_while_a_run_holds_the_file_under_any_name(tmp_path, capsys):
    f = tmp_path / "F.npz"
    _new_field(f)
    link = tmp_path / "link.npz"
    link.symlink_to(f)
    other = tmp_path / "other.field"
    fieldfile.write_field(other, Terrain(Grid((0.0, 0.0), 0.5, (4, 3))), soil_preset(SOIL))
    before = f.read_bytes()
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(f)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, env=env)
    try:
        assert holder.stdout.readline().strip() == b"held"
        for name in (f, link):
            assert main(["terrain", "convert", str(other), str(name)]) == 2
            err = capsys.readouterr().err
            assert len(err.strip().splitlines()) == 1
            assert f"OUT {str(name)!r}" in err and f"pid {holder.pid}" in err and "another symtrack process" in err
            assert f.read_bytes() == before and link.is_symlink()
        with pytest.raises(ScenarioError, match=f"pid {holder.pid}"), terrain_lock(link):  # the API's lock too
            pass
    finally:
        holder.communicate(b"")
    assert holder.returncode == 0
    assert _locks(tmp_path) == []  # its holder removed the lock file on leaving
    assert main(["terrain", "convert", str(other), str(link)]) == 0  # free again: written through the link
    assert link.is_symlink() and storage.load(f).grid.shape == (4, 3)
    assert _locks(tmp_path) == []


def test_a_run_through_a_link_advances_its_target_and_leaves_no_lock_file(tmp_path):
    real = tmp_path / "fields" / "F.npz"
    real.parent.mkdir()
    _new_field(real)
    link = tmp_path / "link.npz"
    link.symlink_to(real)
    sc = tmp_path / "tiny.toml"
    sc.write_text(TINY)
    before = real.read_bytes()
    last_id = storage.load(real).file_id
    for k in (1, 2):
        assert main(["simulate", str(sc), "--out", str(tmp_path / f"o{k}"), "--quiet", "--terrain-in", str(link),
                     "--terrain-out", str(link)]) == 0
        assert link.is_symlink() and link.resolve() == real.resolve()
        t = storage.load(real)
        assert len(t.history) == k and real.read_bytes() != before  # the target advanced, run by run
        assert t.history[-1]["input_file_id"] == last_id  # each run continued the file the link names
        last_id = t.file_id
        # no lock file (nor temporary file) beside the link or the target once the run is over
        assert _locks(tmp_path) == [] and _locks(real.parent) == []
        assert not [p for p in (*tmp_path.iterdir(), *real.parent.iterdir()) if p.name.endswith(".tmp")]
