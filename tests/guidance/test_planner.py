"""Shortest walkable paths and directions: around walls, in free space, to arrival."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.guidance import (
    ARRIVED_M,
    DestinationSpec,
    UnknownDestination,
    Unreachable,
    guide,
    plan_for,
)
from app.guidance.planner import CACHE_SIZE
from app.maps.check import load_map
from app.maps.geometry import segments_cross_walls
from app.maps.model import SemanticMap, parse_map
from app.resources import bundled_maps_dir

SUITE = load_map(bundled_maps_dir() / "office_suite.json")
#: Office 1 of the suite, behind the corridor wall y = 3 from the main entrance.
IN_OFFICE_1 = (3.0, 8.0)


def _in_free_space(m: SemanticMap, a, b, *, skip_end_m: float = 0.0) -> bool:
    """Every point of the segment a -> b (but the last ``skip_end_m``) is in free space."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.hypot(*(b - a)))
    n = max(int(length / 0.02), 1)
    f = np.linspace(0.0, 1.0, n + 1)
    f = f[f * length <= length - skip_end_m + 1e-9]
    pts = a + f[:, None] * (b - a)
    return bool(m.free_space.is_free(pts[:, 0], pts[:, 1]).all())


def test_the_path_around_a_wall_stays_in_free_space() -> None:
    plan = plan_for(SUITE, DestinationSpec("label", "main entrance"))
    g = guide(plan, *IN_OFFICE_1, 0.0)
    door = SUITE.object_xy[SUITE.object_labels.index("main entrance")]
    # The straight line is blocked by the corridor wall; the path is not.
    assert segments_cross_walls([IN_OFFICE_1], [door], SUITE.walls)[0]
    assert g.next is not None and len(g.path) >= 3
    legs = list(zip(g.path[:-1], g.path[1:], strict=True))
    for a, b in legs[:-1]:
        assert _in_free_space(SUITE, a, b)
    # The last leg ends at the door, in the wall; it stays free until the door's reach.
    assert _in_free_space(SUITE, *legs[-1], skip_end_m=0.3)
    assert g.path_m == pytest.approx(float(np.hypot(*np.diff(g.path, axis=0).T).sum()), abs=0.01)
    assert g.path_m > g.distance_m
    assert not g.arrived


@pytest.mark.parametrize(
    ("spec", "start"),
    [
        (DestinationSpec("label", "main entrance"), IN_OFFICE_1),
        (DestinationSpec("label", "printer"), IN_OFFICE_1),
        (DestinationSpec("region", "Office 3"), (2.0, 1.5)),
        (DestinationSpec("point", x=11.0, y=8.0), (16.0, 8.0)),
        (DestinationSpec("class", "plant"), (18.0, 8.0)),
    ],
)
def test_following_every_next_direction_stays_in_free_space_and_arrives(spec, start) -> None:
    """Walk 0.2 m at a time wherever the guidance points; never leave the free space."""
    plan = plan_for(SUITE, spec)
    pos = np.array(start, dtype=float)
    theta = 1.0
    for _ in range(400):
        g = guide(plan, pos[0], pos[1], theta)
        if g.arrived:
            break
        aim = g.next.bearing_deg if g.next is not None else g.bearing_deg
        theta += math.radians(aim)
        step = min(0.2, g.next.distance_m if g.next is not None else g.distance_m)
        new = pos + step * np.array([math.cos(theta), math.sin(theta)])
        assert _in_free_space(SUITE, pos, new), (spec, pos, new, g)
        pos = new
    else:
        pytest.fail(f"never arrived at {spec}")
    assert g.path_m <= ARRIVED_M
    if spec.kind == "region":
        assert SUITE.region_at(*pos) == spec.name or g.path_m <= ARRIVED_M
    else:
        assert min(np.hypot(*(plan.target.points - pos).T)) <= ARRIVED_M + 1e-9


def test_arrived_exactly_within_one_metre_of_walking() -> None:
    plan = plan_for(SUITE, DestinationSpec("point", x=10.0, y=1.5))
    assert guide(plan, 10.0 - 0.95, 1.5, 0.0).arrived
    far = guide(plan, 10.0 - 1.05, 1.5, 0.0)
    assert not far.arrived and far.next is None  # straight ahead: no turn
    assert far.bearing_deg == pytest.approx(0.0, abs=0.5) and far.distance_m == pytest.approx(1.05)


def test_directions_are_relative_to_the_heading() -> None:
    plan = plan_for(SUITE, DestinationSpec("point", x=10.0, y=1.5))
    # Standing at (5, 1.5): the point is due east, 5 m, straight along the corridor.
    for theta_deg, expected in [(0.0, 0.0), (90.0, -90.0), (-90.0, 90.0), (180.0, 180.0)]:
        g = guide(plan, 5.0, 1.5, math.radians(theta_deg))
        assert g.next is None
        assert g.bearing_deg == pytest.approx(expected, abs=1.0)


def test_next_turn_says_where_and_which_way() -> None:
    plan = plan_for(SUITE, DestinationSpec("label", "main entrance"))
    g = guide(plan, *IN_OFFICE_1, math.radians(-90.0))  # facing south, towards the door
    assert g.next is not None
    # The office door is nearly straight ahead, about 5 m; then right (west) towards
    # the entrance: a turn to the right is a negative bearing.
    assert abs(g.next.bearing_deg) < 15
    assert 4.0 < g.next.distance_m < 6.0
    assert -150 < g.next.then_deg < -30


