"""An elevation raster under the 3D vehicle on homogeneous soil (``[terrain.surface] elevation_file`` with
``model.vehicle = "3d"``; docs/vehicle3d.md "An elevation raster"), against independent truth: rasters
sampled from analytic surfaces at their pixel centres. A plane is reproduced exactly by the bilinear
interpolation, so the run on its raster is the analytic run's to round-off; on furrows the heights err
by at most e = h^2 a k^2 / 8 (the bilinear interpolation's bound, h^2 / 8 times the largest second
derivative a k^2 of z0 = a cos(k s)), so the hull at rest sits within e of its analytic height and
tilts within 2 e over its segments' span in pitch and 2 e / B in roll. Refusals: a raster without its
place, a start whose footprint is not on it, NaN; a run that leaves it stops with the run kept."""

from __future__ import annotations

import math

import numpy as np
import pytest

import symtrack
from symtrack.foundations.errors import ScenarioError, SimulationError
from symtrack.model import SystemModel
from symtrack.model.options import ModelOptions
from symtrack.model.static import static_state
from symtrack.simulation.scenario import load_scenario, scenario_from_dict
from symtrack.terrain.surface import parse_surface
from symtrack.vehicles.vehicle3d import footprint_radius_m, make_vehicle


def _raster(tmp_path, surface: dict, pixel_m: float, origin, size_m, name="dem.npy") -> dict:
    """``surface`` sampled at the pixel centres of a raster of ``size_m`` from ``origin``; its table."""
    nx, ny = (int(round(s / pixel_m)) for s in size_m)
    xc = origin[0] + (np.arange(nx) + 0.5) * pixel_m
    yc = origin[1] + (np.arange(ny) + 0.5) * pixel_m
    path = tmp_path / name
    np.save(path, parse_surface(surface).elevation(xc[:, None], yc[None, :]))
    return {"elevation_file": str(path), "elevation_cell_m": pixel_m, "elevation_origin_m": list(origin)}


