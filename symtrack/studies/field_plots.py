"""The plots of a whole-field traffic study (docs/studies.md): the final sinkage map of the whole
field, the passes-per-cell map and the comparison of the two traffic patterns. Pure functions of
arrays and figures; each returns PNG bytes. (The risk map by depth is
:func:`symtrack.reports.subsoil_plots.risk_map_png`.)"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap

from ..reports.plots import plt, png_bytes
from ..reports.subsoil_plots import RISK_COLOURS
from ..soil.subsoil import RISK_NAMES

__all__ = ["RISK_MAP_BLOCKS", "PASSES_MAP_BLOCKS", "block_max", "comparison_png", "operation_gif", "passes_map_png",
           "sinkage_map_png"]

PATTERN_COLOURS = {"random": "C1", "controlled": "C0"}
# a field of many cells is drawn in at most this many blocks along each axis, each block showing
# its largest value (block_max): a rut a few cells wide would otherwise drop out of the picture
# when the image is scaled down to the panel
PASSES_MAP_BLOCKS = 400
RISK_MAP_BLOCKS = 100  # risk_map_png's panels are about 190 pixels high


def block_max(a, max_blocks: int):
    """``a`` (nx, ny, ...) reduced to at most max_blocks blocks along each of its first two axes,
    each block of f x f cells (f = ceil(max(nx, ny) / max_blocks)) its largest value; returns
    (the reduced array, f). f = 1 returns ``a`` itself."""
    a = np.asarray(a)
    nx, ny = a.shape[:2]
    f = max(1, int(np.ceil(max(nx, ny) / max_blocks)))
    if f == 1:
        return a, 1
    px, py = (-nx) % f, (-ny) % f
    low = np.zeros((), dtype=a.dtype) if a.dtype == bool else np.array(np.iinfo(a.dtype).min if a.dtype.kind in "iu"
                                                                       else -np.inf, dtype=a.dtype)
    padded = np.pad(a, [(0, px), (0, py)] + [(0, 0)] * (a.ndim - 2), constant_values=low)
    shape = (padded.shape[0] // f, f, padded.shape[1] // f, f, *a.shape[2:])
    return padded.reshape(shape).max(axis=(1, 3)), f


def sinkage_map_png(z_m, extent_m, title: str) -> bytes:
    """The sinkage z (nx, ny) [m] of the whole field, top view, x along the first axis."""
    z = np.asarray(z_m, dtype=float)
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    im = ax.imshow(1e3 * z.T, origin="lower", extent=extent_m, aspect="equal", cmap="viridis",
                   interpolation="antialiased")
    fig.colorbar(im, ax=ax, label="sinkage [mm]", shrink=0.85)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"final sinkage: {title}")
    return png_bytes(fig)


def passes_map_png(counts, extent_m, title: str) -> bytes:
    """The number of passes that loaded each cell (nx, ny), untrafficked cells white (a large field
    in blocks of cells, each its largest count: :func:`block_max`)."""
    c, f = block_max(np.asarray(counts), PASSES_MAP_BLOCKS)
    top = max(int(c.max()), 1)
    colours = ["#ffffff", *plt.get_cmap("magma_r")(np.linspace(0.15, 0.95, top))]
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(-0.5, top + 1.5), cmap.N)
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    im = ax.imshow(c.T, origin="lower", extent=extent_m, aspect="equal", cmap=cmap, norm=norm,
                   interpolation="nearest")
    cb = fig.colorbar(im, ax=ax, label="passes per cell", shrink=0.85)
    cb.set_ticks(range(0, top + 1, max(1, (top + 1) // 10)))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    frac = float((np.asarray(counts) > 0).mean())
    ax.set_title(f"passes per cell: {title} ({100 * frac:.1f} % of the field trafficked)"
                 + (f"\nblocks of {f} x {f} cells, each its largest count" if f > 1 else ""), fontsize=10)
    return png_bytes(fig)


def comparison_png(figures: dict) -> bytes:
    """The patterns side by side: figures {pattern: field figures (studies.field.field_figures)}.
    Panels: trafficked area fraction; passes-per-cell histogram of the trafficked cells; mean and
    largest rut depth; the field's area fraction at medium and high risk against depth."""
    names = list(figures)
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    ax = axes[0, 0]
    fr = [100 * figures[n]["trafficked_area_fraction"] for n in names]
    ax.bar(names, fr, color=[PATTERN_COLOURS.get(n, "C2") for n in names])
    for i, v in enumerate(fr):
        ax.text(i, v, f"{v:.1f} %", ha="center", va="bottom")
    ax.set_ylabel("trafficked area [% of the field]")
    ax.set_title("area trafficked at least once")
    ax = axes[0, 1]
    width = 0.8 / max(len(names), 1)
    for k, n in enumerate(names):
        h = np.asarray(figures[n]["passes_per_cell_histogram"], dtype=float)[1:]
        area = h * 100.0 / max(figures[n]["field_cells"], 1)
        ax.bar(np.arange(1, h.size + 1) + (k - 0.5 * (len(names) - 1)) * width, area, width,
               label=n, color=PATTERN_COLOURS.get(n, "C2"))
    top = max(len(figures[n]["passes_per_cell_histogram"]) - 1 for n in names)
    ax.set_xticks(range(1, top + 1))
    ax.set_xlabel("passes per cell")
    ax.set_ylabel("area [% of the field]")
    ax.set_title("passes per cell (trafficked cells)")
    ax.legend()
    ax = axes[1, 0]
    x = np.arange(2)
    for k, n in enumerate(names):
        v = [figures[n]["rut_mean_depth_mm"], figures[n]["rut_max_depth_mm"]]
        ax.bar(x + (k - 0.5 * (len(names) - 1)) * width, v, width, label=n, color=PATTERN_COLOURS.get(n, "C2"))
    ax.set_xticks(x, ["mean over the trafficked cells", "largest"])
    ax.set_ylabel("rut depth [mm]")
    ax.set_title("rut depth after all passes")
    ax.legend()
    ax = axes[1, 1]
    shown = False
    for n in names:
        f = figures[n]
        d = f.get("subsoil_depths_m")
        if not d:
            continue
        shown = True
        for name, style, marker in zip(RISK_NAMES[1:], ("--", "-"), ("o", "s"), strict=True):
            v = [100 * x for x in f[f"risk_fraction_of_field_{name}"]]
            # a class the pattern never reaches lies on the axis: its label says so
            ax.plot(v, d, style, marker=marker, color=PATTERN_COLOURS.get(n, "C2"),
                    label=f"{n}: {name} risk" + ("" if any(v) else " (none)"))
    if shown:
        if not any(v for n in names for r in RISK_NAMES[1:] for v in figures[n].get(f"risk_fraction_of_field_{r}", [])):
            ax.text(0.5, 0.5, "no cell above low risk at any depth", transform=ax.transAxes, ha="center")
        ax.invert_yaxis()
        ax.set_xlabel("area [% of the field]")
        ax.set_ylabel("depth [m]")
        ax.legend(fontsize=8)
        ax.axvline(0, color=RISK_COLOURS[0], lw=0.8)
    ax.set_title("subsoil compaction risk by depth (Terranimo classes)")
    fig.suptitle("traffic patterns compared")
    return png_bytes(fig)


