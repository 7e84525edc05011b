"""The public face of symtrack for scripts and notebooks: :func:`simulate` and :class:`Result`.

    import symtrack
    sc = symtrack.load_scenario("validation", {"run.integrator": "rosenbrock"})
    res = symtrack.simulate(sc)
    res.summary["lateral_deviation_m"], res["yaw_rad"]   # a series by its name (res.columns)
    res.to_xarray()               # every series with its unit and description (xarray: optional)
    res.write("out/v")            # exactly the files of `symtrack simulate validation --out out/v`

A scenario with a ``[terrain]`` section runs on the persistent grid terrain (all its passes);
``res.terrain`` is then the field after the last pass (:class:`symtrack.Terrain`: ``save``,
``load``, the storage arrays), and ``simulate(sc, terrain=res.terrain)`` continues on it.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .foundations.errors import ScenarioError, SimulationError
from .foundations.version import __version__
from .native.generate import unit_of
from .reports.run_files import (
    TerrainOut,
    simulation_files,
    terrain_run,
    trajectory_columns,
    validation_rows,
    validation_table,
    write_folder,
)
from .simulation.builder import Built, build
from .simulation.result import RunResult
from .simulation.scenario import Scenario
from .terrain.storage import Terrain

__all__ = ["ANIMATION_EVERY_S", "Built", "IncompleteSimulation", "Result", "build", "describe_series", "simulate"]

# a grid run keeps a snapshot of its loaded cells this often, for the pass animations (with
# run.all_figures only: the default draws no animation)
ANIMATION_EVERY_S = 0.1


# what each series of trajectory.csv is (its unit is in its name's suffix: symtrack.native.generate.unit_of);
# {0}, {1}: the pattern's groups. A name not listed is described by its kind (state, command, output).
_SERIES = (
    (r"t_s", "time"),
    (r"x_m", "x of the centre of gravity in the world frame"),
    (r"y_m", "y of the centre of gravity in the world frame"),
    (r"z_m", "height of the centre of gravity"),
    (r"yaw_rad", "yaw angle (heading) in the world frame"),
    (r"pitch_rad", "pitch angle, positive nose up"),
    (r"roll_rad", "roll angle"),
    (r"u_m_s", "longitudinal speed in the body frame"),
    (r"v_m_s", "lateral speed in the body frame"),
    (r"yaw_rate_rad_s", "yaw rate"),
    (r"heave_rate_m_s", "vertical speed of the centre of gravity"),
    (r"pitch_rate_rad_s", "pitch rate"),
    (r"roll_rate_rad_s", "roll rate"),
    (r"omega_(left|right)_rad_s", "angular speed of the {0} sprocket"),
    (r"torque_(left|right)_N_m", "torque of the {0} sprocket (the actuator's state)"),
    (r"torque_cmd_(left|right)_N_m", "commanded torque of the {0} sprocket"),
    (r"shear_(left|right)_m", "longitudinal shear displacement of the {0} track"),
    (r"lateral_shear_(left|right)_m", "lateral shear displacement of the {0} track"),
    (r"shear_twist_(left|right)_rad", "shear twist of the {0} track (the gradient of its lateral slip along it)"),
    (r"ground_z_m", "height of the ground under the centre of gravity"),
    (r"sinkage_(sprocket|idler)_(left|right)_m", "sinkage under the {0} end of the {1} track"),
    (r"sinkage_rate_(sprocket|idler)_(left|right)_m_s", "sinkage rate under the {0} end of the {1} track"),
    (r"p_(sprocket|idler)_(left|right)_Pa", "contact pressure at the {0} end of the {1} track"),
    (r"tractive_(left|right)_N", "tractive effort of the {0} track"),
    (r"internal_resistance_(left|right)_N", "internal resistance of the {0} track"),
    (r"compaction_resistance_(left|right)_N", "compaction resistance of the {0} track"),
    (r"lateral_force_(left|right)_N", "lateral force on the {0} track"),
    (r"normal_load_(left|right)_N", "normal load on the {0} track"),
    (r"slip_(left|right)", "longitudinal slip of the {0} track"),
    (r"accel_x_m_s2", "longitudinal acceleration in the body frame"),
    (r"accel_y_m_s2", "lateral acceleration in the body frame"),
    (r"yaw_moment_N_m", "yaw moment of the track forces"),
    (r"compaction_power_W", "power spent compacting the soil"),
)


def describe_series(name: str, kind: str = "model output") -> tuple[str, str]:
    """The unit and a description of a series of trajectory.csv (``kind`` describes a name this
    module does not know: "state", "commanded input", "model output")."""
    for pattern, text in _SERIES:
        m = re.fullmatch(pattern, name)
        if m:
            return unit_of(name), text.format(*m.groups())
    return unit_of(name), kind


class IncompleteSimulation(SimulationError):
    """A simulation that failed part of the way; ``result`` holds what was computed up to there
    (its summary has ``complete = false`` and ``error``), and can be written as any result."""

    def __init__(self, message: str, result: Result):
        super().__init__(message)
        self.result = result


class Result:
    """What :func:`simulate` returns.

    Attributes
    ----------
    scenario : Scenario
    runs : list of RunResult
        One per pass (one for the homogeneous terrain).
    summary : dict
        The summary.json of the run (docs/outputs.md); for several passes the whole run's
        figures (symtrack/simulation/passes.py) with ``passes``, the per-pass figures.
    pass_summaries : list of dict
        The summary of each pass (what ``pass_<k>/summary.json`` holds).
    terrain : Terrain or None
        The grid terrain after the run (None on the homogeneous terrain).
    """

    def __init__(self, scenario: Scenario, runs: list[RunResult], summary: dict, pass_summaries: list[dict],
                 study=None):
        self.scenario, self.runs, self.summary, self.pass_summaries = scenario, runs, summary, pass_summaries
        self._study = study
        self.terrain: Terrain | None = None if study is None else study.world.storage

    @property
    def t(self) -> np.ndarray:
        """Output times [s] of the last pass."""
        return self.runs[-1].t

    def column(self, name: str, pass_no: int | None = None) -> np.ndarray:
        """A column of trajectory.csv (``t_s``, a state, a commanded torque or an output) of the
        last pass, or of pass ``pass_no`` (1-based)."""
        run = self.runs[-1 if pass_no is None else self._pass_index(pass_no)]
        return run.t if name == "t_s" else run.column(name)

    def __getitem__(self, name: str) -> np.ndarray:
        """``res["yaw_rad"]``: a series of the last pass by its name, as :meth:`column`."""
        if not isinstance(name, str):
            raise KeyError(f"{name!r}: a Result is indexed by a series name ({', '.join(self.columns[:4])}, ...)")
        return self.column(name)

    def __contains__(self, name) -> bool:
        return name in self.columns

    @property
    def columns(self) -> list[str]:
        """The names of the series (the columns of trajectory.csv, ``t_s`` first), each with its unit in
        its suffix (``_m``, ``_rad``, ``_N_m``, ...; :meth:`units`)."""
        return trajectory_columns(self.runs[-1])[0]

    def units(self) -> dict[str, str]:
        """{series name: unit} ("1" for a dimensionless series such as a slip)."""
        return {n: describe_series(n)[0] for n in self.columns}

    def to_xarray(self, pass_no: int | None = None):
        """The series of the last pass, or of pass ``pass_no``, as an :class:`xarray.Dataset` over the
        time coordinate ``t`` [s]: one variable per series, its ``units`` and ``description`` in its
        attributes, the scenario, integrator and version in the dataset's. xarray is optional (the
        extra ``symtrack[gis]`` installs it)."""
        try:
            import xarray
        except ImportError as err:
            raise ScenarioError("Result.to_xarray needs xarray, which symtrack does not install by default: "
                                "pip install xarray (or pip install 'symtrack[gis]'; Result.to_pandas and "
                                "Result.column need no extra)") from err
        run = self.runs[-1 if pass_no is None else self._pass_index(pass_no)]
        names, data = trajectory_columns(run)
        states = set(run.state_names)

        def attrs(name):
            kind = "state" if name in states else "commanded input" if name.startswith("torque_cmd_") else \
                "model output"
            unit, text = describe_series(name, kind)
            return {"units": unit, "description": text}

        variables = {n: ("t", data[:, k], attrs(n)) for k, n in enumerate(names) if n != "t_s"}
        summary = self.summary if pass_no is None or len(self.runs) == 1 else self.pass_summaries[pass_no - 1]
        return xarray.Dataset(
            variables, coords={"t": ("t", data[:, 0], {"units": "s", "description": "time"})},
            attrs={"scenario": self.scenario.name, "description": self.scenario.description or "",
                   "integrator": str(summary.get("integrator", self.scenario.run.integrator)),
                   "pass": len(self.runs) if pass_no is None else pass_no, "symtrack_version": __version__})

    def _pass_index(self, pass_no: int) -> int:
        if not isinstance(pass_no, int) or not 1 <= pass_no <= len(self.runs):
            raise KeyError(f"pass_no = {pass_no!r}: this result has passes 1 to {len(self.runs)}")
        return pass_no - 1

    @property
    def validation_table(self) -> str | None:
        """The reported-vs-simulated table (Markdown) of a validation scenario, else None."""
        return validation_table(self.scenario, self.summary)

    def write(self, out_dir, terrain_out=None) -> list[Path]:
        """Write the files of the run into ``out_dir`` (as ``symtrack simulate --out``;
        :func:`~symtrack.reports.run_files.simulation_files` through the one writer,
        :func:`~symtrack.reports.run_files.write_folder`: the files of a previous run in the folder
        are removed first, summary.json last, all or nothing). With ``terrain_out`` (a path; as
        ``--terrain-out``) the terrain file is written with them, this run added to its history
        (its id is ``summary["terrain_run_id"]``). Returns the paths written (the folder's)."""
        terrain = None
        if terrain_out is not None:
            if self.terrain is None:
                raise ScenarioError(f"terrain_out = {str(terrain_out)!r}: scenario {self.scenario.name!r} ran on the "
                                    "homogeneous terrain, which has no field to save")
            run = terrain_run(self.scenario, len(self.runs))
            terrain = TerrainOut(Path(terrain_out), self.terrain, self.scenario.soil, run)
            self.summary["terrain_out"] = str(terrain_out)
            self.summary["terrain_run_id"] = run["run_id"]
        files = simulation_files(self.scenario, self.runs, self.summary, self.pass_summaries, self._study)
        return write_folder(out_dir, files, terrain=terrain)

    def __repr__(self) -> str:
        s = self.summary
        head = f"<Result {self.scenario.name!r}: {len(self.runs)} pass{'es' if len(self.runs) != 1 else ''}"
        figs = [f"{k} {s[k]:.4g}" for k in ("sim_time_s", "distance_m", "lateral_deviation_m", "rut_max_depth_mm",
                                             "wall_time_s") if isinstance(s.get(k), int | float)]
        tail = "" if s.get("complete", True) else ", incomplete"
        return f"{head}{', ' if figs else ''}{', '.join(figs)}{tail}>"

    def _repr_html_(self) -> str:
        """The view in a notebook: what ran (scenario, vehicle, soil, integrator, passes), the summary's
        figures with their units, the validation table of a validation scenario."""
        from .reports.html import machine_facts, notebook_html

        sc = self.scenario
        facts = [("scenario", sc.name), ("integrator", self.summary.get("integrator", sc.run.integrator)),
                 ("passes", len(self.runs)), ("terrain", "grid" if self.terrain is not None else "homogeneous")]
        facts += machine_facts(sc.vehicle_preset, sc.soil_preset, sc.params)
        rows = validation_rows(sc, self.summary)
        if rows is not None:
            rows = [(k, reported, value, "yes" if ok else "NO") for k, reported, value, ok in rows]
        return notebook_html(repr(self).strip("<>"), self.summary, facts, rows=rows,
                             row_header=["quantity", "reported (Ferretti & Girelli 1999)", "simulated", "within"])

    def to_pandas(self, pass_no: int | None = None):
        """The trajectory (the columns of trajectory.csv) of the last pass, or of pass ``pass_no``,
        as a pandas DataFrame; pandas is optional (not a dependency of symtrack)."""
        try:
            import pandas
        except ImportError as err:
            raise ScenarioError("Result.to_pandas needs pandas, which symtrack does not install: "
                                "pip install pandas (or use Result.column)") from err
        run = self.runs[-1 if pass_no is None else self._pass_index(pass_no)]
        names, data = trajectory_columns(run)
        return pandas.DataFrame(data, columns=names)


def simulate(scenario, *, integrator: str | None = None, terrain=None, progress: bool | None = None) -> Result:
    """Run a scenario: its torque programme until its stop rule, every pass of a terrain study.

    Parameters
    ----------
    scenario : Scenario, str or Built
        A loaded scenario, a built-in name / TOML path (loaded with no overrides), or what
        :func:`build` returned.
    integrator : str, optional
        Instead of the scenario's ``run.integrator`` (a name of the integrator registry).
    terrain : Terrain or path, optional
        A grid terrain to start from (instead of a new field); the scenario needs a
        ``[terrain]`` section.
    progress : bool or None
        Show progress on stderr: None (the default) once the run has taken 2 s (a quick run says
        nothing), True from the start, False never.

    Returns
    -------
    Result
    """
    built = build(scenario.scenario if isinstance(scenario, Built) else scenario, integrator=integrator,
                  terrain=terrain)
    scenario = built.scenario
    record = ANIMATION_EVERY_S if scenario.run.all_figures else None
    out = built.run(terrain, progress=progress, record_every_s=record)
    result = Result(scenario, out.runs, out.summary, out.pass_summaries, out.study)
    failure = out.failure
    if failure is not None:
        result.summary["complete"] = False
        result.summary["error"] = str(failure)
        raise IncompleteSimulation(str(failure), result) from failure
    return result
