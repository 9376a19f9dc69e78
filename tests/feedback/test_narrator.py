"""What the narrator says, and when: labels, order, repetition, regions, honesty."""

from __future__ import annotations

import math

import pytest

from app.feedback import FeedbackOptions, Narrator
from app.localization.types import Detection, Estimate, Hypothesis, Odometry
from app.maps.model import parse_map
from tests.helpers import paper_office

TWO_OFFICES = parse_map(
    {
        "name": "two_offices",
        "walls": [
            {"x1": 0, "y1": 0, "x2": 10, "y2": 0},
            {"x1": 10, "y1": 0, "x2": 10, "y2": 5},
            {"x1": 10, "y1": 5, "x2": 0, "y2": 5},
            {"x1": 0, "y1": 5, "x2": 0, "y2": 0},
            {"x1": 5, "y1": 0, "x2": 5, "y2": 2},
            {"x1": 5, "y1": 3, "x2": 5, "y2": 5},
        ],
        "objects": [
            {"class": "door", "x": 10, "y": 2.5, "label": "main entrance"},
            {"class": "table", "x": 2, "y": 2.5},
            {"class": "window", "x": 2.5, "y": 5},
            {"class": "table", "x": 8, "y": 1},
            {"class": "window", "x": 7.5, "y": 5},
        ],
        "regions": [
            {"name": "Office 1", "polygon": [[0, 0], [5, 0], [5, 5], [0, 5]]},
            {"name": "Office 2", "polygon": [[5, 0], [10, 0], [10, 5], [5, 5]]},
        ],
    }
)


def located(x: float, y: float, theta_deg: float = 0.0, std: float = 0.05) -> Estimate:
    th = math.radians(theta_deg)
    return Estimate(x, y, th, std, std, math.radians(2), True, (Hypothesis(x, y, th, 1.0),), 1000)


def lost(*modes: tuple[float, float, float]) -> Estimate:
    hyps = tuple(Hypothesis(x, y, 0.0, w) for x, y, w in modes)
    x, y, _ = modes[0]
    return Estimate(x, y, 0.0, 1.5, 1.5, 1.0, False, hyps, 1000)


def test_label_and_phrase_order() -> None:
    n = Narrator(TWO_OFFICES)
    # At (7, 2.5) facing east: the door (labelled) is straight ahead, 3 m away.
    fb = n.update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.0)
    assert "You are in Office 2." in fb.text
    assert "Main entrance at 12 o'clock, about 3 metres." in fb.text
    first = fb.items[0]
    assert (first.cls, first.label, first.clock) == ("door", "main entrance", 12)
    assert first.distance_m == pytest.approx(3.0)


def test_matched_objects_come_first_then_nearest_visible() -> None:
    n = Narrator(TWO_OFFICES, FeedbackOptions(max_items=3))
    # At (7, 2) facing north; the camera sees the window at (7.5, 5) (bearing about -9 deg).
    fb = n.update(located(7, 2, 90), [Detection("window", math.radians(-9.5))], timestamp_s=0.0)
    assert next(i.cls for i in fb.items) == "window"
    assert fb.items[0].clock == 12
    assert len(fb.items) == 3
    rest = fb.items[1:]
    assert rest[0].distance_m <= rest[1].distance_m
    # Objects behind the inner wall are not offered: the west table is hidden.
    assert all(not (i.cls == "table" and i.distance_m and i.distance_m > 4.9) for i in fb.items)


def test_max_items_is_respected() -> None:
    fb = Narrator(TWO_OFFICES, FeedbackOptions(max_items=1)).update(
        located(7, 2.5), [Detection("door", 0.0), Detection("table", -1.0)], timestamp_s=0.0
    )
    assert len(fb.items) == 1


def test_no_repetition_until_something_changes() -> None:
    n = Narrator(TWO_OFFICES)
    dets = [Detection("door", 0.0)]
    first = n.update(located(7, 2.5), dets, timestamp_s=0.0).text
    again = n.update(located(7, 2.5), dets, timestamp_s=0.2).text
    assert first and again != first
    assert "Main entrance" not in again
    # Turning by two hours: the door is announced again at its new clock position,
    # though not within two seconds of the last announcement (speech must keep up).
    door = [Detection("door", math.radians(-60))]
    assert "Main entrance" not in n.update(located(7, 2.5, 60), door, timestamp_s=0.4).text
    turned = n.update(located(7, 2.5, 60), door, timestamp_s=2.5).text
    assert "Main entrance at 2 o'clock" in turned
    # A minute later the unchanged door is repeated.
    later = n.update(
        located(7, 2.5, 60), [Detection("door", math.radians(-60))], timestamp_s=63.0
    ).text
    assert "Main entrance at 2 o'clock" in later


