"""A field that would not fit in memory is refused before it is allocated, with the memory it
would need (issue 26, item 5), and the estimate is honest (issue 38, item 6): within 20 % of the peak
resident set that a fresh `symtrack simulate` process reaches (its VmHWM) on fields of 1e4 and 1e6
cells, new and continued. A run that asks for absurdly many output steps is refused before any work."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from symtrack.bench.memory import simulate_peak
from symtrack.cli import main
from symtrack.foundations import memory
from symtrack.foundations.errors import ScenarioError
from symtrack.terrain import storage as persist
from symtrack.terrain.storage import Grid, Terrain
from symtrack.terrain.world import (
    PASS_BYTES_PER_CELL,
    RUN_BYTES_PER_CELL,
    RUN_FIXED_BYTES,
    run_memory_bytes,
    world_storage_bytes_per_cell,
)

ROOT = Path(__file__).resolve().parent.parent

# a straight metre from the centre of a square field of 0.1 m cells (its side set per test)
PROBE = (ROOT / "examples" / "scenarios" / "memory_probe.toml").read_text()


def test_the_estimate_counts_the_field_as_it_comes_into_memory():
    """A continued field's arrays all (read from its file), a new field's stress record and elevation
    only; the two sinkage copies per pass; the measured rest per cell and the fixed part."""
    t = Terrain(Grid((0.0, 0.0), 0.1, (30, 20)), None, (0.1, 0.3, 0.5, 0.8))
    assert world_storage_bytes_per_cell(4) == t.nbytes / 600
    assert world_storage_bytes_per_cell(4, shaped=True) == world_storage_bytes_per_cell(4) + 8
    n = 1000
    assert run_memory_bytes(n, 4) == RUN_FIXED_BYTES + n * (RUN_BYTES_PER_CELL + 16 + PASS_BYTES_PER_CELL)
    assert run_memory_bytes(n, 4, passes=3) - run_memory_bytes(n, 4) == 2 * n * PASS_BYTES_PER_CELL
    assert run_memory_bytes(n, 4, continued=True) - run_memory_bytes(n, 4) == n * (t.nbytes / 600 - 16)
    assert run_memory_bytes(n, 4, shaped=True) - run_memory_bytes(n, 4) == 8 * n


def test_a_cap_in_the_environment_limits_the_available_memory(monkeypatch):
    monkeypatch.setenv(memory.LIMIT_ENV, "1e6")
    assert memory.available_bytes() == 1_000_000
    monkeypatch.setenv(memory.LIMIT_ENV, "lots")
    with pytest.raises(ScenarioError, match="SYMTRACK_MEMORY_LIMIT_BYTES = 'lots'"):
        memory.available_bytes()


def test_a_field_too_big_for_the_memory_is_refused_before_any_work(monkeypatch, tmp_path, capsys):
    """The million-cell validation field with 50 MB available: exit 2, the keys, the need (about
    0.14 GB) and nothing written."""
    monkeypatch.setenv(memory.LIMIT_ENV, "5e7")
    allocated = []
    real_zeros = np.zeros
    monkeypatch.setattr(np, "zeros", lambda n, *a, **k: allocated.append(n) or real_zeros(n, *a, **k))
    out = tmp_path / "run"
    assert main(["simulate", "validation_grid", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    need = run_memory_bytes(1_000_000, 4) / 1e9
    assert "terrain.size_m = [100.0, 100.0] at terrain.cell_m = 0.1 (1000 x 1000 = 1000000 cells" in err
    assert f"needs {need:.2f} GB of memory (a peak of about " in err and "this machine has 0.05 GB available" in err
    assert "Traceback" not in err and not out.exists() and err.count("\n") == 1
    assert not any(isinstance(n, int) and n >= 1_000_000 for n in allocated), "the field was allocated"


def test_a_terrain_file_too_big_for_the_memory_is_refused_before_it_is_read(monkeypatch, tmp_path, capsys):
    f = tmp_path / "big.npz"
    from symtrack.presets import soil_preset

    persist.save(f, Terrain(Grid((-50.0, -50.0), 0.1, (1000, 1000)), None, (0.1, 0.3, 0.5, 0.8)),
                 soil_preset("clayey_soil_thailand_38"))
    sc = tmp_path / "probe.toml"
    sc.write_text(PROBE.replace("size_m = [10.0, 10.0]\n", ""))
    monkeypatch.setenv(memory.LIMIT_ENV, "1e8")
    loaded = []
    monkeypatch.setattr(persist, "load", lambda *a, **k: loaded.append(a))
    assert main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(f)]) == 2
    err = capsys.readouterr().err
    need = run_memory_bytes(1_000_000, 4, continued=True) / 1e9
    assert f"the terrain file {str(f)!r} (1000 x 1000 = 1000000 cells, 4 subsoil depths" in err
    assert f"needs {need:.2f} GB of memory" in err and "0.10 GB available" in err and "Traceback" not in err
    assert loaded == []


def _peak(tmp_path: Path, cells: float, terrain_in: Path | None = None) -> tuple[float, float]:
    """(the estimate in the run's summary, the peak resident set of its process), bytes: a fresh
    `symtrack simulate` process, its peak read from /proc (VmHWM) as it ends (symtrack.bench.memory)."""
    side = (cells / 100) ** 0.5
    sc = tmp_path / "probe.toml"
    sc.write_text(PROBE)
    args = [str(sc), "--set", f"terrain.size_m=[{side},{side}]"]
    if terrain_in is not None:
        args += ["--terrain-in", str(terrain_in), "--terrain-out", str(terrain_in)]
    return simulate_peak(args, tmp_path / f"o{int(cells)}{'c' if terrain_in else ''}")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/status: Linux")
def test_the_estimate_is_within_20_percent_of_the_measured_peak(tmp_path):
    """1e4 cells (the process's own memory dominates) and 1e6 (the field's does), new; 1e6 continued
    from its file (every array read into memory). The larger sizes, to 3e6 cells: docs/terrain.md."""
    field = tmp_path / "field.npz"
    from symtrack.presets import soil_preset

    persist.save(field, Terrain(Grid((-50.0, -50.0), 0.1, (1000, 1000)), None, (0.1, 0.3, 0.5, 0.8)),
                 soil_preset("clayey_soil_thailand_38"))
    for cells, f in ((1e4, None), (1e6, None), (1e6, field)):
        estimate, peak = _peak(tmp_path, cells, f)
        print(f"{cells:.0e} cells{' continued' if f else ''}: estimate {estimate / 1e6:.1f} MB, "
              f"peak {peak / 1e6:.1f} MB")
        assert 0.8 <= estimate / peak <= 1.2, (cells, f, estimate, peak)


@pytest.mark.parametrize("value", [1e-9, 1e-6, 2.9e-5, 0.0, -1.0, 31.0, "fast", True, float("nan"), 1e300])
def test_an_absurd_output_density_is_refused_with_the_key_value_and_range(value, capsys, tmp_path):
    """run.output_dt_s: above 1e6 output steps over run.duration_s (30 s: below 3e-5 s) or outside
    (0, duration]: exit 2 with one line naming the key, the value and the allowed range; nothing run."""
    setting = f"run.output_dt_s={json.dumps(value) if not isinstance(value, float) else repr(value)}"
    assert main(["simulate", "validation", "--out", str(tmp_path / "o"), "--quiet", "--set", setting]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "run.output_dt_s = " in err
    assert "allowed range" in err or "must be a number" in err
    if isinstance(value, float) and 0 < value < 3e-5:
        assert "the allowed range is [3e-05, 30] s" in err and "output steps" in err
    assert not (tmp_path / "o").exists()
