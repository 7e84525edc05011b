"""Ctrl-C that is never mistaken for a solver failure.

CasADi's solvers catch the interrupt themselves and report it as a failed call, so a run would
say "cvodes failed" (or an MPC would count a failed solve and go on) instead of stopping. Within
an :class:`InterruptWatch` block a SIGINT handler records the signal and still calls the previous
handler (which raises :class:`KeyboardInterrupt` as usual); code that catches a solver failure
calls :func:`raise_if_interrupted`, and on leaving the block a recorded SIGINT raises
KeyboardInterrupt whatever the solver made of it. Outside the main thread it does nothing.

:func:`defer_interrupts` holds Ctrl-C back over a few lines that must run whole (a pass counted in
every record of a study, or in none): a SIGINT inside the block raises KeyboardInterrupt when it ends.
"""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["InterruptWatch", "defer_interrupts", "interrupted", "raise_if_interrupted", "watch_interrupts"]

_active: list[InterruptWatch] = []


class InterruptWatch:
    """The context manager of the module doc (nestable)."""

    def __enter__(self):
        self.hit = False
        self._prev = None
        if threading.current_thread() is threading.main_thread():
            prev = signal.getsignal(signal.SIGINT)
            self._prev = prev if prev is not None else signal.default_int_handler

            def handler(signum, frame):
                self.hit = True
                if callable(self._prev):
                    self._prev(signum, frame)

            signal.signal(signal.SIGINT, handler)
        _active.append(self)
        return self

    def __exit__(self, exc_type, exc, tb):
        _active.remove(self)
        if self._prev is not None:
            signal.signal(signal.SIGINT, self._prev)
        if self.hit and not (exc_type is not None and issubclass(exc_type, KeyboardInterrupt)):
            raise KeyboardInterrupt("interrupted during a solver call")
        return False


def watch_interrupts() -> InterruptWatch:
    """An :class:`InterruptWatch` (``with watch_interrupts(): ...``)."""
    return InterruptWatch()


def interrupted() -> bool:
    """True when SIGINT arrived inside a current :class:`InterruptWatch` block."""
    return any(w.hit for w in _active)


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt when SIGINT arrived (call it where a solver failure is caught)."""
    if interrupted():
        raise KeyboardInterrupt


@contextlib.contextmanager
def defer_interrupts():
    """Run the block whole: a SIGINT that arrives inside it is recorded and raised as
    KeyboardInterrupt when the block ends (module doc). Outside the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    hit = []
    prev = signal.signal(signal.SIGINT, lambda signum, frame: hit.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, prev if prev is not None else signal.default_int_handler)
    if hit:
        raise KeyboardInterrupt
