"""The registry of a run folder's figures, by what they plot.

Every plot of a run folder (``symtrack simulate``, ``symtrack mpc``, a terrain study's passes)
is one entry: a name, the kind of thing it plots and a function of the run that returns its
files (name -> PNG or GIF bytes; several for a figure drawn once per pass, none when it does not
apply). The kinds and what their functions take:

- ``"trajectory"``: a :class:`~symtrack.simulation.result.RunResult` (the time series of one run);
- ``"terrain"`` and ``"subsoil"``: a :class:`TerrainRun` (a terrain study's passes over the grid
  terrain and its scenario);
- ``"control"``: a closed loop (:class:`~symtrack.control.closedloop.ClosedLoopResult`).

:func:`figures` draws the figures of some kinds, in the order of registration (the order of the
files in report.html). Adding a figure is one function and one :func:`register` call.

A figure registered with ``extra`` (what it draws, in words) is slow for what it adds and drawn
only when asked for (``run.all_figures = true``; docs/terrain.md, "What the outputs cost"): the
pass animations (a GIF is 20-30 frames, each drawn like a PNG). :func:`extras` names the ones
left out, for report.html. Of several passes, the sinkage map is the last pass's only unless
``TerrainRun.all_figures`` (the earlier passes' trajectory plots are the caller's:
:func:`symtrack.reports.run_files.simulation_files`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..vehicles import registry as vehicle_registry
from . import control_plots, plots, terrain_plots, vehicle3d_plots

__all__ = ["KINDS", "Figure", "TerrainRun", "extras", "figures", "names", "register", "unregister"]

KINDS = ("trajectory", "terrain", "subsoil", "control")


@dataclass(frozen=True)
class Figure:
    """One registered figure: ``make(source) -> {file name: bytes}``; ``extra``: None for a figure
    always drawn, else what it draws (a figure drawn only with ``all_figures``; module doc)."""

    name: str
    kind: str
    make: Callable[[object], dict[str, bytes]]
    extra: str | None = None


class TerrainRun(NamedTuple):
    """The source of the terrain and subsoil figures: a terrain study's passes
    (:class:`~symtrack.simulation.passes.PassStudy`) and its scenario (its start pose draws the
    rut's cross-section)."""

    scenario: object
    study: object
    all_figures: bool = True  # every pass's sinkage map (else the last pass's)

    @property
    def multi(self) -> bool:
        """True for several passes (their files are numbered)."""
        return len(self.study.runs) > 1


_REGISTRY: dict[str, Figure] = {}


def register(name: str, kind: str, make: Callable[[object], dict[str, bytes]], extra: str | None = None) -> Figure:
    """Register a figure (after the others: its files come after theirs); ``extra``: drawn only
    with ``all_figures`` (module doc), described in these words."""
    if kind not in KINDS:
        raise KeyError(f"figure kind {kind!r} is not one of {', '.join(KINDS)}")
    if name in _REGISTRY:
        raise KeyError(f"a figure named {name!r} is registered already")
    fig = _REGISTRY[name] = Figure(name, kind, make, extra)
    return fig


def unregister(name: str) -> None:
    """Remove a registered figure (a figure registered by a test)."""
    del _REGISTRY[name]


def names(kind: str | None = None) -> list[str]:
    """The registered figures' names (of one kind), in registration order."""
    return [f.name for f in _REGISTRY.values() if kind is None or f.kind == kind]


def _kinds(kinds) -> tuple[str, ...]:
    kinds = (kinds,) if isinstance(kinds, str) else tuple(kinds)
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise KeyError(f"figure kind {unknown[0]!r} is not one of {', '.join(KINDS)}")
    return kinds


def figures(kinds, source, all_figures: bool = True) -> dict[str, bytes]:
    """The files of the registered figures of ``kinds`` (a kind or a tuple of kinds) drawn from
    ``source``, in registration order; without ``all_figures`` not the ``extra`` ones."""
    kinds = _kinds(kinds)
    out: dict[str, bytes] = {}
    for fig in _REGISTRY.values():
        if fig.kind in kinds and (all_figures or fig.extra is None):
            out.update(fig.make(source))
    return out


def extras(kinds) -> list[str]:
    """What the ``extra`` figures of ``kinds`` draw (their descriptions, in registration order):
    the figures :func:`figures` leaves out without ``all_figures``."""
    kinds = _kinds(kinds)
    return [f.extra for f in _REGISTRY.values() if f.kind in kinds and f.extra is not None]


# -- the trajectory of a run ------------------------------------------------------------------------------------
def _time_series(name, series, ylabel, title, scale=1.0):
    return lambda res: {name: plots.time_plot(res, series, ylabel, title, scale)}


register("path", "trajectory", lambda res: {"path.png": plots.path_plot(res)})
register("yaw", "trajectory", _time_series("yaw.png", [("yaw_rad", "yaw")], "yaw [deg]", "yaw angle", np.degrees(1.0)))
register("sinkage", "trajectory", _time_series(
    "sinkage.png", [(f"sinkage_{e}_{k}_m", f"{e} {k}") for e in ("sprocket", "idler") for k in ("left", "right")],
    "sinkage [mm]", "sinkage under sprocket (rear) and idler (front)", 1e3))
register("shear", "trajectory", _time_series("shear.png", [("shear_left_m", "left"), ("shear_right_m", "right")],
                                             "shear displacement [mm]", "mean shear displacement j", 1e3))
register("speeds", "trajectory", _time_series("speeds.png", [("u_m_s", "u (forward)"), ("v_m_s", "v (lateral)")],
                                              "speed [m/s]", "body velocities"))
register("torques", "trajectory", _time_series(
    "torques.png", [("torque_left_N_m", "left (actual)"), ("torque_right_N_m", "right (actual)"),
                    ("torque_cmd_left_N_m", "left (command)"), ("torque_cmd_right_N_m", "right (command)")],
    "torque [N m]", "sprocket torques"))


# the figures a vehicle declares its own (its ``figures``: symtrack.vehicles.base; the 3D vehicle's,
# model.vehicle = "3d", symtrack.reports.vehicle3d_plots; none for a planar run)
def _declared(res, name: str) -> bool:
    return name in vehicle_registry.get(res.scenario.model.vehicle).figures


def _path_elevation(res) -> dict[str, bytes]:
    surface = vehicle3d_plots.run_surface(res) if _declared(res, "path_elevation") else None
    return {} if surface is None else {"path_elevation.png": vehicle3d_plots.path_elevation_png(res, surface)}


register("attitude", "trajectory",
         lambda res: {"attitude.png": vehicle3d_plots.attitude_png(res)} if _declared(res, "attitude") else {})
register("load_split", "trajectory",
         lambda res: {"load_split.png": vehicle3d_plots.load_split_png(res)} if _declared(res, "load_split") else {})
register("path_elevation", "trajectory", _path_elevation)


# -- the terrain of a study's passes ----------------------------------------------------------------------------
def _sinkage_maps(src: TerrainRun) -> dict[str, bytes]:
    st = src.study
    passes = range(len(st.maps)) if src.all_figures else range(len(st.maps) - 1, len(st.maps))
    return {(f"sinkage_map_pass_{k + 1}.png" if src.multi else "sinkage_map.png"):
            terrain_plots.sinkage_map_png(st.world, st.maps[k], k + 1) for k in passes}


def _rut_section(src: TerrainRun) -> dict[str, bytes]:
    st, s = src.study, src.scenario.start
    line = (s.x_m, s.y_m, np.radians(s.yaw_deg))
    return {"rut_section.png": terrain_plots.rut_section_png(st.world, st.maps, st.runs, line)}


def _animations(src: TerrainRun) -> dict[str, bytes]:
    st = src.study
    return {(f"animation_pass_{k + 1}.gif" if src.multi else "animation.gif"):
            terrain_plots.pass_animation_gif(st.world, st.before[k], snaps, st.maps[k])
            for k, snaps in enumerate(st.snapshots) if snaps}


def _surface(src: TerrainRun) -> dict[str, bytes]:
    """The ground's shape: only for a field with an elevation (a non-flat [terrain.surface])."""
    st = src.study
    if st.world.storage.elevation is None:
        return {}
    return {"surface.png": terrain_plots.surface_png(st.world, st.maps, st.runs)}


register("sinkage_map", "terrain", _sinkage_maps)
register("rut_section", "terrain", _rut_section)
register("animation", "terrain", _animations,
         extra="the pass animations (animation.gif, or animation_pass_<k>.gif per pass)")
register("surface", "terrain", _surface)
register("subsoil", "subsoil", lambda src: terrain_plots.subsoil_pngs(src.study.world, src.study.figures))
register("density", "subsoil", lambda src: terrain_plots.density_pngs(src.study.world, src.study.figures,
                                                                      src.study.bulk_density_initial))
register("passes", "terrain",
         lambda src: {"passes.png": terrain_plots.passes_png(src.study.figures)} if src.multi else {})

# -- a closed loop ------------------------------------------------------------------------------------------------
register("closed_loop", "control", control_plots.closed_loop_pngs)
register("closed_loop_terrain", "control", control_plots.closed_loop_terrain_pngs)
