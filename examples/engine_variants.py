"""The terrain engine's variants on a million cells
================================================

The terrain engine's speed on validation_grid (1e6 cells): the default, the two-stage SDIRK for
the steady cells, the previous stop's default (SDIRK, entry windows of 4, no ring windows), the
default without the subsoil stress; built in one process and run in turn, the best of --repeats
kept (ratios taken in one run; docs/terrain.md, "The terrain engine").

    python examples/engine_variants.py --repeats 6 [--set KEY=VALUE ...]

``--set`` adds overrides to every variant, as ``symtrack simulate --set`` (the tests run it on a small
field for half a second).
"""

from __future__ import annotations

import argparse

from symtrack.bench.terrain import _field_scenario
from symtrack.simulation import loop
from symtrack.simulation.plants import make_plant

PREVIOUS_DEFAULT = ["engine.steady_method='sdirk2'", "engine.entry_substeps=4", "engine.ring_tolerance=0"]
VARIANTS = {"default": [], "sdirk2": ["engine.steady_method='sdirk2'"], "previous default": PREVIOUS_DEFAULT,
            "no subsoil": ["terrain.subsoil_depths_m=[]"]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=4)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats = {args.repeats} must be at least 1")
    plants = {}
    for k, extra in VARIANTS.items():
        sc = _field_scenario("validation_grid", (100.0, 100.0), 0.1, ["run.integrator=grid_fast", *extra, *args.set])
        plants[k] = (sc, make_plant(sc))
    best = {}
    for _ in range(args.repeats):
        for k, (sc, plant) in plants.items():
            for a in plant.world.storage.arrays().values():  # a fresh field for every run
                a[:] = 0
            res = loop.run(sc, plant)
            if k not in best or res.wall_time_s < best[k].wall_time_s:
                best[k] = res
    for k, res in best.items():
        st = res.stats
        print(f"{k:18s} {res.t[-1] / res.wall_time_s:6.1f} x real time (wall {res.wall_time_s * 1e3:.1f} ms): "
              + ", ".join(f"{n} {st[f'ns_{n}'] * 1e-6:.1f} ms" for n in ("cells", "subsoil", "manager", "vehicle",
                                                                          "outputs"))
              + f"; {st['n_cell_stages']} stages, {st['n_newton']} Newton iterations")
    return best


if __name__ == "__main__":
    main()
