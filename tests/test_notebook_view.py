"""The results' views in a notebook (``_repr_html_``) and their plain reprs: a simulation's Result, an MPC
run's ClosedLoopResult, a field study's, a season's and a sweep's result say what ran, give their figures
with units and the run time, parse as HTML and escape every string. Built from loaded specs and made-up
figures: nothing is run."""

from __future__ import annotations

import dataclasses
from html.parser import HTMLParser

import numpy as np
import pytest

import symtrack

HOSTILE = "<script>alert('x')</script>&"


class _Page(HTMLParser):
    """The tags, the text and whether every opened tag was closed."""

    VOID = {"br", "hr", "img", "meta"}

    def __init__(self, page: str):
        super().__init__(convert_charrefs=True)
        self.stack, self.tags, self.text, self.cells = [], [], [], []
        self.feed(page)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, (tag, self.stack)
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)
        if self.stack and self.stack[-1] in ("td", "th"):
            self.cells.append(data)


def _check(page: str, *expected: str) -> _Page:
    p = _Page(page)
    assert not p.stack and "script" not in p.tags, p.tags
    text = "".join(p.text)
    for e in expected:
        assert e in text, (e, text)
    return p


def _scenario(name=HOSTILE):
    sc = symtrack.load_scenario("validation", {"vehicle.mass_kg": 6500.0})
    return dataclasses.replace(sc, name=name)


def test_a_simulation_result_names_its_machine_and_escapes_its_name():
    summary = {"schema_version": 1, "scenario": HOSTILE, "integrator": "cvodes", "complete": True,
               "distance_m": 4.5, "sinkage_sprocket_mm": 2.4, "sim_time_s": 3.0, "wall_time_s": 6.5}
    from symtrack.api import Result

    res = Result(_scenario(), [None], summary, [summary])
    page = res._repr_html_()
    assert "<script>" not in page and "&lt;script&gt;" in page
    p = _check(page, f"scenario: {HOSTILE}", "integrator: cvodes", "vehicle: reference_crawler, 6500 kg",
               "soil: clayey_soil_thailand_38")
    cells = p.cells
    i = cells.index("sinkage_sprocket_mm")
    assert cells[i + 1:i + 3] == ["2.4", "mm"] and "wall_time_s" in cells
    assert repr(res).startswith("<Result ") and "wall_time_s 6.5" in repr(res)


def test_an_mpc_result_has_a_short_repr_and_a_view():
    from symtrack.control.closedloop import ClosedLoopResult
    from symtrack.control.scenario import load

    sc = dataclasses.replace(load("straight_offset"), name=HOSTILE)
    n = 3
    z = np.zeros(n)
    summary = {"scenario": HOSTILE, "plant_integrator": "rosenbrock", "rms_lateral_error_m": 0.05,
               "solve_time_median_ms": 1.5, "failed_solves": 0, "sim_time_s": 10.0, "wall_time_s": 2.0}
    res = ClosedLoopResult(sc, z, np.zeros((n, 4)), np.zeros((n, 2)), np.zeros((n, 5)), z, z, z, z, z,
                           np.ones(n, bool), z, ("x_m",), summary, None)
    r = repr(res)
    assert r.startswith("<ClosedLoopResult ") and "rms_lateral_error_m 0.05" in r and "array" not in r
    p = _check(res._repr_html_(), f"scenario: {HOSTILE}", "integrator: rosenbrock", "solver: ",
               "vehicle: reference_crawler", "soil: sandy_loam_15")
    i = p.cells.index("solve_time_median_ms")
    assert p.cells[i + 1:i + 3] == ["1.5", "ms"] and "wall_time_s" in p.cells


def test_a_field_study_result_gives_each_pattern_and_the_run_time():
    from symtrack.studies.field import FieldStudyResult, load_field_spec

    spec = dataclasses.replace(load_field_spec("field_traffic", {"vehicle.mass_kg": 6500.0}), name=HOSTILE)
    summary = {"name": HOSTILE, "complete": True, "patterns_run": ["random", "controlled"], "passes_per_pattern": 4,
               "field_size_m": [20.0, 9.0], "field_cell_m": 0.1, "sim_time_s": 57.0, "build_s": 50.0,
               "wall_time_s": 57.5, "path_note": "a long note", "random_trafficked_area_fraction": 0.37,
               "random_rut_max_depth_mm": 1.6, "controlled_trafficked_area_fraction": 0.18,
               "random_risk_fraction_of_field_high_at_0.3m": 0.0}
    res = FieldStudyResult(spec, {}, summary)
    p = _check(res._repr_html_(), f"field study: {HOSTILE}", "field: 20 m x 9 m, 0.1 m cells",
               "patterns: random, controlled", "vehicle: reference_crawler, 6500 kg")
    assert "random_rut_max_depth_mm" in p.cells and "a long note" not in "".join(p.text)
    assert "random_risk_fraction_of_field_high_at_0.3m" in p.cells and "wall_time_s" in p.cells
    r = repr(res)
    assert r.startswith("<FieldStudyResult ") and "random_trafficked_area_fraction 0.37" in r and "spec" not in r


