"""Sessions in Redis, shared by every worker given the same URL."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from app.service.store.group_commit import JOURNAL_GAP_S
from app.service.store.protocol import Hold, StoreUnavailable
from app.service.store.scripts import ACQUIRE, RELEASE, RENEW, base_key, ms, session_keys
from app.service.store.urls import redacted
from app.service.store.writer import LoopWriter, one_retry

#: How long a journal write may wait for Redis's reply (seconds) before its frames are
#: answered without it: a Redis that stopped (SIGSTOP, a stalled disk) holds answers at
#: most this long, once; then the store counts as down and frames do not wait for it.
JOURNAL_TIMEOUT_S = 0.5


@contextmanager
def _reaching(what: str) -> Iterator[None]:
    """Redis's and the network's errors as :class:`StoreUnavailable`, naming ``what``."""
    from redis import RedisError

    try:
        yield
    except (RedisError, OSError) as exc:
        raise StoreUnavailable(f"{what}: {type(exc).__name__}: {exc}") from exc


class RedisStore:
    """Sessions in Redis (:mod:`app.service.store.scripts` lists the keys).

    The blocking methods (leases, loads, deletes) go through a redis-py client, on the
    session manager's threads; the writes made while sessions are served (journal
    entries, checkpoints) from the event loop (:class:`LoopWriter`). redis-py retries a
    call once, at once, and only if its connection failed
    (:func:`~app.service.store.writer.one_retry`); every
    failure to reach Redis is raised as :class:`StoreUnavailable`.
    """

    shared = True

    def __init__(
        self,
        url: str,
        *,
        timeout_s: float = 5.0,
        journal_gap_s: float = JOURNAL_GAP_S,
        journal_timeout_s: float = JOURNAL_TIMEOUT_S,
    ) -> None:
        import redis

        self.url = url
        self.timeout_s = timeout_s
        self.journal_gap_s = journal_gap_s
        self.journal_timeout_s = journal_timeout_s
        try:
            self._redis = redis.Redis.from_url(
                url,
                socket_timeout=timeout_s,
                socket_connect_timeout=timeout_s,
                retry=one_retry(on_loop=False),
            )
            self._redis.ping()
        except (redis.RedisError, ValueError) as exc:
            raise StoreUnavailable(
                f"cannot reach the session store at {redacted(url)}: {exc}"
            ) from None
        self._acquire = self._redis.register_script(ACQUIRE)
        self._renew = self._redis.register_script(RENEW)
        self._release = self._redis.register_script(RELEASE)
        # Made on the event loop that first writes (an asyncio connection belongs to
        # one loop).
        self._writer: LoopWriter | None = None

    def ping(self) -> None:
        with _reaching("ping"):
            self._redis.ping()

    def acquire(self, session_id: str, owner: str, lease_s: float, ttl_s: float) -> int | None:
        with _reaching("taking a lease"):
            args: list[str | int] = [owner, ms(lease_s), ms(ttl_s)]
            fence = int(self._acquire(keys=[base_key(session_id)], args=args))
        return fence or None

    def renew(
        self, items: Sequence[tuple[str, int]], owner: str, lease_s: float, ttl_s: float
    ) -> list[Hold]:
        if not items:
            return []
        keys = [base_key(sid) for sid, _ in items]
        args: list[str | int] = [owner, ms(lease_s), ms(ttl_s), *(f for _, f in items)]
        with _reaching("renewing leases"):
            return [Hold(v) for v in self._renew(keys=keys, args=args)]

    def release(self, session_ids: Sequence[str], owner: str) -> None:
        if session_ids:
            with _reaching("releasing leases"):
                self._release(keys=[base_key(sid) for sid in session_ids], args=[owner])

    def load(self, session_id: str) -> tuple[bytes | None, list[bytes]]:
        base = base_key(session_id)
        with _reaching("loading a session"):
            pipe = self._redis.pipeline(transaction=True)
            pipe.get(f"{base}:ckpt")
            pipe.lrange(f"{base}:journal", 0, -1)
            data, entries = pipe.execute()
        return data, list(entries)

    async def save(
        self,
        items: Sequence[tuple[str, bytes, int, int]],
        owner: str,
        lease_s: float,
        ttl_s: float,
    ) -> list[bool]:
        writer = self._on_loop()
        out: list[bool] = []
        for start in range(0, len(items), 64):  # a few MB per call at most
            chunk = items[start : start + 64]
            keys = [base_key(sid) for sid, _, _, _ in chunk]
            args: list[bytes | str | int | float] = [owner, ms(lease_s), ms(ttl_s)]
            for _, data, frames, fence in chunk:
                args += [data, frames, fence]
            with _reaching("writing checkpoints"):
                out += [bool(v) for v in await writer.save_checkpoints(keys=keys, args=args)]
        return out

    def _on_loop(self) -> LoopWriter:
        loop = asyncio.get_running_loop()
        if self._writer is None or self._writer.loop is not loop:
            self._writer = LoopWriter(
                self.url, self.timeout_s, loop, self.journal_gap_s, self.journal_timeout_s
            )
        return self._writer

    async def append(
        self, session_id: str, entry: bytes, owner: str, fence: int, lease_s: float, ttl_s: float
    ) -> Hold:
        item = (session_id, entry, owner, fence, ms(lease_s), ms(ttl_s))
        return await self._on_loop().commit.submit(item)

    def delete(self, session_id: str, ttl_s: float) -> None:
        with _reaching("deleting a session"):
            pipe = self._redis.pipeline(transaction=True)
            pipe.delete(*session_keys(session_id))
            pipe.set(f"{base_key(session_id)}:gone", 1, px=ms(ttl_s))
            pipe.execute()

    async def aclose(self) -> None:
        writer, self._writer = self._writer, None
        if writer is not None and writer.loop is asyncio.get_running_loop():
            await writer.aclose()

    def close(self) -> None:
        self._redis.close()
