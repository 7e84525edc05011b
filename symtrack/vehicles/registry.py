"""The vehicle-model menu: one registry of vehicle models (as the integrators have theirs).

A vehicle model is an object with

- ``name``: its registry name (``SystemModel(vehicle=...)`` takes it); optionally ``lateral_laws``:
  the lateral laws whose states it carries (:func:`for_options` picks it for them);
- ``layout``: its :class:`~symtrack.model.layout.StateLayout` (its own states only, in blocks;
  ``state_names`` the same names in order); ``input_names``, ``alg_names``: its inputs and the
  algebraic variables of the DAE form (the accelerations of the load-transfer loop, closed by
  ``acc_implied``); ``tracks``: the names of its tracks (the terrain's signals are per track);
- ``equations(xv, u, acc, P, compaction_N, opts, track_soil=None) -> dict`` with ``xdot`` (as
  many rows as its states), ``acc_implied`` (as many as ``alg_names``), ``dist`` (track ->
  :class:`~symtrack.vehicles.planar.PressureDistribution`: what the terrain's cells carry),
  ``signals`` (named outputs) and ``yaw_moment_N_m`` (:func:`symtrack.vehicles.planar.vehicle_equations`
  documents the arguments);
- ``contact_pose(xv) -> ContactPose``: the pose handed to the terrain's geometry.

The vehicle and soil parameters are the project's (:data:`symtrack.model.PARAM_NAMES`).

Adding a vehicle model is one module and one :func:`register` call::

    register(MyVehicle())           # then SystemModel(opts, terrain, vehicle="my_vehicle")
"""

from __future__ import annotations

from ..foundations.errors import ParameterError
from ..foundations.registry import Registry
from .planar import PlanarLateralVehicle, PlanarVehicle

__all__ = ["DEFAULT_VEHICLE", "REGISTRY", "for_options", "get", "names", "register", "unregister"]

DEFAULT_VEHICLE = "planar"
_REQUIRED = ("name", "layout", "state_names", "input_names", "alg_names", "tracks", "equations", "contact_pose")

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
    return _MENU.add(vehicle.name, vehicle, replace)


unregister = _MENU.remove
names = _MENU.names


def get(vehicle=None):
    """The vehicle model ``vehicle`` names (or ``vehicle`` itself when it is a model; None: the
    default, planar); an unknown name is a :class:`ParameterError` listing the menu."""
    if vehicle is None:
        vehicle = DEFAULT_VEHICLE
    return _MENU.get(vehicle) if isinstance(vehicle, str) else vehicle


def for_options(opts, vehicle=None):
    """The vehicle model for model options ``opts`` when ``vehicle`` is None: the first registered
    model that declares ``opts.lateral_law`` among its ``lateral_laws`` (the laws whose states it
    carries: ``"planar_lateral"`` for ``"shear"``), else the default; else :func:`get`
    (``vehicle``)."""
    if vehicle is None and opts is not None:
        for model in REGISTRY.values():
            if opts.lateral_law in getattr(model, "lateral_laws", ()):
                return model
    return get(vehicle)


register(PlanarVehicle())
register(PlanarLateralVehicle())
