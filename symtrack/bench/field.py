"""The whole-field traffic study's benchmark (the target: 20 passes over the 100 m x 100 m
field in at most 60 s of wall time once compiled): the built-in ``field_traffic`` study, each
pattern timed by its parts.

``python -m symtrack.bench.field [--set KEY=V ...] [--out FILE]`` prints one row per pattern and
writes the JSON (the load average before and after included). The parts of a pattern's wall time:

- ``set_down_s``: ``plant.start`` of every pass (the set-down at the static sinkage and the
  settling of ``terrain.settle_s``, in the engine);
- ``lift_off_s``: ``plant.finish`` of every pass (``TerrainEngine.end_pass``: the active cells
  unloaded in the engine's C);
- ``time_loop_s``: the rest of each pass's ``loop.run`` (the engine's macro steps and the loop);
- ``other_s``: between the passes (the per-pass masks and records, the figures at the end);
- outside the passes: ``build_s`` (the World and the engine: construction, the compiled library
  loaded from its cache) and the figures and files of the pattern.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from ..foundations.files import atomic_write_text
from ..simulation.plants import make_plant
from ..studies.field import load_field_spec, run_field_study

__all__ = ["field_rows", "main"]


class _Timer:
    """Wall time in a method of an object (wrapped on the instance)."""

    def __init__(self, obj, name):
        self.calls: list[float] = []
        fn = getattr(obj, name)

        def wrapped(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.calls.append(time.perf_counter() - t0)
        setattr(obj, name, wrapped)


def field_rows(name: str = "field_traffic", overrides=(), out=None) -> list[dict]:
    """One row per pattern of the study ``name`` (the module doc's parts), from one run."""
    spec = load_field_spec(name, list(overrides))
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    plant = make_plant(spec.scenario)
    build_s = time.perf_counter() - t0
    starts, finishes = _Timer(plant, "start"), _Timer(plant, "finish")
    res = run_field_study(spec, out=out, plant=plant)
    total = time.perf_counter() - t0
    load1 = os.getloadavg()
    rows = []
    done = 0
    for pattern, pr in res.patterns.items():
        n = len(pr.records)
        set_down, lift_off = sum(starts.calls[done:done + n]), sum(finishes.calls[done:done + n])
        done += n
        passes_s = sum(r["wall_time_s"] for r in pr.records)
        loop_s = passes_s - set_down - lift_off
        f = pr.figures
        rows.append({
            "group": "field study (1e6 cells)" if f["field_cells"] >= 1e6 else "field study",
            "case": f"{pattern}: {n} passes x {spec.field.length_m:g} m at {spec.field.speed_m_s} m/s",
            "integrator": spec.scenario.run.integrator, "sim_time_s": pr.sim_time_s,
            "wall_time_s": pr.wall_time_s, "passes_wall_s": passes_s, "set_down_s": set_down,
            "lift_off_s": lift_off, "time_loop_s": loop_s, "other_s": pr.wall_time_s - passes_s,
            "build_s": build_s, "study_wall_time_s": total, "load_average_before": load0,
            "load_average_after": load1, "trafficked_area_fraction": f["trafficked_area_fraction"],
            "passes_per_cell_histogram": f["passes_per_cell_histogram"],
            "note": (f"{n} passes in {pr.wall_time_s:.1f} s: set-down {set_down:.1f} s, time loops {loop_s:.1f} s "
                     f"({pr.sim_time_s / max(loop_s, 1e-9):.0f} x real time), lift-off {lift_off:.1f} s, between "
                     f"the passes {pr.wall_time_s - passes_s:.1f} s; "
                     f"{100 * f['trafficked_area_fraction']:.2f} % trafficked; load {load0[0]:.1f} -> {load1[0]:.1f}"),
        })
    return rows


def main(argv=None) -> int:
    """``python -m symtrack.bench.field``: the rows, printed and written as JSON."""
    ap = argparse.ArgumentParser(prog="python -m symtrack.bench.field")
    ap.add_argument("name", nargs="?", default="field_traffic")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    ap.add_argument("--out", default="out/bench_field.json")
    ap.add_argument("--study-out", help="also write the study's folder here")
    args = ap.parse_args(argv)
    rows = field_rows(args.name, args.set, args.study_out)
    atomic_write_text(Path(args.out), json.dumps({"rows": rows, "cpus": os.cpu_count()}, indent=2) + "\n")
    for r in rows:
        print(f"{r['case']}: {r['note']}")
    print(f"study in all {rows[0]['study_wall_time_s']:.1f} s (build {rows[0]['build_s']:.1f} s); JSON in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