def test_distance_change_is_announced() -> None:
    n = Narrator(TWO_OFFICES)
    n.update(located(6.0, 2.5), [Detection("door", 0.0)], timestamp_s=0.0)
    closer = n.update(located(8.8, 2.5), [Detection("door", 0.0)], timestamp_s=5.0).text
    assert "Main entrance at 12 o'clock, 1 metre." in closer


def test_entering_a_region_is_announced_once() -> None:
    n = Narrator(TWO_OFFICES)
    assert "You are in Office 1." in n.update(located(2, 1), [], timestamp_s=0).text
    assert "You are in" not in n.update(located(2.1, 1), [], timestamp_s=0.2).text
    assert "You are in Office 2." in n.update(located(6, 2.5), [], timestamp_s=5).text


def test_describe_gives_everything_now() -> None:
    n = Narrator(TWO_OFFICES)
    n.update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.0)
    fb = n.update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.2, describe=True)
    assert fb.text.startswith("You are in Office 2.")
    assert "Main entrance at 12 o'clock" in fb.text


def test_uncertain_location_is_never_stated_as_fact() -> None:
    n = Narrator(TWO_OFFICES)
    fb = n.update(
        lost((7, 2.5, 0.6), (7.2, 2.4, 0.2)), [Detection("table", math.radians(-30))], timestamp_s=0
    )
    assert "not certain" in fb.text
    assert "You are in" not in fb.text
    assert "metre" not in fb.text
    assert "I see a table at 1 o'clock; still working out where you are." in fb.text
    assert fb.items[0].distance_m is None and fb.items[0].label is None
    assert fb.items[0].clock == 1


def test_competing_regions_are_named() -> None:
    n = Narrator(TWO_OFFICES)
    fb = n.update(lost((7, 2.5, 0.5), (2, 2.5, 0.45)), [], timestamp_s=0)
    assert "You may be in Office 2 or Office 1" in fb.text
    # Nothing new next frame: no repetition of the status.
    assert n.update(lost((7, 2.5, 0.5), (2, 2.5, 0.45)), [], timestamp_s=0.2).text == ""


def test_losing_the_position_is_said() -> None:
    n = Narrator(TWO_OFFICES)
    n.update(located(7, 2.5), [], timestamp_s=0)
    fb = n.update(lost((7, 2.5, 0.5), (2, 2.5, 0.45)), [], timestamp_s=1)
    assert "no longer sure" in fb.text


def test_imperial_and_left_right_styles() -> None:
    n = Narrator(TWO_OFFICES, FeedbackOptions(style="left_right", units="imperial"))
    fb = n.update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.0)
    assert "Main entrance straight ahead, about 10 feet." in fb.text


def test_unknown_classes_and_zero_scores_are_not_spoken() -> None:
    n = Narrator(TWO_OFFICES)
    fb = n.update(
        lost((7, 2.5, 1.0)), [Detection("sofa", 0.0), Detection("door", 0.0, 0.0)], timestamp_s=0
    )
    assert "sofa" not in fb.text and "door" not in fb.text
    assert fb.items == []


def test_hedging_when_less_certain() -> None:
    n = Narrator(TWO_OFFICES)
    fb = n.update(located(7, 2.5, std=0.3), [Detection("door", 0.0)], timestamp_s=0.0)
    assert "roughly 3 metres" in fb.text


def test_paper_office_walk_sentence() -> None:
    n = Narrator(paper_office())
    # Near the south-west table, facing east: the door is far ahead-left.
    fb = n.update(located(2.0, 1.2), [Detection("door", math.radians(28))], timestamp_s=0)
    assert "Main entrance at 11 o'clock, about 9 metres." in fb.text


def test_hedging_when_the_protection_radius_is_wide() -> None:
    """Converged and tight, but the whole belief a little wider: 'roughly', not 'no longer sure'."""
    from dataclasses import replace

    n = Narrator(TWO_OFFICES)
    fb = n.update(
        replace(located(7, 2.5), protection_m=1.5), [Detection("door", 0.0)], timestamp_s=0
    )
    assert "roughly 3 metres" in fb.text and "no longer sure" not in fb.text
    n = Narrator(TWO_OFFICES)
    fb = n.update(
        replace(located(7, 2.5), protection_m=0.3), [Detection("door", 0.0)], timestamp_s=0
    )
    assert "about 3 metres" in fb.text


def test_a_fix_with_a_wide_radius_is_announced_with_it() -> None:
    """Located with a protection radius past a metre, the person hears how far off the
    fix may be, rounded up (the radius is a bound); a tight one is announced plainly,
    and the radius is said once."""
    from dataclasses import replace

    for radius, units, said in [
        (0.4, "metric", "Location found. "),
        (1.2, "metric", "Location found, to within about 2 metres. "),
        (1.5, "metric", "Location found, to within about 2 metres. "),
        (2.7, "metric", "Location found, to within about 3 metres. "),
        (2.7, "imperial", "Location found, to within about 9 feet. "),
        (1.2, "imperial", "Location found, to within about 4 feet. "),
    ]:
        n = Narrator(TWO_OFFICES, FeedbackOptions(units=units))  # type: ignore[arg-type]
        fix = replace(located(7, 2.5), protection_m=radius)
        fb = n.update(fix, [Detection("door", 0.0)], timestamp_s=0.0)
        assert fb.text.startswith(said), (radius, units, fb.text)
        again = n.update(fix, [Detection("door", 0.0)], timestamp_s=5.0)
        assert "Location found" not in again.text


