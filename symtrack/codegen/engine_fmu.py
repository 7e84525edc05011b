"""``symtrack export fmu SCENARIO --out FILE.fmu`` for a grid scenario: an FMI 2.0 Co-Simulation FMU of the
vehicle on the million-cell terrain engine (docs/codegen.md, "The FMU"; the homogeneous vehicle's FMU is
:mod:`symtrack.codegen.fmu`, which hands a scenario with a ``[terrain]`` section to :func:`export_engine_fmu`).

The FMU is the grid standalone program (:mod:`symtrack.codegen.grid_standalone`) turned into FMI calls::

    modelDescription.xml                    FMI 2.0, co-simulation; variables named with symtrack's signal names
    binaries/linux64/symtrack_grid_engine.so built here with the local compiler (symtrack.toolchain.build)
    sources/                                every C file (symtrack_fmu.c includes the rest)
    documentation/index.html                the variable list

``sources/``: ``symtrack_fmu.c`` (the FMI functions, a copy of ``engine_fmu_template.c``), the terrain
engine ``grid_engine.c`` with ``subsoil.h`` and ``terrain_query.h`` (symtrack/native/, unchanged), the
scenario's generated engine Functions ``engine_gen.inc`` and soil dispatch ``engine_soils.inc`` (the
same code the package's engine library compiles), ``engine_fmu_model.h`` (the scenario's numbers: the
field, the channel modulus, the engine's constants, value references, start values, the soil) and the
FMI 2.0 headers.

Variables (value references in this order): the Real inputs ``torque_cmd_left_N_m``,
``torque_cmd_right_N_m``; the Real parameters ``start_x_m``, ``start_y_m``, ``start_yaw_rad`` (variability
"fixed"); the Real outputs: the vehicle's 12 states, then the engine's outputs
(``TerrainEngine.output_names``); then the String parameters ``field_file`` (read at
fmi2ExitInitializationMode; empty: a virgin field) and ``field_file_out`` (written at fmi2Terminate;
empty: not written), raw field files (:mod:`symtrack.terrain.fieldfile`). The vehicle and soil
parameters are compiled into the generated Functions and the engine's constants (the channel modulus
M, the cells' areal mass and damping, the padding): changing one means exporting again, so they are
not FMU parameters.

What cannot be exported is refused before anything is built (:func:`check_exportable`): another vehicle
than the planar one, an integrator other than the engine (``grid_fast``), a soil map, an elevation, a
moisture programme, a towed trailer, a start terrain in the scenario (give it as ``field_file``), more
than one pass, a torque change off the macro-step grid. The subsoil stress and the bulk density are
carried: their tables as C constants, this pass's maxima computed by the engine, the pass's end folding
them into the field's records as World.fold_pass does (fmi2Terminate).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import uuid
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes
from ..model.parameters import SOIL_DAY_PARAM_NAMES, soil_params, spec
from ..native.generate import unit_of
from ..simulation.scenario import Scenario
from ..terrain import fieldfile
from ..toolchain import BuildSpec, build, casadi_tag, digest
from ..vehicles import registry as vehicle_registry
from ..vehicles.planar import INPUTS
from .fmu_common import (
    FMI2_HEADERS,
    FmuVariable,
    probe_writable,
    scalar_variable_xml,
    unit_definitions,
    xml_number,
    zip_bytes,
)
from .grid_standalone import NATIVE, engine_constants, engine_parts
from .standalone import c_array, c_literal

__all__ = ["ENGINE_FMU_CFLAGS", "ENGINE_INTEGRATOR", "ENGINE_LOG_CATEGORIES", "ENGINE_MODEL_IDENTIFIER",
           "ENGINE_TEMPLATE", "ExportedEngineFmu", "check_exportable", "export_engine_fmu", "fmu_variables"]

log = logging.getLogger("symtrack.codegen")

ENGINE_MODEL_IDENTIFIER = "symtrack_grid_engine"
ENGINE_FMU_BUILD_VERSION = 1  # bumped when the template, header or variable order change: in the cache key
ENGINE_TEMPLATE = Path(__file__).resolve().parent / "engine_fmu_template.c"
ENGINE_INTEGRATOR = "grid_fast"
ENGINE_LOG_CATEGORIES = ("logStatusError", "logStatusWarning", "logAll")
# -std=c99 (ISO C: no contraction of a * b + c into an FMA, as the engine library's -ffp-contract=off);
# portable code, no -march=native: the binary runs on any x86-64 (the engine library is built for the host)
ENGINE_FMU_CFLAGS = ("-O2", "-std=c99", "-Wall", "-Wno-unused-function", "-Wno-unused-variable",
                     "-Wno-unused-but-set-variable", "-ffp-contract=off")
ENGINE_FMU_SHARED_CFLAGS = ("-fPIC", "-fvisibility=hidden")
NATIVE_FILES = ("grid_engine.c", "subsoil.h", "terrain_query.h")
START_POSE = ("start_x_m", "start_y_m", "start_yaw_rad")
FIELD_PARAMETERS = (
    ("field_file", "the field at the start: a raw field file (symtrack terrain convert IN.npz OUT.field; "
     "docs/terrain.md 'Files'), read at fmi2ExitInitializationMode; empty: a virgin field"),
    ("field_file_out", "where fmi2Terminate writes the field after the lift-off (a raw field file, through a "
     "temporary file renamed over it: it may be field_file); empty: not written"),
)
LIFT_MAX_STEPS = 300  # TerrainEngine.end_pass's max_steps


@dataclasses.dataclass(frozen=True)
class ExportedEngineFmu:
    """What :func:`export_engine_fmu` wrote."""

    path: Path
    guid: str
    variables: tuple[FmuVariable, ...]  # the Real variables in value-reference order
    strings: tuple[str, ...]  # the String parameters, value references after the Real ones
    binary: Path
    files: tuple[str, ...]


def check_exportable(sc: Scenario) -> None:
    """A ScenarioError (naming the key, its value and what to do) when the engine FMU cannot represent sc."""
    t = sc.terrain
    if t is None:
        raise ScenarioError(f"scenario {sc.name!r} has no [terrain] section: the engine FMU is of the grid terrain "
                            "(the homogeneous vehicle's FMU is symtrack.codegen.fmu)")
    if not vehicle_registry.get(sc.model.vehicle).standalone_engine:
        carried = [n for n, v in vehicle_registry.REGISTRY.items() if v.standalone_engine]
        raise ScenarioError(f"model.vehicle = {sc.model.vehicle!r}: the engine FMU carries "
                            f"{' or '.join(repr(n) for n in carried)} only (allowed: {', '.join(carried)}; the "
                            "others on the grid run in the package: symtrack simulate)")
    if sc.run.integrator != ENGINE_INTEGRATOR:
        raise ScenarioError(f"run.integrator = {sc.run.integrator!r}: the FMU of a grid scenario runs the terrain "
                            f"engine ({ENGINE_INTEGRATOR!r}; its results are `symtrack simulate` with it); export "
                            f"with --set run.integrator={ENGINE_INTEGRATOR}")
    if t.soil_map is not None:
        raise ScenarioError("terrain.soil_map is set: the engine FMU carries one soil (its field file has no "
                            "soil_index)")
    if t.surface is not None:
        raise ScenarioError("[terrain.surface] is set: the engine FMU carries a flat field")
    if t.moisture is not None:
        raise ScenarioError("[terrain.moisture] is set: the engine FMU's soil is fixed at export")
    if t.towed is not None:  # [terrain.towed] (a trailer behind the crawler)
        raise ScenarioError("[terrain.towed] is set: the engine FMU carries the crawler alone (the trailer's tyres "
                            "are run by Python, symtrack.vehicles.towed)")
    if t.initial_state:
        raise ScenarioError(f"terrain.initial_state = {t.initial_state!r}: the engine FMU takes its start field as the "
                            "string parameter field_file (symtrack terrain convert IN.npz OUT.field); drop "
                            "terrain.initial_state")
    if t.passes != 1:
        raise ScenarioError(f"terrain.passes = {t.passes!r}: an engine FMU run is one pass (run it again with "
                            "field_file = the last run's field_file_out)")
    dt = sc.run.macro_step_s
    for i, e in enumerate(sc.torque):
        n = round(e.t_s / dt)
        if abs(e.t_s - n * dt) > 1e-9 * max(dt, abs(e.t_s)):
            raise ScenarioError(f"torque[{i}].t_s = {e.t_s!r} is not a whole multiple of run.macro_step_s = {dt!r}: "
                                "the FMU's torque inputs change only between macro steps; move the change onto "
                                "the step grid")


def fmu_variables(sc: Scenario, state_names, output_names) -> tuple[FmuVariable, ...]:
    """The FMU's Real variables in value-reference order (module doc)."""
    u0 = sc.torque_at(0.0)
    out: list[FmuVariable] = []

    def add(name, causality, variability, start, description, initial=None):
        out.append(FmuVariable(name, len(out), causality, variability, start, unit_of(name), description, initial))

    for name, v in zip(INPUTS, u0, strict=True):
        add(name, "input", "continuous", float(v), "commanded sprocket torque (held over each communication step)")
    st = sc.start
    for name, v in zip(START_POSE, (st.x_m, st.y_m, math.radians(st.yaw_deg)), strict=True):
        add(name, "parameter", "fixed", float(v), "start pose: the vehicle set down at rest on the field there")
    for name in state_names:
        add(name, "output", "continuous", None, "vehicle state", "calculated")
    for name in output_names:
        add(name, "output", "continuous", None, "terrain engine output", "calculated")
    names = [v.name for v in out] + [n for n, _ in FIELD_PARAMETERS]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ScenarioError(f"the FMU's variable names are not unique: {', '.join(dup)}")
    return tuple(out)


