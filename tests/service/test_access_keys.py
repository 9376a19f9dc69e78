"""The key file, key checks, the token bucket and the fair step executor."""

from __future__ import annotations

import threading
import time

import pytest

from app.service.access import KeyFileError, TokenBucket, parse_keys
from app.service.scheduler import FairExecutor

DEFAULTS = {"default_sessions": 10, "default_particles": 100_000, "default_frames_per_s": 50.0}
K1 = "k1-aaaaaaaaaaaaaaaaaaaa"
K2 = "k2-bbbbbbbbbbbbbbbbbbbb"


def test_a_key_file_with_both_forms_comments_and_defaults() -> None:
    ring = parse_keys(
        f"# keys\n\n{K1}   # a bare key\nphone {K2} 3 - 20.5\n", source="keys.txt", **DEFAULTS
    )
    assert len(ring) == 2
    bare, phone = ring.principals
    assert bare.name is not None and bare.name.startswith("key-") and K1 not in bare.name
    assert (bare.max_sessions, bare.max_particles, bare.max_frames_per_s) == (10, 100_000, 50.0)
    assert (phone.name, phone.max_sessions, phone.max_particles, phone.max_frames_per_s) == (
        "phone",
        3,
        100_000,
        20.5,
    )
    assert ring.authenticate(K2) == phone and ring.authenticate(K1) == bare
    assert ring.authenticate(K2 + "x") is None and ring.authenticate("") is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (f"{K1}\nname {K2} 1 2\n", "keys.txt, line 2: expected 'KEY' or 'NAME KEY"),
        ("short\n", "line 1: the key has 5 characters; use at least 16"),
        (f"a {K1} 1 2 3\na {K2} 1 2 3\n", "line 2: the name 'a' is already used on line 1"),
        (f"a {K1} 1 2 3\nb {K1} 1 2 3\n", "line 2: the same key is already on line 1"),
        (f"a {K1} many 2 3\n", "line 1: max_sessions must be a number or '-', not 'many'"),
        (f"a {K1} 1 0 3\n", "line 1: max_particles must be positive"),
        (f"a {K1} 1 2 nan\n", "line 1: max_frames_per_s must be positive"),
        (f"bad/name {K1} 1 2 3\n", "line 1: the name 'bad/name' may only hold"),
        ("# nothing\n\n", "no keys in the file"),
    ],
)
def test_bad_key_files_name_the_line_and_the_reason(text: str, message: str) -> None:
    with pytest.raises(KeyFileError) as info:
        parse_keys(text, source="keys.txt", **DEFAULTS)
    assert message in str(info.value)
    assert K1 not in str(info.value) and K2 not in str(info.value)  # never echo a key


def test_token_bucket_allows_a_burst_then_the_rate() -> None:
    bucket = TokenBucket(rate=20.0)
    assert all(bucket.take() == 0 for _ in range(20))
    wait = bucket.take()
    assert 0 < wait <= 1 / 20 + 1e-6
    time.sleep(wait + 0.01)
    assert bucket.take() == 0


def test_fair_executor_serves_a_light_owner_between_a_heavy_owners_jobs() -> None:
    pool = FairExecutor(1)
    gate = threading.Event()
    order: list[str] = []
    blocker = pool.submit("heavy", gate.wait)
    heavy = [pool.submit("heavy", order.append, f"h{i}") for i in range(5)]
    light = pool.submit("light", order.append, "l")
    gate.set()
    for f in [blocker, *heavy, light]:
        f.result(timeout=5)
    # Plain FIFO would run the light job last; round-robin runs it after one heavy job.
    assert order.index("l") <= 1
    assert [x for x in order if x != "l"] == [f"h{i}" for i in range(5)]  # order kept per owner
    pool.shutdown()


def test_fair_executor_passes_exceptions_and_drains_at_shutdown() -> None:
    pool = FairExecutor(2)
    bad = pool.submit("a", lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        bad.result(timeout=5)
    slow = [pool.submit("a", time.sleep, 0.05) for _ in range(4)]
    pool.shutdown(wait=True)
    assert all(f.done() and f.exception() is None for f in slow)
    with pytest.raises(RuntimeError, match="shut down"):
        pool.submit("a", print)


def test_one_owner_uses_at_most_its_share_of_the_threads() -> None:
    pool = FairExecutor(2, max_per_owner=1)
    gate = threading.Event()
    running = threading.Semaphore(0)

    def hold() -> None:
        running.release()
        gate.wait()

    heavy = [pool.submit("heavy", hold) for _ in range(3)]
    assert running.acquire(timeout=5)
    light = pool.submit("light", time.sleep, 0)
    # The second thread stays free for another owner: the light job runs while heavy waits.
    assert light.result(timeout=5) is None
    assert not running.acquire(timeout=0.2)  # still only one heavy job running
    gate.set()
    for f in heavy:
        f.result(timeout=5)
    pool.shutdown()


def test_any_hashable_owner_even_none() -> None:
    pool = FairExecutor(2)
    assert [pool.submit(None, pow, 2, i).result(timeout=5) for i in range(3)] == [1, 2, 4]
    pool.shutdown()
