
__all__ = ["MissingExtraError", "ParameterError", "ScenarioError", "SimulationError", "SymtrackError"]
"""Exception types of symtrack. Every message names what was wrong and what is allowed."""


class SymtrackError(Exception):
    """Base class of all errors raised by symtrack on purpose."""


class ParameterError(SymtrackError, ValueError):
    """A model parameter is unknown, missing or outside its allowed range."""


class ScenarioError(SymtrackError, ValueError):
    """A scenario file or override is malformed, has an unknown key or a value out of range."""


class SimulationError(SymtrackError, RuntimeError):
    """The integrator failed or the simulation left its domain of validity."""


class MissingExtraError(SymtrackError, ImportError):
    """A feature needs an optional extra of symtrack that is not installed (the message names the
    ``pip install`` that brings it)."""
