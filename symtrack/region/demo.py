"""A generated region (docs/region.md, "The demo region"): fields, soils' suction series, calendars and the
region file, written into a folder. ``region_demo`` is :func:`write_region` with its defaults; tests and the
benchmark generate their own sizes.

Everything here is generated, not measured:

- **fields**: convex quadrilaterals (a rectangle of random length and width with each corner moved by up to
  a tenth of the shorter side), turned by a random angle, one per cell of a square layout ``spacing_m`` apart,
  in a projected CRS (UTM zone 33N) about a false origin;
- **suction**: per soil and year a daily series, log10 of the suction a seasonal cycle (wet in winter, dry
  in summer) plus a first-order autoregressive noise, shifted down in the wet year and up in the dry year
  (a stand-in for a soil-water model driven by a weather record; the shape, not the numbers, of a central
  European year: ASSUMED);
- **calendars**: the three seasons of :mod:`symtrack.studies.traffic_seasons` (Kroulik et al. 2009's three
  systems), each operation given a window of days of a winter cereal's year in central Europe (ASSUMED:
  typical dates, no source read) and, for the tillage operations, the depth they loosen to (ASSUMED: typical
  depths of the implements).
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np

from ..foundations.config import to_toml
from ..foundations.files import atomic_write_text

__all__ = ["DEMO_NAME", "SYSTEMS", "generate_fields", "suction_series", "write_region"]

DEMO_NAME = "region_demo"
CRS = "EPSG:32633"  # UTM 33N
FALSE_ORIGIN_M = (500_000.0, 5_500_000.0)

# The calendars (module doc). Days of the year: N spreading in March-April, spraying April-June, harvest
# mid-July to early August, stubble work and P, K in August, ploughing and seedbed in September, drilling in
# late September-October. Loosening depths: plough 0.25 m, chisel 0.18 m, short discs 0.08 m, seedbed 0.06 m.
_TRAM = {"machine": "sprayer_24m", "same_lines_as": "tramlines"}
SYSTEMS = {
    "conventional": [
        {"name": "N spreading", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2,
         "window": [70, 110]},
        {"name": "spraying", **_TRAM, "repeat": 3, "window": [100, 165]},
        {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]},
        {"name": "grain transport", "machine": "grain_trailer", "same_day_as": "harvest"},
        {"name": "stubble discing", "machine": "disc_6m", "window": [222, 240], "loosens_to_m": 0.08},
        {"name": "P, K spreading", "machine": "spreader_24m", "window": [230, 250]},
        {"name": "ploughing", "machine": "plough", "window": [245, 268], "loosens_to_m": 0.25,
         "random_offset_m": 0.1},
        {"name": "seedbed preparation", "machine": "seedbed_6m", "window": [262, 280], "loosens_to_m": 0.06},
        {"name": "drilling", "machine": "drill_4m", "window": [268, 292]},
    ],
    "minimum": [
        {"name": "N spreading", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2,
         "window": [70, 110]},
        {"name": "spraying", **_TRAM, "repeat": 3, "window": [100, 165]},
        {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]},
        {"name": "grain transport", "machine": "grain_trailer", "same_day_as": "harvest"},
        {"name": "stubble discing", "machine": "disc_6m", "window": [222, 240], "loosens_to_m": 0.08},
        {"name": "P, K spreading", "machine": "spreader_24m", "window": [230, 250]},
        {"name": "chisel cultivation", "machine": "chisel_4m5", "window": [245, 270], "loosens_to_m": 0.18},
        {"name": "drilling", "machine": "drill_6m", "window": [265, 292]},
    ],
    "direct": [
        {"name": "N spreading", "machine": "spreader_24m", "same_lines_as": "tramlines", "repeat": 2,
         "window": [70, 110]},
        {"name": "spraying", **_TRAM, "repeat": 2, "window": [100, 165]},
        {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]},
        {"name": "grain transport", "machine": "grain_trailer", "same_day_as": "harvest"},
        {"name": "glyphosate spraying", "machine": "sprayer_24m", "window": [225, 245]},
        {"name": "P, K spreading", "machine": "spreader_24m", "window": [230, 250]},
        {"name": "direct drilling", "machine": "drill_6m", "window": [262, 292]},
    ],
}
# the two soils: a loess silt loam and a clay loam (ASSUMED: typical textures and an initial density of
# 1.40 Mg/m^3), over presets of the package for what the fast fidelity does not use (Bekker's and Janosi's
# parameters) and for the stress concentration factor (5 and 6). Over the demo's suctions (pF 1.0-3.4) both are
# inside Schjønning & Lamandé's (2018) range, where their strength grows with the suction
# Each has a denser subsoil below the plough's 0.3 m (1.55 Mg/m^3, ASSUMED: a typical plough-pan subsoil), with
# its own texture and strength, and the topsoil's suction of the day
SOILS = {"silt_loam": {"preset": "sandy_loam_15", "clay_kg_per_kg": 0.18, "silt_kg_per_kg": 0.62,
                       "sand_kg_per_kg": 0.20, "bulk_density_initial_Mg_per_m3": 1.40, "subsoil_top_m": 0.3,
                       "subsoil_bulk_density_initial_Mg_per_m3": 1.55},
         "clay_loam": {"preset": "north_gower_clayey_loam_46", "clay_kg_per_kg": 0.32, "silt_kg_per_kg": 0.40,
                       "sand_kg_per_kg": 0.28, "bulk_density_initial_Mg_per_m3": 1.40, "subsoil_top_m": 0.3,
                       "subsoil_bulk_density_initial_Mg_per_m3": 1.55}}
# the years: one wet (the suction pF 0.4 lower all year) and one dry (pF 0.3 higher)
YEARS = {2021: -0.4, 2022: 0.3}


def generate_fields(n_fields: int, seed: int = 1, spacing_m: float = 420.0, length_m=(180.0, 320.0),
                    width_m=(100.0, 200.0), soils=tuple(SOILS), systems=tuple(SYSTEMS)) -> dict:
    """A GeoJSON FeatureCollection of ``n_fields`` generated fields (module doc)."""
    rng = np.random.default_rng(seed)
    side = int(math.ceil(math.sqrt(n_fields)))
    feats = []
    for i in range(n_fields):
        L = rng.uniform(*length_m)
        W = rng.uniform(*width_m)
        jitter = 0.1 * min(L, W)
        corners = np.array([[-L / 2, -W / 2], [L / 2, -W / 2], [L / 2, W / 2], [-L / 2, W / 2]])
        corners = corners + rng.uniform(-jitter, jitter, corners.shape)
        a = rng.uniform(-math.pi / 2, math.pi / 2)
        c, s = math.cos(a), math.sin(a)
        rot = corners @ np.array([[c, s], [-s, c]])
        cx = FALSE_ORIGIN_M[0] + (i % side) * spacing_m
        cy = FALSE_ORIGIN_M[1] + (i // side) * spacing_m
        ring = [[round(cx + x, 3), round(cy + y, 3)] for x, y in rot]
        ring.append(ring[0])
        feats.append({"type": "Feature",
                      "properties": {"field_id": f"F{i + 1:03d}", "soil": soils[int(rng.integers(len(soils)))],
                                     "system": systems[i % len(systems)]},
                      "geometry": {"type": "Polygon", "coordinates": [ring]}})
    return {"type": "FeatureCollection", "name": "fields", "features": feats}


def suction_series(year: int, shift_pF: float, seed: int, clayey: bool) -> list[tuple[str, float]]:
    """(ISO date, matric suction kPa) for every day of ``year`` (module doc)."""
    rng = np.random.default_rng(seed)
    n = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days
    doy = np.arange(1, n + 1)
    mean = 2.2 + (0.1 if clayey else 0.0) + shift_pF
    cycle = 0.8 * np.sin(2 * math.pi * (doy - 110) / n)  # driest in late July, wettest in late January
    noise = np.zeros(n)
    for k in range(1, n):
        noise[k] = 0.85 * noise[k - 1] + rng.normal(0.0, 0.12)
    pf = np.clip(mean + cycle + noise, 1.0, 3.4)
    kpa = 0.1 * 10.0 ** pf
    return [((dt.date(year, 1, 1) + dt.timedelta(days=int(d) - 1)).isoformat(), float(round(v, 4)))
            for d, v in zip(doy, kpa, strict=True)]


def soil_units(fields: dict, soils=tuple(SOILS)) -> dict:
    """A GeoJSON FeatureCollection of two soil units (a generated soil map: docs/region.md, "A soil map"): the
    fields' extent (100 m around them) cut by a north-south line midway between its west and east edges, the
    first soil west of it, the second east of it (property ``soil``)."""
    pts = [p for f in fields["features"] for p in f["geometry"]["coordinates"][0]]
    x0, y0 = min(p[0] for p in pts) - 100.0, min(p[1] for p in pts) - 100.0
    x1, y1 = max(p[0] for p in pts) + 100.0, max(p[1] for p in pts) + 100.0
    xm = round(0.5 * (x0 + x1), 3)

    def unit(k, a, b):
        ring = [[a, y0], [b, y0], [b, y1], [a, y1], [a, y0]]
        return {"type": "Feature", "id": f"U{k + 1}", "properties": {"soil": soils[k]},
                "geometry": {"type": "Polygon", "coordinates": [ring]}}

    return {"type": "FeatureCollection", "name": "soil_units", "features": [unit(0, x0, xm), unit(1, xm, x1)]}


def write_region(folder, n_fields: int = 36, seed: int = 1, name: str = DEMO_NAME, years=None, cell_m: float = 0.5,
                 systems=None, soil_map: bool = False, **field_kw) -> Path:
    """Write a generated region into ``folder`` (fields.geojson, one suction CSV per soil, region.toml);
    returns the region file. ``soil_map``: the fields' soils from a generated soil map (soil_units.geojson,
    :func:`soil_units`; the fields without a soil of their own) instead of drawn per field."""
    folder = Path(folder)
    years = dict(YEARS) if years is None else dict(years)
    systems = SYSTEMS if systems is None else systems
    fields = generate_fields(n_fields, seed, systems=tuple(systems), **field_kw)
    if soil_map:
        for f in fields["features"]:
            del f["properties"]["soil"]
        atomic_write_text(folder / "soil_units.geojson", json.dumps(soil_units(fields), indent=1) + "\n")
    atomic_write_text(folder / "fields.geojson", json.dumps(fields, indent=1) + "\n")
    soils = {}
    for k, (sname, desc) in enumerate(SOILS.items()):
        rows = ["date,matric_suction_kPa"]
        for j, (y, shift) in enumerate(sorted(years.items())):
            rows += [f"{d},{v!r}" for d, v in suction_series(y, shift, seed * 1000 + 10 * k + j, "clay" in sname)]
        atomic_write_text(folder / f"suction_{sname}.csv", "\n".join(rows) + "\n")
        soils[sname] = {**desc, "suction_file": f"suction_{sname}.csv"}
    doc = {"schema_version": 1, "name": name,
           "description": f"{n_fields} generated fields, two soils, years {', '.join(map(str, sorted(years)))}, "
                          f"{len(systems)} tillage systems",
           "fields_file": "fields.geojson", "crs": CRS, "fleet": "builtin", "years": sorted(years), "seed": seed,
           "cell_m": cell_m, "map_cell_m": max(1.0, cell_m), "soils": soils,
           **({"soil_map": {"file": "soil_units.geojson", "attribute": "soil"}} if soil_map else {}),
           "systems": {k: {"operations": v} for k, v in systems.items()}}
    path = folder / f"{name}.toml"
    atomic_write_text(path, "# a generated region (symtrack/region/demo.py): not measured data\n" + to_toml(doc))
    return path