def model_description(sc: Scenario, variables, guid: str, world) -> str:
    g = world.grid
    desc = (f"symtrack {sc.name}: tracked vehicle on the terrain engine's field of {g.shape[0]} x {g.shape[1]} cells "
            f"of {g.cell_m} m (macro step {sc.run.macro_step_s} s)")
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<fmiModelDescription fmiVersion="2.0"',
        f"  modelName={quoteattr(f'symtrack {sc.name} engine')}",
        f'  guid="{guid}"',
        f"  description={quoteattr(desc)}",
        '  generationTool="symtrack export fmu"',
        '  variableNamingConvention="flat"',
        '  numberOfEventIndicators="0">',
        f'  <CoSimulation modelIdentifier="{ENGINE_MODEL_IDENTIFIER}" needsExecutionTool="false"',
        '    canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false" maxOutputDerivativeOrder="0"',
        '    canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="true"',
        '    canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="false" canSerializeFMUstate="false"',
        '    providesDirectionalDerivative="false">',
        "    <SourceFiles>",
        '      <File name="symtrack_fmu.c"/>',
        "    </SourceFiles>",
        "  </CoSimulation>",
        *unit_definitions(variables),
        "  <LogCategories>",
        *(f'    <Category name="{c}"/>' for c in ENGINE_LOG_CATEGORIES),
        "  </LogCategories>",
        f'  <DefaultExperiment startTime="0.0" stopTime="{xml_number(sc.run.duration_s)}" '
        f'stepSize="{xml_number(sc.run.macro_step_s)}"/>',
        "  <ModelVariables>",
    ]
    for v in variables:
        lines += scalar_variable_xml(v)
    for k, (name, text) in enumerate(FIELD_PARAMETERS):
        lines.append(f"    <!-- {len(variables) + k + 1} -->")
        lines.append(f'    <ScalarVariable name="{name}" valueReference="{len(variables) + k}" '
                     f'description={quoteattr(text)} causality="parameter" variability="fixed">')
        lines.append('      <String start=""/>')
        lines.append("    </ScalarVariable>")
    outs = [v for v in variables if v.causality == "output"]
    lines += ["  </ModelVariables>", "  <ModelStructure>", "    <Outputs>"]
    lines += [f'      <Unknown index="{v.value_reference + 1}"/>' for v in outs]
    lines += ["    </Outputs>", "    <InitialUnknowns>"]
    lines += [f'      <Unknown index="{v.value_reference + 1}"/>' for v in outs]
    lines += ["    </InitialUnknowns>", "  </ModelStructure>", "</fmiModelDescription>", ""]
    return "\n".join(lines)


