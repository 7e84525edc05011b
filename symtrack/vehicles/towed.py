"""A towed load following the crawler: a trailer or grain cart on one axle of two tyres, hitched
behind the crawler, whose wheels load the cells along the crawler's driven path in the same run
(docs/subsoil.md, "A towed load").

The scenario's ``[terrain.towed]`` (every key required but ``element_m``)::

    [terrain.towed]
    axle_load_kN = 60.0              # the axle's load on the ground, both wheels together
    wheel_gauge_m = 1.5              # between the two wheels' centres (>= the tyre's width)
    tyre_width_m = 0.6               # section width b
    tyre_diameter_m = 1.6            # overall diameter D
    tyre_rated_load_kN = 45.0        # the tyre's rated load at its rated pressure (load index)
    tyre_rated_inflation_kPa = 240.0
    inflation_kPa = 160.0            # the pressure it runs at (<= rated)
    hitch_behind_track_centre_m = 1.6  # the hitch on the crawler's centre line, this far behind
                                     # the middle of its tracks' contact
    drawbar_length_m = 4.0           # hitch to the axle's centre
    element_m = 0.025                # the contact's elements (tyre.contact), (0, 0.1]

Each wheel's contact and stress are Keller's (2005) of symtrack/vehicles/tyre.py at a wheel load of
half the axle load; the machine's pass is :func:`symtrack.vehicles.wheeled.wheeled_pass`. Refused on
parsing, before anything is built: a key missing or unknown, a value outside its range, a wheel
load beyond what the tyre carries at the inflation pressure (tyre.load_capacity_kN), a load
Keller's distribution cannot carry, wheels that overlap (gauge below the tyre's width).

**The towed axle's kinematics** (low-speed off-tracking; the tractrix: Sayers, M.W., 1991. Exact
equations for tractrix curves associated with vehicle offtracking. Vehicle System Dynamics 20(5),
297-308, abstract read; the equations below are derived here). The hitch H moves with the crawler;
the axle centre A = H - L u(theta) is L behind it along the trailer's heading theta,
u = (cos theta, sin theta), n = (-sin theta, cos theta). Rolling tyres without side slip allow A to
move only along u: dA/dt . n = 0. With dA/dt = dH/dt - L dtheta/dt n this is

    dtheta/dt = (dH/dt . n) / L .

On a straight piece of the hitch's path (direction phi, arc length s), dH/dt . n = v sin(phi -
theta), so the trailer's angle to the path delta = theta - phi obeys d delta / ds = -sin(delta) / L,
whose solution is

    tan(delta(s) / 2) = tan(delta(0) / 2) exp(-s / L)

(the tractrix). The hitch's path is the polyline of its positions at the run's output times,
integrated piece by piece with this exact solution (no step size error; any path, forward or
reversing). So the axle moves toward the hitch and on a turn cuts inside: with the hitch on a
steady circle of radius r_h the steady state has A's velocity tangent to A's own circle about the
same centre, i.e. u perpendicular to OA, and the right triangle O A H gives

    r_axle = sqrt(r_h^2 - L^2)       (r_h > L; tests/test_towed.py).

The trailer starts each pass aligned with the crawler (theta = psi at the pass's first sample).

ASSUMED, and what is left out: the towed load does not act on the crawler (no drawbar pull, no
vertical hitch load: the crawler drives as it would alone; the axle load is what the trailer's
tyres put on the ground); one axle of two wheels; the wheels do not change the surface (no ruts,
as wheeled_pass); the stress concentration factor is the field's soil 0's.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..foundations.config import check_keys, number
from ..foundations.errors import ParameterError, ScenarioError
from ..terrain.storage import Grid, Terrain
from . import tyre, wheeled

__all__ = ["KEYS", "Towed", "axle_path", "check_inside", "check_scenario", "hitch_path", "parse_towed", "start_pose",
           "towed_pass"]

KEYS = ("axle_load_kN", "wheel_gauge_m", "tyre_width_m", "tyre_diameter_m", "tyre_rated_load_kN",
        "tyre_rated_inflation_kPa", "inflation_kPa", "hitch_behind_track_centre_m", "drawbar_length_m", "element_m")
DEFAULT_ELEMENT_M = 0.025  # tyre.contact's elements in a field pass (docs/subsoil.md: within 0.45 % of 1 cm's)


@dataclasses.dataclass(frozen=True)
class Towed:
    """The parsed ``[terrain.towed]`` (module doc); ``contact`` each wheel's (tyre.contact)."""

    axle_load_kN: float
    wheel_gauge_m: float
    tyre: tyre.Tyre
    inflation_kPa: float
    hitch_behind_track_centre_m: float
    drawbar_length_m: float
    element_m: float
    contact: tyre.Contact = dataclasses.field(compare=False, repr=False)
    raw: dict = dataclasses.field(compare=False, repr=False, default_factory=dict)

    @property
    def wheel_load_kN(self) -> float:
        return 0.5 * self.axle_load_kN

    def wheels(self) -> list[wheeled.Wheel]:
        """The axle's two wheels in the trailer's frame (x forward along theta, y left; the axle
        centre at the origin)."""
        g = 0.5 * self.wheel_gauge_m
        return [wheeled.Wheel(self.contact, 0.0, g), wheeled.Wheel(self.contact, 0.0, -g)]


