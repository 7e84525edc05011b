"""A menu of named entries (integrators, soil laws, vehicle models): add, remove, list, look up.

One mechanism for the package's three registries, so that adding an entry is one line wherever
it is done, and an unknown name is refused the same way everywhere: an error of the menu's own
type that names the key, the value and the menu.
"""

from __future__ import annotations

from typing import Generic, TypeVar

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

    def add(self, name: str, entry: T, replace: bool = False) -> T:
        """Add ``entry`` as ``name``; a name taken already is a ValueError unless ``replace``."""
        if name in self.entries and not replace:
            raise ValueError(f"{self.kind} named {name!r} is registered already")
        self.entries[name] = entry
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
