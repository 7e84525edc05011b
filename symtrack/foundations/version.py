"""The package's version (pyproject.toml's ``version``), here so that every layer can record it in
the files it writes (run manifests, resolved scenarios); ``symtrack.__version__`` is this."""

__all__ = ["__version__"]

__version__ = "0.1.0"
