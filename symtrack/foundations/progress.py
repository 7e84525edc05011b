"""A dependency-free progress bar on stderr for long runs (updates at most ~10 times a second)."""

from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    def __init__(self, total: float, label: str = "", enabled: bool = True, stream=None):
        self.total = max(float(total), 1e-12)
        self.label = label
        self.stream = stream or sys.stderr
        # only on a terminal: logs and CI output stay clean
        self.enabled = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last = 0.0
        self._t0 = time.perf_counter()

    def update(self, done: float, note: str = ""):
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and done < self.total:
            return
        self._last = now
        frac = min(max(done / self.total, 0.0), 1.0)
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        self.stream.write(f"\r{self.label} [{bar}] {100 * frac:5.1f}% {now - self._t0:6.1f} s {note}   ")
        self.stream.flush()

    def close(self):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
