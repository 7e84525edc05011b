"""The run pipeline: the explicit, cached build (a second run of the same model reuses its
model and gives the same figures bit for bit)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import symtrack
from symtrack.foundations.errors import ScenarioError
from symtrack.integrators import registry
from symtrack.model.options import ModelOptions
from symtrack.simulation import builder as build_module
from symtrack.simulation.builder import build_cache_info, clear_build_cache, system_model


def test_a_second_build_reuses_the_model_and_runs_the_same():
    clear_build_cache()
    sc = symtrack.load_scenario("validation", {"run.duration_s": 2.0})
    b1 = symtrack.build(sc)
    assert b1.kind == "homogeneous" and build_cache_info() == {"models": 1, "hits": 0, "misses": 1}
    r1 = symtrack.simulate(b1)
    r2 = symtrack.simulate(sc)
    # the model's construction (most of a short run's cost) is not repeated
    assert build_cache_info()["models"] == 1 and build_cache_info()["hits"] >= 2
    assert build_cache_info()["misses"] == 1
    assert symtrack.build(sc).model is b1.model
    np.testing.assert_array_equal(r1.runs[0].X, r2.runs[0].X)
    np.testing.assert_array_equal(r1.runs[0].Y, r2.runs[0].Y)
    assert {k: v for k, v in r1.summary.items() if "time" not in k} == \
        {k: v for k, v in r2.summary.items() if "time" not in k}


def test_other_model_options_build_another_model():
    sc = symtrack.load_scenario("validation", {"model.traction_sign": "tanh", "run.duration_s": 0.5})
    assert symtrack.build(sc).model is system_model(sc.model)
    assert system_model(sc.model) is not system_model(None)
    assert system_model(sc.model).opts == sc.model


def test_the_model_cache_keeps_the_most_recently_used(monkeypatch):
    clear_build_cache()
    monkeypatch.setattr(build_module, "MAX_MODELS", 2)
    opts = [dataclasses.replace(ModelOptions(), gauss_points=n) for n in (3, 4, 5)]
    first = system_model(opts[0])
    system_model(opts[1])
    assert system_model(opts[0]) is first  # a hit moves it to the end
    system_model(opts[2])  # evicts opts[1], the least recently used
    assert build_cache_info()["models"] == 2 and system_model(opts[0]) is first
    misses = build_cache_info()["misses"]
    system_model(opts[1])
    assert build_cache_info()["misses"] == misses + 1
    clear_build_cache()


@pytest.mark.parametrize("name", ["validation", "validation_grid"])
def test_a_run_looks_its_integrator_up_once(monkeypatch, name):
    """A run resolves its integrator in the registry once, when it is built; every plant of the
    build takes that entry."""
    sc = symtrack.load_scenario(name, {"run.duration_s": 0.05})
    calls = []
    real = registry.get

    def counted(*args, **kw):
        calls.append(args[0])
        return real(*args, **kw)

    monkeypatch.setattr(registry, "get", counted)
    symtrack.simulate(sc)
    assert calls == [sc.run.integrator]


def test_build_checks_the_integrator_and_the_terrain():
    with pytest.raises(ScenarioError):
        symtrack.build("validation", integrator=3)
    with pytest.raises(ScenarioError):
        symtrack.build("validation", terrain="field.npz")
    assert symtrack.build("validation_grid").kind == "grid"


def test_a_figure_registered_in_a_test_is_drawn_and_written(tmp_path):
    """Adding a figure is one function and one registry entry: a toy figure of the trajectory
    kind lands in the run's folder and in report.html, after the built-in ones."""
    from symtrack.reports import figures
    from symtrack.reports.plots import plt, png_bytes

    def toy(res):
        fig, ax = plt.subplots()
        ax.plot(res.t, res.column("u_m_s"))
        return {"toy_speed.png": png_bytes(fig)}

    figures.register("toy_speed", "trajectory", toy)
    try:
        assert figures.names("trajectory")[-1] == "toy_speed"
        res = symtrack.simulate(symtrack.load_scenario("validation", {"run.duration_s": 1.0}))
        written = res.write(tmp_path)
    finally:
        figures.unregister("toy_speed")
    assert tmp_path / "toy_speed.png" in written
    assert (tmp_path / "toy_speed.png").read_bytes()[:4] == b"\x89PNG"
    assert "toy_speed.png" in (tmp_path / "report.html").read_text()
    assert "toy_speed" not in figures.names()
    with pytest.raises(KeyError):
        figures.register("path", "trajectory", toy)  # taken
    with pytest.raises(KeyError):
        figures.register("toy", "sound", toy)


