"""Regenerate the tables of run results in the pages of docs/ (``make figures``).

    python docs/figures.py                       # runs every table's command, rewrites the pages
    python docs/figures.py --only steady-turns   # only these tables (make figures NAMES="a b")
    python docs/figures.py --print --only ...    # runs and prints, the pages untouched
    python docs/figures.py --list                # the tables: name, page, command

Each table of figures the package computes (a run's results, an accuracy against a reference, a
convergence) sits in its page between ``<!-- figures:NAME:start -->`` and ``<!-- figures:NAME:end -->``
and is written whole by this script: a line naming the command that produced it, the machine and
the date, then the table. The command is the one the page names (an example script, a ``symtrack``
command, a function of the package), run here with the settings the page states, in a fresh process
from the checkout. Runs that several tables share run once. The timing tables of docs/performance.md
are docs/performance.py's (``make performance``).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import datetime
import functools
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS))
sys.path.insert(0, str(ROOT))

from performance import machine  # noqa: E402  (the machine as docs/performance.py names it)

MARK = "<!-- figures:{name}:{end} -->"
TOTAL_PAGE = DOCS / "howto.md"


@dataclasses.dataclass(frozen=True)
class Table:
    name: str
    page: str  # docs/<page>
    command: str  # as the page's line above the table names it
    make: Callable[[], str]  # the table's Markdown


TABLES: dict[str, Table] = {}


def table(name: str, page: str, command: str):
    def deco(fn):
        if name in TABLES:
            raise ValueError(f"two tables named {name!r}")
        TABLES[name] = Table(name, page, command, fn)
        return fn
    return deco


# ---------------------------------------------------------------------------------------------------------
# running the commands: a fresh process from the checkout, each command once per regeneration

WORK = Path(tempfile.gettempdir()) / f"symtrack-figures-{os.getpid()}"  # the runs' folders, removed at the end
_ELAPSED: dict[str, float] = {}  # command -> seconds it took
_USED: list[str] = []  # the commands the table being made used


def _argv(command: str, out: Path | None) -> list[str]:
    """A command as the pages write it (``python examples/x.py ...``, ``symtrack ...``) as this process's
    interpreter runs it; ``DIR`` is the command's output folder."""
    args = shlex.split(command)
    args = [str(out) + a[3:] if a == "DIR" or a.startswith("DIR/") else a for a in args]
    if args[0] == "python":
        return [sys.executable, *args[1:]]
    if args[0] == "symtrack":
        return [sys.executable, "-m", "symtrack", *args[1:]]
    raise ValueError(f"not a command of the pages: {command}")


@functools.cache
def _run(command: str) -> tuple[int, str, str, Path]:
    out = WORK / f"run{len(_ELAPSED)}"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
    t0 = time.perf_counter()
    print(f"  $ {command}", file=sys.stderr, flush=True)
    proc = subprocess.run(_argv(command, out), cwd=ROOT, env=env, capture_output=True, text=True)
    _ELAPSED[command] = time.perf_counter() - t0
    return proc.returncode, proc.stdout, proc.stderr, out


def run(command: str, ok=(0,)) -> tuple[str, Path]:
    """(stdout, output folder) of ``command``; a failure (an exit code not in ``ok``) stops the table."""
    code, out, err, folder = _run(command)
    _USED.append(command)
    if code not in ok:
        raise RuntimeError(f"`{command}` exited with {code}:\n{err[-3000:]}")
    return out, folder


def run_json(command: str) -> dict | list:
    """The JSON object a command prints (its stdout, from the first line that opens one)."""
    out, _ = run(command)
    start = re.search(r"^[\[{]", out, re.M)
    if not start:
        raise RuntimeError(f"`{command}` printed no JSON:\n{out[-2000:]}")
    return json.loads(out[start.start():])


def summary(command: str, ok=(0,)) -> dict:
    """summary.json of a ``symtrack simulate|field ... --out DIR`` run."""
    _, folder = run(command, ok)
    return json.loads((folder / "summary.json").read_text(encoding="utf-8"))


@contextlib.contextmanager
def _timed(label: str):
    """Times a computation of this process as a command's run."""
    t0 = time.perf_counter()
    yield
    _ELAPSED[label] = time.perf_counter() - t0
    _USED.append(label)


def md_tables(text: str) -> list[str]:
    """The Markdown tables of a command's output with at least one row, in order."""
    return [m.group(0).rstrip("\n") for m in re.finditer(r"(?m)^\|.*\|\n\|[-:| ]+\|\n(?:\|.*\|(?:\n|\Z))+", text)]


