"""The embedded store: the session store's rules on dictionaries of this process."""

from __future__ import annotations

import threading
from collections.abc import Sequence

from app.service.clock import SYSTEM, Clock
from app.service.store.protocol import Hold, entry_seq


class MemoryStore:
    """The same operations as the Redis store, on dictionaries, expiring by ``clock``.

    ``shared=False`` (what ``--store memory`` builds) tells the manager that nothing
    needs writing, which keeps a single machine exactly as without a store.
    ``shared=True`` makes a store that several managers in one process can share, with
    the same rules as Redis (expiry, leases, fencing tokens, taking a lease back): the
    tests use it. :meth:`forget_everything` is a store restarted without persistence.
    """

    def __init__(self, *, shared: bool = False, clock: Clock = SYSTEM) -> None:
        self.shared = shared
        self._clock = clock
        self._lock = threading.Lock()
        self._values: dict[str, tuple[object, float]] = {}

    def forget_everything(self) -> None:
        """Lose every key, as a store restarted without persistence does."""
        with self._lock:
            self._values.clear()

    def _get(self, key: str) -> object | None:
        item = self._values.get(key)
        if item is None:
            return None
        if item[1] <= self._clock.monotonic():
            del self._values[key]
            return None
        return item[0]

    def _put(self, key: str, value: object, ttl_s: float) -> None:
        self._values[key] = (value, self._clock.monotonic() + ttl_s)

    def _touch(self, key: str, ttl_s: float) -> None:
        value = self._get(key)
        if value is not None:
            self._put(key, value, ttl_s)

    def _hold(self, sid: str, owner: str, fence: int, lease_s: float, ttl_s: float) -> Hold:
        """The fencing rule (the Redis store's Lua ``hold``): held, taken back, or lost."""
        stored = self._get(f"{sid}:fence")
        if stored is not None and stored != fence:
            return Hold.LOST
        holder = self._get(f"{sid}:lease")
        if holder == owner:
            return Hold.HELD
        if holder is not None or self._get(f"{sid}:gone") is not None:
            return Hold.LOST
        self._put(f"{sid}:lease", owner, lease_s)
        self._put(f"{sid}:fence", fence, ttl_s)
        return Hold.RETAKEN

    def ping(self) -> None:
        pass

    def acquire(self, session_id: str, owner: str, lease_s: float, ttl_s: float) -> int | None:
        with self._lock:
            holder = self._get(f"{session_id}:lease")
            fence = self._get(f"{session_id}:fence")
            if holder == owner and fence is not None:
                self._put(f"{session_id}:lease", owner, lease_s)
                return int(fence)  # type: ignore[call-overload]
            if holder is not None:
                return None
            token = (0 if fence is None else int(fence)) + 1  # type: ignore[call-overload]
            self._put(f"{session_id}:lease", owner, lease_s)
            self._put(f"{session_id}:fence", token, ttl_s)
            return token

    def renew(
        self, items: Sequence[tuple[str, int]], owner: str, lease_s: float, ttl_s: float
    ) -> list[Hold]:
        with self._lock:
            out = []
            for sid, fence in items:
                hold = self._hold(sid, owner, fence, lease_s, ttl_s)
                if hold == Hold.HELD:
                    self._put(f"{sid}:lease", owner, lease_s)
                out.append(hold)
            return out

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
        self,
        items: Sequence[tuple[str, bytes, int, int]],
        owner: str,
        lease_s: float,
        ttl_s: float,
    ) -> list[bool]:
        out = []
        with self._lock:
            for sid, data, frames, fence in items:
                if self._hold(sid, owner, fence, lease_s, ttl_s) == Hold.LOST:
                    out.append(False)
                    continue
                out.append(True)
                self._touch(f"{sid}:fence", ttl_s)
                stored = self._get(f"{sid}:ckpt:frames")
                if stored is not None and frames < stored:  # type: ignore[operator]
                    continue  # overtaken by a newer checkpoint
                self._put(f"{sid}:ckpt", data, ttl_s)
                self._put(f"{sid}:ckpt:frames", frames, ttl_s)
                journal = self._get(f"{sid}:journal") or []
                kept = [e for e in journal if entry_seq(e) > frames]  # type: ignore[attr-defined]
                self._put(f"{sid}:journal", kept, ttl_s)
        return out

    def _last_frame(self, session_id: str) -> int:
        journal = self._get(f"{session_id}:journal") or []
        stored = self._get(f"{session_id}:ckpt:frames")
        last = -1 if stored is None else int(stored)  # type: ignore[call-overload]
        return max([last, *(entry_seq(e) for e in journal)])  # type: ignore[attr-defined]

    async def append(
        self, session_id: str, entry: bytes, owner: str, fence: int, lease_s: float, ttl_s: float
    ) -> Hold:
        with self._lock:
            hold = self._hold(session_id, owner, fence, lease_s, ttl_s)
            if hold == Hold.LOST:
                return hold
            last = self._last_frame(session_id)
            if entry_seq(entry) <= last:
                return Hold.HELD  # stored already (a checkpoint overtook it)
            if last != entry_seq(entry) - 1:
                return Hold.GAP  # a checkpoint must come first
            journal = self._get(f"{session_id}:journal") or []
            self._put(f"{session_id}:journal", [*journal, entry], ttl_s)  # type: ignore[misc]
            for part in ("ckpt", "ckpt:frames", "fence"):
                self._touch(f"{session_id}:{part}", ttl_s)
            return Hold.HELD

    def delete(self, session_id: str, ttl_s: float) -> None:
        with self._lock:
            for part in ("ckpt", "ckpt:frames", "journal", "lease", "fence"):
                self._values.pop(f"{session_id}:{part}", None)
            self._put(f"{session_id}:gone", True, ttl_s)

    async def aclose(self) -> None:
        pass

    def close(self) -> None:
        pass
