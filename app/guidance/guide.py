"""From a pose and a plan to directions: where the target is, and where to turn next.

Bearings here follow docs/API.md: degrees relative to the person's forward direction,
counter-clockwise positive (left +90), wrapped to (-180, 180]. Clock hours are the
speaker's business (app.feedback) and the wire's (app.api).

On a venue with several levels, while the way goes through a connector (a lift,
stairs, an escalator, a ramp) to another level, the directions lead to that
connector's stop and :attr:`Guidance.connector` says which it is and where it goes;
on the next level the directions go on from there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.guidance.planner import Plan
from app.maps.geometry import wrap_deg
from app.maps.levels import Level

#: Within this walking distance of the target the person has arrived (metres).
ARRIVED_M = 1.0


@dataclass(frozen=True)
class NextTurn:
    """The next turn of the path: its direction and distance from the person, and the
    direction of the leg after it relative to the leg before it (degrees)."""

    bearing_deg: float
    distance_m: float
    then_deg: float


@dataclass(frozen=True)
class ConnectorStep:
    """The change of level the way takes next.

    Attributes:
        id, kind, label: the connector (kind: elevator, stairs, escalator or ramp).
        direction: "up" or "down".
        to_level: the level the ride ends on.
        at_stop: the person stands at the connector's stop (within ``ARRIVED_M`` of
            its middle): time to take it.
    """

    id: str
    kind: str
    label: str | None
    direction: str
    to_level: Level
    at_stop: bool


@dataclass(frozen=True)
class Guidance:
    """Directions to the destination from one pose.

    Attributes:
        target: the destination as spoken ("main entrance", "door", "Kitchen").
        bearing_deg: direction of the target (the path's end) from the person.
        distance_m: straight-line distance to it.
        path_m: walking distance along the shortest path.
        next: the next turn, or None when the target is straight ahead in a clear line.
        arrived: within ``ARRIVED_M`` of it, walking.
        path: the path's points from the person to the target, shape (P, 2), metres,
            in the map's plane (app.maps.levels).
        connector: while the way changes level next, the connector it takes; then
            ``bearing_deg``, ``distance_m``, ``path_m``, ``next`` and ``path`` lead to
            that connector's stop, and ``arrived`` is false.
    """

    target: str
    bearing_deg: float
    distance_m: float
    path_m: float
    next: NextTurn | None
    arrived: bool
    path: NDArray[np.float64]
    connector: ConnectorStep | None = None


def _heading_deg(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    return math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))


def guide(
    plan: Plan, x: float, y: float, theta_rad: float, level: int | str | None = None
) -> Guidance:
    """Directions from pose (x, y, theta) to the plan's target.

    Args:
        x, y: metres, in the frame of ``level`` (its index or id) when one is given,
            else in the map's plane (the file's frame for a map without levels).

    Raises:
        Unreachable: no walkable path from this pose (see :meth:`Plan.route`).
    """
    route = plan.route(x, y, level)
    pts = route.points  # straightened, small bends merged
    here = pts[0]
    end = pts[-1]
    heading = math.degrees(theta_rad)
    rel = end - here
    distance = float(np.hypot(*rel))
    bearing = wrap_deg(_heading_deg(here, end) - heading) if distance > 1e-9 else 0.0
    turn = None
    if len(pts) > 2:
        corner = pts[1]
        first = _heading_deg(here, corner)
        second = _heading_deg(corner, pts[2])
        turn = NextTurn(
            bearing_deg=round(wrap_deg(first - heading), 1),
            distance_m=round(float(np.hypot(*(corner - here))), 2),
            then_deg=round(wrap_deg(second - first), 1),
        )
    name = plan.target.name
    if route.end_object >= 0 and plan.target.kind == "class":
        label = plan.map.object_labels[route.end_object]
        name = f"{name} ({label})" if label and label.casefold() != name else name
    step = None
    if route.ride is not None:
        ride = route.ride
        step = ConnectorStep(
            id=ride.connector.id,
            kind=ride.connector.kind,
            label=ride.connector.label,
            direction=ride.direction,
            to_level=plan.map.layout.levels[ride.to_level],
            at_stop=route.length_m <= ARRIVED_M,
        )
    return Guidance(
        target=name,
        bearing_deg=round(bearing, 1),
        distance_m=round(distance, 2),
        path_m=round(route.length_m, 2),
        next=turn,
        arrived=step is None and route.length_m <= ARRIVED_M,
        path=pts,
        connector=step,
    )
