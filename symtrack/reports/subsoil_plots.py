"""Subsoil plots (docs/subsoil.md): the risk map by depth, the stress-against-depth profile under
the track with the soil's strength, rut depth and maximum stress against the pass number, and the
bulk density: its map by depth and the field's largest against the pass number. Pure functions of
arrays; each returns PNG bytes."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap

from ..soil.subsoil import RISK_HIGH_ABOVE, RISK_LOW_BELOW, RISK_NAMES
from .plots import fixed_layout, plt, png_bytes

__all__ = ["RISK_COLOURS", "density_map_png", "density_passes_png", "passes_subsoil_png", "risk_map_png",
           "stress_profile_png"]

# Terranimo's colours: green, yellow, red
RISK_COLOURS = ("#2ca02c", "#f2c500", "#d62728")


def risk_map_png(risk, touched, depths_m, extent_m, title: str = "compaction risk") -> bytes:
    """One panel per depth: risk (nx, ny, n_depths) int classes 0/1/2, touched (nx, ny) bool
    (untouched cells blank), extent_m = (x0, x1, y0, y1) of the grid, x along the first axis."""
    risk = np.asarray(risk)
    touched = np.asarray(touched, dtype=bool)
    depths = list(depths_m)
    if risk.ndim != 3 or risk.shape[:2] != touched.shape or risk.shape[2] != len(depths):
        raise ValueError(f"risk has shape {risk.shape}, touched {touched.shape}, {len(depths)} depths: expected "
                         "risk (nx, ny, n_depths) and touched (nx, ny)")
    cmap = ListedColormap(RISK_COLOURS)
    fig, axes = plt.subplots(len(depths), 1, figsize=(9, 1.0 + 2.2 * len(depths)), squeeze=False)
    for k, (ax, d) in enumerate(zip(axes[:, 0], depths, strict=True)):
        shown = np.ma.masked_where(~touched, risk[:, :, k].astype(float))
        ax.imshow(shown.T, origin="lower", extent=extent_m, aspect="equal", cmap=cmap, vmin=-0.5, vmax=2.5,
                  interpolation="nearest")
        ax.set_ylabel("y [m]")
        ax.set_title(f"depth {d:g} m")
    axes[-1, 0].set_xlabel("x [m]")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in RISK_COLOURS]
    labels = [f"{RISK_NAMES[0]} (< {RISK_LOW_BELOW:g})", f"{RISK_NAMES[1]} ({RISK_LOW_BELOW:g}-{RISK_HIGH_ABOVE:g})",
              f"{RISK_NAMES[2]} (> {RISK_HIGH_ABOVE:g})"]
    fig.legend(handles, labels, loc="upper right", title="stress / strength", fontsize=8)
    fig.suptitle(title)
    return png_bytes(fig)


def stress_profile_png(depths_m, sigma_kPa, sigma_pc_kPa, label: str = "maximum under the track") -> bytes:
    """Vertical stress against depth (depth down) with the strength line sigma_pc and the class
    boundaries 0.5 sigma_pc and 1.1 sigma_pc shaded as Terranimo's green / yellow / red."""
    d = np.asarray(depths_m, dtype=float)
    s = np.asarray(sigma_kPa, dtype=float)
    pc = np.broadcast_to(np.asarray(sigma_pc_kPa, dtype=float), d.shape)
    order = np.argsort(d)
    d, s, pc = d[order], s[order], pc[order]
    top = 1.15 * max(float(s.max()), float((RISK_HIGH_ABOVE * pc).max()), 1e-9)
    fig, ax = plt.subplots(figsize=(5.5, 5))
    lo, hi = RISK_LOW_BELOW * pc, RISK_HIGH_ABOVE * pc
    ax.fill_betweenx(d, 0, lo, color=RISK_COLOURS[0], alpha=0.25, lw=0)
    ax.fill_betweenx(d, lo, hi, color=RISK_COLOURS[1], alpha=0.25, lw=0)
    ax.fill_betweenx(d, hi, top, color=RISK_COLOURS[2], alpha=0.25, lw=0)
    ax.plot(pc, d, "k-", lw=2, label="strength (precompression stress)")
    ax.plot(lo, d, "k:", lw=1, label=f"{RISK_LOW_BELOW:g} x strength")
    ax.plot(hi, d, "k--", lw=1, label=f"{RISK_HIGH_ABOVE:g} x strength")
    ax.plot(s, d, "o-", color="C0", lw=2, label=f"vertical stress ({label})")
    ax.set_xlim(0, top)
    ax.set_ylim(float(d.max()) * 1.05, 0)
    ax.set_xlabel("stress [kPa]")
    ax.set_ylabel("depth [m]")
    ax.grid(True)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("stress against strength by depth")
    fixed_layout(fig, left_in=0.8)
    return png_bytes(fig, tight=False)


