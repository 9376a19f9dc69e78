"""Objects of an IMDF venue's level: doors, elevators, restrooms, the other units a
detector sees, and amenities (what each becomes: :mod:`app.maps.importers.imdf`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import shapely

from app.maps.importers.common import MapImportError
from app.maps.importers.imdf_connectors import CONNECTOR_UNITS, POINT_STOP_M, Place, Places
from app.maps.importers.imdf_read import Feature, Projector, class_word, text_of
from app.maps.importers.imdf_summary import ImdfSummary
from app.maps.importers.imdf_walls import open_kind

#: An opening belongs to the units within this distance of it, metres.
TOUCH_M = 0.05


@dataclass
class LevelParts:
    """One map level being built: its IMDF features (metres) and its objects."""

    id: str
    ordinal: int
    name: str
    units: list[tuple[Feature, shapely.Geometry, str, str | None]] = field(default_factory=list)
    openings: list[tuple[Feature, shapely.LineString]] = field(default_factory=list)
    solids: list[shapely.Geometry] = field(default_factory=list)
    objects: list[dict[str, object]] = field(default_factory=list)
    walls: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))


def seen_class(category: str) -> str | None:
    """The object class of a unit a detector sees, or None."""
    if category in CONNECTOR_UNITS and category != "ramp":
        return CONNECTOR_UNITS[category]
    return "restroom" if category.split(".")[0] == "restroom" else None


def _round(x: float) -> float:
    return round(float(x), 4)


def display_point(f: Feature, geom: shapely.Geometry, project: Projector) -> tuple[float, float]:
    """The feature's curated display point in metres, else a point inside its geometry."""
    dp = f.props.get("display_point")
    if isinstance(dp, dict) and isinstance(dp.get("coordinates"), list):
        try:
            x, y = project([dp["coordinates"][:2]])[0]
            return float(x), float(y)
        except (ValueError, TypeError):
            pass
    p = geom.representative_point()
    return p.x, p.y


def map_object(cls: str, x: float, y: float, label: str | None, level: str) -> dict[str, object]:
    """An object of the map file (0.1 mm)."""
    obj: dict[str, object] = {"class": cls, "x": _round(x), "y": _round(y)}
    if label:
        obj["label"] = label
    obj["level"] = level
    return obj


def opening_objects(level: LevelParts, places: Places, summary: ImdfSummary) -> set[str]:
    """Doors, elevators and restrooms at the level's openings; the ids of the units
    that got their object there."""
    seen: set[str] = set()
    if not level.units:
        return seen
    polys = [g for _, g, _, _ in level.units]
    tree = shapely.STRtree(polys)
    for f, line in level.openings:
        mid = line.interpolate(0.5, normalized=True)
        touching = [level.units[int(k)] for k in tree.query(line.buffer(TOUCH_M), "intersects")]
        lift = next((u for u in touching if u[2] == "elevator"), None)
        name = text_of(f.props.get("name"), "en")
        if lift is not None:
            level.objects.append(map_object("elevator", mid.x, mid.y, lift[3], level.id))
            summary.unit_objects["elevator"] += 1
            seen.add(lift[0].id)
        else:
            room = next((u for u in touching if u[3] and open_kind(u[2]) == 0), None)
            label = name or (f"door to {room[3]}" if room is not None else None)
            level.objects.append(map_object("door", mid.x, mid.y, label, level.id))
            summary.doors += 1
        for unit in touching:
            if seen_class(unit[2]) == "restroom":
                level.objects.append(map_object("restroom", mid.x, mid.y, unit[3], level.id))
                summary.unit_objects["restroom"] += 1
                seen.add(unit[0].id)
        places.add(
            f.id,
            Place(level.id, level.ordinal, line.buffer(POINT_STOP_M, quad_segs=2), name, None),
            f"opening.geojson ({f.id})",
        )
    return seen


def amenity_objects(
    features: list[Feature],
    unit_level: Mapping[str, LevelParts],
    places: Places,
    language: str,
    summary: ImdfSummary,
) -> None:
    """Each amenity an object of its category's word, on its unit's level."""
    for i, f in enumerate(features):
        geom = f.geometry
        if geom is None or geom.geom_type != "Point":
            raise MapImportError(
                f"amenity.geojson: features[{i}] ({f.id}): geometry: expected a Point"
            )
        cls = class_word(f.props.get("category"))
        units = f.props.get("unit_ids")
        level = (
            next((unit_level[u] for u in units if isinstance(u, str) and u in unit_level), None)
            if isinstance(units, list)
            else None
        )
        if cls is None:
            summary.amenities_not_used[str(f.props.get("category"))] += 1
            continue
        if level is None:
            summary.amenities_not_used["in no unit of a level"] += 1
            continue
        label = text_of(f.props.get("name"), language)
        level.objects.append(map_object(cls, geom.x, geom.y, label, level.id))
        summary.amenity_objects[cls] += 1
        places.add(
            f.id,
            Place(level.id, level.ordinal, geom.buffer(POINT_STOP_M, quad_segs=2), label, None),
            f"amenity.geojson: features[{i}]",
        )
    summary.amenities = len(features)
