"""The coupled system (vehicle + terrain) frozen into named CasADi Functions.

Like do-mpc's ``setup()``: once built, a :class:`SystemModel` exposes Functions with one
signature, which the integrators, the linearization and the MPC all reuse:

- ``dae(x, z, u, p) -> (ode, alg)``: the semi-explicit DAE; z are the body accelerations, alg
  closes the load-transfer loop exactly (for IDAS);
- ``ode(x, u, p) -> ode``: the ODE form, the loop solved inside the expression by Newton steps
  (for CVODES and for control);
- ``outputs(x, u, p) -> y``: the named outputs of :attr:`output_names`;
- ``jac_ode(x, u, p) -> (A, B)``: the exact Jacobians of ``ode``;
- ``accel(x, u, p) -> z``: the ODE form's accelerations (a consistent z for IDAS).

The vehicle is a vehicle model of :mod:`symtrack.vehicles.registry` (``vehicle=``, default
the planar vehicle, or the one the options need: :func:`~symtrack.vehicles.registry.for_options`);
the state vector's layout is :attr:`SystemModel.layout` (the vehicle's blocks, then the terrain's
``cells``: :mod:`symtrack.model.layout`).

A terrain plugs in through a narrow interface (like Chrono's terrain query):
``state_names``, optional ``param_names`` (its own entries of p, after the vehicle and soil
parameters), ``compaction(xv, xc, P, Q) -> (2,)`` compaction resistance per track (``xv``: the
vehicle's :class:`~symtrack.model.layout.VehicleState`, its states by name and its contact pose
``xv.pose``), and
``equations(xv, xc, dist, P, Q) -> (xc_dot, signals)`` where ``dist`` are the tracks'
:class:`~symtrack.vehicles.planar.PressureDistribution` and ``signals`` must contain
``sinkage_{sprocket,idler}_{left,right}_m`` and ``p_{sprocket,idler}_{left,right}_Pa``.

States, inputs, parameters and outputs are named symbols whose names carry units; the model
holds no numbers except true constants and the numerical options of :class:`ModelOptions`.
"""

from __future__ import annotations

import functools

import casadi as ca

from ..foundations.errors import ParameterError
from ..soil import law as soil_law
from ..vehicles import registry as vehicle_registry
from ..vehicles.base import CONTACT_HULL
from ..vehicles.planar import codegen_options
from ..vehicles.vehicle3d import ContactTerrain
from .homogeneous import HomogeneousTerrain
from .layout import VehicleState
from .options import ModelOptions
from .parameters import model_param_layout

__all__ = ["PARAM_NAMES", "SystemModel"]

# the vehicle and soil parameters of p of the default model (the planar vehicle on the Bekker/Wong law); a
# model's own: SystemModel.model_param_names
PARAM_NAMES = model_param_layout().names


def _syms(names):
    return [ca.SX.sym(n) for n in names]


