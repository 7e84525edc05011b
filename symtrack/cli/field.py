"""``symtrack field``: the whole-field traffic study (docs/studies.md, "Whole-field traffic study");
argument parsing only, the study is :mod:`symtrack.studies.field`. CasADi is imported by the
command, not here, so that ``symtrack --help`` answers at once."""

from __future__ import annotations

import sys

from ..foundations.files import check_output_folder

__all__ = ["add_parser", "field_command"]


def field_command(args) -> int:
    out = check_output_folder(args.out)  # before anything is loaded or built
    from ..reports.run_files import output_lock

    with output_lock(out):  # a second study into the folder fails at once
        return _field(args, out)


def _field(args, out) -> int:
    from ..studies.field import IncompleteFieldStudy, load_field_spec, run_field_study
    from ..studies.operations import is_operation_document, load_operation_spec, run_season

    overrides = list(args.set or [])
    if is_operation_document(args.scenario):  # a field operation or a season (docs/studies.md, "Field operations")
        spec = load_operation_spec(args.scenario, overrides)
        if spec.compare:  # [season] compare: the same season under each traffic system, on new fields
            if args.workers == 0:  # one after another in this process
                from ..studies.operations import traffic_comparison

                table = traffic_comparison(spec.document, spec.compare, out, progress=not args.quiet, name=spec.name)
            else:  # a resumable sweep on Dask, a case per system (docs/studies.md, "Traffic systems on Dask")
                from ..studies.traffic import traffic_sweep

                try:
                    table = traffic_sweep(args.scenario, out, overrides=overrides, workers=args.workers,
                                          scheduler=args.scheduler, progress=not args.quiet)
                except KeyboardInterrupt:
                    print(f"symtrack: interrupted (Ctrl-C); the systems finished are kept in {out} (results.csv); "
                          "run the same command again to do the rest", file=sys.stderr)
                    return 130
            for r in table["rows"]:
                if not r["complete"]:
                    print(f"{r['tracks']}: FAILED (its run in {out}: results.csv, runs/)")
                    continue
                print(f"{r['tracks']}: trafficked {100 * r['trafficked_fraction']:.1f} % (headland "
                      f"{100 * r['headland_trafficked_fraction']:.1f} %, in-field "
                      f"{100 * r['infield_trafficked_fraction']:.1f} %), repeated coverage "
                      f"{100 * r['repeated_coverage_fraction']:.1f} %, turns driven "
                      f"{r['turns_driven']}, {r['wall_time_s']:.0f} s")
            print(f"{spec.name}: {len(table['rows'])} traffic systems; table traffic.csv, figure traffic.png in {out}")
            return 0 if all(r["complete"] for r in table["rows"]) else 1
        res = run_season(spec, out, progress=not args.quiet)
        s = res.summary
        print(f"{s['name']}: {'complete' if s['complete'] else 'FAILED: ' + str(s['error'])}; trafficked "
              f"{100 * s['trafficked_fraction']:.1f} % (headland {100 * s['headland_trafficked_fraction']:.1f} %, "
              f"in-field {100 * s['infield_trafficked_fraction']:.1f} %); turns driven {s['turns_driven']}, lifted 0; "
              f"{s['sim_time_s']:.0f} s simulated in {s['wall_time_s']:.1f} s; results in {out}")
        return 0 if s["complete"] else 1
    if args.pattern:
        overrides.append(f"field.pattern={args.pattern}")
    spec = load_field_spec(args.scenario, overrides)
    try:
        res = run_field_study(spec, out=out, progress=not args.quiet)
    except KeyboardInterrupt:
        if (out / "summary.json").is_file():
            print(f"symtrack: interrupted (Ctrl-C); the whole passes done are kept in {out} (summary.json: complete "
                  "= false); run the same command again to resume from them", file=sys.stderr)
        else:  # stopped while the plant was built, before its first pass
            print(f"symtrack: interrupted (Ctrl-C) before the study's first pass; nothing was run (in {out}: "
                  "field.resolved.toml); run the same command again to start it", file=sys.stderr)
        return 130
    except IncompleteFieldStudy as err:
        print(f"symtrack: error: {err}; what was computed up to there is in {out} (summary.json: complete = "
              "false)", file=sys.stderr)
        return 1
    s = res.summary
    for name, f in s["patterns"].items():
        for line in pattern_lines(name, f):
            print(line)
    print(f"{spec.name}: {s['sim_time_s']:.0f} s simulated in {s['wall_time_s']:.1f} s of wall time (the passes "
          f"{s['passes_wall_time_s']:.1f} s, building {s['build_s']:.1f} s); results in {out}")
    return 0


