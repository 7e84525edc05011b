"""Generate the C sources of a :class:`~symtrack.model.SystemModel` into a folder.

Everything here works on a generic ``SystemModel`` (its Functions ``ode``, ``dae``,
``outputs``, ``accel`` and its symbols), so the grid terrain's coupled system goes through the
same path as the homogeneous one; only the prefix of the names differs.

Files written for a model with prefix ``<m>`` (fixed, predictable names, like acados):

- ``<m>_ode.c/.h``: ``<m>_ode(x,u,p)->ode``, its exact sparse Jacobian ``jac_<m>_ode`` (the
  symbol ``casadi.external`` looks for) and the linearization ``<m>_linearize(x,u,p)->(A,B)``;
- ``<m>_outputs.c/.h``: ``<m>_outputs(x,u,p)->y``; ``<m>_linearize_outputs.c/.h``:
  ``<m>_linearize_outputs(x,u,p)->(C,D)`` (the exact Jacobians with respect to x and u);
- ``<m>_dae.c/.h``: ``<m>_dae(x,z,u,p)->(ode,alg)``, ``jac_<m>_dae``, ``<m>_accel(x,u,p)->z``;
- ``<m>_rosenbrock.c/.h``: the fixed-step integrator (the 8-stage, L-stable, order-5 Rosenbrock
  method of CasADi's ``rosenbrock`` plugin, unrolled with a sparse LU in :mod:`symtrack.native.rosenbrock`,
  on the index-1 DAE form): ``<m>_rosenbrock_step(x0,z0,u,p,h)->(xf,zf,ef)``
  advances one step of length h (``ef``: the step's local error estimate of each differential
  state, the difference from the method's embedded solution,
  :func:`symtrack.native.rosenbrock.step_and_error_expressions`), and
  ``<m>_rosenbrock_controlled_chunk<N>(x0,z0,U,H,p,ctl)->(X,Z,Y,R,NH)`` advances N steps in one
  call, each error-controlled (:func:`controlled_chunks`: halved where its estimate exceeds the
  tolerance ctl[0]; column k of U and H are the input and the length of step k, a step of length
  0 leaves the state unchanged; column k of X, Z, Y is the state, algebraic state and outputs
  after step k, of R and NH its largest error ratio and how many steps were halved);
  ``<m>_consistent_z(x,z0,u,p)->z`` solves the
  algebraic equations for z by Newton steps from z0 (the steps start from the z they are given);
- ``manifest.json``: model hash (SHA-256 over the files' hashes of their serialised Functions;
  each file's own hash is its key in the compiled-library cache), CasADi version, and the names
  and units of every input and output of every function.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca

from ..foundations.units import unit_of_suffix
from . import rosenbrock

__all__ = ["CHUNK_SIZES", "FIXED_STEP_METHOD", "GROUPS", "GROUP_OF", "Generated", "MANIFEST_SCHEMA_VERSION",
           "fixed_step_functions", "manifest", "model_functions", "render", "unit_of", "write_sources"]

MANIFEST_SCHEMA_VERSION = 1
# Steps per call of the chunk functions: a long chunk for the bulk of a run and a short one
# for its end (a run that stops at a distance wastes at most a short chunk).
CHUNK_SIZES = (256, 16)
FIXED_STEP_METHOD = "rosenbrock"

def unit_of(name: str) -> str:
    """The unit a symtrack name carries in its suffix ("1" when it has none;
    :func:`symtrack.foundations.units.unit_of_suffix`)."""
    return unit_of_suffix(name, "1")


@dataclass(frozen=True)
class Generated:
    """The Functions of one model, grouped by the C file they go into."""

    prefix: str
    files: dict  # file stem -> tuple of Functions (in generation order)
    signals: dict  # function input/output label -> tuple of element names
    casadi_version: str
    _hashes: dict = field(default_factory=dict, compare=False, repr=False)

    def functions(self):
        for fs in self.files.values():
            yield from fs

    def function(self, name: str) -> ca.Function:
        for f in self.functions():
            if f.name() == name:
                return f
        raise KeyError(name)

    def file_hash(self, stem: str) -> str:
        """SHA-256 of the serialised Functions of one file (its cache key)."""
        if stem in self._hashes:
            return self._hashes[stem]
        h = hashlib.sha256()
        h.update(f"casadi {self.casadi_version}\n".encode())
        for f in self.files[stem]:
            h.update(f.name().encode() + b"\n")
            h.update(f.serialize().encode())
        self._hashes[stem] = h.hexdigest()
        return self._hashes[stem]

    @property
    def model_hash(self) -> str:
        """SHA-256 over the files' hashes (the whole generated model)."""
        h = hashlib.sha256()
        for stem in self.files:
            h.update(f"{stem} {self.file_hash(stem)}\n".encode())
        return h.hexdigest()


