"""The soil-law registry (symtrack.soil.law): adding a law is one class and one registry
entry. A toy law registered here (linear loading, an elastic line on unloading), with two
coefficients of its own declared in its class, runs through the paths the Bekker/Wong law takes --
the homogeneous model's static state and compaction, a scenario simulated with ``model.soil_law``
(its coefficients in the ``[soil]`` table and the model's parameter vector), one channel loaded,
unloaded and reloaded with its history kept by the channel's INFO_OUT Function -- and meets its
closed form there."""

import casadi as ca
import numpy as np
import pytest

import symtrack
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.foundations.params import param
from symtrack.model import SystemModel
from symtrack.model.homogeneous import HomogeneousTerrain
from symtrack.model.options import ModelOptions
from symtrack.model.parameters import model_params, soil_params
from symtrack.model.static import static_state
from symtrack.model.system import PARAM_NAMES
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.soil import law as soil_law
from symtrack.terrain.channels import PHASE_LOADING, PHASE_UNLOADING, build_cell_functions

_TOY_SOURCE = "a test's toy: the order of the clayey soil preset's unloading stiffness K_e (4e7 Pa/m)"


class LinearPlastic(soil_law.SoilLaw):
    """A toy: p = k z on virgin loading, the line of slope k_u through the top (z_max, p_max) below
    it (clipped at 0 and at the virgin line), no load cycles. k and k_u are the toy's own
    coefficients, declared here and nowhere else."""

    name = "linear_plastic_toy"
    description = "linear loading, elastic unloading line (a test's toy)"
    params = (param("toy_loading_stiffness_Pa_per_m", "the toy's loading stiffness k", 0.0, 1e12, False,
                    default=1.3e7, source=_TOY_SOURCE),
              param("toy_unloading_stiffness_Pa_per_m", "the toy's unloading stiffness k_u", 0.0, 1e12, False,
                    default=4e7, source=_TOY_SOURCE))
    param_names = ("toy_loading_stiffness_Pa_per_m", "toy_unloading_stiffness_Pa_per_m")
    vector_names = ("loading_stiffness_Pa_per_m", "unloading_stiffness_Pa_per_m")

    def vector(self, params):
        return ca.vertcat(params["toy_loading_stiffness_Pa_per_m"], params["toy_unloading_stiffness_Pa_per_m"])

    def virgin_pressure(self, z, law):
        return law[0] * ca.fmax(z, 0)

    def _line(self, z, hist, law):
        return hist[1] + law[1] * (z - hist[0])

    def pressure(self, z, hist, law):
        virgin = self.virgin_pressure(z, law)
        return ca.if_else(z >= hist[0], virgin, ca.fmax(0, ca.fmin(virgin, self._line(z, hist, law))))

    def pressure_and_slope(self, z, hist, law):
        virgin, line = self.virgin_pressure(z, law), self._line(z, hist, law)
        lower = ca.fmin(virgin, line)
        slope_v = ca.if_else(z > 0, law[0], 0)
        slope_l = ca.if_else(virgin <= line, slope_v, law[1])
        p = ca.if_else(z >= hist[0], virgin, ca.fmax(0, lower))
        return p, ca.if_else(z >= hist[0], slope_v, ca.if_else(lower > 0, slope_l, 0))

    def history_update(self, z, p, hist, law):
        loading = z >= hist[0]
        return (ca.if_else(loading, z, hist[0]), ca.if_else(loading, ca.fmax(p, hist[1]), hist[1]), hist[4],
                ca.if_else(ca.logic_and(loading, z > 0), 1, 0), ca.if_else(loading, 1, 2))

    def cycle_increment(self, z, hist, cycles, law, beta):
        return 0 * z

    def compaction_work(self, z, law, width):
        return width * law[0] * z**2 / 2

    def static_sinkage(self, p, law):
        return p / law[0]


@pytest.fixture
def toy():
    soil_law.register(LinearPlastic)  # the one registry entry
    try:
        yield LinearPlastic(ModelOptions(soil_law=LinearPlastic.name))
    finally:
        soil_law.unregister(LinearPlastic.name)


# the toy's defaults beside a vehicle and a soil preset (which knows nothing of the toy)
PARAMS = {**vehicle_preset("reference_crawler"), **soil_preset("clayey_soil_thailand_38"),
          **{s.name: s.default for s in LinearPlastic.params}}