# the animation of an operation (operation_gif): at most this many frames, this many blocks across
ANIMATION_FRAMES = 60
ANIMATION_BLOCKS = 300
ANIMATION_FRAME_MS = 120


def operation_gif(z_m, first_contact_s, trajectory, extent_m, title: str, frames: int = ANIMATION_FRAMES,
                  blocks: int = ANIMATION_BLOCKS, progress=None, phases=None) -> bytes:
    """An animated GIF of an operation over its rut map: frame k shows the rut depth (the
    operation's final sinkage ``z_m``, (nx, ny) m) of the cells a track had come over by the frame's
    time (``first_contact_s``, (nx, ny), inf: never), the rest of the field grey, the driven path up
    to then and the vehicle's position (``trajectory``: rows t, x, y, yaw). The field is drawn in
    blocks (:func:`block_max`, at most ``blocks`` along a side); ``progress(k, n)`` is called per frame.
    ``phases`` (a season, :func:`season_gif`): (t_start, t_end, label, (first row, end row)) of each
    operation on the one time axis; a frame names its operation and draws that operation's path only."""
    from PIL import Image, ImageDraw

    z, f = block_max(np.asarray(z_m, dtype=np.float32), blocks)
    # a block is revealed when its first cell is: the smallest first-contact time of its cells
    tfirst, _ = block_max(-np.asarray(first_contact_s, dtype=np.float32), blocks)
    tfirst = -tfirst
    traj = np.asarray(trajectory, dtype=float)
    t0, t1 = float(traj[0, 0]), float(traj[-1, 0])
    top = max(float(np.nanmax(z)), 1e-6)
    cmap = plt.get_cmap("viridis")
    nx, ny = z.shape
    scale = max(1, int(round(480 / max(nx, ny))))
    x0, x1, y0, y1 = extent_m
    header = 22

    def to_px(x, y):
        return ((x - x0) / (x1 - x0) * nx * scale, header + (1 - (y - y0) / (y1 - y0)) * ny * scale)

    rgb_rut = (cmap(np.clip(z / top, 0, 1))[..., :3] * 255).astype(np.uint8)
    grey = np.full_like(rgb_rut, 225)
    images = []
    n = max(1, min(frames, traj.shape[0]))
    for k in range(n):
        tk = t0 + (t1 - t0) * (k + 1) / n
        shown = (tfirst <= tk)[..., None]
        img = np.where(shown, rgb_rut, grey).transpose(1, 0, 2)[::-1]  # (ny, nx, 3), y up
        img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
        canvas = Image.new("RGB", (img.shape[1], img.shape[0] + header), (255, 255, 255))
        canvas.paste(Image.fromarray(np.ascontiguousarray(img)), (0, header))
        draw = ImageDraw.Draw(canvas)
        rows = traj
        label = title
        if phases:  # this frame's operation: its rows of the trajectory
            _ta, _tb, name, (ra, rb) = next((p for p in phases if tk <= p[1]), phases[-1])
            rows = traj[ra:rb]
            label = f"{title}, {name}"
        upto = rows[rows[:, 0] <= tk]
        if upto.shape[0] > 1:
            pts = [to_px(x, y) for x, y in upto[:: max(1, upto.shape[0] // 2000), 1:3]]
            draw.line(pts, fill=(200, 30, 30), width=1)
        if upto.shape[0]:
            px, py = to_px(upto[-1, 1], upto[-1, 2])
            draw.ellipse([px - 4, py - 4, px + 4, py + 4], fill=(255, 60, 0), outline=(0, 0, 0))
        draw.text((4, 4), f"{label}: t = {tk:.0f} s, rut depth 0-{1e3 * top:.1f} mm (viridis)", fill=(0, 0, 0))
        images.append(canvas.convert("P", palette=Image.ADAPTIVE, colors=128))
        if progress is not None:
            progress(k + 1, n)
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=ANIMATION_FRAME_MS, loop=0)
    return buf.getvalue()


def season_gif(z_m, operations, extent_m, title: str, frames: int = ANIMATION_FRAMES,
               blocks: int = ANIMATION_BLOCKS, progress=None) -> bytes:
    """The animation of a season: every operation in order on one time axis (each driven after the
    one before), over the season's rut map ``z_m``: a cell is shown from the time a track of any
    operation first came over it, each frame names its operation and draws its path.
    ``operations``: (label, first_contact_s (nx, ny), trajectory rows t, x, y, yaw) in order."""
    firsts, trajs, phases = [], [], []
    offset = 0.0
    for label, first, traj in operations:
        traj = np.asarray(traj, dtype=float)
        if traj.shape[0] == 0:
            continue
        t0 = float(traj[0, 0])
        shifted = traj.copy()
        shifted[:, 0] += offset - t0
        firsts.append(np.asarray(first, dtype=np.float32) + np.float32(offset - t0))
        rows = sum(t.shape[0] for t in trajs)
        trajs.append(shifted)
        phases.append((offset, float(shifted[-1, 0]), label, (rows, rows + shifted.shape[0])))
        offset = float(shifted[-1, 0])
    first_all = np.minimum.reduce(firsts) if firsts else np.full(np.shape(z_m), np.inf, np.float32)
    traj_all = np.concatenate(trajs) if trajs else np.zeros((1, 4))
    return operation_gif(z_m, first_all, traj_all, extent_m, title, frames=frames, blocks=blocks,
                         progress=progress, phases=phases or None)
