"""Bulk density against pass number
================================

Bulk density against pass number (docs/subsoil.md, "Repeated passes"): the built-in multipass
scenario (the reference crawler, clayey soil, passes of 4 m on one line) for 1..N passes under three
compression laws, and the grain cart of examples/scenarios/multipass_trailer.toml with and without
the saturation bound. Prints markdown tables of the field's largest bulk density by depth.

    python examples/density_passes.py [--passes 12]

Laws (symtrack/soil/density.py):

- "default": the registry's lines (Keller & Arvidsson's 2007 PTF at 1.5 Mg/m^3), no yield line;
- "osr": O'Sullivan & Robertson's (1996) model with its yield line, the complete parameter set of
  soilphysics' documented soilDeformation example (N 1.9392, lambda 0.06037, kappa 0.00608,
  k2 0.01916, m 1.3, rho_s 2.67, initial rho_b 1.55);
- "osr, w = 0.20": the same on a day of gravimetric water content 0.20 ([soil.moisture] with
  Severiano et al.'s 25 % clay for the strength): the saturation bound 1 + w rho_s / rho_w.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

import symtrack
from symtrack.foundations.errors import SymtrackError
from symtrack.simulation.scenario import load_scenario
from symtrack.soil import density
from symtrack.vehicles import tyre

# the set's N as its strength (the virgin line follows from the strength: docs/subsoil.md "One soil")
OSR_PC_PA = 1e3 * math.exp((1.9392 - 2.67 / 1.55) / (0.06037 - 0.00608))
OSR = [f"soil.precompression_stress_Pa={OSR_PC_PA!r}", "soil.compression_index_lambda=0.06037",
       "soil.recompression_index_kappa=0.00608",
       "soil.yield_compression_index_k2=0.01916", "soil.yield_line_offset_ln_p=1.3",
       "soil.particle_density_Mg_per_m3=2.67", "soil.bulk_density_initial_Mg_per_m3=1.55"]
WET = ["soil.moisture.water_content_kg_per_kg=0.2", "soil.moisture.clay_percent=25.0"]
LAWS = {"default": [], "osr": OSR, "osr, w = 0.20": OSR + WET}
TRAILER = "examples/scenarios/multipass_trailer.toml"
G = 9.81
# a tractor like Botta et al.'s (2006, abstract): 3.1 Mg, 1.0 Mg front / 2.1 Mg rear axle, 7.50-16 front
# and 18.4-34 rear tyres. ASSUMED: the tyres' sizes from their designations (7.50-16: 0.19 x 0.80 m;
# 18.4-34: 0.467 m wide, 0.864 m rim + 2 x 0.85 x 0.467 m = 1.66 m), ratings (7.50-16: 900 kg at
# 280 kPa; 18.4-34: 2900 kg at 160 kPa: not a data sheet), inflated to the load rule's pressure
BOTTA_WHEELS = ((tyre.Tyre(0.19, 0.80, 900 * G / 1e3, 280.0), 1000 * G / 2e3),
                (tyre.Tyre(0.467, 1.66, 2900 * G / 1e3, 160.0), 2100 * G / 2e3))
BOTTA_DEPTHS = (0.1, 0.2, 0.3, 0.5)


def table(scenario, overrides, passes):
    s = symtrack.simulate(load_scenario(scenario, [f"terrain.passes={passes}", *overrides])).summary
    rows = [s["bulk_density_initial_Mg_per_m3"]] + [p["bulk_density_max_Mg_per_m3"] for p in s["passes"]]
    return s["subsoil_depths_m"], rows, s


def botta_like(passes: int, xi: float = 5.0):
    """The mean normal stress below each wheel's centre [kPa] at BOTTA_DEPTHS, and the bulk density
    [Mg/m^3] of O'Sullivan & Robertson's law (the "osr" set) after each pass (front then rear wheel,
    density.load_update in turn), from the initial 1.55."""
    soil = {"virgin_line_N": 1.9392, "compression_index_lambda": 0.06037, "recompression_index_kappa": 0.00608,
            "particle_density_Mg_per_m3": 2.67, "bulk_density_initial_Mg_per_m3": 1.55,
            "yield_line_offset_ln_p": 1.3, "yield_compression_index_k2": 0.01916}
    a = density.soil_arrays([soil])
    p = []
    for t, load in BOTTA_WHEELS:
        c = tyre.contact(t, load, tyre.recommended_inflation_kPa(t, load))
        p.append(tyre.footprint_stress_at_depth(c.x_m, c.y_m, c.force_kN, [0.0], [0.0], BOTTA_DEPTHS, xi)[1][0])
    v = np.full(len(BOTTA_DEPTHS), a["v0"][0])
    rows = [a["rho_s"][0] / v]
    for _ in range(passes):
        for pk in p:
            v = density.load_update(v, np.log(pk), *(a[k][0] for k in ("N", "lambda", "kappa", "lambda_minus_kappa",
                                                                     "m", "k2", "v_min")))
        rows.append(a["rho_s"][0] / v)
    return p, rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--passes", type=int, default=12)
    a = ap.parse_args(argv)
    try:
        print("## multipass: the field's largest bulk density [Mg/m^3] after each pass\n")
        results = {name: table("multipass", ov, a.passes) for name, ov in LAWS.items()}
        depths = next(iter(results.values()))[0]
        print("| pass | " + " | ".join(f"{n} {d} m" for n in LAWS for d in depths[:2]) + " |")
        print("|---" * (1 + 2 * len(LAWS)) + "|")
        for k in range(a.passes + 1):
            cells = [f"{results[n][1][k][j]:.4f}" for n in LAWS for j in range(2)]
            print(f"| {k or 'initial'} | " + " | ".join(cells) + " |")
        print("\n## the grain cart behind the crawler (3 passes): largest bulk density [Mg/m^3] by depth\n")
        print("| law | pass | " + " | ".join(f"{d} m" for d in depths) + " |")
        print("|---" * (2 + len(depths)) + "|")
        for name, ov in (("default", []), ("default, w = 0.20", WET), ("osr", OSR), ("osr, w = 0.20", OSR + WET)):
            _, rows, s = table(TRAILER, ov, 3)
            for k in (1, 3):
                print(f"| {name} | {k} | " + " | ".join(f"{v:.4f}" for v in rows[k]) + " |")
        sz = s["passes"][0].get("towed_subsoil_sigma_z_max_kPa")
        print(f"\n(the cart's largest vertical stress by depth [kPa]: {[round(v, 1) for v in sz]})")
        p, rows = botta_like(a.passes)
        print("\n## a tractor like Botta et al.'s (2006), the osr law, below the wheels' centre line\n")
        print("mean normal stress [kPa], front / rear wheel: " + ", ".join(
            f"{d} m {pf:.1f} / {pr:.1f}" for d, pf, pr in zip(BOTTA_DEPTHS, *p, strict=True)) + "\n")
        print("| passes | " + " | ".join(f"{d} m" for d in BOTTA_DEPTHS) + " |")
        print("|---" * (1 + len(BOTTA_DEPTHS)) + "|")
        for k, r in enumerate(rows):
            print(f"| {k} | " + " | ".join(f"{v:.4f}" for v in r) + " |")
    except SymtrackError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
