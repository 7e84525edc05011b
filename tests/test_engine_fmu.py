"""The engine FMU of ``symtrack export fmu`` for a grid scenario (symtrack/codegen/engine_fmu.py; docs/codegen.md,
"The FMU") and the raw field file it reads and writes (symtrack/terrain/fieldfile.py; docs/terrain.md,
"Files"), checked by an independent importer, fmpy: its validation finds no problem; its co-simulation of
validation_grid (subsoil off) with the scenario's torque programme gives the Python run through the
terrain engine (grid_fast) on every output column; the field the FMU writes at fmi2Terminate, converted to
npz, is the Python run's field; a second run from that field file is Python's second pass from the same
terrain file. The FMU runs the same C as the engine library (grid_engine.c and the same generated
Functions; -O2 -std=c99 against the library's -O3 -march=native, both without FMA contraction): measured
on the development machine, identical to the last bit, and asserted so. Bad field files are fmi2Error
with a logged message."""

from __future__ import annotations

import dataclasses
import itertools
import shutil
import struct
import subprocess
import zipfile

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
from symtrack.simulation.scenario import load_scenario
from symtrack.terrain import fieldfile, storage
from symtrack.toolchain import find_compiler

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")

# a pass without the distance stop (the FMU's master ends the run): 4 s at 2000 N m, 2 s with the left idle
PASS = ["run.duration_s=6.0", "run.stop_after_distance_m=1000"]
REL_TOL = 1e-6
# the engine's storage arrays, then the subsoil records a pass's end folds into (stress, compression state)
STORAGE = ("z", "zdot", "zmax", "pmax", "zoff", "cycles", "phase", "sigma_max", "specific_volume")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("enginefmu") / "validation_grid.fmu"
    return fmu_export.export_fmu("validation_grid", out)  # as shipped: four subsoil depths, the bulk density




def _outputs(path):
    md = fmpy.read_model_description(str(path))
    return [v.name for v in md.modelVariables if v.causality == "output"]


def _cosimulate(exported, sc, stop_s, **start):
    return fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=stop_s, output_interval=sc.run.macro_step_s,
                             input=torque_signal(sc, stop_s), output=_outputs(exported.path),
                             start_values=start)


def _master(exported, sc, stop_s, strings=(), reals=()):
    """A co-simulation master of our own on fmpy's FMU2Slave: the scenario's torques set exactly at every
    macro step (simulate_fmu interpolates its input table, w0 v0 + w1 v1, which moves a held torque by an
    ulp between two table rows); returns {"time": ..., output name: ...} at the start and every step."""
    md = fmpy.read_model_description(str(exported.path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = _outputs(exported.path)
    slave = fmpy.fmi2.FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(exported.path)),
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="master")
    dt = sc.run.macro_step_s
    n = int(round(stop_s / dt))
    rows = []
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        for name, value in dict(strings).items():
            slave.setString([vr[name]], [value])
        for name, value in dict(reals).items():
            slave.setReal([vr[name]], [value])
        slave.exitInitializationMode()
        for k in range(n + 1):
            slave.setReal([vr["torque_cmd_left_N_m"], vr["torque_cmd_right_N_m"]], list(sc.torque_at(k * dt)))
            rows.append([k * dt, *slave.getReal([vr[o] for o in outs])])
            if k < n:
                slave.doStep(k * dt, dt)
        slave.terminate()
    finally:
        slave.freeInstance()
    data = np.array(rows)
    return {"time": data[:, 0], **{o: data[:, 1 + i] for i, o in enumerate(outs)}}


def _worst(res, run, outs, idx=slice(None)):
    worst = {}
    for name in outs:
        a, b = res[name], run.column(name)[idx]
        assert a.shape == b.shape, name
        worst[name] = float(np.max(np.abs(a - b)))
    return worst


