"""Passes over the grid terrain: one world, several runs, the figures of each pass.

summary.json of a terrain study (``schema_version`` 1): the run's summary keys, each over the whole
run (:func:`whole_run`): the sums over the passes of ``distance_m``, ``distance_after_<event>_m``,
``sim_time_s``, ``wall_time_s`` and ``fixed_step_steps_halved`` (``real_time_factor``: total simulated
time over total wall time); the largest of ``sinkage_sprocket_mm``, ``sinkage_idler_mm``,
``shear_driven_max_m``, ``fixed_step_error_max`` and ``terrain_peak_active_cells``, the smallest
``shear_idle_min_m``; ``lateral_deviation_m`` and ``lateral_deviation_signed_m`` of the pass that
deviated most; ``complete`` and ``distance_stop_reached`` true when they are for every pass;
``nose_up`` from the largest sinkages; the figures of the run's end (``stopped_by``,
``speed_final_m_s``, ``yaw_final_deg``) and of the field after it (the terrain figures
``terrain_*``, the rut figures) the last pass's. Then ``passes``: a list with, per pass,
``rut_max_depth_mm``, ``rut_mean_depth_mm`` (mean sinkage over the rut: the cells loaded in
the pass, z_max > 1 um), ``new_sinkage_mean_mm`` (mean sinkage added by the pass over the rut),
``new_sinkage_volume_m3``, ``compaction_resistance_mean_N`` (the sum of both tracks'
compaction resistance, mean over the distance the CG travelled: the compaction work per metre
of travel), ``compaction_resistance_time_mean_N`` (the same, mean over time: dominated by the
start from rest, where R_c = P / max(v, v0) divides the cells' settling power by the speed floor
v0; docs/terrain.md "The compaction resistance figure"), ``rut_cells``, ``distance_m``, ``sim_time_s``,
``wall_time_s``, ``real_time_factor`` (the pass's own); with several passes also ``later_passes_add_less_sinkage`` and
``later_passes_meet_less_resistance``. With the subsoil stress computed (the terrain engine), each
pass also has ``bulk_density_max_Mg_per_m3``: the field's largest dry bulk density after the pass
at each depth of ``subsoil_depths_m`` (docs/subsoil.md "Bulk density"), and the summary has
``bulk_density_initial_Mg_per_m3``: the same before the first pass.

With a towed load (``[terrain.towed]``, symtrack/vehicles/towed.py) each pass is the crawler's run
followed by the trailer's wheels along the path it drove, into the same cells' stress record and
compression state; the pass then also has the trailer's figures ``towed_subsoil_sigma_z_max_kPa``
(its largest vertical stress per depth), ``towed_cells_loaded``, ``towed_axle_poses``,
``towed_offtracking_max_m``, ``towed_wheel_load_kN``, ``towed_inflation_kPa`` and
``towed_bulk_density_max_Mg_per_m3``, and ``crawler_bulk_density_max_Mg_per_m3`` (the field's
largest after the crawler, before the trailer); ``bulk_density_max_Mg_per_m3`` is the field's after
both. The subsoil_* figures stay the crawler's. A pass that fails has no towed part; a trailer
whose wheels would leave the field fails its pass (before loading any cell).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..foundations.errors import ScenarioError
from ..soil import subsoil
from ..terrain.world import World
from ..vehicles import towed
from . import loop
from .plants import GridPlant
from .result import RunResult, summarise

__all__ = ["RUT_THRESHOLD_M", "PassStudy", "pass_figures", "run_passes", "study_summary"]

RUT_THRESHOLD_M = 1e-6


@dataclass
class PassStudy:
    """The passes of a terrain study: one :class:`RunResult` per pass, its figures, the
    sinkage map after it ((nx, ny) arrays), the world they ran on, and per pass the sinkage
    before it and the plant's snapshots (for the animation; empty when none were recorded)."""

    world: World
    runs: list
    figures: list
    maps: list
    before: list = field(default_factory=list)
    snapshots: list = field(default_factory=list)
    bulk_density_initial: list | None = None  # the field's largest bulk density per depth before the passes


