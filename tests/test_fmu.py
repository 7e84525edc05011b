"""The FMU of ``symtrack export fmu`` (symtrack/codegen/fmu.py; docs/codegen.md, "The FMU"), checked by an
independent importer, fmpy: its validation finds no problem; its co-simulation of the validation scenario
(the torque programme as an input signal) agrees with `symtrack simulate validation --integrator
rosenbrock` within 1e-6 relative on every column; a changed parameter gives Python's static start
state; any communication step is taken (whole fixed steps, then a shorter one); what cannot be exported is refused
before anything is built; a second importer (fmu-manipulation-toolbox: the FMI 2.0 XSD and semantic
checks, and its C container stepping the FMU) agrees. The binary is compiled once into the cache (about
10-20 s the first time)."""

from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path

import fmpy  # the dev extra's independent FMI importer
import fmpy.fmi2
import numpy as np
import pytest
from fmi_second_importer import check, container, torque_signal
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from symtrack import toolchain
from symtrack.api import simulate
from symtrack.codegen import fmu as fmu_export
from symtrack.foundations.errors import ScenarioError
from symtrack.model.static import static_state
from symtrack.simulation.builder import system_model
from symtrack.simulation.scenario import load_scenario

REL_TOL = 1e-6


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu") / "validation.fmu"
    res = fmu_export.export_fmu("validation", out)
    return res




def test_fmpy_validation_finds_no_problem(exported):
    assert validate_fmu(str(exported.path)) == []
    with zipfile.ZipFile(exported.path) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", "binaries/linux64/symtrack_homogeneous.so", "sources/symtrack_fmu.c",
            "sources/homogeneous_rosenbrock.c", "sources/fmi2Functions.h", "sources/fmu_model.h"} <= names
    md = fmpy.read_model_description(str(exported.path))
    assert md.guid == exported.guid
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["torque_cmd_left_N_m"].causality == "input" and by_name["torque_cmd_left_N_m"].unit == "N m"
    assert by_name["mass_kg"].causality == "parameter" and float(by_name["mass_kg"].start) > 0
    assert by_name["sinkage_sprocket_left_m"].unit == "m" and by_name["p_idler_left_Pa"].unit == "Pa"


def test_fmpy_cosimulation_agrees_with_the_python_run(exported):
    # the FMU controls its steps' error as the Python run does (its default tolerance)
    sc = load_scenario("validation", ["run.integrator=rosenbrock"])
    ref = simulate(sc)
    t_ref = ref.t
    # the Python run's output grid is k * output_dt_s until its distance stop, whose last interval is
    # shortened (secant); the FMU is run on the same grid up to the last full interval
    dt = sc.run.output_dt_s
    n_full = int(np.floor(t_ref[-1] / dt + 1e-9))
    stop = n_full * dt
    md = fmpy.read_model_description(str(exported.path))
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    res = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=stop, output_interval=dt,
                            input=torque_signal(sc, stop), output=outs)
    t_fmu = res["time"]
    assert len(t_fmu) == n_full + 1
    # align: the Python rows whose time is an FMU output time (all but the shortened last one)
    idx = np.searchsorted(t_ref, t_fmu - 1e-9)
    assert np.allclose(t_ref[idx], t_fmu, rtol=0, atol=1e-9)
    assert len(t_ref) == n_full + 2
    worst = {}
    for name in outs:
        a, b = res[name], ref.column(name)[idx]
        scale = np.max(np.abs(b))
        err = np.max(np.abs(a - b))
        worst[name] = err / scale if scale > 0 else err
    assert len(worst) == 40
    bad = {k: v for k, v in worst.items() if not v <= REL_TOL}
    assert not bad, f"columns beyond {REL_TOL} relative (to the column's largest magnitude): {bad}"