def md(head: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def g(v, digits=4) -> str:
    """A figure to ``digits`` significant digits, as the tables print them."""
    return f"{v:.{digits}g}" if isinstance(v, (int, float)) else str(v)


def pct(new, ref, digits=3) -> str:
    """The relative difference in per cent, signed ("0.000 %" when it rounds to nothing)."""
    if not ref:
        return ""
    s = f"{100 * (new / ref - 1):+.{digits}f} %"
    return s[1:] if float(s[:-2]) == 0 else s


# ---------------------------------------------------------------------------------------------------------
# docs/codegen.md: the compiled fixed-step Rosenbrock against CVODES and its observed order

ROSENBROCK_FIGURES = ("distance_after_idle_m", "lateral_deviation_m", "yaw_final_deg", "sinkage_sprocket_mm",
                      "sinkage_idler_mm", "shear_driven_max_m", "shear_idle_min_m", "speed_final_m_s", "sim_time_s")


@table("rosenbrock-cvodes", "codegen.md", "symtrack simulate validation --integrator rosenbrock|cvodes "
       "[--set run.reltol=1e-10 --set run.abstol=1e-12] --out DIR")
def rosenbrock_cvodes() -> str:
    ref = summary("symtrack simulate validation --integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12 "
                  "--out DIR --quiet")
    rb = summary("symtrack simulate validation --integrator rosenbrock --out DIR --quiet")
    rows = [[f"`{k}`", f"{ref[k]:.7g}", f"{rb[k]:.7g}", f"{abs(rb[k] / ref[k] - 1):.1e}" if ref[k] else ""]
            for k in ROSENBROCK_FIGURES]
    return md(["figure", "CVODES (reltol 1e-10)", "rosenbrock, 10 ms", "relative difference"], rows)


ORDER_STEPS = (4, 8, 16, 32, 64)  # steps over the 0.2 s: h = 50 ... 3.125 ms
ORDER_REFERENCE = 1000  # h = 0.2 ms


@table("rosenbrock-order", "codegen.md",
       "symtrack.integrators.fixed_step.FixedStepper (rosenbrock) over 0.2 s of the validation run from t = 1 s "
       "and t = 6 s, inputs held, h = 50 ... 3.125 ms against 0.2 ms (docs/figures.py)")
def rosenbrock_order() -> str:
    import numpy as np

    from symtrack.integrators.fixed_step import FixedStepper
    from symtrack.integrators.settings import IntegratorSettings
    from symtrack.model import SystemModel
    from symtrack.simulation import loop
    from symtrack.simulation.plants import make_plant
    from symtrack.simulation.scenario import load_scenario

    span, rows = 0.2, []
    with _timed("rosenbrock order"):
        sc = load_scenario("validation", ["run.integrator=rosenbrock"])
        model = SystemModel(sc.model)
        res = loop.run(sc, make_plant(sc, model=model))
        p = np.array(model.param_vector(sc.params))
        scale = np.maximum(np.abs(res.X).max(axis=0), 1e-12)  # each state's range over the run
        for t0, what in ((1.0, "acceleration (from t = 1 s)"), (6.0, "steady turning (from t = 6 s)")):
            k = int(np.searchsorted(res.t, t0))
            x0, u = res.X[k], res.U[k]

            def solve(n, x0=x0, u=u):
                st = FixedStepper(model, IntegratorSettings("rosenbrock", fixed_step_s=span / n))
                z0 = np.array(st.lib.f("accel")(x0, u, p)).ravel()
                return np.array(st.advance(x0, z0, u, p, span)[0]).ravel()

            ref = solve(ORDER_REFERENCE)
            errs = [float(np.max(np.abs(solve(n) - ref) / scale)) for n in ORDER_STEPS]
            orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
            rows.append([what, " / ".join(f"{e:.1e}" for e in errs), " / ".join(f"{o:.1f}" for o in orders)])
    hs = " / ".join(f"{1e3 * span / n:g}" for n in ORDER_STEPS)
    return md(["0.2 s of the validation run", f"largest error over the states at h = {hs} ms (of each state's "
               f"range, against h = {1e3 * span / ORDER_REFERENCE:g} ms)", "observed orders between them"], rows)


# ---------------------------------------------------------------------------------------------------------
# docs/scenarios.md

@table("drive-and-coast", "scenarios.md",
       "symtrack simulate examples/scenarios/drive_and_coast.toml --out DIR ... (each row's options)")
def drive_and_coast() -> str:
    base = "symtrack simulate examples/scenarios/drive_and_coast.toml --out DIR --quiet "
    rows = [("CVODES (reltol 1e-7)", "--integrator cvodes --set run.reltol=1e-7"),
            ("IDAS", "--integrator idas"),
            ("rosenbrock, 1 ms steps, control off",
             "--integrator rosenbrock --set run.fixed_step_s=0.001 --set run.fixed_step_tolerance=0"),
            ("rosenbrock, 10 ms, control off", "--integrator rosenbrock --set run.fixed_step_tolerance=0"),
            ("rosenbrock, 10 ms, default tolerance 1e-3", "--integrator rosenbrock")]
    keys = ("sinkage_sprocket_mm", "sinkage_idler_mm", "distance_m", "speed_final_m_s")
    out, ref = [], None
    for label, opts in rows:
        s = summary(base + opts)
        ref = ref or s
        if s.get("fixed_step_steps_halved"):
            label += f" ({s['fixed_step_steps_halved']} steps halved)"
        cells = []
        for k in keys:
            c = f"{s[k]:.7g}"
            if abs(s[k] / ref[k] - 1) > 0.01:
                c = f"**{c}** ({pct(s[k], ref[k], 0)})"
            cells.append(c)
        out.append([label, f"`{opts}`", *cells])
    return md(["configuration", "command (after `symtrack simulate examples/scenarios/drive_and_coast.toml "
               "--out out/dc`)", *keys], out)


# ---------------------------------------------------------------------------------------------------------
# docs/validation-run.md and docs/validation.md

@table("validation", "validation-run.md",
       "symtrack simulate validation --out DIR; symtrack simulate validation --set model.lateral_law=shear "
       "--out DIR")
def validation_run() -> str:
    from symtrack.reports import validation

    declared = summary("symtrack simulate validation --out DIR --quiet")
    shear = summary("symtrack simulate validation --set model.lateral_law=shear --out DIR --quiet")
    return validation.comparison_markdown(declared, shear, "shear law (the default)").rstrip("\n")


def _validate_tables() -> list[str]:
    _, folder = run("symtrack validate --out DIR")
    return md_tables((folder / "validation.md").read_text(encoding="utf-8"))


@table("validate-points", "validation.md", "symtrack validate --out DIR (DIR/validation.md)")
def validate_points() -> str:
    return _validate_tables()[0]


@table("validate-kinds", "validation.md", "symtrack validate --out DIR (DIR/validation.md)")
def validate_kinds() -> str:
    return _validate_tables()[1]


@table("validate-sensitivity", "validation.md", "symtrack validate --out DIR (DIR/validation.md)")
def validate_sensitivity() -> str:
    return _validate_tables()[2]


# ---------------------------------------------------------------------------------------------------------
# docs/turning.md

@table("steady-turns", "turning.md", "python examples/steady_turns.py")
def steady_turns() -> str:
    out, _ = run("python examples/steady_turns.py")
    return md_tables(out)[0]


def _modes(law: str) -> dict[str, list[str]]:
    """The eigenvalues of `symtrack linearize` at the clay's 10 m, 2 m/s turn, by the reading of its modes.md."""
    return _modes_of(f"symtrack linearize --speed 2 --radius 10 --soil clayey_soil_thailand_38 "
                     f"--set model.lateral_law={law} --out DIR")


def _modes_of(command: str) -> dict[str, list[str]]:
    """The eigenvalues of a `symtrack linearize ... --out DIR` run by the reading of its modes.md."""
    _, folder = run(command)
    modes: dict[str, list[str]] = {}
    for line in md_tables((folder / "modes.md").read_text(encoding="utf-8"))[0].splitlines()[2:]:
        eig, _, _, reading, _ = (c.strip() for c in line.strip("|").split("|"))
        modes.setdefault(reading, []).append(eig.replace("±", "+-"))
    return modes


@table("linearization-modes", "turning.md",
       "symtrack linearize --speed 2 --radius 10 --soil clayey_soil_thailand_38 --set model.lateral_law=LAW "
       "--out DIR (DIR/modes.md)")
def linearization_modes() -> str:
    lagged, quasi = _modes("shear"), _modes("shear_quasistatic")
    n = {law: len(json.loads((run(f"symtrack linearize --speed 2 --radius 10 --soil clayey_soil_thailand_38 "
                                  f"--set model.lateral_law={law} --out DIR")[1] / "linearization.json")
                             .read_text())["state_names"]) for law in ("shear", "shear_quasistatic")}
    rows = [[reading, ", ".join(lagged.get(reading, [])) or "-", ", ".join(quasi.get(reading, [])) or "-"]
            for reading in dict.fromkeys([*lagged, *quasi])]
    return md(["mode (modes.md's reading)", f'lagged law `"shear"` ({n["shear"]} states)',
               f'quasi-static `"shear_quasistatic"` ({n["shear_quasistatic"]} states)'], rows)


@table("turn-rut", "turning.md", "python examples/turn_rut.py [--soil clayey_soil_thailand_38]")
def turn_rut() -> str:
    rows = []
    for soil, cmd in (("sandy_loam_15", "python examples/turn_rut.py"),
                      ("clayey_soil_thailand_38", "python examples/turn_rut.py --soil clayey_soil_thailand_38")):
        d = run_json(cmd)
        st = d["straight"]
        mean = {f: 0.5 * (st["left"][f] + st["right"][f]) for f in st["left"] if isinstance(st["left"][f], float)}
        rows.append([soil, "straight (each track)", f"{d['normal_load_straight_N']:.0f}", f"{mean['depth_mm']:.3f}",
                     "", "", f"{mean['area_mm_m']:.3f}", "", f"{mean['width_m']:.3f}", "",
                     f"{mean['load_cycles_mean']:.3g}"])
        for k, side in enumerate(("inner", "outer")):
            t = d["turn"][side]
            bekker = d.get("bekker_load_transfer_inner_outer")
            rows.append([soil, f"turn, {side}", f"{d['normal_load_inner_outer_N'][k]:.0f}", f"{t['depth_mm']:.3f}",
                         f"**{100 * d[f'{side}_vs_straight_depth_mm']:+.1f} %**",
                         f"{100 * bekker[k]:+.1f} %" if bekker else "",
                         f"{t['area_mm_m']:.3f}", f"**{100 * d[f'{side}_vs_straight_area_mm_m']:+.1f} %**",
                         f"{t['width_m']:.3f}", f"{100 * d[f'{side}_vs_straight_z_max_depth_mm']:+.1f} %",
                         f"{t['load_cycles_mean']:.4g}"])
    return md(["soil", "track", "normal load [N]", "rut depth [mm]", "vs straight",
               "Bekker (N_k / N_straight)^(1/n) - 1", "area [mm m]", "vs straight", "width [m]",
               "z_max depth vs straight", "load cycles"], rows)


LAW_RUNS = [  # (run, scenario, law, integrator label, options)
    ("validation", "validation", "shear_quasistatic", "Rosenbrock 10 ms", "--integrator rosenbrock"),
    ("validation", "validation", "shear_quasistatic", "Rosenbrock 0.5 ms",
     "--integrator rosenbrock --set run.fixed_step_s=0.0005"),
    ("validation", "validation", "shear_quasistatic", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("validation", "validation", "shear", "Rosenbrock 10 ms", "--integrator rosenbrock"),
    ("validation", "validation", "shear", "Rosenbrock 1 ms", "--integrator rosenbrock --set run.fixed_step_s=0.001"),
    ("validation", "validation", "shear", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("validation_grid", "validation_grid", "shear", "engine 10 ms", ""),
    ("validation_grid", "validation_grid", "shear", "IDAS (reltol 1e-5, abstol 1e-8)", "--integrator idas"),
    ("turn, sandy loam", "examples/scenarios/turn_sandy_loam.toml", "shear_quasistatic", "Rosenbrock 10 ms",
     "--integrator rosenbrock"),
    ("turn, sandy loam", "examples/scenarios/turn_sandy_loam.toml", "shear_quasistatic", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("turn, sandy loam", "examples/scenarios/turn_sandy_loam.toml", "shear", "Rosenbrock 10 ms",
     "--integrator rosenbrock"),
    ("turn, sandy loam", "examples/scenarios/turn_sandy_loam.toml", "shear", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("spin, sandy loam", "examples/scenarios/sharp_turn_sandy_loam.toml", "shear_quasistatic", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("spin, sandy loam", "examples/scenarios/sharp_turn_sandy_loam.toml", "shear", "Rosenbrock 10 ms",
     "--integrator rosenbrock"),
    ("spin, sandy loam", "examples/scenarios/sharp_turn_sandy_loam.toml", "shear", "CVODES 1e-10",
     "--integrator cvodes --set run.reltol=1e-10 --set run.abstol=1e-12"),
    ("spin, grid", "examples/scenarios/sharp_turn_sandy_loam_grid.toml", "shear", "engine 10 ms", ""),
]


def _end_xy(folder: Path) -> tuple[float, float]:
    """The CG's last position in a run's trajectory.csv (a grid run's: its pass's)."""
    path = folder / "trajectory.csv"
    if not path.is_file():
        path = sorted(folder.glob("pass_*/trajectory.csv"))[-1]
    with path.open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return float(rows[-1]["x_m"]), float(rows[-1]["y_m"])


@table("lateral-laws", "turning.md", "symtrack simulate SCENARIO --set model.lateral_law=LAW --out DIR "
       "[--integrator ...] (each row's)")
def lateral_laws() -> str:
    rows = []
    for label, scenario, law, integ, opts in LAW_RUNS:
        cmd = f"symtrack simulate {scenario} --set model.lateral_law={law} {opts} --out DIR --quiet"
        s = summary(cmd, ok=(0, 1))
        if not s.get("complete", False):
            err = str(s.get("error", s.get("stopped_by", "incomplete"))).split("\n")[0]
            rows.append([label, law, integ, f"**no**: {err}", "", "", ""])
            continue
        done = "yes"
        if s.get("fixed_step_error_max", 0) > 1:
            done = (f"yes, flagged: a step kept at {s['fixed_step_error_max']:.0f} x its tolerance "
                    f"({s['fixed_step_steps_halved']} steps halved)")
        x, y = _end_xy(run(cmd, ok=(0, 1))[1])
        rows.append([label, law, integ, done, f"{s['yaw_final_deg']:.6g}", f"{s['lateral_deviation_m']:.6g}",
                     f"{x:.4f}, {y:.4f}"])
    return md(["run", "law", "integrator", "complete", "yaw [deg]", "lateral [m]", "end X, Y [m]"], rows)


HULL_ROWS = (("clayey_soil_thailand_38", "3", "3"), ("clayey_soil_thailand_38", "10", "2"),
             ("clayey_soil_thailand_38", "50", "1"), ("sandy_loam_15", "10", "3"), ("sandy_loam_15", "20", "3"),
             ("sandy_loam_15", "50", "1"))


@table("hull-rotation", "turning.md", "python examples/hull_rotation.py --radii 3 5 10 20 50 100 --speeds 1 2 3 "
       "(the rows named in the text)")
def hull_rotation() -> str:
    out, _ = run("python examples/hull_rotation.py --radii 3 5 10 20 50 100 --speeds 1 2 3")
    lines = md_tables(out)[0].splitlines()
    keep = [ln for ln in lines[2:] if tuple(c.strip() for c in ln.strip("|").split("|")[:3]) in HULL_ROWS]
    return "\n".join(lines[:2] + keep)


# ---------------------------------------------------------------------------------------------------------
# docs/terrain.md

MEMORY_PROBE = (Path(__file__).resolve().parent.parent / "examples" / "scenarios" / "memory_probe.toml").read_text()

def _peak(args: list[str], label: str) -> tuple[float, float]:
    """(the run's own estimate, its process's peak resident set), MB, of `symtrack simulate ARGS --out DIR`."""
    from symtrack.bench.memory import simulate_peak

    out = WORK / f"mem{len(_ELAPSED)}"
    t0 = time.perf_counter()
    estimate, peak = simulate_peak(args, out, cwd=ROOT)
    _ELAPSED[label] = time.perf_counter() - t0
    _USED.append(label)
    shutil.rmtree(out, ignore_errors=True)
    return estimate / 1e6, peak / 1e6


@table("memory-peaks", "terrain.md", "symtrack simulate PROBE --set terrain.size_m=[S, S] [--set terrain.passes=3] "
       "[--terrain-in FILE] --out DIR, its process's VmHWM (docs/figures.py)")
def memory_peaks() -> str:
    from symtrack.presets import soil_preset
    from symtrack.terrain import storage as persist
    from symtrack.terrain.storage import Grid, Terrain

    probe = WORK / "memory_probe.toml"
    probe.write_text(MEMORY_PROBE)
    rows = []

    def row(cells, what, args, label):
        est, peak = _peak(args, label)
        rows.append([cells, what, f"{est:.1f} MB", f"{peak:.1f} MB", f"{est / peak:.2f}"])

    def side(cells):
        return (cells / 100) ** 0.5

    for cells in (1e4, 1e5, 1e6, 3e6):
        row(f"{cells:.0e}".replace("e+0", "e"), "new",
            [str(probe), "--set", f"terrain.size_m=[{side(cells)},{side(cells)}]"], f"memory {cells:.0e}")
    row("1e6", "new, 3 passes", [str(probe), "--set", "terrain.size_m=[100.0,100.0]", "--set", "terrain.passes=3"],
        "memory 1e6 x3")
    for cells in (1e6, 3e6):
        n = int(round(side(cells) * 10))
        field = WORK / f"field{n}.npz"
        persist.save(field, Terrain(Grid((-n / 20, -n / 20), 0.1, (n, n)), None, (0.1, 0.3, 0.5, 0.8)),
                     soil_preset("clayey_soil_thailand_38"))
        row(f"{cells:.0e}".replace("e+0", "e"), "continued",
            [_probe_without_size(probe), "--terrain-in", str(field), "--terrain-out", str(field)],
            f"memory {cells:.0e} continued")
        field.unlink()
    row("1e6", "`validation_grid` (20 m)", ["validation_grid"], "memory validation_grid")
    return md(["cells", "field", "estimate", "peak", "estimate / peak"], rows)


def _probe_without_size(probe: Path) -> str:
    p = probe.with_name("memory_probe_file.toml")
    p.write_text(MEMORY_PROBE.replace("size_m = [10.0, 10.0]\n", ""))
    return str(p)


@table("multipass-deepening", "terrain.md", "symtrack simulate multipass --out DIR (its summary's passes)")
def multipass_deepening() -> str:
    from symtrack.presets import soil_preset

    s = summary("symtrack simulate multipass --out DIR --quiet")
    beta = soil_preset("clayey_soil_thailand_38")["repeated_loading_exponent"]
    first = s["passes"][0]["new_sinkage_mean_mm"]
    rows = []
    for k, p in enumerate(s["passes"], start=1):
        new = p["new_sinkage_mean_mm"]
        rows.append([k, f"{new:.4f}", f"{100 * new / first:.1f} %", f"{100 * (k ** beta - (k - 1) ** beta):.1f} %",
                     f"{p['rut_mean_depth_mm']:.3f}", f"{p['rut_max_depth_mm']:.3f}"])
    return md(["pass", "new sinkage, mean [mm]", "of pass 1's", f"closed form k^beta - (k-1)^beta (beta = {beta:g})",
               "rut mean after it [mm]", "rut max [mm]"], rows)


GRID_FIGURES = (("distance after idle (m)", "distance_after_idle_m"), ("lateral deviation (m)", "lateral_deviation_m"),
                ("yaw final (deg)", "yaw_final_deg"), ("sinkage sprocket (mm)", "sinkage_sprocket_mm"),
                ("sinkage idler (mm)", "sinkage_idler_mm"), ("shear driven max (m)", "shear_driven_max_m"),
                ("shear idle min (m)", "shear_idle_min_m"), ("rut max depth (mm)", "rut_max_depth_mm"),
                ("rut mean depth (mm)", "rut_mean_depth_mm"),
                ("compaction resistance, distance mean (N)", "compaction_resistance_mean_N"),
                ("compaction resistance, time mean (N)", "compaction_resistance_time_mean_N"))
VG_IDAS = "symtrack simulate validation_grid --integrator idas --out DIR --quiet"


@table("grid-rosenbrock", "terrain.md", "symtrack simulate validation_grid --integrator idas|rosenbrock "
       "[--set run.fixed_step_tolerance=0 | --set run.fixed_step_s=0.0003125] --out DIR")
def grid_rosenbrock() -> str:
    ref = summary(VG_IDAS)
    rb = summary("symtrack simulate validation_grid --integrator rosenbrock --out DIR --quiet")
    off = summary("symtrack simulate validation_grid --integrator rosenbrock --set run.fixed_step_tolerance=0 "
                  "--out DIR --quiet")
    rb2 = summary("symtrack simulate validation_grid --integrator rosenbrock --set run.fixed_step_s=0.0003125 "
                  "--out DIR --quiet")
    runs = (rb, off, rb2)
    rows = [[label, f"{ref[k]:.6g}", *(f"{r[k]:.6g} ({pct(r[k], ref[k])})" for r in runs)]
            for label, k in GRID_FIGURES if k in ref]
    rows += [["error estimate, largest kept (x tolerance)", "-", *(f"{r['fixed_step_error_max']:.3g}" for r in runs)],
             ["steps halved by the error control", "-", *(f"{r['fixed_step_steps_halved']:d}" for r in runs)]]
    return md(["figure", "IDAS", "rosenbrock 0.625 ms", "0.625 ms, error control off", "rosenbrock 0.3125 ms"], rows)


@table("engine-accuracy", "terrain.md", "symtrack simulate validation_grid [--integrator idas] --out DIR")
def engine_accuracy() -> str:
    ref = summary(VG_IDAS)
    eng = summary("symtrack simulate validation_grid --out DIR --quiet")
    rows = [[label, f"{ref[k]:.6g}", f"{eng[k]:.6g}", pct(eng[k], ref[k])] for label, k in GRID_FIGURES if k in ref]
    return md(["figure", "IDAS", "engine", "difference"], rows)


# ---------------------------------------------------------------------------------------------------------
# docs/vehicle3d.md

@table("flat-ground-3d", "vehicle3d.md", "symtrack simulate validation [--set model.vehicle=3d "
       "[--set model.contact_segments=16]] --out DIR")
def flat_ground_3d() -> str:
    runs = [summary("symtrack simulate validation --out DIR --quiet"),
            summary("symtrack simulate validation --set model.vehicle=3d --out DIR --quiet"),
            summary("symtrack simulate validation --set model.vehicle=3d --set model.contact_segments=16 "
                    "--out DIR --quiet")]
    figs = (("lateral deviation [m]", "lateral_deviation_m", 1, True), ("yaw [deg]", "yaw_final_deg", 1, True),
            ("distance [m]", "distance_m", 1, False), ("final speed [m/s]", "speed_final_m_s", 1, False),
            ("idler sinkage [mm]", "sinkage_idler_mm", 1, False),
            ("sprocket sinkage [mm]", "sinkage_sprocket_mm", 1, True),
            ("driven shear, max [mm]", "shear_driven_max_m", 1e3, True),
            ("idle shear, min [mm]", "shear_idle_min_m", 1e3, True),
            *((f"subsoil stress {z:g} m [kPa]", ("subsoil_sigma_z_max_kPa", i), 1, True)
              for i, z in enumerate(runs[0]["subsoil_depths_m"])),
            ("column compression [mm]", "column_compression_mm", 1, True))
    rows = []
    for label, key, scale, rel in figs:
        def get(s, key=key):
            return s[key[0]][key[1]] if isinstance(key, tuple) else s[key]
        if any(get(s) is None for s in runs):
            continue
        ref = get(runs[0]) * scale
        cells = [f"{ref:.5g}"]
        for s in runs[1:]:
            v = get(s) * scale
            cells.append(f"{v:.5g} ({100 * (v / ref - 1):+.2f} %)" if rel else f"{v:.5g}")
        rows.append([label, *cells])
    return md(["figure", "planar", "3D, 8 segments", "3D, 16"], rows)


@table("side-slope-3d", "vehicle3d.md", "python examples/side_slope_3d.py")
def side_slope_3d() -> str:
    d = run_json("python examples/side_slope_3d.py")
    rows = []
    for name, r in d.items():
        p0, p1 = r["pitch_deg_range"]
        rows.append([name, f"{r['distance_m']:.1f} m", f"{r['drift_y_m']:.3f} m", f"{r['roll_deg_final']:.2f} deg",
                     f"{p0:.1f} .. {p1:.1f} deg", f"{100 * r['load_share_right_final']:.1f} %",
                     f"{r['sinkage_sprocket_right_mm']:.2f} / {r['sinkage_sprocket_left_mm']:.2f} mm"])
    return md(["run (8 s, 1500 N m a sprocket)", "distance", "drift in y", "roll at the end", "pitch range",
               "lower (right) track's share of W at the end", "sprocket sinkage right / left at the end"], rows)


@table("mpc-side-slope-3d", "vehicle3d.md", "python examples/mpc_side_slope_3d.py --slope-deg 8")
def mpc_side_slope_3d() -> str:
    d = run_json("python examples/mpc_side_slope_3d.py --slope-deg 8")
    return md(["figure", "the MPC (RTI)", "open loop (the start's trim torques held)"], [
        ["distance, time", f"{d['distance_m']:.1f} m, {d['time_s']:.1f} s", f"{d['open_loop_distance_m']:.1f} m"],
        ["failed solves / solves (fallbacks)", f"{d['failed_solves']} / {d['solves']} ({d['fallback_solves']})", ""],
        ["lateral error: RMS / max", f"{1e3 * d['rms_lateral_error_m']:.2f} / {1e3 * d['max_lateral_error_m']:.2f} mm",
         f"drift downhill {d['open_loop_drift_downhill_m']:.3f} m"],
        ["last half: normal load lower (right) / upper (left) track",
         f"{d['normal_load_right_last_half_N'] / 1e3:.2f} / {d['normal_load_left_last_half_N'] / 1e3:.2f} kN", ""],
        ["last half: roll", f"{d['roll_last_half_deg']:.3f} deg", ""],
        ["last half: torque lower (right) / upper (left) sprocket",
         f"{d['torque_right_last_half_N_m']:+.0f} / {d['torque_left_last_half_N_m']:+.0f} N m", ""]])


GRID3D_FIGURES = (("distance [m]", "distance_m"), ("lateral deviation [m]", "lateral_deviation_m"),
                  ("yaw [deg]", "yaw_final_deg"), ("final speed [m/s]", "speed_final_m_s"),
                  ("driven shear, max [m]", "shear_driven_max_m"), ("idle shear, min [m]", "shear_idle_min_m"),
                  ("idler sinkage [mm]", "sinkage_idler_mm"), ("sprocket sinkage [mm]", "sinkage_sprocket_mm"))


@table("grid-3d", "vehicle3d.md", "symtrack simulate validation|validation_grid --set model.vehicle=3d "
       "[--set terrain.surface.slope_y_deg=5] --out DIR")
def grid_3d() -> str:
    runs = {}
    for slope in ("", " --set terrain.surface.slope_y_deg=5"):
        for name in ("validation", "validation_grid"):
            runs[name, slope] = summary(f"symtrack simulate {name} --set model.vehicle=3d{slope} --out DIR --quiet")
    rows = []
    for label, k in GRID3D_FIGURES:
        cells = [label]
        for slope in ("", " --set terrain.surface.slope_y_deg=5"):
            h, g = runs["validation", slope][k], runs["validation_grid", slope][k]
            cells += [f"{h:.6g}", f"{g:.6g}", pct(g, h, 2)]
        rows.append(cells)
    return md(["figure", "homogeneous 3D", "grid 3D", "difference", "5 deg side slope: homogeneous", "grid",
               "difference"], rows)


HILL_TOML = """name = "hill"
description = "The 3D crawler past a Gaussian hill on an elevation raster"

[run]
duration_s = 6.0
integrator = "cvodes"

[vehicle]
preset = "reference_crawler"

[soil]
preset = "clayey_soil_thailand_38"

[model]
vehicle = "3d"
lateral_law = "creep"

[terrain.surface]
elevation_file = "hill.npy"
elevation_cell_m = 0.1
elevation_origin_m = [-4.0, -5.0]

[[torque]]
t_s = 0.0
left_N_m = 1500.0
right_N_m = 1500.0
"""
HILL_RUNS = (("CVODES, reltol 1e-6 (the file's)", ""), ("CVODES, reltol 1e-8", " --set run.reltol=1e-8"),
             ("rosenbrock, 10 ms, its error control off", " --integrator rosenbrock --set run.fixed_step_tolerance=0"),
             ("rosenbrock, 10 ms (its default: the error control on)", " --integrator rosenbrock"),
             ("rosenbrock, 5 ms", " --integrator rosenbrock --set run.fixed_step_s=0.005"),
             ("rosenbrock, 2.5 ms", " --integrator rosenbrock --set run.fixed_step_s=0.0025"))


@table("hill-raster", "vehicle3d.md", "symtrack simulate hill.toml [--integrator rosenbrock] [--set ...] --out DIR "
       "(the page's hill.npy and hill.toml; each row's options)")
def hill_raster() -> str:
    import numpy as np

    WORK.mkdir(parents=True, exist_ok=True)
    folder = WORK / "hill"
    folder.mkdir(exist_ok=True)
    px, (x0, y0), (nx, ny) = 0.1, (-4.0, -5.0), (300, 100)  # as the page writes it
    X, Y = np.meshgrid(x0 + (np.arange(nx) + 0.5) * px, y0 + (np.arange(ny) + 0.5) * px, indexing="ij")
    np.save(folder / "hill.npy", 0.3 * np.exp(-((X - 10) ** 2 + (Y - 1.0) ** 2) / (2 * 2.0**2)))
    (folder / "hill.toml").write_text(HILL_TOML, encoding="utf-8")
    rows = []
    for label, opts in HILL_RUNS:
        s = summary(f"symtrack simulate {folder / 'hill.toml'}{opts} --out DIR --quiet")
        rows.append([label, f"{s['distance_m']:.2f} m", f"{s['speed_final_m_s']:.2f} m/s",
                     f"{s['lateral_deviation_m']:.4f} m", f"{s['yaw_final_deg']:.3f} deg",
                     f"{s['sinkage_sprocket_mm']:.1f} / {s['sinkage_idler_mm']:.1f} mm",
                     str(s.get("fixed_step_steps_halved", "")) if "rosenbrock" in opts else ""])
    return md(["integrator", "distance", "final speed", "lateral deviation", "yaw", "largest sinkage sprocket / idler",
               "steps halved"], rows)


@table("ramp-3d", "vehicle3d.md", "python examples/ramp_3d.py")
def ramp_3d() -> str:
    d = run_json("python examples/ramp_3d.py")
    hold, c, s = d["holding_torque_N_m"], d["climb"], d["descent"]

    def col(r):
        return [f"{r['distance_along_slope_m']:.2f} m, {r['speed_final_m_s']:.3f} m/s at the end",
                f"{r['cg_rise_m']:.6f} / {r['cg_rise_geometry_m']:.6f} m ({r['cg_rise_error_rel']:+.1e})",
                f"{r['pitch_mean_deg']:.4f} / {r['pitch_expected_deg']:.4f} deg",
                f"{r['normal_load_sum_over_W_cos_t']:.7f}",
                f"{r['p_idler_kPa']:.1f} / {r['p_sprocket_kPa']:.1f} kPa",
                f"{r['sinkage_idler_mm']:.3f} / {r['sinkage_sprocket_mm']:.3f} mm"]
    labels = ["distance along the slope", "CG rise after the first second / s sin t",
              "pitch (mean of the last 2 s) / the ramp's + the ends' sinkage difference over l",
              "normal loads / W cos t (mean of the last 2 s)", "idler / sprocket pressure (mean)",
              "idler / sprocket sinkage"]
    return md([f"{abs(c['slope_deg']):g} deg, 8 s", f"climb (1.4 x holding: {1.4 * hold:.0f} N m)",
               f"descent (braked: -0.75 x holding, {-0.75 * hold:.0f} N m)"],
              [[lab, a, b] for lab, a, b in zip(labels, col(c), col(s), strict=True)])


@table("furrows-across", "vehicle3d.md", "python examples/furrows_3d.py")
def furrows_across() -> str:
    d = run_json("python examples/furrows_3d.py")
    rows = []
    for r in d["across"]:
        q, ref = r["pitch_range_deg"], r["rigid_ground_pitch_range_deg"]
        flat = max(abs(v) for v in ref) < 1e-6
        ratio = 1 / r["spacing_over_contact_length"]
        rows.append([f"{r['spacing_m']:g} m", f"{ratio:g}" if ratio >= 1 else f"1/{1 / ratio:g}",
                     f"{q[0]:.1f} .. {q[1]:.1f} deg", "0" if flat else f"{ref[0]:.1f} .. {ref[1]:.1f} deg",
                     f"{r['pitch_rms_difference_deg']:.2g} deg", f"{r['pitch_wavelength_m']:.2f} m",
                     f"{r['sinkage_sprocket_max_mm']:.0f} mm",
                     f"{r['distance_m']:.1f} m, {r['speed_final_m_s']:.1f} m/s",
                     "complete" if not r.get("stopped") else
                     f"stopped at {r['time_s']:.2f} s" + (": turned over" if "turned over" in r["stopped"] else "")])
    return md(["spacing", "l / spacing", "pitch range", "rigid ground", "RMS difference", "pitch's wavelength",
               "largest sprocket penetration", "distance, end speed", "run"], rows)


@table("furrows-along", "vehicle3d.md", "python examples/furrows_3d.py")
def furrows_along() -> str:
    d = run_json("python examples/furrows_3d.py")
    a, b = d["along"]

    def col(r):
        change, closed = (1e3 * (r["offset_end_m"] - r["offset_start_m"]),
                          1e3 * (r["offset_end_creep_closed_form_m"] - r["offset_start_m"]))
        return [f"{r['roll_max_abs_deg']:.0e} deg, {r['pitch_max_abs_deg']:.3f} deg",
                f"{r['lower_share_mean']:.4f}", f"{r['normal_load_sum_over_W']:.4f}",
                f"{r['sinkage_sprocket_left_mm']:.4f}, {r['sinkage_sprocket_right_mm']:.4f} mm",
                f"{1e3 * r['offset_start_m']:.1f} -> {1e3 * r['offset_end_m']:.2f} mm",
                f"{1e3 * r['offset_end_creep_closed_form_m']:.2f} mm (change {change:+.2f} against {closed:+.2f}: "
                f"{100 * (change / closed - 1):+.0f} %)",
                f"{r['cg_height_end_m']:.5f} m"]
    labels = ["roll, pitch (largest)", "lower track's share", "normal loads / W", "sprocket sinkage (left, right)",
              "offset from the line: start -> end", "the creep law's closed form", "CG height at the end"]
    return md([f"along, 8 s ({a['distance_m']:.0f} m)", f"{a['tracks']} (start y = {a['start_y_m']:g} m)",
               f"{b['tracks']} (start y = {b['start_y_m']:g} m)"],
              [[lab, x, y] for lab, x, y in zip(labels, col(a), col(b), strict=True)])


FURROWS_CONVERGENCE = "python examples/furrows_3d.py --convergence 8 16 32 64 --spacings 9.6 --torque 2000"
FURROWS_CONVERGENCE_SOFT = FURROWS_CONVERGENCE + " --soil elastic_stiffness_Pa_per_m=4e6 unloading_stiffness_floor=1"


def _furrows_convergence(command: str) -> str:
    rows = [[r["segments"], f"{r['speed_final_m_s']:.2f} m/s",
             f"{r['normal_load_over_W'][0]:.2f} .. {r['normal_load_over_W'][1]:.2f}",
             f"{r['heave_rate_max_m_s']:.2f} m/s", f"{r['compaction_resistance_mean_N']:.0f} N",
             f"{r['cpu_time_s']:.1f} s"] for r in run_json(command)["convergence"]]
    return md(["segments", "speed at 8 s", "total normal load / W", "largest heave rate",
               "compaction resistance (mean)", "CPU"], rows)


@table("furrows-convergence", "vehicle3d.md", FURROWS_CONVERGENCE)
def furrows_convergence() -> str:
    return _furrows_convergence(FURROWS_CONVERGENCE)


@table("furrows-convergence-soft", "vehicle3d.md", FURROWS_CONVERGENCE_SOFT)
def furrows_convergence_soft() -> str:
    return _furrows_convergence(FURROWS_CONVERGENCE_SOFT)


@table("second-pass-3d", "vehicle3d.md", "python examples/second_pass_3d.py")
def second_pass_3d() -> str:
    d = run_json("python examples/second_pass_3d.py")
    x0, x1 = d["x_window_m"]
    return md([f"x = {x0:.1f} ... {x1:.1f} m", "pass 1", "pass 2"], [
        ["rut (mean / max) after the pass",
         f"{d['rut_after_pass_1_mean_mm']:.3f} / {d['rut_after_pass_1_max_mm']:.3f} mm",
         f"new sinkage {d['new_sinkage_pass_2_mean_mm']:.3f} mm (deepening {100 * d['deepening']:.1f} % against the "
         f"cycle law's 2^beta - 1 = {100 * d['deepening_closed_form']:.1f} %)"],
        ["the hull's height", "(reference)", f"{d['hull_drop_mm'][0]:.3f} to {d['hull_drop_mm'][1]:.3f} mm lower"],
        ["pitch (mean)", f"{d['pitch_pass_1_mrad']:.3f} mrad", f"{d['pitch_pass_2_mrad']:.3f} mrad"],
        ["compaction resistance", f"{d['compaction_resistance_pass_1_N']:.1f} N",
         f"{d['compaction_resistance_pass_2_N']:.1f} N"]])


# ---------------------------------------------------------------------------------------------------------
# docs/subsoil.md: the figures of the package's functions (computed here, in this process)

@table("stress-table-memory", "subsoil.md",
       "symtrack.soil.subsoil.build_tables(xi=XI) for the reference crawler (docs/figures.py)")
def stress_table_memory() -> str:
    from symtrack.soil import subsoil

    rows = []
    with _timed("build_tables"):
        for xi in (3, 4, 5, 6):
            T = subsoil.build_tables(xi=float(xi))
            nodes = ", ".join(f"{nx}x{nt}" for nx, nt in zip(T.n_x, T.n_t, strict=True))
            rows.append([xi, f"{T.nbytes / 1024:.0f} KiB", nodes])
    depths = " / ".join(f"{d:g}" for d in subsoil.DEFAULT_DEPTHS_M)
    return md(["xi", "memory", f"nodes (n_x x n_t) at {depths} m"], rows)


@table("rigid-base", "subsoil.md",
       "symtrack.vehicles.tyre.footprint_stress_at_depth(..., 3.0, rigid_base_depth_m=h, rigid_base_interface=...) "
       "of a uniform circle, a = 0.3 m (docs/figures.py)")
def rigid_base() -> str:
    from symtrack.soil.rigid_base import disc_point_forces
    from symtrack.vehicles import tyre

    q, a = 100.0, 0.3
    x, y, F = disc_point_forces(q, a)
    rows = []
    with _timed("rigid base"):
        for h_over_a, fracs in ((1.0, (0.5, 1.0)), (2.0, (1.0,))):
            H = h_over_a * a
            depths = tuple(f * H * (1 - 1e-9) for f in fracs)
            half = tyre.footprint_stress_at_depth(x, y, F, [0.0], [0.0], depths, 3.0)[0][0]
            rough = tyre.footprint_stress_at_depth(x, y, F, [0.0], [0.0], depths, 3.0, rigid_base_depth_m=H)[0][0]
            smooth = tyre.footprint_stress_at_depth(x, y, F, [0.0], [0.0], depths, 3.0, rigid_base_depth_m=H,
                                                    rigid_base_interface="smooth")[0][0]
            for k, f in enumerate(fracs):
                rows.append([f"{h_over_a:g}", "h" if f == 1.0 else f"{f:g} h", f"{half[k] / q:.3f} q",
                             f"{rough[k] / q:.3f} q", f"{smooth[k] / q:.3f} q"])
    return md(["h / a", "depth", "half-space", "rough base", "smooth base"], rows)


@table("rigid-base-dip", "subsoil.md",
       "symtrack.soil.subsoil.stress_bruteforce(..., xi, rigid_base_depth_m=0.7) beside one track unit (1.9 x 0.635 m, "
       "uniform pressure q), 0.4 to 3 m from its centre line (docs/figures.py)")
def rigid_base_dip() -> str:
    import numpy as np

    from symtrack.soil import subsoil

    length, width, q, base = 1.9, 0.635, 100e3, 0.7
    geo = (length, width, width, 0.0, 0.1, 0.0)  # the left track alone is loaded: its centre line at y = width / 2
    a = np.array([0.0, 0.0, 1.0, 0.0, q, 0.0, 0.0, 0.0])
    side = np.arange(0.4, 3.0 + 1e-9, 0.05)
    depths = (0.35, 0.6, base)
    rows = []
    with _timed("rigid base dip"):
        for xi in (3.0, 5.0):
            cells = []
            for z in depths:
                sz = subsoil.stress_bruteforce(np.zeros_like(side), width / 2 + side, a, geo, min(z, base * (1 - 1e-9)),
                                               xi, rigid_base_depth_m=base) / q
                i = int(np.argmin(sz))
                cells.append(f"{sz[i]:+.4f} q at {side[i]:.2f} m" if sz[i] < 0 else f"none (least {sz[i]:.4f} q)")
            rows.append([f"{xi:g}", *cells])
    return md(["xi", *(f"depth {z:g} m" + (" (the base)" if z == base else "") for z in depths)], rows)


SOILFLEX_PRINTED = {"sigma_max": "289", "area": "0.29 / 0.83", "sigma_z": "275 / 262 / 154 / 85 / 51 / 28",
                    "p": "169 / 132 / 62 / 31 / 18 / 10"}  # soilphysics' README, its worked stressTraffic example


@table("soilflex", "subsoil.md",
       "symtrack.vehicles.tyre.contact and tyre.footprint_stress_at_depth below the tyre's centre (docs/figures.py)")
def soilflex() -> str:
    from symtrack.vehicles import tyre

    with _timed("soilflex"):
        W = 4000 * 9.81 / 1e3
        c = tyre.contact(tyre.Tyre(0.4, 1.8, W, 200.0), W, 200.0)
        depths, xis = (0.05, 0.1, 0.3, 0.5, 0.7, 1.0), (4, 5, 5, 5, 5, 5)
        sz, pm = [], []
        for d, xi in zip(depths, xis, strict=True):
            s, p = tyre.footprint_stress_at_depth(c.x_m, c.y_m, c.force_kN, [0.0], [0.0], [d], xi)
            sz.append(float(s[0, 0]))
            pm.append(float(p[0, 0]))
    dl = " / ".join(f"{d:g}" for d in depths)
    return md(["", "soilphysics (printed, rounded)", "ours"], [
        ["max contact stress [kPa]", SOILFLEX_PRINTED["sigma_max"], f"{c.sigma_max_kPa:.2f}"],
        ["contact area [m^2] / length [m]", SOILFLEX_PRINTED["area"], f"{c.area_m2:.4f} / {c.length_m:.4f}"],
        [f"sigma_z {dl} m [kPa]", SOILFLEX_PRINTED["sigma_z"], " / ".join(f"{v:.1f}" for v in sz)],
        ["p (mean normal) at the same depths [kPa]", SOILFLEX_PRINTED["p"], " / ".join(f"{v:.1f}" for v in pm)]])


@table("arvidsson-keller-2007", "subsoil.md", "symtrack.vehicles.tyre.arvidsson_keller_2007() (docs/figures.py)")
def arvidsson_keller_2007() -> str:
    import numpy as np

    from symtrack.vehicles import tyre

    with _timed("arvidsson keller 2007"):
        r = tyre.arvidsson_keller_2007()
    dl = " / ".join(f"{d:g}" for d in r.depths_m)
    rows, ratios = [], []
    for W, (b, D) in r.tyres.items():
        lo, hi = r.peak_kPa[W, 100.0], r.peak_kPa[W, 150.0]
        ratios.append(lo[0] / 100.0)
        rows.append([f"{W:g}", f"{b:g} x {D:g}", f"{lo[0] / 100.0:.2f}", " / ".join(f"{v:.1f}" for v in lo),
                     " / ".join(f"{100 * (h / v - 1):+.0f} %" for h, v in zip(hi, lo, strict=True))])
    rows.append(["mean", "", f"**{np.mean(ratios):.2f}** (measured: 1.39)", "", ""])
    return md(["wheel load [kN]", "tyre (ASSUMED) width x diameter [m]", f"peak at {r.depths_m[0]:g} m / 100 kPa",
               f"peak at {dl} m at 100 kPa [kPa]", "100 -> 150 kPa: the peak's change at the same depths"], rows)


@table("arvidsson-2011", "subsoil.md", "symtrack.vehicles.tyre.arvidsson_2011() (docs/figures.py)")
def arvidsson_2011() -> str:
    from symtrack.vehicles import tyre

    with _timed("arvidsson 2011"):
        r = tyre.arvidsson_2011()
    rows = [["single", f"{r.single_inflation_kPa:.1f} (inflation)", *(f"{v:.1f}" for v in r.single_kPa)],
            ["duals", f"{r.duals_inflation_kPa:.1f} (inflation)", *(f"{v:.1f}" for v in r.duals_kPa)],
            ["tracks", f"{r.track_pressure_kPa:.1f} (uniform)", *(f"{v:.1f}" for v in r.tracks_kPa)],
            ["tracks / duals", "", *(f"{t / d:.2f}" for t, d in zip(r.tracks_kPa, r.duals_kPa, strict=True))]]
    return md(["", "pressure [kPa]", *(f"{d:g} m" for d in r.depths_m)], rows)


@table("one-soil", "subsoil.md", "python examples/one_soil.py --passes 0")
def one_soil() -> str:
    out, _ = run("python examples/one_soil.py --passes 0")
    return md_tables(out)[0]


@table("one-soil-passes", "subsoil.md", 'python examples/one_soil.py --presets "" --passes 10 --soil sandy_loam_15')
def one_soil_passes() -> str:
    out, _ = run('python examples/one_soil.py --presets "" --passes 10 --soil sandy_loam_15')
    return md_tables(out)[0]


def _density_tables() -> list[str]:
    out, _ = run("python examples/density_passes.py")
    return md_tables(out)


@table("density-multipass", "subsoil.md", "python examples/density_passes.py (its first table)")
def density_multipass() -> str:
    return _density_tables()[0]


@table("density-cart", "subsoil.md", "python examples/density_passes.py (its second table)")
def density_cart() -> str:
    return _density_tables()[1]


@table("density-botta", "subsoil.md", "python examples/density_passes.py (its third table)")
def density_botta() -> str:
    return _density_tables()[2]


def _by_pass(values: list[list[float]]) -> list[tuple[str, list[float]]]:
    """Consecutive passes whose figures agree to the table's digits, as one row ("1", "2, 3", "1-3")."""
    groups: list[tuple[list[int], list[float]]] = []
    for k, v in enumerate(values, start=1):
        if groups and [f"{a:.4f}" for a in groups[-1][1]] == [f"{a:.4f}" for a in v]:
            groups[-1][0].append(k)
        else:
            groups.append(([k], v))
    label = {1: lambda p: str(p[0]), 2: lambda p: f"{p[0]}, {p[1]}"}
    return [(label.get(len(p), lambda p: f"{p[0]}-{p[-1]}")(p), v) for p, v in groups]


@table("moisture-days", "subsoil.md", "python examples/compaction_day_and_machine.py")
def moisture_days() -> str:
    d = run_json("python examples/compaction_day_and_machine.py")
    rows = []
    for day, v in d["days"].items():
        for passes, rho in _by_pass(v["bulk_density_max_Mg_per_m3_by_pass"]):
            rows.append([day, f"{v['water_content_kg_per_kg']:.2f}", f"{v['precompression_stress_kPa']:.0f}", passes,
                         *(f"{r:.4f}" for r in rho)])
    return md(["day", "w [kg/kg]", "sigma_pc (risk) [kPa]", "pass", *(f"{x:g} m" for x in d["depths_m"])], rows)


@table("crawler-tractor", "subsoil.md", "python examples/compaction_day_and_machine.py")
def crawler_tractor() -> str:
    d = run_json("python examples/compaction_day_and_machine.py")
    rows = []
    for what, key, f in (("sigma_z max [kPa]", "subsoil_sigma_z_max_kPa", "{:.1f}"),
                         ("bulk density max [Mg/m^3]", "bulk_density_max_Mg_per_m3", "{:.4f}")):
        for m in ("crawler", "tractor"):
            rows.append([m, what, *(f.format(v) for v in d[m][key])])
    return md(["machine", "", *(f"{x:g} m" for x in d["depths_m"])], rows)


@table("towed-cart", "subsoil.md", "symtrack simulate examples/scenarios/multipass_trailer.toml --out DIR")
def towed_cart() -> str:
    s = summary("symtrack simulate examples/scenarios/multipass_trailer.toml --out DIR --quiet")
    rows = []
    for k, p in enumerate(s["passes"], start=1):
        rows.append([k, "crawler", " / ".join(f"{v:.1f}" for v in p["subsoil_sigma_z_max_kPa"]),
                     " / ".join(f"{v:.4f}" for v in p["crawler_bulk_density_max_Mg_per_m3"])])
        rows.append([k, "cart", " / ".join(f"{v:.1f}" for v in p["towed_subsoil_sigma_z_max_kPa"]),
                     " / ".join(f"{v:.4f}" for v in p["towed_bulk_density_max_Mg_per_m3"])])
    dl = " / ".join(f"{x:g}" for x in s["subsoil_depths_m"])
    return md(["pass", "machine", f"sigma_z max {dl} m [kPa]", "field's bulk density max after it [Mg/m^3]"], rows)


@table("tracks-wheels", "subsoil.md", "python examples/tracks_against_wheels.py")
def tracks_wheels() -> str:
    d = run_json("python examples/tracks_against_wheels.py")
    rows = []
    for name, label in (("tracks", "tracks"), ("duals", "duals"), ("singles", "singles"),
                        ("singles_inflated_1_5", "singles at 1.5 x")):
        m = d[name]
        infl = (f"({m['mean_track_pressure_kPa']:.1f} mean)" if name == "tracks" else
                " / ".join(f"{v:.1f}" for v in m["inflation_kPa_front_rear"]))
        rows.append([label, infl, " / ".join(f"{v:.1f}" for v in m["subsoil_sigma_z_max_kPa"]),
                     " / ".join(f"{v:.3f}" for v in m["bulk_density_max_Mg_per_m3"])])

    def ratio(a, b):
        return " / ".join(f"{x / y:.2f}" for x, y in zip(d[a]["subsoil_sigma_z_max_kPa"],
                                                          d[b]["subsoil_sigma_z_max_kPa"], strict=True))
    sz0 = d["singles"]["subsoil_sigma_z_max_kPa"][0]
    rows += [["tracks / duals", "", ratio("tracks", "duals"), ""],
             ["tracks / singles", "", ratio("tracks", "singles"), ""],
             ["singles at 1.5 x / singles", "", ratio("singles_inflated_1_5", "singles"), ""],
             ["singles: sigma_z at the first depth / inflation front / rear", "",
              " / ".join(f"{sz0 / p:.2f}" for p in d["singles"]["inflation_kPa_front_rear"]), ""]]
    dl = " / ".join(f"{x:g}" for x in d["depths_m"])
    return md(["machine", "inflation front / rear [kPa]", f"sigma_z {dl} m", f"rho_b {dl} m"], rows)


# ---------------------------------------------------------------------------------------------------------
# docs/studies.md

@table("kroulik-seasons", "studies.md", "python examples/kroulik_seasons.py")
def kroulik_seasons() -> str:
    out, _ = run("python examples/kroulik_seasons.py")
    return md_tables(out)[0]


KROULIK_VARIANTS = (("as built (line offsets up to 0.5 m)", ""), ("line offsets 0", " --random-offset 0"),
                    ("line offsets up to 1.0 m", " --random-offset 1.0"),
                    ("ploughing and harvest across the field", " --across ploughing harvest"),
                    ("a 1 ha field (100 m x 100 m)", " --size 100 100"),
                    ("a 20 ha field (500 m x 400 m at 0.2 m cells)", " --size 500 400 --cell 0.2"))


@table("kroulik-sensitivity", "studies.md", "python examples/kroulik_seasons.py [--random-offset M] [--across ...] "
       "[--size X Y] [--cell C] (each row's)")
def kroulik_sensitivity() -> str:
    rows, systems = [], None
    for label, opts in KROULIK_VARIANTS:
        out, _ = run(f"python examples/kroulik_seasons.py{opts}")
        lines = md_tables(out)[0].splitlines()
        head = [c.strip() for c in lines[0].strip("|").split("|")]
        col = head.index("run over >= 1x")
        cells = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[2:]]
        systems = systems or [c[0] for c in cells]
        rows.append([label, *(c[col] for c in cells)])
    return md(["variant (`--` options of the example)", *(f"{name}: run over >= 1x" for name in systems)], rows)


def _thousands(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def _risk(p: dict, depths) -> str:
    """The field's share at medium / high risk by depth, or "low everywhere"."""
    parts = [f"{d:g} m: {100 * m:.2f} / {100 * h:.2f} %" for d, m, h in
             zip(depths, p["risk_fraction_of_field_medium"], p["risk_fraction_of_field_high"], strict=True) if m or h]
    return "low everywhere" if not parts else "medium / high " + ", ".join(parts)


@table("field-traffic", "studies.md", "symtrack field field_traffic --out DIR")
def field_traffic() -> str:
    s = summary("symtrack field field_traffic --out DIR --quiet")
    rows = []
    for p in s["patterns"].values():
        label = f"random (seed {p['seed']})" if "seed" in p else f"controlled ({p['lanes']} lanes)"
        depths = p["subsoil_depths_m"]
        rows.append([label, f"{100 * p['trafficked_area_fraction']:.2f} %",
                     " / ".join(_thousands(n) for n in p["passes_per_cell_histogram"]),
                     " / ".join(_thousands(n) for n in p["load_cycles_histogram"]),
                     f"{p['rut_mean_depth_mm']:.3f} / {p['rut_max_depth_mm']:.3f} mm",
                     " / ".join(f"{v:.1f}" for v in p["subsoil_sigma_z_max_kPa"]) + " kPa", _risk(p, depths)])
    d = " / ".join(f"{x:g}" for x in depths)
    return md(["pattern", "trafficked", "passes per cell (cells passed 0 / 1 / 2 ... times)",
               "load cycles (0 / 1 / 2 ...)", "rut mean / max", f"sigma_z max at {d} m", "risk"], rows)


@table("field-mass-sweep", "studies.md", "symtrack sweep field_traffic --vary vehicle.mass_kg=5500,11000,22000 --set "
       "field.passes=4 --set field.lanes=2 --out DIR --workers 2 (DIR/results.csv)")
def field_mass_sweep() -> str:
    _, folder = run("symtrack sweep field_traffic --vary vehicle.mass_kg=5500,11000,22000 --set field.passes=4 "
                    "--set field.lanes=2 --out DIR --workers 2")
    with (folder / "results.csv").open(encoding="utf-8") as f:
        results = list(csv.DictReader(f))
    depths = sorted({float(m.group(1)) for k in results[0] for m in [re.search(r"_at_([\d.]+)m$", k)] if m})
    rows = []
    for r in results:
        if r["status"] != "ok":
            raise RuntimeError(f"the sweep's run {r['run_id']} failed: {r['error']}")
        for pat in ("random", "controlled"):
            risk = [f"{100 * float(r[f'{pat}_risk_fraction_of_field_medium_at_{d:g}m']):.2f} / "
                    f"{100 * float(r[f'{pat}_risk_fraction_of_field_high_at_{d:g}m']):.2f}" for d in depths]
            rows.append([f"{float(r['vehicle.mass_kg']):.0f}", pat,
                         f"{100 * float(r[f'{pat}_trafficked_area_fraction']):.2f} %",
                         f"{float(r[f'{pat}_rut_mean_depth_mm']):.2f} / {float(r[f'{pat}_rut_max_depth_mm']):.2f} mm",
                         *risk])
    return md(["mass (kg)", "pattern", "trafficked", "rut mean / max", *(f"{d:g} m" for d in depths)], rows)


@table("operation-rti", "studies.md", "symtrack field operation_small --set 'operation.follower=\"rti\"' --out DIR "
       "[--set 'soil.preset=\"sandy_loam_15\"']")
def operation_rti() -> str:
    rows = []
    for soil, extra in (("clay", ""), ("sandy loam", " --set 'soil.preset=\"sandy_loam_15\"'")):
        s = summary(f"symtrack field operation_small --set 'operation.follower=\"rti\"'{extra} --out DIR --quiet",
                    ok=(0, 1))
        op = s["operations"][0]
        done = f"yes, {s['turns_driven']} turns" if s["complete"] else f"**no**: {s['error']}"
        rows.append([soil, done, f"{s['rms_lateral_error_lines_m']:.4f} / {s['rms_lateral_error_turns_m']:.4f}",
                     f"{s['max_lateral_error_lines_m']:.3f}", op["solves"], f"**{op['failed_solves']}**",
                     op["fallback_solves"]])
    return md(["soil", "complete", "RMS lines / turns [m]", "max lines [m]", "solves", "failed", "IPOPT fallbacks"],
              rows)


TRAFFIC_SMALL = ("symtrack field traffic_small --set 'season.tracks=\"controlled\"' "
                 "--set 'operation.turn_lane_m=\"{}\"' --set 'operation.follower=\"law\"' "
                 "--out DIR --workers 0 --quiet")


def _season_row(s: dict) -> list[str]:
    return [f"{s['trafficked_fraction']:.4f}", f"{s['headland_trafficked_fraction']:.4f}",
            f"{s['infield_trafficked_fraction']:.4f}",
            f"{s['area_run_over_once_m2']:.1f} / {s['area_run_over_twice_m2']:.1f} / "
            f"{s['area_run_over_3_or_more_m2']:.1f}", f"{s['repeated_coverage_fraction']:.4f}"]


@table("turn-lanes", "studies.md", "symtrack field traffic_small --set 'season.tracks=\"controlled\"' --set "
       "'operation.turn_lane_m=\"auto\"|\"none\"' --set 'operation.follower=\"law\"' --out DIR --workers 0")
def turn_lanes() -> str:
    rows = []
    for lane, label in (("none", '"none"'), ("auto", '"auto"')):
        s = summary(TRAFFIC_SMALL.format(lane), ok=(0, 1))
        if not s["complete"]:
            raise RuntimeError(f"traffic_small, turn_lane_m = {lane}: {s['error']}")
        rows.append([label, *_season_row(s), f"{s['distance_m']:.1f} m",
                     f"{s['rms_lateral_error_lines_m']:.3f} / {s['rms_lateral_error_turns_m']:.3f} m",
                     f"{s['turns_driven']} / {s['turns_lifted']}"])
    return md(["turn_lane_m", "trafficked", "headland", "in-field", "once / twice / 3+ [m^2]", "repeated coverage",
               "distance", "RMS lines / turns", "turns driven / lifted"], rows)


@table("traffic-systems", "studies.md", "symtrack field traffic_small --set 'operation.follower=\"law\"' --out DIR "
       "--workers 0 (DIR/traffic.csv)")
def traffic_systems() -> str:
    _, folder = run("symtrack field traffic_small --set 'operation.follower=\"law\"' --out DIR --workers 0 --quiet")
    with (folder / "traffic.csv").open(encoding="utf-8") as f:
        rows = []
        for r in csv.DictReader(f):
            s = {k: (float(v) if re.fullmatch(r"-?[\d.e+-]+", v or "") else v) for k, v in r.items()}
            rows.append([r["tracks"], *_season_row(s), f"{s['rms_lateral_error_lines_m']:.3f} m",
                         f"{int(s['turns_driven'])} / {int(s['turns_lifted'])}",
                         "yes" if r["complete"] == "True" else "**no**"])
    return md(["system", "trafficked", "headland", "in-field", "once / twice / 3+ [m^2]", "repeated coverage",
               "RMS lines", "turns driven / lifted", "complete"], rows)


# ---------------------------------------------------------------------------------------------------------
# docs/control.md

@table("lane-keeping", "control.md", "python examples/lane_keeping_ruts.py --out DIR --baseline")
def lane_keeping() -> str:
    d = run_json("python examples/lane_keeping_ruts.py --out DIR --baseline")
    ln, p2, base = d["lanes"], d["second_pass"], d["baseline_offset_pass"]
    conv, bconv = p2["after_convergence"], base["after_convergence"]
    return md(["figure", "controlled traffic (follows the lanes)", "offset pass (no lane keeping)"], [
        ["lanes found: gauge / centre / heading",
         f"{ln['gauge_m']:.3f} m (the track gauge {ln['vehicle_track_gauge_m']:g} m) / y = {ln['centre_y0_m']:.4f} m "
         f"(pass 1 drove {ln['first_pass_reference_y_m']:g}) / {ln['heading_deg']:.4f} deg", ""],
        ["converged (\\|e\\| < 5 cm from then on)", f"from s = {p2['converged_from_s_m']:.1f} m",
         "(starts on its line)"],
        ["RMS lateral error from 6 m on (max)",
         f"**{100 * p2['rms_lateral_error_m']:.2f} cm** ({100 * p2['max_lateral_error_after_settle_m']:.2f} cm)", ""],
        [f"new sinkage outside pass 1's ruts, after convergence (cells beyond x = {conv['x_after_m']:.1f} m)",
         f"**{100 * conv['new_sinkage_outside_fraction']:.2f} %** of the new volume "
         f"(max {conv['new_sinkage_max_outside_mm']:.3f} mm)",
         f"{100 * bconv['new_sinkage_outside_fraction']:.0f} % (max {bconv['new_sinkage_max_outside_mm']:.2f} mm)"],
        ["new volume after convergence / pass 1's volume there", f"{100 * conv['new_to_first_pass_volume']:.1f} %",
         f"{100 * bconv['new_to_first_pass_volume']:.0f} %"],
        ["new sinkage outside pass 1's ruts, whole pass",
         f"{100 * p2['whole_pass']['new_sinkage_outside_fraction']:.0f} %",
         f"{100 * base['whole_pass']['new_sinkage_outside_fraction']:.0f} %"]])


@table("linearization-creep", "control.md", "symtrack linearize --speed 2 [--radius 20] --set model.lateral_law=creep "
       "--out DIR (DIR/modes.md; sandy loam, the default soil)")
def linearization_creep() -> str:
    base = "symtrack linearize --speed 2 --set model.lateral_law=creep"
    straight, turn = _modes_of(f"{base} --out DIR"), _modes_of(f"{base} --radius 20 --out DIR")
    rows = [[reading, ", ".join(straight.get(reading, [])) or "-", ", ".join(turn.get(reading, [])) or "-"]
            for reading in dict.fromkeys([*straight, *turn])]
    return md(["mode (modes.md's reading)", "straight running [1/s]", "20 m turn [1/s]"], rows)


# ---------------------------------------------------------------------------------------------------------
# docs/region.md: `symtrack bench region --large` (the full fidelity's seasons, then the fast twins, 1 against 2
# workers, a 1,000 ha region)

def _region() -> dict:
    _, folder = run("symtrack bench region --large --out DIR/region.json")
    return json.loads((folder / "region.json").read_text(encoding="utf-8"))


@table("region-fast-full", "region.md", "symtrack bench region --large --out FILE")
def region_fast_full() -> str:
    rows = []
    for r in _region()["fast_vs_full"]:
        stress = " / ".join(f"{r[f'stress_ratio_{d}m']:.2f}" for d in ("0.1", "0.3", "0.5")) \
            if "stress_ratio_0.1m" in r else "-"  # on the same cells only
        dens = " / ".join(f"{r[f'density_change_ratio_{d}m']:.2f}" for d in ("0.1", "0.3", "0.5"))
        rows.append([r["case"], r["rule"], f"{r.get('cell_m', 0.1):g}", f"{100 * r['trafficked_fraction_full']:.1f}",
                     f"{100 * r['trafficked_fraction_fast']:.1f}", f"{r['trafficked_difference_points']:+.1f}", stress,
                     dens, f"{r['full_wall_time_s']:.0f}", f"{r['fast_wall_time_s']:.2f}", f"{r['cost_ratio']:.0f}"])
    return md(["case", "rule", "cells [m]", "trafficked, full [%]", "fast [%]", "difference [points]",
               "stress fast / full, 0.1 / 0.3 / 0.5 m", "density change fast / full, 0.1 / 0.3 / 0.5 m", "full [s]",
               "fast [s]", "cost full / fast"], rows)


@table("region-cost", "region.md", "symtrack bench region --large --out FILE")
def region_cost() -> str:
    rep = _region()
    fine = [r for r in rep["fast_vs_full"] if "cells" in r]
    full = ", ".join(f"{r['full_s_per_ha_season']:.0f} (`{r['case']}`)" for r in fine if r["rule"] == "overlap")
    fast = ", ".join(f"{r['fast_wall_time_s']:.2f} s (`{r['case']}`, {r['rule']})" for r in fine)
    w = rep.get("workers", [])
    rows = [["the full fidelity, wall seconds per hectare-season (one core a run; the crawler, 0.1 m cells)", full],
            ["the fast fidelity on the same fields and cells", fast]]
    if w:
        rows += [["the fast fidelity, the region's calendars, CPU seconds per hectare-season (the tasks' own)",
                  " and ".join(f"{r['cpu_s_per_ha_season']:.3f} ({r['workers']} worker{'s' * (r['workers'] > 1)})"
                               for r in w)],
                 ["the same as wall seconds per hectare-season per worker",
                  " and ".join(f"{r['s_per_ha_season_per_core']:.2f} ({r['workers']})" for r in w)],
                 [f"{w[0]['field_seasons']} fields ({w[0]['area_ha']:.0f} ha) on 1 and on 2 workers",
                  "tasks " + " and ".join(f"{r['tasks_s']:.1f} s" for r in w)
                  + (f" ({w[1]['speedup_vs_1_worker']:.2f} x); the workers got "
                     + " and ".join(f"{r['cores_used']:.2f}" for r in w) + " of a core in all"
                     if len(w) == 2 else "")]]
    if "large_region" in rep:
        r = rep["large_region"]
        parts = ", ".join(f"{k[:-2]} {r[k]:.0f} s" for k in ("plans_s", "tables_s", "tasks_s", "outputs_s") if k in r)
        rows.append([f"{r['area_ha']:.0f} ha ({r['fields']} fields), one season, {r['workers']} workers, outputs "
                     "included", f"{r['wall_time_s']:.0f} s ({parts})"])
    return md(["what", "measured"], rows)


@table("region-workers", "region.md", "symtrack bench region --workers --repeats 5 --out FILE")
def region_workers() -> str:
    _, folder = run("symtrack bench region --workers --repeats 5 --out DIR/workers.json")
    rep = json.loads((folder / "workers.json").read_text(encoding="utf-8"))
    w = rep["workers"]
    rows = []
    for one, two in zip(w[0::2], w[1::2], strict=True):
        rows.append([f"{one['repeat'] + 1}", f"{one['tasks_s']:.1f}", f"{two['tasks_s']:.1f}",
                     f"{two['speedup_vs_1_worker']:.2f}", f"{one['cores_used']:.2f} / {two['cores_used']:.2f}",
                     f"{one['cpu_s_per_ha_season']:.3f} / {two['cpu_s_per_ha_season']:.3f}"])
    rows.append(["median", "", "", f"{rep['speedup_median']:.2f}", "", ""])
    return md([f"pair ({w[0]['field_seasons']} fields, {w[0]['area_ha']:.0f} ha, one season)", "tasks, 1 worker [s]",
               "tasks, 2 workers [s]", "throughput 2 / 1", "cores the tasks got, 1 / 2 workers",
               "CPU s per hectare-season, 1 / 2 workers"], rows)


@table("region-two-fidelities", "region.md",
       "symtrack.region.study.field_season in each fidelity on the generated field of "
       "tests/test_region_full.py (the drill's tractor and the combine, one season; docs/figures.py)")
def region_two_fidelities() -> str:
    import dataclasses as dc
    import io

    import numpy as np

    from symtrack.region import demo, study
    from symtrack.region.inputs import load_region

    systems = {"one": [{"name": "drilling", "machine": "drill_6m", "window": [262, 292]},
                       {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]}]}
    WORK.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(dir=WORK))
    with _timed("region field_season, full and fast"):
        p = demo.write_region(folder, n_fields=2, seed=7, systems=systems, years={2021: 0.0},
                              length_m=(90.0, 100.0), width_m=(50.0, 60.0), spacing_m=160.0)
        p.write_text(p.read_text() + '\n[full_fidelity]\nfields = ["F002"]\n')
        spec = load_region(p)
        study.check_plans(spec)
        ctx = study.build_context(spec)
        f = spec.fields[0]
        res = {}
        for fid in ("fast", "full"):
            spec.fields[0] = dc.replace(f, fidelity=fid)
            res[fid] = study.field_season(ctx, 0, 2021, None)
    a, b = res["full"]["summary"], res["fast"]["summary"]

    def npz(r):
        with np.load(io.BytesIO(r["files"]["maps.npz"])) as z:
            return {k: z[k] for k in z.files}

    ma, mb = npz(res["full"]), npz(res["fast"])
    both = (ma["counts"] > 0) & (mb["counts"] > 0)
    depths = list(a["depths_m"])
    tags = [f"{d:g}m" for d in depths]
    dl = " / ".join(f"{d:g}" for d in depths)
    largest = [a[f"stress_max_{t}_kPa"] / b[f"stress_max_{t}_kPa"] for t in tags]
    mean = [ma["sigma_max_kPa"][..., k][both].mean() / mb["sigma_max_kPa"][..., k][both].mean()
            for k in range(len(depths))]
    dens = [a[f"density_change_mean_{t}_Mg_per_m3"] / b[f"density_change_mean_{t}_Mg_per_m3"] for t in tags]
    return md(["figure", "full", "fast", "full / fast"], [
        ["field area, cells", f"{a['area_ha']:.2f} ha, {a['cell_m']:g} m", f"{b['area_ha']:.2f} ha, {b['cell_m']:g} m",
         ""],
        ["trafficked share", f"{100 * a['trafficked_fraction']:.1f} %", f"{100 * b['trafficked_fraction']:.1f} %",
         f"{a['trafficked_fraction'] / b['trafficked_fraction']:.3f}"],
        [f"largest stress at {dl} m [kPa]", " / ".join(f"{a[f'stress_max_{t}_kPa']:.1f}" for t in tags),
         " / ".join(f"{b[f'stress_max_{t}_kPa']:.1f}" for t in tags), " / ".join(f"{r:.3f}" for r in largest)],
        [f"mean stress under the cells both trafficked, {dl} m", "", "", " / ".join(f"{r:.3f}" for r in mean)],
        [f"mean density change at {dl} m", "", "", " / ".join(f"{r:.3f}" for r in dens)],
        ["CPU time of the field-season [s] (the full's with its tyres' stress tables, built at their first use)",
         f"{a['cpu_time_s']:.2f}", f"{b['cpu_time_s']:.3f}",
         f"{a['cpu_time_s'] / b['cpu_time_s']:.0f}"]])


# one field-season of a generated one-field region in a fresh process, as a worker runs it (the fast fidelity,
# the region's default cells): the process's resident set before the season (imports, region, tables) and
# its peak during the season (VmHWM reset by /proc/self/clear_refs before it)
_REGION_HWM = """
import io, json, sys
from pathlib import Path
import numpy as np
from symtrack.region import demo, study
from symtrack.region.inputs import load_region

def status(key):
    with open("/proc/self/status") as f:
        return 1024.0 * float(next(line.split()[1] for line in f if line.startswith(key + ":")))

folder, length, width = Path(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
p = demo.write_region(folder, n_fields=1, seed=7, years={2021: 0.0}, length_m=(length, length),
                      width_m=(width, width))
spec = load_region(p)
study.check_plans(spec)
ctx = study.build_context(spec)
before = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
res = study.field_season(ctx, 0, 2021, None)
peak = status("VmHWM")
s = res["summary"]
with np.load(io.BytesIO(res["files"]["maps.npz"])) as z:
    shape = z["counts"].shape  # the field's grid
print(json.dumps({"area_ha": s["area_ha"], "cell_m": s["cell_m"], "shape": list(shape), "before": before,
                  "peak": peak}))
"""
REGION_MEMORY_FIELDS = ((200.0, 180.0), (600.0, 500.0))  # (length, width) [m] of the generated fields


@table("region-worker-memory", "region.md",
       "symtrack.region.study.field_season of a generated one-field region in a fresh process, its VmRSS before "
       "and VmHWM during the season (docs/figures.py)")
def region_worker_memory() -> str:
    if not sys.platform.startswith("linux"):
        raise RuntimeError("the resident set is read from /proc/self/status: Linux only")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    rows = []
    for length, width in REGION_MEMORY_FIELDS:
        WORK.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(dir=WORK))
        with _timed(f"region memory {length:g} x {width:g}"):
            proc = subprocess.run([sys.executable, "-c", _REGION_HWM, str(folder), str(length), str(width)],
                                  cwd=ROOT, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"field_season {length:g} x {width:g} m: exit {proc.returncode}\n{proc.stderr[-2000:]}")
        d = json.loads(proc.stdout.strip().splitlines()[-1])
        grid_ha = d["shape"][0] * d["shape"][1] * d["cell_m"] ** 2 / 1e4
        rows.append([f"{d['area_ha']:.1f} ha", f"{grid_ha:.1f} ha at {d['cell_m']:g} m", f"{d['before'] / 1e9:.2f} GB",
                     f"{d['peak'] / 1e9:.2f} GB", f"{(d['peak'] - d['before']) / 1e6 / grid_ha:.0f} MB"])
    return md(["field", "its grid", "the process before the season", "its peak in the season",
               "peak above before, per hectare of grid"], rows)


@table("region-cost-model", "region.md", "symtrack bench region --large --out FILE")
def region_cost_model() -> str:
    rep = _region()
    w, r = rep["workers"], rep["large_region"]
    ha = r["area_ha"]
    tasks = max(x["cpu_s_per_ha_season"] for x in w)  # the tasks' own CPU seconds per hectare-season
    plans, outputs = r["plans_s"] / ha, r["outputs_s"] / ha  # the client's, one core
    full = max(x["full_s_per_ha_season"] for x in rep["fast_vs_full"] if "full_s_per_ha_season" in x)
    m = 1e6  # hectare-seasons: a 2,000 km^2 region worked for five seasons, all of it fields

    def hours(core_s: float, cores: int) -> str:
        h = core_s / 3600 / cores
        return f"{h:,.0f} h" if h >= 2 else f"{60 * h:,.0f} min"

    return md(["part", "core-seconds", "for 1 million hectare-seasons"], [
        ["the tasks, on the workers (their own CPU time)", f"{tasks:.2f} s x hectare-seasons",
         f"{tasks * m / 3600:,.0f} core-hours: {hours(tasks * m, 64)} on 64 cores, {hours(tasks * m, 1000)} on 1,000"],
        ["checking the plans, on the client", f"{plans:.3f} s x hectare-seasons", f"{hours(plans * m, 1)} on one core"],
        ["the region's maps and report, on the client", f"{outputs:.3f} s x hectare-seasons",
         f"{hours(outputs * m, 1)} on one core"],
        ["the tables, once", f"{r['tables_s']:.0f} s", ""],
        ["the workers beyond which the client's one core sets the study's time", "",
         f"about {tasks / (plans + outputs):.0f}"],
        ["the full fidelity instead (the slowest case above, wall seconds of one core)",
         f"{full:.0f} s x hectare-seasons",
         f"{full * m / 3600:,.0f} core-hours: {hours(full * m, 1000)} on 1,000 cores"]])


# ---------------------------------------------------------------------------------------------------------
# writing the pages

def stamp(t: Table, seconds: float) -> str:
    day = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d")
    took = f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"
    return (f"Produced {day} by `{t.command}` on {machine()}, load average {os.getloadavg()[0]:.1f} at the end "
            f"({took}); regenerate with `make figures NAMES={t.name}`.")


def replace(text: str, name: str, body: str, page: str) -> str:
    """The page with the block between the table's markers replaced (indented as the start marker is: a
    table inside a list item)."""
    start, end = MARK.format(name=name, end="start"), MARK.format(name=name, end="end")
    pat = re.compile(r"^([ \t]*)" + re.escape(start) + r"\n.*?" + re.escape(end), re.S | re.M)
    if not pat.search(text):
        raise SystemExit(f"docs/{page} has no markers for the table {name!r}")

    def block(m):
        ind = m.group(1)
        lines = "\n".join(ind + ln if ln else "" for ln in body.splitlines())
        return f"{ind}{start}\n{lines}\n{ind}{end}"
    return pat.sub(block, text)


def make(t: Table) -> tuple[str, float]:
    """The table's block (its line, a blank line, the table) and the seconds its commands took."""
    _USED.clear()
    t0 = time.perf_counter()
    body = t.make()
    own = time.perf_counter() - t0 - sum(_ELAPSED.get(c, 0.0) for c in set(_USED) if c in _ELAPSED)
    seconds = max(own, 0.0) + sum(_ELAPSED.get(c, 0.0) for c in dict.fromkeys(_USED))
    return f"{stamp(t, seconds)}\n\n{body}", seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", metavar="NAME", help="only these tables (names: --list)")
    ap.add_argument("--print", action="store_true", help="print the tables instead of rewriting the pages")
    ap.add_argument("--list", action="store_true", help="list the tables and exit")
    args = ap.parse_args(argv)
    if args.list:
        for t in TABLES.values():
            print(f"{t.name:24s} docs/{t.page:18s} {t.command}")
        return 0
    names = args.only or list(TABLES)
    unknown = [n for n in names if n not in TABLES]
    if unknown:
        ap.error(f"no table {', '.join(unknown)}; the tables: {', '.join(TABLES)}")
    t_all, failed = time.perf_counter(), []
    WORK.mkdir(parents=True, exist_ok=True)
    try:
        for name in names:
            t = TABLES[name]
            print(f"{name} (docs/{t.page}) ...", file=sys.stderr, flush=True)
            try:
                block, seconds = make(t)
            except Exception as e:  # noqa: BLE001 - one table's failure does not stop the others
                print(f"{name}: FAILED: {e}", file=sys.stderr, flush=True)
                failed.append(name)
                continue
            print(f"{name}: {seconds:.0f} s", file=sys.stderr, flush=True)
            if args.print:
                print(f"## {name} (docs/{t.page})\n\n{block}\n", flush=True)
                continue
            page = DOCS / t.page
            page.write_text(replace(page.read_text(encoding="utf-8"), name, block, t.page), encoding="utf-8")
    finally:
        shutil.rmtree(WORK, ignore_errors=True)
    total = time.perf_counter() - t_all
    print(f"{len(names) - len(failed)} tables in {total / 60:.1f} min"
          + (f"; failed: {' '.join(failed)}" if failed else ""), file=sys.stderr)
    if not args.print and not args.only and not failed:
        day = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d")
        line = (f"The whole run took {total / 60:.0f} min on {machine()} ({day}, load average "
                f"{os.getloadavg()[0]:.1f} at the end).")
        text = TOTAL_PAGE.read_text(encoding="utf-8")
        text = re.sub(r"(<!-- figures-total:start -->\n).*?(\n<!-- figures-total:end -->)",
                      lambda m: m.group(1) + line + m.group(2), text, flags=re.S)
        TOTAL_PAGE.write_text(text, encoding="utf-8")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
