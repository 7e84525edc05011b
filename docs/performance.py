"""Regenerate the measured tables of docs/performance.md (``make performance``).

    python docs/performance.py                # measures, then rewrites the tables in docs/performance.md
    python docs/performance.py --print        # measures and prints the tables only

Each table sits between ``<!-- perf:NAME:start -->`` and ``<!-- perf:NAME:end -->`` markers and is
written whole by this script, with the machine, the date and the command above it: no figure in
docs/performance.md is typed by hand. The rows come from the functions of ``symtrack bench``
(:mod:`symtrack.bench.homogeneous`, :mod:`symtrack.bench.laws`, :mod:`symtrack.bench.terrain`).
Wall-clock figures depend on the machine and its load: the load average is written with them.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import sys
import time
from pathlib import Path

PAGE = Path(__file__).resolve().parent / "performance.md"
COMMAND = "make performance"


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} CPUs, Python {platform.python_version()}, {platform.system()}"


def stamp() -> str:
    day = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d")
    return (f"Measured {day} on {machine()}, load average {os.getloadavg()[0]:.2f} at the end; "
            f"regenerate with `{COMMAND}`.")


def homogeneous_table() -> str:
    from symtrack.bench.homogeneous import homogeneous_rows

    rows = homogeneous_rows(quick=True, repeats=3)
    lines = ["| case | integrator | wall [s] (best) | real-time factor (wall) | real-time factor (CPU, with the "
             "run's setup) |",
             "|---|---|---|---|---|"]
    for r in rows:
        cpu = r.get("cpu_time_s_incl_setup")  # the time loop's process time (the C program: none)
        lines.append(f"| {r['case']} | {r['integrator']} | {r['wall_time_s']:.4f} for {r['sim_time_s']:.2f} s "
                     f"| {r['real_time_factor']:.0f} | {r['sim_time_s'] / cpu:.0f} |" if cpu else
                     f"| {r['case']} | {r['integrator']} | {r['wall_time_s']:.4f} for {r['sim_time_s']:.2f} s "
                     f"| {r['real_time_factor']:.0f} | |")
    return "\n".join(lines)


def grid_table() -> str:
    from symtrack.bench.laws import bench_rows

    rows = [r for r in bench_rows(quick=False) if "real_time_factor" in r]
    lines = ["| case | integrator | wall [s] (median) | real-time factor (wall) | real-time factor (CPU) |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['group']}: {r['case']} | {r['integrator']} | {r['wall_time_s']:.4f} for "
                     f"{r['sim_time_s']:.2f} s | {r['real_time_factor']:.0f} | {r['real_time_factor_cpu']:.0f} |")
    return "\n".join(lines)


def field_size_table() -> str:
    from symtrack.bench.terrain import engine_field_rows

    rows = engine_field_rows((1e4, 1e6))
    lines = ["| field | CPU s per simulated s | real-time factor (CPU) | storage [MB] |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['cells']:.3g} cells at 0.1 m | {r['cpu_s_per_sim_s']:.4f} | "
                     f"{r['real_time_factor_cpu']:.0f} | {r['storage_MB']:.1f} |")
    return "\n".join(lines)


TABLES = {"homogeneous": homogeneous_table, "grid": grid_table, "field-size": field_size_table}


def replace(text: str, name: str, body: str) -> str:
    pat = re.compile(rf"(<!-- perf:{name}:start -->\n)(.*?)(<!-- perf:{name}:end -->)", re.S)
    if not pat.search(text):
        raise SystemExit(f"{PAGE} has no markers for the table {name!r}")
    return pat.sub(lambda m: m.group(1) + body + "\n" + m.group(3), text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--print", action="store_true", help="print the tables instead of rewriting the page")
    ap.add_argument("--only", choices=sorted(TABLES), action="append", help="measure only these tables")
    args = ap.parse_args(argv)
    out = {}
    for name in args.only or TABLES:
        t0 = time.perf_counter()
        print(f"measuring {name} ...", file=sys.stderr, flush=True)
        table = TABLES[name]()
        out[name] = f"{stamp()}\n\n{table}"
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if args.print:
        for name, body in out.items():
            print(f"## {name}\n\n{body}\n")
        return 0
    text = PAGE.read_text(encoding="utf-8")
    for name, body in out.items():
        text = replace(text, name, body)
    PAGE.write_text(text, encoding="utf-8")
    print(f"wrote {PAGE}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
