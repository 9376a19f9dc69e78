"""Time as the service's parts read it, passed in so that tests can move it by hand.

The session store (expiry of leases and checkpoints), its health (how long it has been
down, when to try again) and the token buckets of the quotas read a :class:`Clock`
rather than :func:`time.monotonic` itself: production hands them :data:`SYSTEM`, a test
a :class:`ManualClock` that it advances, instead of sleeping on the wall clock.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Seconds from an arbitrary start that never go back."""

    def monotonic(self) -> float: ...


class SystemClock:
    """The process's monotonic clock (:func:`time.monotonic`)."""

    def monotonic(self) -> float:
        return time.monotonic()


SYSTEM: Clock = SystemClock()


class ManualClock:
    """A clock that stands still until told to move (thread-safe)."""

    def __init__(self, start_s: float = 1000.0) -> None:
        self._now_s = start_s
        self._lock = threading.Lock()

    def monotonic(self) -> float:
        with self._lock:
            return self._now_s

    def advance(self, seconds: float) -> None:
        """Move the clock forward by ``seconds`` (not negative)."""
        if not seconds >= 0:
            raise ValueError(f"a clock only moves forward, not by {seconds!r} s")
        with self._lock:
            self._now_s += seconds