def parse_towed(t) -> Towed:
    """``[terrain.towed]`` -> :class:`Towed`; every refusal names the key, its value and the range."""
    check_keys("terrain.towed", t, KEYS)
    missing = [k for k in KEYS if k != "element_m" and k not in t]
    if missing:
        raise ScenarioError(f"[terrain.towed] needs {', '.join(missing)} (module symtrack.vehicles.towed)")

    def num(k, lo, hi, low_open=True):
        return number(f"terrain.towed.{k}", t[k], lo, hi, low_open)

    width, diameter = num("tyre_width_m", 0.1, 1.2), num("tyre_diameter_m", 0.3, 3.0)
    rated_load, rated_p = num("tyre_rated_load_kN", 0.0, 500.0), num("tyre_rated_inflation_kPa", 0.0, 1000.0)
    ty = tyre.Tyre(width, diameter, rated_load, rated_p)
    p = num("inflation_kPa", 0.0, rated_p)
    cap = tyre.load_capacity_kN(ty, p)
    axle = number("terrain.towed.axle_load_kN", t["axle_load_kN"], 0.0, 1000.0, True)
    if not axle <= 2.0 * cap:
        raise ScenarioError(f"terrain.towed.axle_load_kN = {t['axle_load_kN']!r} is outside the allowed range (0, "
                            f"{2 * cap:.4g}]: two tyres (rated {rated_load:g} kN at {rated_p:g} kPa) carry "
                            f"{cap:.4g} kN each at terrain.towed.inflation_kPa = {p:g} (W = W_max (p / p_max)^0.8, "
                            "symtrack/vehicles/tyre.py)")
    gauge = num("wheel_gauge_m", width, 10.0, low_open=False)
    hitch = num("hitch_behind_track_centre_m", 0.0, 20.0, low_open=False)
    L = num("drawbar_length_m", 0.0, 20.0)
    h = number("terrain.towed.element_m", t.get("element_m", DEFAULT_ELEMENT_M), 0.0, 0.1, True)
    try:
        c = tyre.contact(ty, 0.5 * axle, p, h)
    except ParameterError as err:
        raise ScenarioError(f"terrain.towed: {err}") from err
    return Towed(axle, gauge, ty, p, hitch, L, h, c, dict(t))


def hitch_path(poses, cg_ahead_of_contact_centre_m: float, towed: Towed) -> np.ndarray:
    """The hitch's world (x, y) (n, 2) at the crawler's poses (n, 3) of (X, Y, psi) of its CG: on
    the centre line, ``cg_ahead_of_contact_centre_m + hitch_behind_track_centre_m`` behind the CG."""
    poses = np.asarray(poses, dtype=float)
    back = cg_ahead_of_contact_centre_m + towed.hitch_behind_track_centre_m
    return np.column_stack([poses[:, 0] - back * np.cos(poses[:, 2]), poses[:, 1] - back * np.sin(poses[:, 2])])


