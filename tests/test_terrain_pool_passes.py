"""The bit-exact continuation of a terrain through a file: two passes in one run equal one pass,
saved, loaded and driven again (on the small field of test_terrain_pool.py)."""

import dataclasses

import numpy as np
from test_terrain_pool import SMALL

import symtrack
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.terrain.settings import settings_from_dict
from symtrack.terrain.storage import Terrain


def test_two_passes_equal_one_pass_save_load_and_a_second_pass(tmp_path):
    d = dict(SMALL, run={"duration_s": 5.0, "output_dt_s": 0.01, "integrator": "idas",
                         "stop_after_distance_m": 0.3},
             terrain=dict(SMALL["terrain"], passes=2))
    sc2 = scenario_from_dict(d)
    two = symtrack.simulate(sc2)
    res2, figs2 = two.runs, two.summary["passes"]
    sc1 = dataclasses.replace(sc2, terrain=settings_from_dict(dict(d["terrain"], passes=1)))
    one = symtrack.simulate(sc1)
    f = tmp_path / "after_pass_1.npz"
    one.terrain.save(f)
    again = symtrack.simulate(sc1, terrain=Terrain.load(f))
    for a, b in zip(two.terrain.arrays().values(), again.terrain.arrays().values(), strict=True):
        assert np.array_equal(a, b)  # to the last bit
    assert np.array_equal(res2[-1].X, again.runs[0].X) and np.array_equal(res2[-1].Y, again.runs[0].Y)
    # the second pass over the compacted soil adds less sinkage and meets less resistance
    assert figs2[1]["new_sinkage_mean_mm"] < figs2[0]["new_sinkage_mean_mm"]
    assert figs2[1]["compaction_resistance_mean_N"] < figs2[0]["compaction_resistance_mean_N"]
