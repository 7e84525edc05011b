"""The explicit, cached build of a run (as PyBaMM's ``Simulation.build``): what a scenario's
plant is made of, built once per process for what determines it and reused by every later run.

Building the homogeneous terrain's :class:`~symtrack.model.system.SystemModel` (its CasADi
expressions and Functions) and loading its generated library cost about 0.9 s, the time loop of
the validation scenario 0.04 s. The symbolic model depends only on its
:class:`~symtrack.model.options.ModelOptions` (the vehicle's and the soil's parameters are a
numeric vector handed to every call), and the generated library is cached per model object
(:func:`symtrack.native.cache.library`), so one model per set of options serves every run of a
process: a second ``symtrack.simulate`` of the same model costs its time loop, the integrator's
set-up and the start state.

What is *not* cached is what a run changes: the integrator's stepper (its counters, its
algebraic guess), the plant, and the grid terrain's world (its cell storage is the run's
result).

- :func:`build` -> :class:`Built`: the ingredients of a scenario's plant; :meth:`Built.plant`
  makes a fresh plant from them, :meth:`Built.run` runs the scenario on one (the one time loop,
  every pass of a terrain study) -> :class:`Outcome`;
- :func:`system_model`: the cached model of a set of model options;
- :func:`clear_build_cache`, :func:`build_cache_info`: empty and inspect the cache.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foundations import caches
from ..foundations.errors import ParameterError, ScenarioError
from ..integrators import registry
from ..integrators.settings import IntegratorSettings
from ..model import SystemModel
from ..model.options import ModelOptions
from ..terrain.storage import Terrain
from ..vehicles import registry as vehicle_registry
from . import loop
from .passes import PassStudy, run_passes, study_summary
from .plants import make_plant
from .result import summarise
from .scenario import Scenario, builtin_names, load_scenario

__all__ = ["MAX_MODELS", "MODELS", "Built", "Outcome", "build", "build_cache_info", "clear_build_cache", "system_model"]

# the most recently used models, at most MAX_MODELS (a sweep over model options does not keep them all;
# symtrack.foundations.caches, emptied by symtrack.clear_caches())
MAX_MODELS = 8
MODELS = caches.cache("models", MAX_MODELS)


def _raster_key(surface) -> str | None:
    """An elevation raster's identity for the model cache: its heights, pixel and origin (the table names
    only its file, which may be rewritten between two runs of one process)."""
    r = getattr(surface, "raster", None)
    if r is None:
        return None
    h = hashlib.sha256(np.ascontiguousarray(r.values).tobytes())
    h.update(repr((r.values.shape, r.pixel_m, r.origin_m)).encode())
    return h.hexdigest()


def system_model(opts: ModelOptions | None = None, surface=None) -> SystemModel:
    """The homogeneous terrain's model of ``opts`` (default options when None), built on the
    first call for these options and then shared (a SystemModel is not changed after its
    construction; its generated library is cached per model object). The :data:`MAX_MODELS` most
    recently used are kept. ``surface``: the ground's shape under a vehicle with a hull of its own
    (the 3D vehicle; keyed by its table)."""
    opts = ModelOptions() if opts is None else opts
    key = opts if surface is None else (opts, json.dumps(surface.to_dict(), sort_keys=True), _raster_key(surface))
    return MODELS.get_or_build(key, lambda: SystemModel(opts,
                                                        vehicle=vehicle_registry.for_options(opts, surface=surface)))


def clear_build_cache() -> None:
    """Forget every cached model (the next build builds them again; :func:`symtrack.clear_caches`
    empties every cache of the package)."""
    MODELS.clear()


def build_cache_info() -> dict:
    """``{"models": n, "hits": h, "misses": m}``: the cached models and the lookups so far."""
    i = MODELS.info()
    return {"models": i["entries"], "hits": i["hits"], "misses": i["misses"]}


@dataclass
class Outcome:
    """What :meth:`Built.run` computed.

    Attributes
    ----------
    runs : list of RunResult
        One per pass (one for the homogeneous terrain).
    summary : dict
        The run's summary.json (a terrain study's: the whole run's figures, each pass's in ``passes``).
    pass_summaries : list of dict
        The summary of each pass.
    study : PassStudy or None
        The passes over the grid terrain (None on the homogeneous terrain).
    failure : IncompleteRun or None
        The error that ended the run part of the way (what was computed up to there is kept).
    """

    runs: list
    summary: dict
    pass_summaries: list
    study: PassStudy | None = None
    failure: loop.IncompleteRun | None = None


@dataclass(frozen=True)
class Built:
    """The built ingredients of a scenario's plant (:func:`build`).

    Attributes
    ----------
    scenario : Scenario
        The scenario built for.
    kind : str
        "homogeneous" or "grid" (a ``[terrain]`` section, or a terrain to start from).
    settings : IntegratorSettings
        The integrator of ``run.integrator``, with the scenario's engine settings.
    spec : IntegratorSpec
        Its registry entry (looked up once per build: every plant of the build takes it).
    model : SystemModel or None
        The homogeneous terrain's model (shared, :func:`system_model`); None for the grid,
        whose world builds its model from its channels.
    """

    scenario: object
    kind: str
    settings: IntegratorSettings
    spec: registry.IntegratorSpec
    model: SystemModel | None

    @property
    def params(self) -> dict:
        """The scenario's parameter values (vehicle and soil, SI units, by name), as ``scenario.params``."""
        return self.scenario.params

    def __repr__(self) -> str:
        return (f"<Built {getattr(self.scenario, 'name', '?')!r}: {self.kind} terrain, integrator "
                f"{self.settings.method}, {len(self.params)} parameters (.params)>")

    def plant(self, terrain=None):
        """A fresh plant of the scenario (:func:`symtrack.simulation.plants.make_plant` on the
        built model): a new stepper, and for the grid a new world (on ``terrain``, a
        :class:`~symtrack.terrain.storage.Terrain` or terrain file, if given)."""
        return make_plant(self.scenario, terrain=terrain, model=self.model, spec=self.spec)

    def run(self, terrain=None, progress: bool | None = False, record_every_s: float | None = None) -> Outcome:
        """Run the scenario on a fresh plant (:meth:`plant`): the one time loop
        (:func:`symtrack.simulation.loop.run`) until its stop rule, on the grid terrain every
        pass (:func:`~symtrack.simulation.passes.run_passes`, the grid plant keeping a snapshot
        every ``record_every_s``). A run that fails part of the way is returned with its
        ``failure`` (not raised)."""
        plant = self.plant(terrain)
        if plant.kind == "grid":
            plant.record_every_s = record_every_s
            failure = None
            try:
                study = run_passes(self.scenario, plant, progress=progress)
            except loop.IncompleteRun as err:
                study, failure = err.study, err
            summary, per_pass = study_summary(study)
            if terrain is not None and not isinstance(terrain, Terrain):
                summary["terrain_in"] = str(terrain)
            return Outcome(study.runs, summary, per_pass, study, failure)
        failure = None
        try:
            res = loop.run(self.scenario, plant, progress=progress)
        except loop.IncompleteRun as err:
            res, failure = err.partial, err
        summary = summarise(res)
        return Outcome([res], summary, [summary], None, failure)