def test_fmpy_validation_finds_no_problem_and_it_links_only_libc_and_libm(exported):
    assert validate_fmu(str(exported.path)) == []
    with zipfile.ZipFile(exported.path) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", "binaries/linux64/symtrack_grid_engine.so", "sources/symtrack_fmu.c",
            "sources/grid_engine.c", "sources/engine_gen.inc", "sources/engine_fmu_model.h",
            "sources/fmi2Functions.h"} <= names
    md = fmpy.read_model_description(str(exported.path))
    assert md.guid == exported.guid
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["torque_cmd_left_N_m"].causality == "input" and by_name["torque_cmd_left_N_m"].unit == "N m"
    assert by_name["start_y_m"].causality == "parameter" and by_name["start_y_m"].unit == "m"
    for name in ("field_file", "field_file_out"):
        assert by_name[name].type == "String" and by_name[name].causality == "parameter"
    assert by_name["sinkage_sprocket_left_m"].unit == "m" and by_name["compaction_power_W"].unit == "W"
    assert len(_outputs(exported.path)) == 12 + 25
    if shutil.which("ldd") is None:
        pytest.skip("no ldd")
    out = subprocess.run(["ldd", str(exported.binary)], capture_output=True, text=True).stdout
    libs = {line.split()[0] for line in out.splitlines() if "=>" in line}
    assert libs <= {"libm.so.6", "libc.so.6"}, out


@pytest.fixture(scope="module")
def python_run():
    sc = load_scenario("validation_grid")
    return sc, simulate(sc).runs[0]


def test_fmpy_cosimulation_is_the_python_engine_run(exported, python_run):
    sc, run = python_run
    # Python stops 20 m after the idle event, its last step shortened (secant); the FMU runs the whole
    # macro steps before it (its master decides when to stop)
    dt = sc.run.macro_step_s
    n_full = int(np.floor(run.t[-1] / dt + 1e-9))
    assert run.stopped_by == "distance" and len(run.t) == n_full + 2
    res = _cosimulate(exported, sc, n_full * dt)
    assert len(res) == n_full + 1 and np.allclose(res["time"], run.t[:-1], rtol=0, atol=1e-9)
    outs = _outputs(exported.path)
    assert len(outs) == 37
    # fmpy's simulate_fmu: within 1e-6 relative to each column's largest magnitude (the criterion)
    worst = {k: v / max(float(np.max(np.abs(run.column(k)))), 1e-300)
             for k, v in _worst(res, run, outs, slice(0, n_full + 1)).items()}
    assert not {k: v for k, v in worst.items() if not v <= REL_TOL}
    # with the torques held exactly (our master on fmpy's slave): the same C gives the same numbers
    mine = _master(exported, sc, n_full * dt)
    assert _worst(mine, run, outs, slice(0, n_full + 1)) == dict.fromkeys(outs, 0.0)


def test_a_second_importer_finds_it_compliant_and_its_container_steps_it_as_fmpy_does(exported, tmp_path):
    """fmu-manipulation-toolbox (tests/fmi_second_importer.py): compliant with the FMI 2.0 XSD, no semantic
    error; its container's C runtime stepping the engine FMU every macro step (a virgin field: the
    string parameters' start values) gives fmpy's direct co-simulation on every output column to 1e-9
    relative."""
    check(exported.path)
    sc = load_scenario("validation_grid")
    wrapped = container(exported.path, sc.run.macro_step_s, tmp_path / "container")
    stop, dt = 2.0, sc.run.macro_step_s
    outs = _outputs(exported.path)
    direct, via = (fmpy.simulate_fmu(str(p), start_time=0.0, stop_time=stop, output_interval=dt,
                                     input=torque_signal(sc, stop), output=outs) for p in (exported.path, wrapped))
    assert len(direct) == len(via) == round(stop / dt) + 1
    worst = {n: float(np.max(np.abs(via[n] - direct[n])) / max(float(np.max(np.abs(direct[n]))), 1e-300))
             for n in outs}
    assert len(worst) == 37 and max(worst.values()) < 1e-9, {k: v for k, v in worst.items() if not v < 1e-9}


