"""A menu of named entries (integrators, soil laws, vehicle models): add, remove, list, look up.

One mechanism for the package's three registries, so that adding an entry is one line wherever
it is done, and an unknown name is refused the same way everywhere: an error of the menu's own
type that names the key, the value and the menu.
"""

from __future__ import annotations

from typing import Generic, TypeVar

from . import caches
from .errors import SymtrackError

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(Generic[T]):
    """Named entries, in registration order.

    Parameters
    ----------
    kind : str
        What an entry is, for messages ("an integrator", "a soil law").
    where : str
        The key a user names an entry with, for messages ("run.integrator").
    error : type
        The exception an unknown name raises (a :class:`~symtrack.foundations.errors.SymtrackError`).
    """

    def __init__(self, kind: str, where: str, error: type[SymtrackError]):
        self.kind, self.where, self.error = kind, where, error
        self.entries: dict[str, T] = {}
        self._last: dict[str, T] = {}  # the entry last registered under each name, removed or not

    def add(self, name: str, entry: T, replace: bool = False) -> T:
        """Add ``entry`` as ``name``; a name taken already is a ValueError unless ``replace``.

        An entry other than the one last registered under ``name`` (a replacement, or a new entry after
        a removal) empties the package's in-memory caches (:func:`~symtrack.foundations.caches.clear_caches`):
        what they hold was built from the old entry and is found by its name (a set of model options
        names its soil law, vehicle and integrator), so a model built before would otherwise be
        returned for the new entry. Registering the same entry again clears nothing."""
        if name in self.entries and not replace:
            raise ValueError(f"{self.kind} named {name!r} is registered already")
        if self._last.get(name, entry) is not entry:
            caches.clear_caches()
        self.entries[name] = self._last[name] = entry
        return entry

    def remove(self, name: str) -> None:
        """Remove ``name`` (nothing when it is not there)."""
        self.entries.pop(name, None)

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self.entries)

    def get(self, name: str, where: str | None = None) -> T:
        """The entry of ``name``; an unknown name raises :attr:`error` naming ``where`` and the menu."""
        entry = self.entries.get(name)
        if entry is None:
            raise self.error(f"{where or self.where} = {name!r} is not one of {', '.join(self.entries)}")
        return entry
