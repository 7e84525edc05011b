"""Studies at scale: parameter sweeps of any scenario (``symtrack simulate`` or ``symtrack mpc``)
on Dask distributed, a local cluster or an existing scheduler (docs/studies.md)::

    from symtrack import studies
    res = studies.sweep("validation", ["vehicle.mass_kg=5000,6000", "soil.bekker_n=0.6,0.8"], out="out/sweep",
                        overrides={"run.integrator": "rosenbrock"}, workers=2)
    res.ok, res.rows          # every run succeeded; the rows of out/sweep/results.csv
"""

from .design import Axis, latin_hypercube, parse_vary
from .engine import SCHEMA_VERSION, SweepResult, plan, results_csv, sweep
from .runs import run_one

__all__ = ["SCHEMA_VERSION", "Axis", "SweepResult", "latin_hypercube", "parse_vary", "plan", "results_csv",
           "run_one", "sweep"]
