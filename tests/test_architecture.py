"""The package's structure, read from the source (nothing imported): the layers of LAYERS below,
no import circle (imports inside functions count), no private name imported across modules,
nothing below the CLI and the bench imports symtrack.codegen (and nothing in the package the top-level
codegen/ entry point), no module outside the compile-and-cache API (symtrack.toolchain) composes a
cache path or takes a lock, and the soil law is reached only through its object
(symtrack.soil.law). Also: adding an integrator is one class and one registry entry (adding a
soil law: tests/test_soil_law.py)."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent

# layer of each top-level part of symtrack, bottom first; a module may import its own layer or below
LAYERS = {
    "foundations": 1, "model": 2, "presets": 2, "soil": 2, "vehicles": 2, "terrain": 3, "toolchain": 4, "native": 4,
    "integrators": 5, "simulation": 6, "control": 7, "reports": 7, "api": 7, "studies": 7, "region": 7, "codegen": 7,
    "bench": 8,
    "cli": 9, "__main__": 9, "": 9,
}
# a module of the soil's or the vehicles' room that acts on the field (reads its rasters, passes over its
# storage) sits with the field: nothing of the model's layer may import it
MODULE_LAYERS = {"soil.moisture": 3, "vehicles.wheeled": 3, "vehicles.towed": 3}
CODEGEN_ALLOWED = ("cli", "bench")
# the studies are an application: only the CLI, the bench and the region study (built on the studies' operations
# and sweeps) use them
STUDIES_ALLOWED = ("cli", "bench", "studies", "region")


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
    return MODULE_LAYERS.get(".".join(parts[1:3]), LAYERS[parts[1] if len(parts) > 1 else ""])


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
    """symtrack.toolchain sits below everything that compiles: it imports nothing of symtrack but foundations."""
    _, edges = graph
    below = {t.split(".")[1] for m, e in edges.items() if m.startswith("symtrack.toolchain") for t, _ in e
             if t.startswith("symtrack.") and not t.startswith("symtrack.toolchain")}
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
    """Every compiled artefact goes through symtrack.toolchain.build: no other module calls cache_root(),
    reads $SYMTRACK_CACHE, spells ~/.cache or takes a file lock (the check finds each in a snippet)."""
    mods, _ = graph
    bad = [hit for m, f in sorted(mods.items()) if not m.startswith("symtrack.toolchain")
           for hit in _cache_composers(f)]
    assert bad == []
    assert _cache_composers(mods["symtrack.toolchain.cache"])  # the reader sees the API's own
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


# The soil law's mathematics (symtrack.soil.cell) and its parameter vector belong to the law
# object: no other module calls the law's functions of cell.py, makes a law vector symbol of a
# fixed length, or brings back the positional vector's old helpers.
LAW_MODULES = ("symtrack.soil.cell", "symtrack.soil.law")
LAW_FUNCTIONS = frozenset({"k_eq", "bekker_regularisation_length", "bekker_pressure", "unloading_slope",
                           "reaction_pressure", "reaction_pressure_and_slope", "history_update", "cycle_increment"})
OLD_LAW_NAMES = frozenset({"NLAW", "law_vector", "soil_law_values", "_law_dict", "_law_symbols",
                           "reaction_pressure_fast"})


def _soil_law_misuses(mods, check_cell=True):
    """(module, what) for every use of the soil law around its object (the comment above)."""
    bad = []
    for m, f in mods.items():
        if m in LAW_MODULES:
            continue
        is_pkg = f.name == "__init__.py"
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            names = []
            if isinstance(node, ast.ImportFrom):
                base = _resolve(m, is_pkg, node.level, node.module or "")
                names = [a.name for a in node.names]
                if check_cell and base == "symtrack.soil.cell":
                    bad += [(m, f"from cell import {n}") for n in names if n in LAW_FUNCTIONS]
                names += [a.asname for a in node.names if a.asname]
            elif isinstance(node, ast.Attribute):
                names = [node.attr]
                if check_cell and node.attr in LAW_FUNCTIONS and isinstance(node.value, ast.Name) \
                        and node.value.id == "cell":
                    bad.append((m, f"cell.{node.attr}"))
            elif isinstance(node, ast.Name):
                names = [node.id]
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names = [node.name]
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "sym" \
                    and node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value == "law" \
                    and any(isinstance(a, ast.Constant) for a in node.args[1:2]):
                bad.append((m, "a law vector symbol of a fixed length"))  # (one sized by the law's values is fine)
            bad += [(m, n) for n in names if n in OLD_LAW_NAMES]
    return bad


def test_the_soil_law_is_used_only_through_its_object(graph):
    mods, _ = graph
    assert _soil_law_misuses(mods) == []
    tests = {f"tests.{f.stem}": f for f in (ROOT / "tests").glob("*.py")}  # the tests may test cell.py itself
    assert _soil_law_misuses(tests, check_cell=False) == []


def test_the_soil_law_check_can_fail(tmp_path):
    """The check above sees the old positional vector, a law function of cell.py called from a
    consumer and a law symbol of a fixed length, in a throwaway package."""
    pkg = tmp_path / "symtrack"
    (pkg / "soil").mkdir(parents=True)
    (pkg / "terrain").mkdir()
    (pkg / "terrain" / "a.py").write_text("from ..soil import cell\nimport casadi as ca\n"
                                          "law = ca.SX.sym('law', 5)\np = cell.reaction_pressure(0, 0, 0, *law)\n")
    (pkg / "terrain" / "b.py").write_text("from ..soil.cell import k_eq\nNLAW = 5\n")
    mods = {"symtrack.terrain.a": pkg / "terrain" / "a.py", "symtrack.terrain.b": pkg / "terrain" / "b.py"}
    assert sorted(_soil_law_misuses(mods)) == [
        ("symtrack.terrain.a", "a law vector symbol of a fixed length"),
        ("symtrack.terrain.a", "cell.reaction_pressure"),
        ("symtrack.terrain.b", "NLAW"), ("symtrack.terrain.b", "from cell import k_eq")]


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


# Positional reads of the state vector: where each state sits is symtrack/model/layout.py's business
# (StateLayout); a vehicle model with more states would silently shift every one of these.
_STATE_NAMES = r"(?:x|xv|x0|xs|xt|xc|w|w1|ws|wv|s\.wv|state|self\._x|self\.x_new)"
POSITIONAL_STATE = {
    "an NV constant": re.compile(r"^\s*NV\s*=|#define\s+NV\s+\d"),
    "a slice at the vehicle's size": re.compile(r"(?<!\))\[\s*:\s*(?:NV|nv|12)\s*\]|,\s*:\s*(?:NV|nv|12)\s*\]"
                                                r"|\[\s*(?:NV|nv)\s*(?::|\+)"),
    "len(VEHICLE_STATES) as an index": re.compile(r"len\(VEHICLE_STATES\)"),
    "the pose by position (x[0], x[1], x[2])": re.compile(_STATE_NAMES + r"\[0\],\s*" + _STATE_NAMES + r"\[1\],\s*"
                                                         + _STATE_NAMES + r"\[2\]"),
    "a state's head sliced by position": re.compile(r"\b" + _STATE_NAMES + r"\[:[36]\]"),
    # a trajectory's (rows: times, columns: states) column or head by position: res.X[:, 0], X[:, :2], X[-1, 2]
    "a trajectory column by position (X[:, k])": re.compile(r"(?:(?<![\w.])(?:X|prev)|\.X)\[[^\]\n]*,\s*:?\s*\d+\s*\]"),
    # the prediction's states as the head of a state vector (the MPC names that block: PathTrackingMPC.pred,
    # pred_index)
    "a head at the prediction's size ([:nxp])": re.compile(r"\[\s*:\s*nxp\s*\]"),
    "a cell field by stride (xc[1::2])": re.compile(r"\b" + _STATE_NAMES + r"\[\s*\d\s*::\s*\d\s*\]"),
    # the engine's C reads each state through the generated ENG_W_<NAME> (grid_engine_model.engine_layout_c)
    "a vehicle state by position in C (w[k])": re.compile(r"(?:\b(?:w|w0|w1|ws|wv)|->wv|\.wv)\[\s*\d+\s*\]"),
}
# the C sees the state's sizes and positions through the generated ENG_NV, ENG_NW and ENG_W_<NAME>; the
# Python reads every state through a layout
C_CHECKS = ("an NV constant", "a slice at the vehicle's size", "a vehicle state by position in C (w[k])")
PY_ONLY = ("a vehicle state by position in C (w[k])",)
LAYOUT_MODULE = "symtrack/model/layout.py"


def _positional_state_reads(root: Path):
    found = []
    for f in sorted([*root.rglob("*.py"), *root.rglob("*.c"), *root.rglob("*.h")]):
        rel = f.relative_to(ROOT).as_posix()
        if rel == LAYOUT_MODULE:
            continue
        checks = {w: rx for w, rx in POSITIONAL_STATE.items()
                  if (f.suffix == ".py" and w not in PY_ONLY) or (f.suffix != ".py" and w in C_CHECKS)}
        for n, line in enumerate(f.read_text().splitlines(), 1):
            for what, rx in checks.items():
                if rx.search(line):
                    found.append(f"{rel}:{n}: {what}: {line.strip()}")
    return found


def test_no_positional_slicing_of_the_state_outside_the_layout():
    """Every index into the state vector comes from a StateLayout (issue 20)."""
    assert _positional_state_reads(ROOT / "symtrack") == []


def test_the_positional_scan_catches_todays_forms(tmp_path, monkeypatch):
    """The scan above is not vacuous: each form the package held before the layout is caught."""
    pkg = tmp_path / "symtrack"
    pkg.mkdir()
    before = ["NV = len(VEHICLE_STATES)", "xc, xv = x[NV:], x[:NV]", "x[0], x[1], x[2] = x_m, y_m, yaw_rad",
              "mass_w[:12] = 1.0", "zc = x[NV::2]", "x[NV + 2 * act + 1]", "X, Y, psi = x[:3]",
              "nv = len(VEHICLE_STATES)", "#define NV 12", "self.x_new[None, :NV]", "xs.append(x[:nv].copy())",
              "seg = np.hypot(np.diff(res.X[:, 0]), np.diff(res.X[:, 1]))", "prev = X[:-1, :2]",
              "d = X[:, 0] - prev[:, 0]", "psi0 = res.X[0, 2]", "xm, ym = X[mid, 0], X[mid, 1]",
              "xs = np.concatenate([st.x[:nxp], st.u])", "return ode[:nxp], alg", "rates = xc[1::2][act]"]
    (pkg / "old.py").write_text("\n".join(before) + "\n")
    (pkg / "old.c").write_text("#define NV 12\nscan(E, w1[0], w1[1], w1[2]);\ndouble u = w[3], r = w[5];\n"
                               "pose_grid(E->agrid, E->a, a1, E->wv[2], w1[2], n);\nE.wv[0] = GV_START_X;\n"
                               "double X = w[ENG_W_X];\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = _positional_state_reads(pkg)
    assert {int(f.split(":")[1]) for f in found if "old.py" in f} == set(range(1, len(before) + 1)), "\n".join(found)
    assert sorted({f.split(":")[1] for f in found if "old.c" in f}) == ["1", "2", "3", "4", "5"]
    assert "hexdigest()[:12]" not in "".join(found)
# The world manager's rules (footprint, release, sector assignment Cell[i, j] -> CHANNEL[i mod M, j mod M],
# INFO_IN / INFO_OUT, the collision and coverage errors) have one home: symtrack/native/grid_engine.c
# (the engine runs them in its steps, the IDAS reference path through ChannelManager). The Python copy
# is the tests' oracle (tests/engine_oracle.py).
WORLD_MANAGER_HOME = "symtrack/native/grid_engine.c"
SECTOR_RULE = re.compile(r"%\s*\(?\s*(?:[A-Za-z_]\w*(?:\.|->))*M\b")  # i % M, i % self.M, j % E->M
STORAGE_WRITE = re.compile(r"\.(?:z|zdot|zmax|pmax|phase|zoff|cycles)\[[^\]\n]*\]\s*[+\-]?=(?!=)")  # INFO_OUT
RULE_FUNCTIONS = {"cells_under", "channel_of", "scan", "_scan", "mark_footprint", "check_cover", "info_out",
                  "_info_out", "_check_collisions", "_uncovered"}
STORAGE_OWNER = "symtrack/terrain/storage.py"  # the storage's own files and upgrades


def _world_manager_copies(root: Path) -> list[str]:
    found = []
    for f in sorted((root / "symtrack").rglob("*")):
        rel = f.relative_to(root).as_posix()
        if f.suffix not in (".py", ".c", ".h") or rel == WORLD_MANAGER_HOME:
            continue
        text = f.read_text()
        for n, line in enumerate(text.splitlines(), 1):
            code = line.split("#")[0] if f.suffix == ".py" else line.split("//")[0]
            if SECTOR_RULE.search(code) and "strftime(" not in code:  # (a time format's %M is the minutes)
                found.append(f"{rel}:{n}: the sector rule ({line.strip()})")
            if f.suffix == ".py" and rel != STORAGE_OWNER and STORAGE_WRITE.search(code):
                found.append(f"{rel}:{n}: a write into the cell storage (INFO_OUT) ({line.strip()})")
        if f.suffix == ".py":
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in RULE_FUNCTIONS:
                    found.append(f"{rel}:{node.lineno}: a world-manager rule function {node.name}()")
        elif re.search(r"\b(?:scan|channel_of|mark_footprint|info_out)\s*\([^;]*\)\s*\{", text):
            found.append(f"{rel}: a world-manager rule function in C")
    return found


def test_one_home_for_the_world_manager_rules():
    assert (ROOT / WORLD_MANAGER_HOME).exists()
    assert not _world_manager_copies(ROOT), _world_manager_copies(ROOT)


def test_the_one_home_check_sees_a_second_copy(tmp_path):
    """The check above finds the World's old copy (its sector rule, footprint scan and INFO_OUT)."""
    pkg = tmp_path / "symtrack" / "terrain"
    pkg.mkdir(parents=True)
    (tmp_path / "symtrack" / "native").mkdir()
    (tmp_path / WORLD_MANAGER_HOME).write_text("static long long channel_of(eng_t *E, long long c) { return 0; }\n")
    (pkg / "ok.py").write_text("def figures(world):\n    return world.M % 2 == 0  # modulus parity, not the rule\n")
    assert _world_manager_copies(tmp_path) == []
    (pkg / "world.py").write_text(
        "def channel_of(self, cells):\n    i, j = divmod(cells, self.ny)\n"
        "    return (i % self.M) * self.M + (j % self.M)\n"
        "def after_step(self, st, cells, zc):\n    st.z[cells] = zc\n")
    found = _world_manager_copies(tmp_path)
    assert any("sector rule" in f for f in found) and any("channel_of()" in f for f in found)
    assert any("cell storage" in f for f in found)
    (pkg / "world.py").unlink()
    other = tmp_path / "symtrack" / "native" / "other.c"
    other.write_text("static long long scan(eng_t *E) { return E->n % E->M; }\n")
    assert len(_world_manager_copies(tmp_path)) == 2


