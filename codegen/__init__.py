"""Code generation for symtrack: ``python -m codegen`` writes the C sources into ``generated/``.

See docs/codegen.md. The generation itself lives in :mod:`codegen.generate`; the
command line (and ``symtrack codegen``) in :mod:`codegen.cli`.
"""