def _grid_names() -> list[str]:
    return [n for n in builtin_names() if load_scenario(n).terrain is not None]


def build(scenario, *, integrator: str | None = None, terrain=None) -> Built:
    """Build what a scenario's plant is made of, explicitly (module doc: the model is built once per
    process for its options, so a second build of the same model options costs nothing;
    :func:`symtrack.simulate` builds through here). ``symtrack.build`` is this function.

    Parameters
    ----------
    scenario : Scenario or str
        A loaded scenario, or a built-in name / TOML path (loaded with no overrides).
    integrator : str, optional
        Instead of the scenario's ``run.integrator`` (a name of the integrator registry).
    terrain : Terrain or path, optional
        A grid terrain the run will start from (the plant is then the grid's); the scenario needs
        a ``[terrain]`` section.

    Returns
    -------
    Built
        ``Built.scenario`` is the scenario as run; ``symtrack.simulate(built)`` runs it.
    """
    if isinstance(terrain, str | Path) and not Path(terrain).is_file():  # named as typed (as --terrain-in)
        what = "is a folder" if Path(terrain).is_dir() else "does not exist"
        raise ScenarioError(f"terrain = {str(terrain)!r} {what}: give a terrain file (the .npz that "
                            "Result.write(..., terrain_out=...) or symtrack simulate --terrain-out writes) "
                            "or a Terrain")
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if integrator is not None:
        if not isinstance(integrator, str):
            raise ScenarioError(f"integrator = {integrator!r} must be a name: {', '.join(registry.names())}")
        scenario = dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, integrator=integrator))
    if terrain is not None and scenario.terrain is None:
        raise ScenarioError(f"scenario {scenario.name!r} has no [terrain] section, so it runs on the homogeneous "
                            f"terrain and cannot start from a terrain file; the grid scenarios are "
                            f"{', '.join(_grid_names())} (or add a [terrain] section)")
    settings = dataclasses.replace(scenario.run.integrator_settings(), engine=getattr(scenario, "engine", None))
    spec = registry.get(settings.method, "integrator")
    surface = getattr(scenario, "surface", None)
    vehicle = vehicle_registry.for_options(scenario.model, surface=surface)
    if scenario.terrain is not None or terrain is not None:
        vehicle_registry.check_plant(vehicle, "engine" if spec.grid_engine is not None else "grid", settings.method)
        return Built(scenario, "grid", settings, spec, None)
    try:
        vehicle_registry.check_plant(vehicle, "homogeneous", settings.method)
        vehicle.check_ground(scenario.model, surface, scenario.params)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    model = system_model(scenario.model, surface)
    return Built(scenario, "homogeneous", settings, spec, model)
