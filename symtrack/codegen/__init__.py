"""Code generation for symtrack: ``symtrack codegen`` (or ``python -m codegen`` in a checkout) writes
the C sources into ``generated/``; the standalone programs and the MPC's C closed loop.

See docs/codegen.md. An application of the package (layer 7): only the CLI and the bench import it,
the runtime never does. The generation of the model's Functions lives lower in the package
(:mod:`symtrack.native.generate`, the step builders :mod:`symtrack.native.rosenbrock` and
:mod:`symtrack.native.grid_rosenbrock`), since the runtime compiles the same sources; the command
line is :mod:`symtrack.codegen.cli`, the standalone programs :mod:`symtrack.codegen.standalone` and
:mod:`symtrack.codegen.grid_standalone` (compiled through :func:`symtrack.toolchain.build`), the MPC's
C closed loop :mod:`symtrack.codegen.mpc`. The top-level ``codegen/`` folder of a checkout is only
the entry point of ``python -m codegen``; it is not installed.
"""

__all__: list[str] = []
