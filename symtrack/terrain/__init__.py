"""The persistent grid terrain: Bekker cells simulated through a fixed pool of channels.

The model: docs/model.md; user documentation in docs/terrain.md. This layer knows no
integrator: the world manager is driven by a plant of :mod:`symtrack.simulation.plants`.

- :mod:`.settings`: the ``[terrain]`` scenario section (:class:`TerrainSettings`);
- :mod:`.storage`: :class:`Grid`, :class:`Terrain` (the cell storage Cell[N, N]) and terrain files;
- :mod:`.channels`: :class:`ChannelTerrain`, the symbolic part (a fixed number of channels,
  each one copy of the cell equations of :mod:`symtrack.soil.cell`);
- :mod:`.surface`: :class:`Surface`, the ground's shape (``[terrain.surface]``: slopes, furrows, an
  elevation raster), the initial elevation z0 in numpy and CasADi;
- :mod:`.query`: the terrain query (the ground's height z0 - sinkage, gradient and normal under points);
- :mod:`.world`: :class:`World`, the world manager (footprint, sector rule, INFO_IN / INFO_OUT);
- :mod:`.soil_map`: a field of several soils, the per-cell soil index (``[terrain.soil_map]``);
- :mod:`.fieldfile`: the raw ``.field`` file that C reads; :mod:`.gis`: GIS rasters in and out.

The field holds cells; what their soil does under load is :mod:`symtrack.soil`'s, the machines that
cross it are :mod:`symtrack.vehicles`'.
"""

from __future__ import annotations

from ..foundations.lazy import lazy_getattr

__all__ = ["Grid", "Surface", "Terrain", "TerrainSettings"]

# imported on first use, so that a module of a room below (a vehicle, a soil law) may import one module of
# this package without running the whole of it
__getattr__ = lazy_getattr(__name__, {"Grid": "storage", "Surface": "surface", "Terrain": "storage",
                                      "TerrainSettings": "settings"}, globals())
