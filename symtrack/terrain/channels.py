"""The channel pool: a fixed number of copies of the cell equations (docs/model.md, "Terrain cells,
channels and the world manager").

A channel is one copy of the cell law of :mod:`symtrack.soil.cell` (the cell equation, Bekker
loading, Wong unloading/reloading line). It does not know which cell it simulates: the world
manager (:mod:`symtrack.terrain.world`) writes the cell's identity and history into the
channel's entries of the terrain parameter vector Q before every macro step and reads the
channel's states back after it (the thesis's INFO_IN / INFO_OUT, docs/model.md).

Layout
------
States, per channel c: ``ch{c}_sinkage_m``, ``ch{c}_sinkage_rate_m_s`` (the thesis's int_1_state
and int_2_state).

Q (the terrain's own parameters, appended to the vehicle and soil parameters):
``cell_size_m``, ``end_strip_m``, then per channel c the :data:`CHANNEL_FIELDS`: the cell
centre (world x, y), the history z_max, p_max of the cell, the active flag (1 active,
0 idle), and the cycle law's z_off (plastic sinkage of the cell's earlier load cycles), delta (the
increment this stay may add) and d_c (what it has added so far): symtrack/soil/cell.py. An idle
channel is inert: zero derivatives, no load, no weight, no work.

Coupling with the vehicle
-------------------------
- **Load.** In track k's frame (s from the front/idler end backwards, t across the track) the
  cell is taken as the axis-aligned square of side dx around its centre (exact when the
  heading is a multiple of 90 deg, an approximation of the rotated square otherwise). The
  fraction of its area under the track's l x b rectangle is the product of two clamped 1-D
  overlaps, a continuous (piecewise linear) function of the pose, so the integrator meets no
  discontinuity when a cell enters or leaves the footprint. The load is
  p_load = sum_k frac_k * p_k(s_mid,k), with p_k the track's linear (or triangular) pressure
  distribution of :class:`~symtrack.vehicles.planar.PressureDistribution` evaluated at the
  middle of the overlapped interval of s.
- **Sinkage under the track ends.** The sprocket (idler) sinkage of track k is the mean of the
  channels' sinkages weighted by the area each cell shares with a strip of length
  ``end_strip_m`` (two cells) at the rear (front) end of the contact, the contact being shrunk
  by half a cell on every side first. The shrinking keeps out the cells the track's edges only
  partly cover: they carry only part of the pressure and sink much less (z ~ p^(1/n)), and
  would otherwise bias a rigid track's sinkage low (at dx = 0.1 m and b = 0.45 m, by about
  15 %). The weights are continuous in the pose; with no cell under a strip its sinkage is 0.
  Needs dx < b (checked by the world manager).
- **Compaction resistance** (docs/model.md, reconstruction): the power the track spends
  pressing the soil, divided by the track speed,
  R_c,k = sum_c A_cell frac_k,c p_c max(dz_c/dt, 0) / sqrt(v_k^2 + v0^2),
  with p_c the soil's reaction pressure and v0 = :data:`COMPACTION_SPEED_FLOOR_M_S`. It
  depends on the cells' states, not on the pressure distribution, so it does not enter the
  load-transfer loop.

Why IDAS
--------
The compaction resistance sums over all cells and enters the body's longitudinal
acceleration, which sets the pressure distribution, which loads every cell. In the ODE form
(CVODES) the accelerations are fixed-point iterations of that loop, so every cell's
derivative depends on every other cell's rate and the Jacobian is dense (N x N). In the DAE
form (IDAS) the accelerations are algebraic variables: a cell depends only on its own states,
the pose and the accelerations, and the Jacobian is an arrowhead (see
tests/test_terrain_channel.py). The grid terrain therefore runs with IDAS.

The channel equations are CasADi Functions of one cell, applied to all channels with
``Function.map`` (shared inputs reduced). The model is SX, so the mapped calls are expanded
into the SX graph when the system is assembled; the Jacobian's sparsity is what keeps the
integrator cheap.
"""

from __future__ import annotations

import casadi as ca

from ..foundations.params import ParamLayout
from ..model.options import ModelOptions
from ..soil import cell
from ..soil import law as soil_law
from ..vehicles.planar import ENDS, TRACKS