def _stiffness(params=PARAMS):
    return params["toy_loading_stiffness_Pa_per_m"], params["toy_unloading_stiffness_Pa_per_m"]


def test_the_default_law_is_bekker_wong_and_an_unknown_name_is_refused():
    assert ModelOptions().soil_law == "bekker_wong"
    assert isinstance(soil_law.make(ModelOptions()), soil_law.BekkerWong)
    with pytest.raises(ParameterError, match="bekker_wong"):
        ModelOptions(soil_law="linear_plastic_toy")
    with pytest.raises(ScenarioError, match="soil_law"):
        symtrack.load_scenario("validation", {"model.soil_law": "no_such_law"})
    with pytest.raises(ValueError, match="registered already"):
        soil_law.register(soil_law.BekkerWong)


def test_a_toy_law_in_the_homogeneous_model_meets_its_closed_form(toy):
    k, k_u = _stiffness()
    assert toy.values(PARAMS) == pytest.approx([k, k_u], rel=1e-15)
    model = SystemModel(toy.opts)
    x = static_state(model, PARAMS)
    y = np.array(model.outputs(x, [0, 0], model.param_vector(PARAMS))).ravel()
    for track in ("left", "right"):
        z = {e: x[model.state_index(f"sinkage_{e}_{track}_m")] for e in ("sprocket", "idler")}
        p = {e: y[model.output_index(f"p_{e}_{track}_Pa")] for e in ("sprocket", "idler")}
        assert z["idler"] == pytest.approx(p["idler"] / k, rel=1e-9)  # virgin: z = p / k
        # the sprocket cell reloads the idler's history: the virgin line above p_idler, the
        # elastic line through (z_idler, p_idler) below it
        expect = p["sprocket"] / k if p["sprocket"] >= p["idler"] else z["idler"] + (p["sprocket"] - p["idler"]) / k_u
        assert z["sprocket"] == pytest.approx(expect, rel=1e-9)
    # the compaction resistance of the homogeneous terrain is the toy's work per metre, b k z^2 / 2
    terrain = HomogeneousTerrain(toy.opts)
    xc = np.array([2e-3, 0, 3e-3, 0, 1e-3, 0, 0.5e-3, 0])  # (sprocket, idler) of the left, then the right track
    rc = np.array(terrain.compaction(None, xc, PARAMS, None)).ravel()
    b = PARAMS["track_width_m"]
    assert rc == pytest.approx([b * k * 3e-3**2 / 2, b * k * 1e-3**2 / 2], rel=1e-14)


def test_a_laws_coefficients_are_declared_in_its_module_only(toy):
    """The toy's two coefficients reach the model's parameter set and vector, after the vehicle's and
    the other soil coefficients, and the ``[soil]`` table, from its class alone; the default model's
    set and vector are unchanged by its registration, and a value out of the declared range is refused
    naming the key."""
    names = SystemModel(toy.opts).model_param_names
    assert names[-2:] == LinearPlastic.param_names
    assert not {"bekker_n", "k_c_N_per_m_n1", "elastic_stiffness_Pa_per_m"} & set(names)  # the Bekker/Wong law's
    assert names[:len(PARAM_NAMES) - 10] == PARAM_NAMES[:len(PARAM_NAMES) - 10]  # the vehicle's, as the default's
    assert {s.name for s in soil_params(toy.opts)} >= set(LinearPlastic.param_names)
    assert not set(LinearPlastic.param_names) & {s.name for s in soil_params()}
    assert tuple(s.name for s in model_params()) == PARAM_NAMES == SystemModel().model_param_names
    spec = {s.name: s for s in model_params(toy.opts)}["toy_loading_stiffness_Pa_per_m"]
    assert (spec.unit, spec.default, spec.source) == ("Pa/m", 1.3e7, _TOY_SOURCE)
    with pytest.raises(ScenarioError, match="toy_loading_stiffness_Pa_per_m = -1"):
        symtrack.load_scenario("validation", {"model.soil_law": LinearPlastic.name,
                                              "soil.toy_loading_stiffness_Pa_per_m": -1.0})
    with pytest.raises(ScenarioError, match="toy_loading_stiffness_Pa_per_m"):  # not a key of the Bekker/Wong model
        symtrack.load_scenario("validation", {"soil.toy_loading_stiffness_Pa_per_m": 2e7})
    # an MPC scenario takes them too, and writes them back in its resolved document
    from symtrack.control import scenario as mpc_scenario

    mpc = mpc_scenario.load("straight_offset", {"model.soil_law": LinearPlastic.name,
                                                "soil.toy_unloading_stiffness_Pa_per_m": 5e7})
    assert mpc.params["toy_unloading_stiffness_Pa_per_m"] == 5e7 and "bekker_n" not in mpc.params
    assert mpc.resolved_dict()["soil"]["toy_unloading_stiffness_Pa_per_m"] == 5e7


