"""What a newcomer met following the getting-started tutorial: a parameter named in another unit is
refused with the name it should have, and the starting files carry no measured speeds (the
documentation's performance page has them, measured on the reader's kind of machine)."""

from __future__ import annotations

import re
from importlib import resources

import pytest

import symtrack
from symtrack.foundations.config import key_hints
from symtrack.foundations.errors import ParameterError, ScenarioError
from symtrack.presets.catalog import read_preset_file


def test_key_hints_name_the_key_in_its_unit():
    allowed = ["preset", "cohesion_Pa", "friction_angle_rad", "mass_kg"]
    assert "did you mean friction_angle_rad (in radians" in key_hints(["friction_angle_deg"], allowed)
    assert "did you mean cohesion_Pa (in Pa)" in key_hints(["cohesion_kPa"], allowed)
    assert "did you mean mass_kg" in key_hints(["mass"], allowed)
    assert "did you mean preset" in key_hints(["presett"], allowed)
    assert key_hints(["colour"], allowed) == ""


def test_a_soil_angle_in_degrees_is_refused_with_its_name_in_radians(tmp_path):
    f = tmp_path / "wet.toml"
    f.write_text('base = "clayey_soil_thailand_38"\nfriction_angle_deg = 18.0\n')
    with pytest.raises(ParameterError, match=r"friction_angle_deg: did you mean friction_angle_rad"):
        read_preset_file(f, "soil")
    with pytest.raises(ScenarioError, match=r"cohesion_kPa: did you mean cohesion_Pa"):
        symtrack.load_scenario("validation", ["soil.cohesion_kPa=3"])


def test_the_starting_files_hold_no_measured_speed():
    for f in resources.files("symtrack.cli").joinpath("templates").iterdir():
        if f.name.endswith(".toml"):
            text = f.read_text(encoding="utf-8")
            assert not re.search(r"\d\s*x real time", text), f.name


def test_a_missing_terrain_file_from_python_names_the_argument(tmp_path):
    for path, what in ((tmp_path / "nothere.npz", "does not exist"), (tmp_path, "is a folder")):
        with pytest.raises(ScenarioError, match=r"^terrain = .* " + what) as err:
            symtrack.simulate("validation_grid", terrain=str(path))
        assert "initial_state" not in str(err.value)
        with pytest.raises(ScenarioError, match=what):
            symtrack.build("validation_grid", terrain=path)


def test_an_mpc_run_says_what_it_loads_before_the_solver(monkeypatch, tmp_path):
    """The seconds before the MPC's solver build (the modules, the run file, the vehicle model) are one
    step that says what it does once it passes half a second."""
    from contextlib import contextmanager

    from symtrack.cli.main import main
    from symtrack.control import scenario as mpc_scenario
    from symtrack.foundations import progress

    steps = []

    class Stop(Exception):
        pass

    @contextmanager
    def recorded(what, logger=None, slow_s=progress.SLOW_STEP_S):
        steps.append((what, slow_s))
        yield

    def stop(*a, **k):
        raise Stop

    monkeypatch.setattr(progress, "timed_step", recorded)
    monkeypatch.setattr(mpc_scenario, "load", stop)
    with pytest.raises(Stop):
        main(["mpc", "straight_offset", "--out", str(tmp_path / "o")])
    assert steps == [("loading straight_offset and building its vehicle model", 0.5)]


