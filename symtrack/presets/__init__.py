"""Parameter sets. Each value has exactly one home, here, with its source next to it."""

from .soils import SOILS, soil_preset
from .vehicles import VEHICLES, vehicle_preset

__all__ = ["SOILS", "VEHICLES", "soil_preset", "vehicle_preset"]