def _rename(f: ca.Function, name: str, cse: bool = True, ad: dict | None = None) -> ca.Function:
    """A copy of the SX Function f under another name (same expressions, common subexpressions
    eliminated unless ``cse`` is False: a model on an elevation raster, ``SystemModel.cse``; ``ad``: the
    options of its Jacobians, ``SystemModel.ad_options``)."""
    args = f.sx_in()
    return ca.Function(name, args, f.call(args), f.name_in(), f.name_out(), {"cse": cse, **(ad or {})})


def fixed_step_functions(model, prefix: str):
    """One step of the unrolled Rosenbrock method (:mod:`symtrack.native.rosenbrock`) on the DAE form
    with its error estimate, the consistent z, and chunks of many error-controlled steps per call."""
    x0, z0 = ca.SX.sym("x0", model.x.sparsity()), ca.SX.sym("z0", model.z.sparsity())
    u, p, h = ca.SX.sym("u", model.u.sparsity()), ca.SX.sym("p", model.p.sparsity()), ca.SX.sym("h")
    x1, z1, e1 = rosenbrock.step_and_error_expressions(model.dae, x0, z0, u, p, h,
                                                       getattr(model, "reverse_jacobians", False))
    cse = getattr(model, "cse", True)
    step = ca.Function(f"{prefix}_{FIXED_STEP_METHOD}_step", [x0, z0, u, p, h], [x1, z1, e1],
                       ["x0", "z0", "u", "p", "h"], ["xf", "zf", "ef"], {"cse": cse})
    zc = rosenbrock.consistent_z_expressions(model.dae, x0, z0, u, p)
    consistent = ca.Function(f"{prefix}_consistent_z", [x0, z0, u, p], [zc], ["x", "z0", "u", "p"], ["z"],
                             {"cse": cse})
    return step, consistent, controlled_chunks(model, prefix, step)


