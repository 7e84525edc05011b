"""Kroulik's three seasons as wheel footprints
===========================================

Kroulik et al. (2009)'s three seasons as wheel footprints: the share of the field run over at least
once and the repeated coverage of conventional tillage, minimum tillage and direct seeding, against
their published 95.3 / 72.8 / 55.7 % and 145.6 / 44.8 / 18.4 % (symtrack/studies/traffic_seasons.py;
docs/studies.md, "Kroulik's three seasons as wheel footprints").

    python examples/kroulik_seasons.py                          # the table; 300 m x 200 m at 0.1 m cells
    python examples/kroulik_seasons.py --plot /tmp/kroulik.png --json /tmp/kroulik.json
    python examples/kroulik_seasons.py --operations             # and each operation's own share

Geometry only (no terrain engine): every machine and every season sequence is ASSUMED (the module's
constants say what and why); the paper's own machine table was not read.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from symtrack.studies import traffic_seasons as ts


def table(rows) -> str:
    head = ("| system | operations | run over >= 1x | (Kroulik) | interior | repeated (passes beyond the first) "
            "| (Kroulik) | passes x area / field | once / twice / 3+ [ha] |")
    lines = [head, "|" + "---|" * 9]
    for r in rows:
        lines.append(f"| {ts.SYSTEM_LABELS.get(r['system'], r['system'])} | {r['operations']} "
                     f"| {100 * r['trafficked_fraction']:.1f} % | {100 * r['kroulik_trafficked_fraction']:.1f} % "
                     f"| {100 * r['interior_trafficked_fraction']:.1f} % "
                     f"| {100 * r['repeated_excess_fraction']:.1f} % | {100 * r['kroulik_repeated_fraction']:.1f} % "
                     f"| {100 * r['passes_area_fraction']:.1f} % "
                     f"| {r['area_once_m2'] / 1e4:.2f} / {r['area_twice_m2'] / 1e4:.2f} / "
                     f"{r['area_3_or_more_m2'] / 1e4:.2f} |")
    return "\n".join(lines)


def operations_table(size_m, cell_m) -> str:
    lines = ["| system | operation | machine | width [m] | headland rounds | x | its own share |", "|" + "---|" * 7]
    for k, v in ts.SEASONS.items():
        for o in ts.build_season(v, size_m, cell_m, where=f"seasons.{k}"):
            c = ts.operation_counts(o)
            lines.append(f"| {k} | {o.name} | {o.machine.name} | {o.machine.working_width_m:g} "
                         f"| {o.settings.headland_passes} | {o.repeat} | {100 * (c > 0).mean():.1f} % |")
    return "\n".join(lines)


CLIP_PASSES = 6  # the colour scale's top: 6 or more passes in one colour


def figure(rows, maps, cell_m, path):
    """Top: the whole field, passes per cell; below: a 1 ha excerpt (100 m x 100 m about the centre,
    as the paper shows 1 ha)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(rows)
    fig, axes = plt.subplots(2, n, figsize=(5.2 * n, 8.6), constrained_layout=True, squeeze=False)
    cmap = plt.get_cmap("magma_r", CLIP_PASSES + 1)
    for col, r in enumerate(rows):
        c = np.minimum(maps[r["system"]], CLIP_PASSES)
        nx, ny = c.shape
        label = ts.SYSTEM_LABELS.get(r["system"], r["system"])
        ax = axes[0, col]
        im = ax.imshow(c.T, origin="lower", extent=(0, nx * cell_m, 0, ny * cell_m), cmap=cmap,
                       vmin=-0.5, vmax=CLIP_PASSES + 0.5, interpolation="nearest")
        ax.set_title(f"{label}\nrun over {100 * r['trafficked_fraction']:.1f} % "
                     f"(Kroulik 2009: {100 * r['kroulik_trafficked_fraction']:.1f} %)\n"
                     f"repeated {100 * r['repeated_excess_fraction']:.1f} % "
                     f"(Kroulik: {100 * r['kroulik_repeated_fraction']:.1f} %)", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        cx, cy = 0.5 * nx * cell_m, 0.5 * ny * cell_m
        h = min(50.0, cx, cy)
        ax.add_patch(plt.Rectangle((cx - h, cy - h), 2 * h, 2 * h, fill=False, ec="tab:blue", lw=1.2))
        ax2 = axes[1, col]
        ax2.imshow(c.T, origin="lower", extent=(0, nx * cell_m, 0, ny * cell_m), cmap=cmap,
                   vmin=-0.5, vmax=CLIP_PASSES + 0.5, interpolation="nearest")
        ax2.set_xlim(cx - h, cx + h)
        ax2.set_ylim(cy - h, cy + h)
        i0, i1, j0, j1 = (int(round(v / cell_m)) for v in (cx - h, cx + h, cy - h, cy + h))
        ax2.set_title(f"{2 * h:g} m x {2 * h:g} m excerpt: run over {100 * (c[i0:i1, j0:j1] > 0).mean():.1f} %",
                      fontsize=9)
        ax2.set_xlabel("x [m]")
        ax2.set_ylabel("y [m]")
    cb = fig.colorbar(im, ax=axes, label=f"passes per cell ({cell_m:g} m cells; {CLIP_PASSES} = {CLIP_PASSES} or more)",
                      shrink=0.6)
    cb.set_ticks(range(CLIP_PASSES + 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def variant(seasons, random_offset=None, across=()):
    """The seasons with every random-traffic offset bound replaced (not the plough's) and the named
    operations turned across the field (the tramline operations only all together)."""
    out = {}
    for k, ops in seasons.items():
        rows = []
        for o in ops:
            o = dict(o)
            if random_offset is not None and "same_lines_as" not in o and "random_offset_m" not in o:
                o["random_offset_m"] = random_offset
            if o.get("name") in across:
                o["direction"] = "y"
            rows.append(o)
        out[k] = rows
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, nargs=2, default=ts.FIELD_SIZE_M, metavar=("X_M", "Y_M"))
    ap.add_argument("--cell", type=float, default=ts.FIELD_CELL_M)
    ap.add_argument("--plot", help="the figure (PNG): the three maps of passes per cell")
    ap.add_argument("--json", help="the rows as JSON")
    ap.add_argument("--operations", action="store_true", help="also each operation's own share")
    ap.add_argument("--random-offset", type=float, metavar="M",
                    help=f"every random-traffic line's offset bound (default {ts.RANDOM_OFFSET_M:g} m; the plough's "
                         f"{ts.PLOUGH_OFFSET_M:g} m kept)")
    ap.add_argument("--across", nargs="+", default=(), metavar="OPERATION",
                    help="operations (by name, e.g. 'harvest') driven across the field (direction y)")
    a = ap.parse_args(argv)
    systems = variant(ts.SEASONS, a.random_offset, a.across)
    rows, maps = ts.system_table(tuple(a.size), a.cell, systems)
    print(f"field {a.size[0]:g} m x {a.size[1]:g} m, cells {a.cell:g} m")
    print(table(rows))
    if a.operations:
        print()
        print(operations_table(tuple(a.size), a.cell))
    if a.plot:
        figure(rows, maps, a.cell, a.plot)
        print(f"figure: {a.plot}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
