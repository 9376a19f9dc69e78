"""Every accepted frame is answered exactly once: a fuzz of arrival times against the
merging queue, deterministic and without a wall clock.

A schedule is a list of events: frames arriving (a burst of several at one instant),
turns of the event loop passing (the filter steps in between), the session deleted,
the service's stepper shut down. The stepper yields after every step (``slice_s=0``),
so the interleaving depends on the schedule alone. Whatever the schedule, every
frame's future must end resolved, the results must come in the order the frames were
sent, and the frames merged into one step must share its result and be counted in it.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.types import Detection, Odometry
from app.service.errors import SessionNotFound, SessionUnavailable
from app.service.scheduler import FairStepper
from app.service.types import FrameInput, FrameOutcome, SessionSpec
from tests.helpers import make_manager


@dataclass(frozen=True)
class Arrive:
    frames: int


@dataclass(frozen=True)
class Turns:
    count: int


@dataclass(frozen=True)
class Delete:
    pass


@dataclass(frozen=True)
class Shutdown:
    pass


events = st.one_of(
    st.builds(Arrive, st.integers(1, 6)),
    st.builds(Turns, st.integers(0, 8)),
)
schedules = st.tuples(
    st.lists(events, min_size=1, max_size=30),
    st.sampled_from([None, Delete(), Shutdown()]),
    st.integers(0, 30),  # where the ending event falls
    st.integers(1, 3),  # the queue's limit of separate frames
)


def frame(i: int) -> FrameInput:
    return FrameInput(
        timestamp=0.1 * i,
        odometry=Odometry(0.05, 0.0, 0.01),
        detections=(Detection("door", 0.5, 0.9),),
    )


async def run(schedule: list[object], limit: int) -> tuple[list[asyncio.Future[FrameOutcome]], int]:
    manager = make_manager(max_queued_frames=limit)
    manager._steps = FairStepper(slice_s=0.0)  # yield after every step: no clock involved
    session = await manager.create(SessionSpec(map_name="paper_office", particles=200, seed=1))
    futures: list[asyncio.Future[FrameOutcome]] = []
    accepting = True
    for event in schedule:
        if isinstance(event, Arrive) and accepting:
            for _ in range(event.frames):
                futures.append(manager.submit(session.id, frame(len(futures))))
        elif isinstance(event, Turns):
            for _ in range(event.count):
                await asyncio.sleep(0)
        elif isinstance(event, Delete) and accepting:
            await manager.delete(session.id)
            accepting = False
        elif isinstance(event, Shutdown) and accepting:
            manager.close()
            accepting = False
    # Let whatever is still running finish; a pump never outlives its queue.
    if session.pump is not None:
        await asyncio.wait({session.pump}, timeout=60)
    assert session.pump is None
    return futures, len(session.queue)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(schedules)
def test_every_frame_is_answered_once_in_order_whatever_the_arrival_times(
    schedule: tuple[list[object], object, int, int],
) -> None:
    events_, ending, at, limit = schedule
    plan = list(events_)
    if ending is not None:
        plan.insert(min(at, len(plan)), ending)
    futures, left = asyncio.run(run(plan, limit))

    assert left == 0
    assert all(f.done() for f in futures), "a frame's future was never resolved"
    answered = [f.result() for f in futures if f.exception() is None]
    refused = [f.exception() for f in futures if f.exception() is not None]
    # Only the endings in the schedule refuse frames, and with their own error.
    for exc in refused:
        assert isinstance(exc, SessionNotFound | SessionUnavailable), exc
    if ending is None:
        assert not refused
    # Results come in the order the frames were sent: the answered frames are a prefix,
    # and their step numbers never go back.
    assert all(f.exception() is None for f in futures[: len(answered)])
    seqs = [r.seq for r in answered]
    assert seqs == sorted(seqs)
    # Frames merged into one step share its result, and that step counts them all: one
    # step per distinct result, and the step numbers are consecutive.
    distinct = list(dict.fromkeys(id(r) for r in answered))
    assert len({r.seq for r in answered}) == len(distinct)
    if answered:
        assert seqs[-1] - seqs[0] + 1 == len(distinct)
    for r in answered:
        share = sum(1 for other in answered if other is r)
        if share > 1:
            assert any(f"{share} frames arrived" in w for w in r.warnings)
