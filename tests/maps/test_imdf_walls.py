"""Walls from IMDF unit outlines (app/maps/importers/imdf_walls.py), in metres."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from app.maps.check import _overlapping_walls
from app.maps.geometry import segments_cross_walls
from app.maps.importers.imdf_walls import MIN_SEGMENT_M, dissolve, level_walls


def box(x0: float, y0: float, x1: float, y1: float) -> shapely.Polygon:
    return shapely.box(x0, y0, x1, y1)


def crosses(walls: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> bool:
    return bool(segments_cross_walls([a], [b], walls)[0])


def test_open_floor_rooms_openings_and_the_outer_edge() -> None:
    # A corridor split in two walkway units, a room north of the east half with a 1 m
    # door, stairs north of the west half, and an opening in the outer south edge.
    units = [box(0, 0, 5, 3), box(5, 0, 10, 3), box(5, 3, 10, 7), box(0, 3, 5, 7)]
    categories = ["walkway", "walkway", "room", "stairs"]
    door = shapely.LineString([(7, 3), (8, 3)])
    entrance = shapely.LineString([(2, 0), (3, 0)])
    made = level_walls(units, categories, [door, entrance], [])
    w = made.walls
    assert not crosses(w, (2.5, 1.5), (7.5, 1.5))  # walkway to walkway
    assert not crosses(w, (2.5, 1.5), (2.5, 5.0))  # walkway to its stairs
    assert not crosses(w, (7.5, 1.5), (7.5, 5.0))  # through the door
    assert crosses(w, (6.0, 1.5), (6.0, 5.0))  # beside it
    assert crosses(w, (8.6, 1.5), (8.6, 5.0))
    assert crosses(w, (4.0, 5.0), (6.0, 5.0))  # stairs to room: a wall
    assert crosses(w, (2.5, 1.0), (2.5, -1.0))  # the entrance keeps its wall
    assert (made.gaps, made.outer) == (1, 1)
    # The gap is as wide as the opening.
    on_edge = w[(np.abs(w[:, 1] - 3) < 1e-9) & (np.abs(w[:, 3] - 3) < 1e-9)]
    xs = np.sort(on_edge[:, [0, 2]], axis=1)
    assert np.allclose(sorted(map(tuple, xs)), [(5.0, 7.0), (8.0, 10.0)], atol=1e-6)


def test_a_blocking_fixture_is_walled_whole() -> None:
    made = level_walls([box(0, 0, 10, 4)], ["walkway"], [], [box(4, 1, 6, 2)])
    assert crosses(made.walls, (3, 1.5), (7, 1.5))
    assert not crosses(made.walls, (3, 3), (7, 3))


@settings(max_examples=60, deadline=None)
@given(
    spans=st.lists(st.tuples(st.floats(-50, 50), st.floats(0.5, 20)), min_size=1, max_size=12),
    angle=st.floats(0, np.pi),
    offset=st.floats(-100, 100),
    flip=st.lists(st.booleans(), min_size=12, max_size=12),
)
def test_dissolve_leaves_no_overlap_and_covers_the_same_line(
    spans: list[tuple[float, float]], angle: float, offset: float, flip: list[bool]
) -> None:
    u = np.array([np.cos(angle), np.sin(angle)])
    base = offset * np.array([-u[1], u[0]])
    rows = []
    for (s, length), f in zip(spans, flip, strict=False):
        a, b = base + s * u, base + (s + length) * u
        rows.append(np.r_[b, a] if f else np.r_[a, b])
    seg = np.round(np.array(rows), 4)
    out = dissolve(seg)
    assert _overlapping_walls("t", out) == []
    # The line covered: the union of the spans, each once (overlaps under a centimetre,
    # which map check does not report either, may stay). Spans of half a metre and more:
    # rounded to 0.1 mm, a shorter one's direction is too uncertain to call it collinear.
    covered, reach = 0.0, -np.inf
    for lo, hi in sorted((s, s + length) for s, length in spans):
        covered += max(hi - max(lo, reach), 0.0)
        reach = max(reach, hi)
    assert np.hypot(out[:, 2] - out[:, 0], out[:, 3] - out[:, 1]).sum() == (
        pytest.approx(covered, abs=MIN_SEGMENT_M * len(spans))
    )
    before = shapely.linestrings(seg.reshape(-1, 2, 2))
    after = shapely.union_all(shapely.linestrings(out.reshape(-1, 2, 2)))
    # How far the merged line may stray: each end rounded by up to half 1e-4 in x and y
    # (r), a merged segment lies on its longest member's line, whose direction those
    # roundings turn by up to 2 r / its length, over up to the line's whole extent; and
    # the input lies up to r off the true line on the other side.
    r = 0.5e-4 * np.sqrt(2.0)
    lo = min(s for s, _ in spans)
    extent = max(s + length for s, length in spans) - lo
    longest = max(length for _, length in spans)
    bound = 2.0 * r + 2.0 * r * extent / longest
    assert shapely.union_all(before).hausdorff_distance(after) <= bound
