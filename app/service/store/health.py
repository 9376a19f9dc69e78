"""Whether the session store answers, since when not, and when to try it again."""

from __future__ import annotations

import logging
import threading

from app.service.clock import SYSTEM, Clock

log = logging.getLogger("bearings.store")

#: The first wait before trying an unreachable store again (seconds); each failure
#: doubles it, up to ``RETRY_MAX_S``. Small enough that a store back after a restart is
#: noticed within half a second, and every session stored again within 2 s
#: (docs/API.md).
RETRY_FIRST_S = 0.05
RETRY_MAX_S = 0.4


class StoreHealth:
    """Up or down, with the reason, since when, and when to try again (thread-safe).

    Any operation on the store reports how it went: :meth:`failed` with the error, or
    :meth:`answered`. The first failure after a success logs one warning and the answer
    after failures one line, never a traceback per call.
    """

    def __init__(self, clock: Clock = SYSTEM) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self.up = True
        self.reason = ""
        self.down_since_s = 0.0
        self.failures = 0
        self._retry_at_s = 0.0

    def failed(self, what: str, exc: BaseException) -> bool:
        """The store failed ``what`` (e.g. "journal write"); True if it was up until now."""
        with self._lock:
            now = self._clock.monotonic()
            self.failures += 1
            wait = min(RETRY_MAX_S, RETRY_FIRST_S * 2 ** min(self.failures - 1, 16))
            self._retry_at_s = now + wait
            if not self.up:
                return False
            self.up = False
            self.down_since_s = now
            self.reason = f"{what} failed: {type(exc).__name__}: {exc}"
        log.warning(
            "session store unreachable (%s); sessions are served from memory and are not "
            "persisted until it answers again",
            self.reason,
        )
        return True

    def answered(self) -> float | None:
        """The store answered; the seconds it had been down if it was, else None."""
        with self._lock:
            self.failures = 0
            if self.up:
                return None
            self.up = True
            down_s = self._clock.monotonic() - self.down_since_s
            self.reason = ""
        log.warning("session store answers again after %.1f s down", down_s)
        return down_s

    def retry_in_s(self) -> float:
        """Seconds until the store should be tried again (0: now)."""
        with self._lock:
            return max(0.0, self._retry_at_s - self._clock.monotonic())

    def down_for_s(self) -> float:
        """Seconds since the store stopped answering (0 while up)."""
        with self._lock:
            return 0.0 if self.up else self._clock.monotonic() - self.down_since_s
