"""The terrain examples run (with short settings)."""

import json
import runpy
import sys

import pytest

# the benchmark's smoke run, brute force included: the slow set (make test-slow; CI runs it)
pytestmark = pytest.mark.slow


def test_bench_terrain_quick(monkeypatch, capsys):
    # --quick's run on a 6 m x 3 m field (288 cells) in place of its 12 m x 4 m (768): the test checks the
    # rows, not the speed, and most of the run's CPU was building the brute-force reference's DAE over
    # every cell (its Jacobian's common subexpressions); the footprint (2.4 m x 1.95 m) fits 0.2 s from rest.
    # Its IDAS systems are built without CasADi's cse (the same numbers to the last bit: grid_idas.CSE;
    # for 0.2 s of steps the cse costs more than it saves)
    import symtrack.bench.terrain as bench
    from symtrack.integrators import grid_idas

    monkeypatch.setattr(grid_idas, "CSE", False)
    quick = bench.benchmark

    def smaller(**kw):
        assert kw["big_size_m"] == (12.0, 4.0) and kw.get("small_size_m") is None  # the example's --quick
        return quick(**{**kw, "big_size_m": (6.0, 3.0), "small_size_m": (6.0, 3.0)})
    monkeypatch.setattr(bench, "benchmark", smaller)
    monkeypatch.setattr(sys, "argv", ["bench_terrain.py", "--quick"])
    runpy.run_path("examples/bench_terrain.py", run_name="__main__")
    out = json.loads(capsys.readouterr().out)
    assert out["big_channels"] > 0 and out["big_peak_active_cells"] > 0
    assert out["big_storage_MB"] > 0 and out["big_wall_s_per_sim_s"] > 0
    assert out["small_speed_ratio_brute_over_pool"] > 0 and out["small_pose_difference_m"] < 1e-5


def test_engine_clocks_prints_the_same_fingerprint_for_repeated_runs(capsys):
    """examples/engine_clocks.py: two runs on one plant (the world cleared between) give the same
    fingerprint (the engine is deterministic: the check an engine change that keeps the numbers relies
    on), and every kernel part is reported."""
    mod = runpy.run_path("examples/engine_clocks.py")
    assert mod["main"](["--repeats", "2"]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "fingerprint" in ln]
    assert len(lines) == 2
    prints = {ln.split("fingerprint ")[1].split()[0] for ln in lines}
    assert len(prints) == 1 and len(next(iter(prints))) == 12
    for part in ("cells", "subsoil", "vehicle", "manager", "outputs"):
        assert all(f" {part} " in ln for ln in lines)


def test_engine_variants_runs_each_variant_on_one_engine(capsys):
    """examples/engine_variants.py on a 12 m x 4 m field for 0.5 s: a row per variant; the variants are run-time
    settings of one engine, and the one without the subsoil spends nothing on it."""
    mod = runpy.run_path("examples/engine_variants.py")
    best = mod["main"](["--repeats", "1", "--set", "terrain.size_m=[12.0, 4.0]", "--set", "terrain.cell_m=0.25",
                        "--set", "run.duration_s=0.5"])
    assert set(best) == {"default", "sdirk2", "previous default", "no subsoil"}
    for res in best.values():
        assert res.t[-1] == pytest.approx(0.5) and res.wall_time_s > 0
    assert best["default"].stats["ns_subsoil"] > 0 and best["no subsoil"].stats["ns_subsoil"] == 0
    # the same physics to within the steady cells' method: the poses agree to a millimetre
    ix = best["default"].state_names.index("x_m")
    assert abs(best["sdirk2"].X[-1, ix] - best["default"].X[-1, ix]) < 1e-3
    out = capsys.readouterr().out
    assert out.count("x real time") == 4
