"""The comparison plot of a sweep (``DIR/comparison.png``): each figure of the table against each
varied key, one panel per pair, every successful run one point in every panel (so the spread at
one value of a key shows what the other keys do)."""

from __future__ import annotations

import math

from ..reports.plots import plt, png_bytes

__all__ = ["EXCLUDED_FIGURES", "MAX_FIGURES", "comparison_figures", "comparison_png"]

# the figures left out of the plot: timings of the machine, not results of the model
EXCLUDED_FIGURES = ("run_wall_time_s", "wall_time_s", "real_time_factor", "plant_wall_time_s",
                    "solver_wall_time_s", "plant_wall_time_per_sim_s")
MAX_FIGURES = 16
# the layout, fixed in inches (no tight layout: it measured every tick label again and took about
# half of the plot's time): a panel, the margins around the grid, the gaps between panels
PANEL_IN = (3.2, 1.5)
MARGINS_IN = {"left": 1.0, "right": 0.4, "top": 0.35, "bottom": 0.7}
GAPS_IN = (0.8, 0.5)  # between columns (the next column's tick labels and name), between rows


def _number(v):
    if isinstance(v, bool) or v is None:
        return None
    if isinstance(v, (int, float)) and math.isfinite(v):
        return float(v)
    return None


def comparison_figures(rows: list[dict], keys: list[str]) -> list[str]:
    """The numeric figures of the ok rows that differ between runs (by more than round-off), in
    column order (at most :data:`MAX_FIGURES`)."""
    ok = [r for r in rows if r.get("status") == "ok"]
    names: list[str] = []
    for r in ok:
        names += [k for k in r if k not in names and k not in keys and k != "run_id"]
    out = []
    for name in names:
        if name in EXCLUDED_FIGURES:
            continue
        vals = [_number(r.get(name)) for r in ok]
        if all(v is not None for v in vals) and max(vals) - min(vals) > 1e-9 * max(abs(v) for v in vals):
            out.append(name)
    return out[:MAX_FIGURES]


def comparison_png(rows: list[dict], keys: list[str]) -> bytes | None:
    """PNG bytes of the comparison plot, or None when fewer than two runs succeeded or no figure
    differs between them."""
    ok = [r for r in rows if r.get("status") == "ok"]
    figures = comparison_figures(rows, keys)
    if len(ok) < 2 or not figures:
        return None
    ncol, nrow = len(keys), len(figures)
    width_in = ncol * PANEL_IN[0] + MARGINS_IN["left"] + MARGINS_IN["right"] + (ncol - 1) * GAPS_IN[0]
    height_in = nrow * PANEL_IN[1] + MARGINS_IN["top"] + MARGINS_IN["bottom"] + (nrow - 1) * GAPS_IN[1]
    fig, axes = plt.subplots(nrow, ncol, figsize=(width_in, height_in), squeeze=False)
    fig.subplots_adjust(left=MARGINS_IN["left"] / width_in, right=1 - MARGINS_IN["right"] / width_in,
                        bottom=MARGINS_IN["bottom"] / height_in, top=1 - MARGINS_IN["top"] / height_in,
                        wspace=GAPS_IN[0] / PANEL_IN[0], hspace=GAPS_IN[1] / PANEL_IN[1])
    for j, key in enumerate(keys):
        xs = [r[key] for r in ok]
        numeric = all(_number(x) is not None for x in xs)
        labels = sorted({str(x) for x in xs}) if not numeric else None
        pos = [float(x) for x in xs] if numeric else [labels.index(str(x)) for x in xs]
        for i, name in enumerate(figures):
            ax = axes[i][j]
            ax.plot(pos, [_number(r[name]) for r in ok], "o", ms=4, alpha=0.8)
            if labels is not None:
                ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize=7)
            if j == 0:
                ax.set_ylabel(name, fontsize=7)
            if i == len(figures) - 1:
                ax.set_xlabel(key, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    failed = len(rows) - len(ok)
    axes[0][0].set_title(f"sweep: {len(ok)} runs" + (f" ({failed} failed or not run, not shown)" if failed else ""),
                         fontsize=8, loc="left")
    return png_bytes(fig, tight=False)
