"""The Redis store's writes from one event loop: journal entries and checkpoints."""

from __future__ import annotations

import asyncio
from typing import Any

from app.service.store.connection import Connection, pack
from app.service.store.group_commit import JOURNAL_GAP_S, Entry, GroupCommit
from app.service.store.protocol import Hold
from app.service.store.scripts import APPEND, SAVE, base_key


def one_retry(*, on_loop: bool) -> Any:
    """redis-py's retry policy for the store's clients (``on_loop``: its asyncio
    client's, else its blocking one's): one retry at once, and only of a connection that
    failed (a pooled connection Redis closed when it restarted). redis-py 6 and later
    retry a failed call up to 10 times with growing waits (about 5 s in all), which would
    hold a frame's answer that long while Redis is down; the session manager has its own
    answer to an unreachable store (serve from memory, try again with backoff)."""
    from redis.backoff import NoBackoff
    from redis.exceptions import ConnectionError

    if on_loop:
        from redis.asyncio.retry import Retry as LoopRetry

        return LoopRetry(NoBackoff(), 1, supported_errors=(ConnectionError,))
    from redis.retry import Retry

    return Retry(NoBackoff(), 1, supported_errors=(ConnectionError,))


class LoopWriter:
    """The store's writes from one event loop (journal entries and checkpoints): asyncio
    connections of its own, which belong to that loop, and the group commit of journal
    entries, which writes through a bare connection of its own (:class:`Connection`).
    Writing from the loop, rather than from a thread, spares the two threads handing the
    GIL back and forth while a checkpoint's bytes are sent.

    At most ``CONNECTIONS`` checkpoint writes are in flight; more wait for a connection
    (up to the timeout) rather than fail: a burst of new sessions writes a checkpoint
    each at once. A journal write gives up after ``journal_timeout_s``: its frames are
    then answered without waiting longer for a store that does not reply.
    """

    CONNECTIONS = 8

    def __init__(
        self,
        url: str,
        timeout_s: float,
        loop: asyncio.AbstractEventLoop,
        journal_gap_s: float = JOURNAL_GAP_S,
        journal_timeout_s: float | None = None,
    ) -> None:
        import redis.asyncio

        self.loop = loop
        self.timeout_s = timeout_s
        self.journal_timeout_s = timeout_s if journal_timeout_s is None else journal_timeout_s
        self.pool = redis.asyncio.BlockingConnectionPool.from_url(
            url,
            max_connections=self.CONNECTIONS,
            timeout=timeout_s,
            socket_timeout=timeout_s,
            socket_connect_timeout=timeout_s,
            retry=one_retry(on_loop=True),
        )
        self.client = redis.asyncio.Redis(connection_pool=self.pool)
        self._append = self.client.register_script(APPEND)
        self.save_checkpoints = self.client.register_script(SAVE)
        self.commit = GroupCommit(self._write, journal_gap_s)
        #: The journal's own connection (the group commit writes one batch at a time).
        self._journal: Connection | None = None

    async def _write(self, batch: list[Entry]) -> list[Hold]:
        # One script call per (owner, lease, ttl): in practice one per batch.
        results: dict[int, Hold] = {}
        groups: dict[tuple[str, int, int], list[int]] = {}
        for i, (_, _, owner, _, lease, ttl) in enumerate(batch):
            groups.setdefault((owner, lease, ttl), []).append(i)
        for (owner, lease, ttl), rows in groups.items():
            keys = [base_key(batch[i][0]) for i in rows]
            args: list[bytes | str | int] = [owner, lease, ttl]
            for i in rows:
                args += [batch[i][3], batch[i][1]]
            for i, v in zip(rows, await self._append_call(keys, args), strict=True):
                results[i] = Hold(v)
        return [results[i] for i in range(len(batch))]

    async def _append_call(self, keys: list[str], args: list[bytes | str | int]) -> list[int]:
        """The append script run on the journal's own connection (:class:`Connection`).

        A Redis that lost the script (restarted, or flushed) gets it again, once. A
        connection Redis closed (restarted, or killed it) is replaced, once, as the
        client's own retry would: should the first call have stored the entries after
        all, a replay writes nothing twice (an entry is written only right after the
        stored frames). A restarted Redis does both in one call. Not after a timeout or
        any other error: Redis is slow or refuses, and the frames are better answered at
        once (without the store).
        """
        from redis.exceptions import ConnectionError, NoScriptError

        command = pack("EVALSHA", self._append.sha, len(keys), *keys, *args)
        loaded = reconnected = False
        while True:
            conn = self._journal
            if conn is None or conn.closed:
                conn = self._journal = await Connection.open(self.pool, self.journal_timeout_s)
            try:
                reply: list[int] = await conn.call(command)
                return reply
            except NoScriptError:
                if loaded:
                    raise
                loaded = True
                await conn.call(pack("SCRIPT", "LOAD", APPEND))
            except ConnectionError:
                if reconnected:
                    raise
                reconnected = True

    async def aclose(self) -> None:
        if self._journal is not None:
            self._journal.close()
            self._journal = None
        await self.client.aclose()
        await self.pool.disconnect()