class SystemModel:
    """The vehicle and a terrain (default: the homogeneous terrain's four travelling cells) frozen
    into named CasADi expressions and Functions (module doc): states ``x`` (``state_names``),
    inputs ``u``, parameters ``p`` (``param_vector`` builds it from a parameter dict), algebraic
    accelerations ``z``, outputs (``output_names``)."""

    def __init__(self, opts: ModelOptions | None = None, terrain=None, vehicle=None):
        self.opts = opts or ModelOptions()
        self.vehicle = vehicle_registry.for_options(self.opts, vehicle)
        vm = self.vehicle
        law = soil_law.get(self.opts.soil_law)
        # p: the vehicle's and the soil's parameters their modules declare (parameters.model_params), then the
        # terrain's own
        self.model_layout = model_param_layout(vehicle=vm, law=law)
        self.model_param_names = self.model_layout.names
        unknown = [n for n in law.param_names if n not in self.model_param_names]
        if unknown:
            raise ParameterError(f"soil law {law.name!r} reads parameters neither it nor the vehicle model "
                                 f"{vm.name!r} declares: {', '.join(unknown)}")
        if vm.contact == CONTACT_HULL:
            # a hull's own contact (the 3D vehicle): its penetration is the sinkage; no travelling cells
            if terrain is not None and not isinstance(terrain, ContactTerrain) and \
                    not hasattr(terrain, "contact_history"):
                cells = [n for n, v in vehicle_registry.REGISTRY.items() if v.contact != CONTACT_HULL]
                raise ParameterError(f"the vehicle model {vm.name!r} (its own contact) takes the homogeneous terrain "
                                     f"or the terrain engine's segment sums only, not the "
                                     f"{getattr(terrain, 'name', terrain)!r} terrain (use model.vehicle = one of "
                                     f"{', '.join(cells)})")
            self.terrain = terrain or ContactTerrain(self.opts)
        else:
            self.terrain = terrain or HomogeneousTerrain(self.opts)
        self.layout = vm.layout.with_cells(self.terrain.state_names)
        self.state_names = self.layout.names
        self.input_names = tuple(vm.input_names)
        self.alg_names = tuple(vm.alg_names)
        n_alg = len(self.alg_names)

        self.terrain_param_names = tuple(getattr(self.terrain, "param_names", ()))
        self.param_names = self.model_param_names + self.terrain_param_names
        xs, us, zs, ps = (_syms(n) for n in (self.state_names, self.input_names, self.alg_names, self.param_names))
        x, u, z, p = (ca.vertcat(*s) for s in (xs, us, zs, ps))
        n_model = len(self.model_layout)
        P = self.model_layout.unpack(ps[:n_model])
        Q = ca.vertcat(*ps[n_model:])
        xv, xc = x[self.layout.block("vehicle")], x[self.layout.block("cells")]
        # what the terrain sees of the vehicle: its states by name and its contact pose
        xs_v = VehicleState(xv, vm.layout, vm.contact_pose(xv))
        compaction = self.terrain.compaction(xs_v, xc, P, Q)
        track_soil = self.terrain.track_soil(xs_v, xc, P, Q) if hasattr(self.terrain, "track_soil") else None

        # the grid under the 3D hull (the terrain engine's segment sums): the soil history under each segment
        history = {"contact_history": self.terrain.contact_history(P, Q)} if hasattr(self.terrain,
                                                                                     "contact_history") else {}
        # the homogeneous terrain under the 3D hull: the soil's memory under each segment (its states)
        if getattr(self.terrain, "memory", False):
            history = {"segment_history": self.terrain.segment_history(xc)}

        def evaluate(acc):
            veh = vm.equations(xv, u, acc, P, compaction, self.opts, track_soil, **history)
            cdot, csig = self.terrain.equations(xs_v, xc, veh["dist"], P, Q)
            return veh, ca.vertcat(veh["xdot"], cdot), csig

        # DAE form: the accelerations are algebraic variables.
        veh_z, ode_z, _ = evaluate(z)
        alg = z - veh_z["acc_implied"]
        # ODE form: the load-transfer loop a = g(x, a) solved inside the expression by one
        # fixed-point step from a = 0 and then Newton steps on a - g(x, a) (a 2x2 system).
        gz = veh_z["acc_implied"]
        G = ca.Function("G", [z, x, u, p], [gz, ca.jacobian(gz, z)])
        acc = G(ca.DM.zeros(n_alg), x, u, p)[0]
        for _ in range(self.opts.accel_newton_iterations):
            g, dg = G(acc, x, u, p)
            acc = acc - ca.solve(ca.DM.eye(n_alg) - dg, acc - g)
        veh, ode, csig = evaluate(acc)

        signals = dict(veh["signals"])
        signals.update(csig)
        for i, name in enumerate(self.alg_names):
            signals[name] = acc[i]
        signals["yaw_moment_N_m"] = veh["yaw_moment_N_m"]
        if "pitch_rad" not in signals:  # the planar vehicle: pitch from the sinkages (the 3D: its state)
            pitch = 0
            tracks = vm.tracks
            for k in tracks:
                pitch += (signals[f"sinkage_sprocket_{k}_m"] - signals[f"sinkage_idler_{k}_m"]) / len(tracks)
            signals["pitch_rad"] = pitch / P["contact_length_m"]
        self.output_names = tuple(signals)
        y = ca.vertcat(*signals.values())

        self.x, self.z, self.u, self.p = x, z, u, p
        self.ode_expr, self.alg_expr, self.ode_dae_expr = ode, alg, ode_z
        self._y_expr, self._acc_expr = y, acc

    # The model's Functions are built on first use: each construction eliminates the common subexpressions
    # of its whole expression graph (``cse``), most of a model's build (measured with CasADi 3.8: the shear
    # law's 192-channel model 1.48 s with the four built, 0.20 s without), and most paths use two or three
    # of the four (the terrain engine none, CVODES no ``dae``, IDAS no ``ode``).
    def _function(self, name, inputs, outputs, names_in, names_out) -> ca.Function:
        return ca.Function(name, inputs, outputs, names_in, names_out, {"cse": self.cse, **self.ad_options})

    @functools.cached_property
    def dae(self) -> ca.Function:
        """(x, z, u, p) -> (ode, alg): the DAE form, the accelerations z algebraic."""
        return self._function("dae", [self.x, self.z, self.u, self.p], [self.ode_dae_expr, self.alg_expr],
                              ["x", "z", "u", "p"], ["ode", "alg"])

    @functools.cached_property
    def ode(self) -> ca.Function:
        """(x, u, p) -> ode: the ODE form, the accelerations solved inside the expression."""
        return self._function("ode", [self.x, self.u, self.p], [self.ode_expr], ["x", "u", "p"], ["ode"])

    @functools.cached_property
    def outputs(self) -> ca.Function:
        """(x, u, p) -> y: the outputs (:attr:`output_names`)."""
        return self._function("outputs", [self.x, self.u, self.p], [self._y_expr], ["x", "u", "p"], ["y"])

    @functools.cached_property
    def accel(self) -> ca.Function:
        """(x, u, p) -> z: the accelerations of the ODE form (a consistent start of the DAE's z)."""
        return self._function("accel", [self.x, self.u, self.p], [self._acc_expr], ["x", "u", "p"], ["z"])

    @property
    def cse(self) -> bool:
        """Whether the model's Functions eliminate common subexpressions (CasADi's ``cse``): yes, unless the
        vehicle's ground is an elevation raster: CSE hashes each call node to the raster's interpolant with
        its data (measured: 100 call nodes to a 300 x 100 raster's B-spline, 2.9 s). The 3D vehicle evaluates
        the raster through one mapped call (``Vehicle3D.grounds``: 2 call nodes in ``dae``, 58 in its
        Jacobian, 74 in the unrolled Rosenbrock step with 8 segments a track, where there were 96, 5,376 and
        3,936), and CSE still costs more than it saves: it took the build of the generated ``dae`` and
        Rosenbrock files from 0.3 s to 1.5 s on a 60 x 60 raster, to 6.6 s on 200 x 200 and to 64 s on
        600 x 600 (growing with the pixels), paid on every run (the build cache's key is taken from the
        built Functions), for 4.5 s of gcc's CPU at -O0 paid once (measured with CasADi 3.8 on 2 cores)."""
        surface = getattr(self.vehicle, "surface", None)
        return getattr(surface, "raster", None) is None

    @property
    def reverse_jacobians(self) -> bool:
        """Whether the model's Jacobians are taken in CasADi's reverse mode (one sweep per colour of their
        rows) rather than its default choice, forward mode here (one sweep per colour of their columns):
        yes when the vehicle's ground is an elevation raster. Every sweep passes through each call node to
        the raster (the forward mode's too, where the seed of the pose's states is zero): the DAE's
        Jacobian in reverse mode has 58 call nodes and 92,000 SX instructions where the forward mode had
        112 and 166,000, the Rosenbrock step's 113,000 where it had 146,000 (8 segments a track), and
        gcc's CPU for the generated dae and Rosenbrock files at -O1 is 46 s instead of 54 s (13 s instead
        of 18 s at -O0). The same Jacobians to rounding (1e-14 of their largest entry, measured with CasADi
        3.8). Without a raster the model keeps the default (the same expressions as before)."""
        surface = getattr(self.vehicle, "surface", None)
        return getattr(surface, "raster", None) is not None

    @property
    def ad_options(self) -> dict:
        """The model's Functions' options for their Jacobians (:attr:`reverse_jacobians`: ``ad_weight`` 1,
        reverse mode), empty otherwise."""
        return {"ad_weight": 1.0} if self.reverse_jacobians else {}

    @property
    def jacobian_options(self) -> dict:
        """The options of ``casadi.jacobian`` on the model's expressions (:attr:`reverse_jacobians`:
        ``allow_forward`` False, reverse mode), empty otherwise."""
        return {"allow_forward": False} if self.reverse_jacobians else {}

    # The Jacobian Functions are built on first use: for the grid terrain the ODE form's
    # Jacobian is dense (see symtrack/terrain/channels.py) and costly to build, and the
    # simulation does not need it. Without CasADi's cse: they are evaluated at a few points (a trim's
    # linearisation, a check), where eliminating the common subexpressions of the whole Jacobian cost 30 x
    # what it saves (measured with CasADi 3.8 on the shear law's model: jac_ode 1.54 s to build with cse,
    # 0.05 s without, 1 ms an evaluation either way, the same numbers to the last bit: cse merges identical
    # operations on identical operands). The generated C of jac_outputs (native/generate.py, ``_rename``) is
    # built with cse from it, the same C as from a Function built with cse (compared on the shear, creep and
    # 3D models).
    @functools.cached_property
    def jac_ode(self) -> ca.Function:
        x, u, p, ode = self.x, self.u, self.p, self.ode_expr
        jo = self.jacobian_options
        return ca.Function("jac_ode", [x, u, p], [ca.jacobian(ode, x, jo), ca.jacobian(ode, u, jo)],
                           ["x", "u", "p"], ["A", "B"], {"cse": False})

    @functools.cached_property
    def jac_outputs(self) -> ca.Function:
        x, u, p, y = self.x, self.u, self.p, self._y_expr
        jo = self.jacobian_options
        return ca.Function("jac_outputs", [x, u, p], [ca.jacobian(y, x, jo), ca.jacobian(y, u, jo)],
                           ["x", "u", "p"], ["C", "D"], {"cse": False})

    @functools.cached_property
    def codegen_twin(self) -> SystemModel:
        """The model to generate C from: this one, or, when its tracks' quadrature is large
        (:func:`~symtrack.vehicles.planar.codegen_options`), the same
        vehicle and terrain with ``ModelOptions.quadrature_call`` set: the same Functions (names,
        signatures, values) with the quadrature summed by one call node, whose C does not grow with
        the points. Not for CasADi's interpreter (CVODES, IDAS): it evaluates a call node slowly."""
        twin_opts = codegen_options(self.opts)
        if twin_opts == self.opts:
            return self
        return SystemModel(twin_opts, self.terrain, self.vehicle)

    @property
    def nx(self):
        return len(self.state_names)

    def state_index(self, name: str) -> int:
        return self.layout.index(name)

    def output_index(self, name: str) -> int:
        return self.output_names.index(name)

    def param_vector(self, values: dict, terrain_values=None) -> list[float]:
        """The parameter vector p: vehicle and soil values by name (:attr:`model_layout`), then the
        terrain's own parameters (empty for the homogeneous terrain) as a flat sequence."""
        out = self.model_layout.pack(values)
        if self.terrain_param_names:
            if terrain_values is None or len(terrain_values) != len(self.terrain_param_names):
                raise ValueError(f"the {self.terrain.name} terrain needs {len(self.terrain_param_names)} values")
            out += [float(v) for v in terrain_values]
        return out
