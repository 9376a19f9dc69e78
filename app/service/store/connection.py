"""A bare Redis connection for the journal: commands packed and replies parsed by hiredis."""

from __future__ import annotations

import asyncio
from collections import deque
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from redis.asyncio.connection import ConnectionPool


class Connection(asyncio.Protocol):
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
    async def open(cls, pool: ConnectionPool, timeout_s: float) -> Connection:
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
                await conn.call(pack("AUTH", *auth))
            if like.db:
                await conn.call(pack("SELECT", like.db))
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
            raise reply_error(str(reply))
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


def pack(*args: bytes | str | int) -> bytes:
    """A command in Redis's protocol, packed by hiredis (in C)."""
    import hiredis

    # (hiredis's stub types the tuple as one item long)
    return hiredis.pack_command(args)  # type: ignore[arg-type]


def reply_error(message: str) -> Exception:
    """The redis-py exception for an error reply (``NOSCRIPT ...``: NoScriptError)."""
    from redis.exceptions import NoScriptError, ResponseError

    return NoScriptError(message) if message.startswith("NOSCRIPT") else ResponseError(message)
