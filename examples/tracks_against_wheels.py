"""Tracks against wheels
=====================

A crawler and a wheeled tractor of the same mass on the same field (docs/subsoil.md, "Tracks
against wheels"): the largest vertical stress at 0.1, 0.15, 0.3 and 0.5 m and the bulk density after
one pass, for the crawler on its tracks (terrain engine), the tractor on single wheels and on dual
wheels (symtrack/vehicles/wheeled.py, along the crawler's driven path), and the singles at 1.5 x
their inflation pressure; a table as JSON.

    python examples/tracks_against_wheels.py [--length 8]

The comparison of Arvidsson, Westlin, Keller & Gilbertsson (2011), Soil Till. Res. 117:103-109 (from
its abstract; the paper's tables not read): a 7.7 t tractor on rubber tracks, single and
dual wheels, on two Swedish clays; stress at 0.15, 0.3, 0.5 m: tracks about equal to duals, below
singles; under singles the bulk density rose from 1.24 to 1.36 Mg/m^3.

Here (ASSUMED where no figure of the paper was read):

- the machines weigh 7.7 t: the reference crawler with ``mass_kg = 7700`` (its 2 x 2.4 x 0.45 m
  tracks, 35 kPa on average); the tractor 40 % on the front axle, wheelbase 2.8 m, gauge 1.8 m;
  front 540/65R28 (0.54 m x 1.42 m, load index 142: 2650 kg at 160 kPa), rear 650/65R38
  (0.65 m x 1.85 m, load index 157: 4125 kg at 160 kPa; tests/test_tyre.py's), every tyre at the load
  rule's recommended pressure for its load; duals: every tyre doubled (both axles), 0.1 m apart,
  each pair carrying the single's load;
- the field: the validation clay's surface law (clayey soil, Thailand, 38 %: the crawler's sinkage),
  initial bulk density 1.24 Mg/m^3 (the paper's), compression parameters by Keller & Arvidsson's
  (2007) pedotransfer function of Swedish and Danish soils at that density (density.py).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys

import numpy as np

import symtrack
from symtrack.foundations.errors import SymtrackError
from symtrack.simulation.scenario import scenario_from_dict
from symtrack.soil import density
from symtrack.terrain.storage import Terrain
from symtrack.vehicles import tyre, wheeled

G = 9.81
MASS_KG = 7700.0
FRONT_SHARE = 0.4
WHEELBASE_M, GAUGE_M, DUAL_GAP_M = 2.8, 1.8, 0.1
FRONT_TYRE = tyre.Tyre(0.54, 1.42, 2650.0 * G / 1e3, 160.0)  # 540/65R28 142 (ASSUMED)
REAR_TYRE = tyre.Tyre(0.65, 1.85, 4125.0 * G / 1e3, 160.0)  # 650/65R38 157 (ASSUMED)
RHO_INITIAL = 1.24  # Arvidsson et al. 2011, Soil Till. Res. 117
DEPTHS = (0.1, 0.15, 0.3, 0.5)
ELEMENT_M = 0.025


def document(length_m: float) -> dict:
    # Keller & Arvidsson's lines at the field's density; the strength (and so the virgin line's N, which
    # follows from it) is the one of Keller & Arvidsson's own N: where their virgin line meets the initial
    # recompression line (one strength, docs/subsoil.md "One soil")
    N, lam, kap = density.keller_arvidsson_2007(2.65, RHO_INITIAL)
    pc_Pa = 1e3 * math.exp((N - 2.65 / RHO_INITIAL) / (lam - kap))
    return {
        "name": "tracks_against_wheels",
        "run": {"duration_s": 30.0, "output_dt_s": 0.01, "integrator": "grid_fast", "stop_after_distance_m": length_m},
        "vehicle": {"preset": "reference_crawler", "mass_kg": MASS_KG},
        "soil": {"preset": "clayey_soil_thailand_38", "bulk_density_initial_Mg_per_m3": RHO_INITIAL,
                 "precompression_stress_Pa": pc_Pa, "compression_index_lambda": lam, "recompression_index_kappa": kap},
        "start": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0},
        "terrain": {"size_m": [length_m + 8.0, 6.0], "origin_m": [-4.0, -3.0], "cell_m": 0.1, "passes": 1,
                    "subsoil_depths_m": list(DEPTHS)},
        "torque": [{"t_s": 0.0, "left_N_m": 2000.0, "right_N_m": 2000.0}],
    }


def tractor(duals: bool, inflation_factor: float = 1.0, depths=DEPTHS, xi=5.0):
    """(wheels, tables, the inflation pressures [kPa] front and rear) of the tractor."""
    W = MASS_KG * G / 1e3
    wf, wr = FRONT_SHARE * W / 2, (1 - FRONT_SHARE) * W / 2
    wheels, tables, pressures = [], [], []
    a = WHEELBASE_M / 2
    axles = []
    for ty, w, x in ((FRONT_TYRE, wf, a), (REAR_TYRE, wr, -a)):
        off = 0.5 * (ty.width_m + DUAL_GAP_M)
        axles.append((ty, w / 2, x, [-off, off]) if duals else (ty, w, x, [0.0]))
    for ty, w, x, offsets in axles:
        p = min(ty.rated_inflation_kPa, inflation_factor * tyre.recommended_inflation_kPa(ty, w))
        c, tb = tyre.footprint_table(ty, w, p, ELEMENT_M, tuple(depths), xi, 2 * wheeled.DEFAULT_REACH_M)
        pressures.append(p)
        for side in (1.0, -1.0):
            for o in offsets:
                wheels.append(wheeled.Wheel(c, x, side * GAUGE_M / 2 + o))
                tables.append(tb)
    return wheels, tables, pressures


def compare(length_m: float = 8.0) -> dict:
    res = symtrack.simulate(scenario_from_dict(document(length_m)))
    s = res.summary
    t = res.terrain
    xi = float(t.soil["stress_concentration_factor"])
    poses = res.runs[0].X[:, :3]
    # the crawler's path at a quarter cell (the tractor follows it: wheeled_pass needs the spacing)
    seg = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    keep = np.concatenate([[True], seg > 0])
    P = poses[keep]
    s_along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(P[:, :2], axis=0).T))])
    grid = np.linspace(0.0, s_along[-1], int(np.ceil(s_along[-1] / (t.grid.cell_m / 4))) + 1)
    path = np.column_stack([np.interp(grid, s_along, P[:, k]) for k in range(3)])
    out = {"depths_m": list(DEPTHS), "bulk_density_initial_Mg_per_m3": RHO_INITIAL,
           "tracks": {"subsoil_sigma_z_max_kPa": s["subsoil_sigma_z_max_kPa"],
                      "bulk_density_max_Mg_per_m3": s["bulk_density_max_Mg_per_m3"],
                      "mean_track_pressure_kPa": MASS_KG * G / (2 * 2.4 * 0.45) / 1e3}}
    for name, duals, factor in (("singles", False, 1.0), ("duals", True, 1.0), ("singles_inflated_1_5", False, 1.5)):
        fresh = Terrain(t.grid, copy.deepcopy(t.soil), t.subsoil_depths_m)
        wheels, tables, pressures = tractor(duals, factor, xi=xi)
        f = wheeled.wheeled_pass(fresh, wheels, path, xi, tables=tables)
        out[name] = {"subsoil_sigma_z_max_kPa": f["subsoil_sigma_z_max_kPa"],
                     "bulk_density_max_Mg_per_m3": f["bulk_density_max_Mg_per_m3"],
                     "inflation_kPa_front_rear": pressures}
    out["distance_m"] = float(s["distance_m"])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, default=8.0, help="distance of the pass [m]")
    a = ap.parse_args(argv)
    try:
        out = compare(a.length)
    except SymtrackError as err:
        print(f"tracks_against_wheels: error: {err}", file=sys.stderr)
        return 2
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
