"""Import an IMDF venue (Apple's Indoor Mapping Data Format) as a map with levels.

The archive is read and projected to metres by :mod:`.imdf_read`; here is what each
IMDF feature becomes (docs/API.md, "Importing an IMDF venue"):

* **levels**: one map level per IMDF ordinal (a venue of several buildings has one
  IMDF level per building and floor; they share the ordinal). Its id is ``L<ordinal>``
  (``B<n>`` below ground), its name the IMDF name, its ``elevation_m`` the ordinal
  times the storey height (IMDF gives none).
* **walls** from unit outlines, with gaps at openings (:mod:`.imdf_walls`), and the
  outlines of fixtures that block the way and the view (walls, obstructions, kiosks).
* **objects** (:mod:`.imdf_objects`): each opening a ``door``, except an elevator's,
  which is the ``elevator``; the units a detector sees (elevators, escalators, stairs,
  restrooms) an object of their kind, at their openings when they have any, else at
  their display point; every amenity an object of its category's first word
  (``restroom.female`` is a ``restroom``, ``unspecified`` is not used).
* **connectors** from elevator, escalator, stairs and ramp units and relationships
  (:mod:`.imdf_connectors`).
* **regions**: every named unit; a unit without a name takes its occupant's (through
  the occupant's anchor).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import shapely

from app.maps.importers.common import MapImportError, snap_objects
from app.maps.importers.imdf_connectors import CONNECTOR_UNITS, Place, Places, connectors
from app.maps.importers.imdf_objects import (
    LevelParts,
    amenity_objects,
    display_point,
    map_object,
    opening_objects,
    seen_class,
)
from app.maps.importers.imdf_read import Feature, level_id, read_archive, text_of
from app.maps.importers.imdf_summary import ImdfSummary
from app.maps.importers.imdf_walls import SIMPLIFY_M, level_walls

#: Storey height when none is given, metres (IMDF has ordinals, not heights).
DEFAULT_STOREY_M = 4.0
#: Fixture categories whose outline is a wall (they block both the way and the view).
WALL_FIXTURES = frozenset({"wall", "obstruction", "kiosk"})
#: Objects this close to a wall of their level are moved onto it, metres.
SNAP_M = 0.15


def _wanted(kind: str, props: dict[str, object]) -> bool:
    """Fixtures that make no wall need no geometry (the bulk of a venue's features)."""
    return kind != "fixture" or props.get("category") in WALL_FIXTURES


def _round(x: float) -> float:
    return round(float(x), 4)


def _polygon(geom: shapely.Geometry | None, where: str) -> shapely.Polygon:
    if geom is None or geom.geom_type not in ("Polygon", "MultiPolygon") or geom.is_empty:
        raise MapImportError(f"{where}: geometry: expected a Polygon or MultiPolygon")
    if not geom.is_valid:
        geom = shapely.make_valid(geom)
        parts = [p for p in shapely.get_parts(geom) if p.geom_type == "Polygon"]
        if not parts:
            raise MapImportError(f"{where}: geometry: not a usable polygon")
        geom = shapely.union_all(parts)
    return geom


def _levels(
    features: list[Feature], language: str
) -> tuple[list[LevelParts], dict[str, LevelParts]]:
    """Map levels by ordinal, and the map level of each IMDF level id."""
    if not features:
        raise MapImportError("level.geojson: no levels")
    by_ordinal: dict[int, LevelParts] = {}
    of_id: dict[str, LevelParts] = {}
    for i, f in enumerate(features):
        ordinal = f.props.get("ordinal")
        if isinstance(ordinal, float) and ordinal.is_integer():
            ordinal = int(ordinal)
        if not isinstance(ordinal, int) or isinstance(ordinal, bool):
            raise MapImportError(
                f"level.geojson: features[{i}] ({f.id}): ordinal: expected an integer, "
                f"got {ordinal!r}"
            )
        name = (
            text_of(f.props.get("name"), language)
            or text_of(f.props.get("short_name"), language)
            or f"Level {ordinal}"
        )
        level = by_ordinal.setdefault(ordinal, LevelParts(level_id(ordinal), ordinal, name))
        of_id[f.id] = level
    return [by_ordinal[o] for o in sorted(by_ordinal)], of_id


def _level_of(f: Feature, of_id: Mapping[str, LevelParts], where: str) -> LevelParts:
    ref = f.props.get("level_id")
    if not isinstance(ref, str) or ref not in of_id:
        raise MapImportError(f"{where} ({f.id}): level_id: {ref!r} is no level of level.geojson")
    return of_id[ref]


def _occupant_names(features: Mapping[str, list[Feature]], language: str) -> dict[str, str]:
    """Unit id -> the name of the occupant anchored in it."""
    anchor_unit = {
        a.id: a.props["unit_id"]
        for a in features["anchor"]
        if isinstance(a.props.get("unit_id"), str)
    }
    out: dict[str, str] = {}
    for o in features["occupant"]:
        unit = anchor_unit.get(str(o.props.get("anchor_id")))
        name = text_of(o.props.get("name"), language)
        if unit and name:
            out.setdefault(str(unit), name)
    return out


def import_imdf(
    path: str | Path,
    name: str,
    *,
    storey_m: float = DEFAULT_STOREY_M,
    description: str = "",
    snap_m: float = SNAP_M,
) -> tuple[dict[str, object], ImdfSummary]:
    """The map file's JSON made from an IMDF folder or .zip, and what was made of what.

    Raises:
        MapImportError: a file or feature that cannot be read; the message names it.
    """
    src = Path(path)
    if not (0.5 <= storey_m <= 20.0):
        raise MapImportError(f"--storey-m: {storey_m} m is not a storey height (0.5 to 20 m)")
    features, language, project, not_read = read_archive(src, _wanted)
    summary = ImdfSummary(src.name)
    levels, of_id = _levels(features["level"], language)
    summary.imdf_levels = len(features["level"])
    summary.not_read = not_read
    occupants = _occupant_names(features, language)
    places = Places()
    unit_level: dict[str, LevelParts] = {}
    regions: list[dict[str, object]] = []
    for i, f in enumerate(features["unit"]):
        where = f"unit.geojson: features[{i}]"
        level = _level_of(f, of_id, where)
        geom = _polygon(f.geometry, f"{where} ({f.id})")
        category = str(f.props.get("category") or "unspecified")
        uname = text_of(f.props.get("name"), language) or occupants.get(f.id)
        level.units.append((f, geom, category, uname))
        unit_level[f.id] = level
        kind = CONNECTOR_UNITS.get(category)
        places.add(f.id, Place(level.id, level.ordinal, geom, uname, kind), where)
        if uname:
            outline = geom if geom.geom_type == "Polygon" else max(geom.geoms, key=lambda p: p.area)
            # Surveyed outlines carry a vertex every few centimetres on curves; 2 cm is
            # far below what tells one room from another.
            ring = shapely.get_coordinates(shapely.simplify(outline.exterior, SIMPLIFY_M))[:-1]
            regions.append(
                {
                    "name": uname,
                    "polygon": np.round(ring, 4).tolist(),
                    "level": level.id,
                }
            )
    summary.units = len(features["unit"])
    summary.regions = len(regions)
    for i, f in enumerate(features["opening"]):
        where = f"opening.geojson: features[{i}] ({f.id})"
        level = _level_of(f, of_id, f"opening.geojson: features[{i}]")
        line = f.geometry
        if line is not None and line.geom_type == "MultiLineString":
            line = shapely.line_merge(line)
        if line is None or line.geom_type != "LineString" or line.length <= 0:
            raise MapImportError(f"{where}: geometry: expected a LineString of some length")
        level.openings.append((f, line))
    summary.openings = len(features["opening"])
    for i, f in enumerate(features["fixture"]):
        category = str(f.props.get("category") or "unspecified")
        if category in WALL_FIXTURES:
            level = _level_of(f, of_id, f"fixture.geojson: features[{i}]")
            level.solids.append(_polygon(f.geometry, f"fixture.geojson: features[{i}] ({f.id})"))
            summary.fixture_walls[category] += 1
        else:
            summary.fixtures_not_used[category] += 1
    summary.fixtures = len(features["fixture"])
    walls: list[dict[str, object]] = []
    for level in levels:
        made = level_walls(
            [g for _, g, _, _ in level.units],
            [c for _, _, c, _ in level.units],
            [line for _, line in level.openings],
            level.solids,
        )
        summary.gaps += made.gaps
        summary.outer_doors += made.outer
        seen = opening_objects(level, places, summary)
        for f, geom, category, uname in level.units:
            cls = seen_class(category)
            if cls is not None and f.id not in seen:
                x, y = display_point(f, geom, project)
                level.objects.append(map_object(cls, x, y, uname, level.id))
                summary.unit_objects[cls] += 1
        level.walls = made.walls
        walls += [
            {"x1": a, "y1": b, "x2": c, "y2": d, "level": level.id}
            for a, b, c, d in np.round(made.walls, 4).tolist()
        ]
    summary.walls = len(walls)
    amenity_objects(features["amenity"], unit_level, places, language, summary)
    for level in levels:
        summary.snapped += snap_objects(level.objects, level.walls, snap_m)
    made_connectors = connectors(
        [f.props for f in features["relationship"]],
        places,
        summary.report,
        [lv.id for lv in sorted(levels, key=lambda lv: lv.ordinal)],
    )
    summary.shared_ids = places.shared
    summary.relationships = len(features["relationship"])
    summary.connectors.update(str(c["kind"]) for c in made_connectors)
    # A venue of several buildings has one IMDF level per building and floor: say which
    # map levels gathered several (they share an ordinal).
    sources = Counter(lv.id for lv in of_id.values())
    summary.levels = [
        f"{lv.id} {lv.name!r}" + (f" from {sources[lv.id]}" if sources[lv.id] > 1 else "")
        for lv in levels
    ]
    data: dict[str, object] = {
        "name": name,
        "description": description or f"imported from the IMDF venue {src.name}",
        "levels": [
            {
                "id": lv.id,
                "name": lv.name,
                "ordinal": lv.ordinal,
                "elevation_m": round(lv.ordinal * storey_m, 3),
            }
            for lv in levels
        ],
        "walls": walls,
        "objects": [o for lv in levels for o in lv.objects],
        "regions": regions,
        "connectors": made_connectors,
    }
    return data, summary
