"""tools/venue_gaps.py: each effect takes the odometry out where it says, and the venue
suite's ``alter`` keeps its frames one for one."""

from __future__ import annotations

import pytest

from app.experiments import venue
from tools.venue_gaps import AFTER_RIDE_S, GAP_S, PERIOD_S, lose_tracking, main


@pytest.fixture(scope="module")
def frames() -> list:
    _, walked, _ = venue._walk(0, venue.CONDITIONS["phone-vio"])
    return walked


def test_periodic_gaps_take_out_the_odometry_for_3_s_of_every_20(frames: list) -> None:
    after = lose_tracking(frames, "periodic")
    assert len(after) == len(frames)
    for a, b in zip(frames, after, strict=True):
        t = a.frame.t
        inside = t >= PERIOD_S and t % PERIOD_S < GAP_S
        assert (b.frame.odometry is None) == (inside or a.frame.odometry is None)
        assert b.frame.detections == a.frame.detections


def test_rides_lose_the_odometry_for_the_ride_and_a_second_after(frames: list) -> None:
    after = lose_tracking(frames, "rides")
    ride_end = -float("inf")
    lost_after = 0
    for a, b in zip(frames, after, strict=True):
        if a.riding:
            ride_end = a.frame.t
            assert b.frame.odometry is None
        elif a.frame.t - ride_end <= AFTER_RIDE_S:
            assert b.frame.odometry is None
            lost_after += 1
        else:
            assert b.frame.odometry == a.frame.odometry
    assert lost_after > 0 and any(a.riding for a in frames)


def test_an_alter_that_drops_frames_is_refused() -> None:
    with pytest.raises(ValueError, match="one for one"):
        venue.run_condition("phone-vio", 0, 200, alter=lambda frames: frames[:-1])


def test_bad_arguments_are_refused_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, word in ((["--conditions", "moon"], "moon"), (["--effects", "fog"], "fog")):
        with pytest.raises(SystemExit):
            main(argv)
        assert word in capsys.readouterr().err
