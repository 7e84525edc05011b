"""A field that would not fit in memory is refused before it is allocated, with the memory it
would need (issue 26, item 5)."""

from __future__ import annotations

import numpy as np
import pytest

from symtrack.cli import main
from symtrack.foundations import memory
from symtrack.foundations.errors import ScenarioError
from symtrack.terrain.storage import Grid, Terrain
from symtrack.terrain.world import world_bytes_per_cell


def test_bytes_per_cell_is_what_the_storage_allocates():
    """The estimate is measured from the storage's own arrays: a 30 x 20 terrain with 4 depths takes
    600 cells' worth of the storage share, and the world adds 8 bytes per depth and 2 per cell; a
    shaped field 8 more (its elevation)."""
    t = Terrain(Grid((0.0, 0.0), 0.1, (30, 20)), None, (0.1, 0.3, 0.5, 0.8))
    assert world_bytes_per_cell(4) == t.nbytes / 600 + 8 * 4 + 2
    assert world_bytes_per_cell(4, shaped=True) == world_bytes_per_cell(4) + 8
    assert world_bytes_per_cell(0) < world_bytes_per_cell(4)


def test_a_cap_in_the_environment_limits_the_available_memory(monkeypatch):
    monkeypatch.setenv(memory.LIMIT_ENV, "1e6")
    assert memory.available_bytes() == 1_000_000
    monkeypatch.setenv(memory.LIMIT_ENV, "lots")
    with pytest.raises(ScenarioError, match="SYMTRACK_MEMORY_LIMIT_BYTES = 'lots'"):
        memory.available_bytes()


def test_a_field_too_big_for_the_memory_is_refused_before_any_work(monkeypatch, tmp_path, capsys):
    """The million-cell validation field with 50 MB available: exit 2, the keys, the need (about
    0.1 GB) and nothing written."""
    monkeypatch.setenv(memory.LIMIT_ENV, "5e7")
    allocated = []
    real_zeros = np.zeros
    monkeypatch.setattr(np, "zeros", lambda n, *a, **k: allocated.append(n) or real_zeros(n, *a, **k))
    out = tmp_path / "run"
    assert main(["simulate", "validation_grid", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    need = 1_000_000 * world_bytes_per_cell(4) / 1e9
    assert "terrain.size_m = [100.0, 100.0] at terrain.cell_m = 0.1 (1000 x 1000 = 1000000 cells" in err
    assert f"needs {need:.2f} GB of memory, this machine has 0.05 GB available" in err
    assert "Traceback" not in err and not out.exists()
    assert not any(isinstance(n, int) and n >= 1_000_000 for n in allocated), "the field was allocated"
