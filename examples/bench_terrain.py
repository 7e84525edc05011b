"""Benchmark of the grid terrain
=============================

Benchmark of the grid terrain (not a test): the figures of docs/terrain.md, measured in one run.

    python examples/bench_terrain.py              # the figures of docs/terrain.md (minutes)
    python examples/bench_terrain.py --quick      # a smoke run in seconds (tests/test_terrain_examples.py)

Prints a JSON object: the validation run on the big field (wall time per simulated second, peak
active cells, channels, cell-storage memory, whether the validation figures are met) and the
channel pool against brute force on a 12 m x 4 m field at 0.25 m (speed ratio, pose difference).
"""

import argparse
import json

from symtrack.bench.terrain import benchmark


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 0.2 s on a 12 m x 4 m field at 0.25 m in place of the validation, 0.2 s small")
    args = ap.parse_args()
    if args.quick:
        out = benchmark(big_size_m=(12.0, 4.0), big_cell_m=0.25, small_duration_s=0.2, big_duration_s=0.2)
    else:
        out = benchmark()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
