import pytest

from symtrack.model import SystemModel
from symtrack.presets import soil_preset, vehicle_preset


@pytest.fixture(scope="session")
def model():
    return SystemModel()


@pytest.fixture(scope="session")
def params():
    return {**vehicle_preset("reference_crawler"), **soil_preset("clayey_soil_thailand_38")}
