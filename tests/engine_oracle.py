"""The test oracle of the terrain engine and of the world manager: symtrack/native/grid_engine.c in Python on CasADi's
interpreter, the same algorithm expression by expression (:class:`PyKernel`; slow). It is a second
copy of the world manager's rules (footprint, release, sector assignment, INFO_IN / INFO_OUT, the
collision error), of the cells' step and of the set-down (:func:`static_sinkage`), kept here, with the
tests, to check the C against: ``TerrainEngine(world, settings, kernel=PyKernel)`` runs the engine on
it. :func:`cells_under` and :func:`channel_of` are the footprint and the sector rule in numpy on a World
(the World's own copy before the rules moved to grid_engine.c), for the invariant tests of
tests/test_terrain_world.py."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from symtrack.foundations.errors import SimulationError
from symtrack.integrators.engine.state import (
    ERR_COLLISION,
    ERR_FIELD,
    ERR_NEWTON,
    ERR_NONFINITE,
    ERR_UNCOVERED,
    NEWTON_ACCEPT_STEP,
    NEWTON_MAX_ITER,
    SDIRK_GAMMA,
    EngineState,
)
from symtrack.integrators.settings import VEHICLE_ATOL, VEHICLE_MAX_HALVINGS, window_substeps
from symtrack.native.grid_engine_model import NS
from symtrack.soil import subsoil
from symtrack.terrain import query
from symtrack.terrain.channels import HIST_ROWS, NF, NG
from symtrack.terrain.world import LIFT_TIME_S
from symtrack.vehicles.planar import contact_rectangles

__all__ = ["PyErr", "PyKernel", "cells_under", "channel_of", "cvodes_end_pass", "outside_tracks", "rectangles",
           "ringing", "static_sinkage", "unload_dae"]


def rectangles(params, X, Y, psi, pad) -> list[tuple]:
    """Each track's contact rectangle (the vehicle's, planar.contact_rectangles) at the pose grown by pad,
    left then right: (centre x, centre y, cos, sin, half length, half width) (grid_engine.c
    eng_track_rects)."""
    c, s = math.cos(psi), math.sin(psi)
    return [(X + c * bx - s * by, Y + s * bx + c * by, c, s, hl + pad, hw + pad)
            for bx, by, hl, hw in contact_rectangles(params)]


def cells_under(world, X, Y, psi, pad, check_field=True) -> np.ndarray:
    """Flat indices of the cells whose centres lie in the tracks' rectangles padded by pad (grid_engine.c
    scan), sorted; the field error when a track's contact leaves the field and ``check_field``."""
    g = world.grid
    dx = g.cell_m
    x0, x1, y0, y1 = g.bounds()
    found = []
    for cx, cy, c, s, hl, hw in rectangles(world.params, X, Y, psi, pad):
        ex = abs(c) * hl + abs(s) * hw
        ey = abs(s) * hl + abs(c) * hw
        if check_field:
            exu, eyu = ex - pad * (abs(c) + abs(s)), ey - pad * (abs(c) + abs(s))
            if cx - exu < x0 or cx + exu > x1 or cy - eyu < y0 or cy + eyu > y1:
                raise SimulationError(f"the vehicle left the terrain field: a track's contact around ({cx:.2f}, "
                                      f"{cy:.2f}) m")
        i0 = max(int(math.floor((cx - ex - x0) / dx)), 0)
        i1 = min(int(math.ceil((cx + ex - x0) / dx)), g.shape[0] - 1)
        j0 = max(int(math.floor((cy - ey - y0) / dx)), 0)
        j1 = min(int(math.ceil((cy + ey - y0) / dx)), g.shape[1] - 1)
        if i1 < i0 or j1 < j0:
            continue
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1), indexing="ij")
        px, py = g.centres(ii, jj)
        along = (px - cx) * c + (py - cy) * s
        across = -(px - cx) * s + (py - cy) * c
        inside = (np.abs(along) <= hl) & (np.abs(across) <= hw)
        found.append(ii[inside] * g.shape[1] + jj[inside])
    if not found:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(found))


