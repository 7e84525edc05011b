"""How much memory the machine can give, and a refusal before allocating more (issue 26, item 5).

``available_bytes()`` is the kernel's estimate of the memory a new allocation can take without
swapping (``MemAvailable`` of /proc/meminfo on Linux; elsewhere the free physical pages of
``os.sysconf``; None where neither exists, and then nothing is refused).
``SYMTRACK_MEMORY_LIMIT_BYTES`` in the environment caps it (a job's share of a shared machine, a
container's limit the kernel does not report, and the tests)."""

from __future__ import annotations

import os

from .errors import ScenarioError

__all__ = ["LIMIT_ENV", "available_bytes", "require_memory"]

LIMIT_ENV = "SYMTRACK_MEMORY_LIMIT_BYTES"


def available_bytes() -> int | None:
    """The memory a new allocation can take now, in bytes (module doc), or None when unknown."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = None
    cap = os.environ.get(LIMIT_ENV)
    if cap:
        try:
            cap_b = int(float(cap))
        except ValueError as err:
            raise ScenarioError(f"{LIMIT_ENV} = {cap!r} must be a number of bytes") from err
        avail = cap_b if avail is None else min(avail, cap_b)
    return avail


def require_memory(need_bytes: int, what: str, advice: str) -> None:
    """Raise :class:`ScenarioError` when ``need_bytes`` exceeds the available memory: the message
    names ``what`` needs it (the keys that set it), both figures, and ``advice``."""
    avail = available_bytes()
    if avail is not None and need_bytes > avail:
        raise ScenarioError(f"{what} needs {need_bytes / 1e9:.2f} GB of memory, this machine has "
                            f"{avail / 1e9:.2f} GB available; {advice}")