def test_the_field_written_at_terminate_is_the_python_runs_and_a_second_pass_from_it_too(exported, tmp_path):
    from symtrack.cli import main

    sc = load_scenario("validation_grid", PASS)
    ref = simulate(sc)
    py_npz = tmp_path / "python.npz"
    ref.terrain.save(py_npz, soil=sc.params)
    out1 = tmp_path / "pass1.field"
    res = _master(exported, sc, sc.run.duration_s, {"field_file_out": str(out1)})
    assert _worst(res, ref.runs[0], _outputs(exported.path)) == dict.fromkeys(_outputs(exported.path), 0.0)
    # the FMU's field, converted to npz by the CLI, is the Python run's, bit for bit
    assert main(["terrain", "convert", str(out1), str(tmp_path / "fmu.npz")]) == 0
    mine, theirs = storage.load(tmp_path / "fmu.npz", sc.params), storage.load(py_npz, sc.params)
    for name in STORAGE:
        a, b = getattr(mine, name), getattr(theirs, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert np.count_nonzero(theirs.phase) > 1000 and np.count_nonzero(theirs.specific_volume) > 1000
    assert mine.grid == theirs.grid and mine.subsoil_depths_m == theirs.subsoil_depths_m == (0.1, 0.3, 0.5, 0.8)
    # the second pass: the FMU from its own field file, Python from its own terrain file
    ref2 = simulate(sc, terrain=py_npz)
    out2 = tmp_path / "pass2.field"
    shutil.copy(out1, out2)  # field_file_out = field_file: the file is replaced at terminate
    res2 = _master(exported, sc, sc.run.duration_s, {"field_file": str(out2), "field_file_out": str(out2)})
    worst = _worst(res2, ref2.runs[0], _outputs(exported.path))
    assert not {k: v for k, v in worst.items() if v != 0.0}
    # the rut made the second pass different from the first
    assert np.max(np.abs(res2["sinkage_sprocket_left_m"] - res["sinkage_sprocket_left_m"])) > 1e-4
    second = fieldfile.read_field(out2)
    for name in STORAGE:
        assert np.array_equal(getattr(second, name), getattr(ref2.terrain, name)), name
    # the second pass compacted the subsoil further
    assert np.count_nonzero(second.specific_volume != mine.specific_volume) > 0


def test_the_start_pose_is_a_parameter(exported):
    sc = load_scenario("validation_grid", [*PASS, "run.duration_s=1.0", "start.y_m=5.0", "start.yaw_deg=30"])
    ref = simulate(sc)
    res = _master(exported, sc, 1.0, reals={"start_y_m": 5.0, "start_yaw_rad": float(np.radians(30.0))})
    assert res["y_m"][0] == 5.0
    assert _worst(res, ref.runs[0], _outputs(exported.path)) == dict.fromkeys(_outputs(exported.path), 0.0)


def _slave(exported, name="a"):
    md = fmpy.read_model_description(str(exported.path))
    slave = fmpy.fmi2.FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(exported.path)),
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return slave, vr


def _start_with_field(exported, path):
    slave, vr = _slave(exported)
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setString([vr["field_file"]], [str(path)])
        with pytest.raises(FMICallException):
            slave.exitInitializationMode()
    finally:
        slave.freeInstance()


@pytest.mark.parametrize("damage", ["shape", "origin", "magic", "truncated", "soil", "phase", "depths", "stress",
                                    "missing", "version1", "law", "foreign"])
