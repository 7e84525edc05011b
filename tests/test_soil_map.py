"""A field of several soils (docs/model.md, "Soil that varies over the field"): the soil map's parsing, a
uniform map equal to the single soil bit for bit, each cell's law its own soil's, the traction
from the soil under each track, persistence, and the integrators that take one soil only."""

import copy
import math

import numpy as np
import pytest
from engine_oracle import PyKernel

import symtrack
from symtrack.foundations.errors import ScenarioError
from symtrack.integrators.engine import TerrainEngine
from symtrack.model.options import ModelOptions
from symtrack.presets import soil_preset
from symtrack.simulation.scenario import load_scenario, scenario_from_dict
from symtrack.terrain.storage import Terrain
from symtrack.terrain.world import open_world
from symtrack.vehicles.planar import traction_shape

WET = "clayey_soil_thailand_55"
BASE = {
    "name": "soil_map_test", "run": {"duration_s": 3.0, "output_dt_s": 0.01, "integrator": "grid_fast",
                                     "stop_after_distance_m": 0.6},
    "vehicle": {"preset": "reference_crawler"}, "soil": {"preset": "clayey_soil_thailand_38"},
    "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
    "terrain": {"size_m": [8.0, 5.0], "origin_m": [-3.0, -2.5], "cell_m": 0.1},
    "torque": [{"t_s": 0.0, "left_N_m": 1500.0, "right_N_m": 1500.0}],
}


def _scenario(soil_map=None, **run):
    d = copy.deepcopy(BASE)
    d["run"].update(run)
    if soil_map is not None:
        d["terrain"]["soil_map"] = soil_map
    return scenario_from_dict(d)


@pytest.mark.parametrize("bad, match", [
    ({"soils": [WET], "zones": [{"soil": 2, "x_m": [0, 1], "y_m": [0, 1]}]}, r"zones\[0\]\.soil = 2"),
    ({"soils": ["no_such_soil"], "zones": [{"soil": 1, "x_m": [0, 1], "y_m": [0, 1]}]}, "no_such_soil"),
    ({"soils": [WET]}, "needs zones or a raster"),
    ({"soils": [WET], "zones": [{"soil": 1, "x_m": [1, 0], "y_m": [0, 1]}]}, r"x_m = \[1, 0\] must have low < high"),
    ({"soils": [WET], "colour": "red", "zones": []}, "colour"),
    ({"soils": [{"preset": WET, "bekker_n": -1.0}], "zones": [{"soil": 1, "x_m": [0, 1], "y_m": [0, 1]}]},
     "bekker_n"),
])
def test_a_bad_soil_map_is_refused_naming_the_key(bad, match):
    with pytest.raises(ScenarioError, match=match):
        _scenario(bad)


def test_a_uniform_soil_map_is_the_single_soil_bit_for_bit():
    plain = symtrack.simulate(_scenario())
    # the whole field given the scenario's own soil, as a map: the same soil, the same run
    same = {"soils": ["clayey_soil_thailand_38"], "zones": [{"soil": 1, "x_m": [-10, 10], "y_m": [-10, 10]}]}
    mapped = symtrack.simulate(_scenario(same))
    assert np.array_equal(plain.runs[0].X, mapped.runs[0].X) and np.array_equal(plain.runs[0].Y, mapped.runs[0].Y)
    for name, a in plain.terrain.arrays().items():
        assert np.array_equal(a, mapped.terrain.arrays()[name]), name


def _split_world():
    """The left track (y > 0) on the wet soil, the right on the scenario's."""
    sm = {"soils": [WET], "zones": [{"soil": 1, "x_m": [-10, 10], "y_m": [0.0, 10]}]}
    sc = _scenario(sm)
    world = open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s)
    return sc, world


