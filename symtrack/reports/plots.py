"""PNG plots of a run (matplotlib, Agg backend). Each function returns PNG bytes."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["LATERAL_SCALE_FLOOR_M", "all_plots", "path_plot", "plt", "png_bytes"]

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


def _events(ax, res):
    for e in res.scenario.torque[1:]:
        ax.axvline(e.t_s, color="0.6", ls=":", lw=1)


def path_plot(res) -> bytes:
    X, Y, psi0 = res.state("x_m"), res.state("y_m"), res.X[0, 2]
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
    return png_bytes(fig)


def _time_plot(res, series, ylabel, title, scale=1.0) -> bytes:
    fig, ax = plt.subplots(figsize=(8, 4))
    for name, label in series:
        ax.plot(res.t, scale * res.column(name), label=label)
    _events(ax, res)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True)
    ax.legend()
    return png_bytes(fig)


def all_plots(res) -> dict[str, bytes]:
    return {
        "path.png": path_plot(res),
        "yaw.png": _time_plot(res, [("yaw_rad", "yaw")], "yaw [deg]", "yaw angle", np.degrees(1.0)),
        "sinkage.png": _time_plot(
            res, [(f"sinkage_{e}_{k}_m", f"{e} {k}") for e in ("sprocket", "idler") for k in ("left", "right")],
            "sinkage [mm]", "sinkage under sprocket (rear) and idler (front)", 1e3),
        "shear.png": _time_plot(res, [("shear_left_m", "left"), ("shear_right_m", "right")],
                                "shear displacement [mm]", "mean shear displacement j", 1e3),
        "speeds.png": _time_plot(res, [("u_m_s", "u (forward)"), ("v_m_s", "v (lateral)")],
                                 "speed [m/s]", "body velocities"),
        "torques.png": _time_plot(
            res, [("torque_left_N_m", "left (actual)"), ("torque_right_N_m", "right (actual)"),
                  ("torque_cmd_left_N_m", "left (command)"), ("torque_cmd_right_N_m", "right (command)")],
            "torque [N m]", "sprocket torques"),
    }
