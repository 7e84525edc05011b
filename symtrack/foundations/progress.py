"""Progress of long runs on stderr: a bar on a terminal (at most ~10 updates a second), log
lines otherwise (every ``LOG_EVERY_S`` seconds and at the end), so that logs and CI output show
progress too. :func:`timed_step` says what a step does once it has taken 2 s, and then its time."""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time

__all__ = ["LOG_EVERY_S", "SLOW_STEP_S", "Progress", "timed_step"]

log = logging.getLogger("symtrack.progress")

LOG_EVERY_S = 10.0  # a progress line in logs (stderr not a terminal) at most this often
SLOW_STEP_S = 2.0  # timed_step says what a step does once it has taken this long (no silent wait over 2 s)


class Progress:
    """Progress of one task as a fraction of ``total``. ``enabled=False`` shows nothing; ``None`` shows it once
    the task has taken :data:`SLOW_STEP_S` (a quick task says nothing, a long one is never silent)."""

    def __init__(self, total: float, label: str = "", enabled: bool | None = True, stream=None):
        self.total = max(float(total), 1e-12)
        self.label = label
        self.stream = stream or sys.stderr
        self.delay_s = SLOW_STEP_S if enabled is None else 0.0  # nothing shown before this
        self.enabled = enabled is not False
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last = 0.0
        self._t0 = time.perf_counter()
        self._done = 0.0
        self._note = ""
        self._shown = None  # (fraction, note) of the last line written (a log, not a tty)

    def update(self, done: float, note: str = ""):
        self._done, self._note = done, note
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._t0 < self.delay_s:
            return
        if now - self._last < (0.1 if self.tty else LOG_EVERY_S) and done < self.total:
            return
        self._last = now
        self._write(now)

    def say(self, note: str):
        """Show ``note`` now, at the progress reached (a step between the updates that takes seconds of its
        own, such as drawing maps: the bar says what it waits for)."""
        self._note = note
        if self.enabled and time.perf_counter() - self._t0 >= self.delay_s:
            self._last = time.perf_counter()
            self._write(self._last)

    def _write(self, now, end=False):
        frac = min(max(self._done / self.total, 0.0), 1.0)
        if self.tty:
            bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
            self.stream.write(f"\r{self.label} [{bar}] {100 * frac:5.1f}% {now - self._t0:6.1f} s {self._note}   ")
            if end:
                self.stream.write("\n")
        else:
            if end and self._shown == (frac, self._note):
                return  # the last line said it already (a log gets each state once)
            self.stream.write(f"{self.label}: {100 * frac:5.1f}% after {now - self._t0:.1f} s {self._note}\n")
            self._shown = (frac, self._note)
        self.stream.flush()

    def close(self, complete: bool = True):
        """End the bar; ``complete`` shows 100 % (the task ended by its own rule, which may be
        before the nominal total, e.g. a distance reached before the time limit)."""
        if not self.enabled or (self.delay_s and not self._last):
            return  # off, or a quick task that never showed its bar
        if complete:
            self._done = self.total
        self._write(time.perf_counter(), end=True)


@contextlib.contextmanager
def timed_step(what: str, logger: logging.Logger | None = None, slow_s: float = SLOW_STEP_S):
    """Say what a step does once it has taken ``slow_s`` ("what ..." from a timer thread, while the
    step still runs) and, then, how long it took ("what took 12.3 s"), so that no wait longer than
    ``slow_s`` is silent (a solver build, a model's code generation, an integrator construction;
    the compilations say their own, symtrack.toolchain). A quick step logs nothing."""
    lg = logger or log
    t0 = time.perf_counter()
    announced = threading.Event()

    def announce():
        announced.set()
        lg.info("%s ...", what)

    timer = threading.Timer(slow_s, announce)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        dt = time.perf_counter() - t0
        if announced.is_set() or dt > slow_s:
            lg.info("%s took %.1f s", what, dt)
