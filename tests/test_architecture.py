"""The package's structure, read from the source (nothing imported): the layers of DESIGN.md,
no import circle (imports inside functions count), no private name imported across modules,
nothing below the CLI and the bench imports symtrack.codegen (and nothing in the package the top-level
codegen/ entry point), and no module outside the compile-and-cache API (symtrack.build) composes a
cache path or takes a lock. Also: adding an integrator is one class and one registry entry."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent

# layer of each top-level part of symtrack, bottom first; a module may import its own layer or below
LAYERS = {
    "foundations": 1, "model": 2, "presets": 2, "terrain": 3, "build": 4, "native": 4, "integrators": 5,
    "simulation": 6, "control": 7, "reports": 7, "api": 7, "studies": 7, "codegen": 7, "bench": 8, "cli": 9,
    "__main__": 9, "": 9,
}
CODEGEN_ALLOWED = ("cli", "bench")
STUDIES_ALLOWED = ("cli", "bench", "studies")  # the studies are an application: only the CLI and the bench use them


def _modules():
    mods = {}
    for pkg in ("symtrack", "codegen"):
        for f in (ROOT / pkg).rglob("*.py"):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = f
    return mods


def _resolve(mod, is_pkg, level, name):
    if level == 0:
        return name
    base = mod.split(".")
    if not is_pkg:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _edges(mods):
    """module -> {(imported module, imported name or None)} for imports among mods."""
    out = {m: set() for m in mods}
    for m, f in mods.items():
        is_pkg = f.name == "__init__.py"
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(m, is_pkg, node.level, node.module or "")
                for a in node.names:
                    full = f"{base}.{a.name}"
                    targets.append((full, None) if full in mods else (base, a.name))
            for t, name in targets:
                while t and t not in mods:
                    t = t.rpartition(".")[0]
                if t and t != m:
                    out[m].add((t, name))
    return out


def _layer(mod: str) -> int:
    parts = mod.split(".")
    return LAYERS[parts[1] if len(parts) > 1 else ""]


@pytest.fixture(scope="module")
def graph():
    mods = _modules()
    return mods, _edges(mods)


def test_no_import_cycles(graph):
    mods, edges = graph
    adj = {m: {t for t, _ in e} for m, e in edges.items()}
    index, low, stack, on, sccs = {}, {}, [], set(), []

    def visit(v):  # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in adj[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for m in mods:
        if m not in index:
            visit(m)
    assert sccs == []
    assert len(mods) > 50  # the reader found the package


def test_no_private_names_imported_from_another_module(graph):
    _, edges = graph
    private = [(m, t, n) for m, e in edges.items() for t, n in e if n and n.startswith("_") and not n.startswith("__")]
    assert private == []


def test_layers_import_only_downwards(graph):
    _, edges = graph
    upward = []
    for m, e in edges.items():
        if not m.startswith("symtrack"):
            continue
        for t, _ in e:
            if t.startswith("symtrack") and _layer(t) > _layer(m):
                upward.append((m, t))
    assert upward == []


def test_only_cli_and_bench_import_codegen(graph):
    """symtrack.codegen is an application the CLI and the bench call; the top-level codegen/ is the
    checkout's ``python -m codegen`` entry point only (not installed): nothing in the package imports it."""
    _, edges = graph
    users = {m.split(".")[1] for m, e in edges.items() for t, _ in e
             if m.startswith("symtrack.") and t.startswith("symtrack.codegen") and not m.startswith("symtrack.codegen")}
    assert "cli" in users  # the reader found symtrack codegen
    assert users <= set(CODEGEN_ALLOWED)
    top = [(m, t) for m, e in edges.items() for t, _ in e if m.startswith("symtrack") and t.split(".")[0] == "codegen"]
    assert top == []
    assert {m for m in edges if m.split(".")[0] == "codegen"} == {"codegen", "codegen.__main__"}


def test_the_build_api_imports_only_foundations(graph):
    """symtrack.build sits below everything that compiles: it imports nothing of symtrack but foundations."""
    _, edges = graph
    below = {t.split(".")[1] for m, e in edges.items() if m.startswith("symtrack.build") for t, _ in e
             if t.startswith("symtrack.") and not t.startswith("symtrack.build")}
    assert below <= {"foundations"}


# what only the compile-and-cache API may do: compose a cache path, read the cache's variable, lock
CACHE_CALLS = ("cache_root",)
LOCK_NAMES = ("fcntl", "flock", "lockf")
CACHE_STRINGS = ("SYMTRACK_CACHE", ".cache")


