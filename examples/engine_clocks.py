"""The terrain engine's kernel clocks
==================================

The terrain engine's kernel clocks per macro step and a fingerprint of the run.

    python examples/engine_clocks.py [--repeats 3] [--set KEY=VALUE ...]

Runs validation_grid on the shear law (``--set`` adds overrides, as ``symtrack simulate --set``)
``repeats`` times after a warm-up run on one plant (the world cleared before each), and prints per
run the real-time factor in CPU time, the kernel's parts in microseconds per macro step (cells,
subsoil stress, vehicle, world manager, outputs: ``res.stats["ns_*"]``) and the first 12 hex digits of
a SHA-256 over the vehicle's states and outputs, every stored field of the terrain and the pass's
stress maxima. An engine change meant to leave the numbers alone must leave the fingerprint alone
(docs/terrain.md, "Speed"; the fingerprint depends on the compiler and the machine: compare runs of the
commits before and after the change on one machine).
"""

from __future__ import annotations

import argparse
import hashlib
import statistics

import numpy as np

from symtrack.bench.laws import _clear
from symtrack.simulation import loop
from symtrack.simulation.plants import make_plant
from symtrack.simulation.scenario import load_scenario


def fingerprint(res, world) -> str:
    """SHA-256 (12 hex digits) of the run's states and outputs, the stored fields and the pass maxima."""
    h = hashlib.sha256()
    for a in (res.X, res.Y):
        h.update(np.ascontiguousarray(a).tobytes())
    for _, v in sorted(world.storage.arrays().items()):
        h.update(np.ascontiguousarray(v).tobytes())
    for a in (getattr(world, "pass_sigma", None), getattr(world, "pass_p_mean", None)):
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:12]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args(argv)
    if a.repeats < 1:
        ap.error(f"--repeats = {a.repeats} must be at least 1")
    sc = load_scenario("validation_grid", ["model.lateral_law=shear", *a.set])
    plant = make_plant(sc)
    factors = []
    for k in range(a.repeats + 1):
        _clear(plant)
        res = loop.run(sc, plant)
        if k == 0:
            continue
        n = len(res.t) - 1
        parts = {key[3:]: res.stats[key] / n / 1e3 for key in sorted(res.stats) if key.startswith("ns_")}
        factors.append(float(res.t[-1]) / float(res.cpu_time_s))
        print(f"{factors[-1]:6.1f} x real time (CPU)  fingerprint {fingerprint(res, plant.world)}  [us per macro step] "
              + " ".join(f"{name} {v:.1f}" for name, v in parts.items()), flush=True)
    print(f"median {statistics.median(factors):.1f} x real time (CPU)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
