"""Property-based test of scenario input (issue 26, item 5): hypothesis mutates the built-in
scenario files (every kind a user writes: simulate, MPC, field study) and every outcome must be a
validated scenario or the package's own error with a message, never a traceback of another type.

Mutations: a value replaced (wrong type, NaN, infinities, huge or negative numbers, unicode text,
empty containers), a key deleted, an unknown key added, at any depth (arrays of tables too); and
the whole text mangled (truncated, unicode inserted); the file saved in another encoding (Latin-1,
cp1252, UTF-16, with a UTF-8 byte-order mark) or binary noise, through every file loader (issue 38,
item 7: a one-line error naming the file, not a UnicodeDecodeError). A scenario that is accepted must
also write itself back as TOML that reads back to the same document (scenario.resolved.toml)."""

from __future__ import annotations

import math
import os
import tempfile
import tomllib
from importlib import resources
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from symtrack.foundations.config import to_toml
from symtrack.foundations.errors import SymtrackError
from symtrack.studies.runfile import sweep_kinds
from symtrack.studies.runs import load, package_names, scenario_text

PACKAGES = {name: kind.package for name, kind in sweep_kinds().items()}  # a sweep's kinds: simulate, mpc, field
KINDS = tuple(PACKAGES)
BUILTINS = [(kind, name) for kind in KINDS for name in package_names(PACKAGES[kind])]

VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -1.0, -0.0, 1e-320, 10**30, -(10**30), 0, -1,
                     True, False, "", "nan", "ü∂ß🚜", "a\nb", "\x00", [], {}, [1.0, "x"], {"k": 1}]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.text(max_size=12),
    st.lists(st.floats(allow_nan=False, allow_infinity=False, width=32), max_size=3),
)


def _doc(kind: str, name: str) -> tuple[str, dict]:
    text = resources.files(PACKAGES[kind]).joinpath(name + ".toml").read_text()
    return text, tomllib.loads(text)


def _paths(doc, prefix=()):
    """Every (path, value) of the document: a path is a tuple of keys and list indices."""
    items = doc.items() if isinstance(doc, dict) else enumerate(doc)
    for k, v in items:
        yield (*prefix, k), v
        if isinstance(v, dict) or (isinstance(v, list) and v and isinstance(v[0], dict)):
            yield from _paths(v, (*prefix, k))


def _parent(doc, path):
    for k in path[:-1]:
        doc = doc[k]
    return doc


@st.composite
def mutated(draw):
    kind, name = draw(st.sampled_from(BUILTINS))
    _, doc = _doc(kind, name)
    paths = list(_paths(doc))
    path, _ = draw(st.sampled_from(paths))
    op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown"]))
    parent = _parent(doc, path)
    if op == "replace":
        parent[path[-1]] = draw(VALUES)
    elif op == "delete":
        if isinstance(parent, list):
            parent.pop(path[-1])
        else:
            del parent[path[-1]]
    else:
        target = parent[path[-1]] if isinstance(parent[path[-1]], dict) else parent
        if isinstance(target, list):
            target = doc
        target[draw(st.text(min_size=1, max_size=8))] = draw(VALUES)
    return kind, name, op, path, doc


def _outcome(kind: str, text: str, name: str):
    """The loader's result, or the package's error; any other exception fails the test."""
    try:
        return load(kind, text, name)
    except SymtrackError as err:
        assert str(err).strip(), f"{kind} {name}: an error without a message ({type(err).__name__})"
        return err


# SYMTRACK_FUZZ_EXAMPLES=5000 for a longer search (5000 passed when the test was written)
@settings(max_examples=int(os.environ.get("SYMTRACK_FUZZ_EXAMPLES", "100")), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_document_is_a_scenario_or_a_clear_error(case):
    kind, name, op, path, doc = case
    text = to_toml(doc)  # the writer takes every document a user's TOML can hold
    res = _outcome(kind, text, name)
    event(f"{op}: {'error' if isinstance(res, SymtrackError) else 'accepted'}")
    if isinstance(res, SymtrackError):
        # the message says where: a key of the mutated path (a replaced value, an unknown key's table)
        names = [p for p in path if isinstance(p, str)]
        assert any(n in str(res) for n in names), f"{kind} {name}: {op} at {path}: {res}"
        return
    # accepted: what the run writes as scenario.resolved.toml must read back as the same document
    resolved = _resolved(kind, res)
    back = tomllib.loads(to_toml(resolved))
    assert _same(back, {k: v for k, v in resolved.items() if v is not None}), f"{kind} {name} {op} {path}"


def _resolved(kind: str, res) -> dict:
    """The document a run of ``kind`` writes as its resolved scenario (scenario.resolved.toml,
    field.resolved.toml)."""
    return {"simulate": lambda: res.to_dict(), "mpc": lambda: res.resolved_dict(),
            "field": lambda: res.document}[kind]()


def _same(a, b) -> bool:
    if isinstance(b, tuple):
        b = list(b)
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        b = {k: v for k, v in b.items() if v is not None}
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(BUILTINS), st.data())
def test_mangled_text_is_a_scenario_or_a_clear_error(builtin, data):
    kind, name = builtin
    text, _ = _doc(kind, name)
    cut = data.draw(st.integers(0, len(text)))
    insert = data.draw(st.sampled_from(["", "\x00", "🚜", "\ufeff", "=", "[", "]]", "\n[run]\n", '"', "\r"]))
    _outcome(kind, text[:cut] + insert + text[cut + data.draw(st.integers(0, 20)):], name)