def test_symtrack_run_starts_without_matplotlib():
    """The front door reads its run file before any plotting module loads (matplotlib is a second of
    import: imported by the first run that draws)."""
    import subprocess
    import sys

    code = ("import sys, symtrack.studies.runfile, symtrack.cli.main, symtrack.studies.field, "
            "symtrack.studies.operations, symtrack.control.closedloop, symtrack.cli.control, symtrack.api; "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_season_animation_shows_every_operation():
    """A season's animation.gif: both operations in order on one time axis, the first's ruts kept while
    the second drives, each frame's path that of its own operation (no line from one's end to the next
    one's start)."""
    import io

    import numpy as np
    from PIL import Image

    from symtrack.studies import field_plots

    z = np.zeros((200, 100))
    z[20:180, 20:30] = z[20:180, 70:80] = 0.01
    first1 = np.full((200, 100), np.inf, np.float32)
    first1[20:180, 20:30] = np.linspace(0.0, 10.0, 160)[:, None]
    first2 = np.full((200, 100), np.inf, np.float32)
    first2[20:180, 70:80] = np.linspace(10.0, 0.0, 160)[:, None]  # driven from x = 18 m to 2 m
    traj1 = np.array([(t, 2.0 + 1.6 * t, 2.5, 0.0) for t in np.linspace(0.0, 10.0, 11)])
    traj2 = np.array([(t, 18.0 - 1.6 * t, 7.5, np.pi) for t in np.linspace(0.0, 10.0, 11)])
    gif = field_plots.season_gif(z, [("tillage", first1, traj1), ("drilling", first2, traj2)],
                                 (0.0, 20.0, 0.0, 10.0), "season", frames=6, blocks=100)
    im = Image.open(io.BytesIO(gif))
    assert im.n_frames == 6

    def shown(k):
        im.seek(k)
        a = np.asarray(im.convert("RGB"))[22:][::-1]  # rows: y up
        m = a.shape[1] // 20  # pixels per metre
        lane1 = a[int(2.5 * m):3 * m, 10 * m:15 * m]  # y 2.5-3 m, x 10-15 m
        lane2 = a[int(7.5 * m):8 * m, 10 * m:15 * m]
        return [float(np.mean(~np.all(lane == 225, axis=2))) for lane in (lane1, lane2)]

    early, mid, last = shown(0), shown(3), shown(5)
    assert early[0] < 0.5 and early[1] == 0.0  # the first operation under way, the second not begun
    assert mid[0] > 0.9 and 0.0 < mid[1] < 0.9  # the first's ruts kept while the second drives
    assert last[0] > 0.9 and last[1] > 0.9
    # the second operation's frames draw its own path only: nothing red where neither drove (y 5 m)
    im.seek(4)
    a = np.asarray(im.convert("RGB"))[22:][::-1]
    m = a.shape[1] // 20
    middle = a[int(4.5 * m):int(5.5 * m), 2 * m:19 * m].astype(int)
    assert not np.any((middle[..., 0] > 150) & (middle[..., 1] < 80)), "a line between the operations"


def test_a_simulation_report_says_what_ran():
    from symtrack.reports.run_files import what_ran

    sc = symtrack.load_scenario("validation", {"vehicle.mass_kg": 6500.0, "run.integrator": "cvodes"})
    assert what_ran(sc, {}) == ("Ran: reference_crawler, 6500 kg on clayey_soil_thailand_38, the homogeneous "
                                "terrain, integrator cvodes.")
    assert "the grid terrain, integrator grid_fast" in what_ran(symtrack.load_scenario("validation_grid"),
                                                                 {"integrator": "grid_fast"})


def test_a_pair_typed_without_brackets_says_how_to_write_it():
    from symtrack.foundations.config import list_hint
    from symtrack.studies.field import load_field_spec

    assert list_hint("field.size_m", "30,10") == " (on the command line, in brackets: --set 'field.size_m=[30, 10]')"
    assert list_hint("field.size_m", [30.0]) == ""
    with pytest.raises(ScenarioError, match=r"--set 'field.size_m=\[30, 10\]'"):
        load_field_spec("field_traffic", ["field.size_m=30,10"])


def test_a_field_study_report_says_what_ran(tmp_path):
    from symtrack.studies.field import _report, load_field_spec

    spec = load_field_spec("field_traffic", {"vehicle.mass_kg": 6500.0})
    page = _report(tmp_path, spec, {}, {"complete": True}, {"field.resolved.toml": "name = 'x'\n"})
    assert "Ran: reference_crawler, 6500 kg on clayey_soil_thailand_38, the grid terrain, integrator" in page


def test_writing_a_run_says_what_it_waits_for(monkeypatch, tmp_path):
    """Drawing a run's figures is seconds after the run (the grid's maps: several): one step that says so
    once it passes 2 s."""
    from contextlib import contextmanager
    from types import SimpleNamespace

    from symtrack import api
    from symtrack.cli.main import main
    from symtrack.foundations import progress

    steps, written = [], []

    @contextmanager
    def recorded(what, logger=None, slow_s=progress.SLOW_STEP_S):
        steps.append(what)
        yield

    res = SimpleNamespace(write=lambda out, terrain_out=None: written.append(steps[-1]), validation_table=None,
                          terrain=None, summary={"sim_time_s": 1.0, "wall_time_s": 1.0, "real_time_factor": 1.0})
    monkeypatch.setattr(progress, "timed_step", recorded)
    monkeypatch.setattr(api, "simulate", lambda sc, **k: res)
    out = tmp_path / "o"
    assert main(["simulate", "validation", "--out", str(out), "--quiet"]) == 0
    assert written == [f"writing the results and drawing the figures into {out}"]


def test_a_progress_bar_says_a_slow_step_at_once():
    import io

    from symtrack.foundations.progress import Progress

    s = io.StringIO()
    bar = Progress(8, "field f", stream=s)
    bar.update(1, "random pass 1/4")
    bar.update(4, "random pass 4/4")  # within the log's interval: not written
    bar.say("drawing the random pattern's maps")
    lines = s.getvalue().splitlines()
    assert len(lines) == 2 and lines[-1].startswith("field f:  50.0% after ")
    assert lines[-1].endswith("drawing the random pattern's maps")
    quiet = Progress(8, "x", enabled=False, stream=s)
    quiet.say("nothing")
    assert "nothing" not in s.getvalue()


def test_a_python_run_shows_its_progress_once_it_takes_two_seconds(capsys):
    """symtrack.simulate's default (progress=None): a quick run writes nothing on stderr, a run past 2 s says
    where it is (symtrack/foundations/progress.py)."""
    import io

    from symtrack.foundations.progress import SLOW_STEP_S, Progress

    symtrack.simulate(symtrack.load_scenario("validation", {"run.duration_s": 0.2}))
    assert capsys.readouterr().err == ""
    quick, slow = io.StringIO(), io.StringIO()
    bar = Progress(1.0, "quick", enabled=None, stream=quick)
    bar.update(0.5)
    bar.close()
    assert quick.getvalue() == ""
    bar = Progress(1.0, "slow", enabled=None, stream=slow)
    bar.update(0.1)
    assert slow.getvalue() == ""
    bar._t0 -= SLOW_STEP_S  # as if the run had taken 2 s
    bar.update(0.5)
    bar.close()
    assert "slow:  50.0%" in slow.getvalue() and "slow: 100.0%" in slow.getvalue()
    silent = io.StringIO()
    bar = Progress(1.0, "off", enabled=False, stream=silent)
    bar._t0 -= SLOW_STEP_S
    bar.update(0.5)
    bar.close()
    assert silent.getvalue() == ""


def test_the_front_door_shows_progress_as_simulate_does(monkeypatch):
    """symtrack.run's default is symtrack.simulate's (progress once a run has taken 2 s): it hands its
    simulation None, not False; a sweep through it shows its bar from the start."""
    from symtrack import api
    from symtrack.studies import engine

    seen = {}
    real = api.simulate

    def spy(sc, **kw):
        seen["simulate"] = kw.get("progress")
        return real(sc, **kw)

    monkeypatch.setattr(api, "simulate", spy)
    symtrack.run("validation", overrides=["run.duration_s=0.2"])
    assert seen["simulate"] is None

    def sweep_spy(**kw):
        seen["sweep"] = kw["progress"]

    monkeypatch.setattr(engine, "sweep", sweep_spy)
    from symtrack.studies.runfile import run

    run({"sweep": {"scenario": "validation", "vary": {"vehicle.mass_kg": [5000.0, 6000.0]}}}, out="unused")
    assert seen["sweep"] is True
