"""The key file, key checks, the token bucket and the fair stepper."""

from __future__ import annotations

import asyncio

import pytest

from app.service.access import KeyFileError, TokenBucket, parse_keys
from app.service.clock import ManualClock
from app.service.scheduler import FairStepper

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
    clock = ManualClock()
    bucket = TokenBucket(rate=16.0, clock=clock)  # (times exact in binary)
    assert all(bucket.take() == 0 for _ in range(16))
    wait = bucket.take()
    assert wait == 1 / 16
    clock.advance(wait / 2)
    assert bucket.take() == pytest.approx(wait / 2)  # half a token came back: not enough
    clock.advance(wait / 2)
    assert bucket.take() == 0


def test_the_stepper_serves_a_light_owner_between_a_heavy_owners_jobs() -> None:
    async def main() -> list[str]:
        stepper = FairStepper()
        order: list[str] = []
        heavy = [stepper.submit("heavy", order.append, f"h{i}") for i in range(5)]
        light = stepper.submit("light", order.append, "l")
        assert stepper.waiting == 6 and order == []  # nothing runs until the loop is free
        await asyncio.gather(*heavy, light)
        assert stepper.waiting == 0
        return order

    order = asyncio.run(main())
    # Arrival order would run the light job last; turns run it right after one heavy job.
    assert order.index("l") == 1
    assert [x for x in order if x != "l"] == [f"h{i}" for i in range(5)]  # order kept per owner


def test_without_turns_jobs_run_in_arrival_order() -> None:
    async def main() -> list[str]:
        stepper = FairStepper(fair=False)
        order: list[str] = []
        jobs = [stepper.submit("heavy", order.append, f"h{i}") for i in range(3)]
        jobs.append(stepper.submit("light", order.append, "l"))
        await asyncio.gather(*jobs)
        return order

    assert asyncio.run(main()) == ["h0", "h1", "h2", "l"]


def test_the_stepper_passes_exceptions_on_lets_io_in_and_cancels_at_shutdown() -> None:
    async def main() -> None:
        stepper = FairStepper(slice_s=0.0)  # a turn of the loop after every step
        bad = stepper.submit("a", lambda: 1 / 0)
        ticks: list[int] = []

        async def ticker() -> None:
            for i in range(3):
                ticks.append(i)
                await asyncio.sleep(0)

        good = [stepper.submit("a", ticks.append, -1) for _ in range(3)]
        await asyncio.gather(ticker(), *good)
        with pytest.raises(ZeroDivisionError):
            await bad
        # The loop ran other tasks between the steps, not only after all of them.
        assert ticks.index(2) < len(ticks) - 1
        # With a slice, short steps run back to back within one turn of the loop.
        sliced, ticks[:] = FairStepper(slice_s=1.0), []
        await asyncio.gather(ticker(), *(sliced.submit("a", ticks.append, -1) for _ in range(3)))
        assert ticks == [-1, -1, -1, 0, 1, 2]
        pending = [stepper.submit("a", pow, 2, i) for i in range(3)]
        stepper.shutdown()
        assert all(f.cancelled() for f in pending) and stepper.waiting == 0
        with pytest.raises(RuntimeError, match="shut down"):
            stepper.submit("a", print)

    asyncio.run(main())


def test_any_hashable_owner_even_none() -> None:
    async def main() -> list[int]:
        stepper = FairStepper()
        return list(await asyncio.gather(*(stepper.submit(None, pow, 2, i) for i in range(3))))

    assert asyncio.run(main()) == [1, 2, 4]
