"""Back-pressure: odometry composition, frame merging, the bounded per-session queue."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.config import FilterConfig
from app.localization.motion import compose_odometry, sample_motion
from app.localization.tolerances import motion_position_tolerance
from app.localization.types import Detection, Odometry, Pose
from app.service.errors import CapacityReached
from app.service.queueing import FrameQueue, merge_frames
from app.service.types import FrameInput, SessionSpec
from tests.helpers import make_manager

NO_NOISE = FilterConfig(
    trans_noise_frac=0.0, rot_noise_frac=0.0, trans_noise_floor_m=0.0, rot_noise_floor_deg=0.0
)
odometries = st.builds(
    Odometry,
    st.floats(-3, 3),
    st.floats(-3, 3),
    st.floats(-2 * math.pi, 2 * math.pi),
)


def move(poses: np.ndarray, odometry: Odometry) -> np.ndarray:
    """The motion model itself, without noise: the sequential application to compare with."""
    x, y, t = sample_motion(
        poses[0], poses[1], poses[2], odometry, NO_NOISE, np.random.default_rng(0)
    )
    return np.stack([x, y, t])


@settings(max_examples=200, deadline=None)
@given(st.lists(odometries, min_size=2, max_size=6))
def test_composed_odometry_equals_moving_step_by_step(steps: list[Odometry]) -> None:
    rng = np.random.default_rng(1)
    start = np.stack([rng.uniform(-5, 5, 8), rng.uniform(-5, 5, 8), rng.uniform(-3, 3, 8)])
    sequential = start
    composed: Odometry | None = steps[0]
    for step in steps:
        sequential = move(sequential, step)
    for step in steps[1:]:
        composed = compose_odometry(composed, step)
    assert composed is not None
    at_once = move(start, composed)
    # Both sides move through the motion kernel's approximate sincos: its bound for each
    # step taken one by one, plus the bound for the composed step (which adds a few
    # float64 roundings of its own, covered by the same coordinate-sized term).
    coordinate = 5.0 + sum(abs(o.forward_m) + abs(o.left_m) for o in steps)
    lengths = [math.hypot(o.forward_m, o.left_m) for o in steps]
    tol = sum(motion_position_tolerance(d, coordinate) for d in lengths)
    tol += motion_position_tolerance(math.hypot(composed.forward_m, composed.left_m), coordinate)
    tol += 8 * len(steps) * np.finfo(float).eps * coordinate
    np.testing.assert_allclose(at_once[:2], sequential[:2], atol=tol, rtol=0)
    dtheta = np.angle(np.exp(1j * (at_once[2] - sequential[2])))
    assert np.max(np.abs(dtheta)) < tol


def test_unknown_motion_makes_the_composition_unknown() -> None:
    assert compose_odometry(None, Odometry(1, 0, 0)) is None
    assert compose_odometry(Odometry(1, 0, 0), None) is None


def test_merge_keeps_the_newest_detections_and_ors_describe() -> None:
    old = FrameInput(
        timestamp=1.0,
        odometry=Odometry(1.0, 0.0, math.pi / 2),
        detections=(Detection("door", 0.1),),
        describe=True,
        truth=Pose(0, 0, 0),
    )
    new = FrameInput(
        timestamp=2.0,
        odometry=Odometry(1.0, 0.0, 0.0),
        detections=(Detection("window", -0.2), Detection("table", 1.0)),
        truth=Pose(1, 1, 1),
    )
    merged = merge_frames(old, new)
    assert merged.detections == new.detections and merged.timestamp == 2.0
    assert merged.truth == new.truth and merged.describe is True
    assert merged.odometry is not None
    assert (merged.odometry.forward_m, merged.odometry.left_m) == (1.0, 1.0)
    assert merged.odometry.turn_rad == math.pi / 2


def test_the_queue_holds_a_few_frames_and_merges_the_rest() -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        queue = FrameQueue(limit=2)
        merged = [
            queue.put(FrameInput(timestamp=float(i), odometry=Odometry(0.1)), loop.create_future())
            for i in range(10)
        ]
        assert merged == [False, False] + [True] * 8 and len(queue) == 2
        first, last = queue.pop(), queue.pop()
        assert first is not None and first.count == 1 and len(first.waiters) == 1
        assert last is not None and last.count == 9 and len(last.waiters) == 9
        assert last.frame.timestamp == 9.0 and last.frame.odometry is not None
        assert math.isclose(last.frame.odometry.forward_m, 0.9)
        assert queue.pop() is None

    asyncio.run(main())


def test_a_burst_is_answered_frame_by_frame_with_merge_warnings() -> None:
    async def main() -> None:
        manager = make_manager(max_queued_frames=2)
        session = await manager.create(SessionSpec(map_name="paper_office", particles=3000))
        frames = [FrameInput(timestamp=i * 0.01, odometry=Odometry(0.01)) for i in range(40)]
        futures = [manager.submit(session.id, f) for f in frames]
        outcomes = await asyncio.gather(*futures)
        seqs = [o.seq for o in outcomes]
        assert seqs == sorted(seqs) and seqs[-1] < 40  # fewer steps than frames
        merged = [o for o in outcomes if any("merged" in w for w in o.warnings)]
        assert merged and all(f"{seqs.count(o.seq)} frames" in o.warnings[-1] for o in merged)
        assert session.frames == seqs[-1]
        assert manager.metrics.frames_merged._value.get() == 40 - len(set(seqs))

    asyncio.run(main())


def test_new_sessions_are_refused_while_steps_pile_up() -> None:
    async def main() -> None:
        manager = make_manager(max_waiting_steps=2)
        try:
            # Three steps waiting their turn (none runs before the loop is free).
            held = [manager._steps.submit(f"k{i}", pow, 2, i) for i in range(3)]
            assert manager._steps.waiting == 3
            with pytest.raises(CapacityReached) as info:
                await manager.create(SessionSpec(map_name="paper_office", particles=200))
            assert info.value.code == "busy" and info.value.retry_after_s == 1.0
            assert await asyncio.gather(*held) == [1, 2, 4]
            await manager.create(SessionSpec(map_name="paper_office", particles=200))
        finally:
            manager.close()

    asyncio.run(main())
