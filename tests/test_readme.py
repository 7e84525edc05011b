"""The README and the pages its content moved to say what the code does: the validation table
(docs/validation-run.md) is the code's own output, the Python examples (the README's three lines,
docs/python.md) run and agree with the command line, the README's quick start says how to call the
CLI after `make demo`, and the README stays a front page (at most 150 lines)."""

import re
from pathlib import Path

from conftest import run_once as run

from symtrack.reports import validation
from symtrack.simulation.result import summarise
from symtrack.simulation.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


def test_readme_validation_table_matches_the_code():
    """The validation table (docs/validation-run.md): the validation as it declares itself (the creep law,
    what `make demo` prints) and beside it the same manoeuvre on the package's default law."""
    text = (ROOT / "docs" / "validation-run.md").read_text()
    m = re.search(r"<!-- figures:validation:start -->\nProduced .*?\n\n(.*?)<!-- figures:validation:end -->",
                  text, re.S)
    assert m, "docs/validation-run.md has no validation table markers (docs/figures.py writes the table)"
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
    """The API example of docs/python.md runs and writes what `symtrack simulate validation` writes."""
    import json

    from symtrack.cli import main

    text = (ROOT / "docs" / "python.md").read_text()
    m = re.search(r"<!-- api-example:start -->\n```python\n(.*?)```\n<!-- api-example:end -->", text, re.S)
    assert m, "docs/python.md has no API example markers"
    monkeypatch.chdir(tmp_path)
    ns = {}
    exec(compile(m.group(1), "docs/python.md (API example)", "exec"), ns)
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


def test_readme_three_line_example_runs(tmp_path, monkeypatch, capsys):
    """The README's Python example: three lines that run as written and print the figures they name."""
    import symtrack

    text = (ROOT / "README.md").read_text()
    m = re.search(r"<!-- readme-example:start -->\n```python\n(.*?)```\n<!-- readme-example:end -->", text, re.S)
    assert m, "README has no Python example markers"
    code = m.group(1)
    assert len(code.strip().splitlines()) == 3
    monkeypatch.chdir(tmp_path)
    ns = {}
    exec(compile(code, "README.md (Python example)", "exec"), ns)
    res = ns["res"]
    assert isinstance(res, symtrack.Result) and res.scenario.vehicle["mass_kg"] == 6000.0
    printed = capsys.readouterr().out.split()
    assert float(printed[0]) == res.summary["yaw_final_deg"]


def test_readme_says_how_to_call_the_cli_after_make_demo():
    """After `make demo` the CLI is in .venv, not on PATH: the quick start says so, and the Makefile's
    venv is the one it names."""
    text = (ROOT / "README.md").read_text()
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    assert "make demo" in quick and "make test" in quick
    assert ".venv/bin/symtrack" in quick and "source .venv/bin/activate" in quick
    assert "VENV ?= .venv" in (ROOT / "Makefile").read_text()


def test_readme_is_a_front_page():
    """At most 150 lines: what it is, a picture, the commands, a Python example, links; every link to a
    file of the repository names a file that exists."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    assert re.search(r"!\[[^\]]*\]\(docs/[^)]+\.png\)", text), "README has no picture"
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if "://" not in target:
            assert (ROOT / target).exists(), f"README links to {target}, which does not exist"