__all__ = ["CHANNEL_FIELDS", "COMPACTION_SPEED_FLOOR_M_S", "ChannelTerrain", "GEO_LAYOUT", "GLOBAL_FIELDS", "HIST_ROWS",
           "NF", "NG", "NH", "build_cell_functions", "channel_param_names", "channel_state_names"]

# a cell's geometry input geo: the vehicle's contact (its parameters), the cell size and the end strip
# (the terrain's globals) and, for the terrain engine, 1 / cell size (build_cell_functions'
# cell_reciprocal; C: ENG_GEO_*)
GEO_LAYOUT = ParamLayout(("contact_length_m", "track_width_m", "track_gauge_m", "cg_ahead_of_contact_centre_m",
                          "cell_m", "end_strip_m", "inv_cell_per_m"))
GEO_VEHICLE_PARAMS = GEO_LAYOUT.names[:4]
CHANNEL_FIELDS = ("centre_x_m", "centre_y_m", "z_max_m", "p_max_Pa", "active", "z_off_m", "cycle_increment_m",
                  "cycle_progress_m")
# the history the cell law reads, as rows of the channel fields: z_max, p_max, z_off, delta, d_c
HIST_ROWS = (2, 3, 5, 6, 7)
NH = len(HIST_ROWS)
GLOBAL_FIELDS = ("cell_size_m", "end_strip_m")
NF = len(CHANNEL_FIELDS)
NG = len(GLOBAL_FIELDS)

# Regularisation speed of the compaction resistance R_c = P / sqrt(v^2 + v0^2) (numerical, not
# physical): at walking pace and above it is P / |v|, the work per metre. Measured: with
# v0 = 0.01 m/s (the model's motion_smoothing_m_s) a second pass starting from rest on the
# compacted soil locked up in a stiff loop (resistance from cells settling under the
# decelerating vehicle -> more pitch load -> more settling), IDAS taking 1500 steps per 10 ms;
# with 0.1 m/s it runs through. Below v0 the settling of the cells under a vehicle at rest is
# not a travel resistance anyway.
COMPACTION_SPEED_FLOOR_M_S = 0.1

# Phase flag of a cell (the thesis's ``state``): untouched, loading on the Bekker curve,
# unloading/reloading on the line through (z_max, p_max).
PHASE_VIRGIN, PHASE_LOADING, PHASE_UNLOADING = 0, 1, 2

# Track index -> lateral sign (left track at y = +B/2).
_SIDE = {"left": 1.0, "right": -1.0}


def channel_state_names(c: int) -> tuple[str, str]:
    return f"ch{c}_sinkage_m", f"ch{c}_sinkage_rate_m_s"


def channel_param_names(c: int) -> tuple[str, ...]:
    return tuple(f"ch{c}_{f}" for f in CHANNEL_FIELDS)


def _overlap(c, h, lo, hi, inv_2h=None):
    """Fraction of the interval [c - h, c + h] inside [lo, hi]: continuous, piecewise linear.
    inv_2h: 1 / (2 h) as a symbol of its own (then a product: CasADi would fold a product with
    1 / (2 h) back into the quotient), or None (the quotient)."""
    overlap = ca.fmin(ca.fmax(ca.fmin(hi, c + h) - ca.fmax(lo, c - h), 0), 2 * h)
    return overlap / (2 * h) if inv_2h is None else overlap * inv_2h


def _hist(h):
    """(z_max, p_max, z_off, delta, d_c) from a history vector."""
    return h[0], h[1], h[2], h[3], h[4]


