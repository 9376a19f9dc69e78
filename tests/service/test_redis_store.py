"""The session stores: leases, fencing, journal, expiry; the same rules for the Redis
store (against a real redis-server) and the in-process one.

The Redis cases are skipped where redis-server is missing; required in CI (CI=true).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest
import redis

from app.config import Settings
from app.service.clock import ManualClock
from app.service.store import (
    JOURNAL_GAP_S,
    Hold,
    MemoryStore,
    SessionStore,
    StoreUnavailable,
    open_store,
)
from app.service.store.group_commit import Entry, GroupCommit
from app.service.store.redis_store import RedisStore
from tests.helpers import free_port, redis_server


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    with redis_server() as u:
        yield u


@pytest.fixture
def runner() -> Iterator[asyncio.Runner]:
    """One event loop for a whole test: the journal's connection belongs to one loop."""
    with asyncio.Runner() as r:
        yield r


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture(params=["redis", "memory"])
def store(
    request: pytest.FixtureRequest, runner: asyncio.Runner, clock: ManualClock
) -> Iterator[SessionStore]:
    if request.param == "memory":
        yield MemoryStore(shared=True, clock=clock)
        return
    url = request.getfixturevalue("url")
    redis.Redis.from_url(url).flushdb()
    s = RedisStore(url)
    yield s
    runner.run(s.aclose())
    s.close()


@pytest.fixture
def elapse(store: SessionStore, clock: ManualClock) -> Callable[[float], None]:
    """Let ``seconds`` pass for the store: the memory store's clock moves, Redis's
    own clock is waited for."""
    return clock.advance if isinstance(store, MemoryStore) else time.sleep


@pytest.fixture
def forget(store: SessionStore, request: pytest.FixtureRequest) -> Callable[[], None]:
    """The store loses every key, as after a restart without persistence."""
    if isinstance(store, MemoryStore):
        return store.forget_everything
    return redis.Redis.from_url(request.getfixturevalue("url")).flushall


@pytest.fixture
def append(store: SessionStore, runner: asyncio.Runner) -> Callable[..., Hold]:
    """``store.append`` run to completion on the test's event loop."""
    return lambda sid, entry, owner, fence, lease_s=5, ttl_s=60: runner.run(
        store.append(sid, entry, owner, fence, lease_s, ttl_s)
    )


@pytest.fixture
def save(store: SessionStore, runner: asyncio.Runner) -> Callable[..., list[bool]]:
    """``store.save`` run to completion on the test's event loop."""
    return lambda items, owner, lease_s=5, ttl_s=60: runner.run(
        store.save(items, owner, lease_s, ttl_s)
    )


HELD, LOST, RETAKEN, GAP = Hold.HELD, Hold.LOST, Hold.RETAKEN, Hold.GAP


def test_one_lease_at_a_time_and_it_runs_out(
    store: SessionStore, elapse: Callable[[float], None]
) -> None:
    f1 = store.acquire("s1", "w1", 0.3, 60)
    assert f1 is not None
    assert store.acquire("s1", "w1", 0.3, 60) == f1  # the holder keeps it, and its token
    assert store.acquire("s1", "w2", 0.3, 60) is None
    assert store.renew([("s1", f1)], "w1", 0.3, 60) == [HELD]
    store.release(["s1"], "w2")  # not w2's to release
    assert store.acquire("s1", "w2", 0.3, 60) is None
    elapse(0.4)
    f2 = store.acquire("s1", "w2", 0.3, 60)
    assert f2 is not None and f2 > f1  # a new tenure, a new fencing token
    assert store.renew([("s1", f1)], "w1", 0.3, 60) == [LOST]
    store.release(["s1"], "w2")
    assert store.acquire("s1", "w1", 0.3, 60) == f2 + 1


