"""Where sessions live besides a worker's memory: the session store.

``--store memory`` (the default) keeps every session in the one process that serves it,
as a single machine needs: nothing is written anywhere. ``--store redis://HOST:PORT/DB``
shares sessions between workers (docs/API.md, "Overload and restarts"): each session's
checkpoint (:mod:`app.service.checkpoint`), a journal of the frames answered since it,
and a lease naming the one worker that may step it.

Keys of one session share a Redis Cluster hash tag, ``bearings:{ID}:...``:

* ``:ckpt``: the latest checkpoint, expiring after the idle timeout (``:ckpt:frames``:
  how many frames it covers; an older checkpoint never replaces a newer one);
* ``:journal``: a list of the frames answered since that checkpoint (same expiry);
* ``:lease``: the serving worker's token, with a short expiry (``--lease-s``) that the
  worker renews while it serves the session.

Every write is conditional on holding the lease (a server-side script compares the
token first), so a worker that lost its lease can never overwrite a newer state.

Most of the store's methods block: the session manager calls them from its own threads,
never on the event loop. The two writes made while sessions are served are coroutines
run on the event loop instead: :meth:`SessionStore.append`, made for every frame, and
:meth:`SessionStore.save`, a checkpoint of every session about once a second. The
journal entries of all sessions that arrive while one write is in flight, or within
``JOURNAL_GAP_S`` of the last one's start, go together in the next (group commit), so a
frame's answer waits for its journal entry to be stored without one round trip per
frame, and without a hand-off to another thread (on a busy worker those hand-offs cost
more CPU than the writes themselves; benchmarks/README.md).
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, cast
from urllib.parse import urlsplit, urlunsplit

if TYPE_CHECKING:
    from redis.asyncio.connection import ConnectionPool

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


class StoreUnavailable(RuntimeError):
    """The session store cannot be reached or refused an operation."""


class SessionStore(Protocol):
    """Checkpoints, journals and leases of sessions (see the module docstring).

    ``shared`` is False for a store only this process sees: the manager then keeps
    sessions in memory only and writes nothing.
    """

    shared: bool

    def acquire(self, session_id: str, owner: str, ttl_s: float) -> bool:
        """Take (or keep) the session's lease; False while another owner holds it."""
        ...

    def renew(self, session_ids: Sequence[str], owner: str, ttl_s: float) -> list[bool]:
        """Extend the leases still held by ``owner``; False for each one lost."""
        ...

    def release(self, session_ids: Sequence[str], owner: str) -> None:
        """Give up the leases ``owner`` holds (others' leases are left alone)."""
        ...

    def load(self, session_id: str) -> tuple[bytes | None, list[bytes]]:
        """The checkpoint (None if there is none) and the journal entries after it."""
        ...

    async def save(
        self, items: Sequence[tuple[str, bytes, int]], owner: str, ttl_s: float
    ) -> list[bool]:
        """Write checkpoints (session id, bytes, frames covered) where ``owner`` holds the
        lease, drop the journal entries they cover; False where the lease was lost. On
        the event loop, like :meth:`append`."""
        ...

    async def append(
        self, session_id: str, entry: bytes, owner: str, ttl_s: float, lease_s: float
    ) -> bool:
        """Add a journal entry (on the event loop); True once it is stored.

        A lease that ran out (the owner stalled) is taken back first when nobody went on
        with the session meanwhile: the stored frames end right before this entry's.
        False: another owner has the session."""
        ...

    def delete(self, session_id: str) -> None:
        """Forget the session: checkpoint, journal and lease."""
        ...

    async def aclose(self) -> None:
        """Close what belongs to the event loop (the connection it writes through), from it."""
        ...

    def close(self) -> None:
        """Close the blocking connections (after :meth:`aclose`)."""
        ...


def _seq(entry: bytes) -> int:
    return int(entry.partition(b"|")[0])


