"""The traffic-system comparison as a resumable sweep on Dask (issue 23; symtrack/studies/traffic.py):
a tiny season whose second system is missing (as an interruption leaves it) and is resumed gives
the table of an uninterrupted run; the refusals come before any cluster starts."""

from __future__ import annotations

import csv
import shutil

import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.studies.traffic import traffic_sweep

TINY = """name = "tiny_traffic"
[model]
lateral_law = "shear"
[vehicle]
preset = "reference_crawler"
[soil]
preset = "clayey_soil_thailand_38"
[operation]
size_m = [24.0, 20.0]
working_width_m = 4.0
headland_passes = 1
lane_spacing_m = 4.0
random_offset_m = 0.5
seed = 3
turn = "u"
turn_radius_m = 1.5
lines = 1
# the path-following law drives: the subject is the sweep's resume, not the follower, and a season
# under the MPC follower costs four times the law's CPU (22 s against 5.5 s, mostly its IPOPT fallbacks)
follower = "law"
[season]
compare = ["random", "controlled"]
"""
TIMINGS = ("wall_time_s",)


def _table(path):
    with open(path) as f:
        return [{k: v for k, v in r.items() if k not in TIMINGS} for r in csv.DictReader(f)]


def test_traffic_sweep_refused_before_anything_runs(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY.replace('compare = ["random", "controlled"]', 'compare = ["random", "tramlines"]'))
    with pytest.raises(ScenarioError, match="season.compare = .*'tramlines' is not one of ab, controlled, random"):
        traffic_sweep(str(f), tmp_path / "out", progress=False)
    f.write_text(TINY)
    with pytest.raises(ScenarioError, match="season.tracks = 'lanes' is not one of"):
        traffic_sweep(str(f), tmp_path / "out", overrides=["season.tracks=\"lanes\""], progress=False)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # three tiny seasons on local clusters (about 34 s of CPU in all its processes)
def test_a_traffic_sweep_missing_a_system_resumes_to_the_same_table(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY)
    whole = traffic_sweep(str(f), tmp_path / "whole", workers=2, progress=False)
    assert [r["tracks"] for r in whole["rows"]] == ["random", "controlled"]
    assert all(r["complete"] for r in whole["rows"])
    # the folder an interruption after the first system leaves (the sweep's Ctrl-C and kills:
    # tests/test_sweep.py): the second system's run folder missing, and no traffic table yet
    cut = tmp_path / "cut"
    shutil.copytree(tmp_path / "whole", cut)
    shutil.rmtree(cut / "runs" / whole["sweep"].rows[1]["run_id"])
    for name in ("traffic.csv", "traffic.png"):
        (cut / name).unlink()
    resumed = traffic_sweep(str(f), cut, workers=1, progress=False)
    assert resumed["sweep"].skipped == 1 and resumed["sweep"].ran == 1
    assert _table(cut / "traffic.csv") == _table(tmp_path / "whole" / "traffic.csv")
    assert (cut / "traffic.png").stat().st_size > 0
    # and a third run has nothing left to do (no cluster started)
    again = traffic_sweep(str(f), cut, workers=2, progress=False)
    assert again["sweep"].ran == 0 and again["sweep"].skipped == 2
