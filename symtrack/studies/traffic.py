"""The traffic-system comparison as a resumable sweep on Dask (docs/studies.md, "Traffic
systems on Dask").

    from symtrack.studies.traffic import traffic_sweep
    res = traffic_sweep("traffic_small", "out/traffic", workers=2)   # or scheduler="tcp://HOST:8786"
    res["rows"]                                                        # the rows of out/traffic/traffic.csv

Each traffic system of the season's ``[season] compare`` list (random, ab, controlled) is one case
of a :func:`symtrack.studies.sweep` over the key ``season.tracks`` (every operation of the season
under that system, on a new field): the sweep's folder (``sweep.json``, ``results.csv``,
``runs/<id>/`` with each system's season files, ``summary.json`` last) is the comparison's, so a
rerun of the same command into the same folder skips the systems whose season finished and runs
the rest (an interrupted comparison resumes). At the end the one table and one figure of
:func:`symtrack.studies.operations.traffic_comparison` are written from the cases' summaries:
``traffic.csv``, ``traffic.json``, ``traffic.png``.
"""

from __future__ import annotations

from ..foundations.errors import ScenarioError
from ..foundations.files import atomic_write_bytes, atomic_write_text
from .engine import sweep
from .operations import TRACKS, TrafficComparison, load_operation_spec, traffic_files, traffic_row

__all__ = ["TRACKS_KEY", "traffic_sweep"]

TRACKS_KEY = "season.tracks"  # the varied key: every operation's track system


def traffic_sweep(scenario, out, *, systems=None, overrides=None, workers: int = 2, scheduler: str | None = None,
                  progress: bool = True) -> TrafficComparison:
    """The traffic systems ``systems`` (default: the season's ``[season] compare``) of the season
    ``scenario`` (a built-in of ``symtrack field`` or a TOML file) compared as a sweep on Dask: a
    local cluster of ``workers`` processes or the scheduler at ``scheduler``. Returns a
    :class:`~symtrack.studies.operations.TrafficComparison`, ``{"rows": the rows of traffic.csv, "sweep": the
    SweepResult}`` with a notebook view. Refused (ScenarioError) before anything
    runs when the season or a system is invalid; on Ctrl-C the finished systems are kept (rerun to
    do the rest)."""
    spec = load_operation_spec(scenario, overrides)  # the season checked here first (its message, not the sweep's)
    systems = tuple(spec.compare if systems is None else systems)
    if not systems:
        raise ScenarioError("season.compare is empty: a traffic comparison needs the systems to compare "
                            f"({', '.join(TRACKS)})")
    for s in systems:
        if s not in TRACKS:
            raise ScenarioError(f"season.compare = {list(systems)!r}: {s!r} is not one of {', '.join(TRACKS)}")
    if len(set(systems)) != len(systems):
        raise ScenarioError(f"season.compare = {list(systems)!r} names a system twice")
    res = sweep(scenario, {TRACKS_KEY: list(systems)}, out=out, overrides=overrides, kind="field",
                workers=workers, scheduler=scheduler, progress=progress)
    rows = [traffic_row(r[TRACKS_KEY], r if r["status"] == "ok" else None) for r in res.rows]
    for name, data in traffic_files(rows).items():
        if isinstance(data, bytes):
            atomic_write_bytes(res.out / name, data)
        else:
            atomic_write_text(res.out / name, data)
    return TrafficComparison(spec.name, rows, sweep=res)
