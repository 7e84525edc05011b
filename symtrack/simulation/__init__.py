"""Simulation: scenarios, the Plant protocol and its plants, the one time loop, results, passes."""

from .builder import Built, build
from .loop import run
from .plants import BatchPlant, GridPlant, Plant, StepPlant, make_plant
from .result import RunResult, summarise
from .scenario import RunSettings, Scenario, load_scenario

__all__ = ["BatchPlant", "Built", "GridPlant", "Plant", "RunResult", "RunSettings", "Scenario", "StepPlant",
           "build", "load_scenario", "make_plant", "run", "summarise"]
