"""Walls of one IMDF level: unit outlines, kept where they part spaces, cut at openings.

IMDF draws every space of a floor as a unit polygon; neighbouring units share edges.
An edge is a wall when it parts two different kinds of space: a room from the
corridor, the building from outside. Two open spaces (walkway, lobby, platform...)
drawn as separate units have no wall between them, and neither has a walkway and the
stairs, escalator or ramp that leaves from it. Rooms are entered through openings: an
opening (a line on the room's edge) cuts a gap into that edge as wide as the opening.
An opening in the building's outer edge keeps its wall (the map ends there, so the
door is mounted in it).

How: every unit boundary is noded into one set of segments (shared edges become one
segment), each segment is probed a few centimetres to either side, and the units found
there decide. Probes and containment run through shapely's vectorized STRtree queries,
so a level of hundreds of units takes milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

#: Unit categories of open floor: no wall between two of them.
OPEN_CATEGORIES = frozenset(
    {"walkway", "walkway.island", "lobby", "footbridge", "platform", "unenclosedarea"}
)
#: Unit categories that leave an open floor without a wall (connectors on the level).
PASSAGE_CATEGORIES = frozenset({"stairs", "steps", "escalator", "ramp", "movingwalkway"})
#: Probes either side of an edge, metres.
PROBE_M = 0.05
#: Segments shorter than this (left by snapping) are dropped, metres.
MIN_SEGMENT_M = 0.01
#: Wall polylines are simplified within this tolerance (curved outlines), metres.
SIMPLIFY_M = 0.02


@dataclass(frozen=True)
class LevelWalls:
    """What :func:`level_walls` made of one level.

    Attributes:
        walls: rows (x1, y1, x2, y2), shape (W, 4), metres.
        gaps: openings that cut a gap into a wall.
        outer: openings in the building's outer edge (their wall kept).
    """

    walls: NDArray[np.float64]
    gaps: int
    outer: int


def open_kind(category: str) -> int:
    """0: a room (walled from everything else); 1: open floor; 2: a passage off it."""
    if category in OPEN_CATEGORIES:
        return 1
    if category in PASSAGE_CATEGORIES:
        return 2
    return 0


def _segments(lines: shapely.Geometry) -> NDArray[np.float64]:
    """Every straight piece of (multi)line work as rows (x1, y1, x2, y2)."""
    xy, part = shapely.get_coordinates(shapely.get_parts(lines), return_index=True)
    if xy.shape[0] < 2:
        return np.zeros((0, 4))
    same = part[1:] == part[:-1]
    seg = np.column_stack([xy[:-1][same], xy[1:][same]])
    keep = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) >= MIN_SEGMENT_M
    return seg[keep]


def _side_keys(
    tree: shapely.STRtree, points: NDArray[np.float64], kinds: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per probe point: the index of one unit containing it (-1 for none) and the kind of
    space there (-1 outside every unit, 0 a room, 1 open floor, 2 a passage)."""
    pts = shapely.points(points)
    hit_pt, hit_unit = tree.query(pts, predicate="within")
    unit = np.full(points.shape[0], -1, dtype=np.int64)
    kind = np.full(points.shape[0], -1, dtype=np.int64)
    # Where units overlap, the room (lowest kind) decides: a kiosk drawn on a walkway.
    order = np.lexsort((-kinds[hit_unit], hit_pt))
    for p, u in zip(hit_pt[order], hit_unit[order], strict=True):
        unit[p] = u
        kind[p] = kinds[u]
    return unit, kind


def _tidy(lines: shapely.Geometry) -> shapely.Geometry:
    """Merged into polylines, simplified within ``SIMPLIFY_M``, and dissolved again:
    simplifying collapses slivers thinner than that (surveyed outlines have them) into
    lines that would lie twice over one another."""
    if lines.is_empty:
        return lines
    simplified = shapely.simplify(shapely.line_merge(lines), SIMPLIFY_M, preserve_topology=False)
    return shapely.line_merge(shapely.union_all(shapely.get_parts(simplified)))


#: Segments within these of one another's direction and line are one line (dissolve).
SAME_ANGLE_RAD = 2e-3
SAME_LINE_M = 2e-3
#: Parallel walls closer than this are told apart one pair at a time, metres.
NEAR_LINE_M = 0.05


def _clusters(values: NDArray[np.float64], gap: float) -> list[NDArray[np.int64]]:
    """Indices grouped so that sorted neighbours closer than ``gap`` share a group."""
    order = np.argsort(values, kind="stable")
    cuts = np.flatnonzero(np.diff(values[order]) > gap) + 1
    return np.split(order, cuts)


