"""The progress shown on a log (not a terminal): each state once, the end at 100 % when the task
ended by its own rule."""

import io

from symtrack.foundations.progress import Progress


def test_a_log_gets_the_final_state_once():
    s = io.StringIO()
    p = Progress(10.0, "run", stream=s)
    p.update(10.0, "t=3.0 s")  # the task's last update already shows the end
    p.close()
    assert s.getvalue().count("100.0%") == 1


def test_close_completes_a_task_that_ended_early_and_disabled_shows_nothing():
    s = io.StringIO()
    p = Progress(10.0, "run", stream=s)
    p.update(4.0, "t=1.0 s")
    p.close()
    lines = s.getvalue().splitlines()
    assert lines[0].startswith("run:  40.0%") and lines[-1].startswith("run: 100.0%") and len(lines) == 2
    q = io.StringIO()
    off = Progress(10.0, "run", enabled=False, stream=q)
    off.update(10.0)
    off.close()
    assert q.getvalue() == ""


def test_a_slow_step_says_what_it_does_while_it_runs_and_then_its_time(caplog):
    """No silent wait (issue 26, item 3): past slow_s the step is announced from a timer while it
    still runs, and its time follows; a quick step says nothing."""
    import logging
    import time as _time

    from symtrack.foundations.progress import timed_step

    lg = logging.getLogger("symtrack.test_timed_step")
    with caplog.at_level(logging.INFO, logger=lg.name):
        with timed_step("building a thing", lg, slow_s=0.05):
            deadline = _time.monotonic() + 5.0
            while "building a thing ..." not in caplog.text and _time.monotonic() < deadline:
                _time.sleep(0.01)
            seen_while_running = "building a thing ..." in caplog.text
        assert seen_while_running
        assert "building a thing took" in caplog.text
        caplog.clear()
        with timed_step("a quick thing", lg, slow_s=60.0):
            pass
        assert caplog.text == ""
