"""One terrain cell: MODEL.md section 2 and seed eq. (4), written once in CasADi.

Pressure-sinkage law (z positive down):

- virgin loading (Bekker): p = k_eq z^n with k_eq = k_c / b + k_phi, b the track width.
  Regularised as p = k_eq z+ (z+ + d)^(n-1), z+ = max(z, 0), so that dp/dz stays finite at
  z = 0 (for n < 1 it is infinite in the exact law); the relative error is |1 - n| d / z,
  3e-4 at 1.5 mm with d = 1 um.
- unloading and reloading (Wong; reconstruction): below the largest sinkage so far z_max the
  soil follows the straight line through (z_max, p_max) with slope
  k_u = max(K_e, kappa p_max / z_max), clipped at p >= 0 (no tension). Reloading climbs the same
  line back to (z_max, p_max) and then rejoins the Bekker curve. The floor kappa p_max / z_max
  (kappa >= max(1, n)) keeps the line below the Bekker curve, so
  p = bekker(z) if z >= z_max else max(0, min(bekker(z), line(z))).
- dynamics (seed eq. 4): tau_z d2z/dt2 = p_load - p - c'' dz/dt.

The history (z_max, p_max) enters as an input: inside one integration step it is constant and
the law above switches branch by itself; the world manager updates it between steps.
"""

from __future__ import annotations

import casadi as ca


def k_eq(k_c, k_phi, track_width):
    """Bekker's combined modulus k_eq = k_c / b + k_phi [N/m^(n+2)]."""
    return k_c / track_width + k_phi


def bekker_pressure(z, keq, n, reg_m):
    """Virgin-loading (Bekker) pressure with the finite-slope regularisation of the module doc."""
    zp = ca.fmax(z, 0)
    return keq * zp * (zp + reg_m) ** (n - 1)


def unloading_slope(z_max, p_max, elastic_stiffness, kappa, reg_m):
    return ca.fmax(elastic_stiffness, kappa * p_max / ca.fmax(z_max, reg_m))


def reaction_pressure(z, z_max, p_max, keq, n, elastic_stiffness, kappa, reg_m):
    """Soil reaction pressure p(z; z_max, p_max) [Pa] of the loading/unloading/reloading law."""
    pb = bekker_pressure(z, keq, n, reg_m)
    k_u = unloading_slope(z_max, p_max, elastic_stiffness, kappa, reg_m)
    line = p_max - k_u * (z_max - z)
    return ca.if_else(z >= z_max, pb, ca.fmax(0, ca.fmin(pb, line)))


def cell_acceleration(zdot, p_load, p, areal_mass, damping):
    """Seed eq. (4): d2z/dt2 = (p_load - p - c'' dz/dt) / tau_z."""
    return (p_load - p - damping * zdot) / areal_mass
