"""The README's validation table is the code's own output."""

import re
from pathlib import Path

from conftest import run_once as run

from symtrack.reports import validation
from symtrack.simulation.result import summarise
from symtrack.simulation.scenario import load_scenario


def test_readme_validation_table_matches_the_code():
    """The README's table: the validation as it declares itself (the creep law, what `make demo`
    prints) and beside it the same manoeuvre on the package's default law (issue 21)."""
    text = Path("README.md").read_text()
    m = re.search(r"<!-- validation-table:start -->\n(.*?)<!-- validation-table:end -->", text, re.S)
    assert m, "README has no validation table markers"
    declared = load_scenario("validation")
    assert declared.model.lateral_law == "creep"
    shear = load_scenario("validation", ["model.lateral_law=shear"])
    summary, other = summarise(run(declared)), summarise(run(shear))
    assert [ok for *_, ok in validation.check(summary)] == [True] * len(validation.REPORTED)
    assert m.group(1) == validation.comparison_markdown(summary, other, "shear law (the default)")
    # the table make demo prints is the first four columns
    rows = validation.table_markdown(summary).splitlines()
    assert [r.split(" | ")[:3] for r in rows[2:]] == [r.split(" | ")[:3] for r in m.group(1).splitlines()[2:]]


def test_readme_api_example_runs_and_agrees_with_the_cli(tmp_path, monkeypatch):
    import json

    from symtrack.cli import main

    text = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    m = re.search(r"<!-- api-example:start -->\n```python\n(.*?)```\n<!-- api-example:end -->", text, re.S)
    assert m, "README has no API example markers"
    monkeypatch.chdir(tmp_path)
    ns = {}
    exec(compile(m.group(1), "README.md (API example)", "exec"), ns)
    res, files = ns["res"], ns["files"]
    assert Path("out/api_validation/summary.json") in files
    assert main(["simulate", "validation", "--integrator", "rosenbrock", "--quiet", "--out", "cli"]) == 0
    cli = json.loads((tmp_path / "cli" / "summary.json").read_text())
    api = json.loads((tmp_path / "out" / "api_validation" / "summary.json").read_text())
    assert sorted(p.name for p in (tmp_path / "cli").iterdir()) == sorted(
        p.name for p in (tmp_path / "out" / "api_validation").iterdir())
    for k, v in cli.items():
        if k not in ("wall_time_s", "real_time_factor"):
            assert api[k] == v, k
    assert res.column("yaw_rad")[-1] == ns["yaw"][-1] and len(ns["yaw"]) == len(res.t)
    # the second pass continued the saved terrain: it added less than the first
    assert ns["second"].summary["passes"][0]["new_sinkage_mean_mm"] < ns["first"].summary["passes"][0][
        "new_sinkage_mean_mm"]


def test_readme_says_how_to_call_the_cli_after_make_demo():
    """After `make demo` the CLI is in .venv, not on PATH (issue 26): the quick start says so, and the
    Makefile's venv is the one it names."""
    root = Path(__file__).resolve().parent.parent
    quick = (root / "README.md").read_text().split("## The validation run")[0]
    assert ".venv/bin/symtrack" in quick and "source .venv/bin/activate" in quick
    assert "VENV ?= .venv" in (root / "Makefile").read_text()