def _model_header(sc: Scenario, parts: dict, variables, guid: str) -> bytes:
    from ..integrators.engine import SETTLE_STEP_S
    from ..terrain.world import LIFT_TIME_S

    world, fns, state = parts["world"], parts["fns"], parts["state"]
    nv = fns.layout.nv
    vr_pose, vr_x = len(INPUTS), len(INPUTS) + len(START_POSE)
    vr_y = vr_x + nv
    if variables[vr_x].name != fns.layout.names[0] or len(variables) != vr_y + state.ny_out:
        raise RuntimeError("fmu_variables and engine_fmu_model.h disagree on the value reference layout")
    # the model's soil parameters (its soil law's and its vehicle's declarations and the soil's): the field
    # file's parameter layout, matched by name on reading
    soil_names = tuple(s.name for s in soil_params(sc.model))
    soil_values = [float(sc.params[n]) for n in soil_names]
    lines = [
        f"/* engine_fmu_model.h: the numbers of the engine FMU of scenario '{sc.name}'.",
        " * Written by symtrack export fmu (symtrack/codegen/engine_fmu.py); do not edit. */",
        "#ifndef ENGINE_FMU_MODEL_H", "#define ENGINE_FMU_MODEL_H",
        f'#define EF_GUID "{guid}"', f'#define EF_SCENARIO "{sc.name}"',
        *engine_constants("EF", parts),
        f"#define EF_MACRO_STEP_S {c_literal(sc.run.macro_step_s)}",
        f"#define EF_SETTLE_STEPS {int(round(world.settings.settle_s / SETTLE_STEP_S))}LL",
        f"#define EF_SETTLE_STEP_S {c_literal(SETTLE_STEP_S)}",
        f"#define EF_LIFT_TIME_S {c_literal(LIFT_TIME_S)}", f"#define EF_LIFT_MAX_STEPS {LIFT_MAX_STEPS}LL",
        "#define EF_VR_U 0", f"#define EF_VR_POSE {vr_pose}", f"#define EF_VR_X {vr_x}", f"#define EF_VR_Y {vr_y}",
        f"#define EF_VR_END {len(variables)}", f"#define EF_VR_STR {len(variables)}",
        f"#define EF_N_SOIL {len(soil_values)}", f'#define EF_SOIL_LAW "{sc.model.soil_law}"',
        f"#define FIELD_VERSION {fieldfile.FIELD_VERSION}", f"#define FIELD_NAME_BYTES {fieldfile.FIELD_NAME_BYTES}",
        f"#define EF_NLOGCAT {len(ENGINE_LOG_CATEGORIES)}",
        "static const char *ef_log_categories[EF_NLOGCAT] = {"
        + ", ".join(f'"{c}"' for c in ENGINE_LOG_CATEGORIES) + "};",
        "static const char *ef_soil_names[EF_N_SOIL] = {" + ", ".join(f'"{n}"' for n in soil_names) + "};",
    ]
    body = "\n".join(lines) + "\n"
    body += c_array("ef_pv", state.pv) + c_array("ef_geo", state.geo) + c_array("ef_soil_veh", state.soil_veh)
    body += c_array("ef_soil_law", state.soil_law.ravel())
    body += c_array("ef_u_start", [v.start for v in variables[:vr_pose]])
    body += c_array("ef_pose_start", [v.start for v in variables[vr_pose:vr_x]])
    body += c_array("ef_soil_values", soil_values)
    # the registry's defaults (ef_soil_has_default 0: none): the values of the soil parameters added since an
    # older field file was written
    body += c_array("ef_soil_defaults", [0.0 if spec(n).default is None else float(spec(n).default)
                                         for n in soil_names])
    body += c_array("ef_soil_has_default", [spec(n).default is not None for n in soil_names], "int")
    # a subsoil value that a file lacks is its topsoil's (fieldfile.SAME_AS_TOPSOIL): that value's index, else -1
    body += c_array("ef_soil_same_as", [soil_names.index(fieldfile.SAME_AS_TOPSOIL[n])
                                        if n in fieldfile.SAME_AS_TOPSOIL else -1 for n in soil_names], "int")
    # the day's soil parameters (moisture) are the scenario's on loading a terrain (storage.load): not compared
    body += c_array("ef_soil_checked", [0 if n in SOIL_DAY_PARAM_NAMES else 1 for n in soil_names], "int")
    body += _subsoil_constants(parts)
    body += "#endif\n"
    return body.encode()


