"""Homogeneous-soil terrain: four terrain cells that travel with the vehicle on virgin soil.

Under each track's sprocket end and idler end sits one cell with the dynamics and the
loading/unloading law of docs/model.md, "Pressure-sinkage" (:mod:`symtrack.soil.cell`):

- the idler cell (front) meets virgin soil at every instant: its history is empty
  (z_max = p_max = 0), so it follows the Bekker loading branch;
- the sprocket cell (rear) meets soil that the track has already loaded from the front: its
  history is the idler cell's state (z_max = z_idler, p_max = p_bekker(z_idler)). When the rear
  pressure exceeds the front pressure (nose up) it continues on the Bekker branch; when it is
  lower it sits on the unloading line through the front's (z, p).

The soil law is the model's (:mod:`symtrack.soil.law`, ``opts.soil_law``); above, the
default Bekker/Wong law.

Compaction resistance: the soil law's work per metre to press a rut of depth z (Bekker/Wong:
R_c = b k_eq z^(n+1) / (n+1), reconstruction), with z the deepest sinkage under the track.

This terrain stays as the light terrain for control design once the grid terrain exists.
"""

from __future__ import annotations

import casadi as ca

from ..soil import cell
from ..soil import law as soil_law
from ..vehicles.planar import ENDS, TRACKS
from .options import ModelOptions

__all__ = ["HomogeneousTerrain", "cell_state_names"]


def cell_state_names(track: str, end: str) -> tuple[str, str]:
    return f"sinkage_{end}_{track}_m", f"sinkage_rate_{end}_{track}_m_s"


class HomogeneousTerrain:
    name = "homogeneous"
    param_names = ()

    def __init__(self, opts: ModelOptions):
        self.opts = opts
        self.law = soil_law.make(opts)
        self.state_names = tuple(n for k in TRACKS for e in ENDS for n in cell_state_names(k, e))

    def _index(self, track, end):
        i = 2 * (2 * TRACKS.index(track) + ENDS.index(end))
        return i, i + 1

    def compaction(self, xv, xc, P, Q):
        law = self.law.vector(P)
        out = []
        for k in TRACKS:
            zs = xc[self._index(k, "sprocket")[0]]
            zi = xc[self._index(k, "idler")[0]]
            z = ca.fmax(ca.fmax(zs, zi), 0)
            out.append(self.law.compaction_work(z, law, P["track_width_m"]))
        return ca.vertcat(*out)

    def equations(self, xv, xc, dist: dict, P, Q):
        """Cell state derivatives and named signals, given the vehicle's pressure distributions."""
        law = self.law.vector(P)
        xdot = [None] * len(self.state_names)
        signals = {}
        for k in TRACKS:
            iz_i, iv_i = self._index(k, "idler")
            iz_s, iv_s = self._index(k, "sprocket")
            z_i, z_s = xc[iz_i], xc[iz_s]
            p_idler_soil = self.law.pressure(z_i, (0, 0, 0, 0, 0), law)
            p_hist = self.law.virgin_pressure(z_i, law)
            p_sprocket_soil = self.law.pressure(z_s, (z_i, p_hist, 0, 0, 0), law)
            p_load = {"idler": dist[k].idler, "sprocket": dist[k].sprocket}
            p_soil = {"idler": p_idler_soil, "sprocket": p_sprocket_soil}
            for end, (iz, iv) in (("idler", (iz_i, iv_i)), ("sprocket", (iz_s, iv_s))):
                xdot[iz] = xc[iv]
                xdot[iv] = cell.cell_acceleration(xc[iv], p_load[end], p_soil[end],
                                                  P["cell_areal_mass_kg_per_m2"], P["cell_damping_Pa_s_per_m"])
                signals[f"p_{end}_{k}_Pa"] = p_load[end]
                signals[f"sinkage_{end}_{k}_m"] = xc[iz]
        return ca.vertcat(*xdot), signals