def _lines(a: NDArray[np.float64], b: NDArray[np.float64]) -> list[NDArray[np.int64]]:
    """Groups of the segments a -> b (about parallel) that lie on one line: each
    shorter segment's ends within ``SAME_LINE_M`` of a longer one's line, chained."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    # Row i's line, column j's ends: |(end_j - a_i) . n_i|.
    off_a = np.abs(np.einsum("ijk,ik->ij", a[None, :, :] - a[:, None, :], n))
    off_b = np.abs(np.einsum("ijk,ik->ij", b[None, :, :] - a[:, None, :], n))
    on = (off_a <= SAME_LINE_M) & (off_b <= SAME_LINE_M) & (length[:, None] >= length[None, :])
    rows, cols = np.nonzero(on)
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(a.shape[0],) * 2)
    count, label = connected_components(graph, directed=False)
    return [np.flatnonzero(label == k) for k in range(count)]


def _merge(seg: NDArray[np.float64], group: NDArray[np.int64]) -> list[NDArray[np.float64]]:
    """The group's segments (one line) with overlapping spans joined along its longest."""
    a, b = seg[group, 0:2], seg[group, 2:4]
    length = np.hypot(*(b - a).T)
    ref = int(np.argmax(length))
    u = (b[ref] - a[ref]) / length[ref]
    lo = np.minimum(a @ u, b @ u)
    hi = np.maximum(a @ u, b @ u)
    base = a[ref] - (a[ref] @ u) * u
    spans = sorted(zip(lo.tolist(), hi.tolist(), group.tolist(), strict=True))
    run = [spans[0]]
    for span in spans[1:]:
        if span[0] < run[-1][1] - MIN_SEGMENT_M:  # overlaps the run: extend it
            last = run[-1]
            run[-1] = (last[0], max(last[1], span[1]), -1)
        else:
            run.append(span)
    return [
        seg[member : member + 1] if member >= 0 else np.r_[base + s0 * u, base + s1 * u][None]
        for s0, s1, member in run
    ]


def dissolve(seg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Collinear segments that overlap, as one (rows x1, y1, x2, y2).

    Segments are about parallel when their directions lie within ``SAME_ANGLE_RAD`` of
    one another (chained in sorted order, so no rounding boundary parts two), then
    near one another's line within ``NEAR_LINE_M`` (measured from their middle), and
    on one line when a shorter one's ends lie within ``SAME_LINE_M`` of a longer one's
    line (tested pair by pair: a short segment's direction is uncertain, the longer
    one's line is not). Along a line, overlapping spans become one segment on the
    longest member's line; a segment that overlaps none is kept as it was.
    """
    if seg.shape[0] < 2:
        return seg
    d = seg[:, 2:4] - seg[:, 0:2]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi)
    # Directions just below pi are those just above 0.
    ang = np.where(ang > np.pi - SAME_ANGLE_RAD, ang - np.pi, ang)
    out = []
    for by_angle in _clusters(ang, SAME_ANGLE_RAD):
        mid = 0.5 * (seg[by_angle, 0:2] + seg[by_angle, 2:4])
        mean = float(np.mean(ang[by_angle]))
        normal = np.array([-np.sin(mean), np.cos(mean)])
        offset = (mid - mid.mean(axis=0)) @ normal
        for near in _clusters(offset, NEAR_LINE_M):
            members = by_angle[near]
            if members.size == 1:
                out.append(seg[members])
                continue
            for line in _lines(seg[members, 0:2], seg[members, 2:4]):
                out += _merge(seg, members[line])
    return np.vstack(out)


def level_walls(
    units: list[shapely.Polygon],
    categories: list[str],
    openings: list[shapely.LineString],
    solids: list[shapely.Polygon],
) -> LevelWalls:
    """The walls of one level, in metres.

    Args:
        units: the level's unit polygons (metres).
        categories: each unit's IMDF category.
        openings: the level's openings (metres).
        solids: outlines kept whole as walls (fixtures that block the way).
    """
    if not units:
        return LevelWalls(np.zeros((0, 4)), 0, 0)
    polys = np.array(units, dtype=object)
    kinds = np.array([open_kind(c) for c in categories], dtype=np.int64)
    noded = shapely.union_all(shapely.boundary(polys))
    seg = _segments(noded)
    a, b = seg[:, 0:2], seg[:, 2:4]
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    normal = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    mid = 0.5 * (a + b)
    tree = shapely.STRtree(polys)
    left_unit, left = _side_keys(tree, mid + PROBE_M * normal, kinds)
    right_unit, right = _side_keys(tree, mid - PROBE_M * normal, kinds)
    same = left_unit == right_unit
    open_pair = ((left == 1) & (right >= 1)) | ((right == 1) & (left >= 1))
    wall = ~same & ~open_pair
    outer = wall & ((left < 0) | (right < 0))
    kept = seg[wall]
    outer_lines = shapely.linestrings(seg[outer].reshape(-1, 2, 2)) if outer.any() else []
    cut = 0
    at_edge = 0
    walls_geom: shapely.Geometry = (
        shapely.multilinestrings(shapely.linestrings(kept.reshape(-1, 2, 2)))
        if kept.size
        else shapely.from_wkt("MULTILINESTRING EMPTY")
    )
    if openings:
        outer_geom = (
            shapely.union_all(np.array(outer_lines, dtype=object))
            if len(outer_lines)
            else shapely.from_wkt("LINESTRING EMPTY")
        )
        lines = np.array(openings, dtype=object)
        at_outer = shapely.covers(shapely.buffer(outer_geom, PROBE_M), lines)
        at_edge = int(at_outer.sum())
        holes = shapely.buffer(lines[~at_outer], PROBE_M, cap_style="flat")
        cut = int(shapely.intersects(walls_geom, holes).sum())
        if holes.size:
            walls_geom = shapely.difference(walls_geom, shapely.union_all(holes))
    # Rounded to the 0.1 mm the map file keeps first: two ends a few hundredths of a
    # millimetre apart (left by simplifying) would make two walls the file has twice.
    out = dissolve(np.round(_segments(_tidy(walls_geom)), 4))
    if solids:
        out = np.vstack([out, _segments(shapely.union_all(shapely.boundary(np.array(solids))))])
    return LevelWalls(out, cut, at_edge)
