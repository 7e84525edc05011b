"""``report.html``: one self-contained page per run (no external file, no network): the summary
table, the validation table when the scenario is a validation, the per-pass table of a terrain
study, every plot embedded as a PNG data URI, and the resolved scenario.

A small inline script checks on load that every image decoded and writes the result into the
page (``<body data-images-ok="N/M">``), which a headless browser's DOM dump can read
(tests/test_report.py).
"""

from __future__ import annotations

import base64
import html
import json

__all__ = ["REPORT_SCHEMA_VERSION", "machine_facts", "notebook_html", "report_html", "short_repr", "table_html"]

REPORT_SCHEMA_VERSION = 1

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 1em 0; }
td, th { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: left; }
th { background: #eee; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.5em 0; }
pre { background: #f6f6f6; padding: 1em; overflow-x: auto; }
.bad { color: #b00; font-weight: bold; }
"""

_CHECK = """
window.addEventListener("load", function () {
  var imgs = document.images, ok = 0;
  for (var i = 0; i < imgs.length; i++) { if (imgs[i].complete && imgs[i].naturalWidth > 0) { ok++; } }
  document.body.setAttribute("data-images-ok", ok + "/" + imgs.length);
});
"""


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.6g}"
    if v is None:
        return "n/a"
    return str(v)


def table_html(rows, header) -> str:
    """An HTML table (cells escaped, numbers right-aligned)."""
    out = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for row in rows:
        cells = []
        for v in row:
            cls = ' class="num"' if isinstance(v, (int, float)) and not isinstance(v, bool) else ""
            cells.append(f"<td{cls}>{html.escape(_fmt(v))}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def report_html(title: str, summary: dict, images: dict[str, bytes], scenario_text: str,
                validation_rows=None, passes: list[dict] | None = None, note: str = "",
                tables: dict[str, tuple[list, list]] | None = None, omitted: str = "") -> str:
    """The page (see the module doc). ``images``: file name -> PNG (or GIF) bytes, shown in
    order; ``validation_rows``: (key, reported, value, ok) rows; ``passes``: per-pass figures;
    ``omitted``: which figures the run did not draw (a sentence under the plots' heading)."""
    parts = [f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
             f"<meta name=\"symtrack-report-schema\" content=\"{REPORT_SCHEMA_VERSION}\">\n"
             f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n<script>{_CHECK}</script>\n"
             f"</head>\n<body>\n<h1>{html.escape(title)}</h1>"]
    if summary.get("complete") is False:
        parts.append(f"<p class=\"bad\">Incomplete run: {html.escape(str(summary.get('error', '')))}</p>")
    if note:
        parts.append(f"<p>{html.escape(note)}</p>")
    if validation_rows:
        parts.append("<h2>Validation (Ferretti &amp; Girelli 1999)</h2>")
        parts.append(table_html([(k, rep, v, "yes" if ok else "NO") for k, rep, v, ok in validation_rows],
                            ["quantity", "reported", "simulated", "within"]))
    scalars = [(k, v) for k, v in summary.items() if not isinstance(v, (list, dict))]
    parts.append("<h2>Summary</h2>")
    parts.append(table_html(scalars, ["key", "value"]))
    for heading, (header, rows) in (tables or {}).items():
        parts.append(f"<h2>{html.escape(heading)}</h2>")
        parts.append(table_html(rows, header))
    if passes:
        keys = list(passes[0])
        parts.append("<h2>Passes</h2>")
        parts.append(table_html([[k + 1] + [p.get(c) for c in keys] for k, p in enumerate(passes)], ["pass", *keys]))
    if images or omitted:
        parts.append("<h2>Plots</h2>")
    if omitted:
        parts.append(f"<p class=\"omitted\">{html.escape(omitted)}</p>")
    if images:
        for name, data in images.items():
            mime = "image/gif" if name.endswith(".gif") else "image/png"
            uri = f"data:{mime};base64,{base64.b64encode(data).decode()}"
            parts.append(f"<figure><img src=\"{uri}\" alt=\"{html.escape(name)}\">"
                         f"<figcaption>{html.escape(name)}</figcaption></figure>")
    parts.append("<h2>Scenario (resolved)</h2>")
    parts.append(f"<pre>{html.escape(scenario_text)}</pre>")
    parts.append("<h2>summary.json</h2>")
    parts.append(f"<pre>{html.escape(json.dumps(summary, indent=2, default=str))}</pre>")
    parts.append("</body>\n</html>\n")
    return "\n".join(parts)


def _unit(key: str) -> str:
    """The unit a summary key names in its suffix (``_mm`` -> mm, ``_N_m`` -> N m), or ""."""
    from ..foundations.units import unit_of_suffix

    return unit_of_suffix(key, "")


def machine_facts(vehicle_preset, soil_preset, params=None) -> list[tuple[str, str]]:
    """What a run's view names of its machine and soil: the vehicle preset with the mass it ran with, the
    soil preset (a preset file by its file name)."""
    mass = (params or {}).get("mass_kg")
    vehicle = str(vehicle_preset) + (f", {mass:g} kg" if isinstance(mass, int | float) else "")
    soil = str(soil_preset)
    if soil.endswith(".toml"):
        soil = soil.replace("\\", "/").rsplit("/", 1)[-1]
    return [("vehicle", vehicle), ("soil", soil)]


def short_repr(kind: str, name: str, summary: dict, keys: tuple[str, ...]) -> str:
    """A result's plain repr: ``<kind 'name': key value, ...>``, the figures of ``keys`` the summary has
    (numbers to 4 significant digits), ", incomplete" when the run did not finish."""
    figs = [f"{k} {summary[k]:.4g}" for k in keys
            if isinstance(summary.get(k), int | float) and not isinstance(summary.get(k), bool)]
    tail = "" if summary.get("complete", True) else ", incomplete"
    return f"<{kind} {name!r}{': ' if figs else ''}{', '.join(figs)}{tail}>"


def notebook_html(title: str, summary: dict, facts: list[tuple[str, object]],
                  keys: tuple[str, ...] = (), rows: list[tuple] | None = None, row_header=None) -> str:
    """A result's view in a notebook (Jupyter's ``_repr_html_``): an HTML fragment, no script, no
    image (a notebook renders it inline): the title; ``facts`` (what ran: scenario, soil, machine,
    integrator, ...) as one line; the summary's figures ``keys`` (default: every scalar of the
    summary but the schema's bookkeeping) in a table with their units; optionally a second table
    (``rows`` under ``row_header``). An incomplete run says so first, in red, with its error."""
    esc = html.escape
    parts = [f"<div class=\"symtrack-result\"><strong>{esc(title)}</strong>"]
    if summary.get("complete") is False:
        parts.append(f"<p style=\"color:#b00\">Incomplete run: {esc(str(summary.get('error', '')))}</p>")
    if facts:
        parts.append("<p>" + "; ".join(f"{esc(k)}: <code>{esc(_fmt(v))}</code>" for k, v in facts) + "</p>")
    skip = {"schema_version", "scenario", "error", "complete"}
    chosen = [k for k in (keys or summary) if k in summary and k not in skip
              and not isinstance(summary[k], (list, dict))]
    if chosen:
        parts.append(table_html([(k, summary[k], _unit(k)) for k in chosen], ["figure", "value", "unit"]))
    if rows:
        parts.append(table_html(rows, row_header))
    parts.append("</div>")
    return "\n".join(parts)
