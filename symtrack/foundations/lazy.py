"""Names of a package imported on first use (PEP 562's module ``__getattr__``): a package whose modules
are imported by rooms below it (a vehicle, a soil law) may then export its names without running all
of its modules when one of them is imported."""

from __future__ import annotations

import importlib

__all__ = ["lazy_getattr"]


def lazy_getattr(package: str, table: dict[str, str], namespace: dict):
    """The module ``__getattr__`` of ``package``: ``table`` maps an exported name to the module that
    defines it (``"options"``: a module of the package; ``"symtrack.api"``: an absolute name); a name
    that is itself a module of the package maps to ``""``. The value is kept in ``namespace`` (the
    package's globals), so each name is looked up once."""

    def __getattr__(name: str):
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        where = table[name]
        if where == "":
            value = importlib.import_module(f"{package}.{name}")
        else:
            module = importlib.import_module(where if where.startswith("symtrack.") else f"{package}.{where}")
            value = getattr(module, name)
        namespace[name] = value
        return value

    return __getattr__
