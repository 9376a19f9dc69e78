"""Demo walks on any map with levels: walk to a connector, ride it, walk on.

For the made-up venue of :mod:`app.simulation.venue` the demo takes its suite's walk
(lift, stairs and both escalators); on any other venue (an imported one) it plans one:
from a free point on a level the connector serves, the shortest walkable path to the
connector's stop (:mod:`app.guidance.planner`), the ride to another level it serves
(an elevator preferred, an escalator only its way), and the path from the stop there to
a free point of that level.
"""

from __future__ import annotations

import numpy as np

from app.guidance.planner import Unreachable, plan_for
from app.guidance.targets import DestinationSpec
from app.maps.levels import Connector
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared
from app.simulation.venue import VENUE_NAME, venue_legs
from app.simulation.venue_walk import Leg, Ride, Walk

#: Connector kinds in the order a demo prefers them.
PREFERRED = ("elevator", "escalator", "stairs", "ramp")
#: Free points tried for each end of the walk.
TRIES = 60


def _path(
    semantic_map: SemanticMap, level: int, end: np.ndarray, rng: np.random.Generator, away: bool
) -> tuple[tuple[float, float], ...] | None:
    """A walk on ``level`` (file frame) from a random free point to ``end`` (plane), or
    from ``end`` to one when ``away``; None when no free point there reaches it."""
    layout = semantic_map.layout
    fs = semantic_map.free_space
    off = float(layout.offsets(level))
    for _ in range(TRIES):
        p = fs.sample(1, rng)[0]
        if layout.level_of(p[0]) != level:
            continue
        if float(np.hypot(*(p - end))) < 4.0:
            continue
        a, b = (end, p) if away else (p, end)
        # A point destination on a venue is in its level's frame, with the level.
        file_xy, on_level = layout.from_plane(b[None])
        level_id = layout.levels[int(on_level[0])].id
        to = DestinationSpec(
            "point", x=float(file_xy[0, 0]), y=float(file_xy[0, 1]), level=level_id
        )
        try:
            plan = plan_for(semantic_map, to)
            route = plan.route(float(a[0]), float(a[1]))
        except (Unreachable, ValueError):
            continue
        pts = route.points
        return tuple((round(float(x) - off, 3), round(float(y), 3)) for x, y in pts)
    return None


def _ends(conn: Connector) -> tuple[int, int]:
    """The stops (indexes) a demo rides from and to: up unless the connector runs down."""
    if conn.direction == "down":
        return len(conn.stops) - 1, len(conn.stops) - 2
    return 0, 1


def demo_legs(semantic_map: SemanticMap, rng: np.random.Generator) -> tuple[str, list[Leg]]:
    """A start level's id and the legs of a demo walk with one ride.

    Raises:
        ValueError: the map has no levels, or no connector can be walked to and from.
    """
    semantic_map = ensure_prepared(semantic_map)
    layout = semantic_map.layout
    if not layout.has_levels:
        raise ValueError(f"map {semantic_map.name!r} has no levels")
    if semantic_map.name == VENUE_NAME:
        return venue_legs()
    order = sorted(
        layout.connectors,
        key=lambda c: PREFERRED.index(c.kind) if c.kind in PREFERRED else len(PREFERRED),
    )
    for conn in order:
        i, j = _ends(conn)
        src, dst = conn.stops[i], conn.stops[j]
        here = src.plane_polygon.mean(axis=0)
        there = dst.plane_polygon.mean(axis=0)
        if not (semantic_map.free_space.is_free(*here) and semantic_map.free_space.is_free(*there)):
            continue
        first = _path(semantic_map, src.level, here, rng, away=False)
        last = _path(semantic_map, dst.level, there, rng, away=True)
        if first is None or last is None:
            continue
        off = float(layout.offsets(dst.level))
        ride_to = ((round(float(there[0]) - off, 3), round(float(there[1]), 3)),)
        ride = Ride(
            conn.kind,
            layout.levels[dst.level].id,
            () if conn.kind == "elevator" else ride_to,
            wait_s=3.0 if conn.kind == "elevator" else 0.0,
        )
        return layout.levels[src.level].id, [Walk(first), ride, Walk(last[1:] or last)]
    raise ValueError(f"map {semantic_map.name!r}: no connector can be walked to and from")
