"""The hull-frame rotation of the shear law
========================================

What the hull-frame rotation that the shear law neglects changes (docs/turning.md, "The hull-frame
rotation"): a brute-force numpy reference at the steady turns of symtrack.control.trim.

    python examples/hull_rotation.py
    python examples/hull_rotation.py --soil clayey_soil_thailand_38 --radii 5 10 20 --speeds 1 3

The law (docs/turning.md section 1) accumulates a track element's shear displacement in the hull
frame: j(s) = integral over [0, s] of (i_x, i_y(s')) ds'. The soil is fixed in the ground, so each
increment of sliding keeps its direction on the ground while the hull turns on: seen from the hull
now, the increment made at s' has turned by ``-r_z (s - s') / (r |omega|)`` (the hull's yaw while the element
travelled from s' to s at the tread speed). The reference sums the rotated increments,

    ``j_rot(s) = integral over [0, s] of R(-r_z (s - s') / (r |omega|)) (i_x, i_y(s')) ds'``,

and takes the stress magnitude from ``|j_rot|`` (its direction stays against the sliding velocity now, as
in the law). Both are integrated on 4000 midpoints per track, at the trim's state (normal loads, slips,
lateral velocity); the table gives the law's forces (sum over both tracks: thrust-moment of the
tractive forces, lateral force, the soil's yaw moment) and the relative change with the rotation.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from symtrack.control.trim import TrimError, trim
from symtrack.model import ModelOptions, SystemModel
from symtrack.presets import soil_preset, vehicle_preset

N_POINTS = 4000


def track_forces(P, N, omega, i_x, v, r_z, rotate: bool):
    """(F_x, F_y, M_z) of one track (forward motion, mean-pressure strength, the default options):
    midpoint rule on N_POINTS points; ``rotate``: the displacement increments turned by the hull's yaw."""
    b, l, r = P["track_width_m"], P["contact_length_m"], P["sprocket_radius_m"]
    c, tphi, K = P["cohesion_Pa"], math.tan(P["friction_angle_rad"]), P["shear_modulus_K_m"]
    x_front = l / 2 - P["cg_ahead_of_contact_centre_m"]
    ds = l / N_POINTS
    s = (np.arange(N_POINTS) + 0.5) * ds
    x = x_front - s
    tread = r * abs(omega)
    i_y = (v + r_z * x) / tread
    inc = (i_x + 1j * i_y) * ds  # the sliding increments (longitudinal + i lateral), hull frame
    if rotate:
        a1 = r_z / tread  # the hull's yaw per metre of the element's travel along the contact
        # sum over s' < s of exp(-i a1 (s - s')) inc(s'), up to the midpoint of the current cell
        ph = np.exp(1j * a1 * s)
        j = (np.cumsum(inc * ph) - 0.5 * inc * ph) / ph
    else:
        j = np.cumsum(inc) - 0.5 * inc
    tau = (c + N / (b * l) * tphi) * (1 - np.exp(-np.abs(j) / K))
    norm = np.hypot(i_x, i_y)
    fx, fy = b * tau * i_x / norm, -b * tau * i_y / norm
    return np.array([fx.sum() * ds, fy.sum() * ds, (x * fy).sum() * ds])


def compare(soil, law, radius_m, speed_m_s) -> dict:
    P = {**vehicle_preset("reference_crawler"), **soil_preset(soil)}
    model = SystemModel(ModelOptions(lateral_law=law))
    tp = trim(model, P, speed_m_s, radius_m)
    y = tp.outputs
    B, l, r = P["track_gauge_m"], P["contact_length_m"], P["sprocket_radius_m"]
    v, r_z, u = tp.state("v_m_s"), tp.yaw_rate_rad_s, tp.state("u_m_s")
    out = {}
    for rotate in (False, True):
        tot = np.zeros(3)
        thrust = 0.0
        for k, sgn in (("left", -1), ("right", 1)):
            om = tp.state(f"omega_{k}_rad_s")
            i_x = (r * om - (u + sgn * r_z * B / 2)) / (r * abs(om))
            f = track_forces(P, y[f"normal_load_{k}_N"], om, i_x, v, r_z, rotate)
            tot += f
            thrust += sgn * B / 2 * f[0]
        out[rotate] = (thrust, tot[1], tot[2])
    yaw_contact = r_z * l / (r * abs(tp.state("omega_left_rad_s")))  # the inner track's: the longer time
    return {"soil": soil, "radius_m": radius_m, "speed_m_s": speed_m_s, "yaw_over_contact_rad": yaw_contact,
            "law": out[False], "rotated": out[True],
            "model_lateral_N": y["lateral_force_left_N"] + y["lateral_force_right_N"]}


def _change(a, b) -> str:
    return f"{100 * (b / a - 1):+.2f} % ({b - a:+.1f})"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soil", nargs="+", default=["clayey_soil_thailand_38", "sandy_loam_15"])
    ap.add_argument("--law", default="shear")
    ap.add_argument("--radii", type=float, nargs="+", default=[5.0, 10.0, 20.0, 50.0])
    ap.add_argument("--speeds", type=float, nargs="+", default=[2.0])
    a = ap.parse_args(argv)
    print("| soil | R [m] | V [m/s] | inner track's yaw over its contact [rad] | thrust moment (B/2)(F_R - F_L) "
          "[N m] | its change | lateral force [N] | its change | soil's yaw moment [N m] | its change |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for soil in a.soil:
        for R in a.radii:
            for V in a.speeds:
                try:
                    d = compare(soil, a.law, R, V)
                except TrimError as e:
                    print(f"| {soil} | {R:g} | {V:g} | no steady turn: {e} |")
                    continue
                (t0, y0, m0), (t1, y1, m1) = d["law"], d["rotated"]
                print(f"| {soil} | {R:g} | {V:g} | {d['yaw_over_contact_rad']:.3f} | {t0:.0f} | {_change(t0, t1)} "
                      f"| {y0:.0f} | {_change(y0, y1)} | {m0:.0f} | {_change(m0, m1)} |")


if __name__ == "__main__":
    main()
