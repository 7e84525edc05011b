"""generated/ is in sync with the model, deterministic, exportable and documented by its manifest."""

from __future__ import annotations

import json

import pytest

from symtrack.codegen import cli as codegen_cli
from symtrack.model import SystemModel
from symtrack.native.generate import model_functions, unit_of
from symtrack.simulation.scenario import load_scenario

GEN = codegen_cli.REPO_GENERATED


def test_generated_folder_is_in_sync_with_the_model(tmp_path):
    # regenerate into a temporary folder and compare byte by byte with generated/
    changed = codegen_cli.write(tmp_path)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert changed == names
    committed = sorted(p.name for p in GEN.iterdir() if not p.name.startswith("."))
    assert names == committed
    stale = [n for n in names if (tmp_path / n).read_bytes() != (GEN / n).read_bytes()]
    assert not stale, f"generated/ is out of date ({stale}): run python -m codegen"
    # regenerating over an up-to-date folder changes nothing
    assert codegen_cli.write(tmp_path) == []


def test_generated_files_are_exportable_and_small():
    for path in GEN.iterdir():
        data = path.read_bytes()
        assert len(data) < 1_500_000, f"{path.name} is {len(data)} bytes"
        if path.suffix == ".c":
            assert b"#error" not in data, path.name


def test_manifest_names_hash_and_units():
    man = json.loads((GEN / "manifest.json").read_text())
    # generated/ holds the validation scenario's model (the creep law it declares), not the default
    model = SystemModel(load_scenario("validation").model)
    assert model.opts.lateral_law == "creep" and SystemModel().opts.lateral_law == "shear"
    gen = model_functions(model, "homogeneous")
    assert man["model_hash"] == gen.model_hash
    assert man["casadi_version"] == gen.casadi_version
    funcs = man["functions"]
    for name in ("homogeneous_ode", "jac_homogeneous_ode", "homogeneous_dae", "jac_homogeneous_dae",
                 "homogeneous_outputs", "homogeneous_linearize", "homogeneous_linearize_outputs",
                 "homogeneous_accel", "homogeneous_rosenbrock_step", "homogeneous_rosenbrock_controlled_chunk256",
                 "homogeneous_rosenbrock_controlled_chunk16"):
        assert name in funcs, name
    x_in = funcs["homogeneous_ode"]["inputs"][0]
    assert [e["name"] for e in x_in["elements"]] == list(model.state_names)
    units = {e["name"]: e["unit"] for e in x_in["elements"]}
    assert units["u_m_s"] == "m/s" and units["yaw_rad"] == "rad" and units["torque_left_N_m"] == "N m"
    ode_out = {e["name"]: e["unit"] for e in funcs["homogeneous_ode"]["outputs"][0]["elements"]}
    assert ode_out["d_u_m_s_dt"] == "m/s^2" and ode_out["d_x_m_dt"] == "m/s"
    y = funcs["homogeneous_outputs"]["outputs"][0]["elements"]
    assert [e["name"] for e in y] == list(model.output_names)
    # every file listed with its hash exists
    import hashlib

    for fname, digest in man["files"].items():
        assert hashlib.sha256((GEN / fname).read_bytes()).hexdigest() == digest


@pytest.mark.parametrize("name, unit", [("k_c_N_per_m_n1", "N/m^(n+1)"), ("cell_damping_Pa_s_per_m", "Pa s/m"),
                                        ("accel_x_m_s2", "m/s^2"), ("omega_left_rad_s", "rad/s"),
                                        ("slip_left", "1"), ("bekker_n", "1"), ("mass_kg", "kg"),
                                        ("internal_resistance_per_km_h", "h/km"), ("step_s", "s"),
                                        ("compaction_power_W", "W")])
def test_unit_of(name, unit):
    assert unit_of(name) == unit


def test_unrolled_rosenbrock_step_is_the_casadi_plugin_method():
    """The unrolled step (codegen.rosenbrock) against CasADi's own rosenbrock plugin with the
    same fixed step, from a consistent algebraic state (the plugin re-solves it first)."""
    import casadi as ca
    import numpy as np

    from symtrack.model.static import static_state
    from symtrack.native.rosenbrock import SparseLU, plugin_step
    from symtrack.simulation.scenario import load_scenario

    sc = load_scenario("validation")
    model = SystemModel(sc.model)
    gen = model_functions(model, "homogeneous")
    ours, ref = gen.function("homogeneous_rosenbrock_step"), plugin_step(model)
    p = model.param_vector(sc.params)
    x = static_state(model, sc.params)
    x[3], x[6], x[7], x[10], x[11] = 3.0, 8.0, 8.5, 1500.0, 2500.0
    u = [0.0, 2000.0]
    zs = ca.SX.sym("z", 2)
    rf = ca.rootfinder("rf", "newton", ca.Function("g", [zs], [model.dae(x, zs, u, p)[1]]), {"abstol": 1e-14})
    z = rf(model.accel(x, u, p))
    for h in (0.01, 0.003):
        a, b = ours(x, z, u, p, h), ref(x, z, u, p, h)
        for ai, bi in zip(a[:2], b, strict=True):  # (xf, zf); ours also returns its error estimate
            ai, bi = np.array(ai).ravel(), np.array(bi).ravel()
            assert np.max(np.abs(ai - bi) / np.maximum(np.abs(bi), 1e-3)) < 1e-8
    # the sparse LU solves what it factorises
    W = ca.SX.sym("w", ca.Sparsity.banded(5, 1) + ca.Sparsity.diag(5))
    lu = SparseLU(W)
    b = ca.SX.sym("b", 5)
    f = ca.Function("f", [W, b], [lu.solve(b)])
    rng = np.random.default_rng(0)
    Wn = ca.DM(W.sparsity(), rng.normal(size=W.nnz()) + 0.0)
    Wn = Wn + 10 * ca.DM.eye(5)
    bn = rng.normal(size=5)
    assert np.allclose(np.array(f(Wn, bn)).ravel(), np.linalg.solve(np.array(Wn), bn), rtol=1e-12, atol=1e-12)


def test_python_m_codegen_is_the_checkouts_entry_point_and_not_installed():
    """``python -m codegen`` runs symtrack.codegen's command from a checkout; the wheel installs
    symtrack only (no generic top-level ``codegen`` package in site-packages)."""
    import subprocess
    import sys
    import tomllib

    root = GEN.parent
    res = subprocess.run([sys.executable, "-m", "codegen", "--help"], cwd=root, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "usage: python -m codegen" in res.stdout and "--check" in res.stdout
    tool = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert tool["packages"]["find"]["include"] == ["symtrack*"]
    assert tool["package-data"]["symtrack.codegen"] == ["*.c", "fmi2/*.h"]  # the FMU: template, FMI 2.0 headers
    assert {p.name for p in (root / "symtrack" / "codegen").glob("*_main.c")} == {
        "standalone_main.c", "grid_standalone_main.c", "mpc_main.c"}
