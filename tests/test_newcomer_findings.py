"""What a newcomer met, each answered where it happens (issue 41): a slope on the planar vehicle names
model.vehicle, a missing --terrain-in names the option typed, trim points, linearizations, builds and
terrains print what they are, the validation table says when a run is not the case as published, and
the MPC code generation says what it waits for."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import pytest

import symtrack
from symtrack.cli.main import main
from symtrack.foundations.errors import ScenarioError


def test_a_slope_on_the_planar_vehicle_names_the_3d_vehicle(tmp_path, capsys):
    with pytest.raises(ScenarioError, match=r"terrain.surface: .* needs model.vehicle = '3d'") as err:
        symtrack.load_scenario("validation", ["terrain.surface.slope_y_deg=5"])
    assert "fixed_step_s" not in str(err.value) and "\n" not in str(err.value)
    assert main(["simulate", "validation", "--set", "terrain.surface.slope_y_deg=5", "--out", str(tmp_path / "o")]) == 2
    assert "model.vehicle=3d" in capsys.readouterr().err
    sc = symtrack.load_scenario("validation", ["terrain.surface.slope_y_deg=5", "model.vehicle=3d"])
    assert sc.surface.slope_y_deg == 5.0  # as the message says: the 3D vehicle takes it


def test_a_missing_terrain_in_names_the_option(tmp_path, capsys):
    for cmd in (["simulate", "validation_grid"], ["mpc", "straight_offset"]):
        assert main([*cmd, "--terrain-in", "nothere.npz", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert "--terrain-in 'nothere.npz' does not exist" in err and "initial_state" not in err, err
    assert not (tmp_path / "o").exists()


def test_trim_linearization_built_and_terrain_print_what_they_are(model, params):
    from symtrack.control import linearization as L
    from symtrack.control.trim import trim

    tp = trim(model, params, 2.0, 20.0)
    r = repr(tp)
    assert r.startswith("TrimPoint: a turn of radius 20 m at 2 m/s") and "torque_cmd_left_N_m = " in r
    assert "yaw_rate_rad_s = 0.1" in r and "array(" not in r
    lin = L.linearize(model, tp)
    r = repr(lin)
    assert r.startswith("Linearization at a turn of radius 20 m") and "outputs: " in r and "array(" not in r
    assert "slowest eigenvalues" in r
    built = symtrack.build("validation")
    assert built.params["mass_kg"] == built.scenario.params["mass_kg"]
    assert "validation" in repr(built) and ".params" in repr(built)
    # a terrain's history (tests/test_newcomer.py runs one): "not saved yet" after a run, not "0 run(s)"


def test_the_validation_table_grades_only_the_published_case():
    from symtrack.reports.run_files import validation_table

    summary = {"distance_after_idle_m": 20.0, "lateral_deviation_m": 0.07, "yaw_final_deg": 0.4,
               "sinkage_sprocket_mm": 3.9, "sinkage_idler_mm": 2.8, "shear_driven_max_m": 0.004,
               "shear_idle_min_m": -0.001, "nose_up": True}
    published = validation_table(symtrack.load_scenario("validation"), summary)
    assert published.startswith("| quantity |") and "| NO |" in published
    other = validation_table(symtrack.load_scenario("validation", ["soil.preset=sandy_loam_15",
                                                                    "run.integrator=cvodes"]), summary)
    first = other.splitlines()[0]
    assert first.startswith("Not the validation case as published: soil.preset = 'sandy_loam_15' (published: "
                            "'clayey_soil_thailand_38')") and "integrator" not in first
    assert "NO" not in other and "| no |" in other  # compared, not graded
    assert validation_table(symtrack.load_scenario("validation_grid"), summary).startswith("| quantity |")
    assert validation_table(symtrack.load_scenario("multipass"), summary) is None


def test_codegen_mpc_says_what_it_waits_for(monkeypatch, tmp_path, caplog):
    from symtrack.codegen import mpc as M

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop

    monkeypatch.setattr(M, "require_compiler", lambda what: "cc")
    monkeypatch.setattr(M, "setup", stop)
    args = SimpleNamespace(name="straight_offset", out=str(tmp_path / "c"), set=[], solver=None, no_run=True,
                           compare=False)
    with caplog.at_level(logging.INFO, logger="symtrack.codegen.mpc"), pytest.raises(Stop):
        M.command(args)
    assert "generating the C code of straight_offset's MPC" in caplog.text
    caplog.clear()
    pb = SimpleNamespace(cold_time_s=0.1, cold_status="ok")
    monkeypatch.setattr(M, "setup", lambda sc: pb)
    monkeypatch.setattr(M, "render", lambda pb: {})
    monkeypatch.setattr(M, "write", lambda out, files: None)
    monkeypatch.setattr(M, "build_program", stop)
    with caplog.at_level(logging.INFO, logger="symtrack.codegen.mpc"), pytest.raises(Stop):
        M.command(args)
    assert "compiling " in caplog.text and "mpc_closed_loop" in caplog.text


def test_the_bench_says_what_it_measures(monkeypatch, caplog):
    from symtrack.bench import homogeneous as H

    monkeypatch.setattr(H, "homogeneous_rows", lambda quick, repeats: [{"case": "x"}])
    monkeypatch.setattr(H, "PROVIDERS", ("symtrack.bench.no_such_provider",))
    with caplog.at_level(logging.INFO, logger="symtrack.bench"):
        assert H.collect(quick=True, repeats=1) == [{"case": "x"}]
    assert "measuring the homogeneous terrain's integrators" in caplog.text
    assert "measuring the rows of symtrack.bench.no_such_provider ... (1 row(s) so far" in caplog.text
