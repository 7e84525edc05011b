"""The public face of symtrack for scripts and notebooks: :func:`simulate` and :class:`Result`.

    import symtrack
    sc = symtrack.load_scenario("validation", {"run.integrator": "rosenbrock"})
    res = symtrack.simulate(sc)
    res.summary["lateral_deviation_m"], res.column("yaw_rad")
    res.write("out/v")            # exactly the files of `symtrack simulate validation --out out/v`

A scenario with a ``[terrain]`` section runs on the persistent grid terrain (all its passes);
``res.terrain`` is then the field after the last pass (:class:`symtrack.Terrain`: ``save``,
``load``, the storage arrays), and ``simulate(sc, terrain=res.terrain)`` continues on it.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from .foundations.errors import ScenarioError
from .foundations.files import atomic_write_bytes, atomic_write_text
from .integrators import registry
from .reports import plots, terrain_plots, validation
from .reports.run_files import write_run
from .simulation import loop
from .simulation.passes import run_passes, study_summary
from .simulation.plants import make_plant
from .simulation.result import RunResult, summarise
from .simulation.scenario import Scenario, builtin_names, load_scenario
from .terrain.storage import Terrain

__all__ = ["Result", "simulate"]


class Result:
    """What :func:`simulate` returns.

    Attributes
    ----------
    scenario : Scenario
    runs : list of RunResult
        One per pass (one for the homogeneous terrain).
    summary : dict
        The summary.json of the run (README: "Output files"); for several passes the last
        pass's figures with ``passes``, the per-pass figures.
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

    def _pass_index(self, pass_no: int) -> int:
        if not isinstance(pass_no, int) or not 1 <= pass_no <= len(self.runs):
            raise KeyError(f"pass_no = {pass_no!r}: this result has passes 1 to {len(self.runs)}")
        return pass_no - 1

    @property
    def validation_table(self) -> str | None:
        """The reported-vs-simulated table (Markdown) of a validation scenario, else None."""
        sc = self.scenario
        if sc.run.stop_distance_event == "idle" and "validation" in sc.name:
            return validation.table_markdown(self.summary)
        return None

    def write(self, out_dir) -> list[Path]:
        """Write the files of the run into ``out_dir`` (as ``symtrack simulate --out``);
        summary.json last. Returns the paths written."""
        out = Path(out_dir)
        written = []
        if self._study is None:
            res = self.runs[0]
            figs = plots.all_plots(res)
            write_run(out, res, self.summary, figs)
            written += [out / n for n in ("trajectory.csv", "scenario.resolved.toml", *figs)]
        else:
            st = self._study
            multi = len(st.runs) > 1
            if multi:
                for k, (res, summ) in enumerate(zip(st.runs, self.pass_summaries, strict=True)):
                    figs = plots.all_plots(res)
                    write_run(out / f"pass_{k + 1}", res, summ, figs)
                    written += [out / f"pass_{k + 1}" / n for n in ("trajectory.csv", "scenario.resolved.toml",
                                                                     *figs, "summary.json")]
            pngs = {}
            for k, z in enumerate(st.maps):
                name = f"sinkage_map_pass_{k + 1}.png" if multi else "sinkage_map.png"
                pngs[name] = terrain_plots.sinkage_map_png(st.world, z, k + 1)
            sc = self.scenario
            line = (sc.start.x_m, sc.start.y_m, np.radians(sc.start.yaw_deg))
            pngs["rut_section.png"] = terrain_plots.rut_section_png(st.world, st.maps, st.runs, line)
            if multi:
                for name, data in pngs.items():
                    atomic_write_bytes(out / name, data)
                    written.append(out / name)
                atomic_write_text(out / "summary.json", json.dumps(self.summary, indent=2) + "\n")
            else:
                pngs.update(plots.all_plots(st.runs[0]))
                write_run(out, st.runs[0], self.summary, pngs)
                written += [out / n for n in ("trajectory.csv", "scenario.resolved.toml", *pngs)]
        table = self.validation_table
        if table is not None:
            atomic_write_text(out / "validation_table.md", table)
            written.append(out / "validation_table.md")
        written.append(out / "summary.json")
        return sorted(set(written))


def _grid_names() -> list[str]:
    return [n for n in builtin_names() if load_scenario(n).terrain is not None]


def simulate(scenario, *, integrator: str | None = None, terrain=None, progress: bool = False) -> Result:
    """Run a scenario: its torque programme until its stop rule, every pass of a terrain study.

    Parameters
    ----------
    scenario : Scenario or str
        A loaded scenario, or a built-in name / TOML path (loaded with no overrides).
    integrator : str, optional
        Instead of the scenario's ``run.integrator`` (a name of the integrator registry).
    terrain : Terrain or path, optional
        A grid terrain to start from (instead of a new field); the scenario needs a
        ``[terrain]`` section.
    progress : bool
        Show progress on stderr.

    Returns
    -------
    Result
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if integrator is not None:
        if not isinstance(integrator, str):
            raise ScenarioError(f"integrator = {integrator!r} must be a name: {', '.join(registry.names())}")
        registry.get(integrator, "integrator")
        scenario = dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, integrator=integrator))
    if terrain is not None and scenario.terrain is None:
        raise ScenarioError(f"scenario {scenario.name!r} has no [terrain] section, so it runs on the homogeneous "
                            f"terrain and cannot start from a terrain file; the grid scenarios are "
                            f"{', '.join(_grid_names())} (or add a [terrain] section)")
    plant = make_plant(scenario, terrain=terrain)
    if plant.kind == "grid":
        study = run_passes(scenario, plant, progress=progress)
        summary, per_pass = study_summary(study)
        if terrain is not None and not isinstance(terrain, Terrain):
            summary["terrain_in"] = str(terrain)
        return Result(scenario, study.runs, summary, per_pass, study)
    res = loop.run(scenario, plant, progress=progress)
    summary = summarise(res)
    return Result(scenario, [res], summary, [summary])
