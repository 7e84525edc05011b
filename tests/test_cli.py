"""The command line: the files it writes, and that a failed run writes nothing."""

import csv
import json

from symtrack.cli import main

REQUIRED_COLUMNS = (
    "t_s x_m y_m yaw_rad u_m_s v_m_s yaw_rate_rad_s omega_left_rad_s omega_right_rad_s shear_left_m "
    "shear_right_m torque_left_N_m torque_right_N_m tractive_left_N tractive_right_N p_sprocket_left_Pa "
    "p_idler_left_Pa p_sprocket_right_Pa p_idler_right_Pa sinkage_sprocket_left_m sinkage_idler_left_m "
    "sinkage_sprocket_right_m sinkage_idler_right_m pitch_rad"
).split()


def test_simulate_writes_summary_trajectory_scenario_and_plots(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "validation", "--out", str(out), "--set", "run.output_dt_s=0.02", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["schema_version"] == 1
    for key in ("distance_after_idle_m", "lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm",
                "sinkage_idler_mm", "shear_driven_max_m", "shear_idle_min_m", "nose_up", "sim_time_s",
                "wall_time_s", "real_time_factor"):
        assert key in summary
    with open(out / "trajectory.csv") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    for col in REQUIRED_COLUMNS:
        assert col in header, col
    assert len(rows) > 100 and len(rows[1]) == len(header)
    assert float(rows[-1][0]) == summary["sim_time_s"] or abs(float(rows[-1][0]) - summary["sim_time_s"]) < 1e-6
    assert "output_dt_s = 0.02" in (out / "scenario.resolved.toml").read_text()
    for png in ("path.png", "yaw.png", "sinkage.png", "shear.png", "speeds.png", "torques.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| lateral_deviation_m |" in capsys.readouterr().out


def test_bad_input_fails_clearly_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "bad"
    assert main(["simulate", "validation", "--out", str(out), "--set", "vehicle.mass_kg=-1"]) == 2
    err = capsys.readouterr().err
    assert "vehicle.mass_kg" in err and "-1" in err and "allowed range" in err
    assert not out.exists()


def test_a_shortened_builtin_run_ends_by_duration(tmp_path, caplog):
    out = tmp_path / "short"
    # 0.5 s is not enough to cover 20 m after the idle event at 4 s: the run ends by duration
    # (without figures: the summary and the log are what is checked)
    assert main(["simulate", "validation", "--out", str(out), "--quiet", "--set", "run.duration_s=0.5",
                 "--set", "run.integrator=rosenbrock", "--set", "run.figures=false"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "duration" and s["sim_time_s"] == 0.5 and s["distance_stop_reached"] is False
    assert "before covering run.stop_after_distance_m" in caplog.text
    # the distance stop switched off
    assert main(["simulate", "validation", "--out", str(out), "--quiet", "--set", "run.duration_s=0.3",
                 "--set", "run.stop_after_distance_m=none", "--set", "run.integrator=rosenbrock",
                 "--set", "run.figures=false"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped_by"] == "duration" and "distance_stop_reached" not in s and s["sim_time_s"] == 0.3



def test_summary_of_a_run_that_ends_before_the_last_torque_change(tmp_path):
    scenario = tmp_path / "early.toml"
    scenario.write_text("""
[run]
duration_s = 0.5
output_dt_s = 0.05
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[[torque]]
t_s = 0.0
left_N_m = 1000.0
right_N_m = 1000.0
[[torque]]
t_s = 4.0
left_N_m = 0.0
right_N_m = 1000.0
""")
    out = tmp_path / "early"
    assert main(["simulate", str(scenario), "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped_by"] == "duration" and summary["sim_time_s"] == 0.5
    assert summary["shear_idle_min_m"] is None and summary["shear_driven_max_m"] > 0
