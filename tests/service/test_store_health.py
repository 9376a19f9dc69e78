"""The store's health: down with the first failure's reason, tried again with a
doubling backoff, up again with how long it was down; time from a ManualClock."""

from __future__ import annotations

import pytest

from app.service.backlog import Backlog
from app.service.clock import ManualClock
from app.service.store import StoreHealth
from app.service.store.health import RETRY_FIRST_S, RETRY_MAX_S


def test_the_store_goes_down_once_backs_off_and_comes_back() -> None:
    clock = ManualClock()
    health = StoreHealth(clock)
    assert health.up and health.answered() is None and health.down_for_s() == 0
    assert health.failed("journal", ConnectionError("refused"))  # it was up: news
    assert not health.failed("lease", ConnectionError("refused again"))  # no news
    assert not health.up and health.reason == "journal failed: ConnectionError: refused"
    waits = []
    for _ in range(6):
        waits.append(health.retry_in_s())
        clock.advance(waits[-1])
        health.failed("lease", ConnectionError("still refused"))
    assert waits[0] == pytest.approx(2 * RETRY_FIRST_S)  # (two failures so far)
    assert waits == sorted(waits) and waits[-1] == pytest.approx(RETRY_MAX_S)
    assert health.down_for_s() == pytest.approx(sum(waits))
    clock.advance(0.5)
    assert health.answered() == pytest.approx(sum(waits) + 0.5)
    assert health.up and health.reason == "" and health.retry_in_s() == 0
    health.failed("checkpoint", TimeoutError("slow"))
    assert health.retry_in_s() == pytest.approx(RETRY_FIRST_S)  # the backoff starts over


def test_a_session_catching_up_holds_only_the_entries_after_its_checkpoint() -> None:
    backlog = Backlog()
    assert not backlog.hold("s", b"3|x") and not backlog.lags("s")
    backlog.fall_behind("s")
    assert backlog.lags("s") and not backlog.hold("s", b"4|x")  # behind: nothing kept
    backlog.catching_up("s")  # a checkpoint of frame 5 was packed
    assert backlog.behind() == set() and backlog.lags("s")
    for seq in (5, 6, 7):  # (5: stepped before the packing, journalled after it)
        assert backlog.hold("s", b"%d|x" % seq)
    assert backlog.take_held("s", 5) == [b"6|x", b"7|x"]
    assert backlog.hold("s", b"8|x")  # still catching up until told otherwise
    assert backlog.take_held("s", 5) == [b"8|x"]
    backlog.caught_up("s")
    assert not backlog.lags("s") and not backlog.hold("s", b"9|x") and len(backlog) == 0
