"""The documentation site builds with no warning (``make docs``: Sphinx over docs/*.md, the API reference
from the docstrings, the gallery of examples/ with the figures of the examples it runs), every page of docs/
is in a table of contents, the measured tables are the ones a command writes, and every `symtrack ...`
command the README and the docs show is one the command line accepts. Beside the gallery's few examples
(docs/gallery_examples.py, seconds each), nothing is run here (the example tests run the examples;
``make docs-examples``)."""

from __future__ import annotations

import html
import os
import re
import runpy
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if "__pycache__" not in p.parts}


def test_the_site_builds_with_no_warning(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    pytest.importorskip("furo")
    pytest.importorskip("sphinx_gallery")
    # the sources copied (docs/ without an earlier build's gallery, examples/, the changelog the docs include):
    # every page read, every docstring imported, every example of the gallery run and drawn in this build,
    # nothing written into the checkout
    src = tmp_path / "src"
    shutil.copytree(DOCS, src / "docs", ignore=shutil.ignore_patterns("_build", "gallery", "__pycache__"))
    shutil.copytree(ROOT / "examples", src / "examples", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "CHANGELOG.md", src)
    examples = _files(src / "examples")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
                           "-d", str(tmp_path / "doctrees"), str(src / "docs"), str(tmp_path / "html")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"sphinx failed (warnings are errors):\n{proc.stderr[-6000:]}"
    for page in ("index", "getting-started", "howto", "model", "scenarios", "outputs", "performance",
                 "api/symtrack", "changelog", "gallery/index"):
        assert (tmp_path / "html" / f"{page}.html").is_file(), page
    # the API reference has the docstrings of the front door
    api = (tmp_path / "html" / "api" / "symtrack.html").read_text(encoding="utf-8")
    for name in ("symtrack.simulate", "symtrack.load_scenario", "symtrack.Result", "symtrack.run"):
        assert f'id="{name}"' in api, name
    # the gallery: a page per example with its title; the examples it runs show the figures they drew, the
    # others say how to run them; no example wrote next to the scripts
    run = runpy.run_path(str(DOCS / "gallery_examples.py"))["RUN"]
    names = sorted(p.stem for p in (ROOT / "examples").glob("*.py"))
    assert set(run) <= set(names) and len(names) >= 20
    index = (tmp_path / "html" / "gallery" / "index.html").read_text(encoding="utf-8")
    for name in names:
        page = (tmp_path / "html" / "gallery" / f"{name}.html").read_text(encoding="utf-8")
        title = (ROOT / "examples" / f"{name}.py").read_text(encoding="utf-8").split("\n", 1)[0].removeprefix('"""')
        assert f"{name}.html" in index and title in html.unescape(page).replace("\u2019", "'"), name
        images = re.findall(rf'src="\.\./_images/(sphx_glr_{name}_\d+\.png)"', page)
        if name in run:
            assert images, f"{name}: no figure in its gallery page"
            assert all((tmp_path / "html" / "_images" / image).stat().st_size > 10_000 for image in images), name
        else:
            assert not images and "Not run when this site is built" in page, name
    assert _files(src / "examples") == examples, "the gallery's examples wrote into examples/"


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


# The tables of the pages that are not figures the package computes: reference material (what a key, a
# column, a file, a command or a symbol is; a source's published figures; a layout of images), each by its
# header row with the reason it is reference. Every other table of docs/*.md is a table of run results: it
# sits between `<!-- figures:NAME:start -->` and `<!-- figures:NAME:end -->` and docs/figures.py writes it
# (`make figures`), or between the markers of docs/performance.py (`make performance`) or of the key tables
# (`make keys`). A new hand-typed table of results fails test_no_table_of_results_is_typed_by_hand.
REFERENCE_TABLES = {
    "| command | what it does |": "codegen.md: the commands of the generated code",
    "| preset | soil | clay / silt / sand [kg/kg] | bulk density [Mg/m^3] | suction [kPa] |":
        "getting-started.md: the built-in soils' inputs (checked against the presets: tests/test_newcomer_docs.py)",
    "| file | functions (inputs -> outputs) |": "codegen.md: the generated files",
    "| file | what |": "codegen.md: the files of an export",
    "| member | what |": "codegen.md: the members of a C struct",
    "| value references | causality | what | names [unit] |": "codegen.md: the FMU's variables",
    "| value references | type, causality | what | names [unit] |": "codegen.md: the engine FMU's variables",
    "| file | content |": "control.md: the files a run writes",
    "| name | path | soil |": "control.md: the built-in MPC scenarios",
    "| symbol | state / input | unit |": "model.md: the symbols of the equations",
    "| name | method | terrains |": "model.md: the integrators' registry",
    "| property | checked | tolerance and why |": "model.md: what the physics fuzzer checks",
    "| quantity | reported |": "model.md: Ferretti & Girelli's published validation figures",
    "| key | default | meaning |": "region.md: the keys of a region file",
    "| file | type | value | no data |": "region.md: the input rasters",
    "| column | meaning |": "region.md, validation.md: the columns of an output file",
    "| section | kind of run | the same as |": "scenarios.md: the sections of a scenario file",
    "| key | default | allowed | meaning |": "scenarios.md, terrain.md: the keys of a section",
    "| `[field]` key | default | allowed | meaning |": "studies.md: the keys of a field study",
    "| key | meaning | default |": "subsoil.md: the keys of the subsoil stress",
    "| parameter | default | source |": "subsoil.md: soil parameters and their sources",
    "| parameter | default | meaning, source |": "subsoil.md: soil parameters and their sources",
    "| offset | type | content |": "terrain.md: the layout of the raw field file",
    "| layer | units | GeoTIFF / NetCDF type | what |": "terrain.md: the exported GIS layers",
    "| `lateral_law` | what it is | fixed-step integrators | use it for |": "turning.md: the lateral laws",
    "| what | form | value | effect |": "turning.md: the regularisations and their settings",
    "| path (lateral deviation magnified) | yaw |": "validation-run.md: a layout of the figures",
    "| file | what it holds |": "validation.md: the files of a case",
    "| field | meaning |": "validation.md: the fields of a case file",
}


def _tables(text: str):
    """(line number, header row) of every Markdown table of a page, indented ones included."""
    lines = text.splitlines()
    for i in range(len(lines) - 1):
        if (re.match(r"^\s*\|", lines[i]) and re.match(r"^\s*\|[-:| ]+\|\s*$", lines[i + 1])
                and not (i and re.match(r"^\s*\|", lines[i - 1]))):
            yield i + 1, lines[i].strip()


def _pages():
    return sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)