def build_cell_functions(opts: ModelOptions, cell_reciprocal: bool = False) -> dict[str, ca.Function]:
    """The one-cell Functions a channel is made of.

    - ``geometry(q[5], pose[3], geo[6]) -> g[8]``: frac_left, frac_right, s_mid_left, s_mid_right,
      and the end-strip weights (sprocket_left, idler_left, sprocket_right, idler_right);
      geo = (l, b, B, e, cell size, end strip). With ``cell_reciprocal`` geo[7] ends with
      1 / cell size, and the overlaps are products with it (one division instead of seven; the
      terrain engine's geometry, within an ulp of the quotients).
    - ``soil(z, hist[5], law) -> p``: the reaction pressure of the model's soil law
      (:mod:`symtrack.soil.law`, ``opts.soil_law``); hist = (z_max, p_max, z_off, delta, d_c)
      (:data:`HIST_ROWS` of the channel fields), law = the law's vector (its ``values`` of a
      parameter dict).
    - ``dynamics(z_dot, p_load, p, active, cellpar[2]) -> xc_dot[2]`` (cell.cell_acceleration),
      cellpar = (areal mass, areal damping).
    - ``history(z, hist[5], law) -> (z_max', p_max', d_c', p, phase, plastic)``: INFO_OUT, the
      history update (the law's history_update) applied by the world manager after each macro step.
    - ``entry(z, hist[5], cycles, law, beta) -> delta``: INFO_IN, the plastic increment the
      cell's new stay may add (the law's cycle_increment).
    """
    q = ca.SX.sym("q", NF)
    pose = ca.SX.sym("pose", 3)
    geo = ca.SX.sym("geo", len(GEO_LAYOUT) if cell_reciprocal else len(GEO_LAYOUT) - 1)
    l, b, B, e, dx, strip = (geo[GEO_LAYOUT.offset(n)] for n in GEO_LAYOUT.names[:6])
    inv = geo[GEO_LAYOUT.offset("inv_cell_per_m")] if cell_reciprocal else None  # 1 / dx = 1 / (2 h)
    X, Y, psi = pose[0], pose[1], pose[2]
    ddx, ddy = q[0] - X, q[1] - Y
    xb = ca.cos(psi) * ddx + ca.sin(psi) * ddy
    yb = -ca.sin(psi) * ddx + ca.cos(psi) * ddy
    s = (l / 2 - e) - xb  # distance of the cell centre behind the track's front end
    h = dx / 2
    active = q[4]
    fr, sm, w = [], [], {}
    for k in TRACKS:
        t = yb - _SIDE[k] * B / 2
        fr.append(active * _overlap(s, h, 0, l, inv) * _overlap(t, h, -b / 2, b / 2, inv))
        sm.append(0.5 * (ca.fmax(s - h, 0) + ca.fmin(s + h, l)))
        # end-strip weights on the contact shrunk by half a cell on every side (module doc)
        inner = _overlap(t, h, -(b / 2 - h), b / 2 - h, inv)
        w[("sprocket", k)] = active * _overlap(s, h, l - h - strip, l - h, inv) * inner
        w[("idler", k)] = active * _overlap(s, h, h, h + strip, inv) * inner
    g = ca.vertcat(*fr, *sm, *(w[(end, k)] for k in TRACKS for end in ENDS))
    geometry = ca.Function("channel_geometry", [q, pose, geo], [g], ["q", "pose", "geo"], ["g"])

    sl = soil_law.make(opts)
    z, hist, law = ca.SX.sym("z"), ca.SX.sym("hist", NH), sl.symbols()
    p = sl.pressure(z, _hist(hist), law)
    soil = ca.Function("channel_soil", [z, hist, law], [p], ["z", "hist", "law"], ["p"])

    zdot, pload, ps, act = ca.SX.sym("z_dot"), ca.SX.sym("p_load"), ca.SX.sym("p"), ca.SX.sym("active")
    cellpar = ca.SX.sym("cellpar", 2)
    acc = cell.cell_acceleration(zdot, pload, ps, cellpar[0], cellpar[1])
    dynamics = ca.Function("channel_dynamics", [zdot, pload, ps, act, cellpar],
                           [ca.vertcat(act * zdot, act * acc)],
                           ["z_dot", "p_load", "p", "active", "cellpar"], ["xc_dot"])

    zmax1, pmax1, dc1, plastic, phase = sl.history_update(z, p, _hist(hist), law)
    history = ca.Function("channel_history", [z, hist, law], [zmax1, pmax1, dc1, p, phase, plastic],
                          ["z", "hist", "law"], ["z_max_new", "p_max_new", "d_c_new", "p", "phase", "plastic"])
    cycles, beta = ca.SX.sym("cycles"), ca.SX.sym("beta")
    delta = sl.cycle_increment(z, _hist(hist), cycles, law, beta)
    entry = ca.Function("channel_entry", [z, hist, cycles, law, beta], [delta],
                        ["z", "hist", "cycles", "law", "beta"], ["delta"])
    return {"geometry": geometry, "soil": soil, "dynamics": dynamics, "history": history, "entry": entry}


