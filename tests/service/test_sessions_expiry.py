"""Idle sessions expire; busy ones do not."""

from __future__ import annotations

import asyncio

from app.localization.types import Detection
from app.service.errors import SessionNotFound
from app.service.types import FrameInput, SessionSpec
from tests.helpers import make_manager


def test_idle_sessions_expire() -> None:
    async def main() -> None:
        manager = make_manager(session_idle_timeout_s=0.2)
        idle = await manager.create(SessionSpec(map_name="paper_office", particles=200))
        busy = await manager.create(SessionSpec(map_name="paper_office", particles=200))
        for _ in range(4):
            await asyncio.sleep(0.1)
            await manager.process(busy.id, FrameInput())
        assert await manager.expire_idle() == 1
        try:
            manager.get(idle.id)
        except SessionNotFound:
            pass
        else:
            raise AssertionError("idle session survived")
        assert manager.get(busy.id).frames == 4

    asyncio.run(main())


def test_snapshot_is_a_copy() -> None:
    async def main() -> None:
        manager = make_manager()
        s = await manager.create(SessionSpec(map_name="paper_office", particles=300))
        snap = s.snapshot()
        assert snap.estimate is None and snap.frames == 0
        await manager.process(s.id, FrameInput(detections=(Detection("door", 0.05, 1.0),)))
        later = s.snapshot()
        assert later.version == snap.version + 1 and later.frames == 1
        assert not np.shares_memory(later.x, s.filter.x)
        assert np.isclose(later.weights.sum(), 1.0)

    import numpy as np

    asyncio.run(main())
