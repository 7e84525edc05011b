"""Terrain plots: the sinkage map (top view, like figure 7 of the Politecnico di Milano thesis, docs/model.md)
and the rut cross-section."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..integrators.engine import ChannelManager
from ..soil.density import bulk_density
from .plots import fixed_layout, plt, png_bytes
from .subsoil_plots import density_map_png, density_passes_png

__all__ = ["ANIMATION_MAX_FRAMES", "density_pngs", "pass_animation_gif", "passes_png", "rut_section_png",
           "sinkage_map_png", "surface_png"]

ANIMATION_MAX_FRAMES = 30  # frames of a pass animation (snapshots are thinned to at most this)


def _window(world, maps, margin_cells=10):
    touched = np.zeros(world.grid.shape, dtype=bool)
    for z in maps:
        touched |= z > 0
    if not touched.any():
        return slice(0, world.grid.shape[0]), slice(0, world.grid.shape[1])
    ii, jj = np.nonzero(touched)
    nx, ny = world.grid.shape
    return (slice(max(ii.min() - margin_cells, 0), min(ii.max() + margin_cells + 1, nx)),
            slice(max(jj.min() - margin_cells, 0), min(jj.max() + margin_cells + 1, ny)))


def sinkage_map_png(world, z, pass_no: int, maps=None) -> bytes:
    si, sj = _window(world, maps or [z])
    g = world.grid
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    fig, ax = plt.subplots(figsize=(10, 3.5))
    im = ax.imshow(1e3 * z[si, sj].T, origin="lower", extent=ext, aspect="equal", cmap="viridis")
    fig.colorbar(im, ax=ax, label="sinkage [mm]")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"terrain sinkage after pass {pass_no} (cell {dx:g} m)")
    return png_bytes(fig)


def surface_png(world, maps, results) -> bytes:
    """The ground's shape (a field with an elevation): the initial elevation z0 over the field with
    the driven paths, the surface z0 - z after the last pass around the ruts, and under each track's
    centre-line along the first pass's path the elevation and the rut after the last pass."""
    g = world.grid
    nx, ny = g.shape
    z0 = world.storage.elevation.reshape(g.shape)
    z = maps[-1]
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(10, 11))
    im = a1.imshow(z0.T, origin="lower", extent=(x0, x0 + nx * dx, y0, y0 + ny * dx), aspect="equal", cmap="terrain")
    fig.colorbar(im, ax=a1, label="elevation z0 [m]")
    for k, res in enumerate(results):
        a1.plot(res.state("x_m"), res.state("y_m"), color="k" if k == 0 else "r", lw=1, label=f"pass {k + 1}")
    a1.set_title(f"initial elevation (cell {dx:g} m) and the driven path")
    a1.legend(loc="upper right")
    si, sj = _window(world, maps)
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    im = a2.imshow((z0 - z)[si, sj].T, origin="lower", extent=ext, aspect="equal", cmap="terrain")
    fig.colorbar(im, ax=a2, label="surface z0 - z [m]")
    a2.set_title(f"surface after pass {len(maps)} (elevation minus sinkage)")
    for a in (a1, a2):
        a.set_xlabel("x [m]")
        a.set_ylabel("y [m]")
    xs, ys, psis = (results[0].state(n) for n in ("x_m", "y_m", "yaw_rad"))
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xs), np.diff(ys)))])
    half = 0.5 * float(world.params["track_gauge_m"])
    a4 = a3.twinx()
    for side, name, color in ((1.0, "left", "C0"), (-1.0, "right", "C1")):
        px, py = xs - side * half * np.sin(psis), ys + side * half * np.cos(psis)
        i = np.clip(np.floor((px - x0) / dx).astype(int), 0, nx - 1)
        j = np.clip(np.floor((py - y0) / dx).astype(int), 0, ny - 1)
        a3.plot(s, z0[i, j], color=color, label=f"elevation z0 under the {name} track")
        a4.plot(s, -1e3 * z[i, j], color=color, ls="--", label=f"rut -z under the {name} track")
    a3.set_xlabel("distance along the first pass's path [m]")
    a3.set_ylabel("elevation z0 [m] (solid)")
    a4.set_ylabel(f"rut after pass {len(maps)} [mm] (dashed)")
    a3.set_title("under the tracks' centre-lines: the ground is z0 minus the rut")
    a3.grid(True)
    a3.legend(loc="upper left", fontsize=8)
    a4.legend(loc="lower right", fontsize=8)
    return png_bytes(fig)


