"""Bench rows of the MPC as C (``symtrack codegen mpc``, docs/codegen.md): the same real-time
iteration in the Python closed loop and in the generated C closed loop, measured in one run.

Configuration: ``headland_uturn`` with :data:`symtrack.control.bench.RTI_CONFIG` (the Python
RTI's mapped Functions compiled, pseudo-Huber 0.2 m, terminal lateral x5) on the compiled
Rosenbrock plant (``run.integrator = "rosenbrock"``, the plant the C program integrates); with
``quick`` the straights are 20 + 4 m instead of 25 + 25 m. Solve time = the RTI's feedback phase
(measurement to command) in both. Nothing here asserts a time."""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

from ..control.bench import RTI_CONFIG

__all__ = ["QUICK_PATH", "bench_rows", "comparison"]

log = logging.getLogger("symtrack.bench.mpc_c")

QUICK_PATH = "path.segments=[{straight_m=20.0},{arc_radius_m=4.0,angle_deg=180.0},{straight_m=4.0}]"


def _toml(v) -> str:
    return ("true" if v else "false") if isinstance(v, bool) else repr(v)


def comparison(scenario: str = "headland_uturn", quick: bool = False, out: Path | None = None) -> dict:
    """Python RTI and C RTI closed loops of one configuration: their summaries, the agreement and
    the C build time."""
    from ..codegen import mpc as M
    from ..toolchain import find_compiler

    overrides = [f"mpc.{k}={_toml(v)}" for k, v in RTI_CONFIG.items() if k != "solver"]
    if quick:
        overrides.append(QUICK_PATH)
    sc = M.load_scenario(scenario, overrides)
    cc = find_compiler()
    if cc is None:
        return {}
    with tempfile.TemporaryDirectory(prefix="symtrack-bench-mpc-c-") as scratch:
        d = Path(out) if out is not None else Path(scratch)
        t0 = time.perf_counter()
        pb = M.setup(sc)
        M.write(d, M.render(pb))
        t_gen = time.perf_counter() - t0
        t_build = M.build_program(d, cc)
        c = M.run_program(d)
        py = M.python_closed_loop(sc, pb.model)
        agree = M.compare(py, d / "closed_loop.csv")
    return {"scenario": sc.name, "python": py.summary, "c": c, "agreement": agree, "generate_s": t_gen,
            "build_s": t_build}


def bench_rows(quick: bool) -> list[dict]:
    r = comparison(quick=quick)
    if not r:
        log.info("no C compiler: the MPC-as-C rows are skipped")
        return []
    py, c, a = r["python"], r["c"], r["agreement"]
    group = f"MPC {r['scenario']}{' (20 + 4 m straights)' if quick else ''}, RTI, Rosenbrock plant"
    rows = [{"group": group, "case": "nmpc_rti python (jit)", "integrator": "rosenbrock plant",
             "sim_time_s": py["sim_time_s"], "wall_time_s": py["wall_time_s"],
             "solve_time_median_ms": py["solve_time_median_ms"], "solve_time_p95_ms": py["solve_time_p95_ms"],
             "solve_time_max_ms": py["solve_time_max_ms"],
             "note": (f"solve median {py['solve_time_median_ms']:.3f} / p95 {py['solve_time_p95_ms']:.3f} / max "
                      f"{py['solve_time_max_ms']:.3f} ms; failed {py['failed_solves']}/{py['solves']} "
                      f"(fallbacks {py['fallback_solves']})")}]
    ms = {k: 1e-3 * c[f"solve_time_{k}_us"] for k in ("median", "p95", "max")}
    rows.append({"group": group, "case": "nmpc_rti generated C (symtrack codegen mpc)",
                 "integrator": "rosenbrock plant",
                 "sim_time_s": c["sim_time_s"], "wall_time_s": c["wall_time_s"],
                 "solve_time_median_ms": ms["median"], "solve_time_p95_ms": ms["p95"], "solve_time_max_ms": ms["max"],
                 "build_s": r["build_s"],
                 "note": (f"solve median {ms['median']:.3f} / p95 {ms['p95']:.3f} / max {ms['max']:.3f} ms; failed "
                          f"{c['failed_solves']}/{c['samples']}; build {r['build_s']:.1f} s; final position "
                          f"{100 * a['final_position_difference_m']:.2g} cm from Python's, torque commands within "
                          f"{a['max_torque_cmd_difference_N_m']:.2g} N m")})
    return rows