class MemoryStore:
    """The embedded store: the same operations on dictionaries of this process.

    ``shared=False`` (what ``--store memory`` builds) tells the manager that nothing
    needs writing, which keeps a single machine exactly as without a store.
    ``shared=True`` makes a store that several managers in one process can share, with
    the same semantics as Redis (expiry, leases, fencing): the tests use it.
    """

    def __init__(self, *, shared: bool = False) -> None:
        self.shared = shared
        self._lock = threading.Lock()
        self._values: dict[str, tuple[object, float]] = {}

    def _get(self, key: str) -> object | None:
        item = self._values.get(key)
        if item is None:
            return None
        if item[1] <= time.monotonic():
            del self._values[key]
            return None
        return item[0]

    def _put(self, key: str, value: object, ttl_s: float) -> None:
        self._values[key] = (value, time.monotonic() + ttl_s)

    def _touch(self, key: str, ttl_s: float) -> None:
        value = self._get(key)
        if value is not None:
            self._put(key, value, ttl_s)

    def acquire(self, session_id: str, owner: str, ttl_s: float) -> bool:
        with self._lock:
            holder = self._get(f"{session_id}:lease")
            if holder not in (None, owner):
                return False
            self._put(f"{session_id}:lease", owner, ttl_s)
            return True

    def renew(self, session_ids: Sequence[str], owner: str, ttl_s: float) -> list[bool]:
        with self._lock:
            held = [self._get(f"{sid}:lease") == owner for sid in session_ids]
            for sid, ok in zip(session_ids, held, strict=True):
                if ok:
                    self._put(f"{sid}:lease", owner, ttl_s)
            return held

    def release(self, session_ids: Sequence[str], owner: str) -> None:
        with self._lock:
            for sid in session_ids:
                if self._get(f"{sid}:lease") == owner:
                    del self._values[f"{sid}:lease"]

    def load(self, session_id: str) -> tuple[bytes | None, list[bytes]]:
        with self._lock:
            data = self._get(f"{session_id}:ckpt")
            journal = self._get(f"{session_id}:journal")
            return data, list(journal or [])  # type: ignore[return-value, call-overload]

    async def save(
        self, items: Sequence[tuple[str, bytes, int]], owner: str, ttl_s: float
    ) -> list[bool]:
        out = []
        with self._lock:
            for sid, data, frames in items:
                if self._get(f"{sid}:lease") != owner:
                    out.append(False)
                    continue
                out.append(True)
                stored = self._get(f"{sid}:ckpt:frames")
                if stored is not None and frames < stored:  # type: ignore[operator]
                    continue  # overtaken by a newer checkpoint
                self._put(f"{sid}:ckpt", data, ttl_s)
                self._put(f"{sid}:ckpt:frames", frames, ttl_s)
                journal = self._get(f"{sid}:journal") or []
                kept = [e for e in journal if _seq(e) > frames]  # type: ignore[attr-defined]
                self._put(f"{sid}:journal", kept, ttl_s)
        return out

    def _last_frame(self, session_id: str) -> int:
        journal = self._get(f"{session_id}:journal") or []
        stored = self._get(f"{session_id}:ckpt:frames")
        last = -1 if stored is None else int(stored)  # type: ignore[call-overload]
        return max([last, *(_seq(e) for e in journal)])  # type: ignore[attr-defined]

    async def append(
        self, session_id: str, entry: bytes, owner: str, ttl_s: float, lease_s: float
    ) -> bool:
        with self._lock:
            holder = self._get(f"{session_id}:lease")
            ok = holder == owner
            if holder is None and self._last_frame(session_id) == _seq(entry) - 1:
                self._put(f"{session_id}:lease", owner, lease_s)  # taken back
                ok = True
            if ok:
                journal = self._get(f"{session_id}:journal") or []
                self._put(f"{session_id}:journal", [*journal, entry], ttl_s)  # type: ignore[misc]
                self._touch(f"{session_id}:ckpt", ttl_s)
                self._touch(f"{session_id}:ckpt:frames", ttl_s)
        return ok

    def delete(self, session_id: str) -> None:
        with self._lock:
            for part in ("ckpt", "ckpt:frames", "journal", "lease"):
                self._values.pop(f"{session_id}:{part}", None)

    async def aclose(self) -> None:
        pass

    def close(self) -> None:
        pass