def test_writes_need_the_lease(
    store: SessionStore, append: Callable[..., Hold], save: Callable[..., list[bool]]
) -> None:
    f = store.acquire("s1", "w1", 5, 60)
    assert f is not None
    assert save([("s1", b"ckpt-0", 0, f)], "w1") == [True]
    assert [append("s1", b"%d|{}" % i, "w1", f) for i in (1, 2, 3)] == [HELD] * 3
    assert store.load("s1") == (b"ckpt-0", [b"1|{}", b"2|{}", b"3|{}"])
    # A checkpoint covering frame 2 drops the entries it covers, keeps the rest.
    assert save([("s1", b"ckpt-2", 2, f)], "w1") == [True]
    assert store.load("s1") == (b"ckpt-2", [b"3|{}"])
    assert save([("s1", b"other", 9, f)], "w2") == [False]  # w2 holds no lease
    assert save([("s1", b"other", 9, f + 1)], "w1") == [False]  # nor a later token
    assert store.load("s1")[0] == b"ckpt-2"
    # An entry that would leave a gap is not written.
    assert append("s1", b"5|{}", "w1", f) == GAP
    # Two writes overtaking each other: the older checkpoint does not replace the newer,
    # and an entry the stored checkpoint covers is not written again.
    assert append("s1", b"4|{}", "w1", f) == HELD
    assert save([("s1", b"ckpt-4", 4, f)], "w1") == [True]
    assert save([("s1", b"ckpt-3", 3, f)], "w1") == [True]
    assert append("s1", b"4|{}", "w1", f) == HELD
    assert store.load("s1") == (b"ckpt-4", [])


def test_a_lapsed_lease_is_taken_back_only_if_nobody_took_the_session(
    store: SessionStore,
    append: Callable[..., Hold],
    save: Callable[..., list[bool]],
    elapse: Callable[[float], None],
) -> None:
    f1 = store.acquire("s1", "w1", 0.2, 60)
    assert f1 is not None
    assert save([("s1", b"ckpt-2", 2, f1)], "w1", 0.2) == [True]
    assert append("s1", b"3|{}", "w1", f1, 0.2) == HELD
    elapse(0.3)  # w1 stalled: its lease ran out, nobody took the session
    assert append("s1", b"4|{}", "w1", f1) == HELD  # taken back with the same token
    assert store.acquire("s1", "w2", 5, 60) is None  # and w1 holds the lease again
    store.release(["s1"], "w1")
    f2 = store.acquire("s1", "w2", 5, 60)
    assert f2 is not None
    store.release(["s1"], "w2")  # w2 took it and let it go without a frame
    # w1 comes back: its token is older than the session's latest; refused everywhere.
    assert append("s1", b"5|{}", "w1", f1) == LOST
    assert save([("s1", b"stale", 9, f1)], "w1") == [False]
    assert store.renew([("s1", f1)], "w1", 5, 60) == [LOST]
    assert store.load("s1") == (b"ckpt-2", [b"3|{}", b"4|{}"])


def test_a_lease_that_vanished_with_the_store_is_taken_back_by_its_holder(
    store: SessionStore,
    append: Callable[..., Hold],
    save: Callable[..., list[bool]],
    forget: Callable[[], None],
) -> None:
    """The store restarted empty: the worker still holding the session takes its lease
    back, learns that the stored frames are gone (GAP), and a checkpoint stores it."""
    f = store.acquire("s1", "w1", 5, 60)
    g = store.acquire("s2", "w1", 5, 60)
    assert f is not None and g is not None
    assert save([("s1", b"ckpt-0", 0, f), ("s2", b"ckpt-0", 0, g)], "w1") == [True, True]
    assert append("s1", b"1|{}", "w1", f) == HELD
    forget()
    assert store.renew([("s1", f)], "w1", 5, 60) == [RETAKEN]
    assert store.renew([("s1", f)], "w1", 5, 60) == [HELD]
    assert store.acquire("s1", "w2", 5, 60) is None  # held again
    assert append("s1", b"2|{}", "w1", f) == GAP  # frame 1 is gone from the store
    assert append("s2", b"1|{}", "w1", g) == GAP  # taken back by the entry itself
    assert save([("s1", b"ckpt-2", 2, f)], "w1") == [True]
    assert append("s1", b"3|{}", "w1", f) == HELD
    assert store.load("s1") == (b"ckpt-2", [b"3|{}"])
    # A later tenure still gets a later token than the one taken back.
    store.release(["s1"], "w1")
    assert store.acquire("s1", "w2", 5, 60) == f + 1


