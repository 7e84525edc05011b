"""Structural and numerical options of the symbolic model (not physical parameters)."""

from __future__ import annotations

from dataclasses import dataclass

from ..foundations.errors import ParameterError

TRACTION_SIGN_MODES = ("smooth", "tanh", "sign")


@dataclass(frozen=True)
class ModelOptions:
    """How the equations are written.

    traction_sign: how the sign functions of the model are evaluated: sign(j) of seed eq. (1),
        and the direction sign(omega) of the internal resistance and sign(v_k) of the compaction
        resistance.
        "smooth" (default): sign(j) = j/sqrt(j^2 + d^2) with d = shear_smoothing_m (the product
        with the bracket of eq. (1) is then smooth and odd and differs from the exact law only
        for |j| ~ d); the directions are tanh(omega/omega_smoothing), tanh(v/motion_smoothing).
        "tanh": the seed's approximation, sign(j) = tanh(k j) with k = tanh_steepness_per_m;
        directions as in "smooth".
        "sign": the discontinuous sign() everywhere, kept to reproduce the seed's numerical
        oscillations (Coulomb-like chattering of the internal resistance at omega = 0).
    lateral_segments, gauss_points: the lateral resistance is integrated along each track with
        composite Gauss-Legendre quadrature (segments x points per segment).
    lateral_shear_cap: when true, the lateral resistance per unit area, mu_t p, is capped at
        the soil's shear strength c + p tan(phi) (reconstruction, not in MODEL.md). Without the cap
        the reference crawler on clayey soil (Thailand, 38 %) meets a turning resistance larger
        than the soil lets its tracks push (mu_t W = 29.7 kN > b l c + W tan(phi) = 21.4 kN) and
        holds no steady turn tighter than about 100 m. Off by default: the validation was
        calibrated without it (its lateral creep is far from either limit).
    accel_newton_iterations: the body accelerations a_x, a_y enter the pressure distribution
        (load transfer), which sets the forces, which set the accelerations. For the ODE form this
        algebraic loop is solved inside the expression: one fixed-point step from a = 0, then this
        many Newton steps on the 2x2 system; the DAE form (IDAS) solves it with algebraic
        variables. tests/test_vehicle.py measures the residual.
    """

    traction_sign: str = "smooth"
    tanh_steepness_per_m: float = 1000.0
    shear_smoothing_m: float = 1e-6
    omega_smoothing_rad_s: float = 0.01
    motion_smoothing_m_s: float = 0.01
    bekker_regularisation_m: float = 1e-6
    lateral_segments: int = 4
    gauss_points: int = 3
    accel_newton_iterations: int = 1
    lateral_shear_cap: bool = False

    def __post_init__(self):
        if self.traction_sign not in TRACTION_SIGN_MODES:
            raise ParameterError(
                f"model.traction_sign = {self.traction_sign!r} is not one of {', '.join(TRACTION_SIGN_MODES)}"
            )
        for name in ("tanh_steepness_per_m", "shear_smoothing_m", "omega_smoothing_rad_s",
                     "motion_smoothing_m_s", "bekker_regularisation_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0):
                raise ParameterError(f"model.{name} = {v!r} must be a number > 0")
        if not isinstance(self.lateral_shear_cap, bool):
            raise ParameterError(f"model.lateral_shear_cap = {self.lateral_shear_cap!r} must be true or false")
        for name, lo, hi in (("lateral_segments", 1, 64), ("gauss_points", 1, 16),
                             ("accel_newton_iterations", 0, 20)):
            v = getattr(self, name)
            if not (isinstance(v, int) and lo <= v <= hi):
                raise ParameterError(f"model.{name} = {v!r} must be an integer in [{lo}, {hi}]")
