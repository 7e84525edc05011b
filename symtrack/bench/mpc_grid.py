"""Bench rows of the MPC closed loop on the grid plant: the terrain engine (``grid_fast``, the
default) against IDAS (the reference, the default before) and the compiled grid
Rosenbrock, the same scenario in one process (docs/control.md, "On the grid plant").

    python -m symtrack.bench.mpc_grid [--scenario field_pattern] [--integrators grid_fast idas rosenbrock]
                                      [--quick] [--out DIR]

Per integrator: the plant's build time (World, integrator or engine), the loop's and the plant's
wall time and real-time factors, the solver's wall time, the tracking figures, the ruts after
the lift-off; then each plant's final terrain and trajectory against the first one's (the
engine's by default). ``quick``: two passes of 20 m instead of the scenario's path (a field
scenario). Nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

__all__ = ["QUICK_FIELD", "comparison", "table_markdown"]

QUICK_FIELD = ["path.passes=2", "path.pass_length_m=20.0"]
FIGURES = ("sim_time_s", "wall_time_s", "plant_wall_time_s", "solver_wall_time_s", "rms_lateral_error_m",
           "max_lateral_error_m", "max_lateral_error_straights_m", "max_heading_error_deg", "solve_time_median_ms",
           "solve_time_p95_ms", "failed_solves", "fallback_solves", "solves", "path_completed", "rut_cells",
           "rut_max_depth_mm", "rut_mean_depth_mm", "rut_volume_m3", "terrain_channel_modulus_M",
           "terrain_peak_active_cells")


def comparison(scenario: str = "field_pattern", integrators=("grid_fast", "idas", "rosenbrock"), quick: bool = False,
               out: Path | None = None, overrides=()) -> dict:
    """The closed loop of ``scenario`` on the grid plant with each integrator; returns
    {"rows": [...], "agreement": [...], "load_average": ...}."""
    from ..control import closedloop
    from ..control import scenario as S
    from ..model import SystemModel

    model = SystemModel()
    rows, kept = [], []
    for integ in integrators:
        ov = list(overrides) + (QUICK_FIELD if quick else []) + [f'run.integrator="{integ}"']
        sc = S.load(scenario, ov, plant="grid")
        t0 = time.perf_counter()
        plant = closedloop.make_plant(sc, model)
        t1 = time.perf_counter()
        res = closedloop.run(sc, plant=plant, model=model)
        t2 = time.perf_counter()
        s = res.summary
        row = {"integrator": integ, "plant_class": type(plant).__name__, "macro_step_s": plant.macro_step_s,
               **{k: s.get(k) for k in FIGURES}, "build_s": t1 - t0, "run_and_liftoff_s": t2 - t1,
               "plant_x_real_time": s["sim_time_s"] / s["plant_wall_time_s"],
               "loop_x_real_time": s["sim_time_s"] / s["wall_time_s"], "load_average": os.getloadavg()}
        engine = getattr(plant, "engine", None)
        if engine is not None:  # the share of the compiled calls in the plant's wall time
            row["engine_kernel_s"] = engine.timing["kernel_s"]
        rows.append(row)
        kept.append((integ, res, plant.world.storage.z.copy()))
        if out is not None:
            closedloop.write(Path(out) / integ, res)
            plant.world.storage.save(Path(out) / integ / "terrain.npz", sc.params)
    agreement = []
    if kept:
        ref_name, ref, z_ref = kept[0]
        for name, res, z in kept[1:]:
            n = min(len(ref.t), len(res.t))
            d = np.hypot(res.state("x_m")[:n] - ref.state("x_m")[:n], res.state("y_m")[:n] - ref.state("y_m")[:n])
            agreement.append({"integrator": name, "against": ref_name, "max_position_difference_m": float(d.max()),
                              "final_position_difference_m": float(d[-1]),
                              "terrain_max_abs_dz_mm": 1e3 * float(np.max(np.abs(z - z_ref))),
                              "rut_max_depth_mm": 1e3 * float(z_ref.max())})
    return {"scenario": scenario, "quick": quick, "rows": rows, "agreement": agreement}


def table_markdown(result: dict) -> str:
    head = ("| plant integrator | macro step [s] | plant build [s] | simulated [s] | loop wall [s] (x real time) | "
            "plant wall [s] (x real time) | solver wall [s] | median / p95 solve [ms] | failed (fallbacks) | "
            "RMS lat. straights [cm] | max lat. [cm] | rut volume [m^3] / mean / max [mm] |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in result["rows"]:
        rms = r["rms_lateral_error_m"]
        lines.append(
            f"| {r['integrator']} ({r['plant_class']}) | {r['macro_step_s']:g} | {r['build_s']:.1f} | "
            f"{r['sim_time_s']:.1f} | {r['wall_time_s']:.1f} ({r['loop_x_real_time']:.2f}) | "
            f"{r['plant_wall_time_s']:.2f} ({r['plant_x_real_time']:.1f}) | {r['solver_wall_time_s']:.1f} | "
            f"{r['solve_time_median_ms']:.1f} / {r['solve_time_p95_ms']:.1f} | {r['failed_solves']} "
            f"({r['fallback_solves']}) | {'-' if rms is None else f'{100 * rms:.2f}'} | "
            f"{100 * r['max_lateral_error_m']:.2f} | {r['rut_volume_m3']:.4f} / {r['rut_mean_depth_mm']:.3f} / "
            f"{r['rut_max_depth_mm']:.3f} |")
    for a in result["agreement"]:
        lines.append(f"\n{a['integrator']} against {a['against']}: positions within "
                     f"{100 * a['max_position_difference_m']:.2f} cm (final "
                     f"{100 * a['final_position_difference_m']:.2f} cm), final terrain within "
                     f"{a['terrain_max_abs_dz_mm']:.4f} mm (ruts up to "
                     f"{a['rut_max_depth_mm']:.2f} mm)")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="field_pattern")
    ap.add_argument("--integrators", nargs="+", default=["grid_fast", "idas", "rosenbrock"])
    ap.add_argument("--quick", action="store_true", help="two passes of 20 m (a field scenario)")
    ap.add_argument("--out", default=None, help="write each loop's files, its final terrain.npz and bench.json here")
    ap.add_argument("--set", action="append", default=[], help="scenario override KEY=VALUE (repeatable)")
    args = ap.parse_args(argv)
    res = comparison(args.scenario, args.integrators, args.quick, args.out, args.set)
    if args.out is not None:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "bench.json").write_text(json.dumps(res, indent=2) + "\n")
    print(table_markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