def test_the_coast_case_is_within_two_percent_of_cvodes(exported):
    """Driven at 2500 N m for 5 s, then coasting (examples/scenarios/drive_and_coast.toml, the validation's
    vehicle and soil; the Python run's uncontrolled 10 ms steps peak at 8.2 mm of sprocket sinkage after
    the release, against CVODES's 2.1 mm): the FMU's controlled steps give every compared figure within
    2 % of CVODES."""
    sc = load_scenario(str(Path(__file__).resolve().parent.parent / "examples" / "scenarios" / "drive_and_coast.toml"))
    ref = simulate(load_scenario(str(Path(__file__).resolve().parent.parent / "examples" / "scenarios" /
                                     "drive_and_coast.toml"), ["run.integrator=cvodes", "run.reltol=1e-8"]))
    stop = 10.0
    names = ["x_m", "u_m_s", "sinkage_sprocket_left_m", "sinkage_idler_left_m", "pitch_rad"]
    res = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=stop, output_interval=sc.run.output_dt_s,
                            input=torque_signal(sc, stop), output=names)
    for name in names:
        got, want = res[name][-1], float(np.interp(stop, ref.t, ref.column(name)))
        assert got == pytest.approx(want, rel=0.02), name
    # the largest sinkage after the release (where the uncontrolled steps overshoot)
    after = res["time"] > 5.0
    sink = float(np.max(res["sinkage_sprocket_left_m"][after]))
    sink_ref = float(np.max(ref.column("sinkage_sprocket_left_m")[ref.t > 5.0]))
    assert sink == pytest.approx(sink_ref, rel=0.02)


def test_a_second_importer_finds_it_compliant_and_its_container_steps_it_as_fmpy_does(exported, tmp_path):
    """fmu-manipulation-toolbox (tests/fmi_second_importer.py): compliant with the FMI 2.0 XSD, no
    semantic error; its container's C runtime stepping the FMU at the fixed step gives fmpy's direct
    co-simulation on every output column to 1e-9 relative (measured 2.5e-13)."""
    check(exported.path)
    sc = load_scenario("validation", ["run.integrator=rosenbrock"])
    wrapped = container(exported.path, sc.run.fixed_step_s, tmp_path / "container")
    stop, dt = 6.8, sc.run.output_dt_s
    md = fmpy.read_model_description(str(exported.path))
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    direct, via = (fmpy.simulate_fmu(str(p), start_time=0.0, stop_time=stop, output_interval=dt,
                                     input=torque_signal(sc, stop), output=outs) for p in (exported.path, wrapped))
    assert len(direct) == len(via) == round(stop / dt) + 1
    worst = {n: float(np.max(np.abs(via[n] - direct[n])) / max(float(np.max(np.abs(direct[n]))), 1e-300))
             for n in outs}
    assert len(worst) == 40 and max(worst.values()) < 1e-9, {k: v for k, v in worst.items() if not v < 1e-9}


def test_a_changed_parameter_gives_pythons_static_start_state(exported):
    sc = load_scenario("validation")
    mass = 1.3 * sc.params["mass_kg"]
    res = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=0.02, output_interval=0.01,
                            start_values={"mass_kg": mass, "start_y_m": 2.0},
                            output=["y_m", "sinkage_sprocket_left_m", "sinkage_idler_right_m"])
    model = system_model(sc.model)
    x0 = static_state(model, {**sc.params, "mass_kg": mass}, 0.0, 2.0, 0.0)
    for name in ("y_m", "sinkage_sprocket_left_m", "sinkage_idler_right_m"):
        assert res[name][0] == pytest.approx(x0[model.state_index(name)], rel=1e-10, abs=1e-15)
    base = static_state(model, sc.params)
    assert res["sinkage_sprocket_left_m"][0] > base[model.state_index("sinkage_sprocket_left_m")] * 1.05


def test_any_communication_step_takes_whole_fixed_steps_then_a_shorter_one(exported):
    """A step that is not a whole multiple of the fixed step (a master's last step to its stop time, a
    variable-step master's) takes the whole fixed steps and one shorter Rosenbrock step: fmpy to the Python
    run's own last sample (6.8719... s, its distance stop's shortened interval) gives every row of that run,
    the last one too; at an output interval of 0.0137 s to 6.8719 s, the Python run's pose and speed."""
    # (the FMU controls its steps' error as the Python run does)
    sc = load_scenario("validation", ["run.integrator=rosenbrock"])
    ref = simulate(sc)
    md = fmpy.read_model_description(str(exported.path))
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    stop = float(ref.t[-1])
    assert 6.8719 < stop < 6.872
    res = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=stop, output_interval=sc.run.output_dt_s,
                            input=torque_signal(sc, stop), output=outs)
    assert len(res) == len(ref.t) and np.allclose(res["time"], ref.t, rtol=0, atol=1e-9)
    worst = {n: float(np.max(np.abs(res[n] - ref.column(n))) / max(float(np.max(np.abs(ref.column(n)))), 1e-300))
             for n in outs}
    assert max(worst.values()) <= REL_TOL, {k: v for k, v in worst.items() if not v <= REL_TOL}  # measured 8.7e-14
    odd = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=6.8719, output_interval=0.0137,
                            input=torque_signal(sc, 6.8719), output=outs)
    assert odd["time"][-1] == pytest.approx(6.8719, abs=1e-12) and len(odd) > 500
    for name in ("x_m", "y_m", "yaw_rad", "u_m_s"):  # other steps, the same motion (measured 2.3e-6 relative)
        col = ref.column(name)
        assert odd[name][-1] == pytest.approx(np.interp(6.8719, ref.t, col), abs=1e-4 * np.max(np.abs(col))), name
    # one step shorter than a fixed step, one of 1.5: fine; a step that is not a positive time is fmi2Error
    unzipped = fmpy.extract(str(exported.path))
    slave = fmpy.fmi2.FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="a")
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.doStep(0.0, 0.004)
        slave.doStep(0.004, 0.015)
        assert slave.getRealStatus(fmpy.fmi2.fmi2LastSuccessfulTime) == pytest.approx(0.019, abs=1e-15)
        with pytest.raises(FMICallException):
            slave.doStep(0.019, 0.0)
    finally:
        slave.freeInstance()