def test_a_users_soil_preset_file_holds_a_laws_own_coefficients(toy, tmp_path):
    """A user soil preset file (a built-in base and the toy's coefficient, with its source) feeds a scenario
    on the toy law; ``symtrack presets FILE`` lists the coefficient as set in the file."""
    from symtrack.presets.catalog import describe

    path = tmp_path / "toy_soil.toml"
    path.write_text('base = "clayey_soil_thailand_38"\ntoy_loading_stiffness_Pa_per_m = 1.7e7\n'
                    '[sources]\ntoy_loading_stiffness_Pa_per_m = "a plate test"\n')
    sc = symtrack.load_scenario("validation", {"model.soil_law": LinearPlastic.name, "soil.preset": str(path)})
    assert sc.params["toy_loading_stiffness_Pa_per_m"] == 1.7e7 and "bekker_n" not in sc.params
    assert sc.params["toy_unloading_stiffness_Pa_per_m"] == 4e7  # the declared default
    rows = {r[0]: r for r in describe("soil", str(path))}
    assert rows["toy_loading_stiffness_Pa_per_m"][1:3] == (1.7e7, "Pa/m")
    assert rows["toy_loading_stiffness_Pa_per_m"][4] == "set in toy_soil.toml: a plate test"


def test_a_toy_law_through_a_scenario(toy):
    """``model.soil_law`` in a scenario, with the toy's own coefficient given in ``[soil]``: the
    validation run on the toy soil, its idler cells at the toy's sinkage p / k under the idler
    pressure once the run is steady."""
    sc = symtrack.load_scenario("validation", {"model.soil_law": LinearPlastic.name, "run.duration_s": 3.0,
                                               "run.stop_after_distance_m": "none",
                                               "soil.toy_loading_stiffness_Pa_per_m": 1.6e7})
    assert sc.model.soil_law == LinearPlastic.name
    assert sc.params["toy_loading_stiffness_Pa_per_m"] == 1.6e7 and "bekker_n" not in sc.params
    res = symtrack.simulate(sc)
    k, _ = _stiffness(sc.params)
    assert k == 1.6e7
    for track in ("left", "right"):
        z = res.column(f"sinkage_idler_{track}_m")[-1]
        p = res.column(f"p_idler_{track}_Pa")[-1]
        assert z == pytest.approx(p / k, rel=1e-3)
    ref = symtrack.simulate(symtrack.load_scenario("validation", {"run.duration_s": 3.0,
                                                                  "run.stop_after_distance_m": "none"}))
    assert res.column("sinkage_idler_left_m")[-1] != pytest.approx(ref.column("sinkage_idler_left_m")[-1], rel=1e-2)


