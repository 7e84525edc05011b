"""Sensitivity of the validation figures
=====================================

Sensitivity of the validation figures (docs/turning.md section 4): the validation scenario with
one --set change per row, CVODES, printed as a markdown table.

    python examples/validation_sensitivity.py                 # the table of docs/turning.md
    python examples/validation_sensitivity.py --rows base 'soil.shear_modulus_K_m=0.012'

A row is a ';'-separated list of --set items ("base": none).
"""

from __future__ import annotations

import argparse

from symtrack import simulate
from symtrack.simulation.scenario import load_scenario

ROWS = (
    "base",
    "soil.shear_modulus_K_m=0.012", "soil.shear_modulus_K_m=0.018",
    "vehicle.mass_kg=4400", "vehicle.mass_kg=6600",
    "vehicle.track_gauge_m=1.2", "vehicle.track_gauge_m=1.8",
    "vehicle.sprocket_radius_m=0.304", "vehicle.sprocket_radius_m=0.40",
    "vehicle.contact_length_m=1.92", "vehicle.track_width_m=0.36", "vehicle.cg_height_m=0.72",
    "soil.cohesion_Pa=3312", "soil.cohesion_Pa=4968",
    "soil.friction_angle_rad=0.1815", "soil.friction_angle_rad=0.2722",
    "model.sliding_smoothing=1e-4", "model.sliding_smoothing=1e-6", "model.shear_points=8",
    'model.shear_strength_pressure="local"',
    "soil.shear_modulus_K_m=0.006;vehicle.track_gauge_m=1.1;vehicle.sprocket_radius_m=0.4;"
    "vehicle.track_width_m=0.5;vehicle.mass_kg=6100",
    'model.lateral_law="creep"',
)
FIGURES = ("lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm", "sinkage_idler_mm",
           "shear_driven_max_m", "shear_idle_min_m")


def row(sets: str, integrator: str = "cvodes") -> dict:
    items = [] if sets == "base" else [s for s in sets.split(";") if s]
    sc = load_scenario("validation", [f'run.integrator="{integrator}"', *items])
    return simulate(sc).summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", nargs="+", default=list(ROWS))
    ap.add_argument("--integrator", default="cvodes")
    a = ap.parse_args(argv)
    print("| change | " + " | ".join(FIGURES) + " |")
    print("|---" * (len(FIGURES) + 1) + "|")
    for sets in a.rows:
        s = row(sets, a.integrator)
        print(f"| {sets} | " + " | ".join(f"{s[k]:.4g}" for k in FIGURES) + " |", flush=True)


if __name__ == "__main__":
    main()