@pytest.mark.parametrize(("name", "overrides", "message"), [
    ("validation_grid", ["terrain.passes=2"], "terrain.passes = 2"),  # the engine FMU's (tests/test_engine_fmu.py)
    ("validation", ["run.integrator=cvodes"], "run.integrator = 'cvodes'"),
    ("validation", "torque at 4.005 s", "torque[1].t_s = 4.005"),
    ("validation", ["run.output_dt_s=0.015"], "run.output_dt_s = 0.015"),
])
def test_what_the_fmu_cannot_represent_is_refused_before_any_build(tmp_path, name, overrides, message):
    n_builds = len(toolchain.builds)
    out = tmp_path / "x.fmu"
    if overrides == "torque at 4.005 s":  # a torque change between two fixed steps of 10 ms
        sc = load_scenario(name)
        sc = dataclasses.replace(sc, torque=(sc.torque[0], dataclasses.replace(sc.torque[1], t_s=4.005)))
    else:
        sc = load_scenario(name, overrides)
    with pytest.raises(ScenarioError) as info:
        fmu_export.export_fmu(sc, out)
    assert message in str(info.value)
    assert not out.exists() and len(toolchain.builds) == n_builds


def test_an_unwritable_output_is_refused_before_any_build(tmp_path):
    n_builds = len(toolchain.builds)
    blocker = tmp_path / "file"
    blocker.write_text("")
    for out, message in ((blocker / "x.fmu", "is an existing file"), (tmp_path, "is a folder"),
                         (tmp_path / "x.zip", "ends in .fmu"), (Path("/proc/x.fmu"), "cannot write into")):
        with pytest.raises(ScenarioError) as info:
            fmu_export.export_fmu("validation", out)
        assert message in str(info.value)
    assert len(toolchain.builds) == n_builds


def test_reset_reruns_the_same_steps_and_a_wrong_guid_is_refused(exported):
    md = fmpy.read_model_description(str(exported.path))
    unzipped = fmpy.extract(str(exported.path))
    slave = fmpy.fmi2.FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="a")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave.instantiate()
    try:
        runs = []
        for _ in range(2):
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.setReal([vr["torque_cmd_left_N_m"]], [1500.0])
            slave.exitInitializationMode()
            for k in range(20):
                slave.doStep(0.01 * k, 0.01)
            runs.append(slave.getReal([vr["x_m"], vr["omega_left_rad_s"], vr["tractive_left_N"]]))
            with pytest.raises(FMICallException):  # a parameter is fixed after initialization
                slave.setReal([vr["mass_kg"]], [1.0])
            slave.reset()
        assert runs[0] == runs[1] and runs[0][0] > 0
    finally:
        slave.freeInstance()
    wrong = fmpy.fmi2.FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzipped,
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="b")
    with pytest.raises(Exception, match="instantiate"):
        wrong.instantiate()


def test_the_cli_refuses_a_grid_scenario_it_cannot_represent_with_exit_2(tmp_path, capsys):
    from symtrack.cli import main

    out = tmp_path / "g.fmu"
    assert main(["export", "fmu", "validation_grid", "--out", str(out), "--set", "terrain.passes=2"]) == 2
    assert "terrain.passes = 2" in capsys.readouterr().err and not out.exists()
