"""The soil as an agronomist describes it: texture, dry bulk density and matric suction, and the
pedotransfer functions that turn that description into every parameter the rut, the stress, the
density and the risk need (docs/subsoil.md, "One soil")."""

from .pedotransfer import (
    DESCRIPTION_KEYS,
    K2_POSITION_OSR,
    derive_soil,
    geostatic_vertical_stress_Pa,
    keller_arvidsson_2007,
    schjonning_lamande_2018_kPa,
    van_genuchten_water_content,
    virgin_line_N_from_precompression,
)

__all__ = ["DESCRIPTION_KEYS", "K2_POSITION_OSR", "derive_soil", "geostatic_vertical_stress_Pa",
           "keller_arvidsson_2007", "schjonning_lamande_2018_kPa", "van_genuchten_water_content",
           "virgin_line_N_from_precompression"]
