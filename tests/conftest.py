import pytest

from symtrack.model import SystemModel
from symtrack.presets import soil_preset, vehicle_preset


@pytest.fixture(scope="session")
def model():
    return SystemModel()


@pytest.fixture(scope="session")
def params():
    return {**vehicle_preset("reference_crawler"), **soil_preset("clayey_soil_thailand_38")}


def run_once(scenario, model=None, **plant_kw):
    """One run of a scenario through the time loop with the plant it asks for (a built model
    may be reused)."""
    from symtrack.simulation import loop
    from symtrack.simulation.plants import make_plant

    return loop.run(scenario, make_plant(scenario, model=model, **plant_kw))
