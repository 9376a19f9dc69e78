"""Rotations that carry a map onto itself (app.maps.symmetry)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.experiments.hard_maps import hard_map
from app.maps.check import check_data, load_map
from app.maps.geometry import wrap_rad
from app.maps.model import SemanticMap, parse_map
from app.maps.symmetry import SYMMETRY_TOLERANCE_M, rotational_symmetries, twin_pose
from app.resources import bundled_maps_dir
from app.simulation.venue import venue_map
from tests.helpers import symmetric_venue_spec


def _square(
    objects: list[dict[str, object]], walls: list[dict[str, float]] | None = None
) -> SemanticMap:
    box = [
        {"x1": 0.0, "y1": 0.0, "x2": 6.0, "y2": 0.0},
        {"x1": 6.0, "y1": 0.0, "x2": 6.0, "y2": 6.0},
        {"x1": 6.0, "y1": 6.0, "x2": 0.0, "y2": 6.0},
        {"x1": 0.0, "y1": 6.0, "x2": 0.0, "y2": 0.0},
    ]
    return parse_map({"name": "square", "walls": walls or box, "objects": objects})


def _degrees(m: SemanticMap) -> list[float]:
    return [round(math.degrees(a), 6) for _, _, a in rotational_symmetries(m)]


WINDOWS = [
    {"class": "window", "x": 3.0, "y": 0.0},
    {"class": "window", "x": 6.0, "y": 3.0},
    {"class": "window", "x": 3.0, "y": 6.0},
    {"class": "window", "x": 0.0, "y": 3.0},
]


def test_a_square_with_a_window_in_each_wall_turns_onto_itself_every_quarter() -> None:
    m = _square(WINDOWS)
    assert _degrees(m) == [90.0, 180.0, 270.0]
    assert all((cx, cy) == pytest.approx((3.0, 3.0)) for cx, cy, _ in rotational_symmetries(m))


def test_one_object_of_another_class_or_one_wall_breaks_the_turn() -> None:
    door = [*WINDOWS[:3], {"class": "door", "x": 0.0, "y": 3.0}]
    assert _degrees(_square(door)) == []
    # Two tables on the diagonal: only the half turn keeps them.
    tables = [{"class": "table", "x": 2.0, "y": 2.0}, {"class": "table", "x": 4.0, "y": 4.0}]
    assert _degrees(_square(WINDOWS + tables)) == [180.0]
    # An inner wall along one side only breaks the half turn too.
    inner = {"x1": 1.0, "y1": 1.0, "x2": 1.0, "y2": 3.0}
    box = [
        {"x1": 0.0, "y1": 0.0, "x2": 6.0, "y2": 0.0},
        {"x1": 6.0, "y1": 0.0, "x2": 6.0, "y2": 6.0},
        {"x1": 6.0, "y1": 6.0, "x2": 0.0, "y2": 6.0},
        {"x1": 0.0, "y1": 6.0, "x2": 0.0, "y2": 0.0},
    ]
    assert _degrees(_square(WINDOWS + tables, [*box, inner])) == []
    # ... and its twin across the centre, drawn the other way round, restores it.
    twin = {"x1": 5.0, "y1": 3.0, "x2": 5.0, "y2": 5.0}
    assert _degrees(_square(WINDOWS + tables, [*box, inner, twin])) == [180.0]


def test_objects_are_matched_within_the_tolerance_only() -> None:
    near = SYMMETRY_TOLERANCE_M * 0.8
    shifted = [*WINDOWS[:3], {"class": "window", "x": 0.0, "y": 3.0 + near}]
    assert 180.0 in _degrees(_square(shifted))
    moved = [*WINDOWS[:3], {"class": "window", "x": 0.0, "y": 3.0 + 3 * SYMMETRY_TOLERANCE_M}]
    assert _degrees(_square(moved)) == []


def test_the_suites_maps_only_the_symmetric_room_turns_onto_itself() -> None:
    assert _degrees(hard_map("symmetric_room").map) == [180.0]
    ((cx, cy, _),) = rotational_symmetries(hard_map("symmetric_room").map)
    assert (cx, cy) == pytest.approx((6.0, 4.0))
    # The same room with its one door is no twin case: the door tells the ways apart.
    assert _degrees(hard_map("rotation_room").map) == []
    for path in sorted(bundled_maps_dir().glob("*.json")):
        assert _degrees(load_map(path)) == [], path.name
    assert _degrees(venue_map()) == []


def test_a_twin_pose_is_the_pose_turned_about_the_centre() -> None:
    half = (6.0, 4.0, math.pi)
    x, y, theta = twin_pose(3.0, 2.0, 0.25, half)
    eps = 8 * np.finfo(np.float64).eps * 10.0  # a few ulps of coordinates about 10 m
    assert abs(x - 9.0) < eps and abs(y - 6.0) < eps
    assert abs(wrap_rad(theta - (0.25 + math.pi))) < eps
    # A half turn twice is the pose itself; a quarter turn moves (7, 4) to (6, 5).
    back = twin_pose(x, y, theta, half)
    assert all(abs(a - b) < eps for a, b in zip(back[:2], (3.0, 2.0), strict=True))
    qx, qy, _ = twin_pose(7.0, 4.0, 0.0, (6.0, 4.0, math.pi / 2))
    assert abs(qx - 6.0) < eps and abs(qy - 5.0) < eps


def test_a_venue_turns_onto_itself_only_when_every_floor_and_connector_does() -> None:
    """Every level by one turn about one point of the file's frame, and each stairs'
    landing onto a landing of the same kind: a pose and its twin ride to twin places."""
    m = parse_map(symmetric_venue_spec())
    ((cx, cy, angle),) = rotational_symmetries(m)
    assert (cx, cy, angle) == pytest.approx((6.0, 4.0, math.pi))
    # A sign on the First Floor only: that floor tells the twins apart (after a ride).
    sign = {"class": "sign", "x": 6.0, "y": 7.0}
    assert _degrees(parse_map(symmetric_venue_spec([sign]))) == []
    # One stairs' landings moved: the twin of a place by it rides elsewhere.
    spec = symmetric_venue_spec()
    for stop in spec["connectors"][0]["stops"]:  # type: ignore[index]
        stop["polygon"] = [[x + 1.0, y] for x, y in stop["polygon"]]
    assert _degrees(parse_map(spec)) == []
    # A lift where the stairs were: another kind, no twin.
    spec = symmetric_venue_spec()
    spec["connectors"][0]["kind"] = "elevator"  # type: ignore[index]
    assert _degrees(parse_map(spec)) == []
    # The First Floor drawn half a metre east, stairs and all: each floor turns onto
    # itself, but not by one turn, so no twin.
    spec = symmetric_venue_spec()
    upstairs = [i for i in (*spec["walls"], *spec["objects"]) if i["level"] == "L1"]  # type: ignore[misc]
    for item in upstairs:
        for key in ("x", "x1", "x2"):
            if key in item:
                item[key] += 0.5
    for conn in spec["connectors"]:  # type: ignore[attr-defined]
        upper = conn["stops"][1]
        upper["polygon"] = [[x + 0.5, y] for x, y in upper["polygon"]]
    level_one = parse_map({**spec, "levels": spec["levels"][1:], "connectors": [],  # type: ignore[index]
                           "walls": [w for w in upstairs if "x1" in w],
                           "objects": [o for o in upstairs if "x" in o]})  # fmt: skip
    assert _degrees(level_one) == [180.0]
    assert _degrees(parse_map(spec)) == []
    # The map check names it.
    result = check_data(symmetric_venue_spec(), source="venue.json")
    (warned,) = [p for p in result.problems if "turns onto itself" in p.message]
    assert "180 deg about (6.00, 4.00) on every level" in warned.message


def test_on_a_venue_a_twin_pose_stays_on_its_level() -> None:
    m = parse_map(symmetric_venue_spec())
    layout = m.layout
    offset = layout.levels[1].offset_x
    assert offset > 12.0
    half = (6.0, 4.0, math.pi)
    x, y, theta = twin_pose(3.0 + offset, 2.0, 0.25, half, layout)
    eps = 8 * np.finfo(np.float64).eps * (offset + 12.0)  # a few ulps of plane coordinates
    assert abs(x - (9.0 + offset)) < eps and abs(y - 6.0) < eps
    assert layout.level_of(x) == 1
    assert abs(wrap_rad(theta - (0.25 + math.pi))) < eps
    # On the Ground Floor (no shift) as on a map without levels.
    assert twin_pose(3.0, 2.0, 0.25, half, layout) == twin_pose(3.0, 2.0, 0.25, half)
