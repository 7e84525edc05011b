"""The gallery of examples/ (docs/conf.py, sphinx-gallery): which examples the documentation build runs, with
which options, and the scraper that shows the figures they write.

Every script of examples/ gets a page (its docstring, its code, a download link). The ones in RUN are executed
by the build with reduced settings, their figures written to a temporary folder by their own ``--plot`` or
``--out`` option and shown from there (each example saves its figure as a file, as a user running it would
get it; several close it after saving, so sphinx-gallery's matplotlib scraper would find nothing); the
others (longer runs, tables and no figure, the GIS extra) are shown unexecuted with a note of why and how to
run them.

An executed example must not call ``sys.exit`` when it succeeds: sphinx-gallery runs it in the Sphinx
process, where a ``SystemExit`` ends the build (tests/test_docs_site.py then misses its pages).
"""

from __future__ import annotations

import ast
import atexit
import shutil
import tempfile
from pathlib import Path

# name: (the options the build runs it with, "{out}" the example's output folder; the figures it writes
# there, in the order they are shown). All of them add about 28 s of CPU to a build on an empty compile
# cache (2 s of it the Python imports), a few seconds each: the budget of tests/test_docs_site.py.
RUN: dict[str, tuple[list[str], list[str]]] = {
    "kroulik_seasons": (["--size", "120", "100", "--cell", "0.2", "--plot", "{out}/kroulik_seasons.png"],
                        ["kroulik_seasons.png"]),
    "side_slope_3d": (["--duration", "2", "--slope-deg", "8", "--plot", "{out}/side_slope_3d.png"],
                      ["side_slope_3d.png"]),
    "ramp_3d": (["--duration", "4", "--plot", "{out}/ramp_3d.png"], ["ramp_3d.png"]),
    "furrows_3d": (["--spacings", "9.6", "--duration", "3", "--segments", "8", "--plot", "{out}/furrows_3d.png"],
                   ["furrows_3d.png"]),
    "oscillation_study": (["--duration", "1", "--no-cvodes-check", "--out", "{out}"], ["oscillation_study.png"]),
    "second_pass_3d": (["--size-m", "20", "8", "--stop-m", "8", "--plot", "{out}/second_pass_3d.png"],
                       ["second_pass_3d.png"]),
}

# the examples shown but not run by the build, and why: their time at their own settings on a 2-core machine
# (measured with a warm compile cache), what they show
NOT_RUN: dict[str, str] = {
    "bench_terrain": "it takes minutes (``--quick``: seconds) and prints a JSON object, no figure",
    "compaction_day_and_machine": "it takes under a minute and prints tables, no figure",
    "compaction_reference": "it takes under a minute (``--big``: IDAS for 6-8 min) and prints its figures, no figure",
    "density_passes": "it takes minutes and prints tables, no figure",
    "engine_clocks": "it takes seconds and prints the terrain engine's clocks, no figure",
    "engine_variants": "it takes seconds and prints the terrain engine's speeds, no figure",
    "gis_field": "it takes seconds but needs the GIS extra (``pip install 'symtrack[gis]'``)",
    "hull_rotation": "it takes seconds and prints a table, no figure",
    "lane_keeping_ruts": "it takes under a minute",
    "lqr_speed_yaw": "it takes about ten seconds",
    "mpc_headland_uturn": "it takes minutes",
    "mpc_side_slope_3d": "it takes under a minute",
    "one_soil": "it takes minutes and prints tables, no figure",
    "steady_turns": "it takes seconds and prints a table, no figure",
    "tracks_against_wheels": "it takes under a minute and prints a table, no figure",
    "turn_rut": "it takes under a minute, most of it compiling the terrain engine the first time",
    "validation_sensitivity": "it takes under a minute and prints a table, no figure",
    "wet_headland": "it takes under a minute",
}

# sphinx-gallery's filename_pattern: the scripts it executes
FILENAME_PATTERN = r"/(" + "|".join(RUN) + r")\.py$"

_out: Path | None = None


def _folder(name: str) -> Path:
    """The example's output folder, in a temporary folder removed when the build ends."""
    global _out
    if _out is None:
        _out = Path(tempfile.mkdtemp(prefix="symtrack-gallery-"))
        atexit.register(shutil.rmtree, _out, ignore_errors=True)
    folder = _out / name
    folder.mkdir(exist_ok=True)
    return folder


def reset_argv(gallery_conf, script_vars) -> list[str]:
    """sphinx-gallery's reset_argv: the command-line options of an executed example. Its ``__doc__`` is its
    docstring, as when it runs as a script (sphinx-gallery empties it; the examples' argparse reads its
    title)."""
    src = Path(script_vars["src_file"])
    name = src.stem
    script_vars["example_globals"]["__doc__"] = ast.get_docstring(ast.parse(src.read_text(encoding="utf-8")),
                                                                  clean=False)
    out = _folder(name)
    return [a.format(out=out) for a in RUN[name][0]]


def png_scraper(block, block_vars, gallery_conf) -> str:
    """sphinx-gallery's image scraper: the figures the example has written into its output folder (RUN), copied
    to the gallery's image paths; each shown once."""
    from sphinx_gallery.scrapers import figure_rst

    name = Path(block_vars["src_file"]).stem
    if name not in RUN:
        return ""
    shown = block_vars.setdefault("symtrack_shown", set())
    images = []
    for figure in RUN[name][1]:
        path = _folder(name) / figure
        if figure in shown or not path.is_file():
            continue
        shown.add(figure)
        target = next(block_vars["image_path_iterator"])
        shutil.copyfile(path, target)
        images.append(target)
    return figure_rst(images, gallery_conf["src_dir"])


def note(name: str) -> str:
    """The line under an example's title: the options the build ran it with, or how long it takes and how to
    run it."""
    if name in RUN:
        args = " ".join(a.replace("{out}", "OUT") for a in RUN[name][0])
        return (f"The output below is the documentation build's run, with reduced settings: "
                f"``python examples/{name}.py {args}``.")
    return (f"Not run when this site is built: {NOT_RUN[name]}. Run it from the checkout: "
            f"``python examples/{name}.py`` (``--help`` lists its options).")
