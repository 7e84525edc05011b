"""A dry and a wet day, a crawler and a tractor
============================================

The same traffic on a dry and on a wet day, and a crawler against a wheeled tractor of the same
mass on the same field (docs/subsoil.md, "Moisture" and "Wheeled machines"): two tables of the
largest vertical stress and bulk density by depth.

    python examples/compaction_day_and_machine.py [--length 8] [--passes 3]

Soil: the validation clay's surface (clayey soil, Thailand, 38 %) over a loose tilled subsoil
(initial bulk density 1.2 Mg/m^3), whose compression parameters are Défossez et al.'s (2003) loess
at the day's gravimetric water content (0.10 dry, 0.20 wet) and whose strength is Severiano et al.'s
(2013) for 25 % clay (symtrack/soil/moisture.py). The days' traffic is the reference crawler
loaded to 11 t (50 kPa mean ground pressure: the 5.5 t crawler's 25 kPa stays below the yield line
of both days' strengths, 156 and 224 kPa, and compacts neither); the crawler against the tractor is
the reference crawler (5.5 t) through the terrain engine; the tractor (5.5 t, 40 % on the front
axle, wheelbase 2.4 m, gauge 1.5 m; ASSUMED tyres: front 380/85R28, load index 133, 2060 kg; rear
480/80R38, load index 149, 3250 kg; both rated at 160 kPa, inflated to the rule's recommended
pressure) drives the same line over a fresh copy of the field, its footprints in Python
(symtrack/vehicles/wheeled.py).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys

import numpy as np

import symtrack
from symtrack.foundations.errors import SymtrackError
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.terrain.storage import Terrain
from symtrack.vehicles import tyre, wheeled

G = 9.81
DAYS = {"dry": 0.10, "wet": 0.20}
MOISTURE = {"compression_ptf": "defossez_2003_loess", "clay_percent": 25.0}
MASS_KG = 5500.0
FRONT_SHARE = 0.4
WHEELBASE_M, GAUGE_M = 2.4, 1.5
FRONT_TYRE = tyre.Tyre(0.38, 1.43, 2060.0 * G / 1e3, 160.0)  # 380/85R28 133 (ASSUMED)
REAR_TYRE = tyre.Tyre(0.48, 1.76, 3250.0 * G / 1e3, 160.0)  # 480/80R38 149 (ASSUMED)
ELEMENT_M = 0.025


DAY_CRAWLER_MASS_KG = 11000.0


def document(day: str, passes: int, length_m: float, mass_kg: float = MASS_KG) -> dict:
    return {
        "name": f"compaction_{day}",
        "run": {"duration_s": 30.0, "output_dt_s": 0.01, "integrator": "grid_fast", "stop_after_distance_m": length_m},
        "vehicle": {"preset": "reference_crawler", "mass_kg": mass_kg},
        "soil": {"preset": "clayey_soil_thailand_38", "bulk_density_initial_Mg_per_m3": 1.2,
                 "moisture": {"water_content_kg_per_kg": DAYS[day], **MOISTURE}},
        "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
        "terrain": {"size_m": [length_m + 8.0, 6.0], "origin_m": [-4.0, -3.0], "cell_m": 0.2, "passes": passes},
        "torque": [{"t_s": 0.0, "left_N_m": 1500.0, "right_N_m": 1500.0}],
    }


def tractor_wheels():
    W = MASS_KG * G / 1e3
    wf, wr = FRONT_SHARE * W / 2, (1 - FRONT_SHARE) * W / 2
    cf = tyre.contact(FRONT_TYRE, wf, tyre.recommended_inflation_kPa(FRONT_TYRE, wf), ELEMENT_M)
    cr = tyre.contact(REAR_TYRE, wr, tyre.recommended_inflation_kPa(REAR_TYRE, wr), ELEMENT_M)
    a = WHEELBASE_M / 2
    return [wheeled.Wheel(cf, a, GAUGE_M / 2), wheeled.Wheel(cf, a, -GAUGE_M / 2),
            wheeled.Wheel(cr, -a, GAUGE_M / 2), wheeled.Wheel(cr, -a, -GAUGE_M / 2)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, default=8.0, help="distance of each pass [m]")
    ap.add_argument("--passes", type=int, default=3, help="crawler passes of the dry/wet comparison")
    a = ap.parse_args(argv)
    try:
        days = {}
        for day in DAYS:
            res = symtrack.simulate(scenario_from_dict(document(day, a.passes, a.length, DAY_CRAWLER_MASS_KG)))
            s = res.summary
            days[day] = {"water_content_kg_per_kg": DAYS[day],
                         "precompression_stress_kPa": s["subsoil_precompression_stress_min_kPa"],
                         "bulk_density_initial_Mg_per_m3": s["bulk_density_initial_Mg_per_m3"],
                         "bulk_density_max_Mg_per_m3_by_pass": [p["bulk_density_max_Mg_per_m3"] for p in s["passes"]]}
        # crawler against tractor: one pass each on a fresh wet field
        res = symtrack.simulate(scenario_from_dict(document("wet", 1, a.length)))
        crawler = {"subsoil_sigma_z_max_kPa": res.summary["subsoil_sigma_z_max_kPa"],
                   "bulk_density_max_Mg_per_m3": res.summary["bulk_density_max_Mg_per_m3"]}
        t = res.terrain
        fresh = Terrain(t.grid, copy.deepcopy(t.soil), t.subsoil_depths_m)
        dist = float(res.summary["distance_m"])
        step = t.grid.cell_m / 4
        xs = np.linspace(0.0, dist, int(np.ceil(dist / step)) + 1)
        poses = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
        xi = float(t.soil["stress_concentration_factor"])
        wheels = tractor_wheels()
        tr = wheeled.wheeled_pass(fresh, wheels, poses, xi)
    except SymtrackError as err:
        print(f"compaction_day_and_machine: error: {err}", file=sys.stderr)
        return 2
    out = {"depths_m": res.summary["subsoil_depths_m"], "days": days,
           "crawler": crawler,
           "tractor": {"subsoil_sigma_z_max_kPa": tr["subsoil_sigma_z_max_kPa"],
                       "bulk_density_max_Mg_per_m3": tr["bulk_density_max_Mg_per_m3"],
                       "inflation_kPa": [w.contact.recommended_inflation_kPa for w in wheels[::2]],
                       "wheel_load_kN": [float(w.contact.force_kN.sum()) for w in wheels[::2]]},
           "distance_m": dist}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
