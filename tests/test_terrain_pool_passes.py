"""The bit-exact continuation of a terrain through a file: two passes in one run equal one pass,
saved, loaded and driven again (on the small field of test_terrain_pool.py)."""

import pytest
from conftest import two_passes_against_a_continued_pass
from test_terrain_pool import SMALL

# on IDAS (the same check on the terrain engine is in test_terrain_engine.py, in the fast set): the
# slow set (make test-slow; CI runs it)
pytestmark = pytest.mark.slow


def test_two_passes_equal_one_pass_save_load_and_a_second_pass(tmp_path):
    # passes of 0.15 m (four of them on IDAS here, each from rest: their steps are the test's CPU) on a
    # pool of 14 x 14 channels, not the 18 x 18 that M = "auto" gives for any heading at up to 10 m/s
    # (the straight, slow footprint's cells span 12 x 10 cells; a cell without a channel would stop the
    # run with an error)
    d = dict(SMALL, run={"duration_s": 5.0, "output_dt_s": 0.01, "integrator": "idas",
                         "stop_after_distance_m": 0.15}, terrain=dict(SMALL["terrain"], channels=14))
    two, _ = two_passes_against_a_continued_pass(d, tmp_path)
    figs2 = two.summary["passes"]
    # the second pass over the compacted soil adds less sinkage and meets less resistance
    assert figs2[1]["new_sinkage_mean_mm"] < figs2[0]["new_sinkage_mean_mm"]
    assert figs2[1]["compaction_resistance_mean_N"] < figs2[0]["compaction_resistance_mean_N"]