# Server-side scripts: each compares the lease's token before it writes anything.
_ACQUIRE = """
local v = redis.call('GET', KEYS[1])
if v == ARGV[1] then redis.call('PEXPIRE', KEYS[1], ARGV[2]) return 1 end
if v then return 0 end
redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[2])
return 1
"""
_RENEW = """
local out = {}
for i, k in ipairs(KEYS) do
  if redis.call('GET', k) == ARGV[1] then
    redis.call('PEXPIRE', k, ARGV[2]); out[i] = 1
  else out[i] = 0 end
end
return out
"""
_RELEASE = """
for _, k in ipairs(KEYS) do
  if redis.call('GET', k) == ARGV[1] then redis.call('DEL', k) end
end
return 0
"""
# KEYS: lease, ckpt, journal per session; ARGV: token, ttl_ms, then (data, frames) each.
# A checkpoint older than the stored one (two writes overtaking each other) is ignored.
_SAVE = """
local out = {}
for i = 1, #KEYS / 3 do
  local lease, ckpt, journal = KEYS[3*i-2], KEYS[3*i-1], KEYS[3*i]
  if redis.call('GET', lease) == ARGV[1] then
    local frames = tonumber(ARGV[2*i+2])
    local stored = tonumber(redis.call('GET', ckpt .. ':frames') or '-1')
    if frames >= stored then
      redis.call('SET', ckpt, ARGV[2*i+1], 'PX', ARGV[2])
      redis.call('SET', ckpt .. ':frames', frames, 'PX', ARGV[2])
      while true do
        local head = redis.call('LINDEX', journal, 0)
        if not head then break end
        local seq = tonumber(string.match(head, '^(%d+)|'))
        if seq == nil or seq > frames then break end
        redis.call('LPOP', journal)
      end
    end
    redis.call('PEXPIRE', journal, ARGV[2])
    out[i] = 1
  else out[i] = 0 end
end
return out
"""
# KEYS: lease, ckpt, journal per entry; ARGV: token, ttl_ms, lease_ms, then one entry
# each. A lapsed lease is taken back if the stored frames end right before the entry.
_APPEND = """
local out = {}
for i = 1, #KEYS / 3 do
  local lease, ckpt, journal = KEYS[3*i-2], KEYS[3*i-1], KEYS[3*i]
  local entry = ARGV[i+3]
  local holder = redis.call('GET', lease)
  if not holder then
    local last = tonumber(redis.call('GET', ckpt .. ':frames') or '-1')
    local tail = redis.call('LINDEX', journal, -1)
    if tail then last = math.max(last, tonumber(string.match(tail, '^(%d+)|'))) end
    if last == tonumber(string.match(entry, '^(%d+)|')) - 1 then
      redis.call('SET', lease, ARGV[1], 'PX', ARGV[3])
      holder = ARGV[1]
    end
  end
  if holder == ARGV[1] then
    redis.call('RPUSH', journal, entry)
    redis.call('PEXPIRE', journal, ARGV[2])
    redis.call('PEXPIRE', ckpt, ARGV[2])
    redis.call('PEXPIRE', ckpt .. ':frames', ARGV[2])
    out[i] = 1
  else out[i] = 0 end
end
return out
"""


def _keys(session_id: str) -> tuple[str, str, str]:
    base = f"bearings:{{{session_id}}}"
    return f"{base}:lease", f"{base}:ckpt", f"{base}:journal"


def _ms(seconds: float) -> int:
    return max(1, round(seconds * 1000))