def static_sinkage(soil, law, z0: np.ndarray, hist: np.ndarray, p_load: np.ndarray) -> np.ndarray:
    """grid_engine.c's set_down_z (the set-down's rule), vectorised on CasADi's interpreter: the sinkage at
    which each cell's reaction equals its load, p(z; hist) = p_load (the cells at rest under a vehicle
    set down quasi-statically): bisection on the monotone law, to 1e-15 m (every cell bisected until
    all are within it: the C stops each cell at its own, so the two agree to about 1e-15 m).
    ``soil``: the channel soil Function (z, hist[5], law) -> p; law (5,) or (5, k) (per cell); z0 (k,),
    hist (5, k), p_load (k,).
    A cell whose reaction at z0 already equals its load keeps z0."""
    z0 = np.asarray(z0, dtype=float)
    k = z0.size
    if k == 0:
        return z0.copy()
    law = np.asarray(law, dtype=float)
    if law.ndim == 1 or law.shape[1] == 1:  # one law for all cells
        law = np.repeat(law.reshape(-1, 1), k, axis=1)
    f = soil.map(k)

    def p_of(z):
        return np.array(f(z[None, :], hist, law)).ravel()

    p0 = p_of(z0)
    lo, hi = z0.copy(), z0.copy()
    up = p_load > p0
    down = p_load < p0
    step = np.full(k, 1e-4)
    for _ in range(60):  # bracket the root
        hi = np.where(up, lo + step, hi)
        lo = np.where(down, hi - step, lo)
        ph, pl = p_of(hi), p_of(lo)
        open_ = (up & (ph < p_load)) | (down & (pl > p_load))
        if not open_.any():
            break
        step = np.where(open_, 2 * step, step)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        below = p_of(mid) <= p_load  # (<=: for p_load = 0 the top of the unloaded set, the rest position)
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
        if np.all(hi - lo <= 1e-15):
            break
    return np.where(up | down, 0.5 * (lo + hi), z0)


def unload_dae(world) -> dict:
    """The cells-only DAE of the lift on a World's whole channel pool (the load falling linearly to zero
    over T from the pass end's pressures p_end), time-scaled to [0, 1] over a step of length h:
    parameters (Q, p_end, t0, h, T, each channel's soil law (5 x n, column-major)); the lift's
    reference, which :func:`cvodes_end_pass` integrates with CVODES."""
    n = world.n_channels
    fn = world.terrain.fn
    xc = ca.SX.sym("xc", 2 * n)
    Q = ca.SX.sym("Q", NG + NF * n)
    p_end = ca.SX.sym("p_end", n)
    t0, h, T, tau = ca.SX.sym("t0"), ca.SX.sym("h"), ca.SX.sym("T"), ca.SX.sym("tau")
    qc = ca.reshape(Q[NG:], NF, n)
    xm = ca.reshape(xc, 2, n)
    law = ca.SX.sym("law", world.laws.shape[0], n)  # each channel's soil law (a soil map)
    hist = ca.vertcat(*(qc[r, :] for r in HIST_ROWS))
    p = fn["soil"].map(n)(xm[0, :], hist, law)
    load = p_end.T * ca.fmax(0, 1 - (t0 + h * tau) / T)
    cellpar = ca.DM([world.params["cell_areal_mass_kg_per_m2"], world.params["cell_damping_Pa_s_per_m"]])
    d = fn["dynamics"].map(n, [False, False, False, False, True], [False])(xm[1, :], load, p, qc[4, :], cellpar)
    return {"t": tau, "x": xc, "p": ca.vertcat(Q, p_end, t0, h, T, ca.vec(law)), "ode": h * ca.reshape(d, 2 * n, 1)}


def cvodes_end_pass(manager, x: np.ndarray, dt_s: float = 0.01, max_steps: int = 300) -> bool:
    """grid_engine.c eng_lift's rule by CVODES over the whole channel pool at tight tolerances (rtol
    1e-9, atol 1e-12) on ``manager``'s World (a ChannelManager) from the pass end x, INFO_OUT through
    the manager after every step; then every channel freed and the pass folded in, as
    ChannelManager.end_pass. Returns whether the cells came to rest within max_steps."""
    w = manager.world
    F = ca.integrator("unload", "cvodes", unload_dae(w), 0.0, 1.0, {"abstol": 1e-12, "reltol": 1e-9})
    manager.after_step(x)
    w.z_at_pass_end = w.storage.z.copy()
    act = np.nonzero(w.channel_cell >= 0)[0]
    settled = True
    if act.size:
        L = w.layout
        xc = np.array(x[L.block("cells")], dtype=float)
        p_end = w.p_soil.copy()
        for k in range(max_steps):
            t0 = k * dt_s
            rates = xc[L.cell_index(act, "rate") - L.nv]  # (xc: the cells block)
            if t0 >= LIFT_TIME_S and np.all((w.p_soil[act] <= 0.0) & (np.abs(rates) <= w.settings.release_rate_m_s)):
                break
            par = np.concatenate([w.Q, p_end, [t0, dt_s, LIFT_TIME_S], w.laws[:, w.ch_soil].ravel(order="F")])
            xc = np.array(F(x0=xc, p=par)["xf"]).ravel()
            manager.after_step(np.concatenate([x[L.block("vehicle")], xc]))
        else:
            settled = False
    w.release_all()
    w.fold_pass()
    return settled


