"""Steady turns
============

Steady turns of the reference crawler (docs/turning.md): trim points (symtrack.control.trim) at
several radii and speeds on the validation clay and on sandy loam, printed as a markdown table.

    python examples/steady_turns.py                            # the lagged shear law "shear" (this example's default)
    python examples/steady_turns.py --law shear_quasistatic    # the quasi-static shear law
    python examples/steady_turns.py --law creep                # the velocity-creep law (Ferretti & Girelli's model)

Sinkages: under the sprocket (rear) / the idler (front) of each track, homogeneous soil. Max Re eig:
the largest real part of the eigenvalues of the linearisation at the trim (symtrack.control.linearization;
position states dropped): negative, the steady turn is stable.
"""

from __future__ import annotations

import argparse

import numpy as np

from symtrack.control.linearization import linearize
from symtrack.control.trim import TrimError, trim
from symtrack.model import ModelOptions, SystemModel
from symtrack.model.options import LATERAL_LAWS
from symtrack.presets import soil_preset, vehicle_preset

SOILS = ("clayey_soil_thailand_38", "sandy_loam_15")


def rows(law: str, radii, speeds, soils=SOILS):
    model = SystemModel(ModelOptions(lateral_law=law))
    for soil in soils:
        params = {**vehicle_preset("reference_crawler"), **soil_preset(soil)}
        for radius in radii:
            for speed in speeds:
                try:
                    tp = trim(model, params, speed, radius)
                except TrimError as e:
                    yield {"soil": soil, "radius_m": radius, "speed_m_s": speed, "error": str(e)}
                    continue
                y = tp.outputs
                yield {"soil": soil, "radius_m": radius, "speed_m_s": speed,
                       "torque_left_N_m": float(tp.u[0]), "torque_right_N_m": float(tp.u[1]),
                       "slip_left": float(y["slip_left"]), "slip_right": float(y["slip_right"]),
                       "v_m_s": tp.state("v_m_s"), "lateral_usage": tp.limits["lateral_usage"],
                       **{f"sinkage_{end}_{k}_mm": 1e3 * float(y[f"sinkage_{end}_{k}_m"])
                          for end in ("sprocket", "idler") for k in ("left", "right")},
                       "residual_norm": tp.residual_norm,
                       "max_real_eig_per_s": float(np.linalg.eigvals(linearize(model, tp).A).real.max())}


def table(law: str, radii, speeds) -> str:
    lines = ["| soil | R [m] | V [m/s] | T_left (inner) [N m] | T_right (outer) [N m] | slip_left | slip_right "
             "| v [m/s] | sinkage left s / i [mm] | sinkage right s / i [mm] | lateral usage "
             "| max Re eig [1/s] |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows(law, radii, speeds):
        head = f"| {r['soil']} | {r['radius_m']:g} | {r['speed_m_s']:g} |"
        if "error" in r:
            lines.append(head + " no steady turn | | | | | | | | |")
        else:
            lines.append(head + f" {r['torque_left_N_m']:.0f} | {r['torque_right_N_m']:.0f} | {r['slip_left']:.4f} "
                         f"| {r['slip_right']:.4f} | {r['v_m_s']:.4f} | {r['sinkage_sprocket_left_mm']:.3f} / "
                         f"{r['sinkage_idler_left_mm']:.3f} | {r['sinkage_sprocket_right_mm']:.3f} / "
                         f"{r['sinkage_idler_right_mm']:.3f} | {r['lateral_usage']:.3f} "
                         f"| {r['max_real_eig_per_s']:.4f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--law", choices=LATERAL_LAWS, default="shear")
    ap.add_argument("--radii", type=float, nargs="+", default=[10.0, 15.0, 20.0, 50.0, 100.0])
    ap.add_argument("--speeds", type=float, nargs="+", default=[1.0, 2.0, 3.0])
    a = ap.parse_args(argv)
    print(table(a.law, a.radii, a.speeds), end="")


if __name__ == "__main__":
    main()