def redacted(url: str) -> str:
    """The URL without a password (for logs and messages)."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    host = parts.hostname or ""
    if parts.port is not None:
        host = f"{host}:{parts.port}"
    user = f"{parts.username}:***@" if parts.username else ":***@"
    return urlunsplit(parts._replace(netloc=user + host))


Entry = tuple[str, bytes, str, int, int]  # session id, entry, owner, ttl ms, lease ms


class _GroupCommit:
    """Journal entries of all sessions, written many per round trip, on the event loop.

    Entries submitted while a write is in flight, or less than ``gap_s`` after the last
    one started, wait and go together in the next one. One instance serves one event
    loop (the Redis connection it writes through is bound to that loop).
    """

    def __init__(
        self,
        write: Callable[[list[Entry]], Awaitable[list[bool]]],
        gap_s: float = JOURNAL_GAP_S,
    ) -> None:
        self._write = write
        self._gap_s = gap_s
        self._pending: list[tuple[Entry, asyncio.Future[bool]]] = []
        self._writer: asyncio.Task[None] | None = None
        self._last_write = -math.inf

    def submit(self, item: Entry) -> asyncio.Future[bool]:
        loop = asyncio.get_running_loop()
        done: asyncio.Future[bool] = loop.create_future()
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
            except Exception as exc:  # each waiting frame gets it
                error = StoreUnavailable(f"journal write failed: {exc}")
                for _, done in batch:
                    if not done.done():
                        done.set_exception(error)
            else:
                for (_, done), ok in zip(batch, results, strict=True):
                    if not done.done():
                        done.set_result(ok)


class _Connection(asyncio.Protocol):
    """A bare Redis connection for the journal's script calls: the command is written
    to the transport as it is, and the replies, parsed by hiredis as the bytes arrive,
    resolve one future per command, in order.

    The journal writes once per batch of frames, so what a call costs the event loop's
    thread counts. Through a redis-py asyncio connection (its stream reader and writer,
    the drain, a timeout context and the health checks around every command) a batch of
    one cost about 24 us of CPU, and 87 us with the caches gone cold between calls as on
    a busy worker; through this one about 12 and 46 us (benchmarks/journal_call.py, Redis
    on the same core; on another, idle core every call costs 20-30 us more, both ways).

    It is made from the store's URL, with the client's own settings for it (host and
    port or a Unix socket, TLS, the user and password, the database). A call that times
    out closes the connection (its reply would come late, as the next call's), and so
    does a cancelled one. Error replies raise redis-py's exceptions (``NOSCRIPT``:
    :class:`~redis.exceptions.NoScriptError`), and a connection Redis closed raises its
    :class:`~redis.exceptions.ConnectionError`. Its writes need no flow control of their
    own: the group commit has one command in flight at a time, the size of one batch, and
    spaces them (``JOURNAL_GAP_S``).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, timeout_s: float) -> None:
        import hiredis

        self._loop = loop
        self._timeout_s = timeout_s
        self._reader = hiredis.Reader()
        self._reply_error = hiredis.ReplyError
        self._transport: asyncio.Transport | None = None
        #: The calls waiting for their replies, oldest first, each with its deadline.
        self._waiting: deque[tuple[asyncio.Future[Any], float]] = deque()
        #: One timer for all the calls, armed for the oldest one's deadline (a timer of
        #: each call's own, armed and cancelled, cost a sixth of the call's CPU).
        self._watch: asyncio.TimerHandle | None = None

    @classmethod
    async def open(cls, pool: ConnectionPool, timeout_s: float) -> _Connection:
        """A connection to where the pool's connections go, ready for commands."""
        from redis.asyncio.connection import Connection, SSLConnection, UnixDomainSocketConnection
        from redis.exceptions import ConnectionError
        from redis.exceptions import TimeoutError as RedisTimeoutError

        loop = asyncio.get_running_loop()
        # One of the pool's connections, never connected: only its settings are read.
        like = pool.connection_class(**pool.connection_kwargs)
        conn = cls(loop, timeout_s)
        try:
            async with asyncio.timeout(timeout_s):
                if isinstance(like, UnixDomainSocketConnection):
                    await loop.create_unix_connection(lambda: conn, like.path)
                else:
                    assert isinstance(like, Connection)
                    tls = like.ssl_context.get() if isinstance(like, SSLConnection) else None
                    await loop.create_connection(lambda: conn, like.host, like.port, ssl=tls)
            if like.password:
                auth = [like.username, like.password] if like.username else [like.password]
                await conn.call(_pack("AUTH", *auth))
            if like.db:
                await conn.call(_pack("SELECT", like.db))
        except TimeoutError:  # (asyncio's: an OSError too)
            conn.close()
            raise RedisTimeoutError(f"no connection to Redis in {timeout_s} s") from None
        except OSError as exc:
            conn.close()
            raise ConnectionError(f"cannot connect to Redis: {exc}") from exc
        except BaseException:
            conn.close()
            raise
        return conn

    @property
    def closed(self) -> bool:
        return self._transport is None or self._transport.is_closing()

    async def call(self, command: bytes) -> Any:
        """Send one packed command and wait for its reply."""
        transport = self._transport
        if transport is None or transport.is_closing():
            from redis.exceptions import ConnectionError

            raise ConnectionError("the journal's connection is closed")
        done = self._loop.create_future()
        self._waiting.append((done, self._loop.time() + self._timeout_s))
        if self._watch is None:
            self._watch = self._loop.call_later(self._timeout_s, self._expire)
        transport.write(command)
        try:
            reply = await done
        except BaseException:  # timed out, cancelled or lost: no reply to read later
            self.close()
            raise
        if isinstance(reply, self._reply_error):
            raise _reply_error(str(reply))
        return reply

    def _expire(self) -> None:
        """The watch: fail every call if the oldest is past its deadline, else wait on."""
        from redis.exceptions import TimeoutError

        self._watch = None
        if not self._waiting:
            return
        left = self._waiting[0][1] - self._loop.time()
        if left > 0:
            self._watch = self._loop.call_later(left, self._expire)
            return
        error = TimeoutError(f"no reply from Redis in {self._timeout_s} s")
        while self._waiting:
            done, _ = self._waiting.popleft()
            if not done.done():
                done.set_exception(error)

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()

    # asyncio.Protocol
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # (uvloop's transports are not asyncio.Transport subclasses, only alike)
        self._transport = cast(asyncio.Transport, transport)

    def data_received(self, data: bytes) -> None:
        self._reader.feed(data)
        try:
            while (reply := self._reader.gets()) is not False:
                if not self._waiting:  # a reply nobody asked for: out of step
                    self.close()
                    return
                done, _ = self._waiting.popleft()
                if not done.done():
                    done.set_result(reply)
        except Exception:  # hiredis.ProtocolError: not Redis, or garbled
            self.close()

    def connection_lost(self, exc: Exception | None) -> None:
        from redis.exceptions import ConnectionError

        if self._watch is not None:
            self._watch.cancel()
            self._watch = None
        while self._waiting:
            done, _ = self._waiting.popleft()
            if not done.done():
                done.set_exception(ConnectionError(f"Redis closed the connection ({exc})"))