GENERATED = (r"<!-- figures:([\w-]+):start -->\n.*?<!-- figures:\1:end -->",
             r"<!-- perf:([\w-]+):start -->\n.*?<!-- perf:\1:end -->",
             r"<!-- the key tables: .*?<!-- end of the key tables -->")


def test_the_tables_of_run_results_are_generated():
    """Every table docs/figures.py writes is in its page between its markers, with the line naming the
    command, the machine and the date above it; every pair of markers is one docs/figures.py writes."""
    script = (DOCS / "figures.py").read_text(encoding="utf-8")
    entries = dict(re.findall(r'^@table\("([\w-]+)", "([\w/.-]+\.md)"', script, re.M))
    assert len(entries) >= 30, "docs/figures.py writes fewer tables than the pages hold"
    found = {}
    for page in _pages():
        text = page.read_text(encoding="utf-8")
        for ind, name, body in re.findall(r"^([ \t]*)<!-- figures:([\w-]+):start -->\n(.*?)^\1<!-- figures:\2:end -->",
                                          text, re.S | re.M):
            where = page.relative_to(DOCS).as_posix()
            body = "".join(ln.removeprefix(ind) for ln in body.splitlines(keepends=True))  # a table in a list item
            assert name not in found, f"the table {name!r} is in {found[name]} and in {where}"
            found[name] = where
            assert entries.get(name) == where, f"{where}: the table {name!r} is not one docs/figures.py writes there"
            assert re.match(rf"Produced \d{{4}}-\d\d-\d\d by `[^`]+` on .+ \(\d+ (s|min)\); regenerate with "
                            rf"`make figures NAMES={name}`\.\n\n\|.*\|\n\|[-:| ]+\|\n(\|.*\|\n)+\Z", body), \
                f"{where}: the table {name!r} lacks its line (command, machine, date) or its table"
        starts = re.findall(r"<!-- figures:([\w-]+):start -->", text)
        ends = re.findall(r"<!-- figures:([\w-]+):end -->", text)
        assert sorted(starts) == sorted(ends) == sorted(n for n, w in found.items() if w == page.relative_to(
            DOCS).as_posix()), f"{page.name}: unpaired figures markers"
    assert sorted(found) == sorted(entries), f"tables docs/figures.py writes into no page: {set(entries) - set(found)}"
    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"^figures:.*\n\t\$\(PY\) docs/figures\.py \$\(if \$\(NAMES\),--only \$\(NAMES\)\)", make, re.M)
    assert re.search(r"<!-- figures-total:start -->\n.+\n<!-- figures-total:end -->",
                     (DOCS / "howto.md").read_text(encoding="utf-8"))


