"""The output folder of ``symtrack validate`` (docs/validation.md): one figure per case, validation.csv,
sensitivity.csv, validation.md, report.html and summary.json, written all or nothing through
:func:`symtrack.reports.run_files.write_folder` (a manifest, the folder's lock, atomic renames,
summary.json last)."""

from __future__ import annotations

import datetime
import html
import json
import textwrap
import time

from ..foundations.progress import Progress
from ..foundations.version import __version__
from ..reports.html import report_html, table_html
from ..reports.plots import plt, png_bytes
from ..reports.run_files import output_lock, write_folder
from .validate import (
    SCHEMA_VERSION,
    CaseResult,
    load_case,
    markdown_tables,
    resolve_cases,
    run_case,
    sensitivity_csv,
    summary_rows,
    validation_csv,
)

__all__ = ["SUMMARY_KIND", "ValidationRun", "case_figure", "list_cases", "run_validation", "summary_table"]

SUMMARY_KIND = "symtrack-validate"
_REF_MARKERS = ("s", "^", "v", "D", "P", "X")


def _measured_label(c) -> str:
    """The legend of a case's points: measured, or an empirical relation's values (a kind ending in _empirical)."""
    return "empirical relation (not measured)" if c.kind.endswith("_empirical") else "measured"


def case_figure(r: CaseResult) -> bytes:
    """PNG: the measured points (with their spread where given), the prediction as a line, the band
    of the assumptions' ends, and the reference models' predictions as open markers. A case by depth
    is drawn with depth downwards."""
    c = r.case
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    if c.x_labels is not None:
        return _categories_figure(fig, ax, r)
    by_depth = c.x_name.startswith("depth")
    scale = 1000.0 if c.x_name.endswith("_m") and by_depth else 1.0
    xl = "depth [mm]" if scale == 1000.0 else c.x_name

    def put(x, y, *args, **kw):
        return ax.plot(y, x * scale, *args, **kw) if by_depth else ax.plot(x, y, *args, **kw)

    if by_depth:
        ax.fill_betweenx(r.line_x * scale, r.line_low, r.line_high, color="tab:blue", alpha=0.18,
                         label="band of the assumptions")
    else:
        ax.fill_between(r.line_x, r.line_low, r.line_high, color="tab:blue", alpha=0.18,
                        label="band of the assumptions")
    put(r.line_x, r.line, "-", color="tab:blue", label="symtrack")
    for k, (name, (rx, rv)) in enumerate(c.references.items()):
        put(rx, rv, _REF_MARKERS[k % len(_REF_MARKERS)], mfc="none", color="0.35", ms=7, label=name)
    if c.spread is not None:
        if by_depth:
            ax.errorbar(c.measured, c.x * scale, xerr=c.spread, fmt="o", color="k", label=_measured_label(c))
        else:
            ax.errorbar(c.x, c.measured, yerr=c.spread, fmt="o", color="k", label=_measured_label(c))
    else:
        put(c.x, c.measured, "o", color="k", ms=8, label=_measured_label(c))
    yl = f"{c.quantity} [{c.unit}]"
    if by_depth:
        ax.set_xlabel(yl)
        ax.set_ylabel(xl)
        ax.invert_yaxis()
        ax.set_xlim(left=0.0)
    else:
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_ylim(bottom=0.0)
    ax.set_title("\n".join(textwrap.wrap(c.title, 80)), fontsize=8.5)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="best")
    return png_bytes(fig)


