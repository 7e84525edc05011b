"""symtrack: an agricultural tracked vehicle on soft soil that remembers every pass.

The public API (one import is enough in a notebook)::

    import symtrack
    sc = symtrack.load_scenario("validation", {"run.duration_s": 5.0})
    res = symtrack.simulate(sc)
    res.summary, res.column("x_m"), res.write("out/v")

- :func:`load_scenario`, :class:`Scenario`: built-in scenarios by name or TOML files, with
  overrides in the grammar of ``--set``;
- :func:`run`: any run file (a simulation, an MPC run, a field study, an operation, a season, a
  sweep; the kind told by its sections) -> that kind's result, as ``symtrack run FILE``;
- :func:`simulate` -> :class:`Result` (``summary``, ``column``, ``write``, ``terrain``);
- :func:`build` -> :class:`Built`: the explicit, cached build of a scenario's plant (``simulate``
  builds through it: a second run of the same model costs its time loop);
- :class:`Terrain`: the grid terrain's cell storage (``load``, ``save``, the arrays);
  :func:`export_terrain` its layers as GeoTIFF and NetCDF (the extra ``symtrack[gis]``);
- :class:`SystemModel`: the symbolic model (named CasADi Functions);
- :mod:`symtrack.control`: trim, linearize, the MPC and the closed loop.

The names are imported on first use, so that ``symtrack --help`` stays fast.
"""

from __future__ import annotations

from .foundations.lazy import lazy_getattr
from .foundations.version import __version__

__all__ = ["Built", "Result", "Scenario", "SystemModel", "Terrain", "__version__", "build", "cache_info",
           "clear_caches", "control", "export_terrain", "load_scenario", "run", "simulate"]

__getattr__ = lazy_getattr(__name__, {
    "Result": "symtrack.api", "build": "symtrack.api", "Built": "symtrack.api", "simulate": "symtrack.api",
    "run": "symtrack.studies.runfile", "load_scenario": "symtrack.simulation.scenario",
    "Scenario": "symtrack.simulation.scenario", "Terrain": "symtrack.terrain.storage",
    "export_terrain": "symtrack.terrain.gis", "SystemModel": "symtrack.model.system",
    "clear_caches": "symtrack.foundations.caches", "cache_info": "symtrack.foundations.caches", "control": "",
}, globals())


def __dir__():
    return sorted(set(globals()) | set(__all__))