def pattern_lines(name: str, f: dict) -> list[str]:
    """The console lines of one pattern's figures (``f``: its entry of summary.json's ``patterns``)."""
    hist = f["passes_per_cell_histogram"]
    lines = [f"{name}: {100 * f['trafficked_area_fraction']:.2f} % of the field trafficked; cells by pass count "
             f"{dict(enumerate(hist))}; rut mean {f['rut_mean_depth_mm']:.3f} mm, max {f['rut_max_depth_mm']:.3f} "
             f"mm; {f['passes_done']} passes in {f['wall_time_s']:.1f} s"]
    if f.get("subsoil_sigma_z_max_kPa"):
        by = ", ".join(f"{d:g} m {v:.1f}" for d, v in zip(f["subsoil_depths_m"], f["subsoil_sigma_z_max_kPa"],
                                                            strict=True))
        lines.append(f"  largest vertical stress (kPa): {by}")
    passes = f.get("passes") or []
    rho = passes[-1].get("bulk_density_max_Mg_per_m3") if passes else None
    if rho and len(rho) == len(f.get("subsoil_depths_m", ())):
        by = ", ".join(f"{d:g} m {v:.4f}" for d, v in zip(f["subsoil_depths_m"], rho, strict=True))
        lines.append(f"  largest bulk density after the passes (Mg/m^3): {by}")
    for risk in ("medium", "high"):
        if f"risk_fraction_of_field_{risk}" in f:
            by = ", ".join(f"{d:g} m {100 * v:.2f} %" for d, v in zip(
                f["subsoil_depths_m"], f[f"risk_fraction_of_field_{risk}"], strict=True))
            lines.append(f"  {risk} risk (% of the field): {by}")
    return lines


def add_parser(sub) -> None:
    """Register ``symtrack field`` on the argparse subparsers of symtrack.cli."""
    from pathlib import Path

    # the built-in studies' files, listed without importing symtrack.studies (it imports the plots,
    # and `symtrack --help` stays free of heavy packages: tests/test_first_hour.py)
    fields = Path(__file__).resolve().parent.parent / "studies" / "fields"
    names = sorted(p.name[:-5] for p in fields.iterdir() if p.name.endswith(".toml"))
    fp = sub.add_parser(
        "field", help="a whole-field traffic study: random against controlled traffic (docs/studies.md)",
        description="Work a field of the grid terrain in parallel straight passes (the vehicle lifted off at a "
        "pass's end and set down at the next pass's start), with random and/or controlled traffic, and write "
        "DIR/summary.json, DIR/<pattern>/field.npz, passes.csv and the maps, DIR/comparison.png. Exit code 0 "
        "when every pass ran, 1 when one failed (what was computed is written), 2 for an invalid spec (nothing "
        "run), 130 on Ctrl-C (the whole passes done are written). The same study run again into a folder it was "
        "interrupted in (Ctrl-C, or killed: its folder is checkpointed every minute) resumes from the passes done. "
        f"Built-in: {', '.join(names)}.")
    fp.add_argument("scenario", help="a built-in field study or a TOML file with a [field] section")
    fp.add_argument("--out", required=True, help="output folder")
    fp.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                    help="override a value, e.g. field.passes=4, vehicle.mass_kg=8000")
    fp.add_argument("--pattern", choices=("random", "controlled", "both"),
                    help="shorthand for --set field.pattern=...")
    fp.add_argument("--workers", type=int, default=2, metavar="N",
                    help="a traffic comparison ([season] compare): worker processes of the local Dask cluster, a "
                    "system per case, resumable (default 2); 0 runs the systems one after another in this process")
    fp.add_argument("--scheduler", metavar="ADDRESS",
                    help="a traffic comparison on a running Dask scheduler, e.g. tcp://127.0.0.1:8786")
    fp.add_argument("--quiet", action="store_true", help="no progress bar")
    fp.set_defaults(func=field_command)
