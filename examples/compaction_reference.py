"""The compaction resistance against IDAS
======================================

The compaction resistance of the terrain engine against IDAS with exact integrals
(docs/terrain.md, "The compaction resistance figure").

IDAS integrates, beside the DAE, the compaction power and both tracks' compaction resistance
(quadratures: `ChannelStepper(..., quad=...)`), so its energy and its time mean are exact rather
than sampled at the outputs; the engine's energy is its step work (the step-mean power times the
step). Both print the energy absorbed by the cells, the distance mean of R_c (the pass figure
`compaction_resistance_mean_N`) and the time means from 0.3 s on.

    python examples/compaction_reference.py                      # the 12 m x 4 m field at 0.25 m, 1.5 s (~20 s)
    python examples/compaction_reference.py --big                # validation_grid on 1e6 cells (IDAS ~6-8 min)
    python examples/compaction_reference.py --big --set run.output_dt_s=0.005   # the macro step halved
"""

from __future__ import annotations

import argparse
import dataclasses

import casadi as ca
import numpy as np

from symtrack.integrators.grid_idas import ChannelStepper
from symtrack.simulation import loop
from symtrack.simulation.passes import pass_figures
from symtrack.simulation.plants import GridPlant, make_plant
from symtrack.simulation.scenario import load_scenario
from symtrack.terrain.world import open_world

QUAD_OUTPUTS = ("compaction_power_W", "compaction_resistance_left_N", "compaction_resistance_right_N")


def scenario(big: bool, integrator: str, extra=()):
    size, cell = ((100.0, 100.0), 0.1) if big else ((12.0, 4.0), 0.25)
    sc = load_scenario("validation_grid", [f"run.integrator={integrator}", f"terrain.size_m={list(size)}",
                                           f"terrain.cell_m={cell}", *extra])
    if not big:  # 1.5 s of the torque programme, no distance stop
        sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=1.5, stop_after_distance_m=None,
                                                             stop_distance_event=None))
    return sc


def idas_plant(sc):
    """The IDAS grid plant with the QUAD_OUTPUTS integrated over every step; a list of the steps'
    (h, integrals), emptied when the vehicle has been set down."""
    st = sc.start
    world = open_world(sc.terrain, sc.params, sc.model, sc.run.output_dt_s, start_xy=(st.x_m, st.y_m))
    m = world.model
    y = m.outputs(m.x, m.u, m.p)
    quad = ca.vertcat(*(y[m.output_index(n)] for n in QUAD_OUTPUTS))
    stepper = ChannelStepper(m, sc.run.integrator_settings(), quad=quad)
    plant, steps = GridPlant(world, stepper), []
    step, start = plant.advance, plant.start

    def advance():
        out = step()
        steps.append((plant.h_done, stepper.last_quad.copy()))
        return out

    def start_(*a, **k):
        out = start(*a, **k)
        steps.clear()  # the settling of the set-down is not part of the run
        return out
    plant.advance, plant.start = advance, start_
    return plant, steps


def _late_mean(t, rc):
    """The time mean of sampled R_c from 0.3 s on (the trapezoid; the rectangle for step means)."""
    m = t[1:] > 0.3 + 1e-9
    return float(np.sum(0.5 * (rc[1:] + rc[:-1])[m] * np.diff(t)[m]) / np.sum(np.diff(t)[m]))


def run_idas(big: bool = False, extra=()) -> dict:
    """IDAS with the quadratures: the exact energy and time mean from 0.3 s, and the sampled ones."""
    sc = scenario(big, "idas", extra)
    plant, steps = idas_plant(sc)
    z0 = plant.world.storage.z.copy()
    res = loop.run(sc, plant)
    figs = pass_figures(plant.world, z0, res, plant.world.touched.copy())
    h = np.array([s[0] for s in steps])
    q = np.array([s[1] for s in steps])
    late = np.cumsum(h) > 0.3 + 1e-9
    rc = res.output("compaction_resistance_left_N") + res.output("compaction_resistance_right_N")
    return {"energy_J": float(q[:, 0].sum()), "rc_late_exact_N": float((q[late, 1] + q[late, 2]).sum() / h[late].sum()),
            "rc_late_sampled_N": _late_mean(res.t, rc), **figs}


def run_engine(big: bool = False, extra=()) -> dict:
    """The engine: its step work (step-mean power x step) and the means of its step-mean R_c."""
    sc = scenario(big, "grid_fast", extra)
    plant = make_plant(sc)
    z0 = plant.world.storage.z.copy()
    res = loop.run(sc, plant)
    figs = pass_figures(plant.world, z0, res, plant.world.touched.copy())
    t, P = res.t, res.output("compaction_power_W")
    rc = res.output("compaction_resistance_left_N") + res.output("compaction_resistance_right_N")
    m = t[1:] > 0.3 + 1e-9
    return {"energy_J": float(np.sum(P[1:] * np.diff(t))),
            "rc_late_exact_N": float(np.sum(rc[1:][m] * np.diff(t)[m]) / np.sum(np.diff(t)[m])),
            "rc_late_sampled_N": _late_mean(t, rc), **figs}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--big", action="store_true", help="validation_grid on the million-cell field")
    ap.add_argument("--set", action="append", default=[], help="an override for both runs, KEY=VALUE")
    args = ap.parse_args(argv)
    for name, r in (("IDAS", run_idas(args.big, args.set)), ("engine", run_engine(args.big, args.set))):
        print(f"{name:6s} energy {r['energy_J']:9.3f} J   R_c distance mean {r['compaction_resistance_mean_N']:8.4f} N"
              f"   time mean {r['compaction_resistance_time_mean_N']:8.4f} N   from 0.3 s {r['rc_late_exact_N']:8.4f} N"
              f" (sampled {r['rc_late_sampled_N']:8.4f} N)")


if __name__ == "__main__":
    main()
