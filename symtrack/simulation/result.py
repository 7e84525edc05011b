"""The result of one run (one pass) and its summary figures (summary.json, schema in docs/outputs.md)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.layout import POSE_NAMES
from .scenario import Scenario

__all__ = ["INPUT_COLUMNS", "SUMMARY_SCHEMA_VERSION", "RunResult", "summarise"]

SUMMARY_SCHEMA_VERSION = 1
INPUT_COLUMNS = ("torque_cmd_left_N_m", "torque_cmd_right_N_m")


@dataclass
class RunResult:
    """One run: times ``t`` [s], states ``X`` (columns ``state_names``), commanded torques ``U``
    (:data:`INPUT_COLUMNS`) and outputs ``Y`` (``output_names``) at the output times."""

    scenario: Scenario
    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    state_names: tuple
    output_names: tuple
    wall_time_s: float
    stopped_by: str
    stats: dict = field(default_factory=dict)
    terrain: dict | None = None  # grid terrain figures of the run (World.figures)
    cpu_time_s: float = float("nan")  # CPU time of the time loop (process time: less sensitive to load)

    def state(self, name):
        return self.X[:, self.state_names.index(name)]

    def pose(self) -> np.ndarray:
        """The pose at the output times: columns x_m, y_m, yaw_rad (by name, whatever the state order)."""
        return self.X[:, [self.state_names.index(n) for n in POSE_NAMES]]

    def output(self, name):
        return self.Y[:, self.output_names.index(name)]

    def column(self, name):
        """A state, commanded torque or output by name (the columns of trajectory.csv)."""
        if name in INPUT_COLUMNS:
            return self.U[:, INPUT_COLUMNS.index(name)]
        if name in self.state_names:
            return self.state(name)
        if name in self.output_names:
            return self.output(name)
        names = ["t_s", *self.state_names, *INPUT_COLUMNS]
        names += [n for n in self.output_names if n not in names]  # trajectory.csv's columns, each once
        raise KeyError(f"no column {name!r}; columns: {', '.join(names)}")


def summarise(res: RunResult) -> dict:
    """The summary figures of a run (summary.json keys, docs/outputs.md)."""
    sc = res.scenario
    x, y, psi = res.state("x_m"), res.state("y_m"), res.state("yaw_rad")
    X0, Y0, psi0 = x[0], y[0], psi[0]
    xe, ye, psie = x[-1], y[-1], psi[-1]
    lateral = -(xe - X0) * np.sin(psi0) + (ye - Y0) * np.cos(psi0)
    seg = np.hypot(np.diff(x), np.diff(y))
    out = {
        "schema_version": SUMMARY_SCHEMA_VERSION,
        "scenario": sc.name,
        "integrator": sc.run.integrator,
        "stopped_by": res.stopped_by,
        "distance_m": float(seg.sum()),
        "complete": res.stopped_by != "error",
    }
    if sc.run.stop_after_distance_m is not None:
        out["distance_stop_reached"] = res.stopped_by == "distance"
    if sc.run.stop_distance_event:
        te = sc.event_time(sc.run.stop_distance_event)
        after = res.t[1:] > te + 1e-12
        out[f"distance_after_{sc.run.stop_distance_event}_m"] = float(seg[after].sum())
    out["lateral_deviation_m"] = float(abs(lateral))
    out["lateral_deviation_signed_m"] = float(lateral)
    out["yaw_final_deg"] = float(np.degrees(psie - psi0))
    ends = {}
    for end in ("sprocket", "idler"):
        mean = 0.5 * (res.column(f"sinkage_{end}_left_m") + res.column(f"sinkage_{end}_right_m"))
        ends[end] = float(mean.max())
        out[f"sinkage_{end}_mm"] = 1e3 * ends[end]
    last = sc.torque[-1]
    jl, jr = res.state("shear_left_m"), res.state("shear_right_m")
    if abs(last.left_N_m) != abs(last.right_N_m) and res.t[-1] >= last.t_s:
        driven, idle = (jr, jl) if abs(last.right_N_m) > abs(last.left_N_m) else (jl, jr)
        since = res.t >= last.t_s
        out["shear_driven_max_m"] = float(driven[since].max())
        out["shear_idle_min_m"] = float(idle[since].min())
    else:
        out["shear_driven_max_m"] = float(max(jl.max(), jr.max()))
        out["shear_idle_min_m"] = None
    out["speed_final_m_s"] = float(res.state("u_m_s")[-1])
    out["nose_up"] = bool(ends["sprocket"] > ends["idler"])
    out["sim_time_s"] = float(res.t[-1])
    out["wall_time_s"] = float(res.wall_time_s)
    out["real_time_factor"] = float(res.t[-1] / res.wall_time_s) if res.wall_time_s > 0 else None
    if "fixed_step_error_max" in res.stats:  # the compiled Rosenbrock's error control (FixedStepper)
        out["fixed_step_error_max"] = float(res.stats["fixed_step_error_max"])
        out["fixed_step_steps_halved"] = int(res.stats["fixed_step_steps_halved"])
    if res.terrain:
        out.update(res.terrain)
    elif res.scenario.terrain is None:  # homogeneous soil: the column under the tracks (simulation/column.py)
        from .column import column_figures

        out.update(column_figures(res))
    return out
