"""The soil column under the tracks of a run on homogeneous soil (no terrain cells): the same one soil
as a terrain study's (docs/subsoil.md, "One soil"), so that the rut, the stress, the bulk density and
the risk come from one description of the ground on every model.

A homogeneous run has no cells to keep the soil's state in; its tracks pass once over the ground
under their centre-lines. At the output steps of the largest contact pressure each track's contact is
cut into elements carrying its pressure, linear between the idler's and the sprocket's (the outputs
``p_idler_*_Pa``, ``p_sprocket_*_Pa``), scaled so that the elements carry the track's normal load
(``normal_load_*_N``); Fröhlich's point load (symtrack/soil/subsoil.py, with the soil's
``stress_concentration_factor``) sums their vertical stress at points along each track's centre-line
(a point under the track sees every position of the contact as the track passes over it) and at the
subsoil depths. The largest over those steps and points, under the more loaded track, is the pass's
vertical stress; the density model folds it with the soil's own weight from the initial state at
each depth (symtrack/soil/density.py, each depth's layer), the rut (the deepest sinkage of a track
end over the run) bounds the column's compression, and the risk grades the stress with the own
weight against each depth's precompression stress.

The summary keys (one list per key, in the order of ``subsoil_depths_m``): ``subsoil_depths_m``,
``subsoil_sigma_z_max_kPa`` (the traffic's), ``subsoil_precompression_stress_by_depth_kPa``,
``subsoil_risk_by_depth`` ("low", "medium", "high"), ``bulk_density_initial_Mg_per_m3``,
``bulk_density_after_Mg_per_m3``; and ``column_compression_mm`` (the column's shortening, at most
the rut).
"""

from __future__ import annotations

import numpy as np

from ..soil import density, subsoil

__all__ = ["ELEMENTS_PER_DEPTH", "PEAK_STEPS", "POINTS_ALONG", "column_figures"]

# the output steps of the largest contact pressure that are evaluated (measured: on the validation and the
# drive-and-coast runs the stress by depth is that of all their steps to the last digit)
PEAK_STEPS = 16
# a track's contact cut into point loads at most (shallowest depth) / ELEMENTS_PER_DEPTH apart: the sum
# is then within 0.5 % of the contact's integral at every depth (tests/test_one_soil.py against
# subsoil.stress_bruteforce's Gauss-Legendre quadrature)
ELEMENTS_PER_DEPTH = 3
POINTS_ALONG = 33  # the points along a centre-line where the stress is taken (ends included)


def _pressures(res) -> dict | None:
    names = {f"{what}_{side}": f"{what}_{side}_{unit}" for side in ("left", "right")
             for what, unit in (("p_idler", "Pa"), ("p_sprocket", "Pa"), ("normal_load", "N"))}
    if not all(n in res.output_names for n in names.values()):
        return None  # (a model without these outputs; the 3D vehicle's are its segments' least-squares line)
    return {k: np.asarray(res.output(n), dtype=np.float64) for k, n in names.items()}


def column_figures(res, depths_m=subsoil.DEFAULT_DEPTHS_M) -> dict:
    """The column figures of a homogeneous run (module doc); empty for a model without the contact
    pressure outputs."""
    p = _pressures(res)
    if p is None or res.t.size == 0:
        return {}
    params = res.scenario.params
    b, l_m, gauge = (float(params[k]) for k in ("track_width_m", "contact_length_m", "track_gauge_m"))
    xi = float(params["stress_concentration_factor"])
    depths = np.asarray(depths_m, dtype=np.float64)
    peak = np.max([p[k] for k in p if not k.startswith("normal")], axis=0)
    steps = np.argsort(peak, kind="stable")[-PEAK_STEPS:]
    h = float(depths.min()) / ELEMENTS_PER_DEPTH
    n_along, n_across = max(1, int(np.ceil(l_m / h))), max(1, int(np.ceil(b / h)))
    u = (np.arange(n_along) + 0.5) / n_along  # along the contact, 0 at one end, 1 at the other
    ex = (u - 0.5) * l_m
    ey = ((np.arange(n_across) + 0.5) / n_across - 0.5) * b
    px = np.linspace(-0.5 * l_m, 0.5 * l_m, POINTS_ALONG)
    sides = {"left": 0.5 * gauge, "right": -0.5 * gauge}
    # every element of both tracks (x, y) and the points under both centre-lines
    ex_all = np.concatenate([np.repeat(ex, n_across)] * 2)
    ey_all = np.concatenate([np.tile(ey, n_along) + y0 for y0 in sides.values()])
    qx = np.concatenate([px, px])
    qy = np.concatenate([np.full(POINTS_ALONG, y0) for y0 in sides.values()])
    r = np.hypot(qx[:, None] - ex_all[None, :], qy[:, None] - ey_all[None, :])
    # the elements' forces at each of the steps, one column per step
    F = np.empty((ex_all.size, steps.size))
    for c, k in enumerate(steps):
        forces = []
        for side in sides:
            pe = p[f"p_idler_{side}"][k] + (p[f"p_sprocket_{side}"][k] - p[f"p_idler_{side}"][k]) * u
            f = np.repeat(np.maximum(pe, 0.0), n_across)
            total = f.sum()
            forces.append(f * (max(p[f"normal_load_{side}"][k], 0.0) / total) if total > 0 else 0.0 * f)
        F[:, c] = np.concatenate(forces)
    # Fröhlich's stress is linear in the force: the stress of a unit force from every element at every
    # point, once per depth, times the steps' forces
    sig = np.array([float(np.max(subsoil.frohlich_point(1.0, r, z, xi) @ F, initial=0.0)) for z in depths])
    # the fold of the one pass (density.pass_update's operations) and the rut's bound
    a = density.soil_arrays([params], depths)
    geo = density.geostatic_table([params], depths)[0]
    total = sig + geo  # Pa
    v0 = a["v0"][0]
    line = density.load_update(v0.copy(), np.log(1e-3 * total), a["N"][0], a["lambda"][0], a["kappa"][0],
                               a["lambda_minus_kappa"][0], a["m"][0], a["k2"][0], a["v_min"][0])
    state = np.where(line < v0, line, 0.0).astype(np.float32)[None, :]
    ends = [res.output(f"sinkage_{e}_{s}_m") if f"sinkage_{e}_{s}_m" in res.output_names else res.state(
        f"sinkage_{e}_{s}_m") for e in ("idler", "sprocket") for s in ("left", "right")]
    rut_m = max(float(np.max(e)) for e in ends)
    density.cap_to_rut(state, np.array([0]), v0[None, :], depths, np.array([rut_m]))
    v1 = np.where(state[0] > 0, state[0].astype(np.float64), v0)
    risk = subsoil.risk_class(total, a["pc"][0])
    return {"subsoil_depths_m": [float(z) for z in depths],
            "subsoil_sigma_z_max_kPa": [1e-3 * float(s) for s in sig],
            "subsoil_precompression_stress_by_depth_kPa": [1e-3 * float(v) for v in a["pc"][0]],
            "subsoil_risk_by_depth": [subsoil.RISK_NAMES[int(c)] for c in risk],
            "bulk_density_initial_Mg_per_m3": [float(v) for v in a["rho_s"][0] / v0],
            "bulk_density_after_Mg_per_m3": [float(v) for v in a["rho_s"][0] / v1],
            "column_compression_mm": 1e3 * float(density.column_compression_m(v1[None, :], v0[None, :], depths)[0])}