def pass_figures(world: World, z_before: np.ndarray, res: RunResult, touched: np.ndarray) -> dict:
    """The figures of one pass (module doc) from the storage before and after it."""
    st = world.storage
    z = st.z
    rut = touched & (st.zmax > RUT_THRESHOLD_M)
    dz = z - z_before
    area = world.grid.cell_m ** 2
    rc = res.output("compaction_resistance_left_N") + res.output("compaction_resistance_right_N")
    tt = res.t
    rc_time = float(np.sum(0.5 * (rc[1:] + rc[:-1]) * np.diff(tt)) / (tt[-1] - tt[0])) if tt[-1] > tt[0] else 0.0
    seg = np.hypot(np.diff(res.state("x_m")), np.diff(res.state("y_m")))
    rc_dist = float(np.sum(0.5 * (rc[1:] + rc[:-1]) * seg) / seg.sum()) if seg.sum() > 0 else 0.0
    return {**_subsoil_figures(world), **_density_figures(world), **{
        "rut_max_depth_mm": 1e3 * float(z[rut].max()) if rut.any() else 0.0,
        "rut_mean_depth_mm": 1e3 * float(z[rut].mean()) if rut.any() else 0.0,
        "new_sinkage_mean_mm": 1e3 * float(dz[rut].mean()) if rut.any() else 0.0,
        "new_sinkage_volume_m3": float(dz.sum() * area),
        "compaction_resistance_mean_N": rc_dist,
        "compaction_resistance_time_mean_N": rc_time,
        "rut_cells": int(rut.sum()),
        "distance_m": float(seg.sum()),
        "sim_time_s": float(res.t[-1]),
        "wall_time_s": float(res.wall_time_s),
        "real_time_factor": float(res.t[-1] / res.wall_time_s) if res.wall_time_s > 0 else None,
    }}


def _subsoil_figures(world: World) -> dict:
    """The subsoil figures of a pass (docs/subsoil.md): the depths, the largest vertical stress
    over the field at each, and the area fraction of each risk class at each over the cells the
    pass loaded (Terranimo's classes of stress / precompression stress). Empty when the stress
    is off or was not computed (only the terrain engine computes it). The precompression stress
    figure is the weakest loaded cell's at any depth (a soil map gives cells different soils, a
    subsoil layer its own strength), and by depth the weakest loaded cell's at each."""
    depths = world.storage.subsoil_depths_m
    sig = world.pass_sigma
    # the loaded cells only (a pass loads a few of a field's cells: no temporary of the whole field's size)
    loaded = np.flatnonzero(sig[:, 0] > 0) if sig.size else np.zeros(0, dtype=np.int64)
    if not depths or not loaded.size:
        return {}
    pc = world.precompression_stress_Pa(loaded)
    sig = sig[loaded]
    total = sig.astype(np.float64) + world.geostatic_Pa()[world.storage.soil_index[loaded]]
    fr = subsoil.risk_area_fractions(total, pc, np.ones(loaded.size, dtype=bool), world.grid.cell_m ** 2)
    out = {"subsoil_depths_m": list(depths),
           "subsoil_sigma_z_max_kPa": [1e-3 * float(v) for v in sig.max(axis=0)],
           "subsoil_precompression_stress_min_kPa": 1e-3 * float(pc.min()),
           "subsoil_precompression_stress_by_depth_kPa": [1e-3 * float(v) for v in pc.min(axis=0)],
           "subsoil_loaded_area_m2": float(fr["touched_area_m2"])}
    for name in subsoil.RISK_NAMES:
        out[f"subsoil_risk_fraction_{name}"] = [float(v) for v in fr[f"fraction_{name}"]]
    return out


def _density_figures(world: World) -> dict:
    """The field's largest bulk density at each subsoil depth after the pass; empty when the pass's
    mean normal stress was not computed (only the terrain engine computes it)."""
    p = world.pass_sigma
    if not world.storage.subsoil_depths_m or not p.size or not (p[:, 0] > 0).any():
        return {}
    return {"bulk_density_max_Mg_per_m3": world.bulk_density_max()}


def run_passes(scenario, plant: GridPlant, passes: int | None = None, progress: bool | None = False) -> PassStudy:
    """All passes of the scenario (``terrain.passes`` unless given) with one grid plant. A pass
    that fails raises :class:`~symtrack.simulation.loop.IncompleteRun` with ``study``: the passes
    so far, the failed one up to where it failed."""
    world = plant.world
    n = passes if passes is not None else (scenario.terrain.passes if scenario.terrain is not None else 1)
    study = PassStudy(world, [], [], [])
    trailer = scenario.terrain.towed if scenario.terrain is not None else None
    if trailer is not None:
        xi = _check_towed(scenario, world, trailer)
    if world.storage.subsoil_depths_m:
        study.bulk_density_initial = world.bulk_density_max()
    for k in range(n):
        z0 = world.storage.z.copy()
        label = scenario.name if n == 1 else f"{scenario.name} pass {k + 1}/{n}"
        failure = None
        try:
            res = loop.run(scenario, plant, progress=progress, label=label)
        except loop.IncompleteRun as err:
            res, failure = err.partial, err  # the failed pass up to where it failed: kept, with its figures
        extra = {}
        if trailer is not None and failure is None:
            if _density_figures(world):
                extra["crawler_bulk_density_max_Mg_per_m3"] = world.bulk_density_max()
            try:
                extra.update(towed.towed_pass(world.storage, trailer, res.pose(),
                                              float(world.params["cg_ahead_of_contact_centre_m"]), world.soils, xi,
                                              world.cell_day))
            except ScenarioError as err:  # the trailer's path left the field (checked before it loads a cell)
                failure = loop.IncompleteRun(f"pass {k + 1}: {err}", res)
        study.figures.append({**pass_figures(world, z0, res, world.touched.copy()), **extra})
        study.maps.append(world.storage.copy_z())
        study.runs.append(res)
        study.before.append(z0.reshape(world.grid.shape))
        study.snapshots.append(list(plant.snapshots))
        if failure is not None:
            failure.study = study
            raise failure
    return study


