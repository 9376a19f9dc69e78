"""The group commit: journal entries of all sessions, many per round trip.

A frame's answer waits for its journal entry to be stored, without one round trip per
frame and without a hand-off to another thread (on a busy worker those hand-offs cost
more CPU than the writes themselves; benchmarks/README.md): the entries of all sessions
that arrive while one write is in flight, or within ``JOURNAL_GAP_S`` of the last one's
start, go together in the next.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable

from app.service.store.protocol import Hold, StoreUnavailable

#: Most journal entries written in one round trip.
MAX_BATCH = 512
#: Least time from the start of one journal write to the next (seconds; the default of
#: the ``journal_gap_s`` setting): entries that
#: arrive sooner wait and go together. A worker at 1,200 frames/s wrote about 380 times a
#: second without it, each write a round trip that woke its event loop, and spent 9-11 %
#: more CPU a frame than with the memory store; with 10 ms, 2-4 % more, its p95 the same
#: (benchmarks/README.md). The price is latency at light load: at 120 frames/s a median
#: answer took 5.7 ms instead of 1.5. An entry after a quiet spell is written at once.
JOURNAL_GAP_S = 0.01


#: A journal entry to write: session id, entry, owner, fencing token, lease ms, ttl ms.
Entry = tuple[str, bytes, str, int, int, int]


class GroupCommit:
    """Journal entries of all sessions, written many per round trip, on the event loop.

    Entries submitted while a write is in flight, or less than ``gap_s`` after the last
    one started, wait and go together in the next one. One instance serves one event
    loop (the Redis connection it writes through is bound to that loop).
    """

    def __init__(
        self,
        write: Callable[[list[Entry]], Awaitable[list[Hold]]],
        gap_s: float = JOURNAL_GAP_S,
    ) -> None:
        self._write = write
        self._gap_s = gap_s
        self._pending: list[tuple[Entry, asyncio.Future[Hold]]] = []
        self._writer: asyncio.Task[None] | None = None
        self._last_write = -math.inf

    def submit(self, item: Entry) -> asyncio.Future[Hold]:
        loop = asyncio.get_running_loop()
        done: asyncio.Future[Hold] = loop.create_future()
        self._pending.append((item, done))
        if self._writer is None or self._writer.done():
            self._writer = loop.create_task(self._drain(), name="store-journal")
        return done

    async def _drain(self) -> None:
        loop = asyncio.get_running_loop()
        while self._pending:
            wait = self._last_write + self._gap_s - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)  # what arrives meanwhile joins this write
            self._last_write = loop.time()
            batch, self._pending = self._pending[:MAX_BATCH], self._pending[MAX_BATCH:]
            try:
                results = await self._write([item for item, _ in batch])
            except Exception as exc:  # each waiting frame learns it (and is answered without)
                error = StoreUnavailable(f"journal write failed: {exc}")
                for _, done in batch:
                    if not done.done():
                        done.set_exception(error)
            else:
                for (_, done), ok in zip(batch, results, strict=True):
                    if not done.done():
                        done.set_result(ok)
