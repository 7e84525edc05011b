"""The traffic-system comparison as a resumable sweep on Dask (issue 23; symtrack/studies/traffic.py):
a tiny season, interrupted after its first system and resumed, gives the table of an
uninterrupted run; the refusals come before any cluster starts."""

from __future__ import annotations

import csv

import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.studies import engine
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


@pytest.mark.slow  # four tiny seasons on a local cluster (about 1 min on 2 cores)
def test_interrupted_traffic_sweep_resumes_to_the_same_table(tmp_path, monkeypatch):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY)
    whole = traffic_sweep(str(f), tmp_path / "whole", workers=2, progress=False)
    assert [r["tracks"] for r in whole["rows"]] == ["random", "controlled"]
    assert all(r["complete"] for r in whole["rows"])
    # interrupted (Ctrl-C in the client) once the first system's season is stored: at the progress
    # update that follows it
    class InterruptAfterFirst(engine.Progress):
        def update(self, done, note=""):
            if done >= 1:
                raise KeyboardInterrupt
            super().update(done, note)
    monkeypatch.setattr(engine, "Progress", InterruptAfterFirst)
    with pytest.raises(KeyboardInterrupt):
        traffic_sweep(str(f), tmp_path / "cut", workers=2, progress=False)
    monkeypatch.undo()
    with open(tmp_path / "cut" / "results.csv") as fh:
        status = [r["status"] for r in csv.DictReader(fh)]
    assert status.count("ok") == 1 and status.count("not_run") == 1, status
    assert not (tmp_path / "cut" / "traffic.csv").exists()
    resumed = traffic_sweep(str(f), tmp_path / "cut", workers=2, progress=False)
    assert resumed["sweep"].skipped == 1 and resumed["sweep"].ran == 1
    assert _table(tmp_path / "cut" / "traffic.csv") == _table(tmp_path / "whole" / "traffic.csv")
    assert (tmp_path / "cut" / "traffic.png").stat().st_size > 0
    # and a third run has nothing left to do (no cluster started)
    again = traffic_sweep(str(f), tmp_path / "cut", workers=2, progress=False)
    assert again["sweep"].ran == 0 and again["sweep"].skipped == 2
