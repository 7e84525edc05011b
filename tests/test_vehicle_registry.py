"""The vehicle seam: the named state layout, the vehicle-model registry, and a toy vehicle registered
here that runs through the same path (SystemModel, make_plant, CVODES, the time loop) as the planar one."""

import casadi as ca
import numpy as np
import pytest
from small_field import small_field

import symtrack
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.model import ModelOptions, SystemModel
from symtrack.model.layout import ContactPose, StateLayout
from symtrack.model.static import static_state
from symtrack.simulation import loop
from symtrack.simulation.plants import make_plant
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.vehicles import registry as vehicle_registry
from symtrack.vehicles.planar import LATERAL_STATES, PLANAR_LAYOUT, VEHICLE_STATES, PlanarVehicle, vehicle_equations


class OdometerVehicle(PlanarVehicle):
    """The planar vehicle with one more state, right after the pose: the distance travelled along
    the field's x axis, d(odometer)/dt = dX/dt. Every planar state after the pose moves up by one."""

    name = "odometer_toy"
    # what it declares (symtrack.vehicles.base): the homogeneous terrain and the terrain engine, every
    # integrator of those; not the grid's channel pool (IDAS on the grid), nor the standalone engine
    plants = frozenset({"homogeneous", "engine"})
    standalone_engine = False
    state_names = VEHICLE_STATES[:3] + ("odometer_m",) + VEHICLE_STATES[3:]
    layout = StateLayout((("pose", VEHICLE_STATES[:3]), ("odometer", ("odometer_m",)),
                          *((b, PLANAR_LAYOUT.block_names_of(b))
                            for b in ("velocity", "sprockets", "shear", "torque"))))

    def equations(self, xv, u, acc, P, compaction_N, opts, track_soil=None):
        planar = ca.vertcat(*(xv[self.layout.index(n)] for n in VEHICLE_STATES))  # by name, not by position
        out = vehicle_equations(planar, u, acc, P, compaction_N, opts, track_soil)
        rates = dict(zip(VEHICLE_STATES, ca.vertsplit(out["xdot"]), strict=True))
        rates["odometer_m"] = rates["x_m"]
        return {**out, "xdot": ca.vertcat(*(rates[n] for n in self.state_names))}


@pytest.fixture
def toy():
    vehicle = vehicle_registry.register(OdometerVehicle())  # the one registry entry
    yield vehicle
    vehicle_registry.unregister(vehicle.name)


def test_layout_names_blocks_and_cells():
    lay = PLANAR_LAYOUT.with_cells(("a_m", "a_rate", "b_m", "b_rate"))
    assert lay.size == 16 and lay.nv == 12 and lay.n_cells == 2
    assert lay.index("yaw_rad") == 2 and lay.pose_index == [0, 1, 2]
    assert lay.block("vehicle") == slice(0, 12) and lay.block("cells") == slice(12, 16)
    assert lay.block_names_of("velocity") == ("u_m_s", "v_m_s", "yaw_rate_rad_s")
    x = np.arange(16.0)
    assert list(x[lay.cell_field("sinkage")]) == [12.0, 14.0] and list(x[lay.cell_field("rate")]) == [13.0, 15.0]
    assert list(lay.cell_index(np.array([1, 0]), "rate")) == [15, 13]
    assert lay.view(x)["u_m_s"] == 3.0
    with pytest.raises(KeyError, match="no state named 'z_m'"):
        lay.index("z_m")
    with pytest.raises(ValueError, match="appear more than once"):
        StateLayout((("pose", ("x_m",)), ("other", ("x_m",))))
    with pytest.raises(ValueError, match="not a multiple of 2"):
        PLANAR_LAYOUT.with_cells(("a_m",))


def test_the_default_model_is_the_planar_vehicle():
    """The planar vehicle carries the creep law; the default law ("shear") takes the planar vehicle with
    its four lateral shear states, "planar_lateral" (docs/turning.md section 8)."""
    assert SystemModel().vehicle is vehicle_registry.get("planar").lateral
    assert SystemModel().vehicle.name == "planar_lateral" and vehicle_registry.names()[:2] == ("planar", "3d")
    assert SystemModel().layout.vehicle_names == VEHICLE_STATES + LATERAL_STATES
    model = SystemModel(ModelOptions(lateral_law="creep"))
    assert model.vehicle is vehicle_registry.get("planar")
    assert model.layout.vehicle_names == VEHICLE_STATES and model.state_names == model.layout.names
    pose = model.vehicle.contact_pose(ca.DM(np.arange(12.0)))
    assert isinstance(pose, ContactPose) and pose.is_planar and [float(v) for v in pose.planar] == [0.0, 1.0, 2.0]
    with pytest.raises(ValueError, match="is not one of planar"):
        SystemModel(vehicle="no_such_vehicle")


def test_a_vehicle_without_the_interface_is_refused():
    class Half:
        name = "half"
    with pytest.raises(ValueError, match="lacks layout"):
        vehicle_registry.register(Half())