def test_journal_entries_from_many_sessions_in_one_round_trip(
    store: SessionStore, runner: asyncio.Runner
) -> None:
    ids = [f"s{i}" for i in range(50)]
    fences = {sid: store.acquire(sid, "w1", 5, 60) for sid in ids}
    saved = runner.run(store.save([(sid, b"c", 0, f) for sid, f in fences.items()], "w1", 5, 60))
    assert all(saved)

    async def all_at_once() -> list[Hold]:
        return await asyncio.gather(
            *(
                store.append(sid, b"%d|x" % seq, "w1", fences[sid], 5, 60)  # type: ignore[arg-type]
                for sid in ids
                for seq in (1, 2, 3)
            )
        )

    assert runner.run(all_at_once()) == [HELD] * 150
    assert all(len(store.load(sid)[1]) == 3 for sid in ids)


def test_journal_writes_keep_a_gap_and_what_arrives_within_it_goes_together() -> None:
    """The group commit writes an entry at once when nothing was written lately, and
    holds later entries until ``gap_s`` after that write started, to send them in one
    call (each call is a round trip and wakes the worker's loop)."""
    batches: list[list[str]] = []

    async def write(batch: list[Entry]) -> list[Hold]:
        batches.append([sid for sid, *_ in batch])
        return [HELD] * len(batch)

    async def scenario() -> None:
        commit = GroupCommit(write, gap_s=0.3)
        entry = lambda sid: commit.submit((sid, b"1|x", "w1", 1, 5_000, 60_000))  # noqa: E731
        loop = asyncio.get_running_loop()
        started = loop.time()
        await asyncio.wait_for(entry("a"), 5)  # written at once
        assert loop.time() - started < 0.3
        b = entry("b")
        await asyncio.sleep(0.05)  # written alone, were there no gap to keep
        c, d = entry("c"), entry("d")
        assert await asyncio.gather(b, c, d) == [HELD] * 3
        assert loop.time() - started >= 0.3

    asyncio.run(scenario())
    assert batches == [["a"], ["b", "c", "d"]]


def test_the_journal_gap_is_a_setting(url: str) -> None:
    assert Settings().journal_gap_s == JOURNAL_GAP_S  # the default, written in two places
    store = open_store(url, journal_gap_s=0.25)
    try:
        commit = asyncio.run(_commit_of(store))
        assert commit._gap_s == 0.25
    finally:
        store.close()
    with pytest.raises(ValueError, match="journal_gap_s"):
        Settings(journal_gap_s=-0.01)


async def _commit_of(store: SessionStore) -> GroupCommit:
    assert isinstance(store, RedisStore)
    commit = store._on_loop().commit
    await store.aclose()
    return commit


@pytest.fixture(params=["asyncio", "uvloop"])
def loops(request: pytest.FixtureRequest) -> Iterator[asyncio.Runner]:
    """One event loop for a whole test, of either kind (``bearings serve`` runs uvloop):
    the journal's connection is a protocol on the loop's own transports."""
    import uvloop

    factory = uvloop.new_event_loop if request.param == "uvloop" else None
    with asyncio.Runner(loop_factory=factory) as r:
        yield r


def journal_through(url: str, runner: asyncio.Runner) -> None:
    """A store at ``url`` takes a lease, journals three frames and reads them back."""
    store = RedisStore(url)
    try:
        f = store.acquire("s1", "w1", 5, 60)
        assert f is not None
        assert runner.run(store.save([("s1", b"c", 0, f)], "w1", 5, 60)) == [True]
        for seq in (1, 2, 3):
            assert runner.run(store.append("s1", b"%d|{}" % seq, "w1", f, 5, 60)) == HELD
        assert store.load("s1")[1] == [b"1|{}", b"2|{}", b"3|{}"]
    finally:
        runner.run(store.aclose())
        store.close()