def _tables(tag: str, tables) -> str:
    """A subsoil.h subsoil_tables_t's arrays as C constants ef_<tag>_*."""
    return (c_array(f"ef_{tag}_inv_x", tables.inv_x_step) + c_array(f"ef_{tag}_inv_t", tables.inv_t_step)
            + c_array(f"ef_{tag}_n_x", tables.n_x, "int") + c_array(f"ef_{tag}_n_t", tables.n_t, "int")
            + c_array(f"ef_{tag}_offset", tables.offset, "long long") + c_array(f"ef_{tag}_data", tables.data))


def _subsoil_constants(parts: dict) -> str:
    """The subsoil stress (the tables of the vertical stress, as EngineState builds them) and the bulk
    density's constants (density.soil_arrays of the one soil at each depth), or EF_N_DEPTHS 0."""
    from ..soil import density

    world, state = parts["world"], parts["state"]
    depths = world.storage.subsoil_depths_m
    if state.subsoil is None:
        return "#define EF_N_DEPTHS 0\n#define EF_DENSITY 0\n"
    out = f"#define EF_N_DEPTHS {len(depths)}\n" + c_array("ef_depths", depths) + _tables("sub", state.subsoil)

    # each depth's layer's lines (a soil of two layers: its subsoil's below subsoil_top_m)
    a = density.soil_arrays(world.soils[:1], depths)
    arrays = "".join(c_array(f"ef_dens_{name}", a[key][0]) for name, key in (
        ("N", "N"), ("lmk", "lambda_minus_kappa"), ("v0", "v0"), ("lambda", "lambda"), ("kappa", "kappa"),
        ("m", "m"), ("k2", "k2"), ("vmin", "v_min"))) + c_array(
        "ef_dens_geo", density.geostatic_table(world.soils[:1], depths)[0])
    return (out + "#define EF_DENSITY 1\n"
            + f"#define EF_DENS_YIELD {1 if (a['m'][0] > 0).any() else 0}\n" + arrays)


