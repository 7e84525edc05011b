"""No file in the repository cites a file outside it: the physics is cited as its published sources
and as docs/model.md, never as notes that a reader of the repository does not have (a model or
design note, a reference list, review notes, the source papers' text files, a sibling folder)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (what it catches, the pattern). The notes are matched by the stem of their file names with ".md" after it
# (this file names no file itself); the model note's case-sensitively: docs/model.md is ours.
_MD = r"\.md"
OUTSIDE = (
    ("the project's model note", re.compile(r"\bMODEL" + _MD)),
    ("a reference note", re.compile(r"\bREFERENCES" + _MD, re.I)),
    ("a validation-data note", re.compile(r"\bVALIDATION-DATA(" + _MD + r")?\b", re.I)),
    ("a design note", re.compile(r"\bDESIGN" + _MD, re.I)),
    ("CasADi notes", re.compile(r"\bCASADI_NOTES\b", re.I)),
    ("review notes", re.compile(r"\bREVIEW" + _MD, re.I)),
    ("a sibling folder", re.compile(r"\.\./shared\b|\bshared/", re.I)),
    ("the source papers' text files", re.compile(r"\bseeds/", re.I)),
    ("a folder of the development machine", re.compile(r"(?<![\w.~])/work/")),
    # the development's own retrieval of sources (a reader has the published sources, not that material)
    ("the development's search tool or its stored pages",
     re.compile(r"search tool|stored (?:text|pages?|material)|page-by-page copy|\b(?:scribd|yumpu)\b", re.I)),
    # "the seed": the source papers by a nickname (cite them by their authors); "the seed of" a random generator is fine
    ("a paper by a nickname", re.compile(r"\bseed(?:'s)? (?:eq|section|paper)|\bseed's\b|\bthe seed\b(?! of\b)", re.I)),
)


def _tracked_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
        names = [n for n in out.decode().split("\0") if n]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout: every file under the root
        names = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts]
    return [ROOT / n for n in names]


def test_no_file_cites_a_file_outside_the_repository():
    me = Path(__file__).resolve()
    found = []
    for path in _tracked_files():
        if path.resolve() == me or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue  # binary files
        for lineno, line in enumerate(text.splitlines(), start=1):
            for what, pattern in OUTSIDE:
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{lineno}: {what}: {line.strip()[:100]}")
    assert not found, "files that cite a file outside the repository:\n" + "\n".join(found)


def test_the_model_is_documented_in_the_repository():
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    for section in ("## Pressure-sinkage", "## Tractive effort", "## Terrain cells, channels and the world manager",
                    "## Subsoil stress", "## One soil: pedotransfer functions", "## References"):
        assert section in text, f"docs/model.md has no section {section!r}"
    assert "Ferretti, G. & Girelli, R. (1999)" in text


def test_citations_of_docs_model_name_its_sections():
    """A citation 'docs/model.md, "Section"' names a section the page has (wrapped lines and comment
    markers between its words allowed)."""
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    sections = {line[3:].strip() for line in text.splitlines() if line.startswith("## ")}
    bad = []
    me = Path(__file__).resolve()
    for path in _tracked_files():
        if path.resolve() == me or not path.is_file() or path.suffix not in (".py", ".md", ".toml", ".c", ".h"):
            continue
        flat = re.sub(r"[ \t]*\n[ \t]*(?:#[ \t]*)?", " ", path.read_text(encoding="utf-8"))
        for m in re.finditer(r'docs/model\.md, "([^"]+)"', flat):
            if m.group(1) not in sections:
                bad.append(f"{path.relative_to(ROOT)}: {m.group(1)!r}")
    assert not bad, "citations of sections docs/model.md does not have:\n" + "\n".join(bad)
