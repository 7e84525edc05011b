"""``symtrack export fmu SCENARIO --out FILE.fmu``: an FMI 2.0 Co-Simulation FMU of the vehicle on the
homogeneous terrain (docs/codegen.md, section "The FMU").

The FMU is a zip file::

    modelDescription.xml                   FMI 2.0, co-simulation; variables named with symtrack's signal names
    binaries/linux64/<MODEL_IDENTIFIER>.so built here with the local compiler (symtrack.toolchain.build)
    sources/                               every C file, to build the binary on another platform
    documentation/index.html               the variable list

Inside: the generated fixed-step Rosenbrock integrator and outputs of :mod:`symtrack.native.generate`
(``<prefix>_rosenbrock.c``, ``<prefix>_outputs.c``: ``generated/`` when it matches the scenario's model),
``<prefix>_fmu_init.c`` (generated here: the static sinkage guess, the static cell residual and its
Jacobian, the start accelerations) for the start state, ``fmu_model.h`` (value references, start values,
the fixed step) and ``symtrack_fmu.c`` (the FMI functions, a copy of ``fmu_template.c``), with the
FMI 2.0 headers of the Modelica Association (2-clause BSD, the copies fmpy ships, in ``fmi2/``).

Variables (value references in this order): the inputs ``torque_cmd_left_N_m``, ``torque_cmd_right_N_m``;
the parameters: :attr:`~symtrack.model.system.SystemModel.model_param_names` (the scenario's vehicle and
soil values) and
the start pose ``start_x_m``, ``start_y_m``, ``start_yaw_rad`` (variability "fixed"); the outputs: the
states (``SystemModel.state_names``), then the model's outputs (``SystemModel.output_names``) except
those that repeat a state's name (the four sinkages, which are the states). Units are the names'
suffixes (:func:`symtrack.native.generate.unit_of`), each declared in ``<UnitDefinitions>`` with its SI
base units where it has fixed ones.

A scenario with a ``[terrain]`` section is handed to :func:`symtrack.codegen.engine_fmu.export_engine_fmu`
(the vehicle on the terrain engine, the field as a file parameter). What cannot be exported here is
refused before anything is built (:func:`check_exportable`): a grid terrain scenario, an integrator
other than ``rosenbrock``, a torque change or an output step off the grid of ``run.fixed_step_s`` (the
FMU reproduces the run on that grid; a communication step off it ends with a shorter step), an
unwritable ``--out``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import uuid
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import casadi as ca

from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, check_output_file
from ..integrators.settings import FIXED_STEP_TOLERANCE
from ..native.cache import generated_sources
from ..native.generate import FIXED_STEP_METHOD, model_functions, unit_of
from ..simulation.builder import system_model
from ..simulation.scenario import Scenario, load_scenario
from ..soil.law import make as make_soil_law
from ..toolchain import BuildSpec, build, casadi_tag, digest
from ..vehicles.planar import mean_ground_pressure_Pa
from .fmu_common import (
    BASE_UNITS,
    FMI2_HEADERS,
    LOG_CATEGORIES,
    FmuVariable,
    probe_writable,
    scalar_variable_xml,
    unit_definitions,
    xml_number,
    zip_bytes,
)
from .standalone import c_array, c_literal

__all__ = ["BASE_UNITS", "FMU_BUILD_VERSION", "FMU_CFLAGS", "FMU_TEMPLATE", "FMI2_HEADERS", "LOG_CATEGORIES",
           "MODEL_IDENTIFIER", "FmuVariable", "ExportedFmu", "check_exportable", "command", "export_fmu",
           "fmu_variables", "init_functions", "model_description"]

log = logging.getLogger("symtrack.codegen")

MODEL_IDENTIFIER = "symtrack_homogeneous"
# bumped when the FMU's layout (template, header, variable order) changes: part of the binary's cache key
FMU_BUILD_VERSION = 1
FMU_TEMPLATE = Path(__file__).resolve().parent / "fmu_template.c"
# -fvisibility=hidden without GCC_HASCLASSVISIBILITY: only the fmi2 functions (FMI2_Export) are exported
FMU_CFLAGS = ("-O2", "-std=c99", "-Wall")
FMU_SHARED_CFLAGS = ("-fPIC", "-fvisibility=hidden")
START_POSE = ("start_x_m", "start_y_m", "start_yaw_rad")

@dataclasses.dataclass(frozen=True)
class ExportedFmu:
    """What :func:`export_fmu` wrote."""

    path: Path
    guid: str
    variables: tuple[FmuVariable, ...]
    binary: Path  # the cached shared library inside the FMU
    files: tuple[str, ...]  # the FMU's members


def check_exportable(sc: Scenario) -> None:
    """A ScenarioError (naming the field, its value and what is allowed) when the FMU cannot represent sc."""
    if sc.terrain is not None:
        raise ScenarioError(f"scenario {sc.name!r} has a [terrain] section (the persistent grid terrain): this FMU "
                            "carries the homogeneous terrain only (export_fmu exports a grid scenario as the engine "
                            "FMU, symtrack.codegen.engine_fmu); drop [terrain] to export the vehicle on the "
                            "homogeneous soil")
    if sc.engine is not None:
        raise ScenarioError(f"scenario {sc.name!r} has an [engine] section (the grid terrain engine): the FMU carries "
                            "the homogeneous terrain only")
    run = sc.run
    if run.integrator != FIXED_STEP_METHOD:
        raise ScenarioError(f"run.integrator = {run.integrator!r}: the FMU integrates with the compiled fixed-step "
                            f"{FIXED_STEP_METHOD!r} only (its results match `symtrack simulate ... --integrator "
                            f"{FIXED_STEP_METHOD}`); export with --set run.integrator={FIXED_STEP_METHOD}")
    fs = run.fixed_step_s

    def on_grid(t):
        n = round(t / fs)
        return abs(t - n * fs) <= 1e-9 * max(fs, abs(t))

    if not on_grid(run.output_dt_s):
        raise ScenarioError(f"run.output_dt_s = {run.output_dt_s!r} is not a whole multiple of run.fixed_step_s = "
                            f"{fs!r}: the FMU's communication step (its default experiment's step size) must be")
    for i, e in enumerate(sc.torque):
        if not on_grid(e.t_s):
            raise ScenarioError(f"torque[{i}].t_s = {e.t_s!r} is not a whole multiple of run.fixed_step_s = {fs!r}: "
                                "the FMU's torque inputs change only between its fixed steps, so this torque "
                                "programme cannot be reproduced by it; move the change onto the step grid")


def fmu_variables(model, sc: Scenario) -> tuple[FmuVariable, ...]:
    """The FMU's variables in value-reference order (module doc)."""
    params = sc.params
    u0 = sc.torque_at(0.0)
    out: list[FmuVariable] = []

    def add(name, causality, variability, start, description, initial=None):
        out.append(FmuVariable(name, len(out), causality, variability, start, unit_of(name), description, initial))

    for name, v in zip(model.input_names, u0, strict=True):
        add(name, "input", "continuous", float(v), "commanded sprocket torque (held over each communication step)")
    for name in model.model_param_names:
        kind = "vehicle" if name in sc.vehicle else "soil"
        preset = sc.vehicle_preset if kind == "vehicle" else sc.soil_preset
        add(name, "parameter", "fixed", float(params[name]),
            f"{kind} parameter (scenario {sc.name!r}, preset {preset})")
    st = sc.start
    for name, v in zip(START_POSE, (st.x_m, st.y_m, math.radians(st.yaw_deg)), strict=True):
        add(name, "parameter", "fixed", float(v), "start pose (the terrain cells start in static equilibrium)")
    for name in model.state_names:
        add(name, "output", "continuous", None, "state", "calculated")
    states = set(model.state_names)
    for name in model.output_names:
        if name not in states:
            add(name, "output", "continuous", None, "model output", "calculated")
    names = [v.name for v in out]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ScenarioError(f"the FMU's variable names are not unique: {', '.join(dup)}")
    return tuple(out)