class ChannelTerrain:
    """A terrain of ``n_channels`` channels for :class:`~symtrack.model.SystemModel`."""

    name = "channels"

    def __init__(self, opts: ModelOptions, n_channels: int):
        if not (isinstance(n_channels, int) and n_channels >= 1):
            raise ValueError(f"n_channels = {n_channels!r} must be an integer >= 1")
        self.opts = opts
        self.n = n_channels
        self.state_names = tuple(s for c in range(n_channels) for s in channel_state_names(c))
        self.param_names = GLOBAL_FIELDS + tuple(s for c in range(n_channels) for s in channel_param_names(c))
        self.law = soil_law.make(opts)  # the soil law of the channels (its vector: self.law.values(params))
        self.fn = build_cell_functions(opts)
        n = n_channels
        self._geometry = self.fn["geometry"].map("channels_geometry", "serial", n, [1, 2], [])
        self._soil = self.fn["soil"].map("channels_soil", "serial", n, [2], [])
        self._dynamics = self.fn["dynamics"].map("channels_dynamics", "serial", n, [4], [])
        self._cache = None

    # -- pieces shared by compaction() and equations() (same xv, xc, Q objects from SystemModel)
    def _parts(self, xv, xc, P, Q):
        if self._cache is not None and self._cache[0] is xv and self._cache[1] is xc and self._cache[2] is Q:
            return self._cache[3]
        n = self.n
        qc = ca.reshape(Q[NG:], NF, n)
        pose = ca.vertcat(*xv.pose.planar)  # the flat field's geometry: x, y, yaw
        geo = ca.vertcat(*(P[n] for n in GEO_VEHICLE_PARAMS), Q[0], Q[1])
        g = self._geometry(qc, pose, geo)  # 8 x n
        xcm = ca.reshape(xc, 2, n)
        law = self.law.vector(P)
        hist = ca.vertcat(*(qc[r, :] for r in HIST_ROWS))
        p_soil = self._soil(xcm[0, :], hist, law)  # 1 x n
        parts = {"qc": qc, "g": g, "xcm": xcm, "p_soil": p_soil, "cell_area": Q[0] ** 2}
        self._cache = (xv, xc, Q, parts)
        return parts

    def compaction(self, xv, xc, P, Q):
        d = self._parts(xv, xc, P, Q)
        B = P["track_gauge_m"]
        u, r = xv["u_m_s"], xv["yaw_rate_rad_s"]
        v_track = {"left": u - r * B / 2, "right": u + r * B / 2}
        power_density = d["p_soil"] * ca.fmax(d["xcm"][1, :], 0)  # W/m^2 per cell
        out = []
        for i, k in enumerate(TRACKS):
            power = d["cell_area"] * ca.sum2(d["g"][i, :] * power_density)
            out.append(power / ca.sqrt(v_track[k] ** 2 + COMPACTION_SPEED_FLOOR_M_S**2))
        return ca.vertcat(*out)

    def equations(self, xv, xc, dist: dict, P, Q):
        d = self._parts(xv, xc, P, Q)
        g, xcm = d["g"], d["xcm"]
        p_load = 0
        for i, k in enumerate(TRACKS):
            p_load = p_load + g[i, :] * dist[k].at(g[2 + i, :])
        cellpar = ca.vertcat(P["cell_areal_mass_kg_per_m2"], P["cell_damping_Pa_s_per_m"])
        xdot = self._dynamics(xcm[1, :], p_load, d["p_soil"], d["qc"][4, :], cellpar)  # 2 x n
        signals = {}
        row = 4
        for k in TRACKS:
            for end in ENDS:
                w = g[row, :]
                row += 1
                signals[f"sinkage_{end}_{k}_m"] = ca.sum2(w * xcm[0, :]) / (ca.sum2(w) + 1e-9)
                signals[f"p_{end}_{k}_Pa"] = getattr(dist[k], end)
        signals["compaction_power_W"] = d["cell_area"] * ca.sum2(
            (g[0, :] + g[1, :]) * d["p_soil"] * ca.fmax(xcm[1, :], 0))
        return ca.reshape(xdot, 2 * self.n, 1), signals