def test_a_bad_field_file_is_an_fmi2_error_with_a_logged_message(exported, tmp_path, capsys, damage):
    sc = load_scenario("validation_grid")
    g = storage.Grid((-50.0, -50.0), 0.1, (1000, 1000))
    path = tmp_path / "bad.field"
    expect = {"shape": "a field of 10 x 1000 cells; this FMU's field has 1000 x 1000",
              "origin": "origin (-40, -50) m", "magic": "not a symtrack field file",
              "truncated": "the file is truncated or damaged", "soil": "the field was made with soil bekker_n",
              "phase": "phase of cell 7 is 3", "depths": "1 subsoil depths, this FMU has 4",
              "stress": "sigma_max_Pa of cell 2 at depth 1 is -1", "missing": "cannot open it",
              "version1": "field file version 1, this FMU reads 2 (a version-1 file, which does not name its soil",
              "law": "the field was made with the soil law linear_plastic, this FMU's is bekker_wong",
              "foreign": "the field file holds soil parameter 'bekker_q' that this FMU's soil law does not read",
              }[damage]
    depths = (0.2,) if damage == "depths" else sc.terrain.subsoil_depths_m
    if damage == "missing":
        path = tmp_path / "none.field"
    else:
        if damage == "shape":
            g = dataclasses.replace(g, shape=(10, 1000))
        if damage == "origin":
            g = dataclasses.replace(g, origin_m=(-40.0, -50.0))
        soil = dict(sc.params)
        if damage == "soil":
            soil["bekker_n"] *= 1.01
        field = storage.Terrain(g, subsoil_depths_m=depths)
        if damage == "stress":
            field.sigma_max[2, 1] = -1.0
            # written past the Python writer's checks: what a damaged or foreign file holds
        data = bytearray(fieldfile.field_bytes(field, soil))
        if damage == "magic":
            data[:8] = b"NOTFIELD"
        if damage == "truncated":
            data = data[:-9]
        if damage == "phase":
            data[-8 - 8 * 4 * g.n_cells - g.n_cells + 7] = 3
        if damage in ("law", "foreign"):  # the parameter layout names another law, or a value no law reads
            _rename_in_layout(data, "bekker_wong" if damage == "law" else "bekker_n",
                              "linear_plastic" if damage == "law" else "bekker_q")
        if damage == "version1":
            data = bytearray(_version1(bytes(data)))
        path.write_bytes(bytes(data))
    _start_with_field(exported, path)
    assert expect in capsys.readouterr().out


def test_a_start_pose_off_the_field_is_an_fmi2_error_at_initialisation(exported, capsys):
    slave, vr = _slave(exported)
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setReal([vr["start_x_m"]], [49.5])  # the field ends at x = 50 m: the tracks reach past it
        with pytest.raises(FMICallException):
            slave.exitInitializationMode()
        assert "the set-down at t = 0 s: the vehicle left the terrain field" in capsys.readouterr().out
    finally:
        slave.freeInstance()


def test_any_communication_step_takes_whole_macro_steps_then_a_shorter_one(exported, python_run):
    """A step that is not a whole number of macro steps runs the whole ones and one shorter step of the
    engine: fmpy to the Python run's own last sample (its distance stop's shortened step) gives every row
    of that run, the last one too (measured 9e-14 relative); at an output interval of 0.0137 s, the same
    end pose and speed; a step that is not a positive time is fmi2Error."""
    sc, run = python_run
    stop = float(run.t[-1])
    outs = _outputs(exported.path)
    res = _cosimulate(exported, sc, stop)
    assert len(res) == len(run.t) and np.allclose(res["time"], run.t, rtol=0, atol=1e-9)
    worst = {k: v / max(float(np.max(np.abs(run.column(k)))), 1e-300) for k, v in _worst(res, run, outs).items()}
    assert not {k: v for k, v in worst.items() if not v <= REL_TOL}
    odd = fmpy.simulate_fmu(str(exported.path), start_time=0.0, stop_time=stop, output_interval=0.0137,
                            input=torque_signal(sc, stop), output=outs)
    assert odd["time"][-1] == pytest.approx(stop, abs=1e-12) and len(odd) > 500
    for name in ("x_m", "y_m", "yaw_rad", "u_m_s"):
        col = run.column(name)
        assert odd[name][-1] == pytest.approx(col[-1], abs=1e-4 * np.max(np.abs(col))), name
    slave, vr = _slave(exported)
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.doStep(0.0, 0.02)  # two macro steps
        slave.doStep(0.02, 0.015)  # one and a half
        assert slave.getReal([vr["x_m"]])[0] > 0.0
        assert slave.getRealStatus(fmpy.fmi2.fmi2LastSuccessfulTime) == pytest.approx(0.035, abs=1e-15)
        with pytest.raises(FMICallException):
            slave.doStep(0.035, -0.01)
        with pytest.raises(FMICallException):  # the field files are fixed after initialization
            slave.setString([vr["field_file"]], ["x.field"])
    finally:
        slave.freeInstance()