def passes_subsoil_png(rut_depth_mm, sigma_max_kPa, depths_m) -> bytes:
    """Rut depth (n_passes,) and maximum vertical stress (n_passes, n_depths) against the pass
    number."""
    rut = np.asarray(rut_depth_mm, dtype=float)
    sm = np.asarray(sigma_max_kPa, dtype=float)
    if sm.ndim != 2 or sm.shape[0] != rut.size or sm.shape[1] != len(depths_m):
        raise ValueError(f"sigma_max_kPa has shape {sm.shape}; expected ({rut.size}, {len(depths_m)})")
    k = np.arange(1, rut.size + 1)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    a1.plot(k, rut, "o-")
    a1.set_ylabel("rut depth after the pass [mm]")
    for j, d in enumerate(depths_m):
        a2.plot(k, sm[:, j], "o-", label=f"{d:g} m")
    a2.set_ylabel("max vertical stress [kPa]")
    a2.set_xlabel("pass number")
    a2.set_xticks(k)
    a2.legend(title="depth", fontsize=8)
    for a in (a1, a2):
        a.grid(True)
    a1.set_title("rut depth and subsoil stress pass by pass")
    fixed_layout(fig, hspace_in=0.25)
    return png_bytes(fig, tight=False)


def density_map_png(rho_Mg_per_m3, depths_m, extent_m, title: str = "dry bulk density",
                    initial_Mg_per_m3=None) -> bytes:
    """One panel per depth, x along the first axis, extent_m = (x0, x1, y0, y1) of the grid. ``rho_Mg_per_m3``
    (nx, ny, n_depths): the dry bulk density [Mg/m^3]; with ``initial_Mg_per_m3`` (the same shape, or per depth)
    the map is the change from it, rho - rho_0, on one scale from 0 (a 1.35 topsoil's 0.02 and a 1.55 subsoil's
    show side by side; each panel's title gives the depth's initial and largest density); without it the
    density itself, one colour scale for all depths."""
    rho = np.asarray(rho_Mg_per_m3, dtype=float)
    depths = list(depths_m)
    if rho.ndim != 3 or rho.shape[2] != len(depths):
        raise ValueError(f"rho_Mg_per_m3 has shape {rho.shape}; expected (nx, ny, {len(depths)})")
    change = initial_Mg_per_m3 is not None
    if change:
        rho0 = np.broadcast_to(np.asarray(initial_Mg_per_m3, dtype=float), rho.shape)
        shown = rho - rho0
        lo, hi = 0.0, max(float(shown.max()), 1e-4)
        label, cmap = "increase of the dry bulk density [Mg/m$^3$]", "viridis"
    else:
        shown = rho
        lo, hi = float(rho.min()), float(rho.max())
        hi = hi if hi > lo else lo + 1e-3
        label, cmap = "dry bulk density [Mg/m$^3$]", "cividis_r"
    fig, axes = plt.subplots(len(depths), 1, figsize=(9, 1.0 + 2.2 * len(depths)), squeeze=False)
    im = None
    for k, (ax, d) in enumerate(zip(axes[:, 0], depths, strict=True)):
        im = ax.imshow(shown[:, :, k].T, origin="lower", extent=extent_m, aspect="equal", cmap=cmap, vmin=lo,
                       vmax=hi, interpolation="nearest")
        ax.set_ylabel("y [m]")
        if change:
            ax.set_title(f"depth {d:g} m: initial {float(rho0[:, :, k].min()):.3f}, largest "
                         f"{float(rho[:, :, k].max()):.3f} Mg/m$^3$")
        else:
            ax.set_title(f"depth {d:g} m")
    axes[-1, 0].set_xlabel("x [m]")
    fig.suptitle(title)
    fig.tight_layout(rect=(0.0, 0.0, 0.86, 1.0))
    cax = fig.add_axes((0.88, 0.12, 0.025, 0.76))
    fig.colorbar(im, cax=cax, label=label)
    return png_bytes(fig, tight=False)


def density_passes_png(initial_Mg_per_m3, rho_max_Mg_per_m3, depths_m) -> bytes:
    """The field's largest dry bulk density by depth against the pass number: initial (n_depths,)
    at pass 0, rho_max (n_passes, n_depths) after each pass."""
    r0 = np.asarray(initial_Mg_per_m3, dtype=float)
    rm = np.asarray(rho_max_Mg_per_m3, dtype=float)
    if r0.shape != (len(depths_m),) or rm.ndim != 2 or rm.shape[1] != len(depths_m):
        raise ValueError(f"initial has shape {r0.shape}, rho_max {rm.shape}; expected ({len(depths_m)},) and "
                         f"(n_passes, {len(depths_m)})")
    table = np.vstack([r0, rm])
    k = np.arange(table.shape[0])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for j, d in enumerate(depths_m):
        ax.plot(k, table[:, j], "o-", label=f"{d:g} m")
    ax.set_xlabel("pass number (0: before the first)")
    ax.set_ylabel("largest dry bulk density [Mg/m$^3$]")
    ax.set_xticks(k)
    ax.grid(True)
    ax.legend(title="depth", fontsize=8)
    ax.set_title("bulk density by depth pass by pass (O'Sullivan & Robertson 1996)")
    fixed_layout(fig)
    return png_bytes(fig, tight=False)