def controlled_chunks(model, prefix: str, step: ca.Function):
    """Chunks of error-controlled steps: ``<m>_rosenbrock_controlled_chunk<N>(x0,z0,U,H,p,ctl)->(X,Z,Y,R,NH)``,
    and one such step without the outputs, ``<m>_rosenbrock_controlled_step(x0,z0,u,p,h,ctl)->(xf,zf,r,nh)``.

    Each step of length H[k] is taken, and its error ratio r = max_i |ef_i| / (FIXED_STEP_ATOL +
    rtol max(|x0_i|, |xf_i|)) over the differential states is computed (ctl = (rtol, r_limit)); where
    r > r_limit (or is not a number) the step is replaced by two steps of half its length, each
    controlled the same way, down to 2^-FIXED_STEP_MAX_HALVINGS of H[k] (both in
    :mod:`symtrack.native.rosenbrock`). Column k of R is the
    largest ratio of the steps kept in step k (above r_limit only where the halvings ran out), of
    NH how many steps were halved. The recursion is one C function per depth, each calling the
    one below twice behind a branch (CasADi's ``Function.conditional``): the halvings cost only
    where they are taken. r_limit = inf: no step halved, the ratios measured. A column with H[k] = 0 is
    not computed (a branch: X, Z keep the column before, Y, R, NH are 0)."""
    name = f"{prefix}_{FIXED_STEP_METHOD}"
    X0, Z0 = ca.MX.sym("x0", model.x.sparsity()), ca.MX.sym("z0", model.z.sparsity())
    U, P, H = ca.MX.sym("u", model.u.sparsity()), ca.MX.sym("p", model.p.sparsity()), ca.MX.sym("h")
    ctl = ca.MX.sym("ctl", 2)
    X1, Z1, R = ca.MX.sym("x1", model.x.sparsity()), ca.MX.sym("z1", model.z.sparsity()), ca.MX.sym("r")
    ins, in_names = [X0, Z0, U, P, H, ctl], ["x0", "z0", "u", "p", "h", "ctl"]
    out_names = ["xf", "zf", "r", "nh"]
    # the ratio as one straight-line SX function (its MX form was a loop and a copy per operation)
    xa, xb, ea = (ca.SX.sym(n, model.x.sparsity()) for n in ("xa", "xb", "ea"))
    cs = ca.SX.sym("ctl", 2)
    terms = [ca.fabs(ea[i]) / (rosenbrock.FIXED_STEP_ATOL + cs[0] * ca.fmax(ca.fabs(xa[i]), ca.fabs(xb[i])))
             for i in range(model.nx)]
    rmax = terms[0]
    for t in terms[1:]:
        rmax = ca.fmax(rmax, t)
    ratio = ca.Function(f"{name}_error_ratio", [xa, xb, ea, cs], [rmax], ["x0", "x1", "e1", "ctl"], ["r"])
    below = None
    for depth in reversed(range(rosenbrock.FIXED_STEP_MAX_HALVINGS + 1)):
        x1, z1, e1 = step(X0, Z0, U, P, H)
        r = ratio(X0, x1, e1, ctl)
        if below is None:
            level = ca.Function(f"{name}_controlled{depth}", ins, [x1, z1, r, 0], in_names, out_names)
        else:
            keep = ca.Function(f"{name}_keep{depth}", ins + [X1, Z1, R], [X1, Z1, R, 0],
                               in_names + ["x1", "z1", "r1"], out_names)
            xm, zm, ra, na = below(X0, Z0, U, P, 0.5 * H, ctl)
            xe, ze, rb, nb = below(xm, zm, U, P, 0.5 * H, ctl)
            halve = ca.Function(f"{name}_halve{depth}", ins + [X1, Z1, R], [xe, ze, ca.fmax(ra, rb), 1 + na + nb],
                                in_names + ["x1", "z1", "r1"], out_names)
            branch = ca.Function.conditional(f"{name}_branch{depth}", [keep], halve)
            res = branch(ca.logic_not(r <= ctl[1]), X0, Z0, U, P, H, ctl, x1, z1, r)
            level = ca.Function(f"{name}_controlled{depth}", ins, res, in_names, out_names)
        below = level
    xf, zf, r, nh = below(X0, Z0, U, P, H, ctl)
    # one controlled step without the outputs (the C programs and the FMU: their outputs on demand)
    single = ca.Function(f"{name}_controlled_step", ins, [xf, zf, r, nh], in_names, out_names)
    col_names = ["xf", "zf", "y", "r", "nh"]
    stepped = ca.Function(f"{name}_controlled_column_step", [X0, Z0, U, P, H, ctl],
                          [xf, zf, model.outputs(xf, U, P), r, nh], in_names, col_names)
    # a column of length 0 (a chunk's unused columns: a run's last steps, one communication step of an FMU)
    # costs nothing: a branch around the step, which is the same code as without it
    idle = ca.Function(f"{name}_idle", [X0, Z0, U, P, H, ctl],
                       [X0, Z0, ca.MX.zeros(len(model.output_names), 1), 0, 0], in_names, col_names)
    skip = ca.Function.conditional(f"{name}_step_or_idle", [idle], stepped)
    col = ca.Function(f"{name}_controlled_column", [X0, Z0, U, P, H, ctl], skip(H > 0, X0, Z0, U, P, H, ctl),
                      in_names, col_names)
    chunks = []
    for n in CHUNK_SIZES:
        acc = col.mapaccum(f"{name}_controlled_acc{n}", n, 2)
        Us = ca.MX.sym("U", model.u.numel(), n)
        Hs = ca.MX.sym("H", 1, n)
        Xs, Zs, Ys, Rs, NHs = acc(X0, Z0, Us, ca.repmat(P, 1, n), Hs, ca.repmat(ctl, 1, n))
        chunks.append(ca.Function(f"{name}_controlled_chunk{n}", [X0, Z0, Us, Hs, P, ctl], [Xs, Zs, Ys, Rs, NHs],
                                  ["x0", "z0", "U", "H", "p", "ctl"], ["X", "Z", "Y", "R", "NH"]))
    return [*chunks, single]