def test_field_files_convert_both_ways_bit_for_bit_and_refuse_what_they_cannot_carry(tmp_path):
    sc = load_scenario("validation_grid", [*PASS, "run.duration_s=2.0"])
    st = simulate(sc).terrain
    assert np.count_nonzero(st.sigma_max) > 1000
    fieldfile.write_field(tmp_path / "a.field", st, sc.params)
    back = fieldfile.read_field(tmp_path / "a.field")
    for name in STORAGE:
        assert np.array_equal(getattr(back, name), getattr(st, name)) and getattr(back, name).dtype == getattr(
            st, name).dtype, name
    assert back.grid == st.grid and back.soil == {k: float(sc.params[k]) for k in back.soil}
    assert back.subsoil_depths_m == st.subsoil_depths_m == (0.1, 0.3, 0.5, 0.8)
    assert (tmp_path / "a.field").stat().st_size == 64 + 8 * (len(back.soil) + 4) + 64 * (1 + len(back.soil)) + (
        43 + 32) * st.grid.n_cells + 8
    assert back.soil_law == sc.model.soil_law == "bekker_wong"
    # the file names each value: its values in another order read the same; a version-1 file (no names, the
    # values in FIELD_V1_SOIL_NAMES order) too; one of another soil law, or naming a value no law reads, is refused
    data = (tmp_path / "a.field").read_bytes()
    hbytes, n_soil, n_depths, off = _layout(data)
    perm = list(reversed(range(n_soil)))
    shuffled = bytearray(data[:64] + b"".join(data[64 + 8 * k:72 + 8 * k] for k in perm)
                         + data[64 + 8 * n_soil:off + 64]
                         + b"".join(data[off + 64 * (1 + k):off + 64 * (2 + k)] for k in perm) + data[hbytes:])
    assert bytes(shuffled) != data
    (tmp_path / "shuffled.field").write_bytes(bytes(shuffled))
    (tmp_path / "v1.field").write_bytes(_version1(data))
    for other in ("shuffled.field", "v1.field"):
        again = fieldfile.read_field(tmp_path / other)
        assert again.soil == back.soil and again.soil_law == "bekker_wong", other
        assert all(np.array_equal(getattr(again, n), getattr(back, n)) for n in STORAGE), other
    for old, new, match in (("bekker_wong", "linear_plastic", "soil law 'linear_plastic', which this symtrack"),
                            ("bekker_n", "bekker_q", "soil parameter\\(s\\) bekker_q, which the soil law")):
        bad = bytearray(data)
        _rename_in_layout(bad, old, new)
        (tmp_path / "bad.field").write_bytes(bytes(bad))
        with pytest.raises(ScenarioError, match=match):
            fieldfile.read_field(tmp_path / "bad.field")
    fieldfile.convert(tmp_path / "a.field", tmp_path / "a.npz")  # and back through npz: the same bytes
    fieldfile.convert(tmp_path / "a.npz", tmp_path / "a2.field")
    assert (tmp_path / "a2.field").read_bytes() == (tmp_path / "a.field").read_bytes()
    st.set_elevation(np.zeros(st.grid.n_cells))
    with pytest.raises(ScenarioError, match="elevation"):
        fieldfile.write_field(tmp_path / "b.field", st, sc.params)
    with pytest.raises(ScenarioError, match="by the suffixes"):
        fieldfile.convert(tmp_path / "a.field", tmp_path / "c.field")


@pytest.mark.parametrize(("overrides", "message"), [
    (["run.integrator=idas"], "run.integrator = 'idas'"),
    (["terrain.passes=2"], "terrain.passes = 2"),
    ("soil map", "terrain.soil_map is set"),
    ("initial state", "terrain.initial_state = 'x.npz'"),
    ("torque at 4.005 s", "torque[1].t_s = 4.005"),
])
def test_what_the_engine_fmu_cannot_represent_is_refused_before_any_build(tmp_path, overrides, message):
    n_builds = len(toolchain.builds)
    out = tmp_path / "x.fmu"
    if isinstance(overrides, str):
        sc = load_scenario("validation_grid")
        if overrides == "soil map":
            sc = dataclasses.replace(sc, terrain=dataclasses.replace(sc.terrain, soil_map="map.toml"))
        elif overrides == "initial state":
            sc = dataclasses.replace(sc, terrain=dataclasses.replace(sc.terrain, initial_state="x.npz"))
        else:
            sc = dataclasses.replace(sc, torque=(sc.torque[0], dataclasses.replace(sc.torque[1], t_s=4.005)))
    else:
        sc = load_scenario("validation_grid", overrides)
    with pytest.raises(ScenarioError) as info:
        fmu_export.export_fmu(sc, out)
    assert message in str(info.value)
    assert not out.exists() and len(toolchain.builds) == n_builds


