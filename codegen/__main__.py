"""``python -m codegen [mpc NAME] [--out DIR] [--check]``: :func:`symtrack.codegen.cli.main`."""

import sys

from symtrack.codegen.cli import main

__all__: list[str] = []

sys.exit(main())
