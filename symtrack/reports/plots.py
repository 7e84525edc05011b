"""PNG plots of a run (matplotlib, Agg backend). Each function returns PNG bytes; the run folder's
figures are registered in :mod:`symtrack.reports.figures`."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["LATERAL_SCALE_FLOOR_M", "fixed_layout", "path_plot", "plt", "png_bytes", "time_plot"]

# smallest half-range of the magnified lateral-deviation axis (1 mm)
LATERAL_SCALE_FLOOR_M = 1e-3


def png_bytes(fig, tight: bool = True) -> bytes:
    """The figure as PNG bytes (the figure is closed). ``tight``: lay it out with tight_layout
    first (False for a figure laid out in fixed inches: tight_layout measures every label again)."""
    buf = io.BytesIO()
    if tight:
        fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def fixed_layout(fig, left_in: float = 1.0, right_in: float = 0.25, bottom_in: float = 0.65, top_in: float = 0.45,
                 hspace_in: float = 0.6) -> None:
    """Lay out a figure of one column of axes with fixed margins in inches (left for the y label and
    tick labels of up to 8 characters, bottom for the x label, top for a title, ``hspace_in``
    between the rows), instead of tight_layout, which measures every tick label once more before the
    drawing does: a third of the figure's time (docs/terrain.md "What the outputs
    cost"). tests/test_outputs.py draws every figure laid out so with long tick labels and checks
    that no text leaves the canvas or runs into another axes."""
    w, h = fig.get_size_inches()
    rows = max(ax.get_subplotspec().get_gridspec().nrows for ax in fig.axes if ax.get_subplotspec() is not None)
    axes_h = (h - bottom_in - top_in - (rows - 1) * hspace_in) / rows
    fig.subplots_adjust(left=left_in / w, right=1 - right_in / w, bottom=bottom_in / h, top=1 - top_in / h,
                        hspace=hspace_in / axes_h if rows > 1 else 0.2)


def _events(ax, res):
    for e in res.scenario.torque[1:]:
        ax.axvline(e.t_s, color="0.6", ls=":", lw=1)


def path_plot(res) -> bytes:
    X, Y, psi0 = res.state("x_m"), res.state("y_m"), res.state("yaw_rad")[0]
    along = (X - X[0]) * np.cos(psi0) + (Y - Y[0]) * np.sin(psi0)
    lateral = -(X - X[0]) * np.sin(psi0) + (Y - Y[0]) * np.cos(psi0)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6))
    a1.plot(X, Y)
    a1.set_aspect("equal", adjustable="datalim")
    a1.set_xlabel("x [m]")
    a1.set_ylabel("y [m]")
    a1.set_title("path (true scale)")
    a2.plot(along, 100 * lateral)
    # a floor of scale: a straight run's round-off (1e-15 m) is not drawn as a deviation
    lim = max(float(np.abs(100 * lateral).max()), 100 * LATERAL_SCALE_FLOOR_M)
    a2.set_ylim(-1.1 * lim, 1.1 * lim)
    a2.set_xlabel("distance along the initial heading [m]")
    a2.set_ylabel("lateral deviation [cm] (left +)")
    a2.set_title("lateral deviation from the initial straight line (magnified)")
    a2.grid(True)
    fixed_layout(fig, hspace_in=0.95)
    return png_bytes(fig, tight=False)


def time_plot(res, series, ylabel, title, scale=1.0) -> bytes:
    """Columns of a run against time (``series``: (column, label) pairs, times ``scale``), with
    the torque programme's changes."""
    fig, ax = plt.subplots(figsize=(8, 4))
    for name, label in series:
        ax.plot(res.t, scale * res.column(name), label=label)
    _events(ax, res)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True)
    ax.legend()
    fixed_layout(fig)
    return png_bytes(fig, tight=False)