def test_no_table_of_results_is_typed_by_hand():
    """A table outside the generated blocks is reference material listed in REFERENCE_TABLES (by its
    header row, with the reason); a table of figures the package computes must be written by a command."""
    bad, used = [], set()
    for page in _pages():
        text = page.read_text(encoding="utf-8")
        for pat in GENERATED:
            text = re.sub(pat, lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
        for line, head in _tables(text):
            if head in REFERENCE_TABLES:
                used.add(head)
            else:
                bad.append(f"docs/{page.relative_to(DOCS).as_posix()}:{line}: {head}")
    assert not bad, ("tables that no command writes (put them between figures markers with an entry in "
                     "docs/figures.py, or, if reference material, in REFERENCE_TABLES):\n" + "\n".join(bad))
    assert used == set(REFERENCE_TABLES), f"REFERENCE_TABLES entries no page has: {set(REFERENCE_TABLES) - used}"


def test_the_constants_the_prose_quotes_are_the_codes():
    """A constant of the package that a page quotes in its prose (with its name and file) is the one
    the code holds: the memory estimate's parts (docs/terrain.md, "Memory")."""
    from symtrack.terrain import world

    text = (DOCS / "terrain.md").read_text(encoding="utf-8")
    assert f"- {world.RUN_BYTES_PER_CELL} bytes per cell (`RUN_BYTES_PER_CELL` of `symtrack/terrain/world.py`" in text
    assert f"- {world.RUN_FIXED_BYTES / 1e6:g} MB (`RUN_FIXED_BYTES`" in text
    assert f"{world.PASS_BYTES_PER_CELL} bytes per cell and pass" in text


def test_the_changelog_has_one_entry_per_release():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    import tomllib

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    releases = re.findall(r"^## (\S+)", text, re.M)
    assert releases and releases[0] == version, (releases, version)
    assert len(releases) == len(set(releases))


def _doc_commands():
    """(file, line, argv) of every `symtrack ...` line of a code block (```sh, ```text or no language) of
    README.md and docs/*.md: a trailing comment dropped, `&&` chains split, backslash continuations joined,
    a synopsis's optional parts (`[--set KEY=VALUE ...]`) taken as given."""
    import shlex

    files = [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)]
    for path in files:
        fence, pending = None, ""
        for lineno, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            m = re.match(r"^(\s*)(```+)(\S*)", raw)
            if m and fence is None:
                fence = (m.group(2), m.group(3) in ("", "sh", "bash", "console", "shell", "text"))
                continue
            if m and fence is not None and raw.strip() == fence[0]:
                fence = None
                continue
            if fence is None or not fence[1]:
                continue
            line = pending + raw
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            pending = ""
            for part in line.split("&&"):
                part = part.strip().removeprefix("$ ")
                if part.startswith(".venv/bin/symtrack "):
                    part = part[len(".venv/bin/"):]
                if not part.startswith("symtrack "):
                    continue
                argv = shlex.split(part.replace("[", " ").replace("]", " "), comments=True)
                yield path.relative_to(ROOT).as_posix(), lineno, [a for a in argv[1:] if a != "..."]


