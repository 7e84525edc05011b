"""``python -m codegen`` from a checkout: the entry point of the code generation (Makefile, docs/codegen.md).

Not installed (pyproject.toml installs ``symtrack*`` only): the generators live in the package as
:mod:`symtrack.codegen` (``symtrack codegen`` in an installed package runs the same command); this
folder only keeps the checkout's short command.
"""

__all__: list[str] = []
