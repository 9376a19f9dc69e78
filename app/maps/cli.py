"""`bearings map check | import`: validate map files; turn real floor plans into map files."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: Objects within this distance of a wall are moved onto it on import (mounted in it).
DEFAULT_SNAP_M = 0.15


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="map_command", required=True, metavar="ACTION")
    check = sub.add_parser(
        "check", help="validate map files; print every problem with its field (exit 1 on any)"
    )
    check.add_argument("files", nargs="+", type=Path, metavar="FILE")
    imp = sub.add_parser(
        "import",
        help="make a map file from a ROS occupancy grid (+ objects CSV), a GeoJSON floor, "
        "or an IMDF venue (levels, connectors and all)",
    )
    src = imp.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--occupancy", type=Path, metavar="MAP.yaml", help="ROS map_server YAML (+ its image)"
    )
    src.add_argument("--geojson", type=Path, metavar="FLOOR.geojson", help="GeoJSON floor")
    src.add_argument(
        "--imdf",
        type=Path,
        metavar="DIR_OR_ZIP",
        help="an IMDF venue (Apple's Indoor Mapping Data Format): its folder or .zip",
    )
    imp.add_argument(
        "--objects",
        type=Path,
        metavar="OBJECTS.csv",
        help="objects as class,x,y[,label] rows in map metres (required with --occupancy)",
    )
    imp.add_argument(
        "--regions",
        type=Path,
        metavar="IMG_or_GEOJSON",
        help="rooms: a segmentation image the size of the occupancy image (one colour per "
        "room) or a GeoJSON of Polygons with a 'name'",
    )
    imp.add_argument(
        "--origin",
        metavar="LAT,LON",
        help="the GeoJSON is WGS84 longitude/latitude; project it to metres around this point",
    )
    imp.add_argument(
        "--snap-m",
        type=float,
        default=DEFAULT_SNAP_M,
        help=f"move objects this close to a wall onto it (default {DEFAULT_SNAP_M} m)",
    )
    imp.add_argument(
        "--storey-m",
        type=float,
        default=None,
        metavar="METRES",
        help="with --imdf: the height of a storey, for the levels' elevation_m (IMDF gives "
        "ordinals only; default 4.0)",
    )
    imp.add_argument("--description", default="", help="the map's description")
    imp.add_argument(
        "--out", type=Path, required=True, metavar="NAME.json", help="map file to write"
    )


def run(args: argparse.Namespace) -> int:
    if args.map_command == "check":
        return run_check(args.files)
    return run_import(args)


def run_check(files: list[Path]) -> int:
    """Print every problem of every file; 0 when there is none."""
    from app.maps.check import check_file

    bad = 0
    for path in files:
        result = check_file(path)
        for problem in result.problems:
            print(problem)
        if result.problems:
            bad += 1
        else:
            m = result.map
            assert m is not None
            levels = m.layout.levels
            venue = (
                f", {len(levels)} levels, {len(m.layout.connectors)} connectors" if levels else ""
            )
            print(
                f"{path}: no problems ({len(m.layout.wall_level)} walls, {m.object_count} "
                f"objects, {len(m.region_names)} regions{venue})"
            )
    return 1 if bad else 0


def import_map(args: argparse.Namespace) -> dict[str, object]:
    """The map file's JSON from the import arguments (raises MapImportError)."""
    from app.maps.importers.common import MapImportError, map_dict, read_objects_csv, snap_objects

    name = args.out.stem
    if args.imdf is not None:
        return _import_imdf(args)
    if args.storey_m is not None:
        raise MapImportError("--storey-m goes with --imdf only")
    regions: list[dict[str, object]] = []
    if args.occupancy is not None:
        from app.maps.importers.occupancy import (
            read_occupancy,
            read_region_image,
            region_polygons,
            vectorize,
        )

        if args.objects is None:
            raise MapImportError("--objects OBJECTS.csv is required with --occupancy")
        occ = read_occupancy(args.occupancy)
        walls = vectorize(occ)
        objects = read_objects_csv(args.objects)
        if args.regions is not None and args.regions.suffix.lower() not in (".json", ".geojson"):
            labels = read_region_image(args.regions, occ)
            regions = [
                {"name": f"region #{value:06x}", "polygon": poly.round(4).tolist()}
                for value, poly in region_polygons(labels, occ)
            ]
        source = f"{args.occupancy.name} ({occ.occupied.shape[1]} x {occ.occupied.shape[0]} px)"
    else:
        from app.maps.importers.geojson import parse_origin, read_geojson

        origin = parse_origin(args.origin) if args.origin else None
        walls, objects, regions = read_geojson(args.geojson, origin)
        if args.objects is not None:
            objects += read_objects_csv(args.objects)
        source = args.geojson.name
    if args.regions is not None and args.regions.suffix.lower() in (".json", ".geojson"):
        from app.maps.importers.geojson import parse_origin, read_geojson

        origin = parse_origin(args.origin) if args.origin else None
        regions += read_geojson(args.regions, origin)[2]
    snapped = snap_objects(objects, np.asarray(walls).reshape(-1, 4), args.snap_m)
    print(
        f"{source}: {len(walls)} walls, {len(objects)} objects ({snapped} moved onto a wall), "
        f"{len(regions)} regions"
    )
    description = args.description or f"imported from {source}"
    return map_dict(name, np.asarray(walls), objects, regions, description)


def _import_imdf(args: argparse.Namespace) -> dict[str, object]:
    """The IMDF venue's map (objects already snapped per level); prints the summary."""
    from app.maps.importers.common import MapImportError
    from app.maps.importers.imdf import DEFAULT_STOREY_M, import_imdf

    for flag, value in (("--objects", args.objects), ("--regions", args.regions)):
        if value is not None:
            raise MapImportError(f"{flag} does not go with --imdf (the venue has its own)")
    if args.origin:
        raise MapImportError("--origin does not go with --imdf (the venue places itself)")
    storey_m = DEFAULT_STOREY_M if args.storey_m is None else args.storey_m
    data, summary = import_imdf(
        args.imdf,
        args.out.stem,
        storey_m=storey_m,
        description=args.description,
        snap_m=args.snap_m,
    )
    for line in summary.lines():
        print(line)
    return data


def run_import(args: argparse.Namespace) -> int:
    """Import, check, and write the map file when it has no error."""
    from app.maps.check import check_data
    from app.maps.importers.common import MapImportError

    try:
        data = import_map(args)
    except MapImportError as exc:
        print(f"error: {exc}")
        return 1
    result = check_data(data, source=str(args.out), expected_name=args.out.stem)
    for problem in result.problems:
        print(problem)
    if result.map is None:
        print(f"{args.out}: not written (errors above)")
        return 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result.map.to_json(), indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    return 0