# The files, each a group of Functions that is compiled and loaded on its own: a simulation
# builds and compiles only what it uses (the ODE form's Jacobian of the grid terrain is dense).
GROUPS = ("ode", "dae", "outputs", "linearize_outputs", FIXED_STEP_METHOD)
# short function name (after "<prefix>_") -> group
GROUP_OF = {"ode": "ode", "linearize": "ode", "dae": "dae", "accel": "dae", "outputs": "outputs",
            "linearize_outputs": "linearize_outputs", f"{FIXED_STEP_METHOD}_step": FIXED_STEP_METHOD,
            "consistent_z": FIXED_STEP_METHOD,
            f"{FIXED_STEP_METHOD}_controlled_step": FIXED_STEP_METHOD,
            **{f"{FIXED_STEP_METHOD}_controlled_chunk{n}": FIXED_STEP_METHOD for n in CHUNK_SIZES}}


def _group(model, prefix: str, group: str) -> tuple:
    if group == "ode":
        ode = _rename(model.ode, f"{prefix}_ode", getattr(model, "cse", True), getattr(model, "ad_options", None))
        jac_ode = ode.jacobian()  # named jac_<prefix>_ode: casadi.external finds it
        x, u, p = (ca.MX.sym(n, s) for n, s in (("x", model.x.sparsity()), ("u", model.u.sparsity()),
                                                  ("p", model.p.sparsity())))
        J = jac_ode(x, u, p, ca.MX(ode.sparsity_out(0).size1(), 1))
        lin = ca.Function(f"{prefix}_linearize", [x, u, p], [J[0], J[1]], ["x", "u", "p"], ["A", "B"])
        return ode, jac_ode, lin
    if group == "dae":
        cse = getattr(model, "cse", True)
        dae = _rename(model.dae, f"{prefix}_dae", cse, getattr(model, "ad_options", None))
        return dae, dae.jacobian(), _rename(model.accel, f"{prefix}_accel", cse)
    if group == "outputs":
        return (_rename(model.outputs, f"{prefix}_outputs", getattr(model, "cse", True)),)
    if group == "linearize_outputs":
        return (_rename(model.jac_outputs, f"{prefix}_linearize_outputs", getattr(model, "cse", True)),)
    if group == FIXED_STEP_METHOD:
        step, consistent, controlled = fixed_step_functions(model, prefix)
        return step, consistent, *controlled
    raise ValueError(f"unknown group {group!r}; groups: {', '.join(GROUPS)}")


