"""The check that a client's bearings and turns share the contract's sign convention."""

from __future__ import annotations

import math

import numpy as np
from fastapi.testclient import TestClient

from app.localization.types import Detection, Odometry, Pose
from app.service.conventions import MIN_VOTES, MIRRORED_WARNING, TurnSignCheck
from tests.helpers import paper_office, seen_from

OFFICE = paper_office()


def _turning(mirror: bool, frames: int = 60) -> list[tuple[Odometry, list[Detection]]]:
    """Standing in the paper office turning left 10 deg a frame, bearings with 2 deg
    noise (``mirror``: sent clockwise, as an image's x axis gives them)."""
    rng = np.random.default_rng(4)
    out = []
    for k in range(frames):
        seen = seen_from(OFFICE, Pose(4.0, 3.0, math.radians(10.0 * k)))
        sign = -1.0 if mirror else 1.0
        dets = [
            Detection(d.cls, sign * (d.bearing_rad + rng.normal(0.0, math.radians(2.0))), 1.0)
            for d in seen
        ]
        out.append((Odometry(0.0, 0.0, math.radians(10.0)), dets))
    return out


def test_bearings_sent_clockwise_are_named_once_and_right_ones_never() -> None:
    right, mirrored = TurnSignCheck(), TurnSignCheck()
    said_right = [right.update(o, d) for o, d in _turning(False)]
    said_mirrored = [mirrored.update(o, d) for o, d in _turning(True)]
    assert said_right == [None] * len(said_right) and right.agree >= MIN_VOTES
    assert said_mirrored.count(MIRRORED_WARNING) == 1
    first = said_mirrored.index(MIRRORED_WARNING)
    assert first < 30 and mirrored.agree + mirrored.disagree == MIN_VOTES


def test_a_turn_unknown_breaks_the_window_and_the_checkpoint_keeps_the_votes() -> None:
    check = TurnSignCheck()
    frames = _turning(True)
    for o, d in frames[:12]:
        assert check.update(o, d) is None
    votes = check.agree + check.disagree
    assert votes > 0
    assert check.update(None, frames[12][1]) is None  # no odometry: no window to vote on
    again = TurnSignCheck()
    again.restore(check.checkpoint())
    assert (again.agree, again.disagree) == (check.agree, check.disagree)
    said = [again.update(o, d) for o, d in frames[13:]]
    assert said.count(MIRRORED_WARNING) == 1
    restored_old = TurnSignCheck()
    restored_old.restore(None)  # a session checkpointed before the check
    assert restored_old.agree == restored_old.disagree == 0


def test_the_api_warns_a_client_whose_turns_are_clockwise(client: TestClient) -> None:
    sid = client.post("/sessions", json={"map": "paper_office", "particles": 500}).json()["id"]
    warned = []
    for k, (_, dets) in enumerate(_turning(False, 40)):
        frame = {
            "timestamp": 0.2 * k,
            "odometry": {"forward_m": 0.0, "left_m": 0.0, "turn_deg": -10.0},  # clockwise
            "detections": [
                {"class": d.cls, "bearing_deg": math.degrees(d.bearing_rad)} for d in dets
            ],
        }
        res = client.post(f"/sessions/{sid}/frames", json=frame).json()
        warned += [k for w in res["warnings"] if w == MIRRORED_WARNING]
    assert len(warned) == 1, warned