def test_reset_reruns_the_same_pass_and_an_unwritable_field_file_out_is_an_fmi2_error(exported, tmp_path, capsys):
    slave, vr = _slave(exported)
    slave.instantiate()
    try:
        runs = []
        for out in (tmp_path / "a.field", tmp_path / "no" / "such" / "folder" / "b.field"):
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.setString([vr["field_file_out"]], [str(out)])
            slave.exitInitializationMode()
            for k in range(50):
                slave.doStep(0.01 * k, 0.01)
            runs.append(slave.getReal([vr["x_m"], vr["sinkage_idler_left_m"], vr["compaction_power_W"]]))
            if out.parent == tmp_path:
                slave.terminate()
                assert fieldfile.read_field(out).phase.any()
            else:
                with pytest.raises(FMICallException):
                    slave.terminate()
                assert "field_file_out" in capsys.readouterr().out and not out.exists()
            slave.reset()
        assert runs[0] == runs[1] and runs[0][0] > 0
    finally:
        slave.freeInstance()


def test_without_the_subsoil_stress_the_fmu_and_its_field_file_leave_it_out(tmp_path):
    """The FMU of a scenario with terrain.subsoil_depths_m = [] (no tables compiled, a field file of 43
    bytes per cell): still the Python run, outputs and field, bit for bit."""
    off = ["terrain.subsoil_depths_m=[]"]
    exported = fmu_export.export_fmu("validation_grid", tmp_path / "off.fmu", off)
    sc = load_scenario("validation_grid", [*PASS, *off, "run.duration_s=2.0"])
    ref = simulate(sc)
    out = tmp_path / "off.field"
    res = _master(exported, sc, 2.0, {"field_file_out": str(out)})
    assert _worst(res, ref.runs[0], _outputs(exported.path)) == dict.fromkeys(_outputs(exported.path), 0.0)
    field = fieldfile.read_field(out)
    assert field.subsoil_depths_m == () and out.stat().st_size == 64 + 8 * len(field.soil) + 64 * (
        1 + len(field.soil)) + 43 * 10**6 + 8
    for name in STORAGE:
        assert np.array_equal(getattr(field, name), getattr(ref.terrain, name)), name
    # a field file with the subsoil records does not fit this FMU
    rich = storage.Terrain(field.grid, subsoil_depths_m=(0.1, 0.3, 0.5, 0.8))
    (tmp_path / "rich.field").write_bytes(fieldfile.field_bytes(rich, sc.params))
    _start_with_field(exported, tmp_path / "rich.field")


# a soil with O'Sullivan & Robertson's yield line and a saturation bound that binds under the crawler
# (test values for the validation soil's lines: k2 between its kappa 0.042 and lambda 0.193), and a denser,
# drier subsoil layer below 0.3 m (its own initial state, lines and strength at the deeper depths)
YIELD = ["soil.yield_line_offset_ln_p=1.3", "soil.yield_compression_index_k2=0.09", "soil.specific_volume_min=1.6",
         "soil.subsoil_bulk_density_initial_Mg_per_m3=1.4", "soil.subsoil_matric_suction_kPa=6"]