def test_while_lost_it_suggests_turning_then_walking_and_says_so_every_10_s() -> None:
    """A phone camera (66 deg): turn on the spot until it has looked all around, then
    walk; after a few metres, look around again. Spoken at most once every 10 s; no
    suggestion once located."""
    n = Narrator(TWO_OFFICES)
    turn = Odometry(0.0, 0.0, math.radians(9.0))  # 90 deg/s at 10 frames/s
    said_at, suggestions = [], []
    for k in range(60):  # 6 s of turning: 540 degrees
        fb = n.update(
            lost((3, 2.5, 0.5), (13, 2.5, 0.5)),
            [],
            timestamp_s=0.1 * k,
            fov_deg=66.0,
            odometry=turn,
        )
        suggestions.append(fb.suggestion)
        if "Turn slowly" in fb.text or "Walk a few steps" in fb.text:
            said_at.append(round(0.1 * k, 1))
    assert set(suggestions[:39]) == {"turn"}  # under a full turn
    assert set(suggestions[41:]) == {"walk"}
    assert said_at == [0.0]  # the switch to "walk" waits for the 10 s to pass
    step = Odometry(0.04, 0.0, 0.0)  # 2.4 m in 6 s
    for k in range(60, 120):
        fb = n.update(
            lost((3, 2.5, 0.5), (13, 2.5, 0.5)),
            [],
            timestamp_s=0.1 * k,
            fov_deg=66.0,
            odometry=step,
        )
        if "Walk a few steps" in fb.text:
            said_at.append(round(0.1 * k, 1))
    assert said_at == [0.0, 10.0]
    assert fb.suggestion == "walk"
    fb = n.update(lost((3, 2.5, 1.0)), [], timestamp_s=12.0, fov_deg=66.0, odometry=Odometry(1.0))
    assert fb.suggestion == "turn"  # walked over 3 m: look around again
    fb = n.update(located(7, 2.5), [], timestamp_s=12.5, fov_deg=66.0, odometry=step)
    assert fb.suggestion is None and "Turn" not in fb.text
    # A 360-degree camera has nothing more to see by turning.
    fresh = Narrator(TWO_OFFICES)
    fb = fresh.update(lost((3, 2.5, 1.0)), [], timestamp_s=0.0, fov_deg=360.0, odometry=turn)
    assert fb.suggestion == "walk" and "Walk a few steps" in fb.text


def test_where_only_a_maps_twins_are_left_it_suggests_nothing_and_says_why() -> None:
    """A map that turns onto itself: neither turning nor walking tells the twin places
    apart, so no suggestion is made; the words say what would (a compass), as often as
    a suggestion would be said, and turning or walking is suggested again once other
    places come back into the belief."""
    n = Narrator(TWO_OFFICES)
    said_at = []
    for k in range(120):
        fb = n.update(
            lost((3, 2.5, 0.5), (7, 2.5, 0.5)),
            [],
            timestamp_s=0.1 * k,
            fov_deg=66.0,
            odometry=Odometry(0.0, 0.0, math.radians(9.0)),
            twins=True,
        )
        assert fb.suggestion is None
        assert "Turn slowly" not in fb.text and "Walk a few" not in fb.text
        if "compass" in fb.text:
            said_at.append(round(0.1 * k, 1))
    assert said_at == [0.0, 10.0]
    fb = n.update(lost((3, 2.5, 0.5)), [], timestamp_s=12.0, fov_deg=66.0, describe=True)
    # (it has turned all the way round meanwhile: walking is what is left)
    assert fb.suggestion == "walk" and "Walk a few steps" in fb.text


def test_an_object_taken_for_moved_or_gone_is_not_said() -> None:
    """Where a stale map has an object the filter took for moved or taken away is not
    where it is: the narrator leaves it out, even when a detection of its class points
    its way."""
    import numpy as np

    n = Narrator(TWO_OFFICES)
    gone = np.zeros(TWO_OFFICES.object_count, dtype=bool)
    gone[0] = True  # the main entrance
    fb = n.update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.0, gone=gone)
    assert fb.items and all(i.label != "main entrance" and i.cls != "door" for i in fb.items)
    assert "entrance" not in fb.text.lower()
    plain = Narrator(TWO_OFFICES).update(located(7, 2.5), [Detection("door", 0.0)], timestamp_s=0.0)
    assert plain.items[0].label == "main entrance"
