"""One soil, one deformation
=========================

One soil, one deformation (docs/subsoil.md, "One soil"): for every soil preset, one pass of the
reference crawler (the built-in ``multipass`` scenario, 4 m on one line) and the table of the soil's
description, its one strength, the plastic rut and the column's compression below it; then the bulk
density at 0.1 m against pass number on one soil.

    python examples/one_soil.py [--passes 10] [--soil sandy_loam_15] [--presets a,b,...]

The column's compression of a cell is the integral over depth of its vertical strain, 1 - rho0/rho =
1 - v1/v0 (mass conservation: a column that densifies from rho0 to rho shortens by that fraction),
by the trapezoid rule over the subsoil depths (0.1, 0.3, 0.5, 0.8 m), the strain at the surface taken
as at 0.1 m and none below 0.8 m (:func:`column_compression_m`). The rut is the cell's plastic
sinkage after the pass (its stored z). Both are averaged over the cells the pass left a rut in.
The second table: one run of ``--passes`` passes on one soil, the field's largest bulk density by
pass (the summary's ``bulk_density_max_Mg_per_m3``). A preset the scenario check refuses under the reference
crawler (``heavy_clay_wes_40``: its Bekker law is stiffer than its elastic reloading at this crawler's
ground pressure) gets a row with the check's reason, and the table goes on.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import symtrack
from symtrack.foundations.errors import ScenarioError, SymtrackError
from symtrack.presets.soils import SOILS
from symtrack.simulation.scenario import load_scenario
from symtrack.soil import density
from symtrack.soil.pedotransfer import precompression_ptf_kPa

RUT_MIN_M = 1e-6  # a cell with a rut (its plastic sinkage above a micrometre)


def column_compression_m(specific_volume, v0, depths_m) -> np.ndarray:
    """The shortening of each cell's column [m] (module doc): trapezoid of 1 - v1/v0 over
    (0, depths), the surface strain equal to the first depth's."""
    v = np.where(specific_volume > 0, specific_volume.astype(np.float64), v0)
    strain = 1.0 - v / v0
    z = np.concatenate([[0.0], np.asarray(depths_m, dtype=np.float64)])
    s = np.concatenate([strain[:, :1], strain], axis=1)
    return np.sum(0.5 * (s[:, 1:] + s[:, :-1]) * np.diff(z), axis=1)


def run(soil: str, passes: int):
    res = symtrack.simulate(load_scenario("multipass", [f"soil.preset={soil}", f"terrain.passes={passes}"]))
    return res, res._study.world


def one_pass_row(soil: str) -> dict:
    res, world = run(soil, 1)
    st, sp = world.storage, world.soils[0]
    v0 = density.initial_specific_volume(sp)
    rut = st.z.astype(np.float64)
    cells = np.flatnonzero(rut > RUT_MIN_M)
    comp = column_compression_m(st.specific_volume[cells], v0, st.subsoil_depths_m)
    rho = density.bulk_density(st.specific_volume[cells], st.soil_index[cells], world.soils)
    p = res.summary["passes"][0]
    return {"soil": soil, "clay": sp["clay_kg_per_kg"], "rho0": sp["bulk_density_initial_Mg_per_m3"],
            "suction_kPa": sp["matric_suction_kPa"], "pc_kPa": 1e-3 * sp["precompression_stress_Pa"],
            "ptf": precompression_ptf_kPa(sp)[1].split(" (")[0],
            "sigma01_kPa": p["subsoil_sigma_z_max_kPa"][0], "rut_mm": 1e3 * rut[cells].mean(),
            "comp_mm": 1e3 * comp.mean(), "drho01": rho[:, 0].mean() - sp["bulk_density_initial_Mg_per_m3"],
            "high01": p["subsoil_risk_fraction_high"][0], "low01": p["subsoil_risk_fraction_low"][0]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--passes", type=int, default=10)
    ap.add_argument("--soil", default="sandy_loam_15")
    ap.add_argument("--presets", default=",".join(SOILS))
    a = ap.parse_args(argv)
    try:
        print("## one pass of the reference crawler on every soil preset\n")
        print("| soil | clay | rho0 Mg/m^3 | suction kPa | sigma_pc kPa (PTF) | sigma_z 0.1 m kPa | "
              "risk 0.1 m low/high "
              "| rut mm | column compression mm | rut / compression | mean drho 0.1 m Mg/m^3 |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for soil in [s for s in a.presets.split(",") if s]:
            try:
                r = one_pass_row(soil)
            except ScenarioError as err:  # a soil the check refuses under this crawler: its reason, then the rest
                reason = str(err).split(": ", 1)[-1].split(": ")[0]  # the rule broken, without the advice after it
                print(f"| {soil} | refused on load: {reason} |", flush=True)
                continue
            ratio = r["rut_mm"] / r["comp_mm"] if r["comp_mm"] > 0 else float("inf")
            print(f"| {soil} | {r['clay']:.2f} | {r['rho0']:.2f} | {r['suction_kPa']:.3g} | {r['pc_kPa']:.1f} "
                  f"({r['ptf']}) | {r['sigma01_kPa']:.1f} | {r['low01']:.2f}/{r['high01']:.2f} | {r['rut_mm']:.3f} "
                  f"| {r['comp_mm']:.3f} | {ratio:.3g} | {r['drho01']:.4f} |", flush=True)
        if a.passes < 1:
            return 0
        res, world = run(a.soil, a.passes)
        rho0 = float(world.soils[0]["bulk_density_initial_Mg_per_m3"])
        print(f"\n## {a.soil}: {a.passes} passes on one line, the field's largest bulk density after each pass\n")
        print("| pass | rut max mm | rho 0.1 m | rise 0.1 m | rise / first rise | rho 0.3 m |")
        print("|---|---|---|---|---|---|")
        prev, first = rho0, None
        for n, p in enumerate(res.summary["passes"], start=1):
            rho = p["bulk_density_max_Mg_per_m3"]
            rise = rho[0] - prev
            first = rise if first is None else first
            print(f"| {n} | {p['rut_max_depth_mm']:.3f} | {rho[0]:.5f} | {rise:.2e} | "
                  f"{rise / first if first else float('nan'):.3f} | {rho[1]:.5f} |", flush=True)
            prev = rho[0]
    except SymtrackError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
