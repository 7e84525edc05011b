"""A terrain file's physically impossible values are refused on load with a message naming the array
(issue 38, item 8): a sinkage of -1e6 m, z_max below z, a negative peak pressure, 65535 load cycles;
and a scenario whose terrain.origin_m (or cell_m, size_m) is not the continued file's is refused with
one line instead of being ignored (and recorded wrongly in the resolved scenario)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.cli.main import main
from symtrack.foundations.errors import ScenarioError
from symtrack.presets import soil_preset
from symtrack.terrain import storage
from symtrack.terrain.storage import Grid, Terrain

SOIL = "clayey_soil_thailand_38"
SHAPE = (32, 16)

TINY = TINY_INPLACE_TOML


def _field(path: Path, **arrays) -> Path:
    """A terrain file of a worked field (a rut of 5 mm, two load cycles) with ``arrays`` replaced."""
    t = Terrain(Grid((-2.0, -2.0), 0.25, SHAPE))
    t.z[:] = 0.004
    t.zmax[:] = 0.005
    t.zoff[:] = 0.0005
    t.pmax[:] = 30e3
    t.phase[:] = 2
    t.cycles[:] = 2
    storage.save(path, t, soil_preset(SOIL))
    if arrays:
        with np.load(path) as f:
            d = {k: f[k] for k in f.files}
        for k, v in arrays.items():
            d[k] = np.broadcast_to(np.asarray(v, dtype=d[k].dtype), d[k].shape).copy()
        np.savez(path, **d)
    return path


@pytest.mark.parametrize(("arrays", "message"), [
    ({"z_m": -1e6}, r"z_m = -1000000.0 m at 512 cell\(s\), e.g. cell \(0, 0\), outside \[-10, 10\] m"),
    ({"z_max_m": 1e3}, r"z_max_m = 1000.0 m .* outside \[-10, 10\] m"),
    ({"z_max_m": 0.001}, r"z_max_m = 0.001 m is below z_m = 0.004 m .*z_m <= z_max_m \+ z_off_m"),
    ({"p_max_Pa": -5.0}, r"p_max_Pa = -5.0 Pa at .* outside \[0, 1e\+08\] Pa"),
    ({"load_cycles": 65535}, r"load_cycles = 65535 at 512 cell\(s\).* above 10000"),
])
def test_impossible_values_are_refused_naming_the_array(tmp_path, arrays, message):
    f = _field(tmp_path / "F.npz", **arrays)
    with pytest.raises(ScenarioError, match=message) as err:
        storage.load(f)
    assert "\n" not in str(err.value) and str(f) in str(err.value) and "damaged" in str(err.value)


def test_a_worked_field_and_its_edge_values_load(tmp_path):
    t = storage.load(_field(tmp_path / "F.npz"))
    assert t.cycles.max() == 2 and t.z.max() == 0.004
    # z above z_max by its cycles' plastic sinkage, a slight heave, the bounds themselves: a field
    cycles = np.zeros(SHAPE, dtype=np.uint16)
    cycles[0, 0] = storage.LOAD_CYCLES_LIMIT
    z = np.full(SHAPE, 0.0053)
    z[1, 1] = -6e-8
    storage.load(_field(tmp_path / "G.npz", z_m=z, load_cycles=cycles, p_max_Pa=storage.PRESSURE_LIMIT_PA))


def test_a_scenario_whose_geometry_is_not_the_continued_files_is_refused(tmp_path, capsys):
    f = _field(tmp_path / "F.npz")
    sc = tmp_path / "tiny.toml"
    sc.write_text(TINY)
    before = f.read_bytes()
    for key, value, what in (("terrain.origin_m", "[0.0, -2.0]", "origin_m = [-2.0, -2.0]"),
                             ("terrain.cell_m", "0.5", "cells of 0.25 m"),
                             ("terrain.size_m", "[8.0, 8.0]", "32 x 16 cells")):
        code = main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(f),
                     "--terrain-out", str(f), "--set", f"{key}={value}"])
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert what in err and key in err and str(f) in err
        assert f.read_bytes() == before and not (tmp_path / "o" / "summary.json").exists()
    # the file's own origin (as the scenario gives it): the run continues the file
    assert main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet", "--terrain-in", str(f),
                 "--terrain-out", str(f)]) == 0
    assert len(storage.load(f).history) == 1
