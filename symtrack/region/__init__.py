"""A region study: many fields, season after season, on a Dask cluster, from the machines' planned paths
to compaction maps (docs/region.md).

- :mod:`symtrack.region.inputs`: the region file, the fields (GeoJSON), the soils and their daily suction,
  the calendars, all checked before any work;
- :mod:`symtrack.region.soilmap`: the fields' soils from a soil map (polygons or a raster of codes);
- :mod:`symtrack.region.fleet`: the machines (wheels or tracks, each number with its source) and their
  stress profiles, built once per machine and soil;
- :mod:`symtrack.region.fast`: the fast fidelity, a field's season as its planned paths swept by the
  machines' quasi-static footprints;
- :mod:`symtrack.region.full`: the full fidelity, a field's season with each plan driven over the field's
  terrain (the terrain engine for tracks, the wheeled pass for wheels), on the fields a mixed run chooses;
- :mod:`symtrack.region.study`: the study on Dask (a task per field and season, resumable);
- :mod:`symtrack.region.outputs`: the region's GeoTIFFs, the per-field table and the report, committed once;
  :mod:`symtrack.region.table` the table's columns, :mod:`symtrack.region.gpkg` the table as a GeoPackage;
- :mod:`symtrack.region.demo`: a generated region (``region_demo``);
- :mod:`symtrack.region.check`: the fast fidelity against the full one (``symtrack bench region``).
"""

from __future__ import annotations

from .inputs import RegionSpec, load_region

__all__ = ["RegionSpec", "load_region"]