def _check_towed(scenario, world: World, trailer) -> float:
    """Before the first pass: the trailer's stress concentration factor (the field's soil 0's,
    within [3, 10]: the mean normal stress needs xi - 2 >= 1) and its wheels inside the field at the
    start. Returns xi."""
    xi = float(world.soils[0]["stress_concentration_factor"])
    if not 3.0 <= xi <= 10.0:
        raise ScenarioError(f"terrain.towed: soil.stress_concentration_factor = {xi!r} is outside the allowed range "
                            "[3, 10] for the towed load's stress (its mean normal stress needs xi - 2 >= 1)")
    st = scenario.start
    pose = towed.start_pose(st.x_m, st.y_m, np.radians(st.yaw_deg), float(world.params["cg_ahead_of_contact_centre_m"]),
                            trailer)
    towed.check_inside(world.grid, trailer, pose, "terrain.towed at the start")
    return xi


# the top-level figures of several passes (module doc): sums, largest, smallest over the passes
SUMMED = ("distance_m", "sim_time_s", "wall_time_s", "fixed_step_steps_halved")
LARGEST = ("sinkage_sprocket_mm", "sinkage_idler_mm", "shear_driven_max_m", "fixed_step_error_max",
           "terrain_peak_active_cells")
SMALLEST = ("shear_idle_min_m",)


def whole_run(summaries: list[dict]) -> dict:
    """The summary of a run of several passes from the passes' own (module doc): the last pass's keys,
    with every figure that adds up or has an extreme taken over the whole run."""
    top = dict(summaries[-1])

    def numbers(key):
        return [float(s[key]) for s in summaries
                if isinstance(s.get(key), int | float) and not isinstance(s[key], bool)]

    summed = [*SUMMED, *(k for k in top if k.startswith("distance_after_") and k.endswith("_m"))]
    for key, how in [*((k, sum) for k in summed), *((k, max) for k in LARGEST), *((k, min) for k in SMALLEST)]:
        xs = numbers(key)
        if xs and key in top:
            top[key] = int(how(xs)) if isinstance(top[key], int) and not isinstance(top[key], bool) else how(xs)
    wall = top["wall_time_s"]
    top["real_time_factor"] = top["sim_time_s"] / wall if wall and wall > 0 else None
    worst = max(summaries, key=lambda s: abs(float(s.get("lateral_deviation_m") or 0.0)))
    for key in ("lateral_deviation_m", "lateral_deviation_signed_m"):
        if key in worst:
            top[key] = worst[key]
    for key in ("distance_stop_reached", "complete"):
        if key in top:
            top[key] = all(bool(s.get(key)) for s in summaries)
    if "sinkage_sprocket_mm" in top and "sinkage_idler_mm" in top:
        top["nose_up"] = bool(top["sinkage_sprocket_mm"] > top["sinkage_idler_mm"])
    return top


def study_summary(study: PassStudy) -> tuple[dict, list[dict]]:
    """(the study's summary.json, the summary of each pass)."""
    summaries = []
    for res, fig in zip(study.runs, study.figures, strict=True):
        s = summarise(res)
        s.update(fig)
        summaries.append(s)
    top = whole_run(summaries)  # the whole run's figures at the top (each pass's own are in ``passes``)
    top["passes"] = list(study.figures)
    if study.bulk_density_initial is not None and any("bulk_density_max_Mg_per_m3" in f for f in study.figures):
        top["bulk_density_initial_Mg_per_m3"] = list(study.bulk_density_initial)
    if len(study.runs) > 1:
        pairs = list(zip(study.figures[:-1], study.figures[1:], strict=False))
        top["later_passes_add_less_sinkage"] = all(
            b["new_sinkage_mean_mm"] < a["new_sinkage_mean_mm"] for a, b in pairs)
        top["later_passes_meet_less_resistance"] = all(
            b["compaction_resistance_mean_N"] < a["compaction_resistance_mean_N"] for a, b in pairs)
    return top, summaries