def axle_path(hitch_xy, drawbar_length_m: float, theta0: float, spacing_m: float | None = None) -> np.ndarray:
    """The towed axle's poses (m, 3) of (x, y, theta) behind a hitch moving along the polyline
    ``hitch_xy`` (n, 2), the trailer's heading theta0 at the first point (module doc: the exact
    tractrix on each straight piece). Repeated points are dropped; with ``spacing_m`` every piece
    longer than it is cut into equal parts no longer than it (the axle moves at most as far as the
    hitch, so its poses are at most ``spacing_m`` apart)."""
    H = np.asarray(hitch_xy, dtype=float)
    L = float(drawbar_length_m)
    keep = np.concatenate([[True], np.hypot(*np.diff(H, axis=0).T) > 0.0])
    H = H[keep]
    if spacing_m is not None and len(H) > 1:
        seg = np.hypot(*np.diff(H, axis=0).T)
        parts = np.maximum(1, np.ceil(seg / spacing_m - 1e-9).astype(np.int64))
        pts = [H[:1]]
        for k in range(len(seg)):
            f = (np.arange(1, parts[k] + 1) / parts[k])[:, None]
            pts.append(H[k] + f * (H[k + 1] - H[k]))
        H = np.concatenate(pts)
    theta = np.empty(len(H))
    theta[0] = theta0
    for k in range(1, len(H)):
        dx, dy = H[k] - H[k - 1]
        phi = math.atan2(dy, dx)
        delta = math.remainder(theta[k - 1] - phi, 2.0 * math.pi)
        delta = 2.0 * math.atan(math.tan(0.5 * delta) * math.exp(-math.hypot(dx, dy) / L))
        theta[k] = phi + delta
    return np.column_stack([H[:, 0] - L * np.cos(theta), H[:, 1] - L * np.sin(theta), theta])


def check_inside(grid: Grid, towed: Towed, poses, where: str) -> None:
    """Every wheel's contact (its bounding box) inside the field ``grid`` at every axle pose, else a
    ScenarioError naming ``where`` and the first pose that leaves it."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    x0, x1, y0, y1 = grid.bounds()
    c = towed.contact
    hl, hw = 0.5 * c.length_m, 0.5 * c.width_m
    for w in towed.wheels():
        for bx, by in ((hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw)):
            lx, ly = w.x_m + bx, w.y_m + by
            ct, st = np.cos(poses[:, 2]), np.sin(poses[:, 2])
            px, py = poses[:, 0] + ct * lx - st * ly, poses[:, 1] + st * lx + ct * ly
            out = np.flatnonzero((px < x0) | (px > x1) | (py < y0) | (py > y1))
            if out.size:
                k = int(out[0])
                raise ScenarioError(f"{where}: the towed axle's wheel contact reaches ({px[k]:.3f}, {py[k]:.3f}) m, "
                                    f"outside the field x [{x0:g}, {x1:g}], y [{y0:g}, {y1:g}] m (axle at "
                                    f"({poses[k, 0]:.3f}, {poses[k, 1]:.3f})): enlarge terrain.size_m or move "
                                    "terrain.origin_m")


def check_scenario(settings, start_x_m: float, start_y_m: float, yaw_deg: float, soil: dict,
                   cg_ahead_of_contact_centre_m: float) -> None:
    """A scenario's towed load before anything is built: the stress concentration factor of its soil
    within [3, 10] (the mean normal stress needs xi - 2 >= 1) and, on a new field (no
    ``initial_state``: a terrain file brings its own geometry, checked before its first pass), the
    wheels inside the field at the start (the field centred on the start when ``origin_m`` is not
    given, as the world places it)."""
    tw = settings.towed
    xi = float(soil["stress_concentration_factor"])
    if not 3.0 <= xi <= 10.0:
        raise ScenarioError(f"terrain.towed: soil.stress_concentration_factor = {xi!r} is outside the allowed range "
                            "[3, 10] for the towed load's stress (its mean normal stress needs xi - 2 >= 1)")
    if settings.initial_state is not None:
        return
    nx, ny = settings.shape
    origin = settings.origin_m
    if origin is None:
        origin = (start_x_m - 0.5 * nx * settings.cell_m, start_y_m - 0.5 * ny * settings.cell_m)
    pose = start_pose(start_x_m, start_y_m, math.radians(yaw_deg), cg_ahead_of_contact_centre_m, tw)
    check_inside(Grid((float(origin[0]), float(origin[1])), float(settings.cell_m), (nx, ny)), tw, pose,
                 "terrain.towed at the start")


def start_pose(x_m: float, y_m: float, psi: float, cg_ahead_of_contact_centre_m: float, towed: Towed) -> np.ndarray:
    """The axle's pose (1, 3) with the crawler at rest at (x, y, psi), the trailer aligned."""
    h = hitch_path([[x_m, y_m, psi]], cg_ahead_of_contact_centre_m, towed)[0]
    L = towed.drawbar_length_m
    return np.array([[h[0] - L * math.cos(psi), h[1] - L * math.sin(psi), psi]])


