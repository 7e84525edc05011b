"""A second pass in the ruts of the first, in 3D
=============================================

A second pass riding in the ruts of the first with the 3D vehicle on the grid terrain (``multipass``
with ``model.vehicle = "3d"``, the terrain engine; docs/vehicle3d.md "Studies: the
second pass").

    python examples/second_pass_3d.py                                 # 30 m x 8 m field, 15 m each pass
    python examples/second_pass_3d.py --stop-m 10 --plot /tmp/second_pass_3d.png

The built-in ``multipass`` scenario (clayey soil, 1500 N m a sprocket, the grid's 0.1 m cells) on a
small field: two passes on one line, the second over the cells the first left. The soil remembers its
compaction (docs/model.md, "Pressure-sinkage" and "Repeated loading"): the second pass reloads the
cells along Wong's reloading line to about the first pass's loaded depth and adds the cycle law's
plastic increment rut_1 (2^beta - 1), so the hull sits lower by more than that increment and less
than the first rut, its front (the lightest segment) in the rut, and the cells' work (the compaction
resistance) falls.

Prints a JSON summary (the ruts, the deepening against the closed form, the hull's drop and pitch in
both passes over the middle of the line); ``--plot`` writes the hull's height and pitch in both passes
and the drop against x (matplotlib).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import symtrack
from symtrack.simulation.scenario import load_scenario


def second_pass(size_m=(30.0, 8.0), stop_m: float = 15.0, extra=()) -> dict:
    """Two passes of ``multipass`` with the 3D vehicle on a field of ``size_m``, each ``stop_m`` long."""
    sets = ["model.vehicle=3d", "terrain.passes=2", f"terrain.size_m=[{size_m[0]!r}, {size_m[1]!r}]",
            f"run.stop_after_distance_m={stop_m!r}", *extra]
    sc = load_scenario("multipass", sets)
    r = symtrack.simulate(sc)
    return {"scenario": sc, "runs": r.runs, "passes": r.pass_summaries}


def summary(d: dict, window=(0.3, 0.8)) -> dict:
    """The figures over the middle of the line (``window``: fractions of the first pass's x range)."""
    run1, run2 = d["runs"]
    p1, p2 = d["passes"]
    beta = d["scenario"].params["repeated_loading_exponent"]
    x1 = run1.state("x_m")
    xs = np.linspace(x1[0] + window[0] * (x1[-1] - x1[0]), x1[0] + window[1] * (x1[-1] - x1[0]), 41)
    z1, z2 = (np.interp(xs, run.state("x_m"), run.state("z_m")) for run in (run1, run2))
    q1, q2 = (np.interp(xs, run.state("x_m"), run.state("pitch_rad")) for run in (run1, run2))
    drop = z1 - z2
    deepening = p2["new_sinkage_mean_mm"] / p1["rut_mean_depth_mm"]
    return {
        "rut_after_pass_1_mean_mm": p1["rut_mean_depth_mm"], "rut_after_pass_1_max_mm": p1["rut_max_depth_mm"],
        "new_sinkage_pass_2_mean_mm": p2["new_sinkage_mean_mm"],
        "deepening": deepening, "deepening_closed_form": 2**beta - 1,
        "hull_drop_mm": [1e3 * float(drop.min()), 1e3 * float(drop.max())],
        "pitch_pass_1_mrad": 1e3 * float(np.mean(q1)), "pitch_pass_2_mrad": 1e3 * float(np.mean(q2)),
        "compaction_resistance_pass_1_N": p1["compaction_resistance_mean_N"],
        "compaction_resistance_pass_2_N": p2["compaction_resistance_mean_N"],
        "x_window_m": [float(xs[0]), float(xs[-1])],
    }


def plot(d: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run1, run2 = d["runs"]
    fig, ax = plt.subplots(3, 1, figsize=(9, 10), sharex=True)
    for k, run in enumerate((run1, run2)):
        x = run.state("x_m")
        ax[0].plot(x, 1e3 * (run.state("z_m") - run1.state("z_m")[0]), label=f"pass {k + 1}")
        ax[1].plot(x, 1e3 * run.state("pitch_rad"), label=f"pass {k + 1}")
    x = run1.state("x_m")
    drop = np.interp(x, run1.state("x_m"), run1.state("z_m")) - np.interp(x, run2.state("x_m"), run2.state("z_m"))
    p1, p2 = d["passes"]
    ax[2].plot(x, 1e3 * drop, color="k", label="pass 1 - pass 2")
    ax[2].axhline(p1["rut_mean_depth_mm"], ls=":", color="C0", label="pass 1's rut (mean)")
    ax[2].axhline(p2["new_sinkage_mean_mm"], ls=":", color="C1", label="pass 2's new sinkage (mean)")
    ax[0].set(ylabel="CG height - pass 1's start [mm]", title="the hull's height in both passes")
    ax[1].set(ylabel="pitch [mrad] (nose up +)", title="the hull's pitch in both passes")
    ax[2].set(xlabel="x [m]", ylabel="[mm]", title="how much lower the second pass's hull rides")
    for a in ax:
        a.grid(True)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size-m", type=float, nargs=2, default=[30.0, 8.0], help="the field [m]")
    ap.add_argument("--stop-m", type=float, default=15.0, help="each pass's distance [m]")
    ap.add_argument("--plot", default=None, help="write the figure here (.png)")
    a = ap.parse_args(argv)
    d = second_pass(tuple(a.size_m), a.stop_m)
    out = summary(d)
    print(json.dumps(out, indent=2))
    if a.plot:
        plot(d, a.plot)
    return out


if __name__ == "__main__":
    main()
