"""Homogeneous-soil terrain: four terrain cells that travel with the vehicle on virgin soil.

Under each track's sprocket end and idler end sits one cell with the dynamics and the
loading/unloading law of MODEL.md section 2 (:mod:`symtrack.model.cell`):

- the idler cell (front) meets virgin soil at every instant: its history is empty
  (z_max = p_max = 0), so it follows the Bekker loading branch;
- the sprocket cell (rear) meets soil that the track has already loaded from the front: its
  history is the idler cell's state (z_max = z_idler, p_max = p_bekker(z_idler)). When the rear
  pressure exceeds the front pressure (nose up) it continues on the Bekker branch; when it is
  lower it sits on the unloading line through the front's (z, p).

Compaction resistance (reconstruction; Bekker): the work per metre to press a rut of depth z,
R_c = b k_eq z^(n+1) / (n+1), with z the deepest sinkage under the track.

This terrain stays as the light terrain for control design once the grid terrain exists.
"""

from __future__ import annotations

import casadi as ca

from . import cell
from .options import ModelOptions
from .vehicle import ENDS, TRACKS


def cell_state_names(track: str, end: str) -> tuple[str, str]:
    return f"sinkage_{end}_{track}_m", f"sinkage_rate_{end}_{track}_m_s"


class HomogeneousTerrain:
    name = "homogeneous"
    param_names = ()

    def __init__(self, opts: ModelOptions):
        self.opts = opts
        self.state_names = tuple(n for k in TRACKS for e in ENDS for n in cell_state_names(k, e))

    def _index(self, track, end):
        i = 2 * (2 * TRACKS.index(track) + ENDS.index(end))
        return i, i + 1

    def _keq(self, P):
        return cell.k_eq(P["k_c_N_per_m_n1"], P["k_phi_N_per_m_n2"], P["track_width_m"])

    def compaction(self, xv, xc, P, Q):
        keq, n = self._keq(P), P["bekker_n"]
        out = []
        for k in TRACKS:
            zs = xc[self._index(k, "sprocket")[0]]
            zi = xc[self._index(k, "idler")[0]]
            z = ca.fmax(ca.fmax(zs, zi), 0)
            out.append(P["track_width_m"] * keq * z ** (n + 1) / (n + 1))
        return ca.vertcat(*out)

    def equations(self, xv, xc, dist: dict, P, Q):
        """Cell state derivatives and named signals, given the vehicle's pressure distributions."""
        keq, n = self._keq(P), P["bekker_n"]
        reg = cell.bekker_regularisation_length(keq, n, self.opts.bekker_regularisation_m)
        law = dict(keq=keq, n=n, elastic_stiffness=P["elastic_stiffness_Pa_per_m"],
                   kappa=P["unloading_stiffness_floor"], reg_m=reg)
        xdot = [None] * len(self.state_names)
        signals = {}
        for k in TRACKS:
            iz_i, iv_i = self._index(k, "idler")
            iz_s, iv_s = self._index(k, "sprocket")
            z_i, z_s = xc[iz_i], xc[iz_s]
            p_idler_soil = cell.reaction_pressure(z_i, 0, 0, **law)
            p_hist = cell.bekker_pressure(z_i, keq, n, reg)
            p_sprocket_soil = cell.reaction_pressure(z_s, z_i, p_hist, **law)
            p_load = {"idler": dist[k].idler, "sprocket": dist[k].sprocket}
            p_soil = {"idler": p_idler_soil, "sprocket": p_sprocket_soil}
            for end, (iz, iv) in (("idler", (iz_i, iv_i)), ("sprocket", (iz_s, iv_s))):
                xdot[iz] = xc[iv]
                xdot[iv] = cell.cell_acceleration(xc[iv], p_load[end], p_soil[end],
                                                  P["cell_areal_mass_kg_per_m2"], P["cell_damping_Pa_s_per_m"])
                signals[f"p_{end}_{k}_Pa"] = p_load[end]
                signals[f"sinkage_{end}_{k}_m"] = xc[iz]
        return ca.vertcat(*xdot), signals