def test_a_toy_law_in_one_channel_load_unload_reload(toy):
    """One channel of the grid terrain on the toy law (the channel Functions the world manager
    uses), loaded to 30 kPa, unloaded to 10, reloaded to 30 and on to 40: the toy's lines."""
    fn = build_cell_functions(toy.opts)
    law = toy.values(PARAMS)
    k, k_u = _stiffness()
    z, zd, pl, zmax, pmax = (ca.SX.sym(n) for n in ("z", "zd", "p_load", "z_max", "p_max"))
    p = fn["soil"](z, ca.vertcat(zmax, pmax, 0, 0, 0), law)
    xdot = fn["dynamics"](zd, pl, p, 1.0, [PARAMS["cell_areal_mass_kg_per_m2"], PARAMS["cell_damping_Pa_s_per_m"]])
    F = ca.integrator("ch", "cvodes", {"x": ca.vertcat(z, zd), "p": ca.vertcat(pl, zmax, pmax), "ode": xdot}, 0, 2e-3,
                      {"abstol": 1e-12, "reltol": 1e-10})
    x, zm, pm = np.zeros(2), 0.0, 0.0
    ends, phases = [], []
    for a, b in [(0.0, 30e3), (30e3, 10e3), (10e3, 30e3), (30e3, 40e3)]:
        for s in np.linspace(0, 1, 201)[1:]:
            x = np.array(F(x0=x, p=[a + (b - a) * s, zm, pm])["xf"]).ravel()
            zm, pm, _, _, phase, _ = (float(v) for v in fn["history"](x[0], [zm, pm, 0, 0, 0], law))
        phases.append(phase)
        for _ in range(200):  # hold: settle to the static state
            x = np.array(F(x0=x, p=[b, zm, pm])["xf"]).ravel()
            zm, pm, _, _, phase, _ = (float(v) for v in fn["history"](x[0], [zm, pm, 0, 0, 0], law))
        ends.append((x[0], zm, pm))
    # at rest, each hold sits on the elastic line through the top the history recorded (the top
    # itself when it ends on the virgin line), the top on the virgin line p = k z, near the load's
    # own static sinkage (the ramp's small dynamic overshoot moves the top, as with Bekker's law)
    for (z_end, z_top, p_top), load in zip(ends, (30e3, 10e3, 30e3, 40e3), strict=True):
        assert z_end == pytest.approx(z_top + (load - p_top) / k_u, rel=1e-9)
        assert p_top == pytest.approx(k * z_top, rel=1e-12)
    assert ends[0][0] == pytest.approx(30e3 / k, rel=2e-3)  # virgin line
    assert ends[1][0] == pytest.approx(30e3 / k - 20e3 / k_u, rel=2e-3)  # the elastic line down
    assert ends[2][0] == pytest.approx(ends[1][1] + (30e3 - ends[1][2]) / k_u, rel=1e-9)  # and up again
    assert ends[3][0] == pytest.approx(40e3 / k, rel=2e-3)  # the virgin line beyond the top
    assert phases == [PHASE_LOADING, PHASE_UNLOADING, PHASE_UNLOADING, PHASE_LOADING]
    # the toy's slope (the engine's form) against the Jacobian of its pressure, on every piece
    h = ca.SX.sym("h", 5)
    pz, dpz = toy.pressure_and_slope(z, h, law)
    ref = toy.pressure(z, h, law)
    f = ca.Function("f", [z, h], [pz, dpz, ref, ca.jacobian(ref, z)])
    for zz in (-1e-4, 1e-3, 2.1e-3, 2.9e-3, 3.2e-3):
        pa, da, pb, db = (float(v) for v in f(zz, [30e3 / k, 30e3, 0, 0, 0]))
        assert pa == pb and da == pytest.approx(db, rel=1e-12)
    assert float(toy.cycle_increment(ca.DM(1e-3), [1e-3, 1e4, 0, 0, 0], 3, law, 0.16)) == 0.0


def test_a_toy_law_in_the_terrain_engines_cell_functions(toy):
    """The terrain engine's cell Functions (those its generated C is made of) on the toy law: the
    pressure and slope, INFO_OUT and INFO_IN, and one cell stepped by the engine's kernel (SDIRK
    with the law's slope in its Newton iterations) under a constant load to the toy's p / k."""
    import types

    from engine_oracle import PyKernel

    from symtrack.native.grid_engine_model import build_engine_functions

    f = build_engine_functions(toy.opts, PARAMS, 1)
    row = f.law_row(PARAMS)  # the toy's own coefficients, then the repeated-loading exponent
    assert row == [*toy.values(PARAMS), PARAMS["repeated_loading_exponent"]] and f.law_size == 3
    assert len(f.cell_law) == 1  # the toy declares no specialised copy
    k, k_u = _stiffness()
    top = (30e3 / k, 30e3)
    for z, hist, p, dp in ((1e-3, (0, 0), k * 1e-3, k), (2.1e-3, top, 30e3 + k_u * (2.1e-3 - top[0]), k_u),
                           (1e-3, top, 0.0, 0.0), (3e-3, top, k * 3e-3, k)):
        got = [float(v) for v in f.law(z, [*hist, 0, 0, 0], row)]
        assert got == pytest.approx([p, dp], rel=1e-12, abs=1e-9)
    zm1, pm1, _, plastic, phase = np.array(f.cell_history(3e-3, k * 3e-3, [*top, 0, 0, 0], row)).ravel()
    assert (zm1, pm1, plastic, phase) == pytest.approx((3e-3, k * 3e-3, 1, 1), rel=1e-15)
    assert float(f.cell_entry(1e-3, [*top, 0, 0, 0], 2, row)) == 0.0
    st = types.SimpleNamespace(areal_mass=PARAMS["cell_areal_mass_kg_per_m2"],
                               damping=PARAMS["cell_damping_Pa_s_per_m"], stats={"n_newton": 0, "n_cell_stages": 0},
                               soil_law=f.law_table([PARAMS]))
    kern = PyKernel(f, st)
    z = v = zm = pm = 0.0
    p, dp = (float(x) for x in f.law(0.0, [0, 0, 0, 0, 0], row))
    for i in range(150):  # the load ramped to 20 kPa over 0.5 s, then held: 10 ms macro steps, the history after each
        pl = [20e3 * min(1.0, j * 0.02) for j in (i, i + 1)]
        z, v, p, dp, _ = kern._cell_step(z, v, p, dp, pl, [1.0, 0.0, 1.0, 0.0], [zm, pm, 0, 0, 0], 0, 0.01, 1,
                                         [0.0, 0.0])
        zm, pm = np.array(f.cell_history(z, p, [zm, pm, 0, 0, 0], row)).ravel()[:2]
    # at rest on the elastic line through the top the history recorded, the top on p = k z near
    # the load's own static sinkage (the engine's step lags a little and moves the top)
    assert z == pytest.approx(zm + (20e3 - pm) / k_u, rel=1e-9)
    assert pm == pytest.approx(k * zm, rel=1e-12) and zm == pytest.approx(20e3 / k, rel=2e-2)