def _documentation(sc: Scenario, variables) -> bytes:
    rows = "\n".join(f"<tr><td>{v.value_reference}</td><td>{escape(v.name)}</td><td>{v.causality}</td>"
                     f"<td>{escape(v.unit)}</td><td>{'' if v.start is None else repr(v.start)}</td>"
                     f"<td>{escape(v.description)}</td></tr>" for v in variables)
    rows += "\n" + "\n".join(f"<tr><td>{len(variables) + k}</td><td>{n}</td><td>parameter (String)</td><td></td>"
                             f"<td>\"\"</td><td>{escape(t)}</td></tr>" for k, (n, t) in enumerate(FIELD_PARAMETERS))
    return (f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>symtrack {escape(sc.name)} engine FMU</title>"
            f"</head><body><h1>symtrack {escape(sc.name)}: FMI 2.0 co-simulation FMU of the terrain engine</h1>"
            f"<p>The vehicle on the million-cell terrain engine; a communication step takes whole macro steps of "
            f"{sc.run.macro_step_s} s, then a shorter one for the rest. See symtrack's docs/codegen.md, section "
            "\"The FMU\", and "
            "docs/terrain.md, \"Files\" (the field file).</p><table border=\"1\"><tr><th>value reference</th>"
            "<th>name</th><th>causality</th><th>unit</th><th>start</th><th>description</th></tr>\n"
            f"{rows}\n</table></body></html>\n").encode()


def export_engine_fmu(sc: Scenario, out_path: Path) -> ExportedEngineFmu:
    """Write the engine FMU of the grid scenario ``sc`` to ``out_path`` (checked: a .fmu file name);
    the scenario and the output path are checked before anything is built."""
    check_exportable(sc)
    probe_writable(out_path)
    with tempfile.TemporaryDirectory(prefix="symtrack-enginefmu-") as scratch:
        parts = engine_parts(sc, Path(scratch))
    fns = parts["fns"]
    variables = fmu_variables(sc, fns.layout.names[fns.layout.block("vehicle")], fns.output_names)
    sources: dict[str, bytes] = {"engine_gen.inc": parts["gen"], "engine_soils.inc": parts["soils"]}
    sources.update({n: (NATIVE / n).read_bytes() for n in NATIVE_FILES})
    sources.update({h.name: h.read_bytes() for h in FMI2_HEADERS})
    sources["symtrack_fmu.c"] = ENGINE_TEMPLATE.read_bytes()
    body = model_description(sc, variables, "{GUID}", parts["world"])
    header0 = _model_header(sc, parts, variables, "{GUID}")
    key = digest(body, header0, *(sources[n] for n in sorted(sources)), " ".join(ENGINE_FMU_CFLAGS),
                 casadi_tag(ENGINE_FMU_BUILD_VERSION))
    guid = "{" + str(uuid.UUID(key[:32])) + "}"
    sources["engine_fmu_model.h"] = _model_header(sc, parts, variables, guid)
    xml = model_description(sc, variables, guid, parts["world"])
    spec = BuildSpec(kind="engine-fmu", key=key, output=f"{ENGINE_MODEL_IDENTIFIER}.so", sources=lambda: sources,
                     what=f"the engine FMU of scenario {sc.name!r}", units=("symtrack_fmu.c",),
                     cflags=ENGINE_FMU_CFLAGS, shared_cflags=ENGINE_FMU_SHARED_CFLAGS)
    binary = build(spec)
    members = {"modelDescription.xml": xml.encode(),
               f"binaries/linux64/{ENGINE_MODEL_IDENTIFIER}.so": binary.read_bytes(),
               "documentation/index.html": _documentation(sc, variables),
               **{f"sources/{n}": sources[n] for n in sorted(sources)}}
    atomic_write_bytes(out_path, zip_bytes(members))
    return ExportedEngineFmu(out_path, guid, variables, tuple(n for n, _ in FIELD_PARAMETERS), binary,
                             tuple(members))