def _cache_composers(path: Path) -> list[str]:
    """The places in one source file that compose a cache path or take a lock."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        name = (node.func.id if isinstance(node.func, ast.Name) else node.func.attr
                if isinstance(node.func, ast.Attribute) else "") if isinstance(node, ast.Call) else ""
        if name in CACHE_CALLS or name in LOCK_NAMES:
            found.append(f"{path.name}:{node.lineno} {name}()")
        elif isinstance(node, ast.Import | ast.ImportFrom):
            mods = [a.name for a in node.names] + [node.module or ""] if isinstance(node, ast.ImportFrom) else \
                [a.name for a in node.names]
            if any(m.split(".")[0] in LOCK_NAMES for m in mods):
                found.append(f"{path.name}:{node.lineno} import {', '.join(mods)}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in CACHE_STRINGS:
            found.append(f"{path.name}:{node.lineno} {node.value!r}")
    return found


def test_no_cache_path_or_lock_outside_the_build_api(graph, tmp_path):
    """Every compiled artefact goes through symtrack.build.build: no other module calls cache_root(),
    reads $SYMTRACK_CACHE, spells ~/.cache or takes a file lock (the check finds each in a snippet)."""
    mods, _ = graph
    bad = [hit for m, f in sorted(mods.items()) if not m.startswith("symtrack.build") for hit in _cache_composers(f)]
    assert bad == []
    assert _cache_composers(mods["symtrack.build.cache"])  # the reader sees the API's own
    snippet = tmp_path / "snippet.py"
    snippet.write_text("import fcntl\nfrom x import cache_root\np = cache_root() / 'grid'\nq = env['SYMTRACK_CACHE']\n")
    assert len(_cache_composers(snippet)) == 3


def test_only_cli_and_bench_import_studies(graph):
    _, edges = graph
    users = {m.split(".")[1] for m, e in edges.items() for t, _ in e
             if m.startswith("symtrack.") and t.startswith("symtrack.studies")}
    assert "cli" in users  # the reader found the sweep command
    assert users <= set(STUDIES_ALLOWED)


def test_the_reader_sees_a_circle_and_a_private_import(tmp_path, monkeypatch):
    """The checks above can fail: a two-module circle through a function-level import and a
    private import, in a throwaway package."""
    pkg = tmp_path / "symtrack"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import _hidden\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n\n_hidden = 1\n")
    mods = {"symtrack": pkg / "__init__.py", "symtrack.a": pkg / "a.py", "symtrack.b": pkg / "b.py"}
    e = _edges(mods)
    assert ("symtrack.b", "_hidden") in e["symtrack.a"] and ("symtrack.a", None) in e["symtrack.b"]


class EulerStepper:
    """A toy integrator (explicit Euler on the ODE form, in equal sub-steps of fixed_step_s): the
    one class an integrator needs."""

    def __init__(self, model, settings):
        self.model, self.settings, self.n = model, settings, 0

    def step(self, x, u, p, dt):
        from symtrack.integrators.settings import substeps

        n = substeps(dt, self.settings.fixed_step_s)
        x = np.asarray(x, dtype=float)
        for _ in range(n):
            x = x + dt / n * np.array(self.model.ode(x, u, p)).ravel()
        self.n += n
        return x

    def reset(self):
        pass

    def stats(self):
        return {"nsteps": self.n}


def test_adding_an_integrator_is_one_class_and_one_registry_entry():
    import symtrack
    from symtrack.integrators import registry

    spec = registry.register(registry.IntegratorSpec(  # the one registry entry
        "euler_toy", "explicit Euler (a test's toy)", terrains=frozenset({"homogeneous"}), fixed_step=True,
        homogeneous=EulerStepper))
    try:
        sc = symtrack.load_scenario("validation", {"run.integrator": "euler_toy", "run.duration_s": 0.5,
                                                   "run.fixed_step_s": 0.0005, "run.stop_after_distance_m": "none"})
        res = symtrack.simulate(sc)
        ref = symtrack.simulate(sc, integrator="cvodes")
        assert res.runs[0].stats["nsteps"] == 1000
        assert res.column("u_m_s")[-1] > 0.1
        assert res.column("u_m_s")[-1] == pytest.approx(ref.column("u_m_s")[-1], rel=2e-2)
        with pytest.raises(ScenarioError, match="does not integrate the grid"):
            symtrack.simulate("validation_grid", integrator="euler_toy")
    finally:
        registry.unregister(spec.name)
    with pytest.raises(ScenarioError, match="euler_toy"):
        symtrack.load_scenario("validation", ["run.integrator=euler_toy"])


def test_every_package_folder_is_a_package_and_tracked():
    """A folder without __init__.py (or one a .gitignore pattern hides, as `build/` once did)
    works in an editable install and vanishes from a wheel."""
    import subprocess

    tracked = set(subprocess.run(["git", "ls-files", "symtrack"], cwd=ROOT, capture_output=True, text=True,
                                 check=True).stdout.split())
    if not tracked:
        pytest.skip("not a git checkout")
    folders = {str(Path(f).parent) for f in tracked if f.endswith(".py")}
    missing = sorted(d for d in folders if f"{d}/__init__.py" not in tracked)
    assert missing == []
