"""Connectors of an IMDF venue: where a person changes level, and how.

Two sources, in this order:

* **Relationships** of category elevator, escalator, stairs or ramp (IMDF's
  Relationship: an origin, optional intermediaries and a destination, each a reference
  to a unit, an opening or an amenity). Each becomes one connector; the features it
  references give its stops, one per level. A ``directed`` relationship goes one way:
  up when its destination's level lies above its origin's, else down.
* **Overlap** for the elevator, escalator, stairs and ramp units no relationship names:
  units of one kind whose footprints overlap on different levels are one connector (a
  lift shaft seen on every floor it serves, a stairwell floor after floor). Stairs,
  escalators and ramps join only neighbouring levels (a chain of them joins several).
  Their direction is unknown, so ``both``; an escalator's is needed (guiding someone
  onto one the wrong way is no guidance), so escalators joined only by overlap are
  left out, and said so.

A stop's polygon is the unit's outline; an opening or an amenity stands for the metre
and a half around it.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely

#: IMDF unit categories that are a way between levels, and the connector kind of each.
CONNECTOR_UNITS = {
    "elevator": "elevator",
    "escalator": "escalator",
    "stairs": "stairs",
    "steps": "stairs",
    "ramp": "ramp",
}
#: Relationship categories read as connectors (the rest, e.g. traversal, are not used).
CONNECTOR_RELATIONSHIPS = frozenset({"elevator", "escalator", "stairs", "ramp"})
#: Footprints overlapping by at least this share of the smaller one are one connector.
MIN_OVERLAP = 0.2
#: An opening or an amenity in a relationship stands for this much around it, metres.
POINT_STOP_M = 1.5


@dataclass(frozen=True)
class Place:
    """A feature a connector can stop at: its map level (id and ordinal), outline, name."""

    level: str
    ordinal: int
    polygon: shapely.Polygon
    name: str | None
    kind: str | None  # the connector kind of a connector unit, else None


class Places(dict[str, Place]):
    """The features a connector can stop at, by IMDF id (relationships name them so).

    IMDF ids are unique across a venue's files, but real exports are not always: one
    seen here gave an amenity the id of a stairs unit, and the amenity, read later,
    took the stairs' place, so that the stairs lost a floor. The first feature read
    with an id keeps it (units are read first: the outlines a connector stands on);
    later ones are not stops and are listed in :attr:`shared`.
    """

    def __init__(self) -> None:
        super().__init__()
        self._where: dict[str, str] = {}
        #: Features whose id an earlier one had, said as "<file and feature> has the
        #: id of <the first> (<id>)".
        self.shared: list[str] = []

    def add(self, fid: str, place: Place, where: str) -> None:
        """``place`` under ``fid``, unless a feature read before has that id."""
        if fid in self:
            self.shared.append(f"{where} has the id of {self._where[fid]} ({fid})")
            return
        self[fid] = place
        self._where[fid] = where


@dataclass
class ConnectorReport:
    """What was made of relationships and connector units (for the import summary)."""

    from_relationships: int = 0
    by_overlap: int = 0
    not_used: dict[str, int] = field(default_factory=dict)
    #: Stairs, escalators and ramps whose next stop lies more than one map level away
    #: ("stairs-1 goes from L3 to L5, with no stop on L4"): a flight that passes a floor
    #: without a door to it, or a unit missing on that floor; worth a look.
    skipping: list[str] = field(default_factory=list)

    def skip(self, why: str) -> None:
        self.not_used[why] = self.not_used.get(why, 0) + 1


def _outline(poly: shapely.Geometry) -> list[list[float]]:
    """The exterior ring of the largest part, without the closing point, 0.1 mm."""
    if poly.geom_type != "Polygon":
        poly = max(shapely.get_parts(poly), key=lambda p: p.area)
    return np.round(shapely.get_coordinates(poly.exterior)[:-1], 4).tolist()


def _stops(places: list[Place]) -> list[dict[str, object]]:
    by_level: dict[str, list[Place]] = {}
    for p in places:
        by_level.setdefault(p.level, []).append(p)
    ordered = sorted(by_level.values(), key=lambda ps: ps[0].ordinal)
    return [
        {"level": ps[0].level, "polygon": _outline(shapely.union_all([p.polygon for p in ps]))}
        for ps in ordered
    ]


def _label(kind: str, places: list[Place], counts: dict[str, int]) -> str:
    for p in places:
        if p.name:
            return p.name
    counts[kind] = counts.get(kind, 0) + 1
    return f"{kind} {counts[kind]}"


def connectors(
    relationships: list[Mapping[str, object]],
    places: Mapping[str, Place],
    report: ConnectorReport,
    levels: Sequence[str] = (),
) -> list[dict[str, object]]:
    """The map file's ``connectors``.

    Args:
        relationships: the IMDF relationship features' properties.
        places: every unit, opening and amenity by IMDF id (units carry their kind).
        report: counts what was used and why the rest was not.
        levels: the map's level ids from the lowest up, to say which stairs, escalators
            and ramps pass a level without a stop (``report.skipping``).
    """
    out: list[dict[str, object]] = []
    used: set[str] = set()
    labels: dict[str, int] = {}
    for props in relationships:
        category = str(props.get("category"))
        if category not in CONNECTOR_RELATIONSHIPS:
            report.skip(f"relationship {category}")
            continue
        refs = [props.get("origin"), *(props.get("intermediary") or []), props.get("destination")]  # type: ignore[misc]
        ids = [r.get("id") for r in refs if isinstance(r, dict)]
        found = [places[i] for i in ids if isinstance(i, str) and i in places]
        if len({p.level for p in found}) < 2:
            report.skip(f"relationship {category} on fewer than two levels")
            continue
        direction = "both"
        origin, destination = (
            places.get(_ref_id(props.get("origin"))),
            places.get(_ref_id(props.get("destination"))),
        )
        directed = props.get("direction") == "directed"
        if directed and origin and destination and origin.ordinal != destination.ordinal:
            direction = "up" if destination.ordinal > origin.ordinal else "down"
        if category == "escalator" and (direction == "both" or len({p.level for p in found}) != 2):
            # Guiding someone onto an escalator the wrong way is no guidance.
            report.skip("escalator relationship without a direction between two levels")
            continue
        used.update(i for i in ids if isinstance(i, str))
        out.append(
            {
                "kind": category,
                "label": _label(category, found, labels),
                "direction": direction,
                "stops": _stops(found),
            }
        )
        report.from_relationships += 1
    for kind in ("elevator", "escalator", "stairs", "ramp"):
        members = [(i, p) for i, p in places.items() if p.kind == kind and i not in used]
        for group in _overlapping(members, adjacent_only=kind != "elevator"):
            if len({p.level for p in group}) < 2:
                report.skip(f"{kind} unit on one level only")
                continue
            if kind == "escalator":
                report.skip("escalator units with no directed relationship (way unknown)")
                continue
            out.append(
                {
                    "kind": kind,
                    "label": _label(kind, group, labels),
                    "direction": "both",
                    "stops": _stops(group),
                }
            )
            report.by_overlap += 1
    counts: dict[str, int] = {}
    rank = {level: i for i, level in enumerate(levels)}
    for c in out:
        k = str(c["kind"])
        counts[k] = counts.get(k, 0) + 1
        c["id"] = f"{k}-{counts[k]}"
        if k == "elevator":
            continue  # (a lift passes floors it does not serve)
        stops = [str(s["level"]) for s in c["stops"]]  # type: ignore[attr-defined]
        for a, b in itertools.pairwise(stops):
            if a in rank and b in rank and rank[b] - rank[a] > 1:
                between = ", ".join(levels[rank[a] + 1 : rank[b]])
                report.skipping.append(f"{c['id']} goes from {a} to {b}, with no stop on {between}")
    return [{"id": c.pop("id"), **c} for c in out]


def _ref_id(ref: object) -> str:
    return str(ref.get("id")) if isinstance(ref, dict) else ""


def _overlapping(members: list[tuple[str, Place]], adjacent_only: bool) -> list[list[Place]]:
    """Groups of places joined by overlapping footprints on different levels."""
    if not members:
        return []
    places = [p for _, p in members]
    ordinals = sorted({p.ordinal for p in places})
    rank = {o: i for i, o in enumerate(ordinals)}
    parent = list(range(len(places)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    tree = shapely.STRtree([p.polygon for p in places])
    left, right = tree.query([p.polygon for p in places], predicate="intersects")
    for i, j in zip(left.tolist(), right.tolist(), strict=True):
        a, b = places[i], places[j]
        if i >= j or a.level == b.level:
            continue
        if adjacent_only and abs(rank[a.ordinal] - rank[b.ordinal]) != 1:
            continue
        shared = a.polygon.intersection(b.polygon).area
        if shared >= MIN_OVERLAP * min(a.polygon.area, b.polygon.area):
            parent[root(i)] = root(j)
    groups: dict[int, list[Place]] = {}
    for i, p in enumerate(places):
        groups.setdefault(root(i), []).append(p)
    return sorted(groups.values(), key=lambda g: (g[0].ordinal, g[0].polygon.bounds))
