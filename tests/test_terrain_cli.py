"""symtrack simulate on the grid terrain: outputs, terrain files in and out, errors."""

import json

import numpy as np
import pytest

from symtrack.cli import main
from symtrack.terrain import storage as persist

SCENARIO = """
name = "tiny_terrain"
[run]
duration_s = 3.0
output_dt_s = 0.01
integrator = "idas"
stop_after_distance_m = 0.15
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[terrain]
size_m = [8.0, 4.0]
cell_m = 0.25
settle_s = 0.05
[[torque]]
t_s = 0.0
left_N_m = 2000.0
right_N_m = 2000.0
"""


def test_simulate_with_terrain_out_and_in(tmp_path):
    # on the terrain engine, grid_fast (the terrain file's reading and writing do not depend on the
    # integrator; the channel pool on IDAS, about 40 s a run here: tests/test_terrain_pool_passes.py)
    f = tmp_path / "tiny.toml"
    f.write_text(SCENARIO.replace('integrator = "idas"', 'integrator = "grid_fast"'))
    t1, t2 = tmp_path / "t1.npz", tmp_path / "t2.npz"
    assert main(["simulate", str(f), "--out", str(tmp_path / "a"), "--quiet", "--terrain-out", str(t1)]) == 0
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert s["terrain_channels"] == s["terrain_channel_modulus_M"] ** 2
    assert 0 < s["terrain_peak_active_cells"] < s["terrain_cells"] == 32 * 16
    assert s["passes"][0]["rut_max_depth_mm"] > 0.5
    for name in ("trajectory.csv", "sinkage_map.png", "rut_section.png", "path.png"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    header = (tmp_path / "a" / "trajectory.csv").read_text().splitlines()[0]
    assert "ch0_sinkage_m" not in header and "sinkage_sprocket_left_m" in header
    # the second run without figures (its figures are the first's kinds; the terrain files are its subject)
    assert main(["simulate", str(f), "--out", str(tmp_path / "b"), "--quiet", "--terrain-in", str(t1),
                 "--terrain-out", str(t2), "--set", "run.figures=false"]) == 0
    a, b = persist.load(t1), persist.load(t2)
    assert np.all(b.zmax >= a.zmax) and np.all(b.z >= a.z - 1e-6)  # the second run continued the first's terrain
    sb = json.loads((tmp_path / "b" / "summary.json").read_text())
    # on the compacted rut the second run adds the cycle law's share of the first (soil/cell.py:
    # 2^beta - 1 of the rut, 12 % for the clay; docs/terrain.md "Soil memory")
    first, second = s["passes"][0]["new_sinkage_mean_mm"], sb["passes"][0]["new_sinkage_mean_mm"]
    assert 0.05 * first < second < 0.5 * first


def test_grid_terrain_needs_idas(tmp_path, capsys):
    f = tmp_path / "tiny.toml"
    f.write_text(SCENARIO.replace('integrator = "idas"', 'integrator = "cvodes"'))
    assert main(["simulate", str(f), "--out", str(tmp_path / "a"), "--quiet"]) == 2
    assert "idas" in capsys.readouterr().err


def test_a_terrain_file_of_another_soil_is_refused(tmp_path, capsys):
    f = tmp_path / "tiny.toml"
    f.write_text(SCENARIO)
    t1 = tmp_path / "t1.npz"
    from symtrack.presets import soil_preset
    from symtrack.terrain.storage import Grid, Terrain
    persist.save(t1, Terrain(Grid((-4.0, -2.0), 0.25, (32, 16))), soil_preset("dry_sand"))
    assert main(["simulate", str(f), "--out", str(tmp_path / "a"), "--quiet", "--terrain-in", str(t1)]) == 2
    assert "soil" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["terrain.cell_m=0.5", "terrain.channels=1"])
def test_bad_terrain_settings_are_errors(tmp_path, capsys, bad):
    f = tmp_path / "tiny.toml"
    f.write_text(SCENARIO)
    assert main(["simulate", str(f), "--out", str(tmp_path / "a"), "--quiet", "--set", bad]) == 2
    assert "terrain" in capsys.readouterr().err
