"""The newcomer's list of issue 26 (item 6): each fix held by a small test (the README's
instructions after `make demo`: tests/test_readme.py; --quiet without matplotlib's animation line:
tests/test_commit_once.py)."""

from __future__ import annotations

import importlib
import json
import runpy
from pathlib import Path

import numpy as np
import pytest

import symtrack
from symtrack.cli import main
from symtrack.control import scenario as mpc_scenario
from symtrack.foundations import files as files_module
from symtrack.foundations.config import to_toml
from symtrack.foundations.errors import ScenarioError
from symtrack.reports import run_files
from symtrack.simulation.scenario import load_scenario
from symtrack.studies.field import load_field_spec
from symtrack.terrain.soil_map import parse_soil_map

ROOT = Path(__file__).resolve().parent.parent


def test_a_field_too_small_names_its_size_and_the_smallest_that_fits():
    with pytest.raises(ScenarioError) as err:
        load_field_spec("field_traffic", ["field.size_m=[10.0,10.0]"])
    msg = str(err.value)
    assert msg.startswith("field.size_m = [10.0, 10.0]") and "size_m[0] > 15 m" in msg
    assert "stop_after_distance_m" not in msg


def test_an_unknown_soil_of_a_soil_map_names_the_entry():
    for entry, key in (("mud", "terrain.soil_map.soils[1] = 'mud'"),
                       ({"preset": "mud"}, "terrain.soil_map.soils[1].preset = 'mud'")):
        with pytest.raises(ScenarioError) as err:
            parse_soil_map({"soils": ["dry_sand", entry], "zones": [{"soil": 1, "x_m": [0, 1], "y_m": [0, 1]}]})
        assert str(err.value).startswith(key) and "soil.preset" not in str(err.value)