def test_each_cell_sinks_by_its_own_soil_and_the_traction_uses_the_soil_under_each_track():
    sc, world = _split_world()
    assert len(world.soils) == 2
    eng = TerrainEngine(world)
    eng.begin_pass(0.0, 0.0, 0.0)
    s = eng.state
    act = s.active_channels()
    for soil, frac_col in ((1, 1), (0, 2)):  # soil 1 under the left track (frac_left), soil 0 under the right
        full = act[(s.ch_g[act, frac_col] > 0.999) & (s.ch_soil[act] == soil)]
        assert full.size > 20
        z_static = world.terrain.law.static_sinkage(s.ch_g[full, 0], world.terrain.law.values(world.soils[soil]))
        assert np.max(np.abs(s.ch_z[full] / z_static - 1)) < 1e-2
    # the traction of each track with the soil under it: the engine's outputs at a state with shear
    eng.kernel.sums()
    layout = eng.fns.layout
    x = s.wv[:layout.nv].copy()
    js = {"left": 0.01, "right": 0.012}  # shear displacements
    # straight running at 2 m/s with each track at the steady slip of its shear, i = 2 j / l (Ferretti & Girelli)
    r, l = sc.params["sprocket_radius_m"], sc.params["contact_length_m"]
    x[layout.index("u_m_s")] = 2.0
    for track, j in js.items():
        x[layout.index(f"shear_{track}_m")] = j
        x[layout.index(f"omega_{track}_rad_s")] = 2.0 / (r * (1 - 2 * j / l))
    y = dict(zip(eng.output_names, np.array(eng.fns.outputs(x, [0, 0], s.pv)).ravel(), strict=True))
    opts = ModelOptions()
    P = sc.params

    def eq1(track, soil):
        N = y[f"normal_load_{track}_N"]
        return float(traction_shape(js[track], soil["shear_modulus_K_m"], opts)) * (
            P["track_width_m"] * P["contact_length_m"] * soil["cohesion_Pa"] + N * math.tan(soil["friction_angle_rad"]))

    # the default law's thrust in straight running is Ferretti & Girelli's by its quadrature along
    # the track (docs/turning.md section 1: within 1e-4); the other soil is 3.7 % (left) and 1.6 % (right) off
    for track, soil, other in (("left", world.soils[1], world.soils[0]), ("right", world.soils[0], world.soils[1])):
        assert y[f"tractive_{track}_N"] == pytest.approx(eq1(track, soil), rel=2e-4), track
        assert abs(y[f"tractive_{track}_N"] / eq1(track, other) - 1) > 0.01, track
    assert soil_preset(WET)["cohesion_Pa"] != P["cohesion_Pa"]  # the two soils do differ


def test_the_soil_map_persists_and_a_terrain_keeps_its_own(tmp_path):
    sm = {"soils": [WET], "zones": [{"soil": 1, "x_m": [1.0, 10], "y_m": [-10, 10]}]}
    res = symtrack.simulate(_scenario(sm))
    idx = res.terrain.soil_index.copy()
    assert idx.any() and not idx.all()
    res.terrain.save(tmp_path / "t.npz")
    t = Terrain.load(tmp_path / "t.npz", res.scenario.params)
    assert np.array_equal(t.soil_index, idx) and t.soil_table == res.terrain.soil_table
    # a second pass on the saved terrain, the scenario without a soil map: the file's is kept
    again = symtrack.simulate(_scenario(), terrain=tmp_path / "t.npz")
    assert np.array_equal(again.terrain.soil_index, idx)
    # a scenario with another map cannot continue it
    other = {"soils": [WET], "zones": [{"soil": 1, "x_m": [2.0, 10], "y_m": [-10, 10]}]}
    with pytest.raises(ScenarioError, match="soil map of its own"):
        symtrack.simulate(_scenario(other), terrain=tmp_path / "t.npz")


def test_idas_refuses_a_field_of_several_soils():
    sm = {"soils": [WET], "zones": [{"soil": 1, "x_m": [-10, 10], "y_m": [0.0, 10]}]}
    with pytest.raises(ScenarioError, match="terrain engine only"):
        symtrack.simulate(_scenario(sm, integrator="idas", duration_s=0.05))