def model_description(sc: Scenario, variables, guid: str, model_hash: str, prefix: str = "homogeneous") -> str:
    """modelDescription.xml (FMI 2.0, co-simulation); ``prefix``: the generated files' prefix."""
    desc = (f"symtrack {sc.name}: tracked vehicle on homogeneous deformable soil, compiled fixed-step Rosenbrock "
            f"(model hash {model_hash[:16]})")
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<fmiModelDescription fmiVersion="2.0"',
        f"  modelName={quoteattr(f'symtrack {sc.name}')}",
        f'  guid="{guid}"',
        f"  description={quoteattr(desc)}",
        '  generationTool="symtrack export fmu"',
        '  variableNamingConvention="flat"',
        '  numberOfEventIndicators="0">',
        f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" needsExecutionTool="false"',
        '    canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false" maxOutputDerivativeOrder="0"',
        '    canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false"',
        '    canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="false" canSerializeFMUstate="false"',
        '    providesDirectionalDerivative="false">',
        "    <SourceFiles>",
    ]
    lines += [f'      <File name="{n}"/>' for n in ("symtrack_fmu.c", f"{prefix}_{FIXED_STEP_METHOD}.c",
                                                   f"{prefix}_outputs.c", f"{prefix}_fmu_init.c")]
    lines += ["    </SourceFiles>", "  </CoSimulation>", *unit_definitions(variables), "  <LogCategories>"]
    lines += [f'    <Category name="{c}"/>' for c in LOG_CATEGORIES]
    lines += ["  </LogCategories>",
              f'  <DefaultExperiment startTime="0.0" stopTime="{xml_number(sc.run.duration_s)}" '
              f'stepSize="{xml_number(sc.run.output_dt_s)}"/>',
              "  <ModelVariables>"]
    for v in variables:
        lines += scalar_variable_xml(v)
    lines += ["  </ModelVariables>", "  <ModelStructure>", "    <Outputs>"]
    outs = [v for v in variables if v.causality == "output"]
    lines += [f'      <Unknown index="{v.value_reference + 1}"/>' for v in outs]
    lines += ["    </Outputs>", "    <InitialUnknowns>"]
    lines += [f'      <Unknown index="{v.value_reference + 1}"/>' for v in outs]
    lines += ["    </InitialUnknowns>", "  </ModelStructure>", "</fmiModelDescription>", ""]
    return "\n".join(lines)