def _categories_figure(fig, ax, r: CaseResult) -> bytes:
    """A case whose points are categories: the band as a bar from its low to its high end at each, the
    prediction and the measured value as markers; wider than the others past six categories."""
    c = r.case
    fig.set_size_inches(max(6.4, 1.0 * c.x.size), 4.6)
    ax.bar(c.x, r.band_high - r.band_low, bottom=r.band_low, width=0.5, color="tab:blue", alpha=0.18,
           label="band of the assumptions")
    ax.plot(c.x, r.predicted, "_", color="tab:blue", ms=30, mew=2.5, label="symtrack")
    for k, (name, (rx, rv)) in enumerate(c.references.items()):
        ax.plot(rx, rv, _REF_MARKERS[k % len(_REF_MARKERS)], mfc="none", color="0.35", ms=7, label=name)
    if c.spread is not None:
        ax.errorbar(c.x, c.measured, yerr=c.spread, fmt="o", color="k", label=_measured_label(c))
    else:
        ax.plot(c.x, c.measured, "o", color="k", ms=8, label=_measured_label(c))
    # long names wrapped to the width a category has
    width = 15
    ax.set_xticks(c.x, ["\n".join(textwrap.wrap(lab, width, break_long_words=False, break_on_hyphens=False))
                        for lab in c.x_labels], fontsize=7.5 if any(len(lab) > width for lab in c.x_labels) else None)
    ax.set_xlim(float(c.x.min()) - 0.7, float(c.x.max()) + 0.7)
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel(f"{c.quantity} [{c.unit}]")
    ax.set_title("\n".join(textwrap.wrap(c.title, 80)), fontsize=8.5)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7.5, loc="best")
    return png_bytes(fig)


def summary_table(rows: list[dict]) -> str:
    """The printed summary: one line per kind of quantity."""
    w = max([16, *(len(s["kind"]) for s in rows)])
    head = (f"{'kind':<{w}} {'cases':>5} {'points':>6} {'mean |error|':>14} {'worst relative':>15}  "
            f"{'in band':>7}  worst at")
    lines = [head, "-" * len(head)]
    for s in rows:
        lines.append(f"{s['kind']:<{w}} {s['cases']:>5} {s['points']:>6} {s['mean_abs_error']:>9.3g} {s['unit']:<4} "
                     f"{100 * s['worst_relative_error']:>+14.0f}%  {s['points_in_band']:>3}/{s['points']:<3}  "
                     f"{s['worst_at']}")
    return "\n".join(lines)


def list_cases(names=None) -> list[tuple[str, str, str]]:
    """(name, title, source: citation, page, table) of the cases (every built-in one without names)."""
    out = []
    for path in resolve_cases(names or []):
        c = load_case(path)
        out.append((c.name, c.title + (" [calibration]" if c.calibration else ""),
                    f"{c.source['citation'].split(')')[0]}). {c.source['table']}; {c.source['page']}"))
    return out


class ValidationRun:
    """What :func:`run_validation` returns: the results per case, the summary rows, the files written."""

    def __init__(self, results, summary, files, wall_time_s):
        self.results, self.summary, self.files, self.wall_time_s = results, summary, files, wall_time_s


def _case_section(r: CaseResult) -> str:
    c = r.case
    xs = c.x_labels if c.x_labels else [float(x) for x in c.x]
    rows = [(x, float(m), float(p), float(e), f"{100 * re:+.0f} %", float(lo), float(hi))
            for x, m, p, e, re, lo, hi in zip(xs, c.measured, r.predicted, r.error, r.relative_error, r.band_low,
                                              r.band_high, strict=True)]
    parts = [f"<h2>{html.escape(c.name)}: {html.escape(c.title)}</h2>",
             f"<p>Source: {html.escape(c.source['citation'])} {html.escape(c.source['table'])}; "
             f"{html.escape(c.source['page'])}. Measured as {html.escape(c.source['measured_as'])}."
             f"{' <b>Calibration</b>: a parameter was fitted to these data.' if c.calibration else ''}</p>",
             f"<p><b>Findings.</b> {html.escape(c.findings)}</p>",
             table_html(rows, [c.x_name, f"measured [{c.unit}]", f"predicted [{c.unit}]", f"error [{c.unit}]",
                               "relative", "band low", "band high"])]
    if c.references:
        refs = [(name, ", ".join(f"{x:g}: {v:g}" for x, v in zip(rx, rv, strict=True)))
                for name, (rx, rv) in c.references.items()]
        parts.append("<p>Other models' predictions printed with the measurements (" + html.escape(c.x_name) +
                     ": value):</p>" + table_html(refs, ["model", "predictions"]))
    arows = []
    for a in c.assumptions:
        ends = [run for run in r.runs if run[0] == a.name]
        effect = "; ".join(f"{label} {v if isinstance(v, str) else f'{v:g}'}: " +
                           ", ".join(f"{p:.3g}" for p in pred) for _, label, v, pred, _ in ends)
        span = f"[{a.range[0]:g}, {a.range[1]:g}] {a.unit}" if a.range else " / ".join([a.value, *a.alternatives])
        arows.append((a.name, a.value if isinstance(a.value, str) else float(a.value), span, effect, a.reason))
    parts.append("<p>Assumptions (each run at the ends of its range, the others at their values; "
                 "the predictions at the measured points):</p>" +
                 table_html(arows, ["assumption", "value", "range", "predicted at the ends", "why"]))
    return "\n".join(parts)