def test_the_one_writer_writes_summary_last_and_clears_a_previous_run(tmp_path, monkeypatch):
    from symtrack.reports import run_files

    # a previous run's files (recorded in the folder's manifest), and the user's (not recorded)
    run_files.write_folder(tmp_path, {"old.png": "x", "pass_2/summary.json": "{}", "summary.json": "{}"})
    (tmp_path / "notes.txt").write_text("mine")
    order = []  # the files as they arrive in the folder (moved from the staging folder beside it)
    real = run_files.os.replace
    monkeypatch.setattr(run_files.os, "replace", lambda a, b: (
        order.append(Path(b).relative_to(tmp_path).as_posix()) if Path(b).is_relative_to(tmp_path) else None,
        real(a, b)))
    files = {"pass_1/summary.json": "{}", "summary.json": "{}\n", "pass_1/a.csv": "1", "b.png": b"png"}
    written = run_files.write_folder(tmp_path, files)
    order = [n for n in order if n not in (run_files.MANIFEST, run_files.JOURNAL)]  # (the commit's own records)
    assert order == ["pass_1/a.csv", "b.png", "pass_1/summary.json", "summary.json"]
    assert not list(tmp_path.parent.glob(f".{tmp_path.name}.staging-*"))
    assert written == sorted(tmp_path / n for n in files)
    assert not (tmp_path / "old.png").exists() and not (tmp_path / "pass_2").exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert run_files.read_manifest(tmp_path) == sorted(files)


def test_a_sampled_law_runs_on_its_own_clock():
    """The one loop with a sampled law (the MPC's form): sampled every sample_time_s at the summed
    sample times, its torques held over sub-steps of at most substep_s, the run ended by the law."""
    from symtrack.simulation import loop

    calls = []

    class Law:
        sample_time_s, substep_s = 0.05, 0.02

        def __call__(self, t_s, x, final=False):
            calls.append((t_s, final))
            return None if len(calls) == 5 else (200.0 * len(calls), 100.0)

    sc = symtrack.load_scenario("validation", {"run.duration_s": 10.0})
    res = loop.run(sc, symtrack.build(sc).plant(), torque_law=Law())
    t_expected = [0.0]
    for _ in range(4):
        t_expected.append(t_expected[-1] + 0.05)
    assert [t for t, _ in calls] == t_expected and not any(f for _, f in calls)
    assert res.stopped_by == "controller"
    assert len(res.t) == 1 + 4 * 3  # 3 sub-steps of 1/60 s per sample
    np.testing.assert_allclose(np.diff(res.t), 0.05 / 3, rtol=1e-12)
    np.testing.assert_array_equal(res.U[1:4, 0], 200.0)
    np.testing.assert_array_equal(res.U[10:13, 0], 800.0)
    # at the duration the law sees the last state once more (final)
    calls.clear()
    sc = symtrack.load_scenario("validation", {"run.duration_s": 0.1})
    res = loop.run(sc, symtrack.build(sc).plant(), torque_law=Law())
    assert calls[-1] == (0.1, True) and len(calls) == 3 and res.stopped_by == "duration"


def test_one_loop_and_one_writer_in_the_source():
    """Read from the source: only the time loop (and the plants' own helper) drives a plant
    (``synchronize``), and the run folders of simulate, mpc and the field study are written by
    the one writer (no atomic write of their own in api, control, simulation, reports but
    run_files, studies/field)."""
    import ast
    from pathlib import Path

    root = Path(symtrack.__file__).parent
    drivers, writers = set(), set()
    for f in root.rglob("*.py"):
        rel = f.relative_to(root).as_posix()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Attribute) and node.attr == "synchronize" and isinstance(node.ctx, ast.Load):
                drivers.add(rel)
            if isinstance(node, ast.Name | ast.alias) and getattr(node, "id", getattr(node, "name", "")) in (
                    "atomic_write_bytes", "atomic_write_text"):
                writers.add(rel)
    assert {d for d in drivers if not d.startswith("bench/")} == {"simulation/loop.py", "simulation/plants.py"}
    run_folders = {w for w in writers if w == "api.py" or w.split("/")[0] in ("control", "simulation", "reports")
                   or w == "studies/field.py"}
    assert run_folders == {"reports/run_files.py"}