def _pack(*args: bytes | str | int) -> bytes:
    """A command in Redis's protocol, packed by hiredis (in C)."""
    import hiredis

    # (hiredis's stub types the tuple as one item long)
    return hiredis.pack_command(args)  # type: ignore[arg-type]


def _reply_error(message: str) -> Exception:
    """The redis-py exception for an error reply (``NOSCRIPT ...``: NoScriptError)."""
    from redis.exceptions import NoScriptError, ResponseError

    return NoScriptError(message) if message.startswith("NOSCRIPT") else ResponseError(message)


class _OnLoop:
    """The store's writes from one event loop (journal entries and checkpoints): asyncio
    connections of its own, which belong to that loop, and the group commit of journal
    entries, which writes through a bare connection of its own (:class:`_Connection`).
    Writing from the loop, rather than from a thread, spares the two threads handing the
    GIL back and forth while a checkpoint's bytes are sent.

    At most ``CONNECTIONS`` checkpoint writes are in flight; more wait for a connection
    (up to the timeout) rather than fail: a burst of new sessions writes a checkpoint
    each at once.
    """

    CONNECTIONS = 8

    def __init__(
        self,
        url: str,
        timeout_s: float,
        loop: asyncio.AbstractEventLoop,
        journal_gap_s: float = JOURNAL_GAP_S,
    ) -> None:
        import redis.asyncio

        self.loop = loop
        self.timeout_s = timeout_s
        self.pool = redis.asyncio.BlockingConnectionPool.from_url(
            url,
            max_connections=self.CONNECTIONS,
            timeout=timeout_s,
            socket_timeout=timeout_s,
            socket_connect_timeout=timeout_s,
        )
        self.client = redis.asyncio.Redis(connection_pool=self.pool)
        self._append = self.client.register_script(_APPEND)
        self.save_checkpoints = self.client.register_script(_SAVE)
        self.commit = _GroupCommit(self._write, journal_gap_s)
        #: The journal's own connection (the group commit writes one batch at a time).
        self._journal: _Connection | None = None

    async def _write(self, batch: list[Entry]) -> list[bool]:
        # One script call per (owner, ttl, lease): in practice one per batch.
        results: dict[int, bool] = {}
        groups: dict[tuple[str, int, int], list[int]] = {}
        for i, (_, _, owner, ttl, lease) in enumerate(batch):
            groups.setdefault((owner, ttl, lease), []).append(i)
        for (owner, ttl, lease), rows in groups.items():
            keys = [k for i in rows for k in _keys(batch[i][0])]
            args: list[bytes | str | int] = [owner, ttl, lease]
            args += [batch[i][1] for i in rows]
            for i, v in zip(rows, await self._append_call(keys, args), strict=True):
                results[i] = bool(v)
        return [results[i] for i in range(len(batch))]

    async def _append_call(self, keys: list[str], args: list[bytes | str | int]) -> list[int]:
        """The append script run on the journal's own connection (:class:`_Connection`).

        A Redis that lost the script (restarted, or flushed) gets it again, once. A
        connection Redis closed (restarted, or killed it) is replaced, once, as the
        client's own retry would: should the first call have stored the entries after
        all, a replay skips the second copies (an entry carries its step's number). A
        restarted Redis does both in one call. Not after a timeout or any other error:
        Redis is slow or refuses, and the frames are better answered with an error at
        once.
        """
        from redis.exceptions import ConnectionError, NoScriptError

        command = _pack("EVALSHA", self._append.sha, len(keys), *keys, *args)
        loaded = reconnected = False
        while True:
            conn = self._journal
            if conn is None or conn.closed:
                conn = self._journal = await _Connection.open(self.pool, self.timeout_s)
            try:
                reply: list[int] = await conn.call(command)
                return reply
            except NoScriptError:
                if loaded:
                    raise
                loaded = True
                await conn.call(_pack("SCRIPT", "LOAD", _APPEND))
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


