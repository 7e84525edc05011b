"""The run folder's figures of the 3D vehicle (symtrack/reports/vehicle3d_plots.py; docs/vehicle3d.md
"The run folder"): a 3D run on a side slope writes attitude.png, load_split.png and path_elevation.png
and report.html shows them; a 3D run on flat ground has no elevation map; a planar run none of the
three; the load split's plotted data are the run's output columns of trajectory.csv."""

from __future__ import annotations

import re

import numpy as np
import pytest

from symtrack.cli import main
from symtrack.reports import vehicle3d_plots

FILES_3D = ("attitude.png", "load_split.png", "path_elevation.png")


def _scenario(path, vehicle="3d", surface="slope_y_deg = 8.0"):
    text = f"""name = "report_3d"
[run]
duration_s = 1.0
output_dt_s = 0.05
[model]
vehicle = "{vehicle}"
lateral_law = "creep"
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[[torque]]
t_s = 0.0
left_N_m = 2000.0
right_N_m = 2000.0
"""
    if surface:
        text += f"[terrain.surface]\n{surface}\n"
    path.write_text(text)
    return str(path)


def _shown(out):
    return re.findall(r"<figcaption>([^<]+)</figcaption>", (out / "report.html").read_text())


def _trajectory(out) -> dict:
    data = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    return {n: data[n] for n in data.dtype.names}


def test_a_3d_run_writes_its_figures_and_a_planar_run_does_not(tmp_path, monkeypatch):
    drawn = []  # the load split's figure, captured before it becomes PNG bytes
    real = vehicle3d_plots.png_bytes

    def capture(fig, tight=True):
        if fig.axes and fig.axes[0].get_title().startswith("each track's normal load"):
            drawn.append([[(ln.get_label(), ln.get_xdata(), ln.get_ydata()) for ln in ax.get_lines()]
                          for ax in fig.axes])
        return real(fig, tight)

    monkeypatch.setattr(vehicle3d_plots, "png_bytes", capture)
    out = tmp_path / "slope"
    assert main(["simulate", _scenario(tmp_path / "slope.toml"), "--out", str(out), "--quiet"]) == 0
    for name in FILES_3D:
        assert (out / name).stat().st_size > 1000, name
        assert name in _shown(out), name
    # the plotted load split is the output columns (the written trajectory.csv's)
    cols = _trajectory(out)
    assert len(drawn) == 1
    loads, shares = drawn[0]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(cols["x_m"]), np.diff(cols["y_m"])))])
    (l_lab, l_x, l_y), (r_lab, _, r_y) = loads
    assert l_lab == "left track" and r_lab == "right track"
    np.testing.assert_allclose(l_x, s, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(l_y, cols["normal_load_left_N"] / 1e3, rtol=1e-8)
    np.testing.assert_allclose(r_y, cols["normal_load_right_N"] / 1e3, rtol=1e-8)
    (lo_lab, _, lo_y), (up_lab, _, up_y) = shares[:2]
    total = cols["normal_load_left_N"] + cols["normal_load_right_N"]
    # the ground rises toward +y and the vehicle heads +x: the right track is the lower one
    assert lo_lab == "lower (right) track" and up_lab == "upper (left) track"
    np.testing.assert_allclose(lo_y, 100 * cols["normal_load_right_N"] / total, rtol=1e-8)
    np.testing.assert_allclose(up_y, 100 * cols["normal_load_left_N"] / total, rtol=1e-8)
    assert np.mean(lo_y[-5:]) > 55.0  # cos t / 2 + h sin t / B = 55.6 % at 8 deg (docs/vehicle3d.md)

    flat = tmp_path / "flat"
    assert main(["simulate", _scenario(tmp_path / "flat.toml", surface=""), "--out", str(flat), "--quiet"]) == 0
    assert (flat / "attitude.png").is_file() and (flat / "load_split.png").is_file()
    assert not (flat / "path_elevation.png").exists()  # flat ground: no elevation map

    planar = tmp_path / "planar"
    assert main(["simulate", _scenario(tmp_path / "planar.toml", vehicle="planar", surface=""), "--out", str(planar),
                 "--quiet"]) == 0
    assert (planar / "path.png").is_file()
    for name in FILES_3D:
        assert not (planar / name).exists(), name
        assert name not in _shown(planar)


def test_a_standing_vehicle_is_drawn_against_time():
    """A run that travels less than 5 cm (a vehicle parked on a slope) has time as its abscissa."""
    import types

    t = np.linspace(0.0, 2.0, 41)
    cols = {"x_m": 1e-3 * t, "y_m": 0 * t}
    res = types.SimpleNamespace(t=t, column=cols.__getitem__)
    s, label = vehicle3d_plots.abscissa(res)
    assert label.startswith("t [s]") and np.array_equal(s, t)
    cols["x_m"] = 3.0 * t
    s, label = vehicle3d_plots.abscissa(res)
    assert label == "distance travelled [m]" and s[-1] == pytest.approx(6.0)


@pytest.mark.slow
def test_a_3d_terrain_study_writes_them_per_pass(tmp_path):
    """On the grid (the terrain engine; slow: its 3D variant's first compile) each pass's folder has the
    hull's figures with its trajectory plots; the field's elevation map is the terrain figure surface.png
    (none here: a flat field), not path_elevation.png."""
    out = tmp_path / "mp"
    assert main(["simulate", "multipass", "--out", str(out), "--quiet", "--set", "model.vehicle=3d", "--set",
                 "terrain.passes=2", "--set", "terrain.size_m=[20.0, 8.0]", "--set",
                 "run.stop_after_distance_m=2"]) == 0
    for name in ("attitude.png", "load_split.png"):
        assert (out / "pass_2" / name).stat().st_size > 1000
        assert f"pass_2/{name}" in _shown(out)
    assert not list(out.rglob("path_elevation.png"))
