"""Scenarios: TOML files validated on load.

Schema (every key optional unless marked required; unknown keys are errors)::

    name = "validation"            # defaults to the file name
    description = "..."
    [run]
    duration_s = 30.0              # (0, 1e6]      simulated time limit
    output_dt_s = 0.01             # [duration / 1e6, duration] output (and macro) step (at most 1e6 steps)
    integrator = "cvodes"          # a name of symtrack.integrators.registry: cvodes | idas | rosenbrock
    fixed_step_s = 0.01            # [1e-5, 0.1] rosenbrock: each output step is split into equal steps <= this
    fixed_step_tolerance = 1e-3    # [0, 0.1] rosenbrock: a step whose error estimate exceeds it is halved (0: off)
    compiled = false               # cvodes/idas on the compiled dynamics and Jacobian (docs/codegen.md)
    reltol = 1e-7                  # (0, 1e-2]
    abstol = 1e-9                  # (0, 1e-2]
    stop_after_distance_m = 20.0   # (0, 1e6] or "none": stop once the CG has covered this path length ...
    stop_distance_event = "idle"   # ... counted from this [[torque]] event (default: from t = 0)
    all_figures = false            # true: also the slow figures (pass animations, earlier passes' plots)
    figures = true                 # false: the run folder without its figures (a sweep's many runs)
    [model]                        # numerical/structural options, see symtrack.model.ModelOptions
    traction_sign = "smooth"       # smooth | tanh | sign
    tanh_steepness_per_m = 1000.0
    [vehicle]
    preset = "reference_crawler"   # required: a built-in preset (symtrack presets) or a preset file
                                   # "my_crawler.toml" (symtrack/presets/catalog.py); any vehicle
                                   # parameter may follow as an override
    [soil]
    preset = "clayey_soil_thailand_38"   # required; any soil parameter may follow
    [start]
    x_m = 0.0
    y_m = 0.0
    yaw_deg = 0.0                  # [-360, 360]
    [[torque]]                     # required, at least one; held piecewise constant
    t_s = 0.0                      # the first entry at 0, then strictly increasing
    left_N_m = 2000.0              # [-1e6, 1e6]
    right_N_m = 2000.0
    event = "idle"                 # optional name, unique
    [terrain]                      # optional: the persistent grid terrain (symtrack.terrain.settings)
    [engine]                       # optional: the terrain engine's scheme (run.integrator = "grid_fast"):
    vehicle_substeps = 1           # [1, 64]   (symtrack.integrators.settings.EngineSettings)
    cell_substeps = 1              # [1, 64]
    entry_substeps = 8             # [1, 256]
    exit_substeps = 8              # [1, 256]
    steady_method = "euler"        # or "sdirk2": the cells outside the windows
    entry_fraction = 0.5           # [0, 1]
    ring_tolerance = 5e-3          # [0, 1]: a ringing cell takes an entry window (0: never)
    power = "step_mean"            # or "instantaneous"

Loading (:func:`load_scenario`) reads the document once (:func:`symtrack.foundations.config.read_document`:
a built-in name of ``symtrack/simulation/scenarios/`` or a TOML path, then the overrides) and
checks every section here; the MPC scenarios of :mod:`symtrack.control.scenario` share the
loader, the ``[run]``, ``[vehicle]``, ``[soil]`` and ``[terrain]`` parsers.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..foundations.config import Key, check_document, check_keys, number, read_document
from ..foundations.config import builtin_names as _package_names
from ..foundations.errors import ParameterError, ScenarioError
from ..integrators import registry
from ..integrators.settings import FIXED_STEP_TOLERANCE, EngineSettings, IntegratorSettings
from ..model import plausibility
from ..model.options import BUILD_FLAGS, ModelOptions, scenario_keys
from ..model.parameters import ParamSet, check_set, known_soil_names, soil_params, vehicle_params
from ..presets import soil_preset, vehicle_preset
from ..presets.catalog import read_preset_file
from ..soil import moisture
from ..terrain.settings import PATH_KEYS as TERRAIN_PATH_KEYS
from ..terrain.settings import TerrainSettings, settings_from_dict
from ..terrain.surface import Surface, parse_surface
from ..vehicles import registry as vehicle_registry
from ..vehicles import towed
from ..vehicles.base import CONTACT_HULL

__all__ = ["PlantSetup", "RunSettings", "Scenario", "Start", "TorqueEntry", "builtin_names", "load_scenario",
           "parse_params", "parse_ground", "parse_run", "parse_terrain", "scenario_from_dict"]

SCENARIO_PACKAGE = "symtrack.simulation.scenarios"
TOP_KEYS = ("name", "description", "run", "model", "vehicle", "soil", "start", "torque", "terrain", "engine")


@dataclass(frozen=True)
class TorqueEntry:
    """One entry of the torque programme: from ``t_s`` on, these sprocket torque commands."""

    t_s: float
    left_N_m: float
    right_N_m: float
    event: str | None = None


@dataclass(frozen=True)
class RunSettings:
    """The ``[run]`` section of every scenario kind (each kind accepts the fields it uses:
    :data:`SIMULATION_RUN_KEYS`, :data:`symtrack.control.scenario.MPC_RUN_KEYS`)."""

    duration_s: float = 30.0
    output_dt_s: float = 0.01
    integrator: str = "cvodes"
    reltol: float = 1e-7
    abstol: float = 1e-9
    stop_after_distance_m: float | None = None
    stop_distance_event: str | None = None
    fixed_step_s: float = 0.01
    compiled: bool = False
    rms_exclude_first_m: float = 0.0
    # the run folder's slow figures too: the pass animations (GIF) and, of several passes, the
    # earlier passes' trajectory plots and sinkage maps (docs/terrain.md, "What the outputs cost");
    # the default writes the figures read first, in about a tenth of the time
    all_figures: bool = False
    fixed_step_tolerance: float = FIXED_STEP_TOLERANCE
    # the run folder's figures at all: false writes its files without them (report.html says so), for the
    # many runs of a sweep, where drawing each run's figures took twice the simulation's own CPU
    figures: bool = True

    @property
    def macro_step_s(self) -> float:
        """The grid terrain's macro step [s]: the world manager's step (channels assigned, INFO_IN,
        the vehicle and the cells advanced, INFO_OUT) and the step whose travel sizes the channel
        pool (:func:`symtrack.terrain.world.derive_modulus`). It is the output step today (one
        output per macro step); its one home, so that the two can part without touching readers."""
        return self.output_dt_s

    def integrator_settings(self) -> IntegratorSettings:
        return IntegratorSettings(self.integrator, self.reltol, self.abstol, compiled=self.compiled,
                                  fixed_step_s=self.fixed_step_s, fixed_step_tolerance=self.fixed_step_tolerance)


@dataclass(frozen=True)
class PlantSetup:
    """What a run asks of the one plant factory (:func:`symtrack.simulation.plants.make_plant`) beyond
    its vehicle, soil, model options and start: a scenario's ``plant_setup(grid, terrain)``
    (:meth:`Scenario.plant_setup`; an MPC run's own, :meth:`symtrack.control.scenario.MPCScenario.plant_setup`)."""

    integrator: IntegratorSettings  # the plant's integrator (on the terrain it runs on)
    macro_step_s: float  # the grid's macro step (the world manager's step)
    terrain: TerrainSettings | None = None  # the grid's [terrain] section (None: its defaults)
    batch: bool = True  # a batch stepper advances many output intervals per call (False: one, a StepPlant)


SIMULATION_RUN_KEYS = ("duration_s", "output_dt_s", "integrator", "reltol", "abstol", "stop_after_distance_m",
                       "stop_distance_event", "fixed_step_s", "fixed_step_tolerance", "compiled", "all_figures",
                       "figures")

# the [run] keys as parse_run checks them (their defaults: RunSettings; docs/scenarios.md's table is made from both)
RUN_KEYS = {k.name: k for k in (
    Key("duration_s", "simulated time limit [s]", 0, 1e6, low_open=True),
    Key("output_dt_s", "output step [s]: one row of trajectory.csv per step (and the grid terrain's macro step)",
        allowed="(0, duration_s], at most 1e6 steps"),
    Key("integrator", "the integrator: cvodes, idas (variable step, no build), rosenbrock (compiled fixed step: "
        "a first build of about half a minute, cached), grid_fast (the terrain engine, with [terrain])",
        choices=registry.names()),
    Key("reltol", "relative tolerance of cvodes and idas", 0, 1e-2, low_open=True),
    Key("abstol", "absolute tolerance of cvodes and idas", 0, 1e-2, low_open=True),
    Key("stop_after_distance_m", "stop once the centre of gravity has covered this path length [m]; \"none\": no "
        "distance stop", 0, 1e6, low_open=True, allowed="(0, 1e6] or `\"none\"`"),
    Key("stop_distance_event", "count the stop distance from this [[torque]] event (default: from t = 0)",
        allowed="a [[torque]] event's name"),
    Key("fixed_step_s", "rosenbrock: each output step is split into equal steps of at most this [s]", 1e-5, 0.1),
    Key("fixed_step_tolerance", "rosenbrock: a step whose error estimate exceeds it is halved (0: no control)",
        0, 0.1),
    Key("compiled", "cvodes and idas on the compiled dynamics and Jacobian", choices=(True, False)),
    Key("all_figures", "also the slow figures of a terrain run (pass animations, earlier passes' plots)",
        choices=(True, False)),
    Key("figures", "false: the run folder without its figures (report.html says so; for a sweep's many runs)",
        choices=(True, False)),
    Key("rms_exclude_first_m", "(an MPC run's) the path length before the RMS tracking error is counted [m]", 0, 1e6),
)}


@dataclass(frozen=True)
class Start:
    """The start pose."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Scenario:
    """A simulation scenario, validated: run settings, model options, vehicle and soil parameters
    (preset plus overrides), start pose, torque programme and the optional grid terrain."""

    name: str
    description: str
    run: RunSettings
    model: ModelOptions
    vehicle_preset: str
    vehicle: dict
    soil_preset: str
    soil: dict
    start: Start
    torque: tuple[TorqueEntry, ...]
    terrain: TerrainSettings | None = None
    engine: EngineSettings | None = None  # the [engine] section (the terrain engine's scheme), if given
    # the ground's shape under the 3D vehicle on the homogeneous terrain (model.vehicle = "3d" with a
    # [terrain] section holding only [terrain.surface]; docs/vehicle3d.md)
    surface: Surface | None = None

    @property
    def params(self) -> dict:
        return {**self.vehicle, **self.soil}

    def plant_setup(self, grid: bool, terrain=None) -> PlantSetup:
        """The plant of this scenario (:class:`PlantSetup`): ``run.integrator`` with the ``[engine]``
        section, the macro step of ``run``, the ``[terrain]`` section."""
        return PlantSetup(dataclasses.replace(self.run.integrator_settings(), engine=self.engine),
                          self.run.macro_step_s, self.terrain)

    def event_time(self, name: str) -> float:
        for e in self.torque:
            if e.event == name:
                return e.t_s
        raise ScenarioError(f"no [[torque]] entry has event = {name!r}")

    def torque_at(self, t: float) -> tuple[float, float]:
        cur = self.torque[0]
        for e in self.torque:
            if e.t_s <= t + 1e-12:
                cur = e
        return cur.left_N_m, cur.right_N_m

    def to_dict(self) -> dict:
        run = {k: v for k, v in dataclasses.asdict(self.run).items() if v is not None and k in SIMULATION_RUN_KEYS}
        d = {"name": self.name, "description": self.description, "run": run,
             "model": {k: v for k, v in dataclasses.asdict(self.model).items() if k not in BUILD_FLAGS},
             "vehicle": {"preset": self.vehicle_preset, **self.vehicle},
             "soil": {"preset": self.soil_preset, **self.soil},
             "start": dataclasses.asdict(self.start),
             "torque": [{k: v for k, v in dataclasses.asdict(e).items() if v is not None} for e in self.torque]}
        if self.terrain is not None:
            d["terrain"] = self.terrain.to_dict()
        if self.surface is not None:
            d["terrain"] = {"surface": self.surface.to_dict()}
        if self.engine is not None:
            d["engine"] = dataclasses.asdict(self.engine)
        return d


# the most output steps a run may ask for (run.duration_s / run.output_dt_s): a run keeps each in memory
# (its states, torques and outputs, some 100 float64, and trajectory.csv's line of text, some 1.5 kB), so
# a million steps take a few GB; the built-in scenarios ask for at most 30 000
MAX_OUTPUT_STEPS = 1_000_000


def _num(section, key, value, low, high, low_open=False):
    return number(f"{section}.{key}", value, low, high, low_open)


def parse_run(t: dict, keys=SIMULATION_RUN_KEYS, defaults: RunSettings = RunSettings()) -> RunSettings:
    """A ``[run]`` table with the given keys allowed, on the given defaults."""
    check_keys("run", t, keys)
    d = defaults
    R = RUN_KEYS
    duration = R["duration_s"].check("run", t.get("duration_s", d.duration_s))
    out_dt = _num("run", "output_dt_s", t.get("output_dt_s", d.output_dt_s), 0, duration, True)
    if duration / out_dt > MAX_OUTPUT_STEPS:  # refused before any work: a run keeps every output step in memory
        raise ScenarioError(f"run.output_dt_s = {out_dt!r} s gives {duration / out_dt:.3g} output steps over "
                            f"run.duration_s = {duration:g} s, more than the {MAX_OUTPUT_STEPS} a run keeps in memory; "
                            f"the allowed range is [{duration / MAX_OUTPUT_STEPS:.3g}, {duration:g}] s (raise "
                            "run.output_dt_s or shorten run.duration_s)")
    integ = t.get("integrator", d.integrator)
    if not isinstance(integ, str):
        raise ScenarioError(f"run.integrator = {integ!r} is not one of {', '.join(registry.names())}")
    registry.get(integ)
    reltol = R["reltol"].check("run", t.get("reltol", d.reltol))
    abstol = R["abstol"].check("run", t.get("abstol", d.abstol))
    stop = t.get("stop_after_distance_m", d.stop_after_distance_m)
    ev = t.get("stop_distance_event", d.stop_distance_event)
    if isinstance(stop, str) and stop.lower() == "none":
        stop = ev = None  # the distance stop switched off (--set run.stop_after_distance_m=none)
    if stop is not None:
        stop = R["stop_after_distance_m"].check("run", stop)
    if ev is not None and not isinstance(ev, str):
        raise ScenarioError(f"run.stop_distance_event = {ev!r} must be the name of a [[torque]] event")
    if ev is not None and stop is None:
        raise ScenarioError("run.stop_distance_event is set but run.stop_after_distance_m is not")
    fixed = R["fixed_step_s"].check("run", t.get("fixed_step_s", d.fixed_step_s))
    fixed_tol = R["fixed_step_tolerance"].check("run", t.get("fixed_step_tolerance", d.fixed_step_tolerance))
    compiled = t.get("compiled", d.compiled)
    if not isinstance(compiled, bool):
        raise ScenarioError(f"run.compiled = {compiled!r} must be true or false")
    rms = R["rms_exclude_first_m"].check("run", t.get("rms_exclude_first_m", d.rms_exclude_first_m))
    all_figures = t.get("all_figures", d.all_figures)
    if not isinstance(all_figures, bool):
        raise ScenarioError(f"run.all_figures = {all_figures!r} must be true or false (true: also the pass "
                            "animations and the earlier passes' plots)")
    figs = t.get("figures", d.figures)
    if not isinstance(figs, bool):
        raise ScenarioError(f"run.figures = {figs!r} must be true or false (false: the run folder without its "
                            "figures)")
    if all_figures and not figs:
        raise ScenarioError("run.all_figures = true asks for the slow figures too, run.figures = false for none: "
                            "set one of them")
    return RunSettings(duration, out_dt, integ, reltol, abstol, stop, ev, fixed, compiled, rms, all_figures,
                       fixed_step_tolerance=fixed_tol, figures=figs)


def _parse_model(t: dict) -> ModelOptions:
    fields = scenario_keys()
    check_keys("model", t, fields)
    try:
        return ModelOptions(**t)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err


def parse_params(section, t, preset_fn, specs, default_preset=None, known=()):
    """A [vehicle] or [soil] table: preset (a built-in name or a user preset file ``*.toml``)
    plus overrides (of ``specs`` only), validated as a complete set of ``specs``; ``known``: keys the
    preset may carry that ``specs`` do not read (another soil law's coefficients: left out)."""
    names = [s.name for s in specs]
    check_keys(section, t, ["preset"] + names)
    preset = t.get("preset", default_preset)
    if not isinstance(preset, str):
        raise ScenarioError(f"{section}.preset is required (a preset name), got {preset!r}")
    try:
        if preset.endswith(".toml"):  # a user preset file (symtrack.presets.catalog)
            values, _, _ = read_preset_file(preset, section)
        else:
            values = preset_fn(preset)
        overrides = {k: v for k, v in t.items() if k != "preset"}
        values = check_set(ParamSet(values, derived=getattr(values, "derived", {})).with_given(overrides), specs,
                           section, known)
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    return preset, values


def parse_ground(t_doc, model, vehicle: dict, plant: str = "", engine: bool = False, start=None) -> tuple:
    """``(terrain, surface)`` of a scenario's ``[terrain]`` table (the simulation's and the MPC's
    loaders): under a vehicle with a hull of its own (the 3D vehicle, ``model.vehicle = "3d"``) a table
    holding only ``[terrain.surface]`` is homogeneous soil following that ground (docs/vehicle3d.md:
    ``(None, Surface)``, its contact checked against the vehicle); anything else is the grid terrain
    (``(TerrainSettings or None, None)``), refused for a vehicle model that cannot take it (``plant``:
    what in the message asked for the grid; ``engine``: the run's integrator is the terrain engine: then
    what the vehicle's grid path cannot take is refused, its ``check_grid``; ``start``: the start's
    (x, y), where an elevation raster under a hull on homogeneous soil must hold its footprint, its
    ``check_start``: :mod:`symtrack.vehicles.base`)."""
    vm = vehicle_registry.for_options(model)
    hull = vm.contact == CONTACT_HULL  # a hull of its own drives on the ground's shape
    hulls = [n for n, v in vehicle_registry.REGISTRY.items() if v.contact == CONTACT_HULL]
    if hull and isinstance(t_doc, dict) and set(t_doc) == {"surface"}:
        surface = parse_surface(t_doc["surface"])
        if surface.raster is not None and plant:
            raise ScenarioError("terrain.surface.elevation_file: an elevation raster under the 3D vehicle is "
                                "symtrack simulate's (homogeneous soil), not the MPC's yet; give slopes and furrows")
        try:
            vm.check_ground(model, surface, vehicle)
            if start is not None:
                vm.check_start(surface, vehicle, *start)
        except ParameterError as err:
            raise ScenarioError(str(err)) from err
        return None, surface
    if not hull and isinstance(t_doc, dict) and set(t_doc) == {"surface"}:
        # the ground's shape alone: what a hull drives on (homogeneous soil following it); a vehicle moving
        # in the plane feels no slope, and on its own the table would ask for a grid of default size
        raise ScenarioError(f"terrain.surface: the ground's shape (a slope, furrows, an elevation raster) under "
                            f"homogeneous soil needs model.vehicle = {' or '.join(repr(n) for n in hulls)} (this "
                            f"run has model.vehicle = {model.vehicle!r}, which moves in the plane and feels no "
                            f"slope): add --set model.vehicle={hulls[0]} (docs/vehicle3d.md), or give the grid "
                            "terrain its keys (terrain.size_m, terrain.cell_m) to carry the surface's elevation under "
                            "the planar vehicle")
    terrain = parse_terrain(t_doc)
    if terrain is not None:
        try:
            vehicle_registry.check_plant(vm, "engine" if engine else "grid")
        except ParameterError as err:
            if plant:  # the MPC: its grid plant is the channel pool's
                raise ScenarioError(f"model.vehicle = {model.vehicle!r} runs on the homogeneous terrain only in the "
                                    f"MPC ({plant} asks for the grid, whose MPC plant is the channel pool: {err}); a "
                                    "[terrain] section holding only [terrain.surface] gives it its ground on "
                                    "homogeneous soil") from err
            raise ScenarioError(f"{err}" + (" (a [terrain] section holding only [terrain.surface] gives it its ground "
                                            "on homogeneous soil)" if hull else "")) from err
        try:  # what the vehicle's grid path cannot take
            vm.check_grid(terrain)
            vm.check_ground(model, terrain.surface, vehicle)
        except ParameterError as err:
            raise ScenarioError(str(err)) from err
    return terrain, None


def parse_engine(t) -> EngineSettings | None:
    """The optional ``[engine]`` table: the terrain engine's scheme (docs/terrain.md, "The terrain
    engine"; keys and ranges: :class:`~symtrack.integrators.settings.EngineSettings`)."""
    if t is None:
        return None
    if not isinstance(t, dict):
        raise ScenarioError(f"[engine] = {t!r} must be a table")
    check_keys("engine", t, [f.name for f in dataclasses.fields(EngineSettings)])
    return EngineSettings(**t)


def parse_terrain(t) -> TerrainSettings | None:
    """The optional ``[terrain]`` table."""
    return None if t is None else settings_from_dict(t)


START_KEYS = {k.name: k for k in (
    Key("x_m", "the start position's world x [m]", -1e7, 1e7),
    Key("y_m", "the start position's world y [m]", -1e7, 1e7),
    Key("yaw_deg", "the start heading [deg], 0 along world x, counter-clockwise", -360, 360),
)}
TORQUE_KEYS = {k.name: k for k in (
    Key("t_s", "from this time on [s] (the first entry at 0, then strictly increasing)", 0, 1e6),
    Key("left_N_m", "the left sprocket's torque command [N m]", -1e6, 1e6),
    Key("right_N_m", "the right sprocket's torque command [N m]", -1e6, 1e6),
    Key("event", "a name for this instant (unique; run.stop_distance_event may count from it)",
        allowed="a non-empty string"),
)}


def _parse_torque(entries) -> tuple[TorqueEntry, ...]:
    if not isinstance(entries, list) or not entries:
        raise ScenarioError("[[torque]] is required: at least one entry with t_s, left_N_m, right_N_m")
    out, events = [], set()
    for i, e in enumerate(entries):
        sec = f"torque[{i}]"
        check_keys(sec, e, list(TORQUE_KEYS))
        for k in ("t_s", "left_N_m", "right_N_m"):
            if k not in e:
                raise ScenarioError(f"{sec}.{k} is required")
        t, left, right = (TORQUE_KEYS[k].check(sec, e[k]) for k in ("t_s", "left_N_m", "right_N_m"))
        if i == 0 and t != 0.0:
            raise ScenarioError(f"{sec}.t_s = {e['t_s']!r}: the first torque entry must be at t_s = 0")
        if out and t <= out[-1].t_s:
            raise ScenarioError(
                f"{sec}.t_s = {e['t_s']!r} is not after the previous entry's t_s = {out[-1].t_s!r}: "
                "torque entries must be in strictly increasing time order")
        ev = e.get("event")
        if ev is not None:
            if not isinstance(ev, str) or not ev:
                raise ScenarioError(f"{sec}.event = {ev!r} must be a non-empty string")
            if ev in events:
                raise ScenarioError(f"{sec}.event = {ev!r} is used twice")
            events.add(ev)
        out.append(TorqueEntry(t, left, right, ev))
    return tuple(out)


def _parse_start(t) -> Start:
    check_keys("start", t, list(START_KEYS))
    return Start(*(START_KEYS[k].check("start", t.get(k, getattr(Start, k))) for k in ("x_m", "y_m", "yaw_deg")))


def scenario_from_dict(d: dict, default_name: str = "scenario") -> Scenario:
    """A scenario document (already read) -> :class:`Scenario`, every section checked."""
    check_document("scenario", d, TOP_KEYS, arrays=("torque",))
    name = d.get("name", default_name)
    desc = d.get("description", "")
    run = parse_run(d.get("run", {}))
    model = _parse_model(d.get("model", {}))
    # the [vehicle] and [soil] tables of the model's vehicle and soil law (their declared parameters)
    vehicle_specs, soil_specs, known = vehicle_params(model), soil_params(model), known_soil_names()
    vp, vehicle = parse_params("vehicle", d.get("vehicle", {}), vehicle_preset, vehicle_specs)
    soil_t = d.get("soil", {})
    moist = None
    if isinstance(soil_t, dict) and any(k == "moisture" or k.startswith("moisture.") for k in soil_t):
        # the day's moisture (symtrack.soil.moisture): PTFs over the soil's values; --set gives
        # soil.moisture.KEY=VALUE as the flat key "moisture.KEY"
        moist = dict(soil_t.get("moisture", {})) if isinstance(soil_t.get("moisture", {}), dict) else soil_t["moisture"]
        if isinstance(moist, dict):
            moist.update({k.split(".", 1)[1]: v for k, v in soil_t.items() if k.startswith("moisture.")})
        soil_t = {k: v for k, v in soil_t.items() if k != "moisture" and not k.startswith("moisture.")}
    sp, soil = parse_params("soil", soil_t, soil_preset, soil_specs, known=known)
    if moist is not None:
        try:
            soil = check_set(moisture.apply_moisture(soil, moist, "soil.moisture"), soil_specs, "soil", known)
        except ParameterError as err:
            raise ScenarioError(str(err)) from err
    start = _parse_start(d.get("start", {}))
    torque = _parse_torque(d.get("torque"))
    try:  # what no crawler has (symtrack.model.plausibility): refused, or warned in one line
        plausibility.check_vehicle(vehicle)
        plausibility.check_soil_contact(vehicle, soil)
        if vehicle_registry.get(model.vehicle).contact == CONTACT_HULL:  # a hull that can lean over
            plausibility.check_leaning(vehicle, soil)
        plausibility.check_torque(vehicle, max(max(abs(e.left_N_m), abs(e.right_N_m)) for e in torque), "torque")
    except ParameterError as err:
        raise ScenarioError(str(err)) from err
    terrain, surface = parse_ground(d.get("terrain"), model, vehicle,
                                    engine=registry.get(run.integrator, "run.integrator").grid_engine is not None,
                                    start=(start.x_m, start.y_m))
    engine = parse_engine(d.get("engine"))
    if terrain is not None and terrain.towed is not None:  # (symtrack.vehicles.towed; again before the first pass)
        towed.check_scenario(terrain, start.x_m, start.y_m, start.yaw_deg, soil,
                             float(vehicle["cg_ahead_of_contact_centre_m"]))
    sc = Scenario(name, desc, run, model, vp, vehicle, sp, soil, start, torque, terrain, engine, surface)
    events = [e.event for e in torque if e.event]
    if run.stop_distance_event is not None and run.stop_distance_event not in events:
        raise ScenarioError(f"run.stop_distance_event = {run.stop_distance_event!r} names no [[torque]] event; "
                            f"events: {', '.join(events) or 'none'}")
    return sc


def builtin_names() -> list[str]:
    """The names of the built-in simulation scenarios."""
    return _package_names(SCENARIO_PACKAGE)


def load_scenario(name_or_path, overrides=None) -> Scenario:
    """Load a built-in scenario by name or a TOML file by path, apply the overrides, validate.

    Parameters
    ----------
    name_or_path : str or path
        A built-in name (``symtrack scenarios``) or a TOML file.
    overrides : list of str or dict, optional
        ``["run.duration_s=2", ...]`` as ``--set`` takes them, or ``{"run.duration_s": 2.0}``.

    Returns
    -------
    Scenario
    """
    doc, default_name = read_document(name_or_path, SCENARIO_PACKAGE, "scenario", overrides, paths=TERRAIN_PATH_KEYS)
    return scenario_from_dict(doc, default_name)
