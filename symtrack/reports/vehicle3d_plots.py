"""The run folder's figures of the 3D vehicle (``model.vehicle = "3d"``, docs/vehicle3d.md "The run
folder"): the hull's attitude and the load split against the distance travelled, and on ground that
is not flat the path over the ground's elevation map. Each function returns PNG bytes, or nothing
for a run without the 3D vehicle's outputs (a planar run draws none of them); they are registered in
:mod:`symtrack.reports.figures`.

The abscissa is the distance travelled (the CG's horizontal path length, so a vehicle rolling back
on a ramp still counts forward); a run that moves less than :data:`STANDSTILL_DISTANCE_M` (a vehicle
parked on a side slope) is drawn against time instead.

The load split: each track's normal load (``normal_load_left_N``, ``normal_load_right_N``, the sums
of its segments' loads normal to the ground), and the lower and upper track's shares of their sum.
The lower track is the right one when the hull rolls left side up (``roll_rad`` > 0 over the run's
mean), else the left: one choice per run, so a flat run's round-off roll does not swap the curves.
"""

from __future__ import annotations

import numpy as np

from .plots import fixed_layout, plt, png_bytes

__all__ = ["ATTITUDE_COLUMNS", "LOAD_COLUMNS", "STANDSTILL_DISTANCE_M", "abscissa", "attitude_png",
           "load_split_data", "load_split_png", "path_elevation_png", "run_surface"]

# the outputs of a 3D run these figures draw (symtrack.vehicles.vehicle3d)
ATTITUDE_COLUMNS = ("z_m", "ground_z_m", "roll_rad", "pitch_rad")
LOAD_COLUMNS = ("normal_load_left_N", "normal_load_right_N")
# a run whose CG travels less than this [m] is drawn against time (a vehicle standing still)
STANDSTILL_DISTANCE_M = 0.05


def abscissa(res) -> tuple[np.ndarray, str]:
    """(values, label): the CG's distance travelled [m], or the time [s] for a run standing still."""
    x, y = res.column("x_m"), res.column("y_m")
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    if s[-1] < STANDSTILL_DISTANCE_M:
        return np.asarray(res.t, dtype=float), "t [s] (the vehicle stands: less than 5 cm travelled)"
    return s, "distance travelled [m]"


def attitude_png(res) -> bytes:
    """The CG's height and the ground's under it (top), roll and pitch (bottom) against distance."""
    s, label = abscissa(res)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(s, res.column("z_m"), label="CG height z")
    a1.plot(s, res.column("ground_z_m"), label="ground z0 under the CG")
    a1.set_ylabel("height [m]")
    a1.set_title("the hull's heave and the ground under it")
    a1.grid(True)
    a1.legend(fontsize=8)
    a2.plot(s, np.degrees(res.column("roll_rad")), label="roll (left side up +)")
    a2.plot(s, np.degrees(res.column("pitch_rad")), label="pitch (nose up +)")
    a2.set_xlabel(label)
    a2.set_ylabel("angle [deg]")
    a2.set_title("the hull's roll and pitch")
    a2.grid(True)
    a2.legend(fontsize=8)
    fixed_layout(fig, hspace_in=0.6)
    return png_bytes(fig, tight=False)


def load_split_data(res) -> dict:
    """What :func:`load_split_png` draws: the abscissa, each track's normal load [kN], which track is
    the lower one (module doc) and the lower and upper shares of the two loads' sum [%]."""
    s, label = abscissa(res)
    left, right = (res.column(n) for n in LOAD_COLUMNS)
    lower = "right" if float(np.mean(res.column("roll_rad"))) >= 0.0 else "left"
    total = left + right
    with np.errstate(divide="ignore", invalid="ignore"):
        low = np.where(total > 0, (right if lower == "right" else left) / total, np.nan)
    return {"s": s, "label": label, "left_kN": left / 1e3, "right_kN": right / 1e3, "lower": lower,
            "upper": "left" if lower == "right" else "right", "lower_pct": 100 * low, "upper_pct": 100 * (1 - low)}


