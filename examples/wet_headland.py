"""A field with a wet headland
===========================

A field with a wet headland (docs/terrain.md, "Soil maps"): two passes of the reference crawler
along a 20 m strip whose last 8 m are a wetter, weaker clay, through the terrain engine; the
summary by pass (sinkage, subsoil stress, risk area by depth) and the run folder with the risk
map by depth.

    python examples/wet_headland.py --out out/wet_headland [--passes 2] [--length 14]

The field's soil is the validation clay (clayey soil, Thailand) on a drier day, a matric suction
of 100 kPa (pF 3): its precompression stress from the Schjønning & Lamandé (2018) pedotransfer
function, 102 kPa; the headland is the clay at 55 % moisture (Wong Table 2.3) as its preset
describes it, nearly saturated: 44 kPa (Severiano et al. 2013). Both are the soils' descriptions
through the pedotransfer functions (docs/subsoil.md, "One soil"), not measurements of these soils.
"""

from __future__ import annotations

import argparse
import json
import sys

import symtrack
from symtrack.foundations.errors import SymtrackError
from symtrack.foundations.files import check_output_folder
from symtrack.simulation.scenario import scenario_from_dict

DRY_SUCTION_KPA = 100.0


def scenario(passes: int, length_m: float):
    d = {
        "name": "wet_headland",
        "description": "two passes over a field with a wet headland (a soil map)",
        "run": {"duration_s": 30.0, "output_dt_s": 0.01, "integrator": "grid_fast", "stop_after_distance_m": length_m},
        "vehicle": {"preset": "reference_crawler"},
        "soil": {"preset": "clayey_soil_thailand_38", "matric_suction_kPa": DRY_SUCTION_KPA},
        "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
        "terrain": {
            "size_m": [length_m + 8.0, 8.0], "origin_m": [-4.0, -4.0], "cell_m": 0.1, "passes": passes,
            "soil_map": {"soils": ["clayey_soil_thailand_55"],
                         "zones": [{"soil": 1, "x_m": [length_m - 8.0, length_m + 4.0], "y_m": [-4.0, 4.0]}]},
        },
        "torque": [{"t_s": 0.0, "left_N_m": 1500.0, "right_N_m": 1500.0}],
    }
    return scenario_from_dict(d)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/wet_headland")
    ap.add_argument("--passes", type=int, default=2)
    ap.add_argument("--length", type=float, default=14.0, help="distance of each pass [m]")
    a = ap.parse_args(argv)
    try:
        out = check_output_folder(a.out)  # before the work: a bad --out fails at once
        res = symtrack.simulate(scenario(a.passes, a.length), progress=True)
        res.write(out)
    except SymtrackError as err:
        print(f"wet_headland: error: {err}", file=sys.stderr)
        return 2
    rows = []
    for k, p in enumerate(res.summary["passes"], start=1):
        rows.append({"pass": k, "new_sinkage_mean_mm": p["new_sinkage_mean_mm"],
                     "rut_max_depth_mm": p["rut_max_depth_mm"],
                     "subsoil_sigma_z_max_kPa": p.get("subsoil_sigma_z_max_kPa"),
                     "risk_fraction_medium": p.get("subsoil_risk_fraction_medium"),
                     "risk_fraction_high": p.get("subsoil_risk_fraction_high")})
    print(json.dumps({"depths_m": res.summary.get("subsoil_depths_m"), "passes": rows}, indent=1))
    print(f"written: {a.out}/ (risk_map.png, stress_profile.png, sinkage maps, summary.json)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