def test_the_yield_line_and_the_saturation_bound_fold_as_python_does_bit_for_bit(tmp_path):
    """The C port of density.load_update (the yield line's k2 path, the saturation bound, each depth's
    layer) in the FMU's end of pass: two passes, the compression state equal to the Python run's to the
    last bit."""
    sc = load_scenario("validation_grid", PASS + YIELD)
    from symtrack.soil import density

    layers = density.soil_arrays([sc.params], sc.terrain.subsoil_depths_m)
    assert not layers["top"][0].all() and len(set(layers["v0"][0])) == 2 and len(set(layers["pc"][0])) == 2
    exported = fmu_export.export_fmu(sc, tmp_path / "yield.fmu")
    ref = simulate(sc)
    py_npz = tmp_path / "python.npz"
    ref.terrain.save(py_npz, soil=sc.params)
    ref2 = simulate(sc, terrain=py_npz)
    field = tmp_path / "pass.field"
    _master(exported, sc, sc.run.duration_s, {"field_file_out": str(field)})
    first = fieldfile.read_field(field)
    assert np.array_equal(first.specific_volume, ref.terrain.specific_volume)
    _master(exported, sc, sc.run.duration_s, {"field_file": str(field), "field_file_out": str(field)})
    second = fieldfile.read_field(field)
    assert np.array_equal(second.specific_volume, ref2.terrain.specific_volume)
    # both branches were taken: the second pass at the same stress compacted further (the yield line),
    # and some states sit on the saturation bound's rebound line (v1 = v_min + kappa ln p > the k2 path)
    moved = ref2.terrain.specific_volume != ref.terrain.specific_volume
    assert np.count_nonzero(moved) > 100
    assert np.all(second.specific_volume[second.specific_volume > 0] >= 1.6)


def _layout(data: bytes):
    """(header bytes, n_soil, n_depths, offset of the names) of a version-2 field file."""
    hbytes, n_soil, n_depths = (struct.unpack_from("<I", data, k)[0] for k in (12, 56, 60))
    return hbytes, n_soil, n_depths, 64 + 8 * (n_soil + n_depths)


def _rename_in_layout(data: bytearray, old: str, new: str) -> None:
    """The name ``old`` of a version-2 field file's parameter layout replaced by ``new``, in place."""
    _, n_soil, _, off = _layout(bytes(data))
    for k in range(1 + n_soil):
        at = off + fieldfile.FIELD_NAME_BYTES * k
        if bytes(data[at:at + fieldfile.FIELD_NAME_BYTES]).rstrip(b"\0") == old.encode():
            data[at:at + fieldfile.FIELD_NAME_BYTES] = new.encode().ljust(fieldfile.FIELD_NAME_BYTES, b"\0")
            return
    raise AssertionError(f"{old} is not in the layout")


def _version1(data: bytes) -> bytes:
    """A version-2 field file as version 1 wrote it: its values in FIELD_V1_SOIL_NAMES order, no names."""
    hbytes, n_soil, n_depths, off = _layout(data)
    names = [data[off + 64 * k:off + 64 * (k + 1)].rstrip(b"\0").decode() for k in range(1, 1 + n_soil)]
    values = dict(zip(names, struct.unpack_from(f"<{n_soil}d", data, 64), strict=True))
    v1 = [n for n in fieldfile.FIELD_V1_SOIL_NAMES if n in values]
    out = bytearray(data[:64] + struct.pack(f"<{len(v1)}d", *(values[n] for n in v1)) + data[64 + 8 * n_soil:off]
                    + data[hbytes:])
    struct.pack_into("<I", out, 8, 1)
    struct.pack_into("<I", out, 12, 64 + 8 * (len(v1) + n_depths))
    struct.pack_into("<I", out, 56, len(v1))
    return bytes(out)


def _older_field(src, dst, drop):
    """A field file as a symtrack before the last ``drop`` soil parameters were added wrote it: those
    values and their names cut from the header (n_soil and the header's size adjusted), the arrays as
    they were."""
    data = bytes(src.read_bytes())
    hbytes, n_soil, n_depths, off = _layout(data)
    keep = n_soil - drop
    out = bytearray(data[:64 + 8 * keep] + data[64 + 8 * n_soil:off] + data[off:off + 64 * (1 + keep)]
                    + data[hbytes:])
    struct.pack_into("<I", out, 12, hbytes - (8 + 64) * drop)
    struct.pack_into("<I", out, 56, keep)
    dst.write_bytes(bytes(out))


