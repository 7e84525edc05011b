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
from symtrack.foundations.errors import ScenarioError, SimulationError
from symtrack.simulation.plants import EnginePlant, GridPlant, advance_plant
from symtrack.terrain import storage as persist
from symtrack.vehicles.planar import VEHICLE_STATES

# a short straight run on a small field: 6 m of path at 2 m/s, 3 s simulated; 0.4 m cells, the coarsest
# the 0.45 m track width allows: the IDAS reference's cost grows with the channels (its closed loop 24 s
# of CPU on 0.25 m cells, 10 s on 0.4 m)
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
cell_m = 0.4
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
    assert s["plant"] == "grid" and s["plant_integrator"] == "grid_fast"  # the engine: the default (issue 9)
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
    assert isinstance(plant, EnginePlant)  # the terrain engine: the grid plant's default (issue 9)
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


@pytest.fixture(scope="module")
def idas_run(grid_run):
    """The short run on the IDAS grid plant (the reference integrator, run.integrator = "idas")."""
    d, _ = grid_run
    sc = S.load(str(d / "grid_short.toml"), ['run.integrator="idas"'])
    plant = CL.make_plant(sc, None)
    assert isinstance(plant, GridPlant) and plant.stepper.settings.method == "idas"
    res = CL.run(sc, plant=plant)
    assert res.summary["plant_integrator"] == "idas"
    return res, plant


@pytest.mark.slow  # the IDAS closed loop as the reference (make test-slow)
def test_engine_plant_is_the_default_and_matches_idas(grid_run, idas_run):
    """The default grid plant is the terrain engine (10 ms macro steps, started from the trim);
    its closed loop and ruts agree with the IDAS plant's (0.02 s world steps)."""
    d, out = grid_run
    s = json.loads((out / "summary.json").read_text())
    ref, ref_plant = idas_run
    assert ref.summary["failed_solves"] == 0 and ref.summary["path_completed"]
    traj = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    n = min(len(traj), len(ref.t))
    for k, name in enumerate(VEHICLE_STATES[:6]):
        scale = 1.0 if k < 3 else 2.0  # positions (m, rad) and speeds (m/s, rad/s)
        assert np.max(np.abs(traj[name][:n] - ref.X[:n, k])) < 1e-3 * scale, name
    # the ruts (after the lift-off) to 2 % of their depth, and 2 % in volume
    assert abs(s["rut_max_depth_mm"] / ref.summary["rut_max_depth_mm"] - 1) < 0.02
    assert abs(s["rut_volume_m3"] / ref.summary["rut_volume_m3"] - 1) < 0.02
    engine_z = persist.load(d / "terrain.npz").z
    assert np.max(np.abs(engine_z - ref_plant.world.storage.z)) < 5e-5  # m, of ruts about 2 mm deep
    # the plant is at least 20 x cheaper than IDAS (measured about 300 x: docs/control.md)
    assert s["plant_wall_time_s"] < ref.summary["plant_wall_time_s"] / 20


@pytest.mark.slow  # the IDAS closed loop as the reference (make test-slow)
def test_grid_plant_with_the_compiled_rosenbrock_matches_idas(grid_run, idas_run):
    """run.integrator = "rosenbrock": the compiled grid integrator as the plant's; the closed loop
    and the ruts agree with the IDAS plant's."""
    from symtrack.toolchain import compiler as _compiler

    if _compiler() is None:
        pytest.skip("no C compiler: the grid rosenbrock would run interpreted (slow)")
    d, out = grid_run
    sc = S.load(str(d / "grid_short.toml"), ['run.integrator="rosenbrock"'])
    plant = CL.make_plant(sc, None)
    assert plant.stepper.settings.method == "rosenbrock"
    res = CL.run(sc, plant=plant)
    assert res.summary["failed_solves"] == 0 and res.summary["path_completed"]
    ref, ref_plant = idas_run
    n = min(len(ref.t), len(res.t))
    for k, name in enumerate(("x_m", "y_m")):
        assert np.max(np.abs(res.X[:n, k] - ref.X[:n, k])) < 1e-3, name
    assert np.max(np.abs(plant.world.storage.z - ref_plant.world.storage.z)) < 2e-5  # m, of ruts about 2-6 mm deep


