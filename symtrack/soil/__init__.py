"""The soil: what it is and what it does under load (docs/subsoil.md, "One soil"; docs/model.md,
"Pressure-sinkage").

- :mod:`.pedotransfer`: the soil as an agronomist describes it (texture, dry bulk density, matric
  suction) and the pedotransfer functions that turn that description into every parameter the rut,
  the stress, the density and the risk need (the names below);
- :mod:`.law`: the surface law as an object and the menu of laws (the reaction pressure under a
  track, its history, the work to press a rut); :mod:`.cell`: its mathematics, one terrain cell's
  pressure-sinkage law and cell equation, in CasADi;
- :mod:`.subsoil`: the vertical stress by depth under the tracks (Söhne / Fröhlich) and the
  compaction risk against the soil's strength; :mod:`.rigid_base`: the change a rigid base under
  a soil layer makes to that stress (an elastic layer's);
- :mod:`.density`: compression, the bulk density by depth from the stress history;
- :mod:`.moisture`: the soil on the day, its compression parameters and strength from its water
  content (``[soil.moisture]``).
"""

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