def rut_section_png(world, maps, results, line) -> bytes:
    """Sinkage across the driven line, at the middle of the path of the first pass."""
    g = world.grid
    pose = results[0].pose()
    mid = len(pose) // 2
    xm, ym, psi = pose[mid]
    # sample along the body's lateral axis at the mid point
    across = np.arange(-1.5, 1.5 + 1e-9, g.cell_m / 2)
    px, py = xm - np.sin(psi) * across, ym + np.cos(psi) * across
    i = np.clip(np.floor((px - g.origin_m[0]) / g.cell_m).astype(int), 0, g.shape[0] - 1)
    j = np.clip(np.floor((py - g.origin_m[1]) / g.cell_m).astype(int), 0, g.shape[1] - 1)
    fig, ax = plt.subplots(figsize=(8, 4))
    for k, z in enumerate(maps):
        ax.step(across, -1e3 * z[i, j], where="mid", label=f"after pass {k + 1}")
    ax.set_xlabel("lateral position from the vehicle's centre line [m] (left +)")
    ax.set_ylabel("surface [mm] (sinkage down)")
    ax.set_title(f"rut cross-section at x = {xm:.2f} m, y = {ym:.2f} m")
    ax.grid(True)
    ax.legend()
    fixed_layout(fig)
    return png_bytes(fig, tight=False)


def passes_png(figures: list[dict]) -> bytes:
    """Rut depth (max and mean), the sinkage each pass added and the mean compaction resistance
    against the pass number (the per-pass figures of a terrain study)."""
    k = np.arange(1, len(figures) + 1)
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    a1.plot(k, [f["rut_max_depth_mm"] for f in figures], "o-", label="max")
    a1.plot(k, [f["rut_mean_depth_mm"] for f in figures], "s-", label="mean over the rut")
    a1.set_ylabel("rut depth after the pass [mm]")
    a1.legend()
    a2.bar(k, [f["new_sinkage_mean_mm"] for f in figures])
    a2.set_ylabel("sinkage added by the pass [mm]")
    a3.plot(k, [f["compaction_resistance_mean_N"] for f in figures], "o-")
    a3.set_ylabel("mean compaction resistance [N]")
    a3.set_xlabel("pass number")
    a3.set_xticks(k)
    for a in (a1, a2, a3):
        a.grid(True)
    a1.set_title("the rut pass by pass")
    fixed_layout(fig, hspace_in=0.25)
    return png_bytes(fig, tight=False)


