"""The terrain examples run (with short settings)."""

import json
import runpy
import sys

import pytest

# the benchmark's smoke run, brute force included: the slow set (make test-slow; CI runs it)
pytestmark = pytest.mark.slow


def test_bench_terrain_quick(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["bench_terrain.py", "--quick"])
    runpy.run_path("examples/bench_terrain.py", run_name="__main__")
    out = json.loads(capsys.readouterr().out)
    assert out["big_channels"] > 0 and out["big_peak_active_cells"] > 0
    assert out["big_storage_MB"] > 0 and out["big_wall_s_per_sim_s"] > 0
    assert out["small_speed_ratio_brute_over_pool"] > 0 and out["small_pose_difference_m"] < 1e-5