class RedisStore:
    """Sessions in Redis, shared by every worker given the same URL."""

    shared = True

    def __init__(
        self, url: str, *, timeout_s: float = 5.0, journal_gap_s: float = JOURNAL_GAP_S
    ) -> None:
        import redis

        self.url = url
        self.timeout_s = timeout_s
        self.journal_gap_s = journal_gap_s
        try:
            self._redis = redis.Redis.from_url(
                url, socket_timeout=timeout_s, socket_connect_timeout=timeout_s
            )
            self._redis.ping()
        except (redis.RedisError, ValueError) as exc:
            raise StoreUnavailable(
                f"cannot reach the session store at {redacted(url)}: {exc}"
            ) from None
        self._acquire = self._redis.register_script(_ACQUIRE)
        self._renew = self._redis.register_script(_RENEW)
        self._release = self._redis.register_script(_RELEASE)
        # Made on the event loop that first writes (an asyncio connection belongs to
        # one loop).
        self._writer: _OnLoop | None = None

    def acquire(self, session_id: str, owner: str, ttl_s: float) -> bool:
        return bool(self._acquire(keys=[_keys(session_id)[0]], args=[owner, _ms(ttl_s)]))

    def renew(self, session_ids: Sequence[str], owner: str, ttl_s: float) -> list[bool]:
        if not session_ids:
            return []
        keys = [_keys(sid)[0] for sid in session_ids]
        return [bool(v) for v in self._renew(keys=keys, args=[owner, _ms(ttl_s)])]

    def release(self, session_ids: Sequence[str], owner: str) -> None:
        if session_ids:
            self._release(keys=[_keys(sid)[0] for sid in session_ids], args=[owner])

    def load(self, session_id: str) -> tuple[bytes | None, list[bytes]]:
        _, ckpt, journal = _keys(session_id)
        pipe = self._redis.pipeline(transaction=True)
        pipe.get(ckpt)
        pipe.lrange(journal, 0, -1)
        data, entries = pipe.execute()
        return data, list(entries)

    async def save(
        self, items: Sequence[tuple[str, bytes, int]], owner: str, ttl_s: float
    ) -> list[bool]:
        writer = self._on_loop()
        out: list[bool] = []
        for start in range(0, len(items), 64):  # a few MB per call at most
            chunk = items[start : start + 64]
            keys = [k for sid, _, _ in chunk for k in _keys(sid)]
            args: list[bytes | str | int | float] = [owner, _ms(ttl_s)]
            for _, data, frames in chunk:
                args += [data, frames]
            out += [bool(v) for v in await writer.save_checkpoints(keys=keys, args=args)]
        return out

    def _on_loop(self) -> _OnLoop:
        loop = asyncio.get_running_loop()
        if self._writer is None or self._writer.loop is not loop:
            self._writer = _OnLoop(self.url, self.timeout_s, loop, self.journal_gap_s)
        return self._writer

    async def append(
        self, session_id: str, entry: bytes, owner: str, ttl_s: float, lease_s: float
    ) -> bool:
        item = (session_id, entry, owner, _ms(ttl_s), _ms(lease_s))
        return await self._on_loop().commit.submit(item)

    def delete(self, session_id: str) -> None:
        lease, ckpt, journal = _keys(session_id)
        self._redis.delete(lease, ckpt, f"{ckpt}:frames", journal)

    async def aclose(self) -> None:
        writer, self._writer = self._writer, None
        if writer is not None and writer.loop is asyncio.get_running_loop():
            await writer.aclose()

    def close(self) -> None:
        self._redis.close()


def open_store(url: str, *, journal_gap_s: float = JOURNAL_GAP_S) -> SessionStore:
    """The store a ``--store`` value names: ``memory`` or ``redis://HOST:PORT/DB``
    (``journal_gap_s``: see :data:`JOURNAL_GAP_S`)."""
    if url == "memory":
        return MemoryStore()
    scheme = urlsplit(url).scheme
    if scheme in ("redis", "rediss", "unix"):
        return RedisStore(url, journal_gap_s=journal_gap_s)
    raise ValueError(
        f"store: {redacted(url)!r} is neither 'memory' nor a redis:// (rediss://, unix://) URL"
    )