def test_a_raster_gives_each_cell_its_soil(tmp_path):
    sc = load_scenario("multipass")
    nx, ny = sc.terrain.shape
    r = np.zeros((nx, ny), dtype=np.int16)
    r[:, ny // 2:] = 1
    np.save(tmp_path / "soils.npy", r)
    sm = {"soils": [WET], "raster": str(tmp_path / "soils.npy")}
    d = copy.deepcopy(BASE)
    d["terrain"] = dict(sc.terrain.to_dict(), soil_map=sm)
    s2 = scenario_from_dict(d)
    world = open_world(s2.terrain, s2.params, s2.model, s2.run.output_dt_s)
    assert np.array_equal(world.storage.soil_index.reshape(nx, ny), r.astype(np.uint8))
    np.save(tmp_path / "bad.npy", np.zeros((3, 3), dtype=np.int16))
    d["terrain"]["soil_map"] = {"soils": [WET], "raster": str(tmp_path / "bad.npy")}
    s3 = scenario_from_dict(d)
    with pytest.raises(ScenarioError, match=r"shape \(200, 80\)"):
        open_world(s3.terrain, s3.params, s3.model, s3.run.output_dt_s)


def test_the_wet_headland_example_puts_the_risk_where_the_soil_is_weak(tmp_path):
    import runpy

    ex = runpy.run_path("examples/wet_headland.py")
    res = symtrack.simulate(ex["scenario"](2, 10.0))
    res.write(tmp_path)
    assert (tmp_path / "risk_map.png").stat().st_size > 10000 and (tmp_path / "stress_profile.png").exists()
    st = res.terrain
    world_pc = np.array([sp["precompression_stress_Pa"] for sp in res._study.world.soils])[st.soil_index]
    ratio = st.sigma_max[:, 0] / world_pc
    gx, _ = st.grid.centres(*np.divmod(np.arange(st.grid.n_cells), st.grid.shape[1]))
    risky = ratio >= 0.5
    assert risky.any() and np.all(gx[risky] >= 10.0 - 8.0 - 0.05)  # medium risk only in the wet headland
    assert np.all(ratio[(st.sigma_max[:, 0] > 0) & (gx < 1.9)] < 0.5)  # the dry field stays low
    fr = res.summary["passes"][0]["subsoil_risk_fraction_medium"]
    assert fr[0] > 0.2 and fr[-1] <= fr[0]  # less risk deeper down


def test_compiled_equals_interpreted_on_a_field_of_two_soils():
    """The interpreted kernel (tests/engine_oracle.py's PyKernel) against the C one on the split field:
    the same algorithm, soil by soil (measured: identical to the last bit)."""
    from symtrack.simulation import loop
    from symtrack.simulation.plants import EnginePlant
    from symtrack.toolchain import find_compiler

    if find_compiler() is None:
        pytest.skip("no C compiler")
    sm = {"soils": [WET], "zones": [{"soil": 1, "x_m": [-10, 10], "y_m": [0.0, 10]}]}
    sc = _scenario(sm, duration_s=0.1, stop_after_distance_m="none")
    out = []
    for compiled in (True, False):
        world = open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s)
        res = loop.run(sc, EnginePlant(world, TerrainEngine(world, kernel=None if compiled else PyKernel)))
        out.append((res.X, res.Y, world.storage.z.copy()))
    assert np.max(np.abs(out[0][0] - out[1][0]) / np.maximum(1.0, np.abs(out[1][0]))) < 1e-12
    assert np.max(np.abs(out[0][1] - out[1][1]) / np.maximum(1.0, np.abs(out[1][1]))) < 1e-9
    assert np.max(np.abs(out[0][2] - out[1][2])) < 1e-12


def test_a_cleared_world_is_virgin_soil_on_the_same_soils():
    """World.clear (the field study's next pattern, a benchmark's next run): after a run over a field
    of two soils every stored state and pass record is zero again (virgin soil: 0 is the initial
    specific volume), while the soils of its cells are kept; the same run then gives the same field."""
    from symtrack.simulation import loop
    from symtrack.simulation.plants import make_plant

    sc = _scenario({"soils": [WET], "zones": [{"soil": 1, "x_m": [-10, 10], "y_m": [0.0, 10]}]})
    plant = make_plant(sc)
    world = plant.world
    idx = world.storage.soil_index.copy()
    assert set(np.unique(idx)) == {0, 1}
    loop.run(sc, plant)
    first = {k: a.copy() for k, a in world.storage.arrays().items()}
    assert first["z_max_m"].max() > 0  # the run sank cells
    world.clear()
    for name, a in world.storage.arrays().items():
        if name == "soil_index":
            assert np.array_equal(a, idx)
        else:
            assert not a.any(), name
    assert not world.pass_sigma.any() and not world.pass_p_mean.any() and not world.touched.any()
    loop.run(sc, plant)
    for name, a in world.storage.arrays().items():
        assert np.array_equal(a, first[name]), name
