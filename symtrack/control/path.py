"""Reference paths for path tracking: straight segments and circular arcs, sampled densely.

A path starts at a pose (x_m, y_m, heading) and chains segments; the heading is continuous
(not wrapped), so a U-turn ends at heading + pi. Each sample carries its arc length s, position,
heading, curvature (1/m, positive to the left), the segment index and whether it is straight.
A straight extension is appended after the last segment so that a horizon reaching past the end
still has a reference; it is not part of the path's length.

A segment with ``reverse`` is driven backwards (a K-turn's middle arc): the heading stays the
vehicle's, the position moves against it, s still grows with the distance travelled and the
curvature is d(heading)/ds (a reverse arc of positive radius turns the vehicle counter-clockwise,
its centre on the vehicle's right). ``direction`` holds +1 or -1 per sample, ``cusps_s`` the arc
lengths where it changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..foundations.errors import ScenarioError

__all__ = ["Path", "Segment", "field_segments"]


@dataclass(frozen=True)
class Segment:
    kind: str  # "straight" | "arc"
    length_m: float = 0.0
    radius_m: float = 0.0  # arcs: positive = left turn
    angle_deg: float = 0.0  # arcs: positive sweep
    speed_m_s: float | None = None
    reverse: bool = False  # driven backwards (module doc)


class Path:
    def __init__(self, x_m: float, y_m: float, heading_rad: float, segments, speed_m_s: float,
                 turn_speed_m_s: float | None = None, ds_m: float = 0.02, extension_m: float = 30.0):
        if not segments:
            raise ScenarioError("path: at least one segment is required")
        self.segments = tuple(segments)
        xs, ys, ps = [np.array([x_m], float)], [np.array([y_m], float)], [np.array([heading_rad], float)]
        ks, si, st, vs, ds = [], [], [], [], []
        x, y, psi = x_m, y_m, heading_rad
        all_segs = list(self.segments) + [Segment("straight", extension_m)]
        for idx, seg in enumerate(all_segs):
            if seg.kind == "straight":
                L, kappa = seg.length_m, 0.0
            else:
                L = abs(seg.radius_m) * math.radians(seg.angle_deg)
                kappa = 1.0 / seg.radius_m
            v = seg.speed_m_s or (speed_m_s if seg.kind == "straight" else (turn_speed_m_s or speed_m_s))
            n = max(1, int(math.ceil(L / ds_m)))
            h = L / n
            sgn = -1.0 if seg.reverse else 1.0
            # the segment's n samples after its start: each step's increment summed in order (np.cumsum adds
            # one after the other: the samples to the last bit of a step-by-step walk, on which the
            # controllers' runs depend), the headings psi + dpsi + ... on an arc and its position's
            # increments (sin(psi_k) - sin(psi_(k-1))) / kappa, exact on its circle
            if kappa == 0.0:
                xk = np.cumsum(np.concatenate([[x], np.full(n, sgn * h * math.cos(psi))]))[1:]
                yk = np.cumsum(np.concatenate([[y], np.full(n, sgn * h * math.sin(psi))]))[1:]
                pk = np.full(n, psi)
            else:
                heads = np.cumsum(np.concatenate([[psi], np.full(n, h * kappa)]))
                # the math library's sine and cosine, as the walk's (numpy's may differ in the last bit)
                sin = np.fromiter(map(math.sin, heads), float, heads.size)
                cos = np.fromiter(map(math.cos, heads), float, heads.size)
                xk = np.cumsum(np.concatenate([[x], sgn * (sin[1:] - sin[:-1]) / kappa]))[1:]
                yk = np.cumsum(np.concatenate([[y], -(sgn * (cos[1:] - cos[:-1]) / kappa)]))[1:]
                pk = heads[1:]
            xs.append(xk)
            ys.append(yk)
            ps.append(pk)
            ks.append(np.full(n, kappa))
            si.append(np.full(n, idx if idx < len(self.segments) else -1))
            st.append(np.full(n, seg.kind == "straight"))
            vs.append(np.full(n, float(v)))
            ds.append(np.full(n, sgn))
            x, y, psi = float(xk[-1]), float(yk[-1]), float(pk[-1])
        # the last sample: the extension's (straight, segment -1) curvature, direction and speed once more
        ks, si, st, vs, ds = (np.concatenate([*a, a[-1][-1:]]) for a in (ks, si, st, vs, ds))
        xs, ys, ps = (np.concatenate(a) for a in (xs, ys, ps))
        self.direction = ds
        self.x, self.y, self.psi = xs, ys, ps
        self.kappa, self.segment, self.straight = ks, si, st
        self.speed = vs
        seg_len = np.hypot(np.diff(self.x), np.diff(self.y))
        self.s = np.concatenate([[0.0], np.cumsum(seg_len)])
        # the path ends where the extension's first interval starts
        self.length_m = float(self.s[np.nonzero(self.segment == -1)[0][0]])
        self.cusps_s = self.s[1:-1][np.diff(self.direction[:-1]) != 0] if self.direction.size > 2 else np.zeros(0)

    def project(self, x: float, y: float, s_hint: float | None = None, window_m: tuple = (-3.0, 12.0)) -> float:
        """Arc length of the closest path point; with s_hint, searched only in
        [s_hint + window[0], s_hint + window[1]] (so parallel passes are never confused)."""
        if s_hint is None:
            lo, hi = 0, len(self.s)
        else:
            lo = int(np.searchsorted(self.s, s_hint + window_m[0]))
            hi = int(np.searchsorted(self.s, s_hint + window_m[1])) + 1
            lo, hi = max(lo, 0), min(hi, len(self.s))
        d2 = (self.x[lo:hi] - x) ** 2 + (self.y[lo:hi] - y) ** 2
        i = lo + int(np.argmin(d2))
        # refine on the neighbouring intervals (linear)
        best_s, best_d = self.s[i], d2[i - lo]
        for j in (i - 1, i):
            if 0 <= j < len(self.s) - 1:
                ex, ey = self.x[j + 1] - self.x[j], self.y[j + 1] - self.y[j]
                L2 = ex * ex + ey * ey
                if L2 <= 0:
                    continue
                t = min(1.0, max(0.0, ((x - self.x[j]) * ex + (y - self.y[j]) * ey) / L2))
                px, py = self.x[j] + t * ex, self.y[j] + t * ey
                dd = (px - x) ** 2 + (py - y) ** 2
                if dd < best_d:
                    best_d, best_s = dd, self.s[j] + t * math.sqrt(L2)
        return float(best_s)

    def at(self, s: float) -> dict:
        """Interpolated pose, curvature, speed, segment at arc length s."""
        s = min(max(s, 0.0), self.s[-1])
        i = min(int(np.searchsorted(self.s, s, side="right")) - 1, len(self.s) - 2)
        t = (s - self.s[i]) / max(self.s[i + 1] - self.s[i], 1e-12)
        return {
            "x_m": self.x[i] + t * (self.x[i + 1] - self.x[i]),
            "y_m": self.y[i] + t * (self.y[i + 1] - self.y[i]),
            "yaw_rad": self.psi[i] + t * (self.psi[i + 1] - self.psi[i]),
            "curvature_1_per_m": float(self.kappa[i]),
            "speed_m_s": float(self.speed[i]),
            "segment": int(self.segment[i]),
            "straight": bool(self.straight[i]),
        }

    def errors(self, x: float, y: float, yaw: float, s: float) -> tuple[float, float]:
        """Signed lateral error (positive: left of the path) and heading error at arc length s."""
        r = self.at(s)
        dx, dy = x - r["x_m"], y - r["y_m"]
        e_lat = -dx * math.sin(r["yaw_rad"]) + dy * math.cos(r["yaw_rad"])
        e_psi = (yaw - r["yaw_rad"] + math.pi) % (2 * math.pi) - math.pi
        return e_lat, e_psi

    def reference(self, s0: float, n_steps: int, dt: float, yaw_now: float) -> np.ndarray:
        """(n_steps + 1) x 5 reference [x, y, yaw, speed, curvature] from s0, advancing at the
        path's speed; the yaw is shifted by a multiple of 2 pi to lie near yaw_now."""
        out = np.zeros((n_steps + 1, 5))
        s = s0
        shift = None
        for k in range(n_steps + 1):
            r = self.at(s)
            if shift is None:
                shift = 2 * math.pi * round((yaw_now - r["yaw_rad"]) / (2 * math.pi))
            out[k] = (r["x_m"], r["y_m"], r["yaw_rad"] + shift, r["speed_m_s"], r["curvature_1_per_m"])
            s += r["speed_m_s"] * dt
        return out


def field_segments(passes: int, pass_length_m: float, spacing_m: float, first_turn: str = "left") -> list[Segment]:
    """Parallel passes joined by headland U-turns of radius spacing/2, alternating sides."""
    segs = []
    sign = 1.0 if first_turn == "left" else -1.0
    for i in range(passes):
        segs.append(Segment("straight", pass_length_m))
        if i < passes - 1:
            segs.append(Segment("arc", radius_m=sign * spacing_m / 2, angle_deg=180.0))
            sign = -sign
    return segs