def channel_of(world, cells: np.ndarray) -> np.ndarray:
    """The sector rule Cell[i, j] -> CHANNEL[i mod M, j mod M] (grid_engine.c channel_of)."""
    i, j = np.divmod(cells, world.grid.shape[1])
    return (i % world.M) * world.M + (j % world.M)


def outside_tracks(geo, cx: float, cy: float, a) -> bool:
    """engine.c outside_tracks: the cell centred at (cx, cy) lies wholly outside both contact
    rectangles at the pose and pressure lines a (grown by 0.7072 cell, more than the half cell by
    which the cell geometry's overlap reaches out), so its geometry is exactly zero."""
    length, b, B, e, r = geo[0], geo[1], geo[2], geo[3], 0.7072 * geo[4]
    dx, dy = cx - a[0], cy - a[1]
    xb, yb = a[2] * dx + a[3] * dy, -a[3] * dx + a[2] * dy
    if abs(xb + e) > length / 2 + r:
        return True
    return abs(yb - B / 2) > b / 2 + r and abs(yb + B / 2) > b / 2 + r


def ringing(tol: float, z: float, v: float, p: float, dp: float, plA: float, plB: float, h: float,
            areal_mass: float, damping: float) -> bool:
    """engine.c ringing: the cell (sinkage z, rate v, reaction p, dp/dz = dp at its state) rings at
    the step start, its load going from plA to plB over h: its motion about the quasi-static path
    (p following the load, at the rate (plB - plA) / (h dp)) has an amplitude sqrt(d^2 + e^2 m / dp)
    above tol |z|, d = (plA - p - c v) / dp its displacement from that path and e its excess rate
    (docs/terrain.md, "The cells' ringing")."""
    if not (tol > 0.0 and dp > 0.0 and h > 0.0):
        return False
    ik, ih = 1.0 / dp, 1.0 / h  # as engine.c: the reciprocals, then products
    d = (plA - p - damping * v) * ik
    ev = v - (plB - plA) * ih * ik
    tz = tol * z
    return d * d + areal_mass * ev * ev * ik > tz * tz


class PyErr:
    """The error fields of the C struct, for the interpreted kernel."""

    def __init__(self):
        self.err_code, self.err_a, self.err_b, self.err_ch = 0, -1, -1, -1
        self.err_x = [0.0, 0.0]
        self.n_new = 0