def init_functions(model, prefix: str) -> tuple[ca.Function, ...]:
    """The start state's Functions (as :func:`symtrack.model.static.static_state` and
    ``FixedStepper.consistent_z``): ``<prefix>_fmu_static_guess(p) -> zc`` (the soil law's static sinkage
    of the mean pressure, every cell), ``<prefix>_fmu_static_newton(zc, pose, p) -> (F, J)`` (the cells'
    rates at rest and their dense Jacobian in the sinkages), ``<prefix>_accel(x, u, p) -> z``."""
    lay = model.layout
    cells = lay.cell_indices("sinkage")
    rates = lay.cell_indices("rate")
    pose_idx = lay.indices(("x_m", "y_m", "yaw_rad"))
    p = ca.SX.sym("p", model.p.sparsity())
    P = model.model_layout.unpack(p)
    law = make_soil_law(model.opts)
    p_mean = mean_ground_pressure_Pa(P)
    zg = law.static_sinkage(p_mean, law.vector({k: P[k] for k in law.param_names}))
    guess = ca.Function(f"{prefix}_fmu_static_guess", [p], [ca.repmat(zg, len(cells), 1)], ["p"], ["zc"])
    zc, pose = ca.SX.sym("zc", len(cells)), ca.SX.sym("pose", 3)
    x = ca.SX.zeros(model.nx)
    for k, i in enumerate(pose_idx):
        x[i] = pose[k]
    for k, i in enumerate(cells):
        x[i] = zc[k]
    F = model.ode(x, ca.DM.zeros(model.u.numel()), p)[rates]
    J = ca.densify(ca.jacobian(F, zc))
    newton = ca.Function(f"{prefix}_fmu_static_newton", [zc, pose, p], [F, J], ["zc", "pose", "p"], ["F", "J"],
                         {"cse": True})
    accel = ca.Function(f"{prefix}_accel", model.accel.sx_in(), model.accel.call(model.accel.sx_in()),
                        model.accel.name_in(), model.accel.name_out(), {"cse": True})
    return guess, newton, accel


def _generate(functions, stem: str) -> dict[str, bytes]:
    with tempfile.TemporaryDirectory(prefix="symtrack-fmu-") as scratch:
        cg = ca.CodeGenerator(stem + ".c", {"with_header": True})
        for f in functions:
            cg.add(f)
        cg.generate(scratch + "/")
        return {stem + ext: (Path(scratch) / (stem + ext)).read_bytes() for ext in (".c", ".h")}


