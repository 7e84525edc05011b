"""Code generation for symtrack: ``python -m codegen`` writes the C sources into ``generated/``.

See docs/codegen.md. The generation itself lives in the package (:mod:`symtrack.native.generate`, the step builders
:mod:`symtrack.native.rosenbrock` and :mod:`symtrack.native.grid_rosenbrock`), since the runtime
compiles the same sources; the command line (and ``symtrack codegen``) is :mod:`codegen.cli`, the
standalone program :mod:`codegen.standalone`.
"""
