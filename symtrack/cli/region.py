"""``symtrack region``: a region study (docs/region.md); argument parsing only, the study is
:mod:`symtrack.region`."""

from __future__ import annotations

import sys
from pathlib import Path

from ..foundations.files import check_output_folder

__all__ = ["add_parser", "region_command"]

DEMO = "region_demo"


def region_command(args) -> int:
    out = check_output_folder(args.out)
    from ..reports.run_files import output_lock

    with output_lock(out):  # a second study into the folder fails at once
        return _region(args, out)


def _region(args, out: Path) -> int:
    from ..region.inputs import load_region
    from ..region.study import run_region

    if args.region == DEMO:
        from ..region.demo import write_region

        inputs = out / "inputs"
        path = inputs / f"{DEMO}.toml"
        if not path.is_file():  # generated once: a rerun resumes on the same inputs
            write_region(inputs, n_fields=args.fields, seed=1)
    else:
        if args.fields is not None and args.fields != 36:
            print("symtrack: error: --fields is the demo's (region_demo) only", file=sys.stderr)
            return 2
        path = Path(args.region)
    spec = load_region(path)
    try:
        res = run_region(spec, out, workers=args.workers, scheduler=args.scheduler, progress=not args.quiet)
    except KeyboardInterrupt:
        print(f"symtrack: interrupted (Ctrl-C); the field-seasons finished are kept in {out}/fields; run the same "
              "command again to do the rest", file=sys.stderr)
        return 130
    s = res.summary
    for y in spec.years:
        fy = s["by_year"][str(y)]
        d = min(spec.depths_m, key=lambda x: abs(x - 0.3))
        tag = f"{d:g}m"
        print(f"{y}: trafficked {100 * fy['trafficked_fraction']:.1f} % of {spec.area_ha:.1f} ha; at {d:g} m "
              f"{100 * fy[f'risk_high_fraction_{tag}']:.1f} % high risk, {100 * fy[f'risk_medium_fraction_{tag}']:.1f} "
              f"% medium; mean density change {fy[f'density_change_mean_{tag}_Mg_per_m3']:+.4f} Mg/m^3")
    print(f"{spec.name}: {len(spec.fields)} fields x {len(spec.years)} seasons ({res.ran} run, {res.skipped} finished "
          f"before) in {res.wall_time_s:.1f} s; report.html, fields.csv and maps/ in {out}")
    return 0


def add_parser(sub) -> None:
    """Register ``symtrack region`` on the argparse subparsers of symtrack.cli."""
    rp = sub.add_parser(
        "region", help="a region study: many fields, season after season, on Dask (docs/region.md)",
        description="Work every field of a region through its seasons (the fast fidelity: each operation's planned "
        "paths swept by the machine's footprint, the stress and density by depth from the package's soil models; "
        "the full fidelity, each plan driven over the field's terrain, on the fields the region file's "
        "[full_fidelity] names) on a Dask cluster, and write DIR/fields.csv, DIR/fields.gpkg, DIR/maps/ "
        "(Cloud-Optimized GeoTIFFs), each field-season's maps in DIR/fields/<field_id>/<year>/ (maps.npz and, "
        "unless [outputs] field_maps = false, one GeoTIFF per map on the field's own grid), DIR/report.html. A rerun "
        "into the same folder skips the field-seasons finished. Exit code 0 when done, 2 for invalid inputs "
        f"(nothing run), 130 on Ctrl-C. Built-in: {DEMO} (generated into DIR/inputs).")
    rp.add_argument("region", help=f"a region TOML file, or {DEMO}")
    rp.add_argument("--out", required=True, help="output folder")
    rp.add_argument("--workers", type=int, default=2, metavar="N",
                    help="worker processes of the local Dask cluster (default 2)")
    rp.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://127.0.0.1:8786")
    rp.add_argument("--fields", type=int, default=36, metavar="N", help=f"{DEMO}: how many fields (default 36)")
    rp.add_argument("--quiet", action="store_true", help="no progress")
    rp.set_defaults(func=region_command)
