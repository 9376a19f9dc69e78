"""Sessions shared between workers through a session store (``--store redis://...``).

The rules (docs/API.md, "Overload and restarts"):

* A worker steps a session only while it holds the session's lease. A new session is
  checkpointed and its lease released at once: the proxy may route its frames to any
  worker (they hash on the session id; creation has none).
* Every answered frame is in the store before its answer leaves: its journal entry is
  written first (group commit, :meth:`SessionStore.append`). About once a second the
  keeper writes a checkpoint of each session that changed, which empties its journal.
* The keeper renews the leases every third of their life; a session whose lease was
  lost (the worker stalled longer than the lease) is dropped from memory and served by
  whoever holds it now. A session idle for ``handoff_idle_s`` is checkpointed and let
  go, so that a worker the proxy now prefers (after a restart) can take it.
* On a miss (an id not in memory: the first frame after creation, a reconnection after
  a worker died or stopped), the worker takes the lease (waiting while another live
  worker lets it go, or while a dead worker's lease runs out), loads the checkpoint and
  replays the journal: the session goes on exactly where its client left it.
* At shutdown every session is checkpointed and its lease released.

Store calls run on this module's own threads, never blocking the event loop, except the
writes made while sessions are served: each frame's journal entry
(:meth:`SessionStore.append`) and the checkpoints (:meth:`SessionStore.save`, packed
one session at a time between filter steps) are written from the event loop itself. A
hand-off to another thread and back for each frame cost more CPU than the work it moved
(benchmarks/README.md).
"""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import socket
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import app.service.checkpoint as checkpoint
from app.service.access import Principal
from app.service.errors import SessionNotFound, SessionUnavailable, log_event
from app.service.host import SessionHost
from app.service.session import Session
from app.service.store import SessionStore
from app.service.types import FrameInput

log = logging.getLogger("bearings.sharing")
T = TypeVar("T")

#: How often a waiting worker asks again for a lease another worker holds (seconds).
POLL_S = 0.05
#: How long before ``checkpoint_interval_s`` runs out a round of checkpoints starts
#: (seconds; at most a quarter of the interval), so that each session's checkpoints are
#: at most the interval apart (docs/API.md: at least once a second).
CHECKPOINT_EARLY_S = 0.05