def test_toy_vehicle_runs_through_cvodes_and_keeps_its_own_equations(toy):
    sc = symtrack.load_scenario("validation", {"run.integrator": "cvodes", "run.duration_s": 3.0,
                                               "run.stop_after_distance_m": "none"})
    model = SystemModel(sc.model, vehicle="odometer_toy")
    assert model.layout.index("u_m_s") == 4 and model.layout.nv == 13 and model.nx == 13 + 8
    x0 = static_state(model, sc.params, 1.0, 0.0, 0.0)
    assert x0[model.layout.index("x_m")] == 1.0 and np.all(x0[model.layout.cell_field("sinkage")] > 0)
    run = loop.run(sc, make_plant(sc, model=model))
    ref = loop.run(sc, make_plant(sc))  # the planar vehicle, same scenario, same path
    assert run.state_names == model.state_names and run.X.shape[1] == 21
    assert ref.state("u_m_s")[-1] > 0.5  # it drove
    # what the toy must satisfy: its odometer is the distance travelled along x
    np.testing.assert_allclose(run.state("odometer_m") - run.state("odometer_m")[0],
                               run.state("x_m") - run.state("x_m")[0], rtol=1e-6, atol=1e-7)
    # and the extra state does not feed back: the planar states and the outputs are the planar vehicle's
    # (to CVODES's tolerance: its step choices differ with the toy's extra state; the sinkage rates within
    # 1.3e-7 m/s of each other, measured, where the shear's switch from loading to unloading is a kink)
    for name in VEHICLE_STATES + tuple(n for n in ref.state_names if n.startswith("sinkage_")):
        np.testing.assert_allclose(run.state(name), ref.state(name), rtol=1e-5, atol=3e-7, err_msg=name)
    np.testing.assert_allclose(run.output("compaction_resistance_left_N"), ref.output("compaction_resistance_left_N"),
                               rtol=1e-5)


def _odometer_agrees(run, ref):
    """The toy's closed form: its odometer is the distance along x; its planar states are the planar
    vehicle's."""
    np.testing.assert_allclose(run.column("odometer_m") - run.column("odometer_m")[0],
                               run.column("x_m") - run.column("x_m")[0], rtol=1e-6, atol=1e-7)
    for name in ("x_m", "y_m", "yaw_rad", "u_m_s", "omega_left_rad_s", "torque_left_N_m"):
        np.testing.assert_allclose(run.column(name), ref.column(name), rtol=1e-5, atol=1e-7, err_msg=name)


@pytest.mark.parametrize("integrator", ["cvodes", "idas", "rosenbrock"])
def test_the_toy_is_chosen_by_model_vehicle_on_every_homogeneous_integrator(toy, integrator):
    """``model.vehicle`` names the registry's entry: the toy runs through symtrack.simulate on each
    integrator of the homogeneous terrain it declares."""
    over = {"run.integrator": integrator, "run.duration_s": 1.0, "run.stop_after_distance_m": "none",
            "model.lateral_law": "creep"}
    res = symtrack.simulate(symtrack.load_scenario("validation", {**over, "model.vehicle": "odometer_toy"}))
    ref = symtrack.simulate(symtrack.load_scenario("validation", over))
    assert res.runs[0].state_names[3] == "odometer_m" and ref.column("u_m_s")[-1] > 0.3
    _odometer_agrees(res, ref)


def test_the_toy_runs_on_the_terrain_engine(toy):
    """The engine's C reads the states by the toy's layout (its offsets are generated from it): the
    toy's forward speed sits one further than the planar vehicle's, and the run and the field it leaves
    are the planar vehicle's."""
    doc = small_field("toy_engine")
    doc["model"] = {"lateral_law": "creep"}
    ref = symtrack.simulate(scenario_from_dict(doc))
    doc["model"]["vehicle"] = "odometer_toy"
    res = symtrack.simulate(scenario_from_dict(doc))
    assert res.runs[0].state_names.index("u_m_s") == 4 and ref.column("u_m_s")[-1] > 0.1
    _odometer_agrees(res, ref)
    np.testing.assert_allclose(res.terrain.z, ref.terrain.z, rtol=1e-6, atol=1e-9)


def test_what_a_vehicle_does_not_declare_is_refused(toy):
    """The toy declares neither the grid's channel pool nor the standalone engine: both refused by
    name, with the menu; an unknown vehicle names the menu."""
    doc = small_field("toy_refused", run={"integrator": "idas"})
    doc["model"] = {"lateral_law": "creep", "vehicle": "odometer_toy"}
    with pytest.raises(ScenarioError, match=r"model.vehicle = 'odometer_toy' runs on the homogeneous terrain or "
                                            r"on the grid through the terrain engine .* only; this run asks for the "
                                            r"grid's channel pool .*one of planar"):
        scenario_from_dict(doc)
    from symtrack.codegen.engine_fmu import check_exportable

    doc["run"]["integrator"] = "grid_fast"
    with pytest.raises(ScenarioError, match="model.vehicle = 'odometer_toy': the engine FMU carries 'planar' only"):
        check_exportable(scenario_from_dict(doc))
    with pytest.raises(ParameterError, match="model.vehicle = 'no_such' is not one of planar, 3d, odometer_toy"):
        ModelOptions(vehicle="no_such")