def towed_pass(terrain: Terrain, towed: Towed, crawler_poses, cg_ahead_of_contact_centre_m: float, soils,
               xi: float, cell_params=None) -> dict:
    """The towed axle's pass behind the crawler's poses (n, 3) (X, Y, psi of its CG at the run's
    output times): its path (:func:`axle_path`, poses a quarter cell apart), the field coverage
    checked, then :func:`~symtrack.vehicles.wheeled.wheeled_pass` into the terrain's stress record and
    compression state, with the wheel's stress tabulated once per process
    (:func:`~symtrack.vehicles.tyre.footprint_table`). Returns wheeled_pass's figures with the
    prefix ``towed_`` and the axle's largest distance inside the hitch's path
    (``towed_offtracking_max_m``: how far the axle cuts inside on a turn). ``cell_params``: the
    cells' own compression parameters (a World's ``cell_day``; None: their soils')."""
    P = np.asarray(crawler_poses, dtype=float)
    H = hitch_path(P, cg_ahead_of_contact_centre_m, towed)
    A = axle_path(H, towed.drawbar_length_m, float(P[0, 2]), spacing_m=terrain.grid.cell_m / 4)
    check_inside(terrain.grid, towed, A, "terrain.towed")
    _, table = tyre.footprint_table(towed.tyre, towed.wheel_load_kN, towed.inflation_kPa, towed.element_m,
                                    tuple(terrain.subsoil_depths_m), float(xi), 2 * wheeled.DEFAULT_REACH_M)
    out = wheeled.wheeled_pass(terrain, towed.wheels(), A, xi, soils=soils, tables=[table, table],
                               cell_params=cell_params)
    # the hitch's path with the straight line it came along before the pass (the trailer starts aligned)
    off = _offtracking_max(np.concatenate([A[:1, :2], H]), A[:, :2])
    figs = {f"towed_{k}": v for k, v in out.items() if k != "subsoil_depths_m"}
    figs.update(towed_axle_poses=int(len(A)), towed_offtracking_max_m=off,
                towed_wheel_load_kN=towed.wheel_load_kN, towed_inflation_kPa=towed.inflation_kPa)
    return figs


def _offtracking_max(hitch_xy, axle_xy) -> float:
    """The largest distance of the axle's centre from the hitch's path (a polyline) [m]."""
    H = np.asarray(hitch_xy, dtype=float)
    a = H[:-1]
    d = np.diff(H, axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    best = 0.0
    for p in np.asarray(axle_xy, dtype=float):
        t = np.clip(np.einsum("ij,ij->i", p - a, d) / dd, 0.0, 1.0)
        q = a + t[:, None] * d
        best = max(best, float(np.min(np.hypot(*(p - q).T))))
    return best