def test_a_season_result_lists_its_operations():
    from symtrack.studies.operations import load_operation_spec
    from symtrack.studies.operations.outputs import OperationResult
    from symtrack.studies.operations.season import SeasonResult

    spec = dataclasses.replace(load_operation_spec("traffic_small"), name=HOSTILE)
    ops = [OperationResult(fs.name, {"distance_m": 123.0, "rut_max_depth_mm": 3.0, "sim_time_s": 60.0,
                                     "wall_time_s": 4.0}, np.zeros((2, 2), np.uint16), np.zeros((2, 2), bool),
                           np.zeros((0, 5)), np.zeros((0, 4))) for fs, *_ in spec.operations]
    summary = {"name": HOSTILE, "complete": True, "field_size_m": [60.0, 48.0], "field_cell_m": 0.1,
               "trafficked_fraction": 0.3, "rut_max_depth_mm": 3.0, "sim_time_s": 120.0, "wall_time_s": 9.0,
               "trafficked_note": "a long note"}
    res = SeasonResult(spec, ops, summary, np.zeros((2, 2), np.uint16), None, [])
    names = [fs.name for fs, *_ in spec.operations]
    p = _check(res._repr_html_(), f"season: {HOSTILE}", "field: 60 m x 48 m", *names)
    assert "trafficked_fraction" in p.cells and "a long note" not in "".join(p.text)
    assert p.cells.count("123") == len(names)  # one row per operation
    assert repr(res).startswith("<SeasonResult ") and "wall_time_s 9" in repr(res)


def test_a_traffic_comparison_shows_a_row_per_system_and_stays_a_dict():
    import json

    from symtrack.studies.operations import TRAFFIC_COLUMNS, TrafficComparison, traffic_row

    done = {k: 0.25 for k in TRAFFIC_COLUMNS}
    rows = [traffic_row(HOSTILE, {**done, "complete": True, "trafficked_fraction": 0.4321}),
            traffic_row("controlled", None)]
    res = TrafficComparison(HOSTILE, rows)
    p = _check(res._repr_html_(), f"Traffic systems: {HOSTILE}", "controlled")
    assert p.cells[:len(TrafficComparison.KEYS)] == list(TrafficComparison.KEYS)
    assert "0.4321" in p.cells and p.cells.count(HOSTILE) == 1
    assert repr(res) == f"<TrafficComparison {HOSTILE!r}: trafficked_fraction {HOSTILE} 0.4321, controlled incomplete>"
    assert res["rows"] == rows and json.loads(json.dumps(res)) == {"rows": rows}  # the dict it always was


def test_a_sweep_result_shows_its_counts_and_first_rows(tmp_path):
    from symtrack.studies.engine import SweepResult

    rows = [{"id": f"r{k}", "status": "ok" if k else "failed", "vehicle.mass_kg": 5000 + k, "note": HOSTILE}
            for k in range(SweepResult.SHOWN_ROWS + 3)]
    res = SweepResult(tmp_path, rows, ran=len(rows), wall_time_s=12.0)
    page = res._repr_html_()
    assert HOSTILE not in page
    p = _check(page, "rows not shown: 3", "results.csv")
    assert p.cells.count(HOSTILE) == SweepResult.SHOWN_ROWS and "runs_failed" in p.cells
    assert repr(res).startswith("<SweepResult ") and "runs_failed 1" in repr(res)


@pytest.mark.parametrize("params", [None, {}, {"mass_kg": 7000.0}])
def test_machine_facts(params):
    from symtrack.reports.html import machine_facts

    (v, vehicle), (s, soil) = machine_facts("reference_crawler", "/some/where/wet_clay.toml", params)
    assert (v, s, soil) == ("vehicle", "soil", "wet_clay.toml")
    assert vehicle == ("reference_crawler, 7000 kg" if params else "reference_crawler")


def test_an_operation_and_a_pattern_print_one_line():
    from symtrack.studies.field import PatternResult
    from symtrack.studies.operations.outputs import OperationResult

    big = np.zeros((400, 300), np.uint16)
    op = OperationResult("drilling", {"distance_m": 120.0, "wall_time_s": 4.0}, big, big.astype(bool),
                         np.zeros((0, 5)), np.zeros((0, 4)), error="boom")
    assert repr(op) == "<OperationResult 'drilling': distance_m 120, wall_time_s 4, incomplete>"
    pr = PatternResult("random", [], counts=big, figures={"rut_max_depth_mm": 1.5}, complete=True, wall_time_s=0.6)
    assert repr(pr) == "<PatternResult 'random': passes_done 0, rut_max_depth_mm 1.5, wall_time_s 0.6>"
