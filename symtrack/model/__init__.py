from .options import ModelOptions
from .system import PARAM_NAMES, SystemModel

__all__ = ["ModelOptions", "PARAM_NAMES", "SystemModel"]