def pass_animation_gif(world, z_before, snapshots, z_after, fps: int = 6) -> bytes:
    """A GIF of one pass: the tracks' footprints over the growing sinkage map, from the
    plant's snapshots (t_s, pose, loaded cells, their sinkage)."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.patches import Polygon

    g = world.grid
    manager = ChannelManager(world)  # the tracks' rectangles: the engine's (grid_engine.c eng_track_rects)
    si, sj = _window(world, [z_after])
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    step = max(1, -(-len(snapshots) // ANIMATION_MAX_FRAMES))
    frames = list(range(0, len(snapshots), step))
    if frames and frames[-1] != len(snapshots) - 1:
        frames.append(len(snapshots) - 1)
    z = np.array(z_before, dtype=float).ravel().copy()
    applied = [0]
    vmax = max(1e3 * float(np.max(z_after[si, sj])), 1e-3)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    im = ax.imshow(1e3 * z.reshape(g.shape)[si, sj].T, origin="lower", extent=ext, aspect="equal", cmap="viridis",
                   vmin=0.0, vmax=vmax)
    fig.colorbar(im, ax=ax, label="sinkage [mm]")
    tracks = [ax.add_patch(Polygon(np.zeros((4, 2)), closed=True, fill=False, ec="w", lw=1.5)) for _ in range(2)]
    title = ax.set_title("")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")

    def draw(k):
        while applied[0] <= k:  # the snapshots up to frame k, in order
            _, _, cells, zc = snapshots[applied[0]]
            z[cells] = zc
            applied[0] += 1
        t, pose, _, _ = snapshots[k]
        im.set_data(1e3 * z.reshape(g.shape)[si, sj].T)
        for patch, corners in zip(tracks, manager.track_corners(*pose), strict=True):
            patch.set_xy(corners)
        title.set_text(f"t = {t:.2f} s")
        return [im, *tracks, title]

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    with tempfile.TemporaryDirectory(prefix="symtrack-gif-") as tmp:
        path = Path(tmp) / "pass.gif"
        anim.save(str(path), writer=PillowWriter(fps=fps), dpi=70)
        data = path.read_bytes()
    plt.close(fig)
    return data


def subsoil_pngs(world, figures: list[dict]) -> dict[str, bytes]:
    """The subsoil plots of a terrain study (docs/subsoil.md), when it computed the stress:
    ``risk_map.png`` (the risk class by depth over the field's record of all passes),
    ``stress_profile.png`` (the field's largest stress against depth with the soil's strength) and,
    for several passes, ``subsoil_passes.png`` (rut depth and largest stress against the pass)."""
    from ..soil.subsoil import risk_class
    from .subsoil_plots import passes_subsoil_png, risk_map_png, stress_profile_png

    st = world.storage
    depths = st.subsoil_depths_m
    if not depths or not any("subsoil_sigma_z_max_kPa" in f for f in figures):
        return {}
    g = world.grid
    loaded = (st.sigma_max[:, 0] > 0).reshape(g.shape)
    # the window around the loaded cells (every loaded cell is in it): no array of the whole field's size
    # and the depths (a field of millions of cells, a few of them loaded)
    si, sj = _window(world, [loaded])
    cells = np.arange(g.n_cells).reshape(g.shape)[si, sj]
    loaded = loaded[si, sj]
    pc = world.precompression_stress_Pa(cells.ravel()).reshape(*cells.shape, len(depths))
    sig = st.sigma_max[cells]
    # the risk grades the traffic's stress plus the soil's own weight (soil/density.py)
    sig = np.where(loaded[:, :, None], sig + world.geostatic_Pa()[st.soil_index[cells]], sig)
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    strengths = sorted({float(v) for v in pc[loaded].ravel()})
    label = ", ".join(f"{1e-3 * v:.3g}" for v in strengths[:6]) + (", ..." if len(strengths) > 6 else "")
    # the profile where the stress is largest against its strength
    ratio = (sig / pc).max(axis=2)
    worst = np.unravel_index(np.argmax(np.where(loaded, ratio, -1.0)), loaded.shape)
    out = {"risk_map.png": risk_map_png(risk_class(sig, pc), loaded, depths, ext,
                                        title=f"compaction risk after all passes (strength {label} kPa)"),
           "stress_profile.png": stress_profile_png(depths, 1e-3 * sig[worst], 1e-3 * pc[worst],
                                                    label="the cell nearest its strength")}
    subs = [f for f in figures if "subsoil_sigma_z_max_kPa" in f]
    if len(figures) > 1 and len(subs) == len(figures):
        out["subsoil_passes.png"] = passes_subsoil_png([f["rut_mean_depth_mm"] for f in figures],
                                                       [f["subsoil_sigma_z_max_kPa"] for f in figures], depths)
    return out


def density_pngs(world, figures: list[dict], initial) -> dict[str, bytes]:
    """The bulk density plots of a terrain study (docs/subsoil.md "Bulk density"), when it computed
    the mean normal stress: ``density_map.png`` (the dry bulk density's increase over the initial by depth
    after all passes, around the cells loaded) and ``density_passes.png`` (the field's largest against the pass)."""
    st = world.storage
    depths = st.subsoil_depths_m
    dens = [f for f in figures if "bulk_density_max_Mg_per_m3" in f]
    if not depths or not dens or initial is None:
        return {}
    g = world.grid
    loaded = (st.sigma_max[:, 0] > 0).reshape(g.shape)
    si, sj = _window(world, [loaded])
    x0, y0, dx = g.origin_m[0], g.origin_m[1], g.cell_m
    ext = (x0 + si.start * dx, x0 + si.stop * dx, y0 + sj.start * dx, y0 + sj.stop * dx)
    cells = (np.arange(g.n_cells).reshape(g.shape)[si, sj]).ravel()
    rho = bulk_density(st.specific_volume[cells], st.soil_index[cells], world.soils, depths)
    rho0 = bulk_density(np.zeros_like(st.specific_volume[cells]), st.soil_index[cells], world.soils, depths)
    shape = (si.stop - si.start, sj.stop - sj.start, len(depths))
    out = {"density_map.png": density_map_png(rho.reshape(shape), depths, ext, initial_Mg_per_m3=rho0.reshape(shape),
                                              title="dry bulk density after all passes, increase over the initial")}
    if len(dens) == len(figures):
        out["density_passes.png"] = density_passes_png(initial, [f["bulk_density_max_Mg_per_m3"] for f in dens],
                                                       depths)
    return out
