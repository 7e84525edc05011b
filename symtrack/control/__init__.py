"""Control on the symbolic model: trim points, linearization, MPC of the sprocket torques and
the closed loop against the plants of :mod:`symtrack.simulation.plants`.

Nothing here writes a model equation: everything consumes the named CasADi Functions of
:class:`symtrack.model.SystemModel` (``ode``, ``outputs``, ``jac_ode``, ``jac_outputs``).
See docs/control.md.

    from symtrack import control
    tp = control.trim(model, params, speed_m_s=2.0, radius_m=20.0)
    lin = control.linearize(model, tp)              # lin.sys: a named python-control StateSpace
    sc = control.load_scenario("headland_uturn")
    res = control.closed_loop(sc)                   # ClosedLoopResult with .summary
"""

from .closedloop import ClosedLoopResult, make_plant
from .closedloop import run as closed_loop
from .closedloop import write as write_closed_loop
from .linearization import Linearization, linearize
from .mpc import MPCSettings, PathTrackingMPC
from .scenario import MPCScenario
from .scenario import load as load_scenario
from .trim import TrimPoint, trim

__all__ = ["ClosedLoopResult", "Linearization", "MPCScenario", "MPCSettings", "PathTrackingMPC", "TrimPoint",
           "closed_loop", "linearize", "load_scenario", "make_plant", "trim", "write_closed_loop"]
