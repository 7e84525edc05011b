"""The summary of several passes gives the whole run's figures at the top (issue 38, item 9):
``sim_time_s``, ``wall_time_s`` and ``distance_m`` the sums over the passes, ``real_time_factor`` the
total simulated time over the total wall time, the sinkage and shear extremes and the lateral
deviation over all passes, the run's end the last pass's; each pass's own figures are in ``passes``
(and its ``pass_<k>/``)."""

from __future__ import annotations

import json

import pytest
from small_field import TINY_INPLACE_TOML

from symtrack.cli.main import main

# three passes of 0.3 m on a 32 x 16 field on the terrain engine (the file-safety tests' tiny field)
THREE_PASSES = TINY_INPLACE_TOML.replace('name = "tiny_inplace"', 'name = "tiny_three"').replace(
    "cell_m = 0.25\n", "cell_m = 0.25\npasses = 3\n")
assert "passes = 3" in THREE_PASSES


def test_a_multi_pass_summary_gives_whole_run_figures_at_the_top(tmp_path):
    sc = tmp_path / "three.toml"
    sc.write_text(THREE_PASSES)
    out = tmp_path / "o"
    # (without figures: the summaries are what is checked; they were most of the test's CPU)
    assert main(["simulate", str(sc), "--out", str(out), "--quiet", "--set", "run.figures=false"]) == 0
    top = json.loads((out / "summary.json").read_text())
    passes = top["passes"]
    assert len(passes) == 3
    sim = sum(p["sim_time_s"] for p in passes)
    wall = sum(p["wall_time_s"] for p in passes)
    assert top["sim_time_s"] == pytest.approx(sim, rel=1e-12) and top["wall_time_s"] == pytest.approx(wall, rel=1e-12)
    assert top["sim_time_s"] > 2.5 * passes[-1]["sim_time_s"]  # not the last pass's alone
    assert top["real_time_factor"] == pytest.approx(sim / wall, rel=1e-12)
    for k, p in enumerate(passes, start=1):  # each pass's own, as in its folder's summary
        own = json.loads((out / f"pass_{k}" / "summary.json").read_text())
        assert p["real_time_factor"] == pytest.approx(p["sim_time_s"] / p["wall_time_s"], rel=1e-12)
        for key in ("sim_time_s", "wall_time_s", "real_time_factor"):
            assert own[key] == p[key], (k, key)
    own = [json.loads((out / f"pass_{k}" / "summary.json").read_text()) for k in (1, 2, 3)]
    assert top["distance_m"] == pytest.approx(sum(p["distance_m"] for p in own), rel=1e-12)
    assert top["distance_m"] > 2.5 * own[-1]["distance_m"] > 0.7  # three passes of 0.3 m, not the last alone
    assert all(p["distance_m"] == o["distance_m"] for p, o in zip(passes, own, strict=True))
    for key in ("sinkage_sprocket_mm", "sinkage_idler_mm", "shear_driven_max_m"):
        assert top[key] == max(o[key] for o in own), key
    assert top["lateral_deviation_m"] == max(o["lateral_deviation_m"] for o in own)
    assert top["complete"] and top["distance_stop_reached"]
    for key in ("stopped_by", "speed_final_m_s", "yaw_final_deg", "terrain_max_sinkage_mm"):  # the run's end
        assert top[key] == own[-1][key], key
