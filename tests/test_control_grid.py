"""The closed loop against the grid-terrain plant: the MPC (homogeneous prediction model) drives
the vehicle on the persistent grid terrain, which records the ruts along the driven path."""

import argparse
import json

import numpy as np
import pytest

from symtrack.cli.control import mpc_command
from symtrack.control import closedloop as CL
from symtrack.control import scenario as S
from symtrack.control.closedloop import field_from_path
from symtrack.foundations.errors import ScenarioError
from symtrack.model.vehicle import VEHICLE_STATES
from symtrack.simulation.plants import GridPlant
from symtrack.terrain import storage as persist

# a short straight run on a small field: 6 m of path at 2 m/s, 3 s simulated
SHORT = """
name = "grid_short"
[start]
speed_m_s = 2.0
[path]
speed_m_s = 2.0
segments = [{straight_m = 6.0}]
[run]
duration_s = 5.0
[terrain]
cell_m = 0.25
max_speed_m_s = 4.0
"""


@pytest.fixture(scope="module")
def grid_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("grid")
    toml = d / "grid_short.toml"
    toml.write_text(SHORT)
    out = d / "out"
    args = argparse.Namespace(scenario=str(toml), out=str(out), set=None, solver=None, jit=False, quiet=True,
                              plant=None, terrain_in=None, terrain_out=str(d / "terrain.npz"))
    assert mpc_command(args) == 0
    return d, out


def test_grid_closed_loop_runs_without_failed_solves(grid_run):
    _, out = grid_run
    s = json.loads((out / "summary.json").read_text())
    assert s["plant"] == "grid"
    assert s["path_completed"]
    assert s["failed_solves"] == 0
    assert s["max_lateral_error_m"] < 0.05
    assert s["terrain_channels"] == s["terrain_channel_modulus_M"] ** 2
    assert s["terrain_peak_active_cells"] > 0
    assert s["rut_cells"] > 0 and s["rut_max_depth_mm"] > 0
    assert s["plant_wall_time_s"] > 0 and s["solver_wall_time_s"] > 0
    assert s["terrain_out"].endswith("terrain.npz")
    for name in ("sinkage_map.png", "path.png", "errors.png", "trajectory.csv"):
        assert (out / name).stat().st_size > 0
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header[1:1 + len(VEHICLE_STATES)] == list(VEHICLE_STATES)  # the channel states stay in the plant


def test_grid_terrain_records_the_ruts_along_the_path(grid_run):
    d, out = grid_run
    st = persist.load(d / "terrain.npz")
    g = st.grid
    z = st.z.reshape(g.shape)
    zmax = st.zmax.reshape(g.shape)
    traj = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    xs, ys = traj["x_m"], traj["y_m"]
    cx, cy = g.centres(np.arange(g.shape[0]), np.arange(g.shape[1]))
    # cells under the tracks (gauge 1.5 m: centre lines at y = +-0.75 m) along the middle of the run
    i_mid = np.nonzero((cx > xs[0] + 1.5) & (cx < xs[-1] - 1.5))[0]
    assert i_mid.size > 5
    for y_track in (0.75, -0.75):
        j = int(np.argmin(np.abs(cy - (np.interp(cx[i_mid], xs, ys) + y_track).mean())))
        assert np.all(z[i_mid, j] > 1e-4), f"track at {y_track} m: sinkage {z[i_mid, j]}"
    # between the tracks and away from the path the soil is untouched
    for y_off in (0.0, 2.5, -2.5):
        j = int(np.argmin(np.abs(cy - y_off)))
        assert np.all(zmax[i_mid, j] == 0.0) and np.all(z[i_mid, j] == 0.0), y_off
    # nothing ahead of where the vehicle stopped (beyond the front of the contact, 1.2 m + a cell)
    ahead = cx > xs[-1] + 1.2 + 2 * g.cell_m
    assert np.all(zmax[ahead, :] == 0.0)