def test_class_goes_to_the_nearest_by_walking_not_by_air() -> None:
    # A door 1.5 m away behind a long wall, another 4 m away in the open.
    m = parse_map(
        {
            "name": "two_doors",
            "walls": [
                {"x1": 0, "y1": 0, "x2": 12, "y2": 0},
                {"x1": 12, "y1": 0, "x2": 12, "y2": 6},
                {"x1": 12, "y1": 6, "x2": 0, "y2": 6},
                {"x1": 0, "y1": 6, "x2": 0, "y2": 0},
                {"x1": 0, "y1": 3, "x2": 11, "y2": 3},
            ],
            "objects": [
                {"class": "door", "x": 2, "y": 1.5, "label": "behind the wall"},
                {"class": "door", "x": 6, "y": 6, "label": "in the open"},
            ],
        }
    )
    g = guide(plan_for(m, DestinationSpec("class", "door")), 2.0, 4.5, 0.0)
    assert g.target == "door (in the open)"
    assert g.distance_m == pytest.approx(math.hypot(4.0, 1.5), abs=0.01)


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        (DestinationSpec("label", "main entrence"), "did you mean 'main entrance'"),
        (DestinationSpec("class", "doors"), "did you mean 'door'"),
        (DestinationSpec("region", "office"), "did you mean"),
        (DestinationSpec("region", "zzz"), "known: 'Corridor'"),
        (DestinationSpec("point", x=50.0, y=1.0), "outside map 'office_suite'"),
    ],
)
def test_unknown_destinations_say_what_the_map_has(spec, words: str) -> None:
    with pytest.raises(UnknownDestination, match=words):
        plan_for(SUITE, spec)


def test_names_are_matched_without_case_and_plans_are_cached() -> None:
    a = plan_for(SUITE, DestinationSpec("label", "Main Entrance"))
    b = plan_for(SUITE, DestinationSpec("label", "main entrance"))
    assert a is b and a.target.name == "main entrance"


def test_a_map_keeps_its_latest_plans_only() -> None:
    """Plans are kept with their map (another map plans anew), the latest CACHE_SIZE:
    one more distinct destination and the least recently asked is built again."""
    m, other = _two_rooms((1.0, 3.0)), _two_rooms((1.0, 3.0))
    points = [DestinationSpec("point", x=1.0 + 0.25 * i, y=1.0) for i in range(CACHE_SIZE)]
    first = [plan_for(m, p) for p in points]
    assert plan_for(other, points[0]) is not first[0]
    assert all(plan_for(m, p) is plan for p, plan in zip(points, first, strict=True))
    plan_for(m, DestinationSpec("point", x=10.0, y=3.0))  # points[0] is now the oldest
    assert plan_for(m, points[0]) is not first[0]
    assert plan_for(m, points[-1]) is first[-1]


def test_a_pose_far_from_any_walkable_place_is_unreachable() -> None:
    plan = plan_for(SUITE, DestinationSpec("label", "main entrance"))
    with pytest.raises(Unreachable, match="no walkable path"):
        guide(plan, 40.0, 40.0, 0.0)


def test_region_arrival_inside_the_region() -> None:
    plan = plan_for(SUITE, DestinationSpec("region", "Office 2"))
    assert guide(plan, 10.0, 7.0, 0.0).arrived
    assert not guide(plan, 3.0, 8.0, 0.0).arrived


def _two_rooms(gap: tuple[float, float]) -> SemanticMap:
    """Two 6 x 4 m rooms side by side, joined by a gap in the wall x = 6 between them."""
    return parse_map(
        {
            "name": "two_rooms",
            "walls": [
                {"x1": 0, "y1": 0, "x2": 12, "y2": 0},
                {"x1": 12, "y1": 0, "x2": 12, "y2": 4},
                {"x1": 12, "y1": 4, "x2": 0, "y2": 4},
                {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
                {"x1": 6, "y1": 0, "x2": 6, "y2": gap[0]},
                {"x1": 6, "y1": gap[1], "x2": 6, "y2": 4},
            ],
            "objects": [{"class": "door", "x": 11.0, "y": 0.0, "label": "exit"}],
        }
    )


def test_a_passage_too_narrow_for_the_clearance_is_still_walked() -> None:
    m = _two_rooms((1.75, 2.25))  # 0.5 m: free space, but no room for 0.3 m each side
    g = guide(plan_for(m, DestinationSpec("label", "exit")), 1.0, 2.0, 0.0)
    assert g.path_m < 12.0
    for a, b in zip(g.path[:-2], g.path[1:-1], strict=True):
        assert _in_free_space(m, a, b)
    assert not segments_cross_walls(g.path[:-1], g.path[1:], m.walls).any()


def test_a_pose_against_a_wall_never_snaps_through_it() -> None:
    # A narrow gap: the roomy cells of the right room do not reach the left one.
    m = _two_rooms((1.75, 2.25))
    plan = plan_for(m, DestinationSpec("point", x=4.0, y=1.0))
    # Just on the far side of the dividing wall from the target, 3 cm from it: the
    # nearest cells that lead to the target are 0.3 m away, behind the wall.
    g = guide(plan, 6.03, 1.0, 0.0)
    assert not segments_cross_walls(g.path[:-1], g.path[1:], m.walls).any()
    assert g.path_m > 3.0  # round through the gap, not 2 m through the wall
