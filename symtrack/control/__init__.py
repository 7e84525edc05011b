"""Control on the symbolic model: trim points, linearisation, MPC of the sprocket torques.

Nothing here writes a model equation: everything consumes the named CasADi Functions of
:class:`symtrack.model.SystemModel` (``ode``, ``outputs``, ``jac_ode``, ``jac_outputs``).
See docs/control.md.
"""