# A vehicle is chosen by the registry and read through its capabilities (symtrack.vehicles.base): no code
# outside the vehicles' own modules compares a value with a vehicle model's name or asks for an attribute
# that stood for one.
VEHICLE_HOME = "symtrack/vehicles/"
OLD_VEHICLE_FLAGS = frozenset({"own_contact"})


def _vehicle_name_branches(root: Path, names) -> list[str]:
    found = []
    for f in sorted((root / "symtrack").rglob("*.py")):
        rel = f.relative_to(root).as_posix()
        if rel.startswith(VEHICLE_HOME):
            continue
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                consts = [c.value for side in sides for c in ast.walk(side)
                          if isinstance(c, ast.Constant) and isinstance(c.value, str)]
                hit = [c for c in consts if c in names]
                if hit:
                    found.append(f"{rel}:{node.lineno}: a comparison with the vehicle name {hit[0]!r}")
            elif isinstance(node, ast.Attribute) and node.attr in OLD_VEHICLE_FLAGS:
                found.append(f"{rel}:{node.lineno}: {node.attr}")
            elif isinstance(node, ast.Constant) and node.value in OLD_VEHICLE_FLAGS:
                found.append(f"{rel}:{node.lineno}: {node.value!r}")
    return found


def _vehicle_names():
    from symtrack.vehicles import registry

    return {n for v in registry.REGISTRY.values() for n in (v.name, v.entry_name,
                                                             v.for_options(_options("shear")).name)}