def test_a_scheduler_without_a_port_is_a_clean_error(tmp_path, capsys):
    assert main(["sweep", "validation", "--vary", "vehicle.mass_kg=5000,6000", "--out", str(tmp_path / "s"),
                 "--scheduler", "localhost", "--quiet"]) == 2
    assert "--scheduler 'localhost' must be an address with a port" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_a_different_sweep_into_a_sweeps_folder_is_refused(tmp_path, capsys):
    out = tmp_path / "s"
    out.mkdir()
    design = {"schema_version": 1, "scenario": "multipass", "axes": [{"key": "soil.bekker_n", "values": [0.7]}],
              "runs": [{"id": "0123456789ab", "values": {"soil.bekker_n": 0.7}}]}
    (out / "sweep.json").write_text(json.dumps(design))
    (out / "results.csv").write_text("soil.bekker_n,run_id,status\n0.7,0123456789ab,ok\n")
    assert main(["sweep", "validation", "--vary", "vehicle.mass_kg=5000,6000", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "holds another sweep ('multipass', 1 runs, varied soil.bekker_n)" in err and "another --out" in err
    assert (out / "results.csv").read_text().startswith("soil.bekker_n,run_id")
    assert json.loads((out / "sweep.json").read_text()) == design


def test_linearize_checks_its_folder_before_the_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(files_module.os, "access", lambda *a: False)  # a read-only folder (root ignores modes)

    def no_work(*a, **k):
        raise AssertionError("linearize worked before checking its output folder")

    monkeypatch.setattr(importlib.import_module("symtrack.control.trim"), "trim", no_work)
    assert main(["linearize", "--speed", "1.0", "--out", str(tmp_path / "lin")]) == 2
    assert "is not writable" in capsys.readouterr().err


def test_a_write_that_fails_is_a_clean_error_and_puts_nothing_in_place(tmp_path, monkeypatch):
    def refuse(path, data):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(run_files, "atomic_write_bytes", refuse)
    with pytest.raises(ScenarioError, match="cannot write the run's files into .*Permission denied"):
        run_files.write_folder(tmp_path / "o", {"a.csv": "1\n", "summary.json": "{}"})
    assert not (tmp_path / "o").exists() and not list(tmp_path.glob(".o.staging-*"))


def test_the_wet_headland_example_refuses_an_unwritable_folder_at_once(tmp_path, monkeypatch, capsys):
    ex = runpy.run_path(str(ROOT / "examples" / "wet_headland.py"))
    monkeypatch.setattr(symtrack, "simulate", lambda *a, **k: pytest.fail("simulated before checking --out"))
    monkeypatch.setattr(files_module.os, "access", lambda *a: False)
    assert ex["main"](["--out", str(tmp_path / "w")]) == 2
    assert "wet_headland: error: --out" in capsys.readouterr().err


def test_paths_in_a_scenario_file_are_relative_to_the_file(tmp_path, monkeypatch):
    sub = tmp_path / "project"
    sub.mkdir()
    (sub / "wet.toml").write_text('base = "clayey_soil_thailand_55"\nprecompression_stress_Pa = 31000.0\n')
    (sub / "crawler.toml").write_text('base = "reference_crawler"\nmass_kg = 6150.0\n')
    np.save(sub / "soils.npy", np.zeros((40, 20), dtype=np.int64))
    (sub / "s.toml").write_text(
        '[vehicle]\npreset = "crawler.toml"\n[soil]\npreset = "wet.toml"\n'
        '[run]\nintegrator = "grid_fast"\n'
        '[terrain]\nsize_m = [4.0, 2.0]\ncell_m = 0.1\n'
        '[terrain.soil_map]\nsoils = ["wet.toml"]\nraster = "soils.npy"\n'
        '[[torque]]\nt_s = 0.0\nleft_N_m = 1500.0\nright_N_m = 1500.0\n')
    monkeypatch.chdir(tmp_path)  # not the scenario's folder
    sc = load_scenario("project/s.toml")
    assert sc.vehicle["mass_kg"] == 6150.0 and sc.soil["precompression_stress_Pa"] == 31000.0
    assert Path(sc.terrain.soil_map.raster) == sub / "soils.npy"
    # --set values stay relative to the current folder
    (tmp_path / "dry.toml").write_text('base = "dry_sand"\n')
    assert load_scenario("project/s.toml", ["soil.preset=dry.toml"]).soil_preset == "dry.toml"


def test_presets_tells_a_vehicle_file_from_a_soil_file(tmp_path, capsys):
    f = tmp_path / "my_crawler.toml"
    f.write_text('base = "reference_crawler"\nmass_kg = 6150.0\n[sources]\nmass_kg = "weighbridge"\n')
    assert main(["presets", str(f), "--wide"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("vehicle preset") and "| mass_kg | 6150 |" in out and "weighbridge" in out
    g = tmp_path / "odd.toml"
    g.write_text('description = "nothing"\n')
    assert main(["presets", str(g)]) == 2
    assert "give --kind" in capsys.readouterr().err


def test_the_mpc_resolved_scenario_is_toml_that_loads_back(tmp_path):
    for plant in (None, "grid"):
        sc = mpc_scenario.load("straight_offset", ["vehicle.mass_kg=6100"], plant)
        f = tmp_path / "scenario.resolved.toml"
        f.write_text(to_toml(sc.resolved_dict()))
        assert mpc_scenario.load(str(f)).to_dict() == sc.to_dict()


def test_result_and_terrain_show_what_they_are_and_column_names_each_once(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text('name = "tiny"\n[vehicle]\npreset = "reference_crawler"\n[soil]\npreset = "clayey_soil_thailand_38"\n'
                 '[run]\nintegrator = "grid_fast"\nstop_after_distance_m = 0.3\nduration_s = 3.0\n'
                 'figures = false\n'  # (the representations are checked, not the drawings)
                 '[terrain]\nsize_m = [6.0, 4.0]\norigin_m = [-2.0, -2.0]\ncell_m = 0.25\n'
                 '[[torque]]\nt_s = 0.0\nleft_N_m = 1500.0\nright_N_m = 1500.0\n')
    res = symtrack.simulate(str(f))
    r = repr(res)
    assert r.startswith("<Result 'tiny': 1 pass") and "sim_time_s" in r and "0x" not in r
    t = repr(res.terrain)
    assert t.startswith("<Terrain 24 x 16 cells of 0.25 m") and "loaded" in t
    assert "not saved yet" in t  # after a run (it said "0 run(s) in its history")
    res.write(tmp_path / "o", terrain_out=tmp_path / "field.npz")
    assert "1 saved run(s) in the history of its file" in repr(res.terrain)
    with pytest.raises(KeyError) as err:
        res.column("nope")
    listed = str(err.value).split("columns: ")[1].rstrip("\"'").split(", ")
    assert len(listed) == len(set(listed)) and "yaw_rad" in listed and "t_s" in listed
    try:
        import pandas  # noqa: F401 (optional)
    except ImportError:
        with pytest.raises(ScenarioError, match="needs pandas"):
            res.to_pandas()
    else:
        df = res.to_pandas()
        assert list(df.columns)[0] == "t_s" and len(df) == len(res.t)


def test_an_mpc_resolved_scenario_holds_every_model_option_and_the_version(tmp_path):
    # issue 38, item 10: nobody could tell from an MPC run's folder which lateral law or vehicle ran
    import tomllib

    from symtrack import __version__
    from symtrack.control import closedloop
    from symtrack.model import ModelOptions
    from symtrack.model.options import scenario_keys

    sc = mpc_scenario.load("straight_offset")  # the defaults: no [model] section in the file
    res = closedloop.run(sc, max_steps=2)
    files = closedloop.closed_loop_files(res)
    text = files["scenario.resolved.toml"]
    # the report names the machine, the soil and the plant in the simulation reports' words
    assert (f"Ran: {sc.vehicle_preset}, " in files["report.html"].decode()
            and f"on {sc.soil_preset}, the {res.summary['plant']} plant" in files["report.html"].decode())
    doc = tomllib.loads(text)
    assert doc["symtrack_version"] == __version__
    defaults = ModelOptions()
    assert set(doc["model"]) == {k for k in scenario_keys() if getattr(defaults, k) is not None}
    assert doc["model"]["lateral_law"] == defaults.lateral_law and doc["model"]["vehicle"] == defaults.vehicle
    f = tmp_path / "scenario.resolved.toml"
    f.write_text(text)
    assert mpc_scenario.load(str(f)).to_dict() == sc.to_dict()  # it loads back as the scenario run
    # a simulate run's records the version too (its [model] held every option already)
    sim = symtrack.simulate(symtrack.load_scenario("validation", {"run.duration_s": 0.2}))
    doc = tomllib.loads(run_files.run_files(sim.runs[0], sim.summary, {})["scenario.resolved.toml"])
    assert doc["symtrack_version"] == __version__ and doc["model"]["lateral_law"] == sim.scenario.model.lateral_law
