"""The drivers of an operation's path: the steering map of the vehicle on the field's soil (:func:`steering_map`),
the path-following torque law (:class:`PathFollower`) and the MPC follower (:class:`MPCFollower`), chosen by
:func:`follower_of`.

(The package :mod:`symtrack.studies.operations` describes the operations.)"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...control.closedloop import TrackingLaw
from ...control.mpc import MPCSettings, PathTrackingMPC
from ...control.path import Path
from ...control.trim import TrimError, trim
from ...foundations import caches
from ...foundations.errors import ScenarioError
from ...simulation import loop
from ...simulation.builder import system_model
from .plans import OperationPlan, sample_roles
from .settings import MAP_CURVATURES, OPERATION_RTI_STEP_HALVINGS, PLAN_ACCEL_M_S2, OperationSettings


# ---- the steering map and the follower -------------------------------------------------------------------
def _trim_model(model_opts):
    from ...model import SystemModel
    from ...model.options import ModelOptions

    law = model_opts.lateral_law
    # the lagged shear law's steady states are the quasi-static law's (docs/turning.md section 8)
    if law in ("shear", "shear_transient"):
        model_opts = dataclasses.replace(model_opts, lateral_law="shear_quasistatic")
    assert isinstance(model_opts, ModelOptions)
    return SystemModel(model_opts)


_MAP_CACHE = caches.cache("steering_maps", 16)  # symtrack.foundations.caches


def steering_map(params: dict, model_opts, speeds_m_s, turn_radius_m: float, turn_speed_m_s: float) -> dict:
    """The steady torques of the vehicle on this soil: per speed, the curvatures of
    :data:`MAP_CURVATURES` (and the turn's) with their mean torque and torque difference
    (right - left) from trims. The turn's own trim must exist (else :class:`ScenarioError`: the
    radius cannot be held on this soil at this speed); curvatures a speed cannot hold are left out
    of its row. Cached per (params, law, speeds, radius) in the process."""
    key = (tuple(sorted(params.items())), model_opts, tuple(speeds_m_s), turn_radius_m, turn_speed_m_s)
    hit = _MAP_CACHE.get(key)
    if hit is not None:
        return hit
    model = _trim_model(model_opts)
    try:
        tp = trim(model, params, turn_speed_m_s, turn_radius_m)
    except TrimError as err:
        raise ScenarioError(f"operation.turn_radius_m = {turn_radius_m:g} at operation.turn_speed_m_s = "
                            f"{turn_speed_m_s:g}: the vehicle cannot hold this turn on this soil ({err})") from err
    rows = {}
    for v in sorted(set(speeds_m_s)):
        ks, mean, diff, om_mean, om_diff = [], [], [], [], []
        # the turn's curvature and one 40 % tighter (room for the follower's corrections), where held
        for kappa in sorted(set(MAP_CURVATURES) | {1.0 / turn_radius_m, 1.4 / turn_radius_m}):
            if v > turn_speed_m_s + 1e-9 and kappa > 1.0 / 30 + 1e-12:
                continue  # a line's speed is not driven through tight curves
            try:
                # backwards (v < 0: a K-turn's reverse arc) the same yaw rate kappa |v| is a trim radius of -1/kappa
                t = tp if (v == turn_speed_m_s and kappa == 1.0 / turn_radius_m) else \
                    trim(model, params, v, None if kappa == 0 else math.copysign(1.0, v) / kappa)
            except TrimError as err:
                if v < 0 and kappa == 1.0 / turn_radius_m:
                    raise ScenarioError(f"operation.turn_radius_m = {turn_radius_m:g} at operation.turn_speed_m_s = "
                                        f"{turn_speed_m_s:g} backwards (a K-turn's reverse arc): the vehicle cannot "
                                        f"hold this turn on this soil ({err})") from err
                continue
            ks.append(kappa)
            mean.append(0.5 * float(t.u[0] + t.u[1]))
            diff.append(float(t.u[1] - t.u[0]))
            om_l, om_r = t.state("omega_left_rad_s"), t.state("omega_right_rad_s")
            om_mean.append(0.5 * (om_l + om_r))
            om_diff.append(om_r - om_l)
        rows[v] = (np.array(ks), np.array(mean), np.array(diff), np.array(om_mean), np.array(om_diff))
    return _MAP_CACHE.put(key, rows)


def _map_eval(rows: dict, v: float, kappa: float) -> tuple[float, float, float, float]:
    """Mean torque, torque difference, mean sprocket speed and speed difference (right - left) at
    speed v, curvature kappa (the differences odd in kappa), interpolated; v < 0 (backwards) from
    the rows of negative speeds."""
    speeds = sorted(s for s in rows if (s < 0) == (v < 0))  # backwards (v < 0): the reverse rows
    a = abs(kappa)

    def at(s):
        ks = rows[s][0]
        return np.array([float(np.interp(a, ks, col)) for col in rows[s][1:]])
    if v <= speeds[0] or len(speeds) == 1:
        out = at(speeds[0])
    elif v >= speeds[-1]:
        out = at(speeds[-1])
    else:
        i = int(np.searchsorted(speeds, v)) - 1
        f = (v - speeds[i]) / (speeds[i + 1] - speeds[i])
        out = at(speeds[i]) + f * (at(speeds[i + 1]) - at(speeds[i]))
    m, dd, om, dom = (float(z) for z in out)
    return m, math.copysign(dd, kappa), om, math.copysign(dom, kappa)


def speed_profile(path: Path, creep_m_s: float) -> np.ndarray:
    """The followers' speed profile: the path's, limited by :data:`PLAN_ACCEL_M_S2` in deceleration before
    its slow parts and in acceleration after them (the line's speed asked for at once after a turn made
    the mean torque and the sprockets' speed references step, and the tracks spin: measured, the state
    diverged at the exit of a U-turn on the sandy loam); 0 at a K-turn's cusps (where the path's direction
    reverses: the vehicle stops there) with a creep floor of ``creep_m_s`` so that it gets there and
    starts back."""
    v = path.speed.copy()
    ds = np.diff(path.s)
    cusp_idx = np.searchsorted(path.s, path.cusps_s)
    v[cusp_idx] = 0.0
    for i in range(v.size - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * PLAN_ACCEL_M_S2 * ds[i]))
    for i in range(1, v.size):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * PLAN_ACCEL_M_S2 * ds[i - 1]))
    if cusp_idx.size:
        v = np.maximum(v, np.minimum(creep_m_s, path.speed))
    return v


def _map_stiffness(rows: dict, v: float) -> float:
    """The soil's steering stiffness at speed v: the steering map's torque difference per curvature at
    straight running (N m per 1/m: its first step, 0 to 1/400 1/m), interpolated in the speed; v < 0 from
    the reverse rows. Measured: 2.4e5 on the clay, 4.7e5 on the sandy loam (1 and 2.5 m/s)."""
    speeds = sorted(s for s in rows if (s < 0) == (v < 0))
    vals = []
    for sp in speeds:
        ks, diff = rows[sp][0], rows[sp][2]
        j = int(np.nonzero(ks > 0)[0][0])
        vals.append(float(diff[j] / ks[j]))
    return float(np.interp(v, speeds, vals))


class PathFollower:
    """The path-following torque law (a :class:`~symtrack.simulation.loop.SampledLaw`, sampled
    every ``sample_time_s``, held over the engine's macro steps):

    - kinematic outer loop: the yaw rate asked for, r_d = kappa v - (w_n^2 / v) e - 2 zeta w_n e_psi
      (e: lateral error, positive left of the path; e_psi: heading error), w_n = :attr:`OMEGA_N`,
      zeta = 1; kappa at a preview of :attr:`PREVIEW_S` ahead (the torque lag and the yaw response);
    - the torque difference (right - left): the steering map's at the path's curvature (the
      feed-forward), plus a PI law on the yaw rate, K_r (r_d - r) + K_i integral(r_d - r), both
      gains proportional to the soil's steering stiffness (the map's torque per curvature at straight
      running, twice as large on the sandy loam as on the clay) and to the speed above
      :attr:`GAIN_SPEED_M_S`; the integral is held in N m (a gain that grows with the speed does not
      scale what it learnt at a lower one) and limited to the map's torque at a curvature of
      :attr:`YAW_INTEGRAL_LIMIT_1_M`. The feedback stays in torque and is not passed through the
      map: the map is nearly a step at zero curvature (the turning resistance must be overcome
      before the vehicle yaws at all: on the clay 600 N m from 0 to 1/400 1/m, 380 N m from 1/12
      to 1/3 1/m), so a correction through it reverses the torques (measured: a bang-bang
      oscillation in the first headland corner);
    - a PI law on the speed for the mean torque, over the map's mean torque; the speed reference
      the path's, limited by :data:`PLAN_ACCEL_M_S2` in deceleration before its slow parts and in
      acceleration after them;
    - each sprocket's speed held to the steering map's trim speed at the same curvature,
      :attr:`SPROCKET_GAIN_N_M_S` per rad/s: in a tight turn the braked inner track's soil force is
      at its saturation (dF/dj ~ 0), so without it the sprocket's speed integrates the torque error
      (measured: it stuck at 0 and slipped, period 1 s; docs/studies.md).

    It ends the run (returns None) at the path's end, or when the lateral error exceeds
    ``max_lateral_error_m`` (``failure`` says so). The yaw gains: :attr:`YAW_GAIN_S_M`,
    :attr:`YAW_INTEGRAL_1_M` (chosen on the small operation on clay and sandy loam, docs/studies.md);
    the speed's r m / (2 :attr:`SPEED_TAU_S`) corrects a speed error
    in SPEED_TAU_S."""

    SAMPLE_TIME_S = 0.02  # measured: 0.05 s let the yaw loop oscillate in the headland corners
    OMEGA_N = 1.2  # 1/s: the lateral error's closing rate (0.8: RMS 0.17 / 0.22 m on the lines, clay / sandy loam)
    PREVIEW_S = 0.3
    WINDOW_S = 1.0  # the feed-forward's curvature: the path's averaged over this time at the speed (0: none)
    DIFF_SLEW_N_M_S = 1e9  # the torque difference's largest rate of change
    # the yaw-rate PI law in units of the soil's steering stiffness S (:func:`_map_stiffness`, N m per 1/m),
    # so that it is the same loop on every soil: K_r = YAW_GAIN_S_M S g (N m per rad/s), the integral
    # K_i = YAW_INTEGRAL_1_M S g (N m per rad), held in N m and limited to the torque of a curvature of
    # YAW_INTEGRAL_LIMIT_1_M (the map's error it is there to learn). ASSUMED, chosen on operation_small
    # (both soils; docs/studies.md): on the clay K_r = 13500 N m per rad/s at 1 m/s
    YAW_GAIN_S_M = 0.055
    YAW_INTEGRAL_1_M = 0.025
    YAW_INTEGRAL_LIMIT_1_M = 0.018
    GAIN_SPEED_M_S = 1.0  # the yaw gains grow with the speed above this
    RESET_INTEGRAL = False
    CORRECTION_CURVATURE_1_M = 1.0 / 150.0
    SPEED_TAU_S = 1.0
    # the sprockets' speed loop: N m per rad/s of sprocket speed below the steering map's (ASSUMED,
    # chosen on operation_small, both soils: K / J = 10 1/s, the torque lag's bandwidth; 600 gave the
    # same figures, 0 let the braked inner track stick and slip in the turns)
    SPROCKET_GAIN_N_M_S = 300.0
    # a K-turn's cusps: the cusp counts as reached this close to it (the speed profile is 0 there), and the
    # profile's floor about it (ASSUMED: a creep that reaches the cusp and starts back; chosen on the K-turn test)
    CUSP_TOL_M = 0.1
    CUSP_CREEP_M_S = 0.15

    def __init__(self, plan: OperationPlan, params: dict, rows: dict, state_names, sample_time_s: float,
                 substep_s: float, torque_limit_N_m: float, max_lateral_error_m: float):
        self.plan, self.path, self.rows = plan, plan.path, rows
        self.sample_time_s, self.substep_s = sample_time_s, substep_s
        self.limit, self.max_err = torque_limit_N_m, max_lateral_error_m
        idx = {n: i for i, n in enumerate(state_names)}
        self.ix, self.iy, self.ipsi = idx["x_m"], idx["y_m"], idx["yaw_rad"]
        self.iu, self.ir = idx["u_m_s"], idx["yaw_rate_rad_s"]
        self.iom = (idx["omega_left_rad_s"], idx["omega_right_rad_s"])
        r = params["sprocket_radius_m"]
        self.kp_v = r * params["mass_kg"] / (2 * self.SPEED_TAU_S)
        self.ki_v = self.kp_v / (2 * self.SPEED_TAU_S)
        self.int_r = self.int_v = 0.0
        self.segment = 0
        self.diff_prev = None
        self.s = 0.0
        self.roles = sample_roles(plan)
        self.v_profile = speed_profile(self.path, self.CUSP_CREEP_M_S)
        # the path between cusps: one direction each; the projection never crosses a cusp it has not reached
        self.phase_s = np.concatenate([[-np.inf], self.path.cusps_s, [np.inf]])
        self.phase_dir = [float(self.path.direction[min(int(np.searchsorted(self.path.s, a)), self.path.s.size - 1)])
                          for a in np.concatenate([[0.0], self.path.cusps_s])]
        self.phase = 0
        self.log = []  # (t, s, e_lat, e_psi, role)
        self.failure = None
        self.done = False
        # the law's signals per sample (a list to append to: the diagnosis of docs/studies.md), None: not kept
        self.trace = None

    @property
    def progress_fraction(self) -> float:
        """The share of the path driven (the run's progress bar: the time limit is 4 x the plan's)."""
        return min(self.s / max(self.path.length_m, 1e-9), 1.0)

    def _kappa(self, s: float, window_m: float) -> float:
        """The path's curvature averaged over [s - window/2, s + window/2] (exactly, piecewise constant)."""
        p = self.path
        lo, hi = s - 0.5 * window_m, s + 0.5 * window_m
        i0 = max(int(np.searchsorted(p.s, lo, side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(p.s, hi, side="right")), p.s.size - 1)
        if i1 <= i0 + 1:
            return float(p.kappa[i0])
        edges = np.clip(p.s[i0:i1 + 1], lo, hi)
        return float(np.sum(np.diff(edges) * p.kappa[i0:i1]) / max(hi - lo, 1e-9))

    def __call__(self, t_s, x, final=False):
        if final:
            return None
        X, Y, psi = float(x[self.ix]), float(x[self.iy]), float(x[self.ipsi])
        u, r = float(x[self.iu]), float(x[self.ir])
        lo, hi = self.phase_s[self.phase], self.phase_s[self.phase + 1]
        self.s = self.path.project(X, Y, self.s, window_m=(max(-1.0, lo - self.s), min(3.0, hi - self.s)))
        if self.s >= hi - self.CUSP_TOL_M:  # a cusp reached: on to the next direction
            self.phase += 1
            self.int_v = 0.0
        d = self.phase_dir[self.phase]
        e, e_psi = self.path.errors(X, Y, psi, self.s)
        i = min(int(np.searchsorted(self.path.s, self.s)), self.roles.size - 1)
        self.log.append((t_s, self.s, e, e_psi, int(self.roles[i])))
        if self.s >= self.path.length_m - 0.05:
            self.done = True
            return None
        if abs(e) > self.max_err:
            self.failure = (f"the vehicle left the path: lateral error {e:.2f} m at s = {self.s:.1f} m "
                            f"(t = {t_s:.1f} s) "
                            f"exceeds operation.max_lateral_error_m = {self.max_err:g}")
            return None
        v = max(abs(u), 0.3)
        ahead = min(self.s + v * self.PREVIEW_S, self.phase_s[self.phase + 1])  # not past a cusp
        kappa = self._kappa(ahead, max(v * self.WINDOW_S, 0.05))
        w = self.OMEGA_N
        # backwards (d = -1) de/dt = -v e_psi: the lateral term's sign turns so that e closes as forwards
        r_d = kappa * v - d * (w * w / v) * e - 2 * w * e_psi
        r_d = max(min(r_d, 0.8), -0.8)
        # the speed reference, ramped from the start
        v_ref = d * min(float(np.interp(self.s, self.path.s, self.v_profile)),
                        0.3 + PLAN_ACCEL_M_S2 * t_s)
        h = self.sample_time_s
        er, ev = r_d - r, v_ref - u
        # the yaw law's gains: the soil's steering stiffness at this speed times the law's own (class doc)
        g = max(v / self.GAIN_SPEED_M_S, 1.0)
        stiff = _map_stiffness(self.rows, v_ref)
        lim_i = stiff * self.YAW_INTEGRAL_LIMIT_1_M
        self.int_r = max(min(self.int_r + h * g * stiff * self.YAW_INTEGRAL_1_M * er, lim_i), -lim_i)
        self.int_v = max(min(self.int_v + h * ev, 2.0), -2.0)
        seg = int(self.path.segment[i])
        if self.RESET_INTEGRAL and seg != self.segment:  # a new segment: the integral learnt the last one's map error
            self.segment, self.int_r = seg, 0.0
        # the map at the path's curvature plus the correction's, the correction limited to
        # CORRECTION_CURVATURE_1_M: near straight running it overcomes the turning resistance's step
        # (the threshold a PI law alone would wait for: a stick-slip weave); in a turn, where the map is
        # flat, it moves the torques little (unlimited, it reversed them)
        corr = max(min(r_d / v - kappa, self.CORRECTION_CURVATURE_1_M), -self.CORRECTION_CURVATURE_1_M)
        mean_ff, diff, om_mean, om_diff = _map_eval(self.rows, v_ref, kappa + corr)
        diff_ff, int_r_now = diff, self.int_r
        diff += g * stiff * self.YAW_GAIN_S_M * er + self.int_r
        mean = mean_ff + self.kp_v * ev + self.ki_v * self.int_v
        if self.diff_prev is not None:
            step = self.DIFF_SLEW_N_M_S * h
            diff = min(max(diff, self.diff_prev - step), self.diff_prev + step)
        self.diff_prev = diff
        left, right = mean - 0.5 * diff, mean + 0.5 * diff
        if self.SPROCKET_GAIN_N_M_S:
            k = self.SPROCKET_GAIN_N_M_S
            left += k * (om_mean - 0.5 * om_diff - float(x[self.iom[0]]))
            right += k * (om_mean + 0.5 * om_diff - float(x[self.iom[1]]))
        lim = self.limit
        if self.trace is not None:
            self.trace.append((t_s, self.s, e, e_psi, r_d, r, kappa, diff_ff, diff, int_r_now, v_ref, u, mean_ff, mean,
                               om_mean - 0.5 * om_diff, om_mean + 0.5 * om_diff, float(x[self.iom[0]]),
                               float(x[self.iom[1]]), left, right, seg))
        return (max(min(left, lim), -lim), max(min(right, lim), -lim))


class MPCFollower:
    """The project's path-tracking MPC (:class:`symtrack.control.mpc.PathTrackingMPC`, real-time
    iteration on the scenario's lateral law, the settings of ``symtrack mpc --solver rti`` but
    :data:`OPERATION_RTI_STEP_HALVINGS`) as an operation's follower:
    :class:`symtrack.control.closedloop.TrackingLaw` sampled every ``mpc.sample_time_s`` (held over
    the engine's macro steps) on the operation's path, with the follower's bookkeeping of
    :class:`PathFollower` (``log``, ``s``, ``done``, ``failure``, ``progress_fraction``). The
    prediction's cells are those of steady straight running at the first line's speed (the grid
    plant carries no homogeneous cells), as ``symtrack mpc --plant grid`` has them."""

    def __init__(self, plan: OperationPlan, law, max_lateral_error_m: float):
        self.plan, self.path, self.law, self.max_err = plan, plan.path, law, max_lateral_error_m
        self.sample_time_s, self.substep_s = law.sample_time_s, law.substep_s
        self.roles = sample_roles(plan)
        self.log, self.failure, self.done, self.s = [], None, False, 0.0

    @property
    def progress_fraction(self) -> float:
        return min(self.s / max(self.path.length_m, 1e-9), 1.0)

    def __call__(self, t_s, x, final=False):
        u = self.law(t_s, x, final)
        r = self.law.rows
        if final or not r["s"]:
            return u
        self.s, e, e_psi = r["s"][-1], r["e_lat"][-1], r["e_psi"][-1]
        i = min(int(np.searchsorted(self.path.s, self.s)), self.roles.size - 1)
        self.log.append((t_s, self.s, e, e_psi, int(self.roles[i])))
        if self.s >= self.path.length_m - 0.05 or u is None:
            self.done = self.s >= self.path.length_m - 0.05
            return None
        if abs(e) > self.max_err:
            self.failure = (f"the vehicle left the path: lateral error {e:.2f} m at s = {self.s:.1f} m "
                            f"(t = {t_s:.1f} s) exceeds operation.max_lateral_error_m = {self.max_err:g}")
            return None
        return u


def follower_of(fs: OperationSettings, plan: OperationPlan) -> str:
    """Who drives ``plan``: ``fs.follower``, or for "auto" the project's MPC ("rti"; the path follower
    is the MPC; measured on season_4ha: 0 failed solves of 71 935, RMS 1.9 mm on the lines, docs/studies.md)
    except on a plan with K-turns, whose reverse arcs the MPC's forward-only reference does not take ("law")."""
    if fs.follower != "auto":
        return fs.follower
    return "law" if plan.path.cusps_s.size else "rti"


def mpc_follower(plan: OperationPlan, sc, plant, fs: OperationSettings, duration_s: float):
    """The :class:`MPCFollower` of an operation and the plant's start state (trim of straight running
    at the first segment's speed, placed at the path's start)."""
    model = system_model(sc.model, sc.surface)
    settings = MPCSettings(solver="rti", torque_max_N_m=fs.torque_limit_N_m,
                           rti_step_halvings=OPERATION_RTI_STEP_HALVINGS, rti_relinearisations=1,
                           rti_cold_start="shift")
    mpc = PathTrackingMPC(model, sc.params, settings)
    v0 = float(plan.path.speed[0])
    tp = trim(model, sc.params, v0)
    xv = tp.x[model.layout.block("vehicle")].copy()
    names = tuple(plant.state_names)
    if names != tuple(model.layout.vehicle_names):
        raise ScenarioError("operation.follower = \"rti\": the plant's state is not the vehicle's (the MPC reads it)")
    x0, y0, psi0 = plan.start
    for n, val in (("x_m", x0), ("y_m", y0), ("yaw_rad", psi0)):
        xv[names.index(n)] = val
    cells = tp.x[model.layout.block("cells")]
    # the MPC's reference at the followers' speed profile (the path's own steps from the lines' speed to
    # the turns')
    path = copy.copy(plan.path)
    path.speed = speed_profile(plan.path, 0.0)
    path.speed[0] = v0
    # TrackingLaw reads the scenario's mpc settings, run.duration_s and name only
    view = _MPCView(fs.name, settings, duration_s)
    # the engine's macro step is the operation's run.output_dt_s (each 0.1 s sample held over them)
    law = TrackingLaw(view, mpc, path, names, tp.u.copy(), cells, sc.run.output_dt_s)
    return MPCFollower(plan, law, fs.max_lateral_error_m), loop.StartPoint(x0, y0, psi0, tp.u.copy(), xv), mpc


@dataclass(frozen=True)
class _RunView:
    duration_s: float


class _MPCView:
    """What :class:`~symtrack.control.closedloop.TrackingLaw` reads of an MPC scenario: name, mpc, run.duration_s."""

    def __init__(self, name: str, mpc: MPCSettings, duration_s: float):
        self.name, self.mpc, self.run = name, mpc, _RunView(duration_s)
