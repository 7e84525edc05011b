"""The persistent grid terrain: Bekker cells simulated through a fixed pool of channels.

The model: docs/model.md; user documentation in docs/terrain.md. This layer knows no
integrator: the world manager is driven by a plant of :mod:`symtrack.simulation.plants`.

- :mod:`.settings`: the ``[terrain]`` scenario section (:class:`TerrainSettings`);
- :mod:`.storage`: :class:`Grid`, :class:`Terrain` (the cell storage Cell[N, N]) and terrain files;
- :mod:`.channels`: :class:`ChannelTerrain`, the symbolic part (a fixed number of channels,
  each one copy of the cell equations of :mod:`symtrack.model.cell`);
- :mod:`.surface`: :class:`Surface`, the ground's shape (``[terrain.surface]``: slopes, furrows, an
  elevation raster), the initial elevation z0 in numpy and CasADi;
- :mod:`.query`: the terrain query (the ground's height z0 - sinkage, gradient and normal under points);
- :mod:`.world`: :class:`World`, the world manager (footprint, sector rule, INFO_IN / INFO_OUT).
"""

from .settings import TerrainSettings
from .storage import Grid, Terrain
from .surface import Surface

__all__ = ["Grid", "Surface", "Terrain", "TerrainSettings"]