def test_the_writer_round_trips_strings_a_user_may_write():
    """Descriptions with newlines, quotes, tabs, backslashes and unicode survive
    scenario.resolved.toml."""
    doc = {"name": "n", "description": 'two\nlines, a "quote", a\ttab, a \\ and 🚜\x7f\x01', "run": {"x": 1.0}}
    assert tomllib.loads(to_toml(doc)) == doc


def _file_loaders(kind: str):
    """The loaders of a scenario file of ``kind``: its own (``symtrack simulate / mpc / field``) and the
    sweep's (:func:`symtrack.studies.runs.scenario_text`)."""
    from symtrack.control.scenario import load as load_mpc
    from symtrack.simulation.scenario import load_scenario
    from symtrack.studies.field import load_field_spec
    from symtrack.studies.operations import is_operation_document, load_operation_spec

    def field(path):
        return load_operation_spec(path) if is_operation_document(path) else load_field_spec(path)

    def sweep(path):
        text, name = scenario_text(path, PACKAGES[kind])
        return load(kind, text, name)

    return [{"simulate": load_scenario, "mpc": load_mpc, "field": field}[kind], sweep]


ENCODINGS = ["latin-1", "cp1252", "utf-16", "utf-16-be", "utf-8-sig", "binary"]


@settings(max_examples=int(os.environ.get("SYMTRACK_FUZZ_EXAMPLES", "60")), deadline=None)
@given(st.sampled_from(BUILTINS), st.sampled_from(ENCODINGS), st.binary(min_size=1, max_size=64), st.data())
def test_a_scenario_file_in_another_encoding_is_a_one_line_error_naming_it(builtin, encoding, noise, data):
    kind, name = builtin
    text, _ = _doc(kind, name)
    text = "# Feld über der Straße, 3 °C\n" + text  # a comment a user writes, not ASCII
    if encoding == "binary":
        cut = data.draw(st.integers(0, len(text)))
        raw = text.encode()[:cut] + noise + b"\x00" + text.encode()[cut:]
    else:
        raw = text.encode(encoding)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"{name}.toml"
        path.write_bytes(raw)
        for loader in _file_loaders(kind):
            try:
                res = loader(str(path))
            except SymtrackError as err:
                msg = str(err)
                assert "\n" not in msg and str(path) in msg, f"{kind} {name} {encoding}: {msg}"
                assert encoding != "utf-8-sig", msg  # a UTF-8 byte-order mark is only dropped
                assert ("NUL bytes" if encoding == "binary" else "UTF-16" if "16" in encoding else "not UTF-8") in msg
                event(f"{encoding}: error")
                continue
            assert encoding == "utf-8-sig", f"{kind} {name}: {encoding} accepted"
            event(f"{encoding}: accepted")
            assert res is not None


def test_the_cli_names_a_scenario_and_a_preset_file_that_are_not_utf8(tmp_path, capsys):
    from symtrack.cli.main import main

    text, _ = _doc("simulate", "validation")
    sc = tmp_path / "latin.toml"
    sc.write_bytes(("# über\n" + text).encode("latin-1"))
    assert main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"scenario file {str(sc)!r} is not UTF-8 text (byte 0xfc at offset 2, line 1" in err
    assert not (tmp_path / "o").exists()
    preset = tmp_path / "heavy.toml"
    preset.write_bytes('base = "reference_crawler"\nmass_kg = 7000.0\ndescription = "Rüttler"\n'.encode("utf-16"))
    sc.write_text(text.replace('preset = "reference_crawler"', f'preset = "{preset}"'))
    assert main(["simulate", str(sc), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"vehicle.preset file {str(preset)!r} is UTF-16 text" in err
    assert main(["presets", str(preset)]) == 2
    assert "is UTF-16 text" in capsys.readouterr().err
