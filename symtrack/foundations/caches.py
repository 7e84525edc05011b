"""The package's in-memory caches behind one registry, each bounded.

What a process builds once and reuses (the symbolic models of a set of options, their generated
libraries, the terrain engine's Functions, the subsoil stress tables, the quadrature's call nodes, a
field study's steering maps and cell masks) is kept in a :class:`BoundedCache`: at most
``max_entries`` entries, the least recently used dropped first, so a long-lived process (a Dask
worker running scenario after scenario) holds a bounded number of models whatever it runs. A cache
holds the only reference the package keeps to what it stores: an entry dropped is memory freed once
the caller lets go of it.

- :func:`cache` makes (or returns) the registered cache of a name;
- :func:`register_clear` adds a ``functools.lru_cache``'d function (bounded by its own ``maxsize``)
  so that :func:`clear_caches` empties it too;
- :func:`clear_caches` (``symtrack.clear_caches()``) empties every cache; :func:`cache_info` gives
  per cache its entries, its limit, its hits and misses.

The compiled artefacts on disk (``$SYMTRACK_CACHE``) are :mod:`symtrack.toolchain`'s, not these.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

__all__ = ["BoundedCache", "cache", "cache_info", "clear_caches", "register_clear"]

_lock = threading.Lock()
_CACHES: dict[str, BoundedCache] = {}
_LRU_FUNCTIONS: dict[str, Callable] = {}


class BoundedCache:
    """A least-recently-used map of at most ``max_entries`` entries (thread-safe)."""

    def __init__(self, name: str, max_entries: int):
        if int(max_entries) < 1:
            raise ValueError(f"cache {name!r}: max_entries must be at least 1, not {max_entries}")
        self.name, self.max_entries = name, int(max_entries)
        self._data: OrderedDict[Hashable, Any] = OrderedDict()
        self._lock = threading.RLock()
        self.hits = self.misses = 0

    def __repr__(self) -> str:
        return f"BoundedCache({self.name!r}, {len(self)}/{self.max_entries} entries)"

    def __len__(self) -> int:
        return len(self._data)

    def __contains__(self, key) -> bool:
        return key in self._data

    def get(self, key, default=None):
        """The entry of ``key`` (now the most recently used), or ``default``."""
        with self._lock:
            if key in self._data:
                self._data.move_to_end(key)
                self.hits += 1
                return self._data[key]
            self.misses += 1
            return default

    def put(self, key, value):
        """Store ``value`` under ``key`` (an entry already there is kept and returned: the first of two
        concurrent builds wins), dropping the least recently used beyond the limit."""
        with self._lock:
            value = self._data.setdefault(key, value)
            self._data.move_to_end(key)
            while len(self._data) > self.max_entries:
                self._data.popitem(last=False)
            return value

    def get_or_build(self, key, build: Callable[[], Any]):
        """The entry of ``key``, built by ``build()`` (outside the lock) and stored when missing."""
        sentinel = object()
        hit = self.get(key, sentinel)
        if hit is not sentinel:
            return hit
        return self.put(key, build())

    def drop(self, key) -> None:
        """Forget the entry of ``key`` (if any)."""
        with self._lock:
            self._data.pop(key, None)

    def clear(self) -> None:
        with self._lock:
            self._data.clear()
            self.hits = self.misses = 0

    def info(self) -> dict:
        return {"entries": len(self._data), "max_entries": self.max_entries, "hits": self.hits,
                "misses": self.misses}


def cache(name: str, max_entries: int) -> BoundedCache:
    """The registered cache ``name`` (made on the first call with this limit)."""
    with _lock:
        c = _CACHES.get(name)
        if c is None:
            c = _CACHES[name] = BoundedCache(name, max_entries)
        return c


def register_clear(name: str, fn: Callable) -> Callable:
    """Register a ``functools.lru_cache``'d function under ``name`` (its ``cache_clear`` is called by
    :func:`clear_caches`, its ``cache_info`` reported by :func:`cache_info`); returns ``fn``."""
    with _lock:
        _LRU_FUNCTIONS[name] = fn
    return fn


def clear_caches() -> None:
    """Empty every in-memory cache of the package (the next use builds again)."""
    with _lock:
        caches, fns = list(_CACHES.values()), list(_LRU_FUNCTIONS.values())
    for c in caches:
        c.clear()
    for fn in fns:
        fn.cache_clear()


def cache_info() -> dict:
    """Per registered cache: ``{"entries", "max_entries", "hits", "misses"}``."""
    with _lock:
        caches, fns = dict(_CACHES), dict(_LRU_FUNCTIONS)
    out = {name: c.info() for name, c in caches.items()}
    for name, fn in fns.items():
        i = fn.cache_info()
        out[name] = {"entries": i.currsize, "max_entries": i.maxsize, "hits": i.hits, "misses": i.misses}
    return out