def model_functions(model, prefix: str = "homogeneous", groups=GROUPS) -> Generated:
    """The generated Functions of ``model`` (a SystemModel) in the given groups, with their
    element names."""
    sx, su, sz, sp, sy = (tuple(model.state_names), tuple(model.input_names), tuple(model.alg_names),
                          tuple(model.param_names), tuple(model.output_names))
    signals = {"x": sx, "x0": sx, "xf": sx, "ode": tuple(f"d_{n}_dt" for n in sx), "X": sx,
               "u": su, "U": su, "z": sz, "z0": sz, "zf": sz, "Z": sz, "alg": tuple(f"res_{n}" for n in sz),
               "p": sp, "y": sy, "Y": sy, "h": ("step_s",), "H": ("step_s",),
               "ef": tuple(f"err_{n}" for n in sx), "ctl": ("fixed_step_tolerance", "error_ratio_limit"),
               "R": ("error_ratio",), "NH": ("steps_halved",)}
    files = {f"{prefix}_{g}": _group(model, prefix, g) for g in groups}
    return Generated(prefix, files, signals, ca.__version__)


def _unit_of_signal(label: str, name: str) -> str:
    if label == "ode":
        base = unit_of(name[2:-3])
        if base == "1":
            return "1/s"
        return base + "^2" if base.endswith("/s") else base + "/s"
    return unit_of(name)


def _describe(gen: Generated, f: ca.Function) -> dict:
    def io(label, sp, names):
        d = {"name": label, "shape": [sp.size1(), sp.size2()], "nnz": sp.nnz()}
        if names is not None:
            d["elements"] = [{"name": n, "unit": _unit_of_signal(label, n)} for n in names]
        return d

    def names_for(label):
        return gen.signals.get(label)

    ins = [io(f.name_in(i), f.sparsity_in(i), names_for(f.name_in(i))) for i in range(f.n_in())]
    outs = []
    for i in range(f.n_out()):
        label = f.name_out(i)
        names = names_for(label)
        if names is None:  # Jacobian blocks: rows x columns named by their signals
            outs.append({"name": label, "shape": [f.size1_out(i), f.size2_out(i)], "nnz": f.nnz_out(i),
                         "description": "sparse Jacobian block, column-major (CCS) as in CasADi"})
        else:
            outs.append(io(label, f.sparsity_out(i), names))
    return {"inputs": ins, "outputs": outs}


def manifest(gen: Generated, file_hashes: dict) -> dict:
    funcs = {}
    for stem, fs in gen.files.items():
        for f in fs:
            funcs[f.name()] = {"file": stem + ".c", **_describe(gen, f)}
    return {
        "schema_version": MANIFEST_SCHEMA_VERSION,
        "generator": "python -m codegen (symtrack)",
        "casadi_version": gen.casadi_version,
        "model": gen.prefix,
        "model_hash": gen.model_hash,
        "fixed_step_method": FIXED_STEP_METHOD,
        "chunk_sizes": list(CHUNK_SIZES),
        "model_hash_by_file": {stem + ".c": gen.file_hash(stem) for stem in gen.files},
        "functions": funcs,
        "files": file_hashes,
    }


def write_sources(gen: Generated, out_dir: Path, scratch: Path) -> dict[str, bytes]:
    """Generate every C file of ``gen``; returns file name -> content (not yet in out_dir).

    CasADi's code generator writes into the current folder; it is pointed at ``scratch``.
    """
    out = {}
    for stem, fs in gen.files.items():
        cg = ca.CodeGenerator(stem + ".c", {"with_header": True})
        for f in fs:
            cg.add(f)
        cg.generate(str(scratch) + "/")
        for ext in (".c", ".h"):
            data = (scratch / (stem + ext)).read_bytes()
            if ext == ".c" and b"#error" in data:
                # CasADi writes '#error' for plugins it cannot export; never ship that
                raise RuntimeError(f"{stem}.c contains #error: a component cannot be code-generated")
            out[stem + ext] = data
    return out


def render(gen: Generated, scratch: Path) -> dict[str, bytes]:
    """All files (sources and manifest.json) as name -> bytes."""
    files = write_sources(gen, Path("."), scratch)
    hashes = {n: hashlib.sha256(d).hexdigest() for n, d in sorted(files.items())}
    files["manifest.json"] = (json.dumps(manifest(gen, hashes), indent=1) + "\n").encode()
    return files
