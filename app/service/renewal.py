"""The lease thread: renews one worker's leases, and tries a failing store again.

On a thread of its own, so that a busy event loop cannot delay it. Five times per lease
it renews the leases of the sessions the worker holds (each under its fencing token):
those another worker took are reported lost, those that had vanished and were taken
back (the store restarted, or was unreachable longer than the lease) are reported
retaken, for the keeper to drop or checkpoint (:mod:`app.service.sharing`). While the
store fails it is tried again sooner, with the health's backoff
(:class:`~app.service.store.StoreHealth`), by the same call (or a ping when no session
is held): the first answer is how the worker learns that the store is back.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence

from app.service.store import Hold, SessionStore, StoreHealth, StoreUnavailable

log = logging.getLogger("bearings.sharing")


class LeaseRenewal:
    """Renews ``held()``'s leases (session id, fencing token) every ``lease_s / 5``.

    ``failed(op, exc)`` and ``answered()`` report each call's outcome; ``found()`` is
    called (from this thread) when :meth:`take_found` has something new.
    """

    def __init__(
        self,
        store: SessionStore,
        owner: str,
        *,
        lease_s: float,
        ttl_s: float,
        held: Callable[[], Sequence[tuple[str, int]]],
        health: StoreHealth,
        failed: Callable[[str, BaseException], None],
        answered: Callable[[], None],
        found: Callable[[], None],
    ) -> None:
        self.store = store
        self.owner = owner
        self.lease_s = lease_s
        self.ttl_s = ttl_s
        self._held = held
        self._health = health
        self._failed = failed
        self._answered = answered
        self._found = found
        self._lock = threading.Lock()
        self._lost: set[str] = set()
        self._retaken: set[str] = set()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="lease-renewal", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()

    def take_found(self) -> tuple[set[str], set[str]]:
        """The sessions found lost and those found retaken since the last call."""
        with self._lock:
            lost, self._lost = self._lost, set()
            retaken, self._retaken = self._retaken, set()
        return lost, retaken

    def renew_once(self) -> None:
        """One round (what the thread does every period); raises StoreUnavailable."""
        items = list(self._held())
        if items:
            holds = self.store.renew(items, self.owner, self.lease_s, self.ttl_s)
        else:
            holds = []
            if not self._health.up:
                self.store.ping()
        lost = {sid for (sid, _), h in zip(items, holds, strict=True) if h == Hold.LOST}
        retaken = {sid for (sid, _), h in zip(items, holds, strict=True) if h == Hold.RETAKEN}
        if lost or retaken:
            with self._lock:
                self._lost |= lost
                self._retaken |= retaken
            self._found()
        self._answered()

    def _run(self) -> None:
        period = self.lease_s / 5
        wait = period
        while not self._stop.wait(wait):
            wait = period
            try:
                self.renew_once()
            except StoreUnavailable as exc:
                self._failed("lease", exc)
                wait = min(period, self._health.retry_in_s())
            except Exception:  # a bug: say so, and go on renewing
                log.exception("lease renewal failed")
