"""What a terrain run writes by default and with ``run.all_figures = true`` (issue 26, item 2):
the default leaves out the slow figures (the pass animations, the earlier passes' sinkage maps
and trajectory plots) and report.html says so; every image report.html shows is a file of the
folder; a bad value is an error naming the key."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from symtrack.cli import main
from symtrack.foundations.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["--set", "run.stop_after_distance_m=0.3"]


def _run(out, *sets) -> str:
    assert main(["simulate", "multipass", "--out", str(out), "--quiet", *SHORT, *sets]) == 0
    return _check(out)


def _check(out) -> str:
    page = (out / "report.html").read_text()
    shown = re.findall(r"<figcaption>([^<]+)</figcaption>", page)
    assert shown and all((out / name).is_file() for name in shown)  # the report shows written files only
    return page


def test_the_default_writes_the_figures_read_first_and_the_report_says_what_it_left_out(tmp_path):
    out = tmp_path / "two"
    page = _run(out, "--set", "terrain.passes=2")
    assert not list(out.rglob("*.gif"))
    for name in ("passes.png", "sinkage_map_pass_2.png", "rut_section.png", "risk_map.png", "density_map.png",
                 "pass_2/path.png", "pass_2/torques.png", "pass_1/trajectory.csv", "pass_1/summary.json"):
        assert (out / name).is_file(), name
    assert not (out / "sinkage_map_pass_1.png").exists() and not list((out / "pass_1").glob("*.png"))
    assert "Not drawn" in page and "run.all_figures = true" in page and "passes 1 to 1" in page
    one = tmp_path / "one"
    page = _run(one, "--set", "terrain.passes=1")
    assert (one / "sinkage_map.png").is_file() and (one / "path.png").is_file() and not (one / "animation.gif").exists()
    assert "pass animations" in page and "passes 1 to" not in page


def test_all_figures_writes_the_animations_and_every_pass_plots(tmp_path):
    """In a process of its own, as a user runs it: --quiet prints no matplotlib line
    ("Animation.save using ...", issue 26's newcomer's list) while the GIFs are written."""
    out = tmp_path / "all"
    r = subprocess.run([sys.executable, "-m", "symtrack", "simulate", "multipass", "--out", str(out), "--quiet",
                        *SHORT, "--set", "terrain.passes=2", "--set", "run.all_figures=true"],
                       env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")},
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "Animation" not in r.stderr and "MovieWriter" not in r.stderr, r.stderr
    page = _check(out)
    for name in ("animation_pass_1.gif", "animation_pass_2.gif", "sinkage_map_pass_1.png", "sinkage_map_pass_2.png",
                 "pass_1/path.png", "pass_2/path.png"):
        assert (out / name).stat().st_size > 0, name
    assert "Not drawn" not in page and "animation_pass_1.gif" in page


def test_all_figures_must_be_true_or_false(tmp_path, capsys):
    assert main(["simulate", "multipass", "--out", str(tmp_path / "a"), "--quiet", "--set", "run.all_figures=1"]) == 2
    err = capsys.readouterr().err
    assert "run.all_figures = 1" in err and "true or false" in err
    assert not (tmp_path / "a").exists()
    # a field study draws no per-pass figures: the key is not one of its [run] keys
    from symtrack.studies.field import load_field_spec

    with pytest.raises(ScenarioError, match="all_figures"):
        load_field_spec("field_traffic", ["run.all_figures=true"])


def test_figures_false_writes_the_run_files_without_figures(tmp_path, capsys):
    """run.figures = false (a sweep's many runs): no image in the folder, report.html says why and how to
    draw them, the run's files as with figures; a terrain run of two passes and a homogeneous run."""
    out = tmp_path / "grid"
    assert main(["simulate", "multipass", "--out", str(out), "--quiet", *SHORT, "--set", "terrain.passes=2",
                 "--set", "run.figures=false"]) == 0
    assert not list(out.rglob("*.png")) and not list(out.rglob("*.gif"))
    for name in ("summary.json", "pass_1/scenario.resolved.toml", "pass_1/trajectory.csv", "pass_2/summary.json"):
        assert (out / name).is_file(), name
    page = (out / "report.html").read_text()
    assert "No figures drawn (run.figures = false)" in page and "<figcaption>" not in page
    assert "\nfigures = false" in (out / "pass_2" / "scenario.resolved.toml").read_text()
    homog = tmp_path / "homog"
    assert main(["simulate", "validation", "--out", str(homog), "--quiet", "--set", "run.duration_s=0.3",
                 "--set", "run.figures=false"]) == 0
    assert not list(homog.glob("*.png")) and (homog / "trajectory.csv").is_file()
    assert (homog / "validation_table.md").is_file() and (homog / "summary.json").is_file()
    # bad values and a contradiction are refused before any work
    for sets, words in ((["run.figures=0"], "run.figures = 0"),
                        (["run.figures=false", "run.all_figures=true"], "set one of them")):
        bad = tmp_path / "bad"
        args = [a for kv in sets for a in ("--set", kv)]
        assert main(["simulate", "validation", "--out", str(bad), "--quiet", *args]) == 2
        assert words in capsys.readouterr().err and not bad.exists()


def test_the_bench_row_of_the_outputs_adds_up():
    """symtrack bench's output-cost row (symtrack/bench/outputs.py) on a short pass: the command
    and the timed run ran, the parts add up to the timed run; no wall-time bound."""
    from symtrack.bench.outputs import case_row

    r = case_row("one short pass", "multipass", ["terrain.passes=1", "run.stop_after_distance_m=0.1"])
    assert r["images"] == 12 and r["command_wall_s"] > 0 and 0 < r["time_loop_s"] <= r["simulate_s"]
    parts = r["start_up_s"] + r["simulate_s"] + r["figures_s"] + r["write_s"]
    assert parts == pytest.approx(r["timed_run_wall_s"]) and r["import_s"] <= r["start_up_s"]
    assert r["outputs_over_simulate"] > 0 and "x the simulation" in r["note"]


def _fixed_layout_figures(monkeypatch) -> list:
    """The figures that fixed_layout lays out (instead of tight_layout), drawn with long tick labels
    (values like -12345.678 and 0.0012345), captured before they become PNG bytes."""
    import types

    import numpy as np

    from symtrack.reports import plots, subsoil_plots, terrain_plots, vehicle3d_plots
    from symtrack.terrain.surface import parse_surface

    figs = []

    def capture(fig, tight=True):
        assert not tight  # the figures below are laid out by fixed_layout
        figs.append(fig)
        return b""

    for mod in (plots, subsoil_plots, terrain_plots, vehicle3d_plots):
        monkeypatch.setattr(mod, "png_bytes", capture)
    t = np.linspace(0.0, 123.4, 400)
    wide = -12345.678 + 0.0012345 * np.sin(t)
    cols = {"a": wide, "b": 1e4 * np.cos(t), "x_m": 1234.5 + t, "y_m": -987.6 + 0.01 * t, "yaw_rad": 0 * t}
    ev = [types.SimpleNamespace(t_s=0.0), types.SimpleNamespace(t_s=50.0)]
    res = types.SimpleNamespace(t=t, column=cols.__getitem__, state=cols.__getitem__,
                                X=np.column_stack([cols["x_m"], cols["y_m"], cols["yaw_rad"]]),
                                scenario=types.SimpleNamespace(torque=ev))
    plots.time_plot(res, [("a", "left (actual)"), ("b", "right (actual)")], "torque [N m]", "sprocket torques")
    plots.path_plot(res)
    # the 3D vehicle's (reports/vehicle3d_plots.py): long heights, loads and angles
    cols.update({"z_m": 1234.5678 + 0.0012345 * t, "ground_z_m": 1233.9 + 0 * t, "roll_rad": 0.0012345 * t,
                 "pitch_rad": -0.0012345 * t, "normal_load_left_N": 12345678.9 + t, "normal_load_right_N": 2e4 + t})
    vehicle3d_plots.attitude_png(res)
    vehicle3d_plots.load_split_png(res)
    vehicle3d_plots.path_elevation_png(res, parse_surface({"slope_x_deg": 5.0, "furrow_depth_m": 0.1,
                                                           "furrow_spacing_m": 1.5}))
    k = 12
    figures = [{"rut_max_depth_mm": 1234.567 + i, "rut_mean_depth_mm": 0.0012345 * i, "new_sinkage_mean_mm": -0.5 * i,
                "compaction_resistance_mean_N": 12345.678 * i} for i in range(k)]
    terrain_plots.passes_png(figures)
    subsoil_plots.passes_subsoil_png(np.arange(k) * 1.2345, np.outer(np.arange(k), [123.456, 98.7, 6.5, 0.4]) + 1e3,
                                     [0.1, 0.3, 0.5, 0.8])
    subsoil_plots.density_passes_png([1.2345, 1.3, 1.4, 1.5], np.full((k, 4), 1.56789), [0.1, 0.3, 0.5, 0.8])
    subsoil_plots.stress_profile_png([0.1, 0.3, 0.5, 0.8], [1234.5, 987.6, 654.3, 321.0], 1500.0)
    grid = types.SimpleNamespace(cell_m=0.1, origin_m=(0.0, 0.0), shape=(100, 100))
    maps = [np.full((100, 100), -12.345678 * (i + 1)) for i in range(3)]
    X = np.column_stack([np.linspace(2, 8, 50), np.full(50, 5.0), np.zeros(50)])
    run = types.SimpleNamespace(X=X, pose=lambda: X)  # (the pose by name: x_m, y_m, yaw_rad)
    terrain_plots.rut_section_png(types.SimpleNamespace(grid=grid), maps, [run], None)
    return figs


def test_the_fixed_layouts_keep_every_text_on_the_canvas_and_off_the_other_axes(monkeypatch):
    """fixed_layout (reports/plots.py) replaces tight_layout in the run folder's line plots: with long
    tick labels every visible text lies on the canvas (1 px slack) and no axes' text runs into
    another axes' frame."""
    from matplotlib.text import Text

    from symtrack.reports.plots import plt

    figs = _fixed_layout_figures(monkeypatch)
    assert len(figs) == 10
    for fig in figs:
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        W, H = fig.bbox.width, fig.bbox.height
        for ax in fig.axes:
            assert any(t.get_visible() and t.get_text().strip() for t in ax.findobj(Text))
            bb = ax.get_tightbbox(r)  # what is drawn of the axes: frame, ticks, labels, title, legend
            assert bb.x0 >= -1 and bb.y0 >= -1 and bb.x1 <= W + 1 and bb.y1 <= H + 1, (ax.get_title(), bb, W, H)
            for other in fig.axes:
                if other is not ax:
                    assert not bb.overlaps(other.get_window_extent(r)), (ax.get_title(), other.get_title())
        plt.close(fig)
