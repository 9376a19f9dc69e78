"""Directions and distances in words (table-driven)."""

from __future__ import annotations

import pytest

from app.feedback.phrasing import (
    clock_distance_hours,
    clock_from_bearing_deg,
    direction_phrase,
    distance_phrase,
)

# bearing (deg, CCW positive: left is +90) -> clock hour (12 ahead, 3 right, 9 left)
CLOCK_CASES = [
    (0, 12), (-30, 1), (-60, 2), (-90, 3), (-120, 4), (-150, 5), (180, 6),
    (150, 7), (120, 8), (90, 9), (60, 10), (30, 11),
    # wrap-around and rounding boundaries
    (-180, 6), (360, 12), (-360, 12), (390, 11), (-14.9, 12), (14.9, 12), (-15.1, 1),
    (15.1, 11), (345, 12), (-345, 12), (-344, 11), (344, 1), (540, 6), (-200, 7), (200, 5),
]  # fmt: skip


@pytest.mark.parametrize(("bearing", "hour"), CLOCK_CASES)
def test_bearing_to_clock(bearing: float, hour: int) -> None:
    assert clock_from_bearing_deg(bearing) == hour


@pytest.mark.parametrize(
    ("a", "b", "hours"), [(12, 1, 1), (11, 1, 2), (3, 9, 6), (12, 12, 0), (1, 11, 2)]
)
def test_clock_distance(a: int, b: int, hours: int) -> None:
    assert clock_distance_hours(a, b) == hours


@pytest.mark.parametrize(
    ("bearing", "style", "words"),
    [
        (-60, "clock", "at 2 o'clock"),
        (90, "clock", "at 9 o'clock"),
        (5, "left_right", "straight ahead"),
        (40, "left_right", "ahead to the left"),
        (-40, "left_right", "ahead to the right"),
        (95, "left_right", "to your left"),
        (-100, "left_right", "to your right"),
        (140, "left_right", "behind you to the left"),
        (-175, "left_right", "behind you"),
        (35, "degrees", "35 degrees to the left"),
        (-20, "degrees", "20 degrees to the right"),
        (1, "degrees", "straight ahead"),
        (179, "degrees", "straight behind you"),
    ],
)
def test_direction_phrases(bearing: float, style: str, words: str) -> None:
    assert direction_phrase(bearing, style) == words  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("metres", "units", "certain", "words"),
    [
        (0.4, "metric", True, "less than a metre"),
        (0.99, "metric", True, "less than a metre"),
        (1.2, "metric", True, "1 metre"),
        (1.2, "metric", False, "roughly 1 metre"),
        (3.1, "metric", True, "about 3 metres"),
        (3.1, "metric", False, "roughly 3 metres"),
        (9.6, "metric", True, "about 10 metres"),
        (12.0, "metric", True, "about 10 metres"),
        (13.0, "metric", True, "about 15 metres"),
        (0.5, "imperial", True, "less than 3 feet"),
        (1.0, "imperial", True, "about 3 feet"),
        (3.0, "imperial", True, "about 10 feet"),
        (3.0, "imperial", False, "roughly 10 feet"),
        (10.0, "imperial", True, "about 35 feet"),
    ],
)
def test_distance_phrases(metres: float, units: str, certain: bool, words: str) -> None:
    assert distance_phrase(metres, units, certain=certain) == words  # type: ignore[arg-type]
