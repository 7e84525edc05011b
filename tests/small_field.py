"""The small grid scenario several engine tests share: a 12 m x 4 m field at 0.25 m (768 cells,
M = 18), the reference crawler on the validation clay, from rest at x = -3 m with both sprockets at
2000 N m. :func:`small_field` gives a copy with a test's own name, run settings and changes."""

from __future__ import annotations

import copy

__all__ = ["SMALL_FIELD", "small_field"]

SMALL_FIELD = {
    "name": "small_field",
    "run": {"duration_s": 0.6, "output_dt_s": 0.01, "integrator": "grid_fast"},
    "vehicle": {"preset": "reference_crawler"},
    "soil": {"preset": "clayey_soil_thailand_38"},
    "start": {"x_m": -3.0},
    "terrain": {"size_m": [12.0, 4.0], "cell_m": 0.25, "origin_m": [-6.0, -2.0], "settle_s": 0.1},
    "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0}],
}


def small_field(name: str, run: dict | None = None, terrain: dict | None = None, torque=None) -> dict:
    """A copy of :data:`SMALL_FIELD` named ``name``, its [run] and [terrain] updated by ``run`` and
    ``terrain``, its [[torque]] replaced by ``torque`` when given."""
    d = copy.deepcopy(SMALL_FIELD)
    d["name"] = name
    d["run"].update(run or {})
    d["terrain"].update(terrain or {})
    if torque is not None:
        d["torque"] = copy.deepcopy(torque)
    return d


# one pass of 0.3 m on an 8 m x 4 m field at 0.25 m on the terrain engine: the in-place terrain runs of
# the file-safety tests (test_run_folder, test_terrain_file_checks, test_terrain_locks)
TINY_INPLACE_TOML = """
name = "tiny_inplace"
[run]
duration_s = 5.0
output_dt_s = 0.05
integrator = "grid_fast"
stop_after_distance_m = 0.3
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[terrain]
size_m = [8.0, 4.0]
origin_m = [-2.0, -2.0]
cell_m = 0.25
[[torque]]
t_s = 0.0
left_N_m = 1500.0
right_N_m = 1500.0
"""