class PyKernel:
    """engine.c in Python on CasADi's interpreter: the same algorithm, expression by expression."""

    compiled = False

    def __init__(self, fns, state: EngineState):
        self.f, self.s = fns, state
        self.e = PyErr()

    # the generated Functions
    def _row(self, soil):
        """The soil's law row (grid_engine.c's LAW_ROW: the state's soil_law table)."""
        return self.s.soil_law[soil]

    def _law(self, z, hist, soil):
        p, dp = self.f.law(z, hist, self._row(soil))
        return float(p), float(dp)

    def _hist(self, ch):
        s = self.s
        return [float(s.ch_zmax[ch]), float(s.ch_pmax[ch]), float(s.ch_zoff[ch]), float(s.ch_delta[ch]),
                float(s.ch_dc[ch])]

    def _geo(self, cx, cy, a):
        return np.array(self.f.cell_geo(ca.DM([cx, cy]), ca.DM(a), ca.DM(self.s.geo))).ravel()

    def _scan(self, X, Y, psi, pad, check_field, fn):
        s = self.s
        g = s.grid
        l, b, B, e = (float(v) for v in s.geo[:4])
        c, sn = math.cos(psi), math.sin(psi)
        dx, x0, y0 = g.cell_m, g.origin_m[0], g.origin_m[1]
        nx, ny = g.shape
        x1, y1 = x0 + nx * dx, y0 + ny * dx
        for sg in (1.0, -1.0):
            bx, by = -e, sg * B / 2
            cx, cy = X + c * bx - sn * by, Y + sn * bx + c * by
            hl, hw = l / 2 + pad, b / 2 + pad
            ex = abs(c) * hl + abs(sn) * hw
            ey = abs(sn) * hl + abs(c) * hw
            if check_field:
                exu, eyu = ex - pad * (abs(c) + abs(sn)), ey - pad * (abs(c) + abs(sn))
                if cx - exu < x0 or cx + exu > x1 or cy - eyu < y0 or cy + eyu > y1:
                    self.e.err_code, self.e.err_x = ERR_FIELD, [cx, cy]
                    return 1
            i0, i1 = max(math.floor((cx - ex - x0) / dx), 0), min(math.ceil((cx + ex - x0) / dx), nx - 1)
            j0, j1 = max(math.floor((cy - ey - y0) / dx), 0), min(math.ceil((cy + ey - y0) / dx), ny - 1)
            for i in range(i0, i1 + 1):
                px = x0 + (i + 0.5) * dx
                for j in range(j0, j1 + 1):
                    py = y0 + (j + 0.5) * dx
                    along = (px - cx) * c + (py - cy) * sn
                    across = -(px - cx) * sn + (py - cy) * c
                    if abs(along) <= hl and abs(across) <= hw:
                        fn(i * ny + j)
        return 0

    def _channel_of(self, cell):
        i, j = divmod(cell, self.s.grid.shape[1])
        return (i % self.s.M) * self.s.M + (j % self.s.M)

    def assign(self, h: float):
        s, e = self.s, self.e
        w = s.wv
        X, Y, psi, u, v, r = (float(w[i]) for i in range(6))
        c, sn = math.cos(psi), math.sin(psi)
        X1, Y1, psi1 = X + h * (u * c - v * sn), Y + h * (u * sn + v * c), psi + h * r
        s.stamp += 1
        new = []

        def mark(cell):
            if e.err_code:
                return
            ch = self._channel_of(cell)
            if s.ch_cell[ch] == cell:
                s.ch_foot[ch] = s.stamp
            elif s.ch_new_stamp[ch] == s.stamp:
                if s.ch_new_cell[ch] != cell:
                    e.err_code, e.err_a, e.err_b, e.err_ch = ERR_COLLISION, int(s.ch_new_cell[ch]), cell, ch
            else:
                s.ch_new_stamp[ch] = s.stamp
                s.ch_new_cell[ch] = cell
                new.append(cell)

        e.n_new = 0
        if self._scan(X, Y, psi, s.pad, True, mark) or self._scan(X1, Y1, psi1, s.pad, True, mark) or e.err_code:
            s.new_list[:len(new)] = new
            e.n_new = len(new)
            return e.err_code, e
        keep = []
        for ch in s.act[:s.n_act]:
            if s.ch_foot[ch] != s.stamp and s.ch_p[ch] <= 0.0 and abs(s.ch_v[ch]) <= s.release_rate:
                s.ch_cell[ch] = -1
                s.ch_z[ch] = s.ch_v[ch] = s.ch_p[ch] = 0.0
            else:
                keep.append(ch)
        s.n_act = len(keep)
        s.act[:s.n_act] = keep
        s.new_list[:len(new)] = new
        e.n_new = len(new)
        for cell in new:
            ch = self._channel_of(cell)
            if s.ch_cell[ch] >= 0:
                e.err_code, e.err_a, e.err_b, e.err_ch = ERR_COLLISION, cell, int(s.ch_cell[ch]), ch
                return e.err_code, e
        g = s.grid
        st = s.storage
        for cell in new:
            ch = self._channel_of(cell)
            i, j = divmod(cell, g.shape[1])
            s.ch_cell[ch] = cell
            s.ch_cx[ch] = g.origin_m[0] + (i + 0.5) * g.cell_m
            s.ch_cy[ch] = g.origin_m[1] + (j + 0.5) * g.cell_m
            s.ch_z[ch], s.ch_v[ch] = st.z[cell], st.zdot[cell]
            s.ch_zmax[ch], s.ch_pmax[ch] = st.zmax[cell], st.pmax[cell]
            s.ch_zoff[ch], s.ch_delta[ch], s.ch_dc[ch], s.ch_counted[ch] = st.zoff[cell], 0.0, 0.0, 0
            s.ch_soil[ch] = st.soil_index[cell]
            soil = int(s.ch_soil[ch])
            s.ch_delta[ch] = float(self.f.cell_entry(float(s.ch_z[ch]), self._hist(ch), float(st.cycles[cell]),
                                                self._row(soil)))
            s.ch_p[ch] = 0.0
            s.ch_pw[ch] = 0.0
            s.ch_vr[ch] = s.ch_v[ch]
            s.ch_p[ch], s.ch_dp[ch] = self._law(s.ch_z[ch], self._hist(ch), soil)
            s.touched[cell] = True
            s.ch_g[ch] = self._geo(s.ch_cx[ch], s.ch_cy[ch], s.a)
            s.act[s.n_act] = ch
            s.n_act += 1
        s.peak_active = max(s.peak_active, s.n_act)
        return 0, e

    def _coefficients(self, gh):
        """engine.c stage_coefficients: (a, 1 / a, g) of a stage of length gh."""
        m, cd = self.s.areal_mass, self.s.damping
        a = (1.0 + gh * cd / m) / gh
        return a, 1.0 / a, gh / m

    def _stage(self, zeta, omega, pl, a, ia, g, hist, soil, zs, ps, dps):
        s = self.s
        hi = zeta + (omega + g * pl) * ia
        lo = -math.inf
        x = (a * zeta + omega + g * (pl - ps + dps * zs)) / (a + g * dps)
        if not x < hi:
            x = hi
        for _ in range(NEWTON_MAX_ITER):
            s.stats["n_newton"] += 1
            p, dp = self._law(x, hist, soil)
            F = a * (x - zeta) + g * p - omega - g * pl
            if F > 0.0:
                hi = x
            elif F < 0.0:
                lo = x
            else:
                break
            xn = x - F / (a + g * dp)
            if abs(xn - x) <= 1e-13 * abs(xn) + 1e-18:
                break
            if abs(xn - x) <= NEWTON_ACCEPT_STEP * abs(xn) and lo < xn < hi:
                p = max(0.0, p + dp * (xn - x))
                x = xn
                break
            if not (lo < xn < hi):
                if lo == -math.inf:
                    ph, _ = self._law(hi, hist, soil)
                    lo = hi - g * ph * ia
                if not (lo < xn < hi):
                    xn = 0.5 * (lo + hi)
            x = xn
        if not abs(a * (x - zeta) + g * p - omega - g * pl) <= (1e-6 * abs(x) + 1e-18) * (a + g * dp):
            return None  # the Newton step from x, F / F', not below 1e-6 |x| + 1e-18 m
        return x, p, dp

    def _cell_step(self, z0, v0, pz, dpz, pl, f, hist, soil, h, n, work, euler=False):
        gam = SDIRK_GAMMA
        hs = h / n
        gh = gam * hs
        if euler:
            vr = v0
            ae, iae, ge = self._coefficients(hs)
            ihs = 1.0 / hs
            for k in range(n):
                p0 = pz
                r1 = self._stage(z0, v0, pl[k + 1], ae, iae, ge, hist, soil, z0, pz, dpz)
                if r1 is None:
                    return None
                Z1, pz, dpz = r1
                w1 = 0.5 * (p0 + pz) * max(Z1 - z0, 0.0)
                for t in range(2):
                    work[t] += 0.5 * (f[2 * k + t] + f[2 * k + 2 + t]) * w1
                v0 = (Z1 - z0) * ihs
                vr = v0
                z0 = Z1
                self.s.stats["n_cell_stages"] += 1
            return z0, v0, pz, dpz, vr
        a, ia, g = self._coefficients(gh)
        igh, ihs = 1.0 / gh, 1.0 / hs
        q0, q1, q2 = (1.0 - gam) / gam * ihs, ihs / (gam * (gam - 1.0)), (2.0 - gam) / (1.0 - gam) * ihs
        for k in range(n):
            p0 = pz
            plA, plB = pl[k], pl[k + 1]
            r1 = self._stage(z0, v0, plA + (plB - plA) * gam, a, ia, g, hist, soil, z0, pz, dpz)
            if r1 is None:
                return None
            Z1, pz, dpz = r1
            p1 = pz
            V1 = (Z1 - z0) * igh
            A1 = (V1 - v0) * igh
            zeta, omega = z0 + hs * (1.0 - gam) * V1, v0 + hs * (1.0 - gam) * A1
            r2 = self._stage(zeta, omega, plB, a, ia, g, hist, soil, Z1, pz, dpz)
            if r2 is None:
                return None
            Z2, pz, dpz = r2
            m1, m2 = 0.5 * gam, 0.5 * (gam + 1.0)
            w1, w2 = 0.5 * (p0 + p1) * max(Z1 - z0, 0.0), 0.5 * (p1 + pz) * max(Z2 - Z1, 0.0)
            for t in range(2):
                fa, fb = f[2 * k + t], f[2 * k + 2 + t]
                work[t] += (fa + (fb - fa) * m1) * w1 + (fa + (fb - fa) * m2) * w2
            v0 = (Z2 - zeta) * igh
            vr = z0 * q0 + Z1 * q1 + Z2 * q2  # the quadratic through (0, z0), (gamma, Z1), (1, Z2)
            z0 = Z2
            self.s.stats["n_cell_stages"] += 2
        return z0, v0, pz, dpz, vr

    def _info_out(self, ch, hist, soil):
        s, st = self.s, self.s.storage
        zc, p = float(s.ch_z[ch]), float(s.ch_p[ch])
        zm1, pm1, dc1, plastic, phase = np.array(self.f.cell_history(zc, p, hist, self._row(soil))).ravel()
        cell = int(s.ch_cell[ch])
        st.z[cell], st.zdot[cell], st.zmax[cell], st.pmax[cell] = zc, s.ch_v[ch], zm1, pm1
        st.phase[cell] = int(phase) if zm1 > 0 else 0
        st.zoff[cell] = s.ch_zoff[ch] + dc1
        if plastic > 0 and not s.ch_counted[ch]:
            s.ch_counted[ch] = 1
            st.cycles[cell] = min(int(st.cycles[cell]) + 1, 65535)
        s.ch_zmax[ch], s.ch_pmax[ch], s.ch_dc[ch] = zm1, pm1, dc1

    def static(self) -> None:
        s = self.s
        for ch in s.act[:s.n_act]:
            soil, hist = int(s.ch_soil[ch]), self._hist(ch)
            z0, pl = float(s.ch_z[ch]), float(s.ch_g[ch, 0])
            p, _ = self._law(z0, hist, soil)
            if pl != p:
                up = pl > p
                lo = hi = z0
                step = 1e-4
                for _ in range(60):
                    if up:
                        hi = lo + step
                    else:
                        lo = hi - step
                    p, _ = self._law(hi if up else lo, hist, soil)
                    if (not p < pl) if up else (not p > pl):
                        break
                    step *= 2.0
                for _ in range(200):
                    if not hi - lo > 1e-15:
                        break
                    mid = 0.5 * (lo + hi)
                    p, _ = self._law(mid, hist, soil)
                    if p <= pl:
                        lo = mid
                    else:
                        hi = mid
                s.ch_z[ch] = 0.5 * (lo + hi)
            s.ch_v[ch] = s.ch_vr[ch] = 0.0
            s.ch_p[ch], s.ch_dp[ch] = self._law(float(s.ch_z[ch]), hist, soil)

    def surface(self, x, y):
        """eng_surface: the numpy terrain query on the storage (symtrack/terrain/query.py)."""
        q = query.query(self.s.storage, x, y, outside="nan")
        out = np.column_stack([q.elevation_m, q.sinkage_m, q.height_m, q.normal, q.gradient])
        return int(np.count_nonzero(q.cell < 0)), q.cell, q.phase.astype(np.intc), out

    def lift(self, p_end, h, T, n, max_steps):
        s, e = self.s, self.e
        fr = [0.0] * (2 * (n + 1))
        for k in range(max_steps):
            t0 = k * h
            act = s.act[:s.n_act]
            if t0 >= T and all(s.ch_p[ch] <= 0.0 and abs(s.ch_v[ch]) <= s.release_rate for ch in act):
                return k, True, e
            for ch in act:
                pe = float(p_end[ch])
                if s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and pe == 0.0:
                    continue
                pl = [pe * max(0.0, 1.0 - (t0 + h * j / n) / T) for j in range(n + 1)]
                hist = self._hist(ch)
                soil = int(s.ch_soil[ch])
                out = self._cell_step(float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]), float(s.ch_dp[ch]),
                                      pl, fr, hist, soil, h, n, [0.0, 0.0])
                if out is None:
                    e.err_code, e.err_a = ERR_NEWTON, int(s.ch_cell[ch])
                    return -ERR_NEWTON, False, e
                s.ch_z[ch], s.ch_v[ch], s.ch_p[ch], s.ch_dp[ch], _ = out
                self._info_out(ch, hist, soil)
        return max_steps, False, e

    def sums(self):
        s = self.s
        S = [0.0] * s.n_sums
        for ch in s.act[:s.n_act]:
            g = s.ch_g[ch]
            zc = float(s.ch_z[ch])
            if s.settings.power == "step_mean":
                S[0] += s.ch_pw[ch, 0]
                S[1] += s.ch_pw[ch, 1]
            else:
                pw = float(s.ch_p[ch]) * max(float(s.ch_vr[ch]), 0.0)
                S[0] += g[1] * pw
                S[1] += g[2] * pw
            for r in range(4):
                S[2 + r] += g[3 + r] * zc
                S[6 + r] += g[3 + r]
            if s.n_sums > NS:
                sv = s.soil_veh[3 * int(s.ch_soil[ch]):3 * int(s.ch_soil[ch]) + 3]
                for t in range(2):
                    S[NS + t] += g[1 + t]
                    for i in range(3):
                        S[NS + 2 + 3 * t + i] += g[1 + t] * sv[i]
        s.pv[-s.n_sums:] = S

    def _uncovered(self, w1):
        s = self.s
        missing = []

        def check(cell):
            if s.ch_cell[self._channel_of(cell)] != cell:
                missing.append(cell)
        self._scan(*w1[self.f.layout.pose_index], 0.5 * s.grid.cell_m, False, check)
        return missing

    def _vehicle_step(self, u, h):
        return self._vehicle_step_controlled(np.array(self.s.wv, dtype=float), u, h, 0)

    def _vehicle_step_controlled(self, w0, u, h, depth):
        """engine.c vehicle_step_controlled: the step, halved while its error estimate is too large."""
        w1, a1, e1 = (np.array(v).ravel() for v in self.f.vehicle_step(w0, u, self.s.pv, h))
        self.s.stats["n_vehicle_steps"] += 1
        rtol = self.s.settings.vehicle_tolerance
        if not rtol > 0.0 or depth >= VEHICLE_MAX_HALVINGS:
            return w1, a1
        nv = self.f.layout.nv
        scale = VEHICLE_ATOL + rtol * np.maximum(np.abs(w0[:nv]), np.abs(w1[:nv]))
        if np.all(np.abs(e1[:nv]) <= scale):
            return w1, a1
        self.s.stats["n_vehicle_halved"] += 1
        wm, _ = self._vehicle_step_controlled(w0, u, 0.5 * h, depth + 1)
        return self._vehicle_step_controlled(wm, u, 0.5 * h, depth + 1)

    def _pose_grid(self, a1, psi1, n):
        """engine.c pose_grid: the pose and pressure lines at the ends of n equal substeps."""
        s = self.s
        grid = [s.a.copy()]
        for j in range(1, n):
            th = j / n
            psi = s.wv[2] + (psi1 - s.wv[2]) * th
            aj = s.a + (a1 - s.a) * th
            aj[2], aj[3] = math.cos(psi), math.sin(psi)
            grid.append(aj)
        grid.append(a1.copy())
        return grid

    def run(self, t0, T, U, dist, check_covered, T_out, X, Y):
        s, e = self.s, self.e
        t = t0
        n_done = 0
        sset = s.settings
        nsub = sset.cell_substeps
        nentry, nexit = window_substeps(sset)
        for k in range(T.size):
            t_next = float(T[k])
            h = t_next - t
            u = U[k]
            done = False
            rc, _ = self.assign(h)
            if rc:
                return -rc, n_done, e
            w1, a1 = self._vehicle_step(u, h)
            if dist[1] >= 0.0 and t_next > dist[2] + 1e-12:
                d_step = math.hypot(w1[0] - s.wv[0], w1[1] - s.wv[1])
                if dist[0] + d_step >= dist[1]:
                    for _ in range(3):
                        if d_step <= 0:
                            break
                        h *= (dist[1] - dist[0]) / d_step
                        w1, a1 = self._vehicle_step(u, h)
                        d_step = math.hypot(w1[0] - s.wv[0], w1[1] - s.wv[1])
                    t_next = t + h
                    done = True
                dist[0] += d_step
            if not np.all(np.isfinite(w1)):
                e.err_code = ERR_NONFINITE
                return -ERR_NONFINITE, n_done, e
            grid_exit = self._pose_grid(a1, w1[2], nexit)
            grid_entry = grid_exit if nentry == nexit else self._pose_grid(a1, w1[2], nentry)
            ih = 1.0 / h if h > 0.0 else 0.0  # engine.c: the step's reciprocal
            for ch in s.act[:s.n_act]:
                if (s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and s.ch_g[ch][0] == 0.0
                        and outside_tracks(s.geo, s.ch_cx[ch], s.ch_cy[ch], a1)):
                    s.ch_g[ch] = 0.0
                    s.ch_pw[ch] = 0.0
                    s.ch_p[ch] = 0.0
                    s.ch_vr[ch] = 0.0
                    continue
                gB = self._geo(s.ch_cx[ch], s.ch_cy[ch], a1)
                gA = s.ch_g[ch]
                plA, plB = float(gA[0]), float(gB[0])
                s.ch_pw[ch] = 0.0
                if s.ch_z[ch] == 0.0 and s.ch_v[ch] == 0.0 and plA == 0.0 and plB == 0.0:
                    s.ch_g[ch] = gB
                    s.ch_p[ch] = 0.0
                    s.ch_vr[ch] = 0.0
                    continue
                ns = nsub
                wgrid = None
                if (plB < plA and gB[1] + gB[2] < gA[1] + gA[2]
                        and s.ch_z[ch] < s.ch_zmax[ch] + s.ch_zoff[ch] + s.ch_dc[ch]):
                    if nexit > ns:
                        ns, wgrid = nexit, grid_exit
                elif (s.ch_p[ch] < sset.entry_fraction * max(plA, plB)
                      or ringing(sset.ring_tolerance, float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]),
                                 float(s.ch_dp[ch]), plA, plB, h, s.areal_mass, s.damping)):
                    if nentry > ns:
                        ns, wgrid = nentry, grid_entry
                pl, fr = [plA], [float(gA[1]), float(gA[2])]
                for j in range(1, ns):
                    if wgrid is not None:
                        gj = self._geo(s.ch_cx[ch], s.ch_cy[ch], wgrid[j])
                        pl.append(float(gj[0]))
                        fr += [float(gj[1]), float(gj[2])]
                    else:
                        th = j / ns
                        pl.append(plA + (plB - plA) * th)
                        fr += [float(gA[1] + (gB[1] - gA[1]) * th), float(gA[2] + (gB[2] - gA[2]) * th)]
                pl.append(plB)
                fr += [float(gB[1]), float(gB[2])]
                work = [0.0, 0.0]
                hist = self._hist(ch)
                soil = int(s.ch_soil[ch])
                out = self._cell_step(float(s.ch_z[ch]), float(s.ch_v[ch]), float(s.ch_p[ch]), float(s.ch_dp[ch]),
                                      pl, fr, hist, soil, h, ns, work,
                                      wgrid is None and sset.steady_method == "euler")
                if out is None:
                    e.err_code, e.err_a = ERR_NEWTON, int(s.ch_cell[ch])
                    return -ERR_NEWTON, n_done, e
                s.ch_z[ch], s.ch_v[ch], s.ch_p[ch], s.ch_dp[ch], s.ch_vr[ch] = out
                s.ch_pw[ch] = (work[0] * ih, work[1] * ih)
                s.ch_g[ch] = gB
                self._info_out(ch, hist, soil)
            if s.subsoil is not None:
                act = s.act[:s.n_act]
                act = act[s.ch_g[act, 0] > 0.0]
                if act.size:
                    sig = subsoil.stress_at(s.subsoil, s.ch_cx[act], s.ch_cy[act], a1, s.geo).astype(np.float32)
                    cells = s.ch_cell[act]
                    s.sig_pass[cells] = np.maximum(s.sig_pass[cells], sig)
                    if s.compute_mean_stress and s.subsoil_p is not None:  # the mean normal stress (when asked)
                        pm = subsoil.stress_at(s.subsoil_p, s.ch_cx[act], s.ch_cy[act], a1, s.geo).astype(np.float32)
                        s.p_pass[cells] = np.maximum(s.p_pass[cells], pm)
            s.wv[:] = w1
            s.a[:] = a1
            self.sums()
            t = t_next
            T_out[k] = t
            vs = self.f.layout.block("vehicle")
            X[k] = w1[vs]
            Y[k] = np.array(self.f.outputs(w1[vs], u, s.pv)).ravel()
            n_done = k + 1
            if check_covered:
                missing = self._uncovered(w1)
                if missing:
                    e.err_code, e.err_a, e.err_b = ERR_UNCOVERED, missing[0], len(missing)
                    return -ERR_UNCOVERED, n_done, e
            if done:
                return 1, n_done, e
        return 0, n_done, e

