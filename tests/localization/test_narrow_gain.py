"""A first fix is told only once its radius has been narrow for a few frames in a row."""

from __future__ import annotations

import math

import numpy as np
import pytest

import app.localization.filter as filter_module
from app.localization.config import FilterConfig
from app.localization.convergence import GAIN_PROTECTION_M
from app.localization.filter import (
    NARROW_FRAMES,
    SEPARATION_RINGS_FOV_DEG,
    WIDE_VIEW_GAIN_PROTECTION_M,
    ParticleFilter,
)
from app.localization.types import Odometry, Pose
from tests.helpers import paper_office, seen_from

OFFICE = paper_office()
POSE = Pose(3.0, 2.0, math.pi / 2)


def _first_fix(
    monkeypatch: pytest.MonkeyPatch, radii: list[float], fov_deg: float = 360.0
) -> tuple[int, int]:
    """Standing still at POSE from a global start, each frame on which a gain is
    tested gets the next radius of ``radii`` (then narrow ones); returns the frame of
    the first fix and the frame of the first test."""
    tested: list[int] = []
    frame = [0]

    def radius(*args: object, **kwargs: object) -> float:
        tested.append(frame[0])
        k = len(tested) - 1
        return radii[k] if k < len(radii) else 0.5 * GAIN_PROTECTION_M

    monkeypatch.setattr(filter_module, "widened_radius", radius)
    config = FilterConfig(particles=3000, fov_deg=fov_deg)
    pf = ParticleFilter(OFFICE, config, rng=np.random.default_rng(1))
    seen = seen_from(OFFICE, POSE)
    for k in range(80):
        frame[0] = k
        if pf.step(Odometry(0.0, 0.0, 0.0), seen).converged:
            return k, tested[0]
    raise AssertionError("never converged")


def test_one_narrow_frame_among_wide_ones_tells_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Through a 66-degree camera the radius swings between 1.5 and 6 m from a frame to
    the next; fixes 7 m off were told on the one frame it dipped below 1.5 m (phone
    suite, stale office)."""
    narrow, wide = 0.5 * GAIN_PROTECTION_M, 4.0 * GAIN_PROTECTION_M
    swinging = [narrow if k % 2 else wide for k in range(11)]  # ends wide
    told, first_test = _first_fix(monkeypatch, swinging)
    # The swing lasts 11 tested frames; then NARROW_FRAMES narrow ones in a row.
    assert told == first_test + len(swinging) + NARROW_FRAMES - 1
    told, first_test = _first_fix(monkeypatch, [])
    assert told == first_test + NARROW_FRAMES - 1


def test_a_camera_that_sees_all_around_is_first_told_within_a_metre(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A radius between 1 m and GAIN_PROTECTION_M holds back a first fix through a
    camera of SEPARATION_RINGS_FOV_DEG or more (with objects all around, a right place
    is pinned well under a metre), not through a narrower one."""
    between = 0.5 * (WIDE_VIEW_GAIN_PROTECTION_M + GAIN_PROTECTION_M)
    assert WIDE_VIEW_GAIN_PROTECTION_M < between < GAIN_PROTECTION_M
    told, first_test = _first_fix(monkeypatch, [between] * 6, SEPARATION_RINGS_FOV_DEG)
    assert told == first_test + 6 + NARROW_FRAMES - 1
    told, first_test = _first_fix(monkeypatch, [between] * 6, SEPARATION_RINGS_FOV_DEG - 90.0)
    assert told == first_test + NARROW_FRAMES - 1
