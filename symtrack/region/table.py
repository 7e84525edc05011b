"""The per-field table's schema (docs/region.md, "Outputs"): one row per field and season, the same columns in
``fields.csv`` and in ``fields.gpkg`` (:mod:`symtrack.region.gpkg`)."""

from __future__ import annotations

import csv
import io

__all__ = ["FIXED_COLUMNS", "PER_DEPTH", "TABLE_COLUMNS", "cell_text", "fields_csv"]

FIXED_COLUMNS = ("field_id", "soil", "system", "year", "area_ha", "headland_share", "days_worked",
                 "trafficked_fraction", "headland_trafficked_fraction", "infield_trafficked_fraction",
                 "repeated_coverage_fraction", "passes_max", "outside_field_trafficked_m2", "soil_share", "fidelity")
PER_DEPTH = ("risk_low_fraction_{d}", "risk_medium_fraction_{d}", "risk_high_fraction_{d}",
             "density_change_mean_{d}_Mg_per_m3", "density_change_trafficked_mean_{d}_Mg_per_m3",
             "density_change_max_{d}_Mg_per_m3", "stress_max_{d}_kPa")


def TABLE_COLUMNS(depths_m) -> list[str]:  # noqa: N802 - the table's schema, a function of the depths
    """fields.csv's columns for a study's depths (docs/region.md, "Outputs", documents each)."""
    return [*FIXED_COLUMNS, *(c.format(d=f"{d:g}m") for d in depths_m for c in PER_DEPTH), "wall_time_s"]


def cell_text(v) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, dict):
        return ";".join(f"{k}={x}" for k, x in v.items())
    return str(v)


def fields_csv(rows: list[dict], depths_m) -> str:
    cols = TABLE_COLUMNS(depths_m)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([cell_text(r.get(c, "")) for c in cols])
    return buf.getvalue()
