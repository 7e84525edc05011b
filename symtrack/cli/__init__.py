"""The ``symtrack`` command line (the console script calls :func:`main`)."""

from .main import main

__all__ = ["main"]
