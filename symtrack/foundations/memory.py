"""How much memory the machine can give, and a refusal before allocating more.

``available_bytes()`` is the kernel's estimate of the memory a new allocation can take without
swapping (``MemAvailable`` of /proc/meminfo on Linux; elsewhere the free physical pages of
``os.sysconf``; None where neither exists, and then nothing is refused).
``SYMTRACK_MEMORY_LIMIT_BYTES`` in the environment caps it (a job's share of a shared machine, a
container's limit the kernel does not report, and the tests)."""

from __future__ import annotations

import os

from .errors import ScenarioError

__all__ = ["LIMIT_ENV", "available_bytes", "require_memory", "resident_bytes"]

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


def resident_bytes() -> int:
    """The memory this process holds now (its resident set, /proc/self/statm on Linux; elsewhere its
    peak so far, ``getrusage``), in bytes."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        pass
    try:
        import resource
        import sys

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return int(peak if sys.platform == "darwin" else peak * 1024)  # bytes on macOS, KiB elsewhere
    except (ImportError, OSError):
        return 0


def require_memory(need_bytes: int, what: str, advice: str) -> int:
    """Raise :class:`ScenarioError` when ``need_bytes`` (the memory the work will take beyond what the
    process holds now) exceeds the available memory: the message names ``what`` needs it (the keys that
    set it), the need, the peak it makes for this process, what is available, and ``advice``. Returns the
    estimated peak of the process, in bytes."""
    peak = resident_bytes() + int(need_bytes)
    avail = available_bytes()
    if avail is not None and need_bytes > avail:
        raise ScenarioError(f"{what} needs {need_bytes / 1e9:.2f} GB of memory (a peak of about {peak / 1e9:.2f} GB "
                            f"for this process), this machine has {avail / 1e9:.2f} GB available; {advice}")
    return peak
