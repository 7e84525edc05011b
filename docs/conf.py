"""Sphinx configuration of the symtrack documentation (``make docs``: docs/_build/html).

The pages are the Markdown files of docs/ (MyST); the API reference is autodoc of the public
modules, their NumPy-style docstrings read by napoleon. The gallery (docs/gallery/, generated, not
committed) is sphinx-gallery's page per script of examples/: the few that run in seconds are executed
at build time and their figures are the build's (docs/gallery_examples.py), the others are shown
unexecuted.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the checkout's symtrack, installed or not
sys.path.append(str(ROOT / "docs"))  # gallery_examples: sphinx-gallery's callables, by name

# the examples the gallery runs compile their models at -O0 and the terrain engine at -O0 (their runs take
# seconds: gcc's time is most of theirs; the same arithmetic, tests/conftest.py), unless set otherwise
os.environ.setdefault("SYMTRACK_OPT_LEVEL", "0")
os.environ.setdefault("SYMTRACK_TUNED_OPT_LEVEL", "0")

import gallery_examples  # noqa: E402

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
    "sphinx_gallery.gen_gallery",
]

# the pages are Markdown; the gallery's pages are the reStructuredText sphinx-gallery writes
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
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

# the gallery of examples/ (docs/gallery/index): every script a page; the ones of gallery_examples.RUN executed
# with their options, their figures collected from the files they write; a failing one fails the build
sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "gallery",
    "filename_pattern": gallery_examples.FILENAME_PATTERN,
    "reset_argv": "gallery_examples.reset_argv",
    "image_scrapers": ("gallery_examples.png_scraper",),
    "abort_on_example_error": True,
    "within_subsection_order": "ExampleTitleSortKey",
    "download_all_examples": False,
    "write_computation_times": False,
    "show_memory": False,
    "show_signature": False,
    "min_reported_time": 3600,  # no "Total running time" line: the build's reduced runs say little
}

html_theme = "furo"
html_title = f"symtrack {release}"
html_static_path: list[str] = []
pygments_style = "sphinx"


def _gallery_page(app, docname, source):
    """A gallery page: under its title the note saying how the build ran the example, or how to run it; the
    command lines of its docstring (an indented block of ``python examples/...`` lines) shown as code."""
    if not docname.startswith("gallery/") or docname == "gallery/index":
        return
    lines = source[0].splitlines()
    command = re.compile(r"    (\S+=\S+ )*\S*python examples/")
    out, noted = [], False
    for i, line in enumerate(lines):
        if (i and not line.strip() and i + 1 < len(lines) and command.match(lines[i + 1])
                and not lines[i - 1].rstrip().endswith("::")):
            out += ["", "::"]  # the paragraph "::" alone: the indented block after it is literal
        out.append(line)
        if not noted and i and line and set(line) == {"="} and len(line) >= len(lines[i - 1].strip()) > 0:
            out += ["", ".. note::", "", "   " + gallery_examples.note(docname.removeprefix("gallery/"))]
            noted = True
    source[0] = "\n".join(out) + "\n"


def setup(app):
    app.connect("source-read", _gallery_page)
