"""Sphinx configuration of the symtrack documentation (``make docs``: docs/_build/html).

The pages are the Markdown files of docs/ (MyST); the API reference is autodoc of the public
modules, their NumPy-style docstrings read by napoleon. Nothing is executed at build time.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the checkout's symtrack, installed or not

from symtrack.foundations.version import __version__  # noqa: E402

project = "symtrack"
author = "the symtrack developers"
copyright = "the symtrack developers, MIT License"  # noqa: A001
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**/_build", "Thumbs.db", ".DS_Store"]

# MyST: the pages are plain Markdown; headings get anchors so that `page.md#a-section` links work
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 4

# autodoc: the docstrings are NumPy style
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autosummary_generate = False
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False

html_theme = "furo"
html_title = f"symtrack {release}"
html_static_path: list[str] = []
pygments_style = "sphinx"
