"""The CasADi side of the terrain engine (:mod:`symtrack.terrain.engine`): the equations the
engine's hot path evaluates, as small SX Functions built from the project's symbolic model.

The engine integrates the vehicle and the active cells *staggered* over each macro step
(docs/terrain.md, "The terrain engine"): the vehicle first, with the terrain's channel sums
held at their values at the step start, then every active cell on its own, with its load
interpolated between the step's two poses. So the Functions are:

- ``eng_vehicle_step(w[14], u[2], pv, h) -> (w1[14], a1[8], e1[14])``: w = the 12 vehicle states and the
  two body accelerations of the DAE form (the load-transfer loop as algebraic equations, as IDAS
  sees it); the accelerations made consistent with the channel sums (two Newton steps), then
  ``vehicle_substeps`` steps of the 8-stage, order-5, L-stable Rosenbrock method of CasADi's
  ``rosenbrock`` plugin (the tableau of :mod:`symtrack.native.rosenbrock`) with the exact Jacobian, and
  the pressure line ``a`` of both tracks at the end state. ``pv`` = vehicle and soil parameters,
  the terrain's two globals (cell size, end strip) and the 10 channel sums S (:data:`SUM_NAMES`).
  ``e1``: the last stage's increment, the method's error estimate (the difference from its embedded
  solution), which grid_engine.c's ``vehicle_step_controlled`` compares with
  ``EngineSettings.vehicle_tolerance``.
- ``eng_vehicle_a(w[14], pv) -> a[8]``: a = (X, Y, cos psi, sin psi, alpha_L, beta_L, alpha_R,
  beta_R) with each track's pressure p(s) = max(0, alpha + beta s) (the linear and both
  triangular distributions of :class:`~symtrack.vehicles.planar.PressureDistribution` are of
  this form).
- ``eng_outputs(x[12], u[2], pv) -> y``: the model's outputs (same names and order as the
  channel model's) from the vehicle state and the channel sums.
- ``eng_cell_geo(c[2], a[8], geo[7]) -> g[7]``: one cell's load p_load = sum_k frac_k
  p_k(s_mid,k), its overlap fractions (left, right) and its four end-strip weights, from
  :func:`symtrack.terrain.channels.build_cell_functions`'s geometry.
- ``eng_cell_law_<v>(z, hist[5], law) -> (p, dp/dz)``: the reaction pressure of the model's soil law
  (:mod:`symtrack.soil.law`) and its exact derivative (the Newton iteration of each implicit stage),
  written by branch (the law's ``pressure_and_slope``); hist = (z_max, p_max, z_off, delta, d_c), the
  cycle law's history; ``law`` the soil's law row (:func:`law_row`: the law vector, then the
  repeated-loading exponent), an input, so one build of the engine runs every soil of the law: the
  C holds a table of the rows (eng_t.soil_law, one per soil of the field) and passes the cell's soil's.
  v = 0 is the general law; v >= 1 the law's specialised copies
  (:attr:`~symtrack.soil.law.SoilLaw.engine_specialisations`), with some entries of the row fixed as
  numbers, which the C runs for a soil whose row has those values (a test of the row at run time). The
  Bekker/Wong law has one, n = 0.5: its regularised Bekker term k z+ (z+ + d)^(n-1) written
  k z+ / sqrt(z+ + d) (the same number; libm's pow is about 20 x slower than sqrt).
- ``eng_cell_history(z, p, hist[5], law) -> (z_max', p_max', d_c', plastic, phase)``: the law's
  ``history_update`` (INFO_OUT).
- ``eng_cell_entry(z, hist[5], cycles, law) -> delta``: the law's ``cycle_increment`` with the soil's
  repeated-loading exponent (INFO_IN).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re

import casadi as ca
import numpy as np

from ..foundations.errors import ParameterError
from ..foundations.params import ParamLayout
from ..model import SystemModel
from ..model.layout import StateLayout
from ..soil import law as soil_law
from ..terrain.channels import (
    COMPACTION_SPEED_FLOOR_M_S,
    GEO_LAYOUT,
    GLOBAL_FIELDS,
    NF,
    NG,
    NH,
    build_cell_functions,
)
from ..toolchain import digest
from ..vehicles import registry as vehicle_registry
from ..vehicles.base import CONTACT_HULL
from ..vehicles.planar import ALGEBRAIC, ENDS, PLANAR_LAYOUT, TRACK_SOIL_PARAM_NAMES, TRACKS
from ..vehicles.vehicle3d import hull_rotation
from .rosenbrock import GAMMA as RB_GAMMA
from .rosenbrock import N_STAGES as RB_STAGES
from .rosenbrock import A as RB_A
from .rosenbrock import C as RB_C
from .rosenbrock import M as RB_M

NA = 8
NS = 10
NGEO = len(GEO_LAYOUT)
# the engine's vehicle is the planar one: w = its states and its algebraic accelerations (the C reads
# ENG_NV and ENG_NW: engine_layout_c); NW of the default vehicle (the "shear" law's has two
# more: EngineFunctions.nw)
NW = PLANAR_LAYOUT.nv + len(ALGEBRAIC)


def _sum_names():
    names = [f"sum_power_{k}" for k in TRACKS]
    names += [f"sum_wz_{end}_{k}" for k in TRACKS for end in ENDS]
    names += [f"sum_w_{end}_{k}" for k in TRACKS for end in ENDS]
    return tuple(names)


SUM_NAMES = _sum_names()
# with a soil map: per track the load fraction and the load-fraction-weighted soil coefficients the
# vehicle's traction reads (the planar vehicle's soil_params: cohesion, friction angle, shear modulus)
# of the cells under it (the traction uses their means); per soil of the field their values are the
# engine's soil_veh (C: ENG_TRACK_SOIL_*, ENG_N_TRACK_SOIL)
TRACK_SOIL_LAYOUT = ParamLayout(TRACK_SOIL_PARAM_NAMES)
SOIL_SUM_NAMES = tuple(f"sum_f_{k}" for k in TRACKS) + tuple(
    f"sum_f_{name}_{k}" for k in TRACKS for name in TRACK_SOIL_LAYOUT)
NS_SOIL = len(SOIL_SUM_NAMES)


class SumsTerrain:
    """The grid terrain seen from the vehicle: the channel sums S as parameters, no states.
    ``soil_sums``: the field's soil varies (a soil map): the sums also carry the soil under each
    track (:data:`SOIL_SUM_NAMES`) and the traction uses it (:meth:`track_soil`)."""

    name = "channel_sums"

    def __init__(self, soil_sums: bool = False):
        self.state_names = ()
        self.names = SUM_NAMES + (SOIL_SUM_NAMES if soil_sums else ())
        self.param_names = GLOBAL_FIELDS + self.names
        self.soil_sums = soil_sums
        self.dist_dae = None  # the pressure distributions of the DAE form (the first evaluation)
        if soil_sums:
            self.track_soil = self._track_soil

    def _S(self, Q):
        return {n: Q[NG + i] for i, n in enumerate(self.names)}

    def _track_soil(self, xv, xc, P, Q):
        """track -> (c, phi, K): the load-fraction-weighted means over the cells under the track
        (the scenario's soil where no cell is under it)."""
        S = self._S(Q)
        out = {}
        for k in TRACKS:
            f = S[f"sum_f_{k}"]
            out[k] = tuple(ca.if_else(f > 1e-12, S[f"sum_f_{n}_{k}"] / ca.fmax(f, 1e-12), P[n])
                           for n in TRACK_SOIL_LAYOUT)
        return out

    def compaction(self, xv, xc, P, Q):
        S = self._S(Q)
        B = P["track_gauge_m"]
        u, r = xv["u_m_s"], xv["yaw_rate_rad_s"]
        v_track = {"left": u - r * B / 2, "right": u + r * B / 2}
        area = Q[0] ** 2
        return ca.vertcat(*(area * S[f"sum_power_{k}"] / ca.sqrt(v_track[k] ** 2 + COMPACTION_SPEED_FLOOR_M_S**2)
                            for k in TRACKS))

    def equations(self, xv, xc, dist, P, Q):
        if self.dist_dae is None:
            self.dist_dae = dist
        S = self._S(Q)
        signals = {}
        for k in TRACKS:
            for end in ENDS:
                signals[f"sinkage_{end}_{k}_m"] = S[f"sum_wz_{end}_{k}"] / (S[f"sum_w_{end}_{k}"] + 1e-9)
                signals[f"p_{end}_{k}_Pa"] = getattr(dist[k], end)
        signals["compaction_power_W"] = Q[0] ** 2 * (S["sum_power_left"] + S["sum_power_right"])
        return ca.SX(0, 1), signals


# the 3D vehicle on the grid (docs/vehicle3d.md, "The grid under the 3D vehicle"): per track and
# segment, the sums over the cells under it (weights: the cell's load fraction under the track times
# the hat function of its position along the track about the segment's centre) of the weight and of
# the weight times the cell's sinkage and its soil history (soil_law.HISTORY_NAMES), grid_engine.c's
# seg_sums (this order: index ((track n + segment) SEG_NF + field))
SEG_FIELDS = ("w", "z", "zmax", "pmax", "zoff", "delta", "dc")
SEG_NF = len(SEG_FIELDS)
# a segment whose weight is below this has no cell under it: its history is the virgin soil's
SEG_WEIGHT_FLOOR = 1e-9


def segment_sum_names(n_seg: int) -> tuple[str, ...]:
    return tuple(f"sum_seg_{f}_{k}_{i}" for k in TRACKS for i in range(n_seg) for f in SEG_FIELDS)


class SegmentSumsTerrain(SumsTerrain):
    """The grid terrain seen from the 3D vehicle (:class:`~symtrack.vehicles.vehicle3d.Vehicle3D`): the
    planar sums (the cells' compaction power per track, the end strips) and per segment of each
    track the load-weighted means of the cells' sinkage and history (:data:`SEG_FIELDS`), so each
    segment's pressure is the soil law on the history of the cells under it (:meth:`contact_history`;
    the ruts of an earlier pass are its reload line) and the compaction resistance is the cells' work."""

    def __init__(self, n_seg: int):
        super().__init__(soil_sums=False)
        self.n_seg = int(n_seg)
        self.names = SUM_NAMES + segment_sum_names(self.n_seg)
        self.param_names = GLOBAL_FIELDS + self.names

    def _mean(self, S, field, k, i):
        w = S[f"sum_seg_w_{k}_{i}"]
        return S[f"sum_seg_{field}_{k}_{i}"] / ca.fmax(w, SEG_WEIGHT_FLOOR)

    def contact_history(self, P, Q):
        """track -> per segment (z_max, p_max, z_off, delta, d_c): the weighted means of the cells
        under it (all 0, the virgin soil's, where no cell is)."""
        S = self._S(Q)
        return {k: [tuple(self._mean(S, f, k, i) for f in SEG_FIELDS[2:]) for i in range(self.n_seg)]
                for k in TRACKS}

    def equations(self, xv, xc, dist, P, Q):
        if self.dist_dae is None:
            self.dist_dae = dist
        S = self._S(Q)
        signals = {}
        # the cells' sinkage (the end strips, as the planar engine's sinkage outputs) beside the hull's
        # penetration (the vehicle's sinkage_* outputs), and the mean of the cells under each end segment
        for k in TRACKS:
            for end in ENDS:
                signals[f"cell_sinkage_{end}_{k}_m"] = S[f"sum_wz_{end}_{k}"] / (S[f"sum_w_{end}_{k}"] + 1e-9)
            for end, i in (("idler", 0), ("sprocket", self.n_seg - 1)):
                signals[f"cell_sinkage_segment_{end}_{k}_m"] = self._mean(S, "z", k, i)
        signals["compaction_power_W"] = Q[0] ** 2 * (S["sum_power_left"] + S["sum_power_right"])
        return ca.SX(0, 1), signals


def piecewise_linear(p, l, s):
    """The pressure at s of n equal segments' pressures ``p`` at their centres over a contact of length
    ``l``: linear between the centres, constant beyond the first and the last (the value of
    :meth:`SegmentDistribution.at <symtrack.vehicles.vehicle3d.SegmentDistribution.at>`), written as
    p_0 + sum_j (p_j+1 - p_j) clamp((s - s_j) / ds, 0, 1): n - 1 clamps, where the hat functions cost n
    absolute values, clamps and branches (the engine evaluates it for every loaded cell)."""
    n = len(p)
    if n == 1:
        return p[0]
    u = s * (n / l) - 0.5  # the position in segments from the first centre
    out = p[0]
    for j in range(n - 1):
        out = out + (p[j + 1] - p[j]) * ca.fmin(ca.fmax(u - j, 0), 1)
    return out


def least_squares_line(dist):
    """(alpha, beta): the least-squares line p = alpha + beta s through a
    :class:`~symtrack.vehicles.vehicle3d.SegmentDistribution`'s segment pressures
    (:meth:`~symtrack.vehicles.vehicle3d.SegmentDistribution.least_squares_line`: at the centres of equal
    segments its integral over the contact is the pieces' own, the load is kept). The subsoil stress
    takes it (subsoil.h's strip tables are for a linear line per track)."""
    return dist.least_squares_line()


def pressure_line(dist):
    """(alpha, beta) with the track's pressure p(s) = max(0, alpha + beta s) on the contact."""
    b, l, N = dist.b, dist.l, dist.N
    a_lin, b_lin = dist.p_mean + dist.slope * l / 2, -dist.slope
    Af = 2 * N / (b * dist.Lc_front)
    Ar = 2 * N / (b * dist.Lc_rear)
    a_f, b_f = Af, -Af / dist.Lc_front
    a_r, b_r = Ar * (1 - l / dist.Lc_rear), Ar / dist.Lc_rear
    alpha = ca.if_else(dist.e_r > l / 6, a_f, ca.if_else(dist.e_r < -l / 6, a_r, a_lin))
    beta = ca.if_else(dist.e_r > l / 6, b_f, ca.if_else(dist.e_r < -l / 6, b_r, b_lin))
    return alpha, beta


def _lu_solve_factory(A):
    """Doolittle LU of a small dense SX matrix without pivoting (I - gamma h J is close to the
    identity at the vehicle's steps) and a solve that reuses it."""
    n = A.shape[0]
    L = [[None] * n for _ in range(n)]
    U = [[A[i, j] for j in range(n)] for i in range(n)]
    for k in range(n):
        for i in range(k + 1, n):
            f = U[i][k] / U[k][k]
            L[i][k] = f
            for j in range(k + 1, n):
                U[i][j] = U[i][j] - f * U[k][j]

    def solve(b):
        y = [b[i] for i in range(n)]
        for i in range(n):
            for k in range(i):
                y[i] = y[i] - L[i][k] * y[k]
        x = [None] * n
        for i in reversed(range(n)):
            s = y[i]
            for j in range(i + 1, n):
                s = s - U[i][j] * x[j]
            x[i] = s / U[i][i]
        return ca.vertcat(*x)

    return solve


@dataclasses.dataclass(frozen=True)
class EngineFunctions:
    vehicle_step: ca.Function
    vehicle_a: ca.Function
    outputs: ca.Function
    cell_geo: ca.Function
    cell_law: tuple  # eng_cell_law_<v>: the general law (v = 0), then one per law_variants entry
    cell_history: ca.Function
    cell_entry: ca.Function
    output_names: tuple
    param_layout: ParamLayout  # the vehicle and soil parameters at the head of pv (SystemModel.model_layout)
    n_pv: int
    n_sums: int  # NS, or NS + NS_SOIL with a soil map
    layout: StateLayout = PLANAR_LAYOUT  # the vehicle's states (w = these, then its accelerations)
    na: int = NA  # the length of a: 8, or 8 + 2 n_seg for the 3D vehicle (its segment pressures)
    n_seg: int = 0  # the 3D vehicle's segments per track (0: the planar vehicle)
    soil_law_model: soil_law.SoilLaw | None = None  # the law the cell Functions evaluate (its rows: law_row)
    # cell_law[v], v >= 1: the law with these entries of the law row fixed, ((index, value), ...)
    law_variants: tuple = ()

    @property
    def nw(self) -> int:
        """The length of w: the vehicle's states and its algebraic accelerations."""
        return self.layout.nv + len(ALGEBRAIC)

    @property
    def law_size(self) -> int:
        """The length of a soil's law row (:func:`law_row`): the law vector and the repeated-loading exponent."""
        return self.soil_law_model.size + len(LAW_ROW_EXTRA)

    def law_row(self, params: dict) -> list[float]:
        """The row of the soil ``params`` in the engine's law table (:func:`law_row`)."""
        return law_row(self.soil_law_model, params)

    def law_table(self, soils) -> np.ndarray:
        """The engine's law table: one :meth:`law_row` per soil of ``soils`` (soil index order), (n, law_size)."""
        return np.array([self.law_row(sp) for sp in soils], dtype=float).reshape(len(soils), self.law_size)

    def law_variant(self, row) -> int:
        """The law Function a soil's row runs (the C's ENG_LAW_CALL): the first variant whose fixed
        entries the row has, else 0, the general law."""
        return law_variant(self.law_variants, row)

    def law(self, z, hist, row):
        """(p, dp/dz) of the law at sinkage z on history ``hist`` for the soil of law row ``row``, by the
        variant that soil runs (as grid_engine.c's law())."""
        return self.cell_law[self.law_variant(row)](z, hist, row)

    def all(self):
        return (self.vehicle_step, self.vehicle_a, self.outputs, self.cell_geo, *self.cell_law, self.cell_history,
                self.cell_entry)

    @functools.cached_property
    def serial_digest(self) -> str:
        """SHA-256 of the serialised Functions (:meth:`all`), the Functions' part of the engine library's
        cache key: computed once per EngineFunctions (serialising the vehicle step's Functions takes a
        good part of a second, and every engine on these Functions asks for the key)."""
        return digest(*(f.serialize() for f in self.all()))


# the entries of a soil's law row after its law vector (SoilLaw.vector_names)
LAW_ROW_EXTRA = ("repeated_loading_exponent",)


def law_row(sl: soil_law.SoilLaw, params: dict) -> list[float]:
    """A soil's row of the engine's law table (eng_t.soil_law): the law vector of ``sl`` for the soil
    ``params`` (:meth:`~symtrack.soil.law.SoilLaw.values`) and its :data:`LAW_ROW_EXTRA` (the cycle
    law's exponent)."""
    return sl.values(params) + [float(params[n]) for n in LAW_ROW_EXTRA]


def law_variants(sl: soil_law.SoilLaw) -> tuple:
    """The law's specialised copies for the engine (:attr:`~symtrack.soil.law.SoilLaw.engine_specialisations`)
    as ((index in the law row, value), ...) per copy."""
    out = []
    for spec in sl.engine_specialisations:
        fixed = []
        for name, value in spec.items():
            if name not in sl.vector_names:
                raise ValueError(f"soil law {sl.name!r}: engine_specialisations names {name!r}, not an entry of "
                                 f"its law vector {sl.vector_names}")
            if not math.isfinite(float(value)):
                raise ValueError(f"soil law {sl.name!r}: engine_specialisations {name} = {value!r} is not finite")
            fixed.append((sl.vector_names.index(name), float(value)))
        out.append(tuple(fixed))
    return tuple(out)


def law_variant(variants: tuple, row) -> int:
    """The index of the law Function for ``row`` (EngineFunctions.law_variant)."""
    for v, fixed in enumerate(variants, start=1):
        if all(float(row[i]) == value for i, value in fixed):
            return v
    return 0


def build_engine_functions(opts, params: dict, vehicle_substeps: int, soils: tuple = (),
                           surface=None) -> EngineFunctions:
    """The Functions of the module doc for model options ``opts``; ``params``, the scenario's vehicle
    and soil, and ``soils``, with a soil map the parameter dicts of every soil of the field (index 0 the
    scenario's), give no number to the Functions (the soils' values are the engine's law table and pv,
    at run time): several soils only make the sums carry the soil under each track.
    The vehicle is the one ``opts.vehicle`` names (:func:`symtrack.vehicles.registry.for_options`); with
    a hull of its own (the 3D vehicle, ``opts.vehicle = "3d"``) it is the hull on the ground ``surface``
    (None: flat) over :class:`SegmentSumsTerrain`; its ``a`` is the pose, the least-squares line of each track
    (the subsoil's) and then the segment pressures (n per track, left then right), and
    ``eng_cell_geo`` loads a cell with the piecewise-linear pressure between segment centres."""
    soils = tuple(soils) or (params,)
    n_seg = 0
    vehicle = vehicle_registry.for_options(opts, surface=surface)
    vehicle_registry.check_plant(vehicle, "engine")
    if vehicle.contact == CONTACT_HULL:
        if len(soils) > 1:
            raise ParameterError(f"model.vehicle = {vehicle.entry_name!r} on the grid takes one soil: a soil map "
                                 "(terrain.soil_map, terrain.moisture) is not coupled to its hull's segments")
        n_seg = opts.contact_segments
        terr = SegmentSumsTerrain(n_seg)
    else:
        terr = SumsTerrain(soil_sums=len(soils) > 1)
    veh = SystemModel(opts, terr, vehicle=vehicle)
    x, zacc, u, pv = veh.x, veh.z, veh.u, veh.p
    dist = terr.dist_dae
    D, Dseg = [], []
    for k in TRACKS:
        D += list(pressure_line(dist[k]) if not n_seg else least_squares_line(dist[k]))
        if n_seg:
            Dseg += list(dist[k].p)
    na = NA + 2 * n_seg
    w = ca.vertcat(x, zacc)
    pose = veh.vehicle.contact_pose(x[veh.layout.block("vehicle")])
    ax, ay = pose.x_m, pose.y_m
    if n_seg:
        # the 3D hull: the cells' frame is centred below the CG on the tracks' ground line, (0, 0, -h) in
        # the body placed by the hull's pitch and roll (on a side slope of t the tracks' contact lies
        # h sin t across from the CG: 7 cm at 5 deg), so the cells loaded are those under the segments
        Rz, Rpr = hull_rotation(pose.yaw_rad, pose.pitch_rad, pose.roll_rad)
        foot = ca.mtimes(ca.mtimes(Rz, Rpr), ca.vertcat(0, 0, -pv[veh.param_names.index("cg_height_m")]))
        ax, ay = ax + foot[0], ay + foot[1]
    a = ca.vertcat(ax, ay, ca.cos(pose.yaw_rad), ca.sin(pose.yaw_rad), *D, *Dseg)
    # common subexpressions merged (CasADi's cse), except over an elevation raster's interpolant: cse hashes
    # each call node to it with the raster's data. With a call per segment the merge of eng_vehicle_step took
    # 83 s of the plant's build (a 200 x 100 raster, measured 2026-12-04); with the contact's points in one
    # mapped call (Vehicle3D.grounds: 15 call nodes in eng_vehicle_step, 297 before) the merge of these
    # Functions still took 15 s against 1 s without, for 2 s of gcc's CPU saved at -O0 (docs/vehicle3d.md,
    # "An elevation raster on the grid")
    raster = getattr(surface, "raster", None) if n_seg else None
    fo, fo_vehicle = {"cse": True}, {"cse": raster is None}
    vehicle_a = ca.Function("eng_vehicle_a", [w, pv], [a], ["w", "pv"], ["a"], fo_vehicle)
    outputs = ca.Function("eng_outputs", [x, u, pv], [veh.outputs(x, u, pv)], ["x", "u", "pv"], ["y"], fo_vehicle)

    # The 8-stage, order-5, L-stable, stiffly accurate Rosenbrock method of CasADi 3.8's plugin
    # (symtrack/native/rosenbrock.py's tableau) on the time-scaled DAE F = (h f, alg), unit step,
    # mass M = diag(1 (12), 0 (2)): W U_i = F(w0 + sum a_ij U_j) + M sum c_ij U_j, W = M / gamma - dF/dw,
    # w1 = w0 + sum m_i U_i. (ROS2, order 2, was measured first: docs/terrain.md.)
    h = ca.SX.sym("h")
    hs = h / vehicle_substeps
    hsym = ca.SX.sym("hs")
    Fh = ca.vertcat(hsym * veh.ode_dae_expr, veh.alg_expr)
    # the stages call F and J as functions of their own (call nodes, never inlined): writing the DAE out
    # at the eight stages of every substep made eng_vehicle_step one C function of 36,000 lines per
    # substep, whose register allocation took gcc -O1 most of the engine's build (the shear law's
    # engine with 2 substeps: 30.6 s of gcc CPU, 5.8 s with the calls; the same arithmetic to rounding:
    # validation_grid's states within 4e-14 m). Measured with the sources the build writes (the
    # BuildSpec's sources() in a folder) and `gcc <the build's flags> -c engine.c` under /usr/bin/time.
    # (cse over a raster's interpolant call nodes as for eng_vehicle_step: 68 s of CPU in CasADi's cse
    # for eng_vehicle_J alone over a 200 x 100 raster with a call per segment, measured 2026-12-06; with the
    # mapped call, above)
    call = {"cse": raster is None, "never_inline": True}
    fF = ca.Function("eng_vehicle_F", [w, u, pv, hsym], [Fh], call)
    # (in reverse mode on a raster: SystemModel.reverse_jacobians)
    fJ = ca.Function("eng_vehicle_J", [w, u, pv, hsym], [ca.jacobian(Fh, w, veh.jacobian_options)], call)
    mass = ca.DM.zeros(veh.layout.nv + len(ALGEBRAIC))
    vs = veh.layout.block("vehicle")
    mass[vs] = 1.0
    g = veh.alg_expr
    Jg = ca.jacobian(g, zacc)
    # the accelerations first made consistent with the (new) channel sums: two Newton steps
    ws = w
    for _ in range(2):
        gz = ca.substitute(g, w, ws)
        ws = ca.vertcat(ws[vs], ws[vs.stop:] - ca.solve(ca.substitute(Jg, w, ws), gz))
    for _ in range(vehicle_substeps):
        Wm = ca.diag(mass) / RB_GAMMA - fJ(ws, u, pv, hs)
        solve = _lu_solve_factory(Wm)
        Us = []
        for i in range(RB_STAGES):
            wi = ws
            for j, aij in enumerate(RB_A[i]):
                if aij != 0.0:
                    wi = wi + aij * Us[j]
            r = fF(wi, u, pv, hs)
            for j, cij in enumerate(RB_C[i]):
                if cij != 0.0:
                    r = r + cij * (mass * Us[j])
            Us.append(solve(r))
        for mi, Ui in zip(RB_M, Us, strict=True):
            ws = ws + mi * Ui
    vehicle_step = ca.Function("eng_vehicle_step", [w, u, pv, h], [ws, vehicle_a(ws, pv), Us[-1]],
                               ["w", "u", "pv", "h"], ["w1", "a1", "e1"], fo_vehicle)

    # one cell: load and weights
    fn = build_cell_functions(opts, cell_reciprocal=True)
    c = ca.SX.sym("c", 2)
    av = ca.SX.sym("a", na)
    geo = ca.SX.sym("geo", 7)
    ddx, ddy = c[0] - av[0], c[1] - av[1]
    qb = ca.vertcat(av[2] * ddx + av[3] * ddy, -av[3] * ddx + av[2] * ddy, 0, 0, 1, ca.DM.zeros(NF - 5))
    g = fn["geometry"](qb, ca.DM.zeros(3), geo)
    p_load = 0
    for i in range(2):
        if n_seg:  # the 3D vehicle's segments: piecewise linear between their centres (SegmentDistribution)
            p_load = p_load + g[i] * ca.fmax(0, piecewise_linear([av[NA + i * n_seg + j] for j in range(n_seg)],
                                                                 geo[0], g[2 + i]))
        else:
            p_load = p_load + g[i] * ca.fmax(0, av[4 + 2 * i] + av[5 + 2 * i] * g[2 + i])
    cell_geo = ca.Function("eng_cell_geo", [c, av, geo], [ca.vertcat(p_load, g[0], g[1], g[4], g[5], g[6], g[7])],
                           ["c", "a", "geo"], ["g"], fo)

    sl = soil_law.make(opts)
    variants = law_variants(sl)
    cell_law, cell_history, cell_entry = _cell_functions(sl, variants, fo)
    n_sums = NS + (NS_SOIL if len(soils) > 1 else 0)
    if n_seg:
        n_sums = len(terr.names)
    return EngineFunctions(vehicle_step, vehicle_a, outputs, cell_geo, cell_law, cell_history, cell_entry,
                           veh.output_names, veh.model_layout, len(veh.model_layout) + NG + n_sums, n_sums,
                           veh.layout, na, n_seg, sl, variants)


def _cell_functions(sl: soil_law.SoilLaw, variants: tuple, fo: dict):
    """eng_cell_law_<v> (the general law, then one per variant), eng_cell_history and eng_cell_entry (the
    module doc), each taking the soil's law row (:func:`law_row`) as its input ``law``."""
    z, hist, ps, cycles = ca.SX.sym("z"), ca.SX.sym("hist", NH), ca.SX.sym("p"), ca.SX.sym("cycles")
    row = ca.SX.sym("law", sl.size + len(LAW_ROW_EXTRA))
    vec = [row[i] for i in range(sl.size)]
    laws = []
    for v, fixed in enumerate(((),) + variants):
        law = list(vec)
        for i, value in fixed:  # the variant's entries as numbers (the law's specialised form)
            law[i] = value
        p, dp = sl.pressure_and_slope(z, hist, law)
        laws.append(ca.Function(f"eng_cell_law_{v}", [z, hist, row], [p, dp], ["z", "hist", "law"], ["p", "dp_dz"],
                                fo))
    zm1, pm1, dc1, plastic, phase = sl.history_update(z, ps, hist, vec)
    cell_history = ca.Function("eng_cell_history", [z, ps, hist, row], [ca.vertcat(zm1, pm1, dc1, plastic, phase)],
                               ["z", "p", "hist", "law"], ["h"], fo)
    delta = sl.cycle_increment(z, hist, cycles, vec, row[sl.size])
    cell_entry = ca.Function("eng_cell_entry", [z, hist, cycles, row], [delta], ["z", "hist", "cycles", "law"],
                             ["delta"], fo)
    return tuple(laws), cell_history, cell_entry


# the vehicle states the C reads (grid_engine.c, the standalone program, the engine FMU): C name ->
# state name; engine_layout_c defines ENG_W_<C name> as the state's position in w from the layout
ENGINE_STATE_READS = {"X": "x_m", "Y": "y_m", "YAW": "yaw_rad", "U": "u_m_s", "V": "v_m_s", "R": "yaw_rate_rad_s"}


def engine_layout_c(layout: StateLayout = PLANAR_LAYOUT, na: int = NA, n_seg: int = 0) -> list[str]:
    """The engine's state sizes and positions as C defines, from the vehicle's layout (grid_engine.c
    reads them): ENG_NV, the vehicle's states; ENG_NW, with its algebraic accelerations; ENG_NA, the
    length of a; ENG_NSEG, the 3D vehicle's segments per track (0: planar, its code compiled out);
    ENG_W_X, ENG_W_Y, ... the position in w of each state the C reads (:data:`ENGINE_STATE_READS`); ENG_GEO_*, the
    entries of geo (:data:`~symtrack.terrain.channels.GEO_LAYOUT`), ENG_NGEO its length; ENG_TRACK_SOIL_*, the soil
    coefficients of a soil's soil_veh row (:data:`TRACK_SOIL_LAYOUT`), ENG_N_TRACK_SOIL their count."""
    return [f"#define ENG_NV {layout.nv} /* the vehicle's states (symtrack.model.layout) */",
            f"#define ENG_NW {layout.nv + len(ALGEBRAIC)} /* and its algebraic accelerations */",
            f"#define ENG_NA {na} /* the pose and pressure lines (and the 3D vehicle's segment pressures) */",
            f"#define ENG_NSEG {n_seg} /* the 3D vehicle's segments per track (0: planar) */",
            f"#define ENG_SEG_NF {SEG_NF} /* its sums per segment (grid_engine_model.SEG_FIELDS) */",
            *(f"#define ENG_W_{c} {layout.index(name)} /* {name} */" for c, name in ENGINE_STATE_READS.items()),
            *GEO_LAYOUT.c_defines("ENG_GEO", "ENG_NGEO"),
            *TRACK_SOIL_LAYOUT.c_defines("ENG_TRACK_SOIL", "ENG_N_TRACK_SOIL")]


def soil_dispatch_c(fns: EngineFunctions, vehicle_sizes: tuple[int, int, int] | None = None) -> str:
    """The C of engine_soils.inc for the engine Functions ``fns``: the state sizes of :func:`engine_layout_c`
    (of the vehicle's layout, ``na``, ``n_seg``); ENG_LAW_ROW, the length of a soil's row of the law table
    eng_t.soil_law (:func:`law_row`); ENG_LAW_CALL(row, arg, res), the call of the law Function that a soil of
    law row ``row`` runs (:meth:`EngineFunctions.law_variant`: a test of the row's entries that the law
    fixes in a specialised copy, the general law otherwise; one Function: a plain call); the laws over
    CELL_LANES lanes (:func:`law_lanes_c`) and the geometry over a window's poses (:func:`geo_lanes_c`);
    with ``vehicle_sizes`` (engine.state.vehicle_work_sizes) ENG_SZ_ARG and
    ENG_SZ_RES, the arg and res sizes of the vehicle's Functions (grid_engine.c's defaults, 4 and 3,
    without)."""
    lines = engine_layout_c(fns.layout, fns.na, fns.n_seg)
    names = ", ".join((*fns.soil_law_model.vector_names, *LAW_ROW_EXTRA))
    lines += [f"#define ENG_LAW_ROW {fns.law_size} /* a soil's row of eng_t.soil_law: {names} */",
              "#define ENG_LAW_CALL(row, arg, res) \\",
              *_variant_dispatch(fns, lambda v: f"eng_cell_law_{v}(arg, res, 0, WORK, 0)")]
    if vehicle_sizes is not None:
        lines += [f"#define ENG_SZ_ARG {int(vehicle_sizes[0])} /* the vehicle's Functions' arg, res sizes */",
                  f"#define ENG_SZ_RES {int(vehicle_sizes[1])}"]
    return "\n".join(lines) + "\n" + law_lanes_c(fns) + geo_lanes_c(fns.cell_geo)


def _c_double(value: float) -> str:
    """A C literal of exactly ``value`` (Python's repr is the shortest string that reads back to it)."""
    return repr(float(value))


def _variant_dispatch(fns: EngineFunctions, call) -> list[str]:
    """The body lines of a macro that runs ``call(v)`` for the law variant of the row ``row``
    (:meth:`EngineFunctions.law_variant`, in C)."""
    if not fns.law_variants:
        return [f"  {call(0)}"]
    out = []
    for v, fixed in enumerate(fns.law_variants, start=1):
        test = " && ".join(f"(row)[{i}] == {_c_double(value)}" for i, value in fixed)
        out.append(f"  {'do { if' if v == 1 else 'else if'} ({test}) {call(v)}; \\")
    out.append(f"  else {call(0)}; }} while (0)")
    return out


_GENERATED_BODY = re.compile(
    r"/\* (\w+):\(.*?\)->\(.*?\) \*/\n"
    r"static int \w+\(const casadi_real\*\* arg, casadi_real\*\* res, casadi_int\* iw, casadi_real\* w, int mem\) \{\n"
    r"(.*?)\n  return 0;\n\}", re.S)


def _lanes_body(f: ca.Function, args: list, results: list) -> str | None:
    """The body of CasADi's generated C of ``f`` (an SX Function of scalars and vectors) for one lane
    ``i`` of a loop: input ``arg[a][k]`` becomes ``args[a](k)``, output ``res[r][k] = v`` becomes
    ``results[r](k) = v`` (a result of None: that output is dropped, and the compiler drops what only
    it needed), casadi_fmax/fmin the fmax/fmin that CasADi's helpers call. The operations and their order
    are the generated code's. None when the body has another form (a call of another CasADi helper,
    work vectors, a branch or a loop): the caller keeps the scalar Function."""
    cg = ca.CodeGenerator(f"{f.name()}_lanes.c", {"with_header": False})
    cg.add(f)
    m = _GENERATED_BODY.search(cg.dump())
    if m is None or m.group(1) != f.name():
        return None
    body = re.sub(r"arg\[(\d+)\]\? arg\[\1\]\[(\d+)\] : 0", lambda g: args[int(g.group(1))](int(g.group(2))),
                  m.group(2))
    lines = []
    for ln in body.splitlines():
        r = re.fullmatch(r"  if \(res\[(\d+)\]!=0\) res\[\1\]\[(\d+)\]=(\w+);", ln)
        if r:
            target = results[int(r.group(1))](int(r.group(2)))
            if target is not None:
                lines.append(f"  {target}={r.group(3)};")
        else:
            lines.append(ln)
    body = "\n".join(lines).replace("casadi_fmax(", "fmax(").replace("casadi_fmin(", "fmin(")
    if re.search(r"\b(arg|res|w|iw)\[|\bcasadi_\w+\(|\bif \(|\bfor \(|\bwhile \(", body):
        return None
    return body


def law_lanes_c(fns: EngineFunctions) -> str:
    """The law Functions (eng_cell_law_<v>: the general law and its variants) over the CELL_LANES lanes of
    grid_engine.c's stage_block: ``eng_cell_law_<v>_lanes(z[L], hist[5 L], law, p[L], dp[L])``, ``hist`` by
    component (``hist[c L + i]``), ``law`` the lanes' soil's law row, and ENG_LAW_LANES(row, z, hist, p, dp)
    that calls the variant of the soil of law row ``row`` (as ENG_LAW_CALL).

    Each function is CasADi's generated body of that law (:func:`_lanes_body`) in a loop over the lanes
    with a fixed count: the generated law is branch-free (its if_else are selects), so the compiler
    turns the loop into SIMD code, every lane running the law's operations in the law's order
    (-ffp-contract=off: no contraction): each lane's result is the scalar law's to the last bit
    (tests/test_terrain_engine.py, the one-lane build and the stored SHA). A law of another form gives
    no ENG_LAW_LANES, and grid_engine.c calls the scalar law lane by lane."""
    out = []
    for v, f in enumerate(fns.cell_law):
        body = _lanes_body(f, [lambda c: "z[i]", lambda c: f"hist[{c} * CELL_LANES + i]", lambda c: f"law[{c}]"],
                           [lambda c: "p[i]", lambda c: "dp[i]"])
        if body is None:
            return ""
        out.append(f"static void eng_cell_law_{v}_lanes(const double *restrict z, const double *restrict hist,\n"
                   f"                                  const double *restrict law, double *restrict p,\n"
                   f"                                  double *restrict dp) {{\n"
                   f"  for (int i = 0; i < CELL_LANES; ++i) {{\n"
                   + "\n".join("  " + ln for ln in body.splitlines()) + "\n  }\n}\n")
    lines = ["/* the cell laws over CELL_LANES lanes (grid_engine_model.law_lanes_c) */", *out,
             "#define ENG_LAW_LANES(row, z, hist, p, dp) \\",
             *_variant_dispatch(fns, lambda v: f"eng_cell_law_{v}_lanes(z, hist, row, p, dp)")]
    return "\n".join(lines) + "\n"


def geo_lanes_c(cell_geo: ca.Function) -> str:
    """eng_cell_geo over many poses or many cells at once (grid_engine.c ``geo_window`` and the cells'
    loop of ``eng_run``), with ENG_GEO_LANES defined:

    - ``eng_cell_geo_lanes(n, c[2], aT, as, geo[7], gT, gs)``: one cell at the poses ``aT[k as + i]``,
      i < n (a transient window's substeps): the load and the two fractions (outputs 0-2, the rest not
      used there) to ``gT[k gs + i]``;
    - ``eng_cell_geo_cells(n, cT, cs, a, geo[7], gT, gs)``: the cells centred at ``cT[k cs + i]``, i < n,
      at one pose ``a``: all NGEO outputs to ``gT[k gs + i]``.

    The same operations per pose or cell as eng_cell_geo (:func:`law_lanes_c`'s argument: the same
    bits). Empty (the scalar Function one at a time) for a body of another form."""
    window = _lanes_body(cell_geo, [lambda k: f"c[{k}]", lambda k: f"aT[{k} * as + i]", lambda k: f"geo[{k}]"],
                         [lambda k: f"gT[{k} * gs + i]" if k < 3 else None])
    cells = _lanes_body(cell_geo, [lambda k: f"cT[{k} * cs + i]", lambda k: f"a[{k}]", lambda k: f"geo[{k}]"],
                        [lambda k: f"gT[{k} * gs + i]"])
    if window is None or cells is None:
        return ""

    def loop(body: str) -> str:
        return "  for (int i = 0; i < n; ++i) {\n" + "\n".join("  " + ln for ln in body.splitlines()) + "\n  }\n}\n"

    return ("/* the cell geometry over a window's poses and over many cells (grid_engine_model.geo_lanes_c) */\n"
            "#define ENG_GEO_LANES 1\n"
            "static void eng_cell_geo_lanes(int n, const double *restrict c, const double *restrict aT, long long as,\n"
            "                               const double *restrict geo, double *restrict gT, long long gs) {\n"
            + loop(window) +
            "static void eng_cell_geo_cells(int n, const double *restrict cT, long long cs, const double *restrict a,\n"
            "                               const double *restrict geo, double *restrict gT, long long gs) {\n"
            + loop(cells))


def pv_base(layout: ParamLayout, params: dict, cell_m: float, end_strip_m: float) -> list[float]:
    """The first entries of pv: the vehicle and soil parameters of ``layout`` (EngineFunctions.param_layout),
    the terrain's globals; the sums follow."""
    return layout.pack(params) + [float(cell_m), float(end_strip_m)]


def geo_vector(params: dict, cell_m: float, end_strip_m: float) -> list[float]:
    """eng_cell_geo's geo (:data:`~symtrack.terrain.channels.GEO_LAYOUT`: l, b, B, e, cell size, end strip,
    1 / cell size)."""
    return GEO_LAYOUT.pack({**params, "cell_m": cell_m, "end_strip_m": end_strip_m,
                            "inv_cell_per_m": 1.0 / float(cell_m)})


def track_soil_vector(soils) -> list[float]:
    """The engine's soil_veh: per soil of the field (soil index order) its :data:`TRACK_SOIL_LAYOUT` values."""
    return [v for sp in soils for v in TRACK_SOIL_LAYOUT.pack(sp)]


def cell_constants(params: dict) -> tuple[float, float]:
    """(areal mass, areal damping) of the cells."""
    return float(params["cell_areal_mass_kg_per_m2"]), float(params["cell_damping_Pa_s_per_m"])


__all__ = ["EngineFunctions", "SEG_FIELDS", "SegmentSumsTerrain", "build_engine_functions", "least_squares_line",
           "piecewise_linear", "segment_sum_names", "SUM_NAMES", "SOIL_SUM_NAMES", "NA", "NS", "NS_SOIL", "NGEO",
           "NF", "TRACK_SOIL_LAYOUT", "ENGINE_STATE_READS", "engine_layout_c", "geo_vector", "pv_base",
           "soil_dispatch_c", "track_soil_vector", "LAW_ROW_EXTRA", "law_row", "law_variants"]
