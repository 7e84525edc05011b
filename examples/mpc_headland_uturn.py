"""MPC of a headland U-turn
========================

Nonlinear MPC of the sprocket torques on a headland U-turn, against the full simulator.

    PYTHONPATH=. .venv/bin/python examples/mpc_headland_uturn.py --out out/mpc_uturn [--solver fatrop --jit]

The same as ``symtrack mpc headland_uturn --out DIR``, written out with the library calls: load
the built-in scenario, build the MPC on the model's Functions, run the closed loop with the
default plant (CVODES on the SystemModel), write the files (summary.json last).
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from symtrack.control import closedloop, scenario
from symtrack.control.mpc import PathTrackingMPC
from symtrack.model import SystemModel


def run(out=None, solver="ipopt", jit=False, max_steps=None, horizon_steps=None):
    sc = scenario.load("headland_uturn")
    changes = {"solver": solver, "jit": jit}
    if horizon_steps is not None:
        changes["horizon_steps"] = horizon_steps
    sc = dataclasses.replace(sc, mpc=dataclasses.replace(sc.mpc, **changes))
    model = SystemModel()
    mpc = PathTrackingMPC(model, sc.params, sc.mpc)
    plant = closedloop.make_plant(sc, model)
    res = closedloop.run(sc, plant=plant, model=model, mpc=mpc, max_steps=max_steps)
    if out is not None:
        closedloop.write(out, res)
    return res.summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/mpc_uturn")
    ap.add_argument("--solver", choices=("ipopt", "fatrop"), default="ipopt")
    ap.add_argument("--jit", action="store_true")
    ap.add_argument("--max-steps", type=int, default=None, help="stop after this many MPC steps")
    args = ap.parse_args(argv)
    print(json.dumps(run(args.out, args.solver, args.jit, args.max_steps), indent=2))


if __name__ == "__main__":
    main()
