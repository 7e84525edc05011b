"""The persistent grid terrain: Bekker cells simulated through a fixed pool of channels.

MODEL.md sections 2 and 3; user documentation in docs/terrain.md.

- :mod:`.channels`: :class:`ChannelTerrain`, the symbolic part (a fixed number of channels,
  each one copy of the cell equations of :mod:`symtrack.model.cell`);
- :mod:`.world`: :class:`World`, the numpy cell storage Cell[N, N] and the world manager;
- :mod:`.config`: the ``[terrain]`` scenario section;
- :mod:`.persist`: terrain files (save / load);
- :mod:`.study`: running scenarios on the grid terrain (passes, summaries, plots);
- :mod:`.bench`: the benchmark.

This package is kept light on import: :mod:`symtrack.scenario` imports :mod:`.config` to
register the ``[terrain]`` section.
"""
