"""tools/unmodelled.py: each effect does to the frames what it says, and bad arguments
are refused by name."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.experiments import phone
from tools.unmodelled import EFFECTS, PERIOD_S, main


@pytest.fixture(scope="module")
def frames() -> list:
    from app.simulation.phone import simulate_phone

    scenario = phone.Scenario("office_suite", "vio-360")
    sm, _ = phone.suite_map(scenario.map_name)
    cond = phone.CONDITIONS[scenario.condition]
    walk = phone.walk_of(scenario, max_s=45.0)
    return simulate_phone(sm, walk, cond.effects, np.random.default_rng(3))


def _changed(before: list, after: list) -> list[int]:
    return [i for i, (a, b) in enumerate(zip(before, after, strict=True)) if a != b]


def test_a_tracking_jump_lengthens_one_frame_a_period(frames: list) -> None:
    after = EFFECTS["tracking-jump-0.8m"](frames, np.random.default_rng(0))
    changed = _changed(frames, after)
    assert [int(frames[i].t // PERIOD_S) for i in changed] == [1, 2]
    for i in changed:
        assert after[i].odometry.forward_m == pytest.approx(frames[i].odometry.forward_m + 0.8)
        assert after[i].odometry.turn_rad == frames[i].odometry.turn_rad
        assert int(frames[i - 1].t // PERIOD_S) < int(frames[i].t // PERIOD_S)


def test_a_heading_jump_turns_and_a_yaw_shifts_every_bearing(frames: list) -> None:
    turned = EFFECTS["heading-jump-20deg"](frames, np.random.default_rng(0))
    for i in _changed(frames, turned):
        diff = turned[i].odometry.turn_rad - frames[i].odometry.turn_rad
        assert math.degrees(diff) == pytest.approx(20.0)
    yawed = EFFECTS["camera-yaw-6deg"](frames, np.random.default_rng(0))
    for a, b in zip(frames, yawed, strict=True):
        shifts = [
            math.degrees(d.bearing_rad - c.bearing_rad)
            for c, d in zip(a.detections, b.detections, strict=True)
        ]
        assert shifts == pytest.approx([6.0] * len(shifts))


def test_a_pause_drops_eight_seconds_and_the_odometry_after(frames: list) -> None:
    after = EFFECTS["paused-8s"](frames, np.random.default_rng(0))
    assert not any(25.0 <= f.t < 33.0 for f in after)
    resumed = next(f for f in after if f.t >= 33.0)
    assert resumed.odometry is None
    assert len(after) == len(frames) - sum(25.0 <= f.t < 33.0 for f in frames)


def test_lost_tracking_blanks_the_odometry_three_seconds_a_period(frames: list) -> None:
    after = EFFECTS["tracking-lost-3s"](frames, np.random.default_rng(0))
    for a, b in zip(frames, after, strict=True):
        blank = a.t >= PERIOD_S and a.t % PERIOD_S < 3.0
        assert (b.odometry is None) if blank else (b == a)
        assert b.detections == a.detections


def test_occlusion_bursts_lose_detections_only_in_the_bursts(frames: list) -> None:
    after = EFFECTS["occlusion-bursts"](frames, np.random.default_rng(0))
    for a, b in zip(frames, after, strict=True):
        if a.t % PERIOD_S < 5.0:
            assert len(b.detections) <= len(a.detections)
        else:
            assert b == a
    burst = [(a, b) for a, b in zip(frames, after, strict=True) if a.t % PERIOD_S < 5.0]
    kept = sum(len(b.detections) for _, b in burst) / sum(len(a.detections) for a, _ in burst)
    assert 0.05 < kept < 0.4  # 20 % kept, give or take a few hundred detections' chance


def test_bad_arguments_are_refused_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--rows", "office_suite/nope"])
    assert "'office_suite/nope' is no MAP/CONDITION" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--effects", "gravity"])
    assert "unknown effect 'gravity'" in capsys.readouterr().err
