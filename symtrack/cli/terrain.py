"""``symtrack terrain export``: a terrain file's layers as GeoTIFF and NetCDF (docs/terrain.md,
"GIS rasters"); ``symtrack terrain convert``: a terrain file (.npz) to the raw field file (.field) the
engine FMU reads and writes, or back (docs/terrain.md, "Files"). Argument parsing only, the work is
:func:`symtrack.terrain.gis.export_terrain` and :func:`symtrack.terrain.fieldfile.convert` (imported by
the commands, not here, so that ``symtrack --help`` answers at once)."""

from __future__ import annotations

from ..foundations.errors import ScenarioError
from ..foundations.files import check_output_file, check_output_folder

__all__ = ["add_parser", "convert_command", "export_command"]


def export_command(args) -> int:
    if args.geotiff is None and args.netcdf is None:
        raise ScenarioError("symtrack terrain export: give --geotiff DIR and/or --netcdf FILE.nc (nothing to write)")
    # before anything is read: the outputs can be written
    from ..terrain.gis import export_terrain

    folder = None if args.geotiff is None else check_output_folder(args.geotiff, "--geotiff")
    nc = None if args.netcdf is None else check_output_file(args.netcdf, "--netcdf")
    out = export_terrain(args.terrain, geotiff_dir=folder, netcdf=nc, crs=args.crs)
    crs = "no CRS (local coordinates)" if out["crs"] is None else out["crs"].split('"')[1]
    for f in out["geotiff"]:
        print(f"wrote {f}")
    if out["netcdf"] is not None:
        print(f"wrote {out['netcdf']}")
    print(f"CRS: {crs}")
    return 0


def convert_command(args) -> int:
    check_output_file(args.out, "OUT")  # before anything is read
    from ..reports.run_files import terrain_lock
    from ..terrain.fieldfile import convert

    # the writer takes the file's lock (a run's --terrain-out takes the same): while a run holds it,
    # the conversion is refused instead of being overwritten by the run
    with terrain_lock(args.out, "OUT"):
        st = convert(args.src, args.out)
    print(f"wrote {args.out} ({st.grid.shape[0]} x {st.grid.shape[1]} cells)")
    return 0


def add_parser(sub) -> None:
    """Register ``symtrack terrain`` on the argparse subparsers of symtrack.cli."""
    tp = sub.add_parser("terrain", help="work with terrain files: export their layers for GIS tools")
    tsub = tp.add_subparsers(dest="terrain_cmd", required=True)
    ex = tsub.add_parser(
        "export", help="a terrain file's layers as GeoTIFF files and/or one NetCDF dataset (needs symtrack[gis])",
        description="Write the field's state (rut depth, passes, stress and risk class by depth, ...: "
        "docs/terrain.md, \"GIS rasters\") as one GeoTIFF per layer in DIR and/or one NetCDF dataset, in the "
        "terrain's CRS (kept from a GeoTIFF soil map) or the one given by --crs.")
    ex.add_argument("terrain", metavar="FILE.npz", help="a terrain file (--terrain-out, Terrain.save)")
    ex.add_argument("--geotiff", metavar="DIR", help="folder for the GeoTIFF layers (<layer>.tif)")
    ex.add_argument("--netcdf", metavar="FILE.nc", help="the NetCDF dataset")
    ex.add_argument("--crs", metavar="CRS", help="the CRS of a terrain that has none, e.g. EPSG:32633 (projected, "
                    "in metres); a terrain with a CRS keeps it")
    ex.set_defaults(func=export_command)
    cv = tsub.add_parser(
        "convert", help="a terrain file (.npz) to a raw field file (.field, the engine FMU's field_file) or back",
        description="Convert by the suffixes: FILE.npz -> FILE.field or FILE.field -> FILE.npz (docs/terrain.md, "
        "\"Files\"). A field file carries one soil, no subsoil records, no elevation, no history.")
    cv.add_argument("src", metavar="IN", help="FILE.npz or FILE.field")
    cv.add_argument("out", metavar="OUT", help="FILE.field or FILE.npz")
    cv.set_defaults(func=convert_command)