def test_engine_plant_starts_from_a_running_state(grid_run):
    """EnginePlant.start(state=): set down at rest (cells at their static sinkage, settled), then
    given the trim's running state; the algebraic accelerations are made consistent with it."""
    d, _ = grid_run
    # 0.25 m cells: each cell under a track wholly under it (on 0.4 m cells an edge cell can carry nothing)
    sc = S.load(str(d / "grid_short.toml"), ["terrain.cell_m=0.25"])
    plant = CL.make_plant(sc, None)
    from symtrack.model import SystemModel

    model = SystemModel(sc.model)
    xt, ut = CL.initial_state(model, sc)
    xv = xt[model.layout.block("vehicle")]
    x, y = plant.start(xv[0], xv[1], xv[2], ut, state=xv)
    assert np.array_equal(x, xv)
    s = plant.engine.state
    act = s.active_channels()
    loaded = act[s.ch_g[act, 0] > 0.0]  # the cells under the tracks (the others: the footprint's padding)
    assert loaded.size > 0 and np.all(s.ch_z[loaded] > 1e-4)  # they carry the vehicle
    w1, _, _ = plant.engine.fns.vehicle_step(s.wv, ut, s.pv, 0.0)  # consistent: a zero step changes nothing
    assert np.max(np.abs(np.array(w1).ravel() - s.wv)) < 1e-9
    x1, _ = advance_plant(plant, ut, 0.1, plant.macro_step_s)
    assert abs(x1[3] - xv[3]) < 0.02 and 0.19 < x1[0] - xv[0] < 0.21  # running on at the trim speed
    with pytest.raises(SimulationError, match="pose"):
        plant.start(xv[0] + 1.0, xv[1], xv[2], ut, state=xv)
    with pytest.raises(SimulationError, match=f"{model.layout.nv} vehicle states"):
        plant.start(xv[0], xv[1], xv[2], ut, state=xv[:6])


def test_engine_plant_retry_and_partial_commit_from_checkpoints(grid_run):
    """checkpoints=True: retry re-runs an interval from the saved engine state (storage + channel
    tables), bit for bit; a commit of fewer intervals than advanced leaves the plant there."""
    d, _ = grid_run
    sc = S.load(str(d / "grid_short.toml"))
    from symtrack.model import SystemModel

    model = SystemModel(sc.model)
    xt, ut = CL.initial_state(model, sc)
    xv = xt[model.layout.block("vehicle")]
    h = 0.01

    def started(checkpoints):
        p = CL.make_plant(sc, None)
        p.checkpoints = checkpoints
        p.start(xv[0], xv[1], xv[2], ut, state=xv)
        return p

    ivs = [(k * h, h, ut) for k in range(6)]
    a = started(True)
    a.synchronize(ivs)
    X = a.advance()
    z_adv = a.world.storage.z.copy()
    assert np.array_equal(a.retry(5, h), X[5])  # the same length: the same state, to the bit
    assert np.array_equal(a.world.storage.z, z_adv)
    x_short = a.retry(3, 0.004)  # interval 3 shortened: the plant is then at 0.034 s
    Y = a.commit(4)
    assert Y.shape[0] == 4
    b = started(False)
    b.synchronize(ivs[:3] + [(3 * h, 0.004, ut)])
    Xb = b.advance()
    b.commit(4)
    assert np.array_equal(Xb[3], x_short)
    assert np.array_equal(a.world.storage.z, b.world.storage.z)
    assert np.array_equal(a.engine.state.ch_cell, b.engine.state.ch_cell)
    # a partial commit: 6 advanced, 2 accepted = a run of 2
    a.synchronize([(0.034 + k * h, h, ut) for k in range(6)])
    a.advance()
    a.commit(2)
    b.synchronize([(0.034 + k * h, h, ut) for k in range(2)])
    b.advance()
    b.commit(2)
    assert np.array_equal(a.engine.state.wv, b.engine.state.wv)
    assert np.array_equal(a.world.storage.z, b.world.storage.z)
    with pytest.raises(SimulationError, match="checkpoints"):
        b.synchronize(ivs[:2])
        b.advance()
        b.retry(1, 0.005)


def test_terrain_in_takes_the_file_geometry(grid_run):
    d, _ = grid_run
    sc = S.load("straight_offset", plant="homogeneous")
    plant = CL.make_plant(sc, None, str(d / "terrain.npz"))  # no [terrain]: all from the file
    g = persist.load(d / "terrain.npz").grid
    assert plant.world.grid == g and plant.world.grid.cell_m == 0.4
    from symtrack.terrain.settings import TerrainSettings
    from symtrack.terrain.world import derive_modulus

    # derived for the file's 0.4 m cells (and the default 10 m/s bound), not the 0.1 m default cells
    assert plant.world.M == derive_modulus(sc.params, TerrainSettings(cell_m=0.4), plant.macro_step_s) < 25
    with pytest.raises(ScenarioError, match="cell_m"):
        CL.make_plant(S.load("straight_offset", ["terrain.cell_m=0.2"]), None, str(d / "terrain.npz"))
