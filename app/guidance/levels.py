"""The walkable graph of a venue's levels, joined at its connectors.

The map's free space already holds every level side by side in one plane
(:mod:`app.maps.levels`), fenced apart, so each level's walkable cells form their own
part of the planner's grid graph. Here the parts are joined: every connector stop is
one extra node, tied to the walkable cells inside its polygon, and every ride a
connector offers (:meth:`~app.maps.levels.Connector.reachable`: a lift to any level it
serves, stairs and escalators to the next, escalators only their way) is an edge from
one stop's node to another's.

Costs are in metres of walking, so that one shortest-path search weighs a longer walk
against a slower ride:

* a cell to its stop's node: 1.1 x the distance to the stop's middle, plus 0.5 m, so
  the path walks to the middle before it rides and no path takes a stop's node as a
  shortcut across the stop (the grid's own detour is at most 8.3 %);
* a ride: a fixed part (waiting for a lift) plus a part per metre of height
  (:data:`RIDE_BASE_M`, :data:`RIDE_PER_M`): stairs count three metres of walking per
  metre climbed, an escalator two, a ramp twelve (its run at the 1:12 gradient
  accessibility codes allow), a lift one and 20 m of waiting.

``step_free`` leaves out everything but lifts and ramps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.maps.geometry import points_in_polygon
from app.maps.levels import Connector, LevelLayout

#: Connector kinds a person who needs a step-free way can take.
STEP_FREE_KINDS = frozenset({"elevator", "ramp"})
#: Fixed cost of a ride, metres of walking (waiting for the lift).
RIDE_BASE_M = {"elevator": 20.0, "escalator": 2.0, "stairs": 2.0, "ramp": 0.0}
#: Cost per metre of height, metres of walking.
RIDE_PER_M = {"elevator": 1.0, "escalator": 2.0, "stairs": 3.0, "ramp": 12.0}
#: Walking to a stop's node: this factor on the distance to its middle, plus ENTRY_M.
ENTRY_FACTOR = 1.1
ENTRY_M = 0.5


@dataclass(frozen=True)
class StopNode:
    """A connector's stop on one level as a graph node; ``centre`` in the plane."""

    connector: Connector
    level: int
    centre: NDArray[np.float64]


def stop_nodes(layout: LevelLayout, step_free: bool) -> list[StopNode]:
    """Every stop of every connector the person may take."""
    out = []
    for conn in layout.connectors:
        if step_free and conn.kind not in STEP_FREE_KINDS:
            continue
        for stop in conn.stops:
            out.append(StopNode(conn, stop.level, stop.plane_polygon.mean(axis=0)))
    return out


def entry_edges(
    stops: list[StopNode], layout: LevelLayout, centres: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """(cell, stop, cost) for every walkable cell inside a stop's polygon.

    Args:
        centres: the walkable cells' centres in the plane, shape (n, 2).
    """
    cells, which, cost = [], [], []
    for s, node in enumerate(stops):
        stop = node.connector.stop_on(node.level)
        assert stop is not None  # stop_nodes took it from the connector
        poly = stop.plane_polygon
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        box = np.flatnonzero(np.all((centres >= lo) & (centres <= hi), axis=1))
        inside = box[points_in_polygon(centres[box], poly)] if box.size else box
        d = np.hypot(*(centres[inside] - node.centre).T)
        cells.append(inside)
        which.append(np.full(inside.size, s, dtype=np.int64))
        cost.append(ENTRY_FACTOR * d + ENTRY_M)
    if not cells:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(cells), np.concatenate(which), np.concatenate(cost)


def ride_cost_m(kind: str, height_m: float) -> float:
    """The cost of one ride over ``height_m`` metres of height, metres of walking."""
    return RIDE_BASE_M[kind] + RIDE_PER_M[kind] * abs(height_m)


def ride_edges(
    stops: list[StopNode], layout: LevelLayout
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """(from stop, to stop, cost) for every ride, in the direction it is taken."""
    index = {(id(n.connector), n.level): s for s, n in enumerate(stops)}
    src, dst, cost = [], [], []
    for s, node in enumerate(stops):
        for to in node.connector.reachable(node.level):
            t = index.get((id(node.connector), to))
            if t is None:
                continue
            dz = layout.levels[to].elevation_m - layout.levels[node.level].elevation_m
            src.append(s)
            dst.append(t)
            cost.append(ride_cost_m(node.connector.kind, dz))
    return (
        np.array(src, dtype=np.int64),
        np.array(dst, dtype=np.int64),
        np.array(cost, dtype=np.float64),
    )


@dataclass(frozen=True)
class Ride:
    """The next change of level on a route: which connector, from and to which level
    (indices), and the way it goes."""

    connector: Connector
    from_level: int
    to_level: int

    @property
    def direction(self) -> str:
        return "up" if self.to_level > self.from_level else "down"