def test_the_journal_logs_in_and_picks_the_database_the_url_names(
    loops: asyncio.Runner,
) -> None:
    """The journal's connection of its own authenticates (a password, or a user and a
    password) and selects the URL's database, as the client's connections do."""
    user = ["--user", "bearings", "on", ">pw2", "~*", "&*", "+@all"]
    with redis_server("--requirepass", "pw1", *user) as plain:
        port = urlsplit(plain).port
        journal_through(f"redis://:pw1@127.0.0.1:{port}/3", loops)
        journal_through(f"redis://bearings:pw2@127.0.0.1:{port}/5", loops)
        sizes = [redis.Redis(port=port, password="pw1", db=db).dbsize() for db in (0, 3, 5)]
        # a lease, a fencing token, a checkpoint (with its frame count) and a journal in
        # each of the URLs' databases
        assert sizes == [0, 5, 5]


def test_the_journal_reaches_redis_through_a_unix_socket(
    loops: asyncio.Runner, tmp_path: Path
) -> None:
    sock = tmp_path / "redis.sock"
    with redis_server("--unixsocket", str(sock), "--unixsocketperm", "700"):
        journal_through(f"unix://{sock}?db=2", loops)


def test_the_journal_goes_on_after_redis_forgets_its_script_or_drops_it(
    url: str, loops: asyncio.Runner
) -> None:
    """The journal writes through a connection of its own: a Redis that forgot its
    scripts, that closed that connection (while it was idle, or while a write waited for
    its reply), or both at once as after a restart, must not lose an entry."""
    r = redis.Redis.from_url(url)
    r.flushdb()
    store = RedisStore(url)
    f = store.acquire("s1", "w1", 5, 60)
    assert f is not None

    async def killed_while_it_waits(seq: int) -> Hold:
        r.client_pause(10_000, all=False)  # the script waits in Redis
        try:
            pending = asyncio.ensure_future(store.append("s1", b"%d|{}" % seq, "w1", f, 5, 60))
            await asyncio.sleep(0.1)
            r.client_kill_filter(_type="normal", skipme=True)
            await asyncio.sleep(0.1)
        finally:
            r.client_unpause()
        return await pending

    try:
        assert loops.run(store.save([("s1", b"c", 0, f)], "w1", 5, 60)) == [True]
        append = lambda seq: loops.run(store.append("s1", b"%d|{}" % seq, "w1", f, 5, 60))  # noqa: E731
        assert append(1) == HELD
        r.script_flush()
        assert append(2) == HELD
        r.client_kill_filter(_type="normal", skipme=True)
        assert append(3) == HELD
        assert loops.run(killed_while_it_waits(4)) == HELD
        r.script_flush()
        assert loops.run(killed_while_it_waits(5)) == HELD  # both in one write
        assert store.load("s1")[1] == [b"%d|{}" % seq for seq in (1, 2, 3, 4, 5)]
    finally:
        loops.run(store.aclose())
        store.close()


def test_a_journal_write_without_a_reply_fails_in_time_and_its_connection_goes(
    url: str, loops: asyncio.Runner
) -> None:
    """A Redis that does not answer: the write fails after the journal's timeout (the
    frames waiting for it are answered without it), and its late reply is never taken
    for the next write's."""
    r = redis.Redis.from_url(url)
    r.flushdb()
    store = RedisStore(url, journal_timeout_s=0.3)
    f = store.acquire("s1", "w1", 5, 60)
    assert f is not None

    async def next_write_then_unpause() -> Hold:
        pending = asyncio.ensure_future(store.append("s1", b"2|{}", "w1", f, 5, 60))
        await asyncio.sleep(0.1)  # written, behind the first one if on its connection
        r.client_unpause()
        return await pending

    try:
        assert loops.run(store.save([("s1", b"c", 0, f)], "w1", 5, 60)) == [True]
        assert loops.run(store.append("s1", b"1|{}", "w1", f, 5, 60)) == HELD
        r.client_pause(10_000, all=False)  # scripts wait; CLIENT UNPAUSE does not
        start = time.monotonic()
        with pytest.raises(StoreUnavailable, match=r"no reply from Redis in 0\.3 s"):
            # s2 has no checkpoint: Redis refuses this entry (a gap), when it runs it
            loops.run(store.append("s2", b"1|{}", "w1", 1, 5, 60))
        assert time.monotonic() - start < 2.0
        assert loops.run(next_write_then_unpause()) == HELD
        assert store.load("s1")[1] == [b"1|{}", b"2|{}"]
    finally:
        r.client_unpause()
        loops.run(store.aclose())
        store.close()


