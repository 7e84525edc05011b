
__all__ = ["ImplausibleRunError", "MissingExtraError", "ParameterError", "ScenarioError", "SimulationError",
           "SymtrackError"]
"""Exception types of symtrack. Every message names what was wrong and what is allowed."""


class SymtrackError(Exception):
    """Base class of all errors raised by symtrack on purpose."""


class ParameterError(SymtrackError, ValueError):
    """A model parameter is unknown, missing or outside its allowed range."""


class ScenarioError(SymtrackError, ValueError):
    """A scenario file or override is malformed, has an unknown key or a value out of range."""


class SimulationError(SymtrackError, RuntimeError):
    """The integrator failed or the simulation left its domain of validity."""


class ImplausibleRunError(SimulationError):
    """A run stopped by a plausibility limit (:mod:`symtrack.model.plausibility`): a figure no crawler
    reaches, so that the run cannot be physically true from there on. ``quantity`` names the limit
    ("speed", "tread_speed", "sinkage" or "tilt"; "rest": the 3D vehicle's start found no static rest that the
    model carries, raised before the first step); the message says the value, the time and the allowed range."""

    def __init__(self, message: str, quantity: str = ""):
        super().__init__(message)
        self.quantity = quantity


class MissingExtraError(SymtrackError, ImportError):
    """A feature needs an optional extra of symtrack that is not installed (the message names the
    ``pip install`` that brings it)."""