def _model_header(model, sc: Scenario, variables, guid: str, prefix: str) -> bytes:
    lay = model.layout
    n_in, n_p = len(model.input_names), len(model.model_param_names)
    outs = [v.name for v in variables if v.causality == "output"][model.nx:]
    y_index = [model.output_names.index(n) for n in outs]
    # value reference blocks: u, p, pose, x, y (the template relies on this order)
    vr_p, vr_pose = n_in, n_in + n_p
    vr_x = vr_pose + 3
    vr_y = vr_x + model.nx
    if variables[vr_x].name != model.state_names[0] or len(variables) != vr_y + len(outs):
        raise RuntimeError("fmu_variables and fmu_model.h disagree on the value reference layout")
    fnames = [f"{prefix}_{FIXED_STEP_METHOD}_controlled_step", f"{prefix}_outputs",
              f"{prefix}_consistent_z", f"{prefix}_accel", f"{prefix}_fmu_static_newton", f"{prefix}_fmu_static_guess"]
    macros = ["F_STEP", "F_OUTPUTS", "F_CONSISTENT_Z", "F_ACCEL", "F_STATIC_NEWTON", "F_STATIC_GUESS"]
    tol = float(sc.run.fixed_step_tolerance)
    text = [
        f"/* fmu_model.h: the numbers of the FMU of scenario '{sc.name}'.",
        " * Written by symtrack export fmu; do not edit. */",
        "#ifndef FMU_MODEL_H", "#define FMU_MODEL_H",
        f'#include "{prefix}_{FIXED_STEP_METHOD}.h"', f'#include "{prefix}_outputs.h"',
        f'#include "{prefix}_fmu_init.h"',
        f'#define FMU_GUID "{guid}"',
        f"#define FMU_NX {model.nx}", f"#define FMU_NZ {model.z.numel()}", f"#define FMU_NU {n_in}",
        f"#define FMU_NP {n_p}", f"#define FMU_NY {len(model.output_names)}",
        f"#define FMU_NCELL {len(lay.cell_indices('sinkage'))}",
        f"#define FMU_FIXED_STEP_S {c_literal(sc.run.fixed_step_s)}",
        # the steps' error control (symtrack/integrators/fixed_step.py): the tolerance and the largest ratio
        # of the estimate to it before a step is halved (off, run.fixed_step_tolerance = 0: never halved,
        # the ratio against the default tolerance still reported)
        f"#define FMU_TOLERANCE {c_literal(tol if tol > 0 else FIXED_STEP_TOLERANCE)}",
        f"#define FMU_TOLERANCE_ON {1 if tol > 0 else 0}",
        "#define FMU_VR_U 0", f"#define FMU_VR_P {vr_p}", f"#define FMU_VR_POSE {vr_pose}", f"#define FMU_VR_X {vr_x}",
        f"#define FMU_VR_Y {vr_y}", f"#define FMU_VR_END {len(variables)}",
        f"#define FMU_NF {len(fnames)}",
        *(f"#define {m} {i}" for i, m in enumerate(macros)),
        f"#define FMU_NLOGCAT {len(LOG_CATEGORIES)}",
        "static const char *fmu_log_categories[FMU_NLOGCAT] = {" + ", ".join(f'"{c}"' for c in LOG_CATEGORIES) + "};",
        "typedef struct {",
        "  int (*eval)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);",
        "  int (*work)(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);",
        "  int (*checkout)(void);", "  void (*release)(int mem);", "  void (*incref)(void);", "  void (*decref)(void);",
        "} FmuFunction;",
        "static const FmuFunction fmu_functions[FMU_NF] = {",
        *(f"  {{{f}, {f}_work, {f}_checkout, {f}_release, {f}_incref, {f}_decref}}," for f in fnames),
        "};",
        "static const char *fmu_state_names[FMU_NX] = {" + ", ".join(f'"{n}"' for n in model.state_names) + "};",
    ]
    p0 = [v.start for v in variables[vr_p:vr_pose]]
    u0 = [v.start for v in variables[:n_in]]
    pose0 = [v.start for v in variables[vr_pose:vr_x]]
    body = "\n".join(text) + "\n"
    body += c_array("fmu_u_start", u0) + c_array("fmu_p_start", p0) + c_array("fmu_pose_start", pose0)
    body += c_array("fmu_pose_index", lay.indices(("x_m", "y_m", "yaw_rad")), "int")
    body += c_array("fmu_cell_index", lay.cell_indices("sinkage"), "int")
    body += c_array("fmu_y_index", y_index, "int")
    body += "#endif\n"
    return body.encode()


