"""Numerical tables kept in the cache between processes: arrays that take seconds to compute and depend
only on their arguments and on the code that computes them (a tyre's stress table below its footprint:
:func:`symtrack.region.fleet.footprint_table_cached`).

A table is ``<cache>/tables/<kind>-<key>.npz`` (numpy's npz, no pickles), written atomically once it is
computed. The key is the SHA-256 of the kind, the arguments' text, numpy's version and the source text of
the modules that compute the table, so that a change to that code computes the table afresh instead of
reading an old one. A file that cannot be read (truncated, not an npz, other arrays) is computed again and
replaced, with a warning; a cache that cannot be written costs the computation only (the table is then
kept in the process alone). Each process reads a table once: the callers keep what they read in memory.
"""

from __future__ import annotations

import inspect
import logging
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..foundations.files import atomic_write_bytes, npz_bytes
from .cache import cache_root, digest

__all__ = ["cached_arrays", "table_path"]

log = logging.getLogger("symtrack.toolchain")

# bump when the file's layout changes
TABLES_VERSION = 1


def _source_text(modules) -> str:
    return "".join(inspect.getsource(m) for m in modules)


def table_path(kind: str, args: str, modules=()) -> Path:
    """The table's file: ``<cache>/tables/<kind>-<key>.npz`` (module doc)."""
    key = digest(kind, "\0", args, "\0", np.__version__, "\0", str(TABLES_VERSION), "\0", _source_text(modules))
    return cache_root() / "tables" / f"{kind}-{key[:32]}.npz"


def cached_arrays(kind: str, args: str, compute: Callable[[], dict[str, np.ndarray]], names: tuple[str, ...],
                  modules=()) -> dict[str, np.ndarray]:
    """The arrays ``names`` of the table ``kind`` for the arguments' text ``args``: read from the cache, or
    ``compute()``-d and written there (module doc). ``modules``: the modules whose source computes the
    table (part of the key)."""
    path = table_path(kind, args, modules)
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {n: np.array(z[n]) for n in names}
            return arrays
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as err:
            log.warning("the cached table %s cannot be read (%s): computing it again", path, err)
    arrays = {n: np.asarray(v) for n, v in compute().items()}
    missing = set(names) - set(arrays)
    if missing:
        raise KeyError(f"the {kind} table's computation gave no {sorted(missing)}")
    try:
        atomic_write_bytes(path, npz_bytes(**{n: arrays[n] for n in names}))
    except OSError as err:  # a full disk or a cache that went read-only: the process keeps its table
        log.warning("the table %s could not be written to the cache (%s)", path, err)
    return arrays
