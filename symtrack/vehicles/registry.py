"""The vehicle-model menu: one registry of vehicle models (as the integrators have theirs);
``[model] vehicle`` (:class:`~symtrack.model.options.ModelOptions`) names an entry.

A vehicle model is an object with

- ``name``: its registry name (``SystemModel(vehicle=...)`` and ``model.vehicle`` take it);
- ``layout``: its :class:`~symtrack.model.layout.StateLayout` (its own states only, in blocks;
  ``state_names`` the same names in order); ``input_names``, ``alg_names``: its inputs and the
  algebraic variables of the DAE form (the accelerations of the load-transfer loop, closed by
  ``acc_implied``); ``tracks``: the names of its tracks (the terrain's signals are per track);
- ``equations(xv, u, acc, P, compaction_N, opts, track_soil=None) -> dict`` with ``xdot`` (as
  many rows as its states), ``acc_implied`` (as many as ``alg_names``), ``dist`` (track ->
  :class:`~symtrack.vehicles.planar.PressureDistribution`: what the terrain's cells carry),
  ``signals`` (named outputs) and ``yaw_moment_N_m`` (:func:`symtrack.vehicles.planar.vehicle_equations`
  documents the arguments);
- ``contact_pose(xv) -> ContactPose``: the pose handed to the terrain's geometry;
- its capabilities (:class:`~symtrack.vehicles.base.VehicleModel`, whose defaults a subclass
  inherits): its contact kind, the plants and integrators it runs on, whether the standalone engine
  carries it, the hull states the MPC's prediction may take quasi-static, its figures, the
  parameters it reads, and :meth:`~symtrack.vehicles.base.VehicleModel.for_options`, the model for a
  run's options and ground.

A vehicle declares its parameters (``params``, ``soil_params``:
:class:`~symtrack.foundations.params.ParamSpec`); the model's parameter set adds the soil law's and the
soil's (:func:`symtrack.model.parameters.model_params`). The terrain engine reads the states it needs
by name (its C offsets come from the vehicle's layout).

Adding a vehicle model is one module and one :func:`register` call::

    register(MyVehicle())           # then [model] vehicle = "my_vehicle"
"""

from __future__ import annotations

from ..foundations.errors import ParameterError
from ..foundations.registry import Registry
from .base import CONTACTS, PLANT_WORDS, PLANTS
from .planar import PlanarLateralVehicle, PlanarVehicle
from .vehicle3d import Vehicle3D

__all__ = ["DEFAULT_VEHICLE", "REGISTRY", "check_plant", "for_options", "get", "names", "register", "unregister"]

DEFAULT_VEHICLE = "planar"
_REQUIRED = ("name", "layout", "state_names", "input_names", "alg_names", "tracks", "equations", "contact_pose",
             "contact", "plants", "integrators", "standalone_engine", "hull_states", "figures", "params",
             "soil_params", "param_names", "for_options", "check_ground", "check_start", "check_grid")

_MENU: Registry = Registry("a vehicle model", "vehicle", ParameterError)
REGISTRY = _MENU.entries


def register(vehicle, replace: bool = False):
    """Add a vehicle model to the menu; returns it."""
    missing = [a for a in _REQUIRED if not hasattr(vehicle, a)]
    if missing:
        raise ValueError(f"vehicle model {getattr(vehicle, 'name', vehicle)!r} lacks {', '.join(missing)}")
    if tuple(vehicle.layout.names) != tuple(vehicle.state_names) or vehicle.layout.n_cells:
        raise ValueError(f"vehicle model {vehicle.name!r}: its layout must hold its state_names, in order, "
                         "and no terrain cells")
    if vehicle.contact not in CONTACTS or not set(vehicle.plants) <= set(PLANTS) or not vehicle.plants:
        raise ValueError(f"vehicle model {vehicle.name!r}: contact {vehicle.contact!r} must be one of "
                         f"{', '.join(CONTACTS)} and plants {sorted(vehicle.plants)} some of {', '.join(PLANTS)}")
    missing = [n for n in vehicle.hull_states if n not in vehicle.state_names]
    if missing:
        raise ValueError(f"vehicle model {vehicle.name!r}: hull_states {missing} are not among its states")
    return _MENU.add(vehicle.name, vehicle, replace)


unregister = _MENU.remove
names = _MENU.names


def get(vehicle=None, where: str = "model.vehicle"):
    """The vehicle model ``vehicle`` names (or ``vehicle`` itself when it is a model; None: the
    default, planar); an unknown name is a :class:`ParameterError` naming ``where``, the value and
    the menu."""
    if vehicle is None:
        vehicle = DEFAULT_VEHICLE
    return _MENU.get(vehicle, where) if isinstance(vehicle, str) else vehicle


def for_options(opts, vehicle=None, surface=None):
    """The vehicle model of a run: ``vehicle`` when it is a model; else the entry ``vehicle`` names
    (None: the one ``opts.vehicle`` names, the default for no options) for ``opts`` and the ground
    ``surface`` (:meth:`~symtrack.vehicles.base.VehicleModel.for_options`: the "shear" law's variant
    with the lateral shear states, a hull on its ground)."""
    if vehicle is not None and not isinstance(vehicle, str):
        return vehicle
    entry = get(vehicle if vehicle is not None else getattr(opts, "vehicle", None))
    return entry if opts is None else entry.for_options(opts, surface)


def check_plant(vehicle, plant: str, integrator: str | None = None) -> None:
    """A :class:`ParameterError` naming ``model.vehicle``, its value and what it runs on unless the
    vehicle model ``vehicle`` runs on ``plant`` (of :data:`~symtrack.vehicles.base.PLANTS`) with
    ``integrator`` (None: not asked), naming the vehicles that do."""
    name = vehicle.entry_name
    if plant not in vehicle.plants:
        others = [n for n, v in REGISTRY.items() if plant in v.plants]
        raise ParameterError(
            f"model.vehicle = {name!r} runs on {' or on '.join(PLANT_WORDS[p] for p in PLANTS if p in vehicle.plants)}"
            f" only; this run asks for {PLANT_WORDS[plant]}"
            + ("; use run.integrator = 'grid_fast'" if plant == "grid" and "engine" in vehicle.plants else "")
            + f", or model.vehicle = one of {', '.join(others)}")
    allowed = vehicle.integrators
    if integrator is not None and allowed is not None and integrator not in allowed:
        raise ParameterError(f"run.integrator = {integrator!r}: model.vehicle = {name!r} runs on "
                             f"{', '.join(sorted(allowed))} only")


register(PlanarVehicle(lateral=PlanarLateralVehicle()))
register(Vehicle3D())
