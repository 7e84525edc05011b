"""The standalone C program of the grid validation (symtrack/codegen/grid_standalone_main.c): the terrain
engine of ``validation_grid`` on its million-cell field, linking only libc and libm.

``python -m codegen`` writes, besides the homogeneous files, into ``generated/``:

- ``engine_gen.inc``: the engine's CasADi Functions for the scenario's model options
  (:func:`symtrack.native.grid_engine_model.build_engine_functions`, the same code the package's
  engine library compiles; the soil's values are not in it), ``engine_soils.inc`` (the sizes and
  the law's dispatch by the soil's law row);
- ``grid_validation.h``: the scenario as C constants: the field (origin, cell, shape), the
  channel modulus M, the engine's constants (padding, release rate, cells' areal mass and
  damping, SDIRK gamma, substeps, power mode), the parameter vector, the geometry vector, the
  soil's law row (``gv_soil_law``), the work size, the settling, the torque programme and the run settings.

The program includes symtrack/native/grid_engine.c (and subsoil.h and terrain_query.h; the subsoil stress is off:
it feeds nothing back) and runs what TerrainEngine.begin_pass and the time loop do: the set-down
(eng_assign, eng_static), the settling, then the scenario's output steps in one eng_run with the
distance stop, and writes every step's vehicle state and outputs as CSV.
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from ..foundations.errors import SimulationError
from ..native.cache import REPO_GENERATED
from .standalone import build_program, c_array, c_literal

__all__ = ["CFLAGS", "FILES", "MAIN_C", "NATIVE", "NATIVE_FILES", "SCENARIO", "build", "engine_constants",
           "engine_parts", "render", "run"]

SCENARIO = "validation_grid"
MAIN_C = Path(__file__).resolve().parent / "grid_standalone_main.c"
NATIVE = Path(__file__).resolve().parent.parent / "native"
# the terrain engine's C that the program (and the engine FMU) include, unchanged
NATIVE_FILES = ("grid_engine.c", "subsoil.h", "terrain_query.h", "distance_stop.h")
FILES = ("engine_gen.inc", "engine_soils.inc", "grid_validation.h")
CFLAGS = ("-O2", "-Wall", "-Wno-unused-function", "-Wno-unused-variable", "-Wno-unused-but-set-variable")


def _time_grid(sc) -> tuple[np.ndarray, np.ndarray]:
    """The end times and torques of the scenario's output steps (simulation.loop.OutputGrid)."""
    from symtrack.simulation.loop import OutputGrid

    grid = OutputGrid(sc)
    ivs = grid.take(10**9)
    return np.array([t1 for _, t1, _ in ivs]), np.array([u for _, _, u in ivs])


def engine_parts(sc, scratch: Path) -> dict:
    """What the engine of the grid scenario ``sc`` runs on (as TerrainEngine sets it up): ``world``,
    ``settings`` (the scenario's [engine] or the defaults), ``fns``, ``state`` (an EngineState on the
    scenario's new field) and the generated C, ``gen`` (engine_gen.inc) and ``soils``
    (engine_soils.inc) as bytes; ``scratch``: a folder for the code generator."""
    from symtrack.foundations.errors import ScenarioError
    from symtrack.integrators.engine import EngineSettings, EngineState, engine_functions
    from symtrack.integrators.engine.state import vehicle_work_sizes
    from symtrack.native.grid_engine_model import soil_dispatch_c
    from symtrack.terrain.world import open_world
    from symtrack.vehicles import registry as vehicle_registry

    if not vehicle_registry.get(sc.model.vehicle).standalone_engine:  # (the 3D hull's runs in the package only)
        carried = [n for n, v in vehicle_registry.REGISTRY.items() if v.standalone_engine]
        raise ScenarioError(f"model.vehicle = {sc.model.vehicle!r}: the standalone engine (its program and the "
                            f"engine FMU) carries {', '.join(carried)} only; allowed: model.vehicle = "
                            f"{' or '.join(repr(n) for n in carried)}")
    settings = sc.engine or EngineSettings()
    st = sc.start
    world = open_world(sc.terrain, sc.params, sc.model, sc.run.macro_step_s, start_xy=(st.x_m, st.y_m))
    fns = engine_functions(sc.model, sc.params, settings.vehicle_substeps, world.soils)
    state = EngineState(world, settings, fns)
    cg = ca.CodeGenerator("engine_gen.c", {"with_header": False})
    for f in fns.all():
        cg.add(f)
    cg.generate(str(scratch) + "/")
    gen = (Path(scratch) / "engine_gen.c").read_bytes()
    # the vehicle step's stages call its F and J (call nodes): its arg and res arrays are larger than its
    # inputs and outputs; the programs give the generated Functions no integer work (none needs it here)
    sizes = vehicle_work_sizes(fns)
    if sizes[2] > 1:
        raise ScenarioError(f"the vehicle's Functions need {sizes[2]} integers of work, which the standalone "
                            "engine does not give them")
    return {"world": world, "settings": settings, "fns": fns, "state": state, "gen": gen,
            "soils": soil_dispatch_c(fns, sizes).encode()}