def _options(lateral_law):
    from symtrack.model.options import ModelOptions

    return ModelOptions(lateral_law=lateral_law)


def test_no_branch_on_a_vehicle_name_outside_the_vehicles():
    names = _vehicle_names()
    assert {"planar", "planar_lateral", "3d", "3d_lateral"} <= names  # the reader knows the menu
    assert _vehicle_name_branches(ROOT, names) == []


def test_the_vehicle_name_check_sees_todays_old_forms(tmp_path):
    """The check above finds the branches the package held before the vehicle plug-in."""
    pkg = tmp_path / "symtrack" / "simulation"
    pkg.mkdir(parents=True)
    (pkg / "a.py").write_text(
        "def f(opts, model, sc):\n"
        "    if opts.vehicle == '3d':\n        pass\n"
        "    if getattr(opts, 'vehicle', 'planar') == '3d':\n        pass\n"
        "    if sc.model.vehicle != 'planar':\n        pass\n"
        "    if getattr(model.vehicle, 'own_contact', False):\n        pass\n"
        "    return model.vehicle.own_contact or opts.vehicle in ('planar_lateral',)\n")
    (tmp_path / "symtrack" / "vehicles").mkdir()
    (tmp_path / "symtrack" / "vehicles" / "ok.py").write_text("name = 'x' if 1 == 2 else '3d'\nb = 'planar' == name\n")
    found = _vehicle_name_branches(tmp_path, {"planar", "planar_lateral", "3d", "3d_lateral"})
    assert sorted(int(f.split(":")[1]) for f in found) == [2, 4, 6, 8, 10, 10], found
