"""What a vehicle model declares besides its equations: its capabilities, read by the rest of the
package instead of its name (:mod:`symtrack.vehicles.registry` lists the whole interface).

- :attr:`VehicleModel.contact`: how its tracks meet the ground. ``"cells"`` (:data:`CONTACT_CELLS`):
  a terrain's cells carry the tracks' pressure distribution (the homogeneous terrain's travelling
  cells, the grid's channels or the terrain engine's sums) and give back the compaction resistance;
  ``"hull"`` (:data:`CONTACT_HULL`): the vehicle's own contact, the hull's penetration into the
  ground's shape is the sinkage (the terrain is then a
  :class:`~symtrack.vehicles.vehicle3d.ContactTerrain`, or the engine's segment sums), so it drives
  on the ground's shape over homogeneous soil and starts settled on it;
- :attr:`VehicleModel.plants`: the terrains it runs on, of :data:`PLANTS`: ``"homogeneous"`` (CVODES,
  IDAS, the compiled Rosenbrock), ``"grid"`` (the grid's channel pool: IDAS and the grid Rosenbrock)
  and ``"engine"`` (the terrain engine, ``run.integrator = "grid_fast"``); :attr:`integrators`: the
  integrators it runs on (None: every one that integrates those plants);
- :attr:`VehicleModel.standalone_engine`: whether the standalone engine program and the engine FMU
  (symtrack codegen) carry it;
- :attr:`VehicleModel.hull_states`: the states of a hull that the MPC's prediction may take as
  quasi-static (``mpc.prediction_hull``; none: the prediction keeps every state);
- :attr:`VehicleModel.figures`: the run folder's figures of its own (:mod:`symtrack.reports.figures`
  names);
- :attr:`VehicleModel.params` and :attr:`VehicleModel.soil_params`: the declarations
  (:class:`~symtrack.foundations.params.ParamSpec`) of the parameters it brings: its own (the
  ``[vehicle]`` table) and the soil coefficients its equations read (the ``[soil]`` table); a
  model's parameter set is these, its soil law's and the soil's (:mod:`symtrack.model.parameters`).
  :attr:`VehicleModel.param_names`: their names;
- :meth:`VehicleModel.for_options`: the model for a run's options and ground (a variant with the
  lateral shear states, a hull on a surface); :meth:`check_ground`, :meth:`check_start` and
  :meth:`check_grid`: what it refuses of a run before anything is built
  (:func:`symtrack.vehicles.registry.check_plant`: what it runs on).
"""

from __future__ import annotations

__all__ = ["CONTACTS", "CONTACT_CELLS", "CONTACT_HULL", "PLANTS", "PLANT_WORDS", "VehicleModel"]

CONTACT_CELLS = "cells"
CONTACT_HULL = "hull"
CONTACTS = (CONTACT_CELLS, CONTACT_HULL)
PLANTS = ("homogeneous", "grid", "engine")
# each plant in a message
PLANT_WORDS = {"homogeneous": "the homogeneous terrain",
               "grid": "the grid's channel pool (IDAS, the grid Rosenbrock)",
               "engine": "the grid through the terrain engine (run.integrator = 'grid_fast')"}


class VehicleModel:
    """The capabilities of a vehicle model, their defaults those of a vehicle whose tracks load a
    terrain's cells (module doc). A vehicle model subclasses it (or sets the same attributes)."""

    contact: str = CONTACT_CELLS
    plants: frozenset = frozenset(PLANTS)
    integrators: frozenset | None = None
    standalone_engine: bool = False
    hull_states: tuple = ()
    figures: tuple = ()
    params: tuple = ()
    soil_params: tuple = ()
    surface = None  # the ground's shape a hull drives on (None: flat, or no hull)
    menu_name: str | None = None  # a variant's registry entry (for_options gave it; None: its own name)

    @property
    def param_names(self) -> tuple[str, ...]:
        """The names of the parameters it declares (:attr:`params`, then :attr:`soil_params`)."""
        return tuple(s.name for s in (*self.params, *self.soil_params))

    @property
    def entry_name(self) -> str:
        """The name ``model.vehicle`` gives this model's registry entry."""
        return self.menu_name or self.name

    def for_options(self, opts, surface=None):
        """The model for model options ``opts`` on the ground ``surface`` (this one)."""
        return self

    def check_ground(self, opts, surface, params: dict) -> None:
        """A :class:`ParameterError` naming the key when the model cannot resolve ``surface`` (none)."""

    def check_start(self, surface, params: dict, x_m: float, y_m: float) -> None:
        """A :class:`ParameterError` naming the key when it cannot start at (x, y) on ``surface`` (none)."""

    def check_grid(self, terrain) -> None:
        """A :class:`ParameterError` naming the key for what of the grid ``terrain`` (a
        :class:`~symtrack.terrain.settings.TerrainSettings`) it cannot take (none)."""
