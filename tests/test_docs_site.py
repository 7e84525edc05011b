"""The documentation site builds with no warning (``make docs``: Sphinx over docs/*.md, the API reference
from the docstrings), every page of docs/ is in a table of contents, and the commands the README and the
tutorial name exist. The examples are not run here (the example tests run them; ``make docs-examples``)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def test_the_site_builds_with_no_warning(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    pytest.importorskip("furo")
    # a fresh output and doctree folder: every page read, every docstring imported
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
                           "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"sphinx failed (warnings are errors):\n{proc.stderr[-6000:]}"
    for page in ("index", "getting-started", "howto", "model", "scenarios", "outputs", "performance",
                 "api/symtrack", "changelog"):
        assert (tmp_path / "html" / f"{page}.html").is_file(), page
    # the API reference has the docstrings of the front door
    api = (tmp_path / "html" / "api" / "symtrack.html").read_text(encoding="utf-8")
    for name in ("symtrack.simulate", "symtrack.load_scenario", "symtrack.Result", "symtrack.run"):
        assert f'id="{name}"' in api, name


def test_every_page_is_in_a_table_of_contents():
    """A Markdown file of docs/ that no toctree names would be a page no reader finds (Sphinx warns too;
    this names the file)."""
    named = set()
    for md in DOCS.rglob("*.md"):
        if "_build" in md.parts:
            continue
        for block in re.findall(r"```\{toctree\}\n(.*?)```", md.read_text(encoding="utf-8"), re.S):
            for line in block.splitlines():
                line = line.strip()
                if line and not line.startswith(":"):
                    named.add((md.parent / line).relative_to(DOCS).as_posix())
    pages = {md.relative_to(DOCS).with_suffix("").as_posix() for md in DOCS.rglob("*.md") if "_build" not in md.parts}
    assert pages - named == {"index"}, f"pages in no toctree: {sorted(pages - named - {'index'})}"


def test_performance_tables_name_their_command_machine_and_date():
    """docs/performance.md holds only tables that docs/performance.py writes, each with the command,
    the machine and the date above it."""
    text = (DOCS / "performance.md").read_text(encoding="utf-8")
    script = (DOCS / "performance.py").read_text(encoding="utf-8")
    names = re.findall(r"<!-- perf:([\w-]+):start -->\n(.*?)<!-- perf:\1:end -->", text, re.S)
    assert names, "docs/performance.md has no generated tables"
    for name, body in names:
        assert f'"{name}":' in script, f"table {name!r} is not one docs/performance.py writes"
        assert re.match(r"Measured \d{4}-\d\d-\d\d on .+; regenerate with `make performance`\.", body), name
    # every table of the page is inside the markers
    outside = re.sub(r"<!-- perf:([\w-]+):start -->.*?<!-- perf:\1:end -->", "", text, flags=re.S)
    assert "|---" not in outside, "a table of docs/performance.md that docs/performance.py does not write"
    assert "performance:" in (ROOT / "Makefile").read_text()


def test_the_changelog_has_one_entry_per_release():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    import tomllib

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    releases = re.findall(r"^## (\S+)", text, re.M)
    assert releases and releases[0] == version, (releases, version)
    assert len(releases) == len(set(releases))
