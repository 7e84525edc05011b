"""Seasons of wheeled machines as footprints (symtrack/studies/traffic_seasons.py): the raster of one
straight pass and of one arc against their closed forms, a season's trafficked share and passes
against an independent polygon test of the plan's sampled path, the refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from symtrack.foundations.errors import ScenarioError
from symtrack.studies import operations as op
from symtrack.studies import traffic_seasons as ts

TWO = {"working_width_m": 4.0, "turn_radius_m": 3.0,
       "wheels": [{"lateral_m": 0.9, "width_m": 0.6}, {"lateral_m": -0.9, "width_m": 0.6},
                  {"lateral_m": 1.0, "width_m": 0.4}, {"lateral_m": -1.6, "width_m": 0.5}]}
WIDE = {"working_width_m": 12.0, "turn_radius_m": 4.0,
        "wheels": [{"lateral_m": 0.8, "width_m": 0.45}, {"lateral_m": -0.8, "width_m": 0.45}]}


def test_one_straight_pass_is_its_wheel_widths_times_its_length():
    m = ts.machine_from_dict({"working_width_m": 3.0, "wheels": [{"lateral_m": 0.9, "width_m": 0.6},
                                                                 {"lateral_m": -1.0, "width_m": 0.5}]})
    shape, cell = (600, 300), 0.1  # 60 m x 30 m
    for psi_deg in (0.0, 30.0, 90.0):
        psi = math.radians(psi_deg)
        L = 25.0
        geo = [("straight", 20.0, 5.0, psi, L)]
        c = ts.segment_counts(geo, m, shape, cell)
        share = (c > 0).mean()
        exact = (0.6 + 0.5) * L / (60.0 * 30.0)
        assert abs(share / exact - 1) < 0.01, (psi_deg, share, exact)
        assert c.max() == 1


def test_one_arc_is_its_annular_sectors():
    m = ts.machine_from_dict({"working_width_m": 3.0, "wheels": [{"lateral_m": 1.0, "width_m": 0.5},
                                                                 {"lateral_m": -1.0, "width_m": 0.5}]})
    for R, sweep in ((5.0, 90.0), (-5.0, 250.0)):
        geo = [("arc", 30.0, 20.0, 0.3, (R, math.radians(sweep)))]
        c = ts.segment_counts(geo, m, (600, 400), 0.1)
        exact = math.radians(sweep) * 0.5 * (4.0 + 6.0)  # sum of sweep x radius x width
        assert abs((c > 0).sum() * 0.01 / exact - 1) < 0.01, (R, sweep)


def _polygons(plan, machine):
    """Per segment, the wheels' strips as polygons from the plan's sampled path (control.path: its own
    integration of the segments, every 5 cm), left edge forward and right edge back."""
    p = plan.path
    out = []
    for i in range(len(p.segments)):
        k = np.nonzero(p.segment == i)[0]
        k = np.append(k, k[-1] + 1)
        x, y, psi = p.x[k], p.y[k], p.psi[k]
        nx_, ny_ = -np.sin(psi), np.cos(psi)
        polys = []
        for w in machine.wheels:
            lo, hi = w.lateral_m - 0.5 * w.width_m, w.lateral_m + 0.5 * w.width_m
            left = np.column_stack([x + hi * nx_, y + hi * ny_])
            right = np.column_stack([x + lo * nx_, y + lo * ny_])[::-1]
            polys.append(MplPath(np.vstack([left, right, left[:1]]), closed=True))
        out.append(polys)
    return out


def test_season_share_equals_an_independent_polygon_test():
    machines = {"two": TWO, "wide": WIDE}
    ops = [{"name": "a", "machine": "two", "seed": 3, "random_offset_m": 0.5},
           {"name": "b", "machine": "wide", "seed": 4},
           {"name": "across", "machine": "two", "seed": 5, "direction": "y"},
           {"name": "c", "machine": "wide", "same_lines_as": "tram", "repeat": 2}]
    season = ts.build_season(ops, size_m=(70.0, 50.0), cell_m=0.1, machines=machines)
    counts = ts.season_counts(season)
    sh = ts.season_shares(counts, 0.1, border_m=0.0)
    shape = counts.shape
    xc, yc = np.meshgrid((np.arange(shape[0]) + 0.5) * 0.1, (np.arange(shape[1]) + 0.5) * 0.1, indexing="ij")
    pts = np.column_stack([xc.ravel(), yc.ravel()])
    hit = np.zeros(pts.shape[0], dtype=bool)
    passes = np.zeros(pts.shape[0], dtype=np.int64)
    for s in season:
        xy = pts[:, ::-1] if s.direction == "y" else pts  # a turned plan's x is the field's y
        for polys in _polygons(op.plan_operation(s.settings), s.machine):
            seg_hit = np.zeros(pts.shape[0], dtype=bool)
            for poly in polys:
                ext = poly.get_extents()
                sel = np.nonzero((xy[:, 0] >= ext.x0) & (xy[:, 0] <= ext.x1)
                                 & (xy[:, 1] >= ext.y0) & (xy[:, 1] <= ext.y1))[0]
                seg_hit[sel] |= poly.contains_points(xy[sel])
            hit |= seg_hit
            passes += s.repeat * seg_hit
    assert abs(sh["trafficked_fraction"] / hit.mean() - 1) < 0.01, (sh["trafficked_fraction"], hit.mean())
    assert abs(sh["passes_area_fraction"] / passes.mean() - 1) < 0.01
    assert 0.2 < hit.mean() < 0.9  # a season that overlaps itself, not a trivial one


def test_a_repeated_operation_adds_passes_not_area():
    machines = {"wide": WIDE}
    one = ts.season_counts(ts.build_season([{"machine": "wide"}], size_m=(60.0, 40.0), machines=machines))
    three = ts.season_counts(ts.build_season([{"machine": "wide", "repeat": 3}], size_m=(60.0, 40.0),
                                             machines=machines))
    assert np.array_equal(three, 3 * one)
    a, b = ts.season_shares(one, 0.1), ts.season_shares(three, 0.1)
    assert a["trafficked_fraction"] == b["trafficked_fraction"]
    assert b["repeated_excess_fraction"] == pytest.approx(a["repeated_excess_fraction"] + 2 * a["trafficked_fraction"])


def test_an_operation_across_is_the_one_along_turned():
    machines = {"two": TWO}
    a = ts.season_counts(ts.build_season([{"machine": "two", "seed": 2}], size_m=(50.0, 50.0), machines=machines))
    b = ts.season_counts(ts.build_season([{"machine": "two", "seed": 2, "direction": "y"}], size_m=(50.0, 50.0),
                                         machines=machines))
    assert np.array_equal(b, a.T) and not np.array_equal(a, b)
    with pytest.raises(ScenarioError, match=r"season\[0\]\.direction = 'z' is not one of x, y"):
        ts.build_season([{"machine": "two", "direction": "z"}], machines=machines)


def test_bad_machines_and_seasons_are_refused_naming_key_and_range():
    bad_wheel = {"working_width_m": 3.0, "wheels": [{"lateral_m": 1.6, "width_m": 0.5}]}
    with pytest.raises(ScenarioError, match=r"m\.wheels\[0\]\.lateral_m = 1\.6 is outside the allowed range "
                                            r"\[-1\.25, 1\.25\]"):
        ts.machine_from_dict(bad_wheel, where="m")
    with pytest.raises(ScenarioError, match=r"m\.wheels\[0\]\.width_m = 4"):
        ts.machine_from_dict({"working_width_m": 3.0, "wheels": [{"lateral_m": 0.0, "width_m": 4.0}]}, where="m")
    with pytest.raises(ScenarioError, match=r"m\.turn_radius_m = 1 is outside the allowed range \[1\.2"):
        ts.machine_from_dict({"working_width_m": 3.0, "turn_radius_m": 1.0,
                              "wheels": [{"lateral_m": 1.0, "width_m": 0.4}]}, where="m")
    huge = {"huge": {"working_width_m": 50.0, "wheels": [{"lateral_m": 1.0, "width_m": 0.5}]}}
    with pytest.raises(ScenarioError, match=r"machines\.huge\.working_width_m = 50 is outside the allowed range "
                                            r"\(0, 40\] m"):
        ts.build_season([{"machine": "huge"}], size_m=(60.0, 40.0), machines=huge)
    with pytest.raises(ScenarioError, match=r"season\[0\]\.machine = 'nope' is not one of"):
        ts.build_season([{"machine": "nope"}], machines={"two": TWO})
    with pytest.raises(ScenarioError, match=r"season\[0\]\.repeat = 0 must be an integer in \[1, 100\]"):
        ts.build_season([{"machine": "two", "repeat": 0}], machines={"two": TWO})


def test_the_built_in_machines_and_seasons_are_valid():
    for name, t in ts.MACHINES.items():
        ts.machine_from_dict(t, where=name)
    for k, v in ts.SEASONS.items():
        assert ts.build_season(v, where=k)


def test_the_example_prints_the_table_and_draws_the_figure(tmp_path, capsys):
    import runpy

    ns = runpy.run_path("examples/kroulik_seasons.py")
    png = tmp_path / "k.png"
    rows = ns["main"](["--size", "120", "100", "--cell", "0.2", "--plot", str(png)])
    assert png.stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "| conventional tillage |" in out and "95.3 %" in out
    shares = {r["system"]: r["trafficked_fraction"] for r in rows}
    # more tillage, more traffic: the order of Kroulik's three systems
    assert shares["conventional"] > shares["minimum"] > shares["direct"]
