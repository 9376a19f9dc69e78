"""Back-pressure for one session: a short queue of frames, merged when it is full.

A session runs one filter step at a time. Frames that arrive meanwhile wait here; at
most ``limit`` of them stay separate, and every later frame is merged into the last
waiting one (motion composed in SE(2), the newest frame's detections, ``describe`` if
any asked). Every merged frame's sender gets the merged step's result, whose warnings
say how many frames it holds, so a client sending faster than the filter runs gets
answers that stay current instead of a backlog that grows without bound.
"""

from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass, field, replace

from app.localization.motion import compose_odometry
from app.service.types import FrameInput, FrameOutcome


def merge_frames(older: FrameInput, newer: FrameInput) -> FrameInput:
    """One frame standing for ``older`` then ``newer``.

    The motion is the composition of both odometries (unknown if either is); the
    detections, timestamp and ground truth are the newer frame's (older detections were
    seen from a pose the person has left); ``describe`` holds if either asked.
    """
    return replace(
        newer,
        odometry=compose_odometry(older.odometry, newer.odometry),
        describe=older.describe or newer.describe,
    )


def merged_warning(count: int) -> str:
    return (
        f"{count} frames arrived while the filter was busy and were merged into this step "
        "(motion added up, the newest frame's detections kept); send frames no faster "
        "than answers come back"
    )


@dataclass
class Waiting:
    """A frame waiting for its step (possibly several merged) and everyone awaiting it."""

    frame: FrameInput
    count: int = 1
    waiters: list[asyncio.Future[FrameOutcome]] = field(default_factory=list)


class FrameQueue:
    """The frames of one session waiting for the filter (event-loop thread only)."""

    def __init__(self, limit: int) -> None:
        self.limit = max(1, limit)
        self._items: deque[Waiting] = deque()

    def __len__(self) -> int:
        return len(self._items)

    def put(self, frame: FrameInput, waiter: asyncio.Future[FrameOutcome]) -> bool:
        """Queue ``frame``; True when it was merged into a frame already waiting."""
        if len(self._items) < self.limit:
            self._items.append(Waiting(frame, 1, [waiter]))
            return False
        tail = self._items[-1]
        tail.frame = merge_frames(tail.frame, frame)
        tail.count += 1
        tail.waiters.append(waiter)
        return True

    def pop(self) -> Waiting | None:
        return self._items.popleft() if self._items else None
