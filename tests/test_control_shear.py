"""The nonlinear MPC on the soil's shear law (docs/turning.md, "Nonlinear MPC on the shear law"):
the prediction's regularisation of the sliding direction, the [model] section of MPC scenarios, and
a short closed loop into the U-turn on the clay."""

import dataclasses
import itertools

import casadi as ca
import numpy as np
import pytest

from symtrack.control import closedloop as CL
from symtrack.control import scenario as S
from symtrack.control.mpc import MPCSettings, prediction_model
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.model import SystemModel
from symtrack.model.options import ModelOptions
from symtrack.presets import soil_preset, vehicle_preset
from symtrack.vehicles.planar import PressureDistribution, shear_forces

CLAY = "clayey_soil_thailand_38"


def _max_curvature(opts) -> float:
    """The largest |d^2 F_x / d omega^2| of one track [N/(rad/s)^2] near straight running at 2 m/s on
    the clay: longitudinal slips -2 % ... +2 % (41 sprocket speeds), lateral velocities 0, 1 mm/s,
    -1 cm/s, yaw rates 0, 1e-3, -1e-2, 0.1 rad/s, shear displacements -1 mm, 10 um, 1 mm."""
    P = {**vehicle_preset("reference_crawler"), **soil_preset(CLAY)}
    B, b, l, r = P["track_gauge_m"], P["track_width_m"], P["contact_length_m"], P["sprocket_radius_m"]
    e = P["cg_ahead_of_contact_centre_m"]
    N = P["mass_kg"] * 9.80665 / 2
    x = ca.SX.sym("x", 5)
    vx, vy, rz, om, j = (x[i] for i in range(5))
    Fx, _, _ = shear_forces(j, om, None, vx + rz * B / 2, vy, rz, l / 2 - e, PressureDistribution(N, 0.0, b, l), N,
                            b, l, r, P["cohesion_Pa"], P["friction_angle_rad"], P["shear_modulus_K_m"], opts)
    pts = [[2.0, vy, rz, (2.0 + rz * B / 2) * (1 + di) / r, j]
           for vy, rz, j in itertools.product((0.0, 1e-3, -1e-2), (0.0, 1e-3, -1e-2, 0.1), (-1e-3, 1e-5, 1e-3))
           for di in np.linspace(-0.02, 0.02, 41)]
    f = ca.Function("h", [x], [ca.hessian(Fx, om)[0]]).map(len(pts))
    return float(np.max(np.abs(np.array(f(np.array(pts).T)))))


def test_the_prediction_regularisation_bounds_the_curvature_that_stalls_ipopt():
    # the exact law's tractive force depends on the ratio of the longitudinal to the lateral slip:
    # near straight running (both small) it turns over tiny changes of the sprocket speed
    exact = _max_curvature(ModelOptions(lateral_law="shear_quasistatic"))
    pred = _max_curvature(ModelOptions(lateral_law="shear_quasistatic", sliding_smoothing=0.01,
                                       sliding_sign="velocity"))
    assert exact > 1e9  # measured 2.3e10
    assert pred < 3e6  # measured 1.2e6; the creep law's tractive force does not depend on omega at all