def test_every_command_in_the_docs_parses():
    """Each `symtrack ...` command the README and the docs show is one the command line accepts (its
    subcommand and options), and a `symtrack simulate` of a built-in scenario loads with the `--set` values
    it shows: a renamed option or key fails here, not in a reader's shell. Nothing is run."""
    import contextlib
    import io

    from symtrack.cli.main import build_parser
    from symtrack.simulation.scenario import builtin_names, load_scenario

    parser = build_parser()
    builtin = set(builtin_names())
    bad, n = [], 0
    for where, line, argv in _doc_commands():
        n += 1
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                args = parser.parse_args(argv)
        except SystemExit as e:
            if e.code not in (0, None):  # --help and --version exit 0
                bad.append(f"{where}:{line}: symtrack {' '.join(argv)}: {err.getvalue().strip().splitlines()[-1]}")
            continue
        if args.cmd == "simulate" and args.scenario in builtin:
            sets = list(args.set or [])
            if args.integrator:
                sets.append(f"run.integrator={args.integrator}")
            try:
                load_scenario(args.scenario, sets)
            except Exception as e:  # noqa: BLE001 - any refusal is a finding
                bad.append(f"{where}:{line}: symtrack {' '.join(argv)}: {e}")
    assert n > 50, f"only {n} commands found in the docs"
    assert not bad, "commands in the docs that the command line refuses:\n" + "\n".join(bad)


def test_the_tutorial_files_load(tmp_path):
    """The files of the getting-started tutorial, as it has the reader write them (the starting files of
    `symtrack new` with its TOML snippets applied, its soil file as shown), load and validate: a renamed
    key or preset fails here. Nothing is run (the tutorial's runs take a minute)."""
    import tomllib

    from symtrack.foundations.config import to_toml
    from symtrack.simulation.scenario import load_scenario
    from symtrack.studies.field import load_field_spec

    text = (DOCS / "getting-started.md").read_text(encoding="utf-8")
    snippets = [tomllib.loads(b) for b in re.findall(r"```toml\n(.*?)```", text, re.S)]
    soil_file = [s for s in snippets if "base" in s]
    assert len(soil_file) == 1, "the tutorial shows one soil file (with base = ...)"
    (tmp_path / "wet_clay.toml").write_text(to_toml(soil_file[0]))
    named = re.search(r"Write `(\w+\.toml)` next to `my_run\.toml`", text)
    assert named and named.group(1) == "wet_clay.toml"

    def merged(template: str, parts: list[dict]) -> dict:
        doc = tomllib.loads((ROOT / "symtrack" / "cli" / "templates" / template).read_text())
        for part in parts:
            for section, values in part.items():
                doc.setdefault(section, {}).update(values)
        return doc

    step5 = text.index("## 5.")
    sim_parts = [s for s in snippets if "base" not in s and "field" not in s]
    field_parts = [tomllib.loads(b) for b in re.findall(r"```toml\n(.*?)```", text[step5:], re.S)]
    assert sim_parts and field_parts
    (tmp_path / "my_run.toml").write_text(to_toml(merged("simulation.toml", sim_parts)))
    sc = load_scenario(str(tmp_path / "my_run.toml"))
    assert sc.vehicle["mass_kg"] == 6500.0 and sc.soil["cohesion_Pa"] == soil_file[0]["cohesion_Pa"]
    (tmp_path / "my_field.toml").write_text(to_toml(merged("field.toml", field_parts)))
    spec = load_field_spec(str(tmp_path / "my_field.toml"))
    assert spec.scenario.vehicle["mass_kg"] == 6500.0
    assert spec.scenario.soil["cohesion_Pa"] == soil_file[0]["cohesion_Pa"]
    assert list(spec.field.size_m) == [20.0, 9.0]
