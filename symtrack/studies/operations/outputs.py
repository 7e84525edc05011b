"""What an operation writes: its result (:class:`OperationResult`), the maps and the animation, the passes per
cell, and the traffic comparison's table and figure.

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass

import numpy as np

from ...foundations.files import npz_bytes
from ...terrain.storage import Terrain
from .settings import SCHEMA_VERSION, OperationSettings


# ---- running it -----------------------------------------------------------------------------------------
@dataclass
class OperationResult:
    """One operation driven: its figures (summary), the passes per cell (nx, ny) uint16, the cells
    the engine stressed (nx, ny) bool, the follower's log, the terrain after it (shared, not copied)."""

    name: str
    figures: dict
    counts: np.ndarray
    stressed: np.ndarray
    log: np.ndarray
    trajectory: np.ndarray  # t, x, y, yaw every COUNT_SAMPLE_S
    error: str | None = None
    first_contact_s: np.ndarray | None = None  # (nx, ny) float32: when a track first came over the cell (inf: never)

    def __repr__(self) -> str:
        from ...reports.html import short_repr

        figures = {**self.figures, "complete": self.error is None}
        return short_repr("OperationResult", self.name, figures,
                          ("operation_trafficked_fraction", "distance_m", "rut_max_depth_mm", "sim_time_s",
                           "wall_time_s"))


def map_pngs(counts, z, fs: OperationSettings, label: str) -> dict:
    from .. import field_plots

    ext = (0.0, fs.size_m[0], 0.0, fs.size_m[1])
    return {"passes_map.png": field_plots.passes_map_png(counts, ext, f"passes per cell: {label}"),
            "rut_map.png": field_plots.sinkage_map_png(z, ext, f"rut depth: {label}")}


def _gif(what: str, progress: bool, draw) -> bytes:
    """``draw(progress=...)``'s GIF, its frames counted on a progress bar named ``what``."""
    from ...foundations.progress import Progress

    bar = Progress(1.0, what, enabled=progress)
    gif = draw(progress=lambda k, n: bar.update(k / n, f"frame {k}/{n}"))
    bar.close()
    return gif


def animation(r: OperationResult, terrain: Terrain, fs: OperationSettings, label: str, progress: bool) -> bytes:
    """The operation's GIF over the rut map (:func:`symtrack.studies.field_plots.operation_gif`), with progress."""
    from .. import field_plots

    return _gif(f"animation {fs.name}", progress, lambda progress: field_plots.operation_gif(
        terrain.z.reshape(r.counts.shape), r.first_contact_s, r.trajectory, (0.0, fs.size_m[0], 0.0, fs.size_m[1]),
        label, progress=progress))


def season_animation(results: list, terrain: Terrain, fs: OperationSettings, labels: list, title: str,
                     progress: bool) -> bytes:
    """The season's GIF: every operation in order over the season's rut map
    (:func:`symtrack.studies.field_plots.season_gif`), with progress."""
    from .. import field_plots

    ops = [(label, r.first_contact_s, r.trajectory) for r, label in zip(results, labels, strict=True)
           if r.first_contact_s is not None]
    return _gif("animation of the season", progress, lambda progress: field_plots.season_gif(
        terrain.z.reshape(results[0].counts.shape), ops, (0.0, fs.size_m[0], 0.0, fs.size_m[1]), title,
        progress=progress))


def counts_npz(counts, cell_m) -> bytes:
    return npz_bytes(kind=np.array("symtrack-field-passes"), schema_version=np.array(SCHEMA_VERSION),
                     origin_m=np.zeros(2), cell_m=np.array(cell_m), shape=np.array(counts.shape), passes=counts)


TRAFFIC_COLUMNS = ("tracks", "complete", "trafficked_fraction", "headland_trafficked_fraction",
                   "infield_trafficked_fraction",
                   "area_run_over_once_m2", "area_run_over_twice_m2", "area_run_over_3_or_more_m2",
                   "repeated_coverage_fraction", "rut_max_depth_mm", "distance_m", "sim_time_s", "energy_sprockets_J",
                   "turns_driven", "turns_lifted", "rms_lateral_error_lines_m", "wall_time_s")


class TrafficComparison(dict):
    """The traffic systems' comparison: a dict with ``rows`` (one per system, :data:`TRAFFIC_COLUMNS`; the
    rows of traffic.csv) and, from the Dask sweep, ``sweep`` (its :class:`~symtrack.studies.engine.SweepResult`);
    in a notebook a table of the systems, in a console one line per system's share trafficked."""

    KEYS = ("tracks", "complete", "trafficked_fraction", "repeated_coverage_fraction", "rut_max_depth_mm",
            "distance_m", "wall_time_s")

    def __init__(self, name: str, rows: list, **more):
        super().__init__(rows=rows, **more)
        self.name = name

    def __repr__(self) -> str:
        shares = ", ".join(f"{r['tracks']} {r['trafficked_fraction']:.4g}" if r.get("trafficked_fraction") is not None
                           else f"{r['tracks']} incomplete" for r in self["rows"])
        return f"<TrafficComparison {self.name!r}: trafficked_fraction {shares}>"

    def _repr_html_(self) -> str:
        """A table of the systems' figures (the columns of :data:`KEYS`)."""
        from ...reports.html import notebook_html

        rows = [tuple(r.get(k) for k in self.KEYS) for r in self["rows"]]
        return notebook_html(f"Traffic systems: {self.name}", {}, [("systems", len(rows))], keys=(), rows=rows,
                             row_header=list(self.KEYS))


def traffic_row(system: str, summary: dict | None) -> dict:
    """A row of the traffic table (:data:`TRAFFIC_COLUMNS`) from a system's season summary (None:
    the season did not finish: complete false, the figures empty)."""
    summary = summary or {"complete": False}
    return {"tracks": system, **{k: summary.get(k) for k in TRAFFIC_COLUMNS if k != "tracks"}}


def traffic_files(rows) -> dict:
    """The comparison's table and figure: ``traffic.csv``, ``traffic.png``, ``traffic.json``."""
    import csv

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TRAFFIC_COLUMNS)
    for r in rows:
        w.writerow(["" if r[c] is None else r[c] for c in TRAFFIC_COLUMNS])
    return {"traffic.csv": buf.getvalue(), "traffic.png": _traffic_png(rows),
            "traffic.json": json.dumps(rows, indent=2) + "\n"}


def _traffic_png(rows) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [("trafficked_fraction", "trafficked (whole field)"), ("infield_trafficked_fraction", "in-field"),
            ("headland_trafficked_fraction", "headland"), ("repeated_coverage_fraction", "repeated coverage")]
    fig, ax = plt.subplots(figsize=(7.0, 3.6))
    n = len(rows)
    width = 0.8 / n
    for i, r in enumerate(rows):
        ax.bar(np.arange(len(keys)) + i * width, [r[k] or 0.0 for k, _ in keys], width, label=r["tracks"])
    # Kroulik et al. 2009 (Soil & Tillage Research): the share run over at least once in their DGPS-logged seasons
    for share, lab, ls in ((0.953, "Kroulik 2009: conventional 95.3 %", "-"), (0.728, "minimum tillage 72.8 %", "--"),
                           (0.557, "direct seeding 55.7 %", ":")):
        ax.hlines(share, -0.5 * width, 0.8 - 0.5 * width, colors="k", linestyles=ls, linewidth=1.0, label=lab)
    ax.set_xticks(np.arange(len(keys)) + 0.4 - width / 2, [lab for _, lab in keys])
    ax.set_ylabel("share of the area")
    ax.legend(fontsize=7)
    ax.set_title("traffic systems: the same season on new fields")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()