def test_prediction_model_and_settings():
    # every law: the prediction's shear displacement without the unloading switch (the plant's own
    # unloading with mpc.prediction_shear_unloading = None), every other option the plant's
    creep = SystemModel(ModelOptions(lateral_law="creep"))
    pm = prediction_model(creep, MPCSettings())
    assert not pm.opts.shear_unloading and creep.opts.shear_unloading
    assert dataclasses.replace(pm.opts, shear_unloading=True) == creep.opts
    assert prediction_model(creep, MPCSettings(prediction_shear_unloading=None)) is creep
    # the default (lagged) law: its sliding predicted exactly by every solver (measured: docs/turning.md
    # section 6)
    lagged = SystemModel()
    for settings in (MPCSettings(), MPCSettings(solver="rti")):
        assert dataclasses.replace(prediction_model(lagged, settings).opts, shear_unloading=True) == lagged.opts
    assert prediction_model(lagged, MPCSettings(prediction_shear_unloading=None)) is lagged
    shear = SystemModel(ModelOptions(lateral_law="shear_quasistatic"))
    pm = prediction_model(shear, MPCSettings())
    assert pm.opts.sliding_smoothing == 0.01 and pm.opts.sliding_sign == "velocity" and not pm.opts.shear_unloading
    assert pm.opts.lateral_law == "shear_quasistatic" and shear.opts.sliding_sign == "displacement"
    same = prediction_model(shear, MPCSettings(prediction_sliding_smoothing=None, prediction_sliding_sign="model",
                                               prediction_shear_unloading=None))
    assert same is shear
    with pytest.raises(ParameterError, match="mpc.prediction_shear_unloading"):
        MPCSettings(prediction_shear_unloading=1)
    with pytest.raises(ParameterError, match="mpc.prediction_sliding_sign"):
        MPCSettings(prediction_sliding_sign="sideways")
    with pytest.raises(ParameterError, match="mpc.prediction_sliding_smoothing"):
        MPCSettings(prediction_sliding_smoothing=0.0)
    with pytest.raises(ParameterError, match="model.sliding_sign"):
        ModelOptions(sliding_sign="sideways")


def test_mpc_scenario_model_section():
    sc = S.load("straight_offset", ['model.lateral_law="shear_quasistatic"'])
    assert sc.model.lateral_law == "shear_quasistatic"
    assert sc.to_dict()["model"] == {"lateral_law": "shear_quasistatic"}
    assert "model" not in S.load("straight_offset").to_dict()
    with pytest.raises(ScenarioError, match="unknown key"):
        S.load("straight_offset", ["model.lateral_lw='shear'"])
    with pytest.raises(ScenarioError, match="model.lateral_law"):
        S.load("straight_offset", ["model.lateral_law='coulomb'"])
    # the grid plant's terrain engine: the [engine] section and run.output_dt_s (its macro step)
    g = S.load("straight_offset", ['model.lateral_law="shear_quasistatic"', "engine.vehicle_substeps=4",
                                   "run.output_dt_s=0.002", "terrain.cell_m=0.25"])
    assert CL.grid_integrator(g).engine.vehicle_substeps == 4 and g.run.output_dt_s == 0.002
    assert g.to_dict()["engine"]["vehicle_substeps"] == 4
    assert CL.grid_integrator(S.load("straight_offset")).engine is None
    # the plant and the prediction take the scenario's model: a model built otherwise is an error
    with pytest.raises(ScenarioError, match=r"\[model\]"):
        CL.run(sc, model=SystemModel(), max_steps=1)


def test_shear_law_closed_loop_into_the_u_turn_on_clay():
    # the headland U-turn on the clay with the shear law, shortened to 3 m of straight: the turn
    # enters the horizon at once (where the unregularised prediction hit max_iter on every solve)
    sc = S.load("headland_uturn", [f"soil.preset='{CLAY}'", 'model.lateral_law="shear_quasistatic"',
                                   "path.segments=[{straight_m=3.0}, {arc_radius_m=4.0, angle_deg=180.0}]"])
    model = SystemModel(sc.model)
    res = CL.run(sc, model=model, max_steps=25)
    s = res.summary
    assert s["initial_solve_success"]
    assert s["failed_solves"] == 0 and s["fallback_solves"] == 0
    assert res.solve_ok.all() and res.solve_iter.max() < sc.mpc.max_iter
    # 1.5 s into the arc of radius 4 m (yaw rate about 0.3 rad/s), on the path within centimetres
    assert res.ref[-1, 4] == pytest.approx(0.25)
    assert np.max(np.abs(res.e_lat)) < 0.05
    yr = res.X[-1, res.state_names.index("yaw_rate_rad_s")]
    assert yr > 0.2