def test_a_burst_of_checkpoints_waits_for_connections_rather_than_failing(
    store: SessionStore, runner: asyncio.Runner
) -> None:
    """Many sessions created at once each write a checkpoint at once (more than the
    client's pool of connections holds)."""
    ids = [f"s{i}" for i in range(150)]
    fences = {sid: store.acquire(sid, "w1", 60, 60) for sid in ids}

    async def burst() -> list[list[bool]]:
        return await asyncio.gather(
            *(store.save([(sid, b"ckpt", 0, f)], "w1", 60, 60) for sid, f in fences.items())  # type: ignore[list-item]
        )

    assert runner.run(burst()) == [[True]] * len(ids)
    assert all(store.load(sid) == (b"ckpt", []) for sid in ids)


def test_checkpoints_expire_after_the_idle_timeout(
    store: SessionStore,
    append: Callable[..., Hold],
    save: Callable[..., list[bool]],
    elapse: Callable[[float], None],
) -> None:
    f = store.acquire("s1", "w1", 5, 0.3)
    assert save([("s1", b"ckpt", 0, f)], "w1", 5, 0.3) == [True]
    assert append("s1", b"1|{}", "w1", f, 5, 0.3) == HELD
    elapse(0.2)
    assert store.load("s1") == (b"ckpt", [b"1|{}"])
    elapse(0.25)
    assert store.load("s1") == (None, [])


def test_delete_forgets_everything_and_its_holder_cannot_take_it_back(
    store: SessionStore, append: Callable[..., Hold], save: Callable[..., list[bool]]
) -> None:
    f = store.acquire("s1", "w1", 5, 60)
    assert save([("s1", b"ckpt", 0, f)], "w1") == [True]
    store.delete("s1", 60)
    assert store.load("s1") == (None, [])
    # The worker that held it (and missed the deletion) is told it lost the session.
    assert store.renew([("s1", f)], "w1", 5, 60) == [LOST]
    assert append("s1", b"1|{}", "w1", f) == LOST
    assert save([("s1", b"ckpt", 1, f)], "w1") == [False]
    assert store.load("s1") == (None, [])
    assert store.acquire("s1", "w2", 5, 60) is not None


def test_an_unreachable_store_says_where_it_looked() -> None:
    port = free_port()
    with pytest.raises(StoreUnavailable, match=f"127.0.0.1:{port}"):
        open_store(f"redis://:secret@127.0.0.1:{port}/0")
    try:
        open_store(f"redis://:secret@127.0.0.1:{port}/0")
    except StoreUnavailable as exc:
        assert "secret" not in str(exc)
    with pytest.raises(ValueError, match="neither 'memory'"):
        open_store("postgres://x")


def test_sessions_move_between_managers_through_redis(url: str) -> None:
    """The manager-level handover of test_checkpoint.py, through a real Redis."""
    from tests.service.test_checkpoint import SPEC, frame, manager

    redis.Redis.from_url(url).flushdb()

    async def main() -> None:
        a, b = manager(RedisStore(url)), manager(RedisStore(url))
        sid = (await a.create(SPEC)).id
        for i in range(10):
            assert (await a.process(sid, frame(i))).seq == i + 1
        await a.sharing.shutdown()  # clean stop: checkpoint, release
        out = await b.process(sid, frame(10))
        assert out.seq == 11 and out.estimate.converged
        await b.sharing.shutdown()
        for m in (a, b):
            m.close()

    asyncio.run(main())