def test_grid_plant_continues_a_saved_terrain(grid_run, tmp_path):
    d, _ = grid_run
    sc = S.load(str(d / "grid_short.toml"), ["run.duration_s=0.3"])
    plant = CL.make_plant(sc, None, str(d / "terrain.npz"))
    before = persist.load(d / "terrain.npz")
    assert np.array_equal(plant.world.storage.z, before.z)
    assert isinstance(plant, GridPlant)
    res = CL.run(sc, plant=plant)
    assert res.summary["failed_solves"] == 0
    # the history of the cells only grows: the second run adds to the ruts of the first
    after = plant.world.storage
    assert np.all(after.zmax >= before.zmax)
    assert np.any(after.zmax > before.zmax)


def test_plant_choice_and_terrain_validation():
    assert S.load("field_pattern").plant == "grid"
    assert S.load("field_pattern", plant="homogeneous").plant == "homogeneous"
    sc = S.load("straight_offset", plant="grid")
    assert sc.plant == "grid" and sc.terrain.to_dict() == S.GRID_DEFAULT_TERRAIN
    assert S.load("straight_offset", ["terrain.cell_m=0.2"]).terrain.to_dict() == {"cell_m": 0.2}
    with pytest.raises(ScenarioError, match="terrain.cell_m"):
        S.load("straight_offset", ["terrain.cell_m=9.0"])
    with pytest.raises(ScenarioError, match="unknown key"):
        S.load("straight_offset", ["terrain.cells=3"])
    with pytest.raises(ScenarioError, match="terrain.passes"):
        CL.make_plant(S.load("straight_offset", ["terrain.passes=2"]), None)
    with pytest.raises(ScenarioError, match="plant"):
        S.load("straight_offset", plant="moon")
    # the field covers the path plus the margin
    origin, size = field_from_path(S.load("field_pattern").build_path())
    assert origin[0] < -4 and origin[1] <= -4 and size[0] > 48 and size[1] >= 31.9


def test_grid_plant_with_the_compiled_rosenbrock_matches_idas(grid_run, tmp_path):
    """run.integrator = "rosenbrock": the compiled grid integrator as the plant's; the closed loop
    and the ruts agree with the IDAS plant's."""
    from symtrack.native.cache import compiler as _compiler

    if _compiler() is None:
        pytest.skip("no C compiler: the grid rosenbrock would run interpreted (slow)")
    d, out = grid_run
    sc = S.load(str(d / "grid_short.toml"), ['run.integrator="rosenbrock"'])
    plant = CL.make_plant(sc, None)
    assert plant.stepper.settings.method == "rosenbrock"
    res = CL.run(sc, plant=plant)
    assert res.summary["failed_solves"] == 0 and res.summary["path_completed"]
    ref = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    n = min(len(ref), len(res.t))
    for k, name in enumerate(("x_m", "y_m")):
        assert np.max(np.abs(res.X[:n, k] - ref[name][:n])) < 1e-3, name
    idas = persist.load(d / "terrain.npz")
    assert np.max(np.abs(plant.world.storage.z - idas.z)) < 2e-5  # m, of ruts about 2-6 mm deep


def test_terrain_in_takes_the_file_geometry(grid_run):
    d, _ = grid_run
    sc = S.load("straight_offset", plant="homogeneous")
    plant = CL.make_plant(sc, None, str(d / "terrain.npz"))  # no [terrain]: all from the file
    g = persist.load(d / "terrain.npz").grid
    assert plant.world.grid == g and plant.world.grid.cell_m == 0.25
    from symtrack.terrain.settings import TerrainSettings
    from symtrack.terrain.world import derive_modulus

    # derived for the file's 0.25 m cells (and the default 10 m/s bound), not the 0.1 m default cells
    assert plant.world.M == derive_modulus(sc.params, TerrainSettings(cell_m=0.25), plant.macro_step_s) < 25
    with pytest.raises(ScenarioError, match="cell_m"):
        CL.make_plant(S.load("straight_offset", ["terrain.cell_m=0.2"]), None, str(d / "terrain.npz"))
