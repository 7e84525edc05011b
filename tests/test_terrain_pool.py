"""The channel pool against brute force (every cell of a small field integrated as its own state);
the bit-exact continuation of a terrain through a file is in test_terrain_pool_passes.py (a file
of its own, so that a parallel run can give it to the other worker)."""

import numpy as np
import pytest

from symtrack.bench.terrain import brute_force_run, pool_run
from symtrack.integrators import grid_idas
from symtrack.simulation.scenario import scenario_from_dict

# every cell of the field as its own IDAS state: the slow set (make test-slow; CI runs it)
pytestmark = pytest.mark.slow

# An 8 m x 4 m field at 0.25 m (512 cells: the pool's peak of 96 active cells is under a quarter of
# it); both sprockets at 2000 N m for 0.3 s, then the left one idle: the vehicle starts from rest,
# accelerates and begins to turn. 0.6 s (0.17 m driven): the brute-force reference's steps were most of
# the test's CPU over the 1 s (0.55 m) it ran before.
SMALL = {
    "name": "pool_vs_brute",
    "run": {"duration_s": 0.6, "output_dt_s": 0.01, "integrator": "idas"},
    "vehicle": {"preset": "reference_crawler"},
    "soil": {"preset": "clayey_soil_thailand_38"},
    "start": {"x_m": -3.0},
    "terrain": {"size_m": [8.0, 4.0], "cell_m": 0.25, "origin_m": [-6.0, -2.0], "settle_s": 0.1},
    "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0},
               {"t_s": 0.3, "left_N_m": 0.0, "right_N_m": 2000.0}],
}

# Tolerances (stated): the two systems differ only in the cells the pool has released (at rest
# to |dz/dt| <= 1e-5 m/s, p = 0) and in the integrator's step choices (reltol 1e-7).
# The pose: 3 um (measured 2.1e-6 m with the shear law's elastic unloading, whose switch from loading
# to unloading is a kink in the shear's rate that the two integrators' different step choices cross at
# different points; the tolerance was 1e-6 before it)
POSE_TOL_M = 3e-6
SINKAGE_TOL_M = 1e-7  # 0.1 um, against sinkages of about 1 mm
RATE_TOL = 1e-4  # velocities, speeds, shears, torques: relative to 1 + abs(value)


@pytest.fixture(scope="module")
def both():
    sc = scenario_from_dict(SMALL)
    # both IDAS systems built without CasADi's cse (the same numbers to the last bit: grid_idas.CSE): for
    # 0.6 s of steps its build (7 s of CPU on the 512 cells) costs more than it saves
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(grid_idas, "CSE", False)
        world, pool = pool_run(sc, SMALL["run"]["duration_s"])
        brute = brute_force_run(sc, SMALL["run"]["duration_s"])
    return world, pool, brute


def test_pool_and_brute_force_give_the_same_vehicle_motion(both):
    world, pool, brute = both
    assert pool.t.shape == brute.t.shape and np.allclose(pool.t, brute.t)
    assert pool.X[-1, 0] - pool.X[0, 0] > 0.1  # it did drive (0.17 m)
    assert np.max(np.abs(pool.X[:, :3] - brute.X[:, :3])) < POSE_TOL_M
    assert np.max(np.abs(pool.X[:, 3:12] - brute.X[:, 3:12]) / (1 + np.abs(brute.X[:, 3:12]))) < RATE_TOL


def test_pool_and_brute_force_give_the_same_terrain(both):
    world, pool, brute = both
    z_pool = world.z_at_pass_end.reshape(world.grid.shape)  # before the vehicle is lifted off
    assert z_pool.max() > 5e-4  # a rut of about a millimetre
    assert np.max(np.abs(z_pool - brute.z)) < SINKAGE_TOL_M
    # the pool simulated far fewer cells at a time than the field has
    assert pool.terrain["terrain_peak_active_cells"] < world.grid.n_cells / 4