def test_a_toy_law_on_the_terrain_engine_and_its_terrain_file(toy, tmp_path):
    """The toy law's run on the grid (the terrain engine) writes a terrain file that records the parameter
    layout it was made with: the law's name and its own coefficients by name, none of the Bekker/Wong
    law's; the file continued under another law is refused, naming both."""
    grid = {"terrain.size_m": [12.0, 6.0], "terrain.cell_m": 0.1, "run.duration_s": 1.0}
    sc = symtrack.load_scenario("validation_grid", {**grid, "model.soil_law": LinearPlastic.name,
                                                    "soil.toy_loading_stiffness_Pa_per_m": 1.6e7})
    res = symtrack.simulate(sc)
    path = tmp_path / "toy.npz"
    res.terrain.save(path)
    with np.load(path) as f:
        assert str(f["soil_law"]) == LinearPlastic.name
        names = [str(n) for n in f["soil_names"]]
        assert dict(zip(names, f["soil_values"], strict=True))["toy_loading_stiffness_Pa_per_m"] == 1.6e7
    assert set(LinearPlastic.param_names) <= set(names) and "bekker_n" not in names
    assert float(res.terrain.zmax.max()) > 1e-3  # the cells were loaded
    with pytest.raises(ScenarioError, match="soil law 'linear_plastic_toy', the scenario has model.soil_law = "
                                            "'bekker_wong'"):
        symtrack.simulate(symtrack.load_scenario("validation_grid", {**grid, "terrain.initial_state": str(path)}))


def test_a_toy_law_on_a_soil_map(toy):
    """A soil map under the toy law: each soil of the map takes the toy's coefficients (their defaults: a
    soil preset knows nothing of them) and leaves the Bekker/Wong law's out; the run on the terrain
    engine carries both soils' traction coefficients under the tracks."""
    sc = symtrack.load_scenario("validation_grid", {
        "terrain.size_m": [12.0, 6.0], "terrain.cell_m": 0.1, "run.duration_s": 1.0,
        "model.soil_law": LinearPlastic.name,
        "terrain.soil_map": {"soils": ["clayey_soil_thailand_55",
                                       {"preset": "clayey_soil_thailand_55", "toy_loading_stiffness_Pa_per_m": 2e7}],
                             "zones": [{"soil": 1, "x_m": [-100.0, 100.0], "y_m": [-100.0, 0.0]},
                                       {"soil": 2, "x_m": [-100.0, 100.0], "y_m": [1.0, 100.0]}]}})
    res = symtrack.simulate(sc)
    world_soils = res.terrain.soil_table
    assert len(world_soils) == 2
    (label, soil), (_, soil2) = world_soils
    assert soil["toy_loading_stiffness_Pa_per_m"] == 1.3e7 and "bekker_n" not in soil
    assert soil2["toy_loading_stiffness_Pa_per_m"] == 2e7  # an entry's own value of the law's coefficient
    assert soil["cohesion_Pa"] != sc.params["cohesion_Pa"]  # the map's own soil
    assert float(res.terrain.zmax.max()) > 1e-3