def engine_constants(tag: str, parts: dict) -> list[str]:
    """The engine's constants as C macros ``<tag>_NAME`` (the field, M, the struct's sizes and
    settings) for a program that fills grid_engine.c's eng_t itself."""
    from symtrack.integrators.engine import POWER_MODES, SDIRK_GAMMA, window_substeps
    from symtrack.integrators.settings import VEHICLE_ATOL, VEHICLE_MAX_HALVINGS
    from symtrack.native.grid_engine_model import NA, NGEO

    world, settings, fns, state = parts["world"], parts["settings"], parts["fns"], parts["state"]
    g = world.grid
    return [
        f"#define {tag}_NX {g.shape[0]}LL", f"#define {tag}_NY {g.shape[1]}LL", f"#define {tag}_M {world.M}LL",
        f"#define {tag}_X0 {c_literal(g.origin_m[0])}", f"#define {tag}_Y0 {c_literal(g.origin_m[1])}",
        f"#define {tag}_DX {c_literal(g.cell_m)}",
        f"#define {tag}_NA {NA}", f"#define {tag}_NW {fns.nw}", f"#define {tag}_NGEO {NGEO}",
        f"#define {tag}_N_PV {state.pv.size}LL", f"#define {tag}_N_SUMS {state.n_sums}LL",
        f"#define {tag}_NY_OUT {state.ny_out}LL", f"#define {tag}_WORK {state.work.size}LL",
        f"#define {tag}_CELL_SUBSTEPS {settings.cell_substeps}LL",
        f"#define {tag}_ENTRY_SUBSTEPS {window_substeps(settings)[0]}LL",
        f"#define {tag}_EXIT_SUBSTEPS {window_substeps(settings)[1]}LL",
        f"#define {tag}_STEADY_EULER {int(settings.steady_method == 'euler')}LL",
        f"#define {tag}_POWER_MODE {POWER_MODES.index(settings.power)}LL",
        f"#define {tag}_PAD {c_literal(state.pad)}", f"#define {tag}_RELEASE_RATE {c_literal(state.release_rate)}",
        f"#define {tag}_AREAL_MASS {c_literal(state.areal_mass)}",
        f"#define {tag}_DAMPING {c_literal(state.damping)}",
        f"#define {tag}_GAMMA {c_literal(SDIRK_GAMMA)}",
        f"#define {tag}_ENTRY_FRACTION {c_literal(settings.entry_fraction)}",
        f"#define {tag}_RING_TOL {c_literal(settings.ring_tolerance)}",
        f"#define {tag}_VEHICLE_RTOL {c_literal(settings.vehicle_tolerance)}",
        f"#define {tag}_VEHICLE_ATOL {c_literal(VEHICLE_ATOL)}",
        f"#define {tag}_VEHICLE_MAX_HALVINGS {VEHICLE_MAX_HALVINGS}LL",
    ]


def render(scratch: Path, overrides=()) -> dict[str, bytes]:
    """The generated/ files of the grid standalone program, name -> bytes (``overrides``: ``--set``
    items applied to the scenario)."""
    from symtrack.integrators.engine import SETTLE_STEP_S
    from symtrack.simulation.scenario import load_scenario

    sc = load_scenario(SCENARIO, list(overrides))
    parts = engine_parts(sc, scratch)
    world, fns, state = parts["world"], parts["fns"], parts["state"]
    st = sc.start
    T, U = _time_grid(sc)
    run = sc.run
    te = sc.event_time(run.stop_distance_event) if run.stop_distance_event else 0.0
    lines = [
        f"/* grid_validation.h: the built-in '{sc.name}' scenario as C constants, for",
        " * symtrack/codegen/grid_standalone_main.c. Generated by python -m codegen; do not edit. */",
        "#ifndef GRID_VALIDATION_H",
        "#define GRID_VALIDATION_H",
        f'#define GV_SCENARIO "{sc.name}"',
        *engine_constants("GV", parts),
        f"#define GV_START_X {c_literal(st.x_m)}", f"#define GV_START_Y {c_literal(st.y_m)}",
        f"#define GV_START_YAW {c_literal(np.radians(st.yaw_deg))}",
        f"#define GV_SETTLE_STEPS {int(round(world.settings.settle_s / SETTLE_STEP_S))}LL",
        f"#define GV_SETTLE_STEP_S {c_literal(SETTLE_STEP_S)}",
        f"#define GV_N_STEPS {T.size}LL",
        f"#define GV_STOP_DISTANCE_M {c_literal(run.stop_after_distance_m if run.stop_after_distance_m else -1.0)}",
        f"#define GV_STOP_FROM_T_S {c_literal(te)}",
    ]
    text = "\n".join(lines) + "\n"
    text += c_array("gv_pv", state.pv) + c_array("gv_geo", state.geo) + c_array("gv_soil_veh", state.soil_veh)
    text += c_array("gv_soil_law", state.soil_law.ravel())
    text += c_array("gv_T", T) + c_array("gv_U", U.ravel())
    names = ", ".join(f'"{n}"' for n in fns.output_names)
    text += f"static const char *gv_output_names[{len(fns.output_names)}] = {{{names}}};\n"
    text += "#endif\n"
    return {"engine_gen.inc": parts["gen"], "engine_soils.inc": parts["soils"], "grid_validation.h": text.encode()}


def build(src_dir: Path | None = None) -> Path:
    """Compile the grid standalone program from the generated sources in src_dir (default: the
    repository's generated/) into the cache (keyed by the sources' hash); returns its path."""
    src = Path(src_dir) if src_dir else REPO_GENERATED
    hashed = [*(src / n for n in FILES), *(NATIVE / n for n in NATIVE_FILES)]
    return build_program("grid_standalone", MAIN_C, hashed, CFLAGS)


def run(binary: Path, out_csv: Path | None = None) -> np.ndarray:
    """Run the program; returns its rows (t, the 12 vehicle states, the outputs) as an array."""
    with tempfile.TemporaryDirectory(prefix="symtrack-gridsa-") as d:
        csv = Path(out_csv) if out_csv else Path(d) / "grid_validation.csv"
        res = subprocess.run([str(binary), str(csv)], capture_output=True, text=True)
        if res.returncode != 0:
            raise SimulationError(f"{binary} failed ({res.returncode}): {res.stderr.strip()}")
        return np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