def test_a_field_file_written_before_the_soil_description_loads_with_the_defaults(exported, tmp_path):
    """Field files of an older symtrack (without the four parameters of the soil's description and the
    subsoil layer's, appended to the list) load in Python with the registry's defaults of those and the
    subsoil's description its topsoil's, every other value and array the same; a file lacking a parameter
    that has neither is refused."""
    from symtrack.model.parameters import SOIL_PARAM_NAMES
    from symtrack.soil.pedotransfer import DESCRIPTION_KEYS, SUBSOIL_KEYS

    sc = load_scenario("validation_grid", PASS)
    full = tmp_path / "full.field"
    _master(exported, sc, 1.0, {"field_file_out": str(full)})
    old = tmp_path / "old.field"
    added = SOIL_PARAM_NAMES[SOIL_PARAM_NAMES.index(DESCRIPTION_KEYS[0]):]
    assert set(added) == set(DESCRIPTION_KEYS) | set(SUBSOIL_KEYS.values()) | {"subsoil_top_m"}
    _older_field(full, old, len(added))
    a, b = fieldfile.read_field(full), fieldfile.read_field(old)
    assert {k: v for k, v in a.soil.items() if k not in added} == {k: v for k, v in b.soil.items() if k not in added}
    assert all(b.soil[k] == storage.spec(k).default for k in DESCRIPTION_KEYS + ("subsoil_top_m",))
    assert all(b.soil[sub] == b.soil[top] for top, sub in SUBSOIL_KEYS.items())
    for name in STORAGE:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # cut further, into parameters without a default: refused by both
    n_defaulted = len(list(itertools.takewhile(lambda n: storage.spec(n).default is not None
                                               or n in fieldfile.SAME_AS_TOPSOIL, reversed(SOIL_PARAM_NAMES))))
    bad = tmp_path / "bad.field"
    _older_field(full, bad, n_defaulted + 1)
    with pytest.raises(ScenarioError, match="soil values"):
        fieldfile.read_field(bad)
    with pytest.raises(FMICallException):
        _master(exported, sc, 1.0, {"field_file": str(bad)})


def test_the_soil_is_a_parameter_and_a_changed_value_runs_as_the_python_engine_does(exported, capsys):
    """The soil's run-time values are Real parameters with their units and ranges: a soil law coefficient
    and a traction value set on the FMU give the Python engine's run with the same values in the scenario,
    bit for bit (the law row computed in the FMU by the law's generated vector); a value outside its range
    is an fmi2Error."""
    md = fmpy.read_model_description(str(exported.path))
    by_name = {v.name: v for v in md.modelVariables}
    k_phi = by_name["k_phi_N_per_m_n2"]
    assert k_phi.causality == "parameter" and k_phi.variability == "fixed" and k_phi.unit == "N/m^(n+2)"
    assert float(k_phi.min) == 0.0 and float(k_phi.max) == 1e12
    assert float(by_name["bekker_n"].max) == 3.0 and by_name["cohesion_Pa"].unit == "Pa"
    changed = {"k_phi_N_per_m_n2": 1.2e6, "cohesion_Pa": 2000.0}
    sc = load_scenario("validation_grid", [*PASS, "run.duration_s=1.0",
                                           *(f"soil.{k}={v!r}" for k, v in changed.items())])
    ref = simulate(sc).runs[0]
    res = _master(exported, sc, 1.0, reals=changed)
    outs = _outputs(exported.path)
    assert _worst(res, ref, outs) == dict.fromkeys(outs, 0.0)
    exported_soil = _master(exported, sc, 1.0)
    z = exported_soil["sinkage_sprocket_left_m"]
    assert np.max(np.abs(res["sinkage_sprocket_left_m"] - z)) > 0.1 * np.max(np.abs(z))  # a stiffer soil sinks less
    slave, vr = _slave(exported)
    slave.instantiate()
    try:
        with pytest.raises(FMICallException):
            slave.setReal([vr["bekker_n"]], [5.0])
    finally:
        slave.freeInstance()
    assert "bekker_n = 5 is outside its range (0, 3]" in capsys.readouterr().out
