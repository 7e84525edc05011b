"""Bulk density against pass number (docs/subsoil.md, "Repeated passes"): the built-in multipass
scenario (the reference crawler, clayey soil, passes of 4 m on one line) for 1..N passes under three
compression laws, and the grain cart of examples/scenarios/multipass_trailer.toml with and without
the saturation bound. Prints markdown tables of the field's largest bulk density by depth.

    python examples/density_passes.py [--passes 12]

Laws (symtrack/terrain/density.py):
- "default": the registry's lines (Keller & Arvidsson's 2007 PTF at 1.5 Mg/m^3), no yield line;
- "osr": O'Sullivan & Robertson's (1996) model with its yield line, the complete parameter set of
  soilphysics' documented soilDeformation example (N 1.9392, lambda 0.06037, kappa 0.00608,
  k2 0.01916, m 1.3, rho_s 2.67, initial rho_b 1.55);
- "osr, w = 0.20": the same on a day of gravimetric water content 0.20 ([soil.moisture] with
  Severiano et al.'s 25 % clay for the strength): the saturation bound 1 + w rho_s / rho_w.
"""

from __future__ import annotations

import argparse
import sys

import symtrack
from symtrack.foundations.errors import SymtrackError
from symtrack.simulation.scenario import load_scenario

OSR = ["soil.virgin_line_N=1.9392", "soil.compression_index_lambda=0.06037", "soil.recompression_index_kappa=0.00608",
       "soil.yield_compression_index_k2=0.01916", "soil.yield_line_offset_ln_p=1.3",
       "soil.particle_density_Mg_per_m3=2.67", "soil.bulk_density_initial_Mg_per_m3=1.55"]
WET = ["soil.moisture.water_content_kg_per_kg=0.2", "soil.moisture.clay_percent=25.0"]
LAWS = {"default": [], "osr": OSR, "osr, w = 0.20": OSR + WET}
TRAILER = "examples/scenarios/multipass_trailer.toml"


def table(scenario, overrides, passes):
    s = symtrack.simulate(load_scenario(scenario, [f"terrain.passes={passes}", *overrides])).summary
    rows = [s["bulk_density_initial_Mg_per_m3"]] + [p["bulk_density_max_Mg_per_m3"] for p in s["passes"]]
    return s["subsoil_depths_m"], rows, s


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
    except SymtrackError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
