"""The MPC on the 3D vehicle (issue 22: ``model.vehicle = "3d"``; docs/vehicle3d.md, "The MPC on the
3D vehicle"): the scenario's ground, refusals, finite derivatives of the NLP, the closed loop."""

import math

import casadi as ca
import numpy as np
import pytest

from symtrack.control import closedloop as CL
from symtrack.control import scenario as S
from symtrack.control.mpc import PathTrackingMPC
from symtrack.foundations.config import read_document
from symtrack.foundations.errors import ScenarioError
from symtrack.simulation.builder import system_model


def _doc(overrides=(), surface=None):
    d, default = read_document("straight_offset", S.SCENARIO_PACKAGE, "MPC scenario",
                               ["model.vehicle=3d", *overrides])
    if surface is not None:
        d["terrain"] = {"surface": surface}
    return d, default


def test_an_mpc_scenario_gives_the_3d_vehicle_its_ground():
    d, default = _doc(surface={"slope_y_deg": 8.0})
    sc = S.scenario_from_dict(d, default)
    assert sc.terrain is None and sc.plant == "homogeneous"
    assert sc.surface.slope_y_deg == 8.0
    again = S.scenario_from_dict(sc.resolved_dict())  # scenario.resolved.toml reads back the same ground
    assert again.surface.to_dict() == sc.surface.to_dict() and again.model == sc.model


def test_the_3d_vehicle_on_the_grid_plant_is_refused_at_load():
    with pytest.raises(ScenarioError, match=r"model.vehicle = '3d' runs on the homogeneous .*--plant grid"):
        S.load("straight_offset", ["model.vehicle=3d"], plant="grid")
    # furrows finer than the segments resolve: the key and the allowed range
    d, default = _doc(surface={"furrow_spacing_m": 0.5, "furrow_depth_m": 0.05})
    with pytest.raises(ScenarioError, match=r"model.contact_segments = 8 .* allowed range is \[20, 64\]"):
        S.scenario_from_dict(d, default)
    # --plant homogeneous keeps the 3D vehicle's ground (it drops a grid [terrain] only)
    d, _ = _doc(surface={"slope_y_deg": 5.0})
    assert S.scenario_from_dict(d).surface.slope_y_deg == 5.0


@pytest.mark.slow
def test_no_nan_in_the_mpc_s_derivatives_for_the_3d_vehicle():
    """At the MPC's initial guess on a side slope, and with the hull lifted 1 cm off the ground (an
    iterate where a track has no contact: where Bekker's compaction work had NaN derivatives,
    COMPACTION_DEPTH_FLOOR_M), the stage's constraint Jacobians in (x, u, K) and in the model's
    parameters and the Hessian of the constraints' sum are finite. Creep law (a fast build)."""
    d, default = _doc(["model.lateral_law=creep", "start.y_m=0.0"], surface={"slope_y_deg": 8.0})
    sc = S.scenario_from_dict(d, default)
    model = system_model(sc.model, sc.surface)
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    xt, ut = CL.initial_state(model, sc)
    path = sc.build_path()
    ref = path.reference(path.project(xt[0], xt[1]), mpc.N, sc.mpc.sample_time_s, xt[2])
    w0 = mpc._initial_guess(mpc._x0s(xt[:mpc.nxp], ut), ref)
    nxa, nu, blk = mpc.nxa, mpc.nu, mpc.block
    Xs, Us, Ks = (ca.SX.sym(n, k) for n, k in (("x", nxa), ("u", nu), ("k", mpc.nk)))
    P = ca.SX.sym("p", len(mpc.p_model))
    g = mpc.coll_res_fn(Xs, Us, Ks, P, ca.DM())
    z = ca.vertcat(Xs, Us, Ks)
    f = ca.Function("d", [Xs, Us, Ks, P], [ca.jacobian(g, z), ca.jacobian(g, P), ca.hessian(ca.sum1(g), z)[0]])
    iz = mpc.pred_names.index("z_m")
    for lift_m in (0.0, 0.01):
        w = w0.copy()
        for j in range(mpc.d + 1):  # the stage's state and its collocation points
            w[iz + (0 if j == 0 else nxa + nu + (j - 1) * mpc.nc)] += lift_m / mpc.sx[iz]
        out = f(w[:nxa], w[nxa:nxa + nu], w[nxa + nu:blk], mpc.p_model)
        for v in out:
            assert np.all(np.isfinite(np.array(v.full()))), lift_m
    # the trim on the slope: the hull rolled by the slope, the lower (right) track the more loaded
    assert math.degrees(xt[model.state_index("roll_rad")]) == pytest.approx(8.0, abs=0.1)


@pytest.mark.slow
def test_the_3d_closed_loop_keeps_the_line_along_a_side_slope():
    """examples/mpc_side_slope_3d.py on an 8 deg side slope: the MPC holds the line within 5 cm RMS
    (measured 0.07 cm) where the open loop drifts downhill (0.16 m over 60 m), the lower track
    carries more and its sprocket drives harder than the upper one."""
    import runpy

    ns = runpy.run_path("examples/mpc_side_slope_3d.py")
    out = ns["main"](["--slope-deg", "8"])
    assert out["rms_lateral_error_m"] <= 0.05 and out["distance_m"] >= 59.0
    assert out["open_loop_drift_downhill_m"] > 0.05 > abs(out["lateral_error_last_half_mean_m"])
    assert out["normal_load_right_last_half_N"] > out["normal_load_left_last_half_N"]
    assert out["torque_right_last_half_N_m"] > out["torque_left_last_half_N_m"]
    assert out["roll_last_half_deg"] == pytest.approx(8.0, abs=0.1)
