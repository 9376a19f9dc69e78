"""Spoken directions: the phrase, when it is repeated, never while not converged."""

from __future__ import annotations

import numpy as np
import pytest

from app.feedback.guidance import FINDING, GuidanceSpeaker, directions
from app.guidance import Guidance, NextTurn

PATH = np.zeros((2, 2))


def g(bearing=-30.0, distance=3.0, turn: NextTurn | None = None, arrived=False, path_m=None):
    return Guidance("main entrance", bearing, distance, path_m or distance, turn, arrived, PATH)


@pytest.mark.parametrize(
    ("guidance", "style", "units", "text"),
    [
        (
            g(-55.0, 7.4, NextTurn(-30.0, 3.0, -90.0)),
            "clock",
            "metric",
            "Main entrance: go to 1 o'clock, 3 metres, then to 3 o'clock.",
        ),
        (g(-30.0, 3.2), "clock", "metric", "Main entrance: go to 1 o'clock, 3 metres."),
        (g(0.0, 1.2), "clock", "metric", "Main entrance: go to 12 o'clock, 1 metre."),
        (g(0.0, 0.6), "clock", "metric", "Main entrance: go to 12 o'clock, less than a metre."),
        (g(90.0, 3.0), "left_right", "metric", "Main entrance: go to your left, 3 metres."),
        (
            g(10.0, 8.0, NextTurn(40.0, 3.0, 90.0)),
            "degrees",
            "imperial",
            "Main entrance: go 40 degrees to the left, 10 feet, then 90 degrees to the left.",
        ),
        (g(arrived=True), "clock", "metric", "You have arrived at main entrance."),
    ],
)
def test_the_phrase(guidance, style, units, text: str) -> None:
    assert directions(guidance, style, units) == text


def test_never_directions_while_not_converged() -> None:
    s = GuidanceSpeaker()
    assert s.update(None, False, 0.0, 0, 0) == FINDING
    assert s.update(None, False, 1.0, 0, 0) == ""  # not repeated at once
    assert s.update(g(), False, 2.0, 0, 0) == ""  # guidance on an unconverged pose: silence
    assert s.update(None, False, 31.0, 0, 0) == FINDING  # after a while, again
    assert "go to" in s.update(g(), True, 32.0, 0, 0)


def test_repeated_on_an_hour_of_change_or_every_ten_seconds_while_walking() -> None:
    s = GuidanceSpeaker()
    assert s.update(g(-30.0), True, 0.0, 0.0, 0.0).startswith("Main entrance: go to 1")
    assert s.update(g(-35.0), True, 1.0, 0.2, 0.0) == ""  # same hour, soon
    assert s.update(g(-60.0), True, 2.0, 0.4, 0.0).startswith("Main entrance: go to 2")
    assert s.update(g(-60.0), True, 13.0, 0.4, 0.0) == ""  # standing still: no repeat
    assert s.update(g(-60.0), True, 14.0, 2.0, 0.0) != ""  # walked and 10 s passed
    assert s.update(g(-60.0), True, 15.0, 3.0, 0.0) == ""


def test_turning_on_the_spot_is_not_a_torrent_of_words() -> None:
    s = GuidanceSpeaker()
    assert s.update(g(-30.0), True, 0.0, 0.0, 0.0) != ""
    assert s.update(g(-90.0), True, 0.5, 0.0, 0.0) == ""  # two hours, but just said
    assert s.update(g(-150.0), True, 1.0, 0.0, 0.0) == ""
    assert "go to 5 o'clock" in s.update(g(-150.0), True, 2.1, 0.0, 0.0)  # then the latest


def test_arrival_is_said_once() -> None:
    s = GuidanceSpeaker()
    s.update(g(), True, 0.0, 0, 0)
    assert s.update(g(arrived=True), True, 5.0, 0, 0) == "You have arrived at main entrance."
    assert s.update(g(arrived=True), True, 6.0, 0, 0) == ""
    assert s.update(g(distance=1.5, path_m=1.5), True, 7.0, 0, 0) == ""  # a step away
    assert s.update(g(distance=4.0, path_m=4.0), True, 8.0, 0, 0) != ""  # left: guide again


def test_no_way_is_said_now_and_then_and_guidance_resumes() -> None:
    s = GuidanceSpeaker()
    assert s.no_way("main entrance", 0.0) == "I cannot find a way from here to main entrance."
    assert s.no_way("main entrance", 5.0) == ""
    assert "go to" in s.update(g(), True, 6.0, 0, 0)  # a way again: directions at once
