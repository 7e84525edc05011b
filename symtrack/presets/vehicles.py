"""Vehicle parameter sets.

The vehicle data of Ferretti & Girelli (1999) are NOT public. The reference crawler below is a
medium agricultural crawler whose every value lies in the plausible ranges of such machines
and whose free values were calibrated against Ferretti & Girelli's validation table (docs/model.md,
"Validation case and calibrated values"),
as marked on each line. Wong's internal-resistance coefficients are from Wong, *Theory of Ground
Vehicles* (tracked vehicles: R_in = W (0.0222 + 0.0003 V[km/h])).
"""

from __future__ import annotations

from ..foundations.errors import ParameterError
from ..model.parameters import VEHICLE_PARAMS, check_set

VEHICLES: dict[str, dict[str, float]] = {
    "reference_crawler": {
        # calibrated against the validation table: with the contact area below it gives a mean
        # ground pressure of about 25 kPa, i.e. 1-2 mm of sinkage on clayey soil (Thailand, 38 %).
        "mass_kg": 5500.0,
        # estimated: uniform box of 3.5 m x 1.9 m, m (L^2 + W^2) / 12.
        "yaw_inertia_kg_m2": 7000.0,
        # calibrated against the validation table (range 1.1-1.8 m): sets the yaw moment.
        "track_gauge_m": 1.5,
        # calibrated against the validation table (range 0.3-0.5 m).
        "track_width_m": 0.45,
        # calibrated against the validation table (range 1.5-2.4 m).
        "contact_length_m": 2.4,
        # calibrated against the validation table (range 0.25-0.40 m): sets the tractive force
        # 2000 N m / r, hence the acceleration, the load transfer and the shear.
        "sprocket_radius_m": 0.38,
        # calibrated against the validation table (range 0.6-1.0 m): sets the rearward load
        # transfer under acceleration (nose up, rear sinkage below 2 mm).
        "cg_height_m": 0.6,
        # assumed: CG above the contact centre.
        "cg_ahead_of_contact_centre_m": 0.0,
        # estimated: track mass about 200 kg, m_track r^2 ~ 29 kg m^2 (range 10-60 per side).
        "sprocket_inertia_kg_m2": 30.0,
        # calibrated against the oscillation study of the Politecnico di Milano thesis (docs/model.md):
        # a 0.1 s actuator lag removes the model-related shear oscillations that a torque step excites.
        "torque_time_constant_s": 0.1,
        # Wong, Theory of Ground Vehicles (tracked vehicles).
        "internal_resistance_const": 0.0222,
        "internal_resistance_per_km_h": 0.0003,
        # calibrated against the validation table with the creep law (range 0.5-0.65); used by
        # lateral_law = "creep" (the paper's law, which the validation scenarios declare) only: the
        # shear laws (the default "shear", "shear_quasistatic") take their lateral resistance from the
        # soil (c, phi, K) and ignore both values below.
        "lateral_friction_coeff": 0.55,
        # calibrated against the validation table with the creep law: the yaw drift of 0.4 deg over 20 m is a
        # creep whose rate is proportional to this speed (docs/model.md, "Lateral resistance and turning").
        # Not a soil property; docs/turning.md.
        "lateral_creep_speed_m_s": 0.009,
        # the validation run pulls no implement.
        "drawbar_pull_N": 0.0,
        # assumed drawbar hitch height (only used when drawbar_pull_N > 0).
        "hitch_height_m": 0.5,
    },
}


def vehicle_preset(name: str) -> dict[str, float]:
    if name not in VEHICLES:
        raise ParameterError(f"vehicle.preset = {name!r} is not a known vehicle; known: {', '.join(VEHICLES)}")
    return check_set(dict(VEHICLES[name]), VEHICLE_PARAMS, f"vehicle preset {name!r}")