def _run_cases(cases, bar, dask: bool, workers: int, scheduler: str | None) -> list[CaseResult]:
    """Each case's :func:`run_case`, in order: here one after another, or on Dask (``dask``, or a
    ``scheduler`` given) as one task per case on a local cluster of ``workers`` processes or on the
    running scheduler, as ``symtrack sweep`` runs its runs (:func:`symtrack.studies.engine.dask_client`)."""
    if not (dask or scheduler):
        results = []
        for k, c in enumerate(cases):
            bar.update(k, c.name)
            results.append(run_case(c))
        return results
    from distributed import as_completed

    from .engine import dask_client

    with dask_client("validate", workers, scheduler) as client:
        futures = client.map(run_case, cases, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        results = [None] * len(cases)
        for done, f in enumerate(as_completed(futures)):
            results[index[f.key]] = f.result()
            bar.update(done + 1, cases[index[f.key]].name)
    return results


def run_validation(names, out, progress: bool = True, dask: bool = False, workers: int = 2,
                   scheduler: str | None = None) -> ValidationRun:
    """Run the cases ``names`` (built-in names or case files; none: all), write the folder ``out``
    (docs/validation.md, "The output folder") and return the results. The folder is locked from
    before the first case; an unknown case or a bad case file fails before anything runs. ``dask``
    (or a ``scheduler`` address): the cases run on Dask, one task each (:func:`_run_cases`); the
    figures and files are made here, the same as without."""
    t0 = time.perf_counter()
    paths = resolve_cases(names)
    cases = [load_case(p) for p in paths]  # every case file checked before the first runs
    with output_lock(out):
        bar = Progress(len(cases), "validate", enabled=progress)
        results = _run_cases(cases, bar, dask, workers, scheduler)
        images = {f"{r.case.name}.png": case_figure(r) for r in results}
        bar.close()
        rows = summary_rows(results)
        summary = {"kind": SUMMARY_KIND, "schema_version": SCHEMA_VERSION, "symtrack_version": __version__,
                   "written_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
                   "cases": [r.case.name for r in results], "by_kind": rows,
                   "wall_time_s": time.perf_counter() - t0}
        body = "\n".join(_case_section(r) for r in results)
        table = table_html([(s["kind"], s["cases"], s["points"], s["mean_abs_error"], s["unit"],
                             f"{100 * s['worst_relative_error']:+.0f} %", s["worst_at"],
                             f"{s['points_in_band']}/{s['points']}", s["calibrations"]) for s in rows],
                           ["kind", "cases", "points", "mean |error|", "unit", "worst relative", "worst at",
                            "measured in band", "calibrations"])
        page = report_html("symtrack validate: published measurements against the package's models",
                           {k: v for k, v in summary.items() if k != "by_kind"}, images,
                           "\n".join(f"# {p.name}\n{p.read_text()}" for p in paths),
                           note="Each case: the measured points, the package's prediction with every assumption "
                           "at its value, and the band its assumptions span (each run at the ends of its range). "
                           "Nothing is fitted unless the case says calibration.")
        page = page.replace("<h2>Summary</h2>", "<h2>Errors by kind of quantity</h2>\n" + table + "\n" + body +
                            "\n<h2>Summary</h2>", 1).replace("<h2>Scenario (resolved)</h2>", "<h2>Case files</h2>", 1)
        files = {"validation.csv": validation_csv(results), "sensitivity.csv": sensitivity_csv(results),
                 "validation.md": markdown_tables(results, rows),
                 "report.html": page, **images,
                 "summary.json": json.dumps(summary, indent=1, default=float) + "\n"}
        written = write_folder(out, files)
    return ValidationRun(results, rows, written, time.perf_counter() - t0)