def _documentation(sc: Scenario, variables) -> bytes:
    rows = "\n".join(f"<tr><td>{v.value_reference}</td><td>{escape(v.name)}</td><td>{v.causality}</td>"
                     f"<td>{escape(v.unit)}</td><td>{'' if v.start is None else repr(v.start)}</td>"
                     f"<td>{escape(v.description)}</td></tr>" for v in variables)
    return (f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>symtrack {escape(sc.name)} FMU</title></head>"
            f"<body><h1>symtrack {escape(sc.name)}: FMI 2.0 co-simulation FMU</h1><p>The vehicle on the homogeneous "
            f"soil, integrated by the compiled fixed-step Rosenbrock method (fixed step {sc.run.fixed_step_s} s; a "
            "communication step takes whole fixed steps, then a shorter one for the rest). See symtrack's "
            "docs/codegen.md, section \"The FMU\".</p><table border=\"1\"><tr><th>value reference</th><th>name</th>"
            "<th>causality</th>"
            f"<th>unit</th><th>start</th><th>description</th></tr>\n{rows}\n</table></body></html>\n").encode()


def export_fmu(scenario, out, overrides=None) -> ExportedFmu:
    """Write the FMU of ``scenario`` (a name, a TOML path or a Scenario) to ``out`` (a .fmu file, written
    atomically). The scenario and the output path are checked before anything is built."""
    out_path = check_output_file(str(out), "--out")
    if out_path.suffix != ".fmu":
        raise ScenarioError(f"--out {str(out)!r}: an FMU file name ends in .fmu")
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if sc.terrain is not None:  # the grid terrain: the vehicle on the terrain engine
        from .engine_fmu import export_engine_fmu

        return export_engine_fmu(sc, out_path)
    check_exportable(sc)
    probe_writable(out_path)  # the scenario first: a refused scenario creates no folder
    model = system_model(sc.model)
    prefix = model.terrain.name  # the generated files' prefix
    variables = fmu_variables(model, sc)
    gen = model_functions(model, prefix, groups=(FIXED_STEP_METHOD, "outputs"))
    sources: dict[str, bytes] = {}
    for stem in (f"{prefix}_{FIXED_STEP_METHOD}", f"{prefix}_outputs"):
        sources.update({k: v for k, v in generated_sources(gen, stem).items() if k.startswith(stem + ".")})
    sources.update(_generate(init_functions(model, prefix), f"{prefix}_fmu_init"))
    sources.update({h.name: h.read_bytes() for h in FMI2_HEADERS})
    sources["symtrack_fmu.c"] = FMU_TEMPLATE.read_bytes()
    # the GUID: the model's hash with everything else the binary and the description depend on
    body = model_description(sc, variables, "{GUID}", gen.model_hash, prefix)
    key = digest(gen.model_hash, body, *(sources[n] for n in sorted(sources)), " ".join(FMU_CFLAGS),
                 casadi_tag(FMU_BUILD_VERSION))
    guid = "{" + str(uuid.UUID(key[:32])) + "}"
    sources["fmu_model.h"] = _model_header(model, sc, variables, guid, prefix)
    xml = model_description(sc, variables, guid, gen.model_hash, prefix)
    spec = BuildSpec(kind="fmu", key=key, output=f"{MODEL_IDENTIFIER}.so", sources=lambda: sources,
                     what=f"the FMU of scenario {sc.name!r}",
                     units=("symtrack_fmu.c", f"{prefix}_{FIXED_STEP_METHOD}.c", f"{prefix}_outputs.c",
                            f"{prefix}_fmu_init.c"),
                     cflags=FMU_CFLAGS, shared_cflags=FMU_SHARED_CFLAGS)
    binary = build(spec)
    members = {"modelDescription.xml": xml.encode(),
               f"binaries/linux64/{MODEL_IDENTIFIER}.so": binary.read_bytes(),
               "documentation/index.html": _documentation(sc, variables),
               **{f"sources/{n}": sources[n] for n in sorted(sources)}}
    atomic_write_bytes(out_path, zip_bytes(members))
    return ExportedFmu(out_path, guid, variables, binary, tuple(members))


def command(args) -> int:
    """``symtrack export fmu SCENARIO --out FILE.fmu [--set ...]``."""
    res = export_fmu(args.scenario, args.out, args.set)
    n = {c: sum(v.causality == c for v in res.variables) for c in ("input", "parameter", "output")}
    strings = getattr(res, "strings", ())
    binary = next(f for f in res.files if f.startswith("binaries/"))
    log.info("wrote %s (FMI 2.0 co-simulation, GUID %s): %d inputs, %d parameters%s, %d outputs; binary "
             "%s (linux64), C sources in sources/", res.path, res.guid, n["input"], n["parameter"] + len(strings),
             f" ({', '.join(strings)} among them)" if strings else "", n["output"], binary)
    return 0