def load_split_png(res) -> bytes:
    """Each track's normal load (top) and the lower / upper track's share of their sum (bottom)."""
    d = load_split_data(res)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(d["s"], d["left_kN"], label="left track")
    a1.plot(d["s"], d["right_kN"], label="right track")
    a1.set_ylabel("normal load [kN]")
    a1.set_title("each track's normal load (its segments' loads normal to the ground)")
    a1.grid(True)
    a1.legend(fontsize=8)
    a2.plot(d["s"], d["lower_pct"], label=f"lower ({d['lower']}) track")
    a2.plot(d["s"], d["upper_pct"], label=f"upper ({d['upper']}) track")
    a2.axhline(50.0, color="0.6", ls=":", lw=1)
    a2.set_xlabel(d["label"])
    a2.set_ylabel("share of the load [%]")
    a2.set_title("the load split between the tracks")
    a2.grid(True)
    a2.legend(fontsize=8)
    fixed_layout(fig, hspace_in=0.6)
    return png_bytes(fig, tight=False)


def run_surface(res):
    """The ground a run's hull drove on when it is not flat (homogeneous soil's ``[terrain.surface]``),
    else None. A grid run's ground is drawn by the terrain figure ``surface.png`` (the elevation of its
    cells with the path: :func:`symtrack.reports.terrain_plots.surface_png`), so not here."""
    surface = getattr(res.scenario, "surface", None)
    if surface is None or surface.is_flat:
        return None
    return surface


def path_elevation_png(res, surface, margin_m: float = 3.0, samples: int = 240) -> bytes:
    """The CG's path (start and end marked) over the ground's elevation z0 (``surface``:
    :class:`~symtrack.terrain.surface.Surface`), the map extended to the axes' aspect so that it is
    drawn to scale; blank beyond an elevation raster."""
    x, y = res.column("x_m"), res.column("y_m")
    fig, ax = plt.subplots(figsize=(8, 5))
    fixed_layout(fig, right_in=1.35)
    pos = ax.get_position()
    w_in, h_in = fig.get_size_inches()
    box = (pos.width * w_in) / (pos.height * h_in)  # the axes' width over height
    cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
    half_w, half_h = 0.5 * (x.max() - x.min()) + margin_m, 0.5 * (y.max() - y.min()) + margin_m
    if half_w / half_h < box:
        half_w = half_h * box
    else:
        half_h = half_w / box
    gx, gy = np.meshgrid(np.linspace(cx - half_w, cx + half_w, samples),
                         np.linspace(cy - half_h, cy + half_h, max(int(samples / box), 20)))
    z = surface.elevation(gx, gy)
    raster = getattr(surface, "raster", None)
    if raster is not None and raster.origin_m is not None:  # beyond the raster the heights are not the ground's
        rx0, rx1, ry0, ry1 = raster.bounds()
        z = np.where((gx >= rx0) & (gx <= rx1) & (gy >= ry0) & (gy <= ry1), z, np.nan)
    cs = ax.contourf(gx, gy, z, 30, cmap="terrain")
    ax.plot(x, y, "k-", lw=2, label="CG path")
    ax.plot(x[0], y[0], "o", color="k", ms=6, label="start")
    ax.plot(x[-1], y[-1], "s", color="r", ms=6, label="end")
    ax.set_xlim(cx - half_w, cx + half_w)
    ax.set_ylim(cy - half_h, cy + half_h)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("the path over the ground's elevation ([terrain.surface])")
    ax.legend(loc="upper right", fontsize=8)
    cax = fig.add_axes((pos.x1 + 0.2 / w_in, pos.y0, 0.18 / w_in, pos.height))
    fig.colorbar(cs, cax=cax, label="elevation z0 [m]")
    return png_bytes(fig, tight=False)
