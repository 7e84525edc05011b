"""The front door (symtrack/studies/runfile.py, symtrack/cli/run.py): `symtrack run FILE` tells the
kind of any run file by its sections and runs it; `symtrack new KIND` writes a starting file of each
kind that runs as written; a file of no kind or of several is refused in one line naming the
deciding sections."""

from __future__ import annotations

import json
import tomllib

import pytest

import symtrack
from symtrack.cli.main import main
from symtrack.cli.run import NEW_KINDS, template_text
from symtrack.foundations.errors import ScenarioError
from symtrack.studies.runfile import KINDS, detect_kind, read_run_file


def test_every_kind_has_a_starting_file_of_its_own_kind():
    assert set(NEW_KINDS) == set(KINDS)
    for kind in NEW_KINDS:
        doc = tomllib.loads(template_text(kind))
        assert detect_kind(doc, kind) == kind
        assert template_text(kind).startswith("# ")  # commented


@pytest.mark.parametrize(("name", "kind"), [("validation", "simulation"), ("straight_offset", "mpc"),
                                            ("field_traffic", "field"), ("operation_small", "operation"),
                                            ("season_4ha", "season"), ("traffic_small", "season")])
def test_the_built_in_runs_are_told_by_their_sections(name, kind):
    assert read_run_file(name).kind == kind


def test_no_kind_or_several_kinds_is_one_line_naming_the_sections(tmp_path):
    none = tmp_path / "none.toml"
    none.write_text('[vehicle]\npreset = "reference_crawler"\n')
    with pytest.raises(ScenarioError) as err:
        read_run_file(none)
    msg = str(err.value)
    assert "\n" not in msg and "none of the sections that decide the kind" in msg
    for section in ("[[torque]]", "[path]", "[mpc]", "[field]", "[operation]", "[season]", "[sweep]"):
        assert section in msg
    both = {"torque": [{"t_s": 0.0, "left_N_m": 1.0, "right_N_m": 1.0}], "path": {}}
    with pytest.raises(ScenarioError, match=r"several kinds of run: \[\[torque\]\] \(a simulation\), "
                                            r"\[path\] \(an MPC run\)"):
        detect_kind(both, "x")
    assert detect_kind({"operation": {}, "season": {}}) == "season"  # a season lays its operations over [operation]
    with pytest.raises(ScenarioError, match="does not exist"):
        read_run_file(tmp_path / "missing.toml")
    # the CLI: exit code 2, the one line, nothing written
    assert main(["run", str(none), "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()


def test_new_writes_the_file_and_never_replaces_one(tmp_path, capsys):
    out = tmp_path / "mine.toml"
    assert main(["new", "mpc", "--out", str(out)]) == 0
    assert out.read_text() == template_text("mpc", out)
    assert f"symtrack run {out}" in capsys.readouterr().out
    out.write_text("# my own edits\n")
    assert main(["new", "mpc", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert out.read_text() == "# my own edits\n"


def _run_template(kind, tmp_path):
    path = tmp_path / f"{kind}.toml"
    assert main(["new", kind, "--out", str(path)]) == 0
    out = tmp_path / f"out_{kind}"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("kind", ["simulation", "mpc", "field", "sweep"])
def test_each_starting_file_runs_as_written(kind, tmp_path):
    out = _run_template(kind, tmp_path)
    if kind == "sweep":
        rows = (out / "results.csv").read_text().splitlines()
        assert len(rows) == 3 and all(",ok," in r for r in rows[1:])  # two masses, both run
    else:
        summary = json.loads((out / "summary.json").read_text())
        assert summary.get("complete", True) is not False
    assert (out / "report.html").is_file() or kind in ("mpc", "field")


@pytest.mark.slow  # an operation and a season with their turns driven, about 10 s each
@pytest.mark.parametrize("kind", ["operation", "season"])
def test_each_field_operation_starting_file_runs_as_written(kind, tmp_path):
    out = _run_template(kind, tmp_path)
    assert json.loads((out / "summary.json").read_text())["complete"]


def test_python_front_door_and_overrides(tmp_path):
    doc = tomllib.loads(template_text("simulation"))
    res = symtrack.run(doc, overrides={"run.duration_s": 0.5})
    assert isinstance(res, symtrack.Result) and res.summary["sim_time_s"] == pytest.approx(0.5)
    with pytest.raises(ScenarioError, match="writes its folder as it goes: give out="):
        symtrack.run(tomllib.loads(template_text("field")))


def test_a_sweep_file_names_its_scenario_or_is_it(tmp_path):
    from symtrack.studies import plan
    from symtrack.studies.runfile import sweep_arguments

    named = {"sweep": {"scenario": "validation", "vary": {"vehicle.mass_kg": [5000.0, 6000.0]}}}
    args = sweep_arguments(read_run_file(named, {"sweep.seed": 2, "run.duration_s": 0.5}))
    assert args["scenario"] == "validation" and args["seed"] == 2 and args["overrides"] == {"run.duration_s": 0.5}
    p = plan(args["scenario"], args["vary"], overrides=args["overrides"])
    assert len(p.runs) == 2 and p.source.kind == "simulate"
    inline = tomllib.loads(template_text("sweep"))
    args = sweep_arguments(read_run_file(inline, ["run.duration_s=0.5"]))
    text = args["scenario"].text
    assert args["kind"] == "simulate" and "[[torque]]" in text and "[sweep" not in text
    assert plan(args["scenario"], args["vary"], overrides=args["overrides"]).source.name == "my_sweep"
    with pytest.raises(ScenarioError, match=r"sweep.scenario names the scenario, so the file holds only \[sweep\]"):
        sweep_arguments(read_run_file({**named, "vehicle": {"mass_kg": 6000.0}}))
    with pytest.raises(ScenarioError, match="varies nothing"):
        sweep_arguments(read_run_file({"sweep": {"scenario": "validation"}}))
    with pytest.raises(ScenarioError, match=r"unknown key\(s\) in \[sweep\]: vary_me"):
        sweep_arguments(read_run_file({"sweep": {"vary_me": 1}}))
    with pytest.raises(ScenarioError, match=r"its scenario: the file without \[sweep\]\): none of the sections"):
        sweep_arguments(read_run_file({"sweep": {"vary": {"a.b": [1]}}, "name": "x"}))