class SessionSharing:
    """The store side of one worker's sessions, kept through ``host`` (the
    :class:`~app.service.sessions.SessionManager`, seen as a
    :class:`~app.service.host.SessionHost`)."""

    def __init__(
        self,
        host: SessionHost,
        store: SessionStore,
        *,
        lease_s: float,
        checkpoint_interval_s: float,
        idle_timeout_s: float,
        handoff_idle_s: float = 1.0,
    ) -> None:
        self.host = host
        self.store = store
        self.lease_s = lease_s
        self.checkpoint_interval_s = checkpoint_interval_s
        self.idle_timeout_s = idle_timeout_s
        self.handoff_idle_s = handoff_idle_s
        #: This process's lease token: host, pid and a random part (pids are reused).
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"
        self.stopping = False
        self._io = ThreadPoolExecutor(max_workers=2, thread_name_prefix="store")
        # Lease renewals never queue behind loads or checkpoints.
        self._lease_io = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lease")
        self._resuming: dict[str, asyncio.Future[Session]] = {}
        self._releasing: set[str] = set()  # let go of, lease not yet released
        self._lost: set[str] = set()  # leases the renewal thread found lost
        self._lost_lock = threading.Lock()
        self._saved: dict[str, int] = {}  # session id -> version last checkpointed
        self._saved_at = time.monotonic()
        #: Seconds from one round of checkpoints to the next: a little less than the
        #: interval, since the event loop may wake the keeper late and a round takes a
        #: while to pack.
        self._round_every = checkpoint_interval_s - min(
            CHECKPOINT_EARLY_S, checkpoint_interval_s / 4
        )

    async def _run(self, fn: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(self._io, fn, *args)

    # ---------------------------------------------------------------- checkpoints
    def _pack(self, session: Session) -> tuple[str, bytes, int, int]:
        # Packed under the lock too: the captured state refers to the session's own
        # (frozen or not yet replaced) values rather than copies.
        with session.state_lock:
            state = session.capture()
            return session.id, checkpoint.pack(state), int(state["frames"]), session.version

    async def save(self, sessions: list[Session]) -> list[Session]:
        """Checkpoint ``sessions``; return those whose lease was lost.

        Each is packed on the event loop, with a turn for the other tasks (filter steps,
        answers) after each one, then written from the event loop too."""
        if not sessions:
            return []
        packed = []
        for session in sessions:
            packed.append(self._pack(session))
            await asyncio.sleep(0)
        items = [(sid, data, frames) for sid, data, frames, _ in packed]
        ok = await self.store.save(items, self.owner, self.idle_timeout_s)
        metrics = self.host.metrics
        lost = []
        for session, (sid, data, _, version), held in zip(sessions, packed, ok, strict=True):
            if held:
                self._saved[sid] = version
                metrics.checkpoints.inc()
                metrics.checkpoint_bytes.inc(len(data))
            else:
                lost.append(session)
        return lost

    async def publish(self, session: Session) -> None:
        """A new session: store it and let it go, for whichever worker gets its frames."""
        sid = session.id
        await self._run(self.store.acquire, sid, self.owner, self.lease_s)
        await self.save([session])
        await self._run(self.store.release, [sid], self.owner)

    # ------------------------------------------------------------------ resuming
    async def resume(self, session_id: str) -> Session:
        """The session from the store, now owned here (one load per id at a time)."""
        if self.stopping:
            raise SessionUnavailable(
                "this worker is shutting down; reconnect and another worker will serve the session",
                code="worker_stopping",
            )
        waiting = self._resuming.get(session_id)
        if waiting is not None:
            return await asyncio.shield(waiting)
        future: asyncio.Future[Session] = asyncio.get_running_loop().create_future()
        future.add_done_callback(lambda f: f.cancelled() or f.exception())
        self._resuming[session_id] = future
        try:
            session = await self._take(session_id, SessionNotFound, SessionUnavailable)
        except BaseException as exc:
            future.set_exception(exc)
            raise
        else:
            future.set_result(session)
            return session
        finally:
            del self._resuming[session_id]

    async def _take(self, sid: str, not_found: type, unavailable: type) -> Session:
        # Long enough for a dead worker's lease to run out, or a live one to let go.
        deadline = time.monotonic() + self.lease_s + self.handoff_idle_s + 1.0
        started = time.monotonic()
        while sid in self._releasing or not await self._run(
            self.store.acquire, sid, self.owner, self.lease_s
        ):
            if time.monotonic() > deadline:
                data, _ = await self._run(self.store.load, sid)
                if data is None:
                    raise not_found(sid)
                raise unavailable(
                    "another worker is still serving this session; try again in a moment",
                    code="session_busy",
                )
            await asyncio.sleep(POLL_S)
        leased = time.monotonic()
        try:
            data, journal = await self._run(self.store.load, sid)
            if data is None:
                raise not_found(sid)
            session, replayed = await self._run(self._restore, sid, data, journal)
        except BaseException:
            await self._run(self.store.release, [sid], self.owner)
            raise
        self._saved[sid] = session.version if not replayed else -1
        self.host.adopt(session)
        self.host.metrics.sessions_resumed.inc()
        log_event(
            "session_resumed",
            tag=session.tag,
            frames=session.frames,
            replayed=replayed,
            lease_wait_s=round(leased - started, 3),
            restore_s=round(time.monotonic() - leased, 3),
        )
        return session

    def _restore(self, sid: str, data: bytes, journal: list[bytes]) -> tuple[Session, int]:
        """Build the session from its checkpoint, then replay the frames after it."""
        state = checkpoint.unpack(data)
        session = self.host.build(
            checkpoint.spec_of(state),
            session_id=sid,
            created_at=checkpoint.created_at_of(state),
            filter_state=state["filter"],
        )
        session.restore(state)
        replayed = 0
        for entry in journal:
            seq, frame, merged = checkpoint.decode_frame(entry)
            if seq <= session.frames:
                continue
            if seq != session.frames + 1:
                log.warning("journal gap after frame %d; replay stops there", session.frames)
                break
            session.process_sync(frame, merged)
            replayed += 1
        return session, replayed

    # ------------------------------------------------------------------- frames
    @staticmethod
    def entry(seq: int, frame: FrameInput, merged: int = 1) -> bytes:
        return checkpoint.encode_frame(seq, frame, merged)

    async def journal(self, session: Session, entry: bytes) -> bool:
        """Store one answered frame's entry; False if another worker has the session
        now (then this copy is dropped, and the step with it)."""
        if await self.store.append(
            session.id, entry, self.owner, self.idle_timeout_s, self.lease_s
        ):
            return True
        self._drop(session, "lease_lost")
        return False

    async def confirm(self, session: Session) -> bool:
        """Whether this worker still holds the session (and its copy is current); if
        not, the copy is dropped and the caller finds the session again."""
        loop = asyncio.get_running_loop()
        (held,) = await loop.run_in_executor(
            self._lease_io, self.store.renew, [session.id], self.owner, self.lease_s
        )
        if not held:
            self._drop(session, "lease_lost")
        return bool(held)

    async def let_go(self, session_id: str) -> None:
        """Checkpoint a session and release it now (its WebSocket closed: the client may
        come back through another worker, which then need not wait)."""
        session = self.host.live(session_id)
        if session is None or session.busy or self.stopping:
            return
        self._releasing.add(session_id)
        try:
            self._drop(session, None)
            if not await self.save([session]):
                await self._run(self.store.release, [session_id], self.owner)
        finally:
            self._releasing.discard(session_id)

    async def delete_stored(self, session_id: str, owner: Principal | None) -> int:
        """Delete a session this worker does not hold, if ``owner`` may see it; return how
        many frames its checkpoint covered."""
        data, journal = await self._run(self.store.load, session_id)
        if data is None:
            raise SessionNotFound(session_id)
        state = checkpoint.unpack(data)
        if owner is not None and owner.name is not None and state["owner"] != owner.name:
            raise SessionNotFound(session_id)
        await self.delete(session_id)
        return int(state["frames"]) + len(journal)

    async def delete(self, session_id: str) -> bool:
        """Remove the session from the store; False if it had no checkpoint."""
        data, _ = await self._run(self.store.load, session_id)
        await self._run(self.store.delete, session_id)
        self._saved.pop(session_id, None)
        return data is not None

    # ------------------------------------------------------------------- keeper
    def _renew_forever(self, stop: threading.Event) -> None:
        """Thread: renew the leases of the sessions in memory, five times per lease.

        On a thread of its own, so a busy event loop cannot delay it; leases found lost
        are handed to the keeper, which drops those sessions.
        """
        period = self.lease_s / 5
        while not stop.wait(period):
            # Sessions being resumed too: a slow restore must not lose its lease.
            ids = list(dict.fromkeys([*self.host.live_ids(), *self._resuming]))
            try:
                held = self.store.renew(ids, self.owner, self.lease_s)
            except Exception:
                log.exception("lease renewal failed; retrying")
                continue
            lost = [sid for sid, ok in zip(ids, held, strict=True) if not ok]
            if lost:
                with self._lost_lock:
                    self._lost.update(lost)

    async def run_keeper(self) -> None:
        """Forever: renew leases (a thread), checkpoint what changed, let idle sessions go."""
        stop = threading.Event()
        renewer = threading.Thread(
            target=self._renew_forever, args=(stop,), name="lease-renewal", daemon=True
        )
        renewer.start()
        tick = max(0.05, min(self.lease_s / 3, self.checkpoint_interval_s / 2))
        try:
            while True:
                # Every tick, and in time for the next checkpoint (a fixed tick of 0.4 s
                # checkpointed every 1.2 s where the interval says 1 s).
                due_in = self._saved_at + self._round_every - time.monotonic()
                await asyncio.sleep(max(0.01, min(tick, due_in)))
                try:
                    await self.keep()
                except Exception:
                    log.exception("session store upkeep failed; retrying")
                    await asyncio.sleep(tick)  # not at once, however overdue
        finally:
            stop.set()

    async def keep(self) -> None:
        host = self.host
        with self._lost_lock:
            lost, self._lost = self._lost, set()
        for sid in lost:
            session = host.live(sid)
            # A step in flight finds out itself, as it journals.
            if session is not None and not session.busy:
                self._drop(session, "lease_lost")
        sessions = host.sessions()
        now = time.monotonic()
        live = sessions
        idle = [s for s in live if now - s.last_active > self.handoff_idle_s and not s.busy]
        due = now - self._saved_at >= self._round_every
        changed = [s for s in live if self._saved.get(s.id) != s.version and (due or s in idle)]
        if due:
            self._saved_at = now
        for session in await self.save(changed):
            self._drop(session, "lease_lost")
        # Let idle sessions go, unless a frame arrived while they were being saved.
        gone = [s for s in idle if now - s.last_active > self.handoff_idle_s]
        gone = [s for s in gone if self._saved.get(s.id) == s.version and not s.busy]
        ids = [s.id for s in gone]
        self._releasing.update(ids)
        try:
            for session in gone:
                self._drop(session, None)
            await self._run(self.store.release, ids, self.owner)
        finally:
            self._releasing.difference_update(ids)

    def _drop(self, session: Session, reason: str | None) -> None:
        self.host.forget(session)
        self._saved.pop(session.id, None)
        if reason is not None:
            log_event(f"session_{reason}", tag=session.tag, frames=session.frames)

    async def shutdown(self) -> None:
        """Checkpoint every session and release its lease (SIGTERM, clean stop).

        Runs after the manager answered every frame it accepted (no step in flight).
        """
        self.stopping = True
        sessions = self.host.sessions()
        for session in sessions:
            self.host.forget(session)
        await self.save(sessions)
        await self._run(self.store.release, [s.id for s in sessions], self.owner)
        await self.store.aclose()
        if sessions:
            log.info("checkpointed %d sessions and released their leases", len(sessions))

    def close(self) -> None:
        self._io.shutdown(wait=True)
        self._lease_io.shutdown(wait=True)
        self.store.close()
