"""Every Python block of the documentation runs as written: the blocks of a page run in order in one
namespace (a later block may use an earlier one's names, as a reader in one session would), in a fresh
folder holding only what the page has the reader make before it. A block that cannot run here says why
in a comment on the line above its fence, ``<!-- docs-test: not run (REASON) -->`` (a cluster the tests do
not have): it is compiled, and its imports of symtrack's names are executed. The README's block is run by
tests/test_readme.py."""

import re
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
FENCE = re.compile(r"^(?P<indent>[ \t]*)```python\n(?P<body>.*?)^(?P=indent)```", re.S | re.M)
NOT_RUN = re.compile(r"<!-- docs-test: not run \((?P<reason>[^)]+)\) -->\s*$")


def _blocks(page: Path) -> list[tuple[int, str, str | None]]:
    """(line, code, reason not run or None) of each Python block of ``page``."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        reason = NOT_RUN.search(before)
        body = textwrap.dedent(m.group("body"))
        out.append((line, body, reason.group("reason") if reason else None))
    return out


PAGES = sorted(p for p in DOCS.glob("*.md") if _blocks(p))


def _my_run_toml(folder: Path) -> None:
    """The getting-started tutorial's first file, as its step `symtrack new simulation --out my_run.toml`
    writes it."""
    from symtrack.cli.main import main

    assert main(["new", "simulation", "--out", str(folder / "my_run.toml")]) == 0


# what a page has the reader make before its Python blocks
SETUP = {"getting-started.md": _my_run_toml}
def _ok_rows(table: str) -> int:
    import csv

    with open(table, newline="") as f:
        return sum(row["status"] == "ok" for row in csv.DictReader(f))


# what a page's blocks computed, where a block shows a result without asserting it
CHECKS = {
    "getting-started.md": lambda ns: ns["res"].summary["sinkage_sprocket_mm"] > 0,
    "python.md": lambda ns: ns["res"].summary["complete"] and len(ns["second"].summary["passes"]) == 1,
    # the sweeps' tables (the field study's result is the last ``res``): 4 runs of the grid, 4 of the LHS, all ok
    "studies.md": lambda ns: all(_ok_rows(f"out/{name}/results.csv") == 4 for name in ("sweep", "lhs"))
    and ns["res"].patterns["random"].counts.max() >= 1,
    "subsoil.md": lambda ns: ns["sz"][0][1] > 18.8,  # the floor raises the stress above it
}


def test_the_blocks_are_found_and_every_one_not_run_says_why():
    found = {p.name: _blocks(p) for p in PAGES}
    assert {"getting-started.md", "python.md", "studies.md", "subsoil.md", "region.md"} <= set(found)
    for name, blocks in found.items():
        for line, code, reason in blocks:
            compile(code, f"docs/{name}:{line}", "exec")  # every block is Python, run or not
            assert reason is None or len(reason) > 10, f"docs/{name}:{line}: say why the block is not run"


@pytest.mark.parametrize("page", [p.name for p in PAGES])
def test_the_python_blocks_of_a_page_run_as_written(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if page in SETUP:
        SETUP[page](tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    for line, code, reason in _blocks(DOCS / page):
        where = f"docs/{page}:{line}"
        if reason is not None:
            # the block's imports of the package's names must hold (a renamed function fails here)
            for imp in re.findall(r"^(?:from symtrack[\w.]* import [\w, ]+|import symtrack[\w.]*)$", code, re.M):
                exec(compile(imp, where, "exec"), {})
            continue
        try:
            exec(compile(code, where, "exec"), namespace)
        except Exception as err:  # the block's own error, with where it is
            raise AssertionError(f"{where}: the block does not run as written: {type(err).__name__}: {err}") from err
    if page in CHECKS:
        assert CHECKS[page](namespace), f"docs/{page}: the blocks ran but their result is not the one shown"