def _doc(surface: dict, integrator="cvodes", duration_s=3.0, yaw_deg=0.0) -> dict:
    return {"name": "raster_3d", "run": {"duration_s": duration_s, "output_dt_s": 0.05, "integrator": integrator},
            "model": {"vehicle": "3d", "lateral_law": "creep"}, "vehicle": {"preset": "reference_crawler"},
            "soil": {"preset": "clayey_soil_thailand_38"}, "start": {"yaw_deg": yaw_deg},
            "terrain": {"surface": surface},
            "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0}]}


PLANE = {"slope_x_deg": 5.0, "slope_y_deg": 3.0}
COLUMNS = ("x_m", "y_m", "z_m", "pitch_rad", "roll_rad", "normal_load_right_N", "sinkage_sprocket_left_m")


def _columns(sc) -> np.ndarray:
    run = symtrack.simulate(sc).runs[0]
    return np.column_stack([run.column(n) for n in COLUMNS])


def test_a_plane_s_raster_runs_as_the_analytic_plane(tmp_path):
    """The bilinear interpolation of a plane is the plane: 3 s climbing across a 5 deg / 3 deg plane on
    its 0.5 m raster equals the analytic run (CVODES, both Jacobians exact) to the integrator's own
    error: the two differ by rounding, which CVODES's step choices amplify where the soil's shear
    switches between loading and unloading (docs/model.md, "Track kinematics and shear displacement"; the climb's
    sprocket-shear oscillation reverses the slip some 20 times): measured 3.6e-7 of each column's scale
    (the sprocket sinkage; 5e-8 before the unloading rate's bound, SHEAR_UNLOADING_TIME_MIN_S, 2e-12
    without the elastic unloading, where the tolerance was 1e-9), 4.5e-9 of its scale in x."""
    ras = _raster(tmp_path, PLANE, 0.5, (-5.0, -6.0), (30.0, 12.0))
    a, b = _columns(scenario_from_dict(_doc(PLANE))), _columns(scenario_from_dict(_doc(ras)))
    assert a[-1, 0] > 2.0  # it climbed
    scale = np.maximum(np.abs(a).max(axis=0), 1e-3)
    assert np.max(np.abs(a - b) / scale) < 1e-6, np.max(np.abs(a - b) / scale, axis=0)


def test_furrows_on_a_raster_hold_the_hull_within_the_interpolation_bound(tmp_path):
    """Furrows 0.1 m deep every 9.6 m across x on a 4 deg / 3 deg plane, rastered at 0.1 m: the hull at
    rest at four poses sits within 2 e (e = h^2 a k^2 / 8 = 2.7e-5 m) of its analytic height, pitches
    within 2 e / (l - l/n) and rolls within 2 e / B (measured 3.0e-5 m, 5.4e-6 and 1.2e-5 rad against
    5.4e-5 m, 2.5e-5 and 3.6e-5 rad)."""
    surf = {"slope_x_deg": 4.0, "slope_y_deg": 3.0, "furrow_spacing_m": 9.6, "furrow_depth_m": 0.1,
            "furrow_heading_deg": 90.0}
    h = 0.1
    ras = parse_surface(_raster(tmp_path, surf, h, (-4.0, -4.0), (8.0, 8.0)))
    params = load_scenario("validation").params
    opts = ModelOptions(lateral_law="creep", vehicle="3d")
    poses = [(0.0, 0.0, 0.0), (1.3, 0.4, 0.5), (-0.9, -0.7, 1.2), (0.6, 1.1, -0.8)]

    def settle(surface):
        m = SystemModel(opts, vehicle=make_vehicle(opts, surface))
        idx = m.layout.indices(("z_m", "pitch_rad", "roll_rad"))
        return np.array([static_state(m, params, *pose)[idx] for pose in poses])

    d = np.abs(settle(ras) - settle(parse_surface(surf))).max(axis=0)
    e = h**2 * 0.05 * (2 * math.pi / 9.6) ** 2 / 8
    l, n, B = params["contact_length_m"], opts.contact_segments, params["track_gauge_m"]
    # the tilts: the ends' heights err by e each way over the segments' span (the track width); the height:
    # the contact's weighted mean shift (at most e) plus the tilt's error times the lever from the load's
    # centre to the CG's vertical (the slopes put it h tan t off: 1.1 e here), 2 e allowed
    assert d[0] <= 2 * e and d[1] <= 2 * e / (l - l / n) and d[2] <= 2 * e / B, (d, e)


def test_refusals_and_leaving_the_raster(tmp_path):
    ras = _raster(tmp_path, PLANE, 0.5, (-5.0, -6.0), (30.0, 12.0))
    # a .npy without its place: there is no field to put it at
    no_origin = {k: v for k, v in ras.items() if k != "elevation_origin_m"}
    with pytest.raises(ScenarioError, match="elevation_origin_m is needed"):
        scenario_from_dict(_doc(no_origin))
    # the start's footprint must lie on the raster's pixel centres
    doc = _doc(ras)
    doc["start"] = {"x_m": 23.5, "y_m": 0.0}
    r = footprint_radius_m(load_scenario("validation").params)
    with pytest.raises(ScenarioError, match=r"start \(x, y\) = \(23.5, 0\) m must lie in x in \[-2.60"):
        scenario_from_dict(doc)
    assert 25.0 - 0.25 - r < 23.5  # (the reason: within the footprint of the raster's last pixel centre)
    # NaN stays refused (the raster is read by the scenario)
    bad = np.load(ras["elevation_file"])
    bad[3, 4] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(ScenarioError, match="NaN"):
        scenario_from_dict(_doc({**ras, "elevation_file": str(tmp_path / "nan.npy")}))
    # the MPC does not take a raster yet
    from symtrack.control import scenario as mpc_scenario
    from symtrack.foundations.config import read_document

    d, default = read_document("straight_offset", mpc_scenario.SCENARIO_PACKAGE, "MPC scenario", ["model.vehicle=3d"])
    d["terrain"] = {"surface": ras}
    with pytest.raises(ScenarioError, match="not the MPC's"):
        mpc_scenario.scenario_from_dict(d, default)
    # a run that drives off the raster (heading -x from x = 0: 2.8 m to its usable edge) stops, the run kept
    doc = _doc(ras, duration_s=6.0, yaw_deg=180.0)
    with pytest.raises(SimulationError, match="left terrain.surface.elevation_file") as err:
        symtrack.simulate(scenario_from_dict(doc))
    partial = err.value.partial if hasattr(err.value, "partial") else None
    if partial is not None:
        assert partial.column("x_m")[-1] >= -5.0 + 0.25 + r


@pytest.mark.slow
def test_the_compiled_rosenbrock_takes_the_raster(tmp_path):
    """The scenario's default integrator, the compiled Rosenbrock (the raster's B-spline in the generated
    C): the plane's raster against the analytic plane on the same integrator at 5 ms (measured 2.3e-9 of
    the columns' ranges; at 10 ms 2.5e-6 and at 2.5 ms 1.3e-10: the Rosenbrock's stages use the Jacobian,
    whose second derivatives of the ground differ at the B-spline's knots, and the difference goes with
    the step; 1e-7 allowed)."""
    ras = _raster(tmp_path, PLANE, 0.5, (-5.0, -6.0), (30.0, 12.0))
    da, db = _doc(PLANE, integrator="rosenbrock"), _doc(ras, integrator="rosenbrock")
    da["run"]["fixed_step_s"] = db["run"]["fixed_step_s"] = 0.005
    a, b = _columns(scenario_from_dict(da)), _columns(scenario_from_dict(db))
    scale = np.maximum(np.abs(a).max(axis=0), 1e-3)
    assert np.max(np.abs(a - b) / scale) < 1e-7, np.max(np.abs(a - b) / scale, axis=0)


def _call_nodes(f) -> int:
    """The call nodes of an SX Function (here: to the surface mapped over the contact's points)."""
    import casadi as ca

    return sum(f.instruction_id(k) == ca.OP_CALL for k in range(f.n_instructions()))


def test_the_raster_is_evaluated_through_few_call_nodes(tmp_path):
    """The contact's points go through one call of the surface mapped over them (Vehicle3D.grounds), so
    the call nodes to the raster do not grow with the points: the DAE holds two (the heights and
    gradients, and their rates) with 8 segments a track as with 16, its Jacobian (the generated
    jac_<m>_dae) one per call node and sweep (at most one sweep per input), the unrolled Rosenbrock
    step (the generated C's) two per stage and two per sweep of its Jacobian. A call per point and per
    derivative made 96, 5,376 and 3,936 with 8 segments (the Jacobian's C 6.6 MB, 20 s of gcc's CPU at
    -O0); measured now 2, 58 and 74 (16 segments: 2, 90, 106; in forward mode, before
    SystemModel.reverse_jacobians, 2, 112 and 82)."""
    import casadi as ca

    from symtrack.native import rosenbrock

    surface = parse_surface(_raster(tmp_path, PLANE, 0.5, (-5.0, -6.0), (30.0, 12.0)))
    outputs = []
    for n in (8, 16):
        opts = ModelOptions(lateral_law="creep", vehicle="3d", contact_segments=n)
        m = SystemModel(opts, vehicle=make_vehicle(opts, surface))
        ny, n_in = m.nx + m.z.numel(), m.nx + m.z.numel() + m.u.numel() + m.p.numel()
        x0, z0 = ca.SX.sym("x0", m.nx), ca.SX.sym("z0", m.z.numel())
        u, p, h = ca.SX.sym("u", m.u.numel()), ca.SX.sym("p", m.p.numel()), ca.SX.sym("h")
        step = ca.Function("step", [x0, z0, u, p, h],
                           list(rosenbrock.step_and_error_expressions(m.dae, x0, z0, u, p, h, m.reverse_jacobians)))
        dae, jac, stepped = _call_nodes(m.dae), _call_nodes(m.dae.jacobian()), _call_nodes(step)
        assert dae == 2 and jac <= dae * n_in and stepped <= dae * (rosenbrock.N_STAGES + ny), (n, dae, jac, stepped)
        outputs.append(_call_nodes(m.outputs))
    assert outputs[0] == outputs[1] <= 5, outputs  # the outputs: also the tracks' ends and the CG's ground
