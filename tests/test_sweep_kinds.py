"""A sweep runs the kinds of run file of the one registry (symtrack.studies.runfile.KINDS): the run ids
of each kind are those earlier versions computed (so their sweep folders resume), a folder an earlier
version wrote resumes without running anything, and a kind registered once runs in a sweep, by
symtrack.run and by `symtrack run`."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import pytest

from symtrack import studies
from symtrack.cli import main
from symtrack.cli.run import template_text
from symtrack.foundations.errors import ScenarioError
from symtrack.studies import engine as sweep_module
from symtrack.studies import plan, runfile
from symtrack.studies.runfile import Kind, read_run_file, register_kind, sweep_arguments

FAST = ["run.integrator=rosenbrock", "run.stop_after_distance_m=none", "run.duration_s=0.6", "run.output_dt_s=0.05"]
# written by `symtrack sweep validation --vary vehicle.mass_kg=5000,6500 --workers 1 --set ...FAST` at
# commit b641379 (before the kinds were one registry); kept: sweep.json, each run's summary.json and run.json
FOLDER_B641379 = Path(__file__).parent / "data" / "sweep_folder_v1"

# (scenario, varied, fixed overrides, --kind, the run ids computed at commit b641379)
PINNED = [
    ("validation", {"vehicle.mass_kg": [5000.0, 6000.0]}, FAST, "auto", ["28e7bd827670", "bae4168a7175"]),
    ("straight_offset", {"mpc.rti_relinearisations": [1, 3]}, ["run.duration_s=0.4"], "auto",
     ["ffd262ec42dc", "c59674ab242c"]),
    ("field_traffic", {"field.passes": [1, 2]}, [], "auto", ["2b1c78370504", "d8ce6c55a5c9"]),
    ("operation_small", {"operation.speed_m_s": [1.5, 2.0]}, [], "auto", ["d69917225787", "65a15521e04c"]),
    ("traffic_small", {"season.tracks": ["random", "controlled"]}, [], "field", ["a7da8e99e637", "0d2cc9cc5fd6"]),
]


@pytest.mark.parametrize(("scenario", "vary", "overrides", "kind", "ids"), PINNED, ids=[p[0] for p in PINNED])
def test_run_ids_are_those_of_earlier_versions(scenario, vary, overrides, kind, ids):
    p = plan(scenario, vary, overrides=overrides, kind=kind)
    assert [r["id"] for r in p.runs] == ids


def test_the_run_ids_of_a_sweep_file_are_those_of_earlier_versions():
    args = sweep_arguments(read_run_file(tomllib.loads(template_text("sweep")), ["run.duration_s=0.5"]))
    p = plan(args["scenario"], args["vary"], overrides=args["overrides"])
    assert p.source.kind == "simulate" and [r["id"] for r in p.runs] == ["447b26ead2da", "4b0c87913255"]


def test_a_sweep_folder_of_an_earlier_version_resumes_without_running(tmp_path, monkeypatch):
    out = tmp_path / "sweep"
    shutil.copytree(FOLDER_B641379, out)

    def no_cluster(*args, **kwargs):
        raise AssertionError("a finished run of the folder was to run again")

    monkeypatch.setattr(sweep_module, "_client", no_cluster)
    res = studies.sweep("validation", {"vehicle.mass_kg": [5000, 6500]}, out=out, overrides=FAST, workers=1,
                        progress=False)
    assert (res.ran, res.skipped, res.ok) == (0, 2, True)
    for row in res.rows:
        summary = json.loads((out / "runs" / row["run_id"] / "summary.json").read_text())
        assert row["sim_time_s"] == summary["sim_time_s"] == pytest.approx(0.6)
    assert json.loads((out / "sweep.json").read_text())["kind"] == "simulate"


def _load_toy(rf):
    t = rf.document.get("toy")
    if not isinstance(t, dict) or set(t) != {"side_m"} or not isinstance(t["side_m"], float) or t["side_m"] <= 0:
        raise ScenarioError(f"[toy] = {t!r} must hold side_m, a length > 0 [m]")
    return t["side_m"]


def _run_toy(side_m, out, progress):
    """The toy's run: the area of a square, into the folder's summary.json."""
    Path(out).mkdir(parents=True, exist_ok=True)
    (Path(out) / "summary.json").write_text(json.dumps({"side_m": side_m, "area_m2": side_m ** 2}))
    return side_m ** 2


@pytest.fixture
def toy_kind(monkeypatch):
    """A kind of run file of a test: registered once, in a registry given back after the test."""
    monkeypatch.setattr(runfile, "KINDS", dict(runfile.KINDS))
    return register_kind(Kind("toy", ("[toy]",), "a toy run", "symtrack run", None, _load_toy, _run_toy, sweep="toy"))


def test_a_kind_registered_once_runs_in_a_sweep_and_by_the_front_doors(toy_kind, tmp_path):
    from distributed import LocalCluster

    import symtrack

    f = tmp_path / "square.toml"
    f.write_text("[toy]\nside_m = 1.0\n")
    assert read_run_file(str(f)).kind == "toy"
    assert symtrack.run(str(f), tmp_path / "one", overrides=["toy.side_m=3.0"]) == 9.0
    assert json.loads((tmp_path / "one" / "summary.json").read_text())["area_m2"] == 9.0
    assert main(["run", str(f), "--out", str(tmp_path / "cli"), "--quiet"]) == 0
    assert json.loads((tmp_path / "cli" / "summary.json").read_text())["area_m2"] == 1.0
    with pytest.raises(ScenarioError, match="must hold side_m"):
        plan(str(f), {"toy.side_m": [2.0, 0.0]})
    # a cluster in this process (its workers are threads): they see the kind registered here
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address=None) as cluster:
        res = studies.sweep(str(f), {"toy.side_m": [2.0, 0.5]}, out=tmp_path / "sweep",
                            scheduler=cluster.scheduler_address, progress=False)
    assert res.ok and [(r["toy.side_m"], r["area_m2"]) for r in res.rows] == [(2.0, 4.0), (0.5, 0.25)]
    assert json.loads((tmp_path / "sweep" / "sweep.json").read_text())["kind"] == "toy"


def test_a_sweep_of_field_kinds_tells_them_by_their_sections():
    from symtrack.studies.field import FieldSpec
    from symtrack.studies.operations import OperationSpec
    from symtrack.studies.runs import load, resolve_source

    for name, spec_type in (("field_traffic", FieldSpec), ("operation_small", OperationSpec),
                            ("traffic_small", OperationSpec)):
        source = resolve_source(name)
        assert source.kind == "field" and isinstance(load(source.kind, source.text, source.name), spec_type)
    with pytest.raises(ScenarioError, match=r"\[field\] \(a field study\), \[operation\] \(a field operation\)"):
        load("field", "[field]\n[operation]\n", "both")
    with pytest.raises(ScenarioError, match=r"kind = 'toy' is not one of simulate, mpc, field"):
        load("toy", "[toy]\nside_m = 1.0\n", "toy")
