"""A held fix is not swapped for a young alternative its own circle holds (filter:
``_weigh_alternatives``): a search's best candidate near the told place fits its short
window better than the truth by selection alone, so it waits out its probation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.localization.alternatives import DEFAULT_EVIDENCE
from app.localization.evidence import EvidenceTracker
from app.localization.types import Odometry, Pose
from app.simulation.venue import venue_map
from tests.helpers import told_at

VENUE = venue_map()
POSE = Pose(8.0, 3.0, math.pi / 2)


def _swaps_asked(
    monkeypatch: pytest.MonkeyPatch, offset_m: float, age: int
) -> tuple[int, bool, float]:
    """A fix told at POSE (a 66-degree camera, a known start: its circle about 0.47 m
    wide), then three frames in
    which the evidence says a swap is due onto an alternative ``offset_m`` east of the
    fix, tracked ``age`` frames: how many swaps the filter made, and converged and the
    error after."""
    pf, seen, est = told_at(VENUE, POSE)
    still = Odometry(0.0, 0.0, 0.0)
    assert est.converged and pf._last_fix is not None
    asked: list[int] = []

    def swap(self: EvidenceTracker, n: int) -> tuple[np.ndarray, ...]:
        asked.append(n)  # the alternative's cloud: the person's place moved east
        return (pf.x + offset_m, pf.y.copy(), pf.theta.copy())

    with monkeypatch.context() as m:
        m.setattr(EvidenceTracker, "update", lambda self, *a, **k: True)
        m.setattr(EvidenceTracker, "strongest", lambda self: (POSE.x + offset_m, POSE.y, age))
        m.setattr(EvidenceTracker, "swap", swap)
        for _ in range(3):
            est = pf.step(still, seen)
    return len(asked), est.converged, math.hypot(est.x - POSE.x, est.y - POSE.y)


def test_a_young_alternative_inside_the_told_circle_is_not_swapped_in(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    swaps, converged, err = _swaps_asked(monkeypatch, 0.3, age=1)
    assert swaps == 0 and converged and err < 0.2


def test_one_through_its_probation_or_outside_the_circle_is(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    swaps, _, err = _swaps_asked(monkeypatch, 0.3, age=DEFAULT_EVIDENCE.probation)
    assert swaps >= 1 and err > 0.25
    swaps, _, err = _swaps_asked(monkeypatch, 8.0, age=1)
    assert swaps >= 1 and err > 4.0
