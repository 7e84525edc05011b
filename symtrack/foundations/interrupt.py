"""Ctrl-C that is never mistaken for a solver failure.

CasADi's solvers catch the interrupt themselves and report it as a failed call, so a run would
say "cvodes failed" (or an MPC would count a failed solve) instead of stopping. Inside
:func:`watch_interrupts`, SIGINT still raises :class:`KeyboardInterrupt` as usual, and is also
recorded, so code that catches a solver failure can call :func:`raise_if_interrupted` and stop.
"""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["interrupted", "raise_if_interrupted", "watch_interrupts"]

_pressed = False


def _handler(signum, frame):
    global _pressed
    _pressed = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def watch_interrupts():
    """Record SIGINT within the block (main thread only; elsewhere a no-op)."""
    global _pressed
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    _pressed = False
    signal.signal(signal.SIGINT, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)


def interrupted() -> bool:
    """True when SIGINT arrived inside the current :func:`watch_interrupts` block."""
    return _pressed


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt when SIGINT arrived (call it where a solver failure is caught)."""
    if _pressed:
        raise KeyboardInterrupt
