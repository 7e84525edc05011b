"""The unit a symtrack name carries in its suffix (``sinkage_m``, ``torque_N_m``, ``rut_max_depth_mm``):
one table for the model's signals, the parameters and the summaries' figures."""

from __future__ import annotations

__all__ = ["UNIT_SUFFIXES", "unit_of_suffix"]

# suffix -> unit; the longest matching suffix wins (``_kPa`` over ``_Pa``, ``_kg_per_m2`` over ``_m2``,
# ``_per_km_h`` over ``_km_h``)
UNIT_SUFFIXES = (
    ("_N_per_m_n1", "N/m^(n+1)"), ("_N_per_m_n2", "N/m^(n+2)"), ("_Pa_s_per_m", "Pa s/m"), ("_Pa_per_m", "Pa/m"),
    ("_kg_per_m2", "kg/m^2"), ("_kg_m2", "kg m^2"), ("_per_km_h", "h/km"), ("_km_h", "km/h"), ("_rad_s", "rad/s"),
    ("_m_s2", "m/s^2"), ("_m_s", "m/s"), ("_N_m", "N m"), ("_rad", "rad"), ("_deg", "deg"), ("_kg_per_kg", "kg/kg"),
    ("_Mg_per_m3", "Mg/m^3"), ("_kg", "kg"), ("_MPa", "MPa"), ("_kPa", "kPa"), ("_Pa", "Pa"), ("_kN", "kN"),
    ("_N", "N"), ("_kW", "kW"), ("_W", "W"), ("_kJ", "kJ"), ("_J", "J"), ("_mm", "mm"), ("_cm", "cm"), ("_km", "km"),
    ("_m2", "m^2"), ("_m3", "m^3"), ("_m", "m"), ("_ms", "ms"), ("_s", "s"), ("_h", "h"), ("_ha", "ha"),
    ("_percent", "%"),
)
_BY_LENGTH = tuple(sorted(UNIT_SUFFIXES, key=lambda su: -len(su[0])))


def unit_of_suffix(name: str, none: str = "1") -> str:
    """The unit ``name`` carries in its suffix (the longest of :data:`UNIT_SUFFIXES` it ends with), or
    ``none`` when it ends with none of them (a dimensionless name)."""
    for suffix, unit in _BY_LENGTH:
        if name.endswith(suffix):
            return unit
    return none
