"""Sessions shared between workers through a session store (``--store redis://...``).

The rules (docs/API.md, "Session store"):

* A worker steps a session only while it holds the session's lease, under the fencing
  token it got when it took it (:mod:`app.service.store.protocol`). A new session is
  checkpointed and its lease released at once: the proxy may route its frames to any
  worker (they hash on the session id; creation has none).
* Every answered frame is in the store before its answer leaves: its journal entry is
  written first (group commit, :meth:`SessionStore.append`). About once a second the
  keeper writes a checkpoint of each session that changed, which empties its journal.
* The keeper renews the leases five times per lease; a session another worker took
  (this one stalled longer than the lease) is dropped from memory and served by whoever
  holds it now. A lease that vanished while nobody took the session (the store was
  unreachable, or restarted empty) is taken back, and the session checkpointed. A
  session idle for ``handoff_idle_s`` is checkpointed and let go, so that a worker the
  proxy now prefers (after a restart) can take it.
* On a miss (an id not in memory: the first frame after creation, a reconnection after
  a worker died or stopped), the worker takes the lease (waiting while another live
  worker lets it go, or while a dead worker's lease runs out), loads the checkpoint and
  replays the journal: the session goes on exactly where its client left it.
* At shutdown every session is checkpointed and its lease released.

While the store fails, nothing stops (:class:`~app.service.store.StoreHealth`): the
sessions in memory go on being stepped, their results carry ``state_not_persisted``
(:mod:`app.service.backlog`), the lease thread tries the store again with backoff, and
once it answers every live session is checkpointed, a chunk at a time. What is lost is
only what both the worker and the store lost: a worker that dies while the store is
down takes with it the frames it answered meanwhile (docs/API.md).

Store calls run on this module's own threads, never blocking the event loop, except the
writes made while sessions are served: each frame's journal entry
(:meth:`SessionStore.append`) and the checkpoints (:meth:`SessionStore.save`, packed
one session at a time between filter steps) are written from the event loop itself. A
hand-off to another thread and back for each frame cost more CPU than the work it moved
(benchmarks/README.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import secrets
import socket
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import app.service.checkpoint as checkpoint
from app.service.access import Principal
from app.service.backlog import Backlog
from app.service.clock import SYSTEM, Clock
from app.service.errors import SessionNotFound, SessionUnavailable, log_event
from app.service.host import SessionHost
from app.service.renewal import LeaseRenewal
from app.service.session import Session
from app.service.store import Hold, SessionStore, StoreHealth, StoreUnavailable
from app.service.types import FrameInput

log = logging.getLogger("bearings.sharing")
T = TypeVar("T")

#: How often a waiting worker asks again for a lease another worker holds (seconds).
POLL_S = 0.05
#: How long before ``checkpoint_interval_s`` runs out a round of checkpoints starts
#: (seconds; at most a quarter of the interval), so that each session's checkpoints are
#: at most the interval apart (docs/API.md: at least once a second).
CHECKPOINT_EARLY_S = 0.05
#: Sessions checkpointed per write when catching up after the store failed: one chunk
#: in flight at a time, each session packed between filter steps, so that a thousand
#: sessions coming back at once do not stampede the store or stall the event loop.
RECOVERY_CHUNK = 32


def rebuild(host: SessionHost, state: Mapping[str, Any], session_id: str | None = None) -> Session:
    """The session an unpacked checkpoint (:func:`~app.service.checkpoint.unpack`) holds,
    built by ``host`` from its spec, id (``session_id`` when given), creation time and
    filter state, then restored; not yet served."""
    session = host.build(
        checkpoint.spec_of(state),
        session_id=state["id"] if session_id is None else session_id,
        created_at=checkpoint.created_at_of(state),
        filter_state=state["filter"],
    )
    session.restore(state)
    return session


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
        clock: Clock = SYSTEM,
    ) -> None:
        self.host = host
        self.store = store
        self.lease_s = lease_s
        self.checkpoint_interval_s = checkpoint_interval_s
        self.idle_timeout_s = idle_timeout_s
        self.handoff_idle_s = handoff_idle_s
        self.clock = clock
        #: This process's lease token: host, pid and a random part (pids are reused).
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"
        self.stopping = False
        self.health = StoreHealth(clock)
        self._io = ThreadPoolExecutor(max_workers=2, thread_name_prefix="store")
        # Lease renewals never queue behind loads or checkpoints.
        self._lease_io = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lease")
        self._resuming: dict[str, asyncio.Future[Session]] = {}
        self._releasing: set[str] = set()  # let go of, lease not yet released
        #: The fencing token of each session held here (or being resumed). Read by the
        #: lease thread as a copy (``dict.copy`` is atomic).
        self._fences: dict[str, int] = {}
        self.backlog = Backlog()
        self.renewal = LeaseRenewal(
            store,
            self.owner,
            lease_s=lease_s,
            ttl_s=idle_timeout_s,
            held=self._held,
            health=self.health,
            failed=self._failed,
            answered=self._answered,
            found=self._wake_keeper,
        )
        self._recovered_lock = threading.Lock()
        self._recovered_at: float | None = None  # the store answered again, then
        self._recovering_since: float | None = None  # catching up after an outage
        self._wake: asyncio.Event | None = None  # set to run the keeper at once
        self._loop: asyncio.AbstractEventLoop | None = None
        self._deletes: set[str] = set()  # deleted here, not yet in the store
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

    # ------------------------------------------------------------------ health
    def _failed(self, op: str, exc: BaseException) -> None:
        """An operation on the store failed: count it, and mark the store down."""
        metrics = self.host.metrics
        metrics.store_failures.labels(op).inc()
        if self.health.failed(op, exc):
            metrics.store_up.set(0)
            log_event("store_down", op=op, error=str(exc))

    def _answered(self) -> None:
        """The store answered (from any thread): if it was down, catch every session up."""
        down_s = self.health.answered()
        if down_s is None:
            return
        self.host.metrics.store_up.set(1)
        log_event("store_up", down_s=round(down_s, 2))
        with self._recovered_lock:
            self._recovered_at = self.clock.monotonic()
        self._wake_keeper()

    def _held(self) -> list[tuple[str, int]]:
        """(id, fencing token) of every session held here, for the lease thread: those
        served, and those being resumed (a slow restore must not lose its lease)."""
        fences = self._fences.copy()  # (atomic: the loop changes it meanwhile)
        ids = dict.fromkeys([*self.host.live_ids(), *self._resuming])
        return [(sid, fences[sid]) for sid in ids if sid in fences]

    def _wake_keeper(self) -> None:
        loop, wake = self._loop, self._wake
        if loop is not None and wake is not None and not loop.is_closed():
            loop.call_soon_threadsafe(wake.set)

    def _fall_behind(self, session_id: str) -> None:
        self.backlog.fall_behind(session_id)
        self.host.metrics.sessions_behind.set(len(self.backlog))

    def degraded(self) -> str | None:
        """Why this worker is not storing what it answers (for ``/healthz``), or None."""
        if self.health.up:
            return None
        return (
            f"session store unreachable for {self.health.down_for_s():.1f} s "
            f"({self.health.reason}); {len(self.backlog)} sessions are served from memory "
            "and not persisted until it answers"
        )

    # ---------------------------------------------------------------- checkpoints
    def _pack(self, session: Session) -> tuple[str, bytes, int, int]:
        # Packed under the lock too: the captured state refers to the session's own
        # (frozen or not yet replaced) values rather than copies.
        with session.state_lock:
            state = session.capture()
            return session.id, checkpoint.pack(state), int(state["frames"]), session.version

    async def save(self, sessions: list[Session]) -> list[Session]:
        """Checkpoint ``sessions``; return those another worker took. Raises
        :class:`StoreUnavailable` when the store fails (the sessions are then behind).

        Each is packed on the event loop, with a turn for the other tasks (filter steps,
        answers) after each one, then written from the event loop too. A session behind
        holds the entries of the frames answered after its packing until the checkpoint
        has landed, then writes them (:mod:`app.service.backlog`)."""
        if not sessions:
            return []
        packed = []
        for session in sessions:
            packed.append(self._pack(session))
            if self.backlog.lags(session.id):
                self.backlog.catching_up(session.id)
            await asyncio.sleep(0)
        items = [(sid, data, frames, self._fences.get(sid, 0)) for sid, data, frames, _ in packed]
        try:
            ok = await self.store.save(items, self.owner, self.lease_s, self.idle_timeout_s)
        except StoreUnavailable as exc:
            self._failed("checkpoint", exc)
            for session in sessions:
                self._fall_behind(session.id)
            raise
        self._answered()
        metrics = self.host.metrics
        lost = []
        catching_up = []
        for session, (sid, data, frames, version), held in zip(sessions, packed, ok, strict=True):
            if held:
                self._saved[sid] = version
                metrics.checkpoints.inc()
                metrics.checkpoint_bytes.inc(len(data))
                if self.backlog.lags(sid):
                    catching_up.append(self._catch_up(session, frames))
            else:
                lost.append(session)
        if catching_up:
            await asyncio.gather(*catching_up)
        metrics.sessions_behind.set(len(self.backlog))
        return lost

    async def _catch_up(self, session: Session, frames: int) -> None:
        """The session's checkpoint (of ``frames``) landed: write the entries held since,
        in order, until none is left; then its frames are journalled again."""
        sid = session.id
        while entries := self.backlog.take_held(sid, frames):
            fence = self._fences.get(sid, 0)
            args = (self.owner, fence, self.lease_s, self.idle_timeout_s)
            try:
                holds = await asyncio.gather(*(self.store.append(sid, e, *args) for e in entries))
            except StoreUnavailable as exc:
                self._failed("journal", exc)
                self._fall_behind(sid)
                return
            if Hold.LOST in holds:
                self._drop(session, "lease_lost")
                return
            if Hold.GAP in holds:
                self._fall_behind(sid)
                return
        if self.host.live(sid) is session:
            self.backlog.caught_up(sid)

    async def publish(self, session: Session) -> None:
        """A new session: store it and let it go, for whichever worker gets its frames.

        While the store fails, the session is served here instead, and stored (then let
        go) once the store answers again."""
        sid = session.id
        try:
            fence = await self._run(
                self.store.acquire, sid, self.owner, self.lease_s, self.idle_timeout_s
            )
            self._fences[sid] = 0 if fence is None else fence
            await self.save([session])
            await self._run(self.store.release, [sid], self.owner)
        except StoreUnavailable as exc:
            if self.health.up:  # (a failed checkpoint has counted itself)
                self._failed("checkpoint", exc)
            self._fences.setdefault(sid, 0)  # (a new id: nobody else can hold it)
            self.host.adopt(session)
            self._fall_behind(sid)
            return
        self._fences.pop(sid, None)

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
            session = await self._take(session_id)
        except StoreUnavailable as exc:
            self._failed("resume", exc)
            error = SessionUnavailable(
                "the session store is unreachable and this worker does not hold the "
                "session; try again in a moment",
                code="store_unavailable",
                retry_after_s=1.0,
            )
            future.set_exception(error)
            raise error from None
        except BaseException as exc:
            future.set_exception(exc)
            raise
        else:
            future.set_result(session)
            return session
        finally:
            del self._resuming[session_id]

    async def _take(self, sid: str) -> Session:
        # Long enough for a dead worker's lease to run out, or a live one to let go.
        deadline = time.monotonic() + self.lease_s + self.handoff_idle_s + 1.0
        started = time.monotonic()
        while True:
            if sid not in self._releasing:
                live = self.host.live(sid)
                if live is not None:  # kept here after all (a let-go that failed)
                    return live
                fence = await self._run(
                    self.store.acquire, sid, self.owner, self.lease_s, self.idle_timeout_s
                )
                if fence is not None:
                    break
            if time.monotonic() > deadline:
                data, _ = await self._run(self.store.load, sid)
                if data is None:
                    raise SessionNotFound(sid)
                raise SessionUnavailable(
                    "another worker is still serving this session; try again in a moment",
                    code="session_busy",
                )
            await asyncio.sleep(POLL_S)
        self._answered()
        leased = time.monotonic()
        self._fences[sid] = fence
        try:
            data, journal = await self._run(self.store.load, sid)
            if data is None:
                raise SessionNotFound(sid)
            session, replayed = await self._run(self._restore, sid, data, journal)
        except BaseException:
            self._fences.pop(sid, None)
            with contextlib.suppress(StoreUnavailable):  # (the lease runs out by itself)
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
        session = rebuild(self.host, checkpoint.unpack(data), sid)
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
        """Store one answered frame's entry; False if it is not stored (the store fails,
        or the session is behind: the answer then says ``state_not_persisted``).

        Raises :class:`SessionUnavailable` (``session_moved``) if another worker has the
        session now: this copy is then dropped, and the step with it."""
        sid = session.id
        if self.backlog.hold(sid, entry):  # written once its checkpoint has landed
            return self._not_persisted()
        if not self.health.up or self.backlog.lags(sid):
            self._fall_behind(sid)
            return self._not_persisted()
        try:
            hold = await self.store.append(
                sid, entry, self.owner, self._fences.get(sid, 0), self.lease_s, self.idle_timeout_s
            )
        except StoreUnavailable as exc:
            self._failed("journal", exc)
            self._fall_behind(sid)
            return self._not_persisted()
        if hold == Hold.HELD:
            return True
        if hold == Hold.GAP:  # the store lost frames before this one (restarted)
            self._fall_behind(sid)
            self._wake_keeper()
            return self._not_persisted()
        self._drop(session, "lease_lost")
        raise SessionUnavailable(
            "another worker serves this session now; reconnect to go on", "session_moved", 0.5
        )

    def _not_persisted(self) -> bool:
        self.host.metrics.frames_not_persisted.inc()
        return False

    async def confirm(self, session: Session) -> bool:
        """Whether this worker still holds the session (and its copy is current); if
        not, the copy is dropped and the caller finds the session again. While the store
        fails, the copy in memory is the session."""
        loop = asyncio.get_running_loop()
        item = [(session.id, self._fences.get(session.id, 0))]
        try:
            (hold,) = await loop.run_in_executor(
                self._lease_io,
                self.store.renew,
                item,
                self.owner,
                self.lease_s,
                self.idle_timeout_s,
            )
        except StoreUnavailable as exc:
            self._failed("lease", exc)
            return True
        if hold == Hold.RETAKEN:
            self._fall_behind(session.id)
            self._wake_keeper()
        if hold == Hold.LOST:
            self._drop(session, "lease_lost")
            return False
        return True

    async def let_go(self, session_id: str) -> None:
        """Checkpoint a session and release it now (its WebSocket closed: the client may
        come back through another worker, which then need not wait). Not while the
        store fails or the session's stored state lags: it stays here until stored."""
        session = self.host.live(session_id)
        if session is None or session.busy or self.stopping:
            return
        if not self.health.up or self.backlog.lags(session_id):
            return
        self._releasing.add(session_id)
        try:
            self.host.forget(session)  # (its fencing token is needed to write)
            try:
                lost = await self.save([session])
                if not lost:
                    await self._run(self.store.release, [session_id], self.owner)
            except StoreUnavailable as exc:
                if self.health.up:
                    self._failed("release", exc)
                self.host.adopt(session)  # kept here until the store answers
                self._fall_behind(session_id)
                return
            self._drop(session, None)
        finally:
            self._releasing.discard(session_id)

    async def delete_stored(self, session_id: str, owner: Principal | None) -> int:
        """Delete a session this worker does not hold, if ``owner`` may see it; return how
        many frames its checkpoint covered."""
        try:
            data, journal = await self._run(self.store.load, session_id)
        except StoreUnavailable as exc:
            self._failed("delete", exc)
            raise SessionUnavailable(
                "the session store is unreachable; try deleting again in a moment",
                code="store_unavailable",
                retry_after_s=1.0,
            ) from None
        if data is None:
            raise SessionNotFound(session_id)
        state = checkpoint.unpack(data)
        if owner is not None and owner.name is not None and state["owner"] != owner.name:
            raise SessionNotFound(session_id)
        await self.delete(session_id)
        return int(state["frames"]) + len(journal)

    async def delete(self, session_id: str) -> None:
        """Remove the session from the store (later, should the store fail now)."""
        self._saved.pop(session_id, None)
        self._fences.pop(session_id, None)
        self.backlog.forget(session_id)
        try:
            await self._run(self.store.delete, session_id, self.idle_timeout_s)
        except StoreUnavailable as exc:
            self._failed("delete", exc)
            self._deletes.add(session_id)

    # ------------------------------------------------------------------- keeper
    async def run_keeper(self) -> None:
        """Forever: renew leases (a thread), checkpoint what changed, let idle sessions go."""
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        self.renewal.start()
        tick = max(0.05, min(self.lease_s / 3, self.checkpoint_interval_s / 2))
        try:
            while True:
                # Every tick, and in time for the next checkpoint (a fixed tick of 0.4 s
                # checkpointed every 1.2 s where the interval says 1 s); at once when the
                # lease thread found something.
                due_in = self._saved_at + self._round_every - time.monotonic()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._wake.wait(), max(0.01, min(tick, due_in)))
                self._wake.clear()
                try:
                    await self.keep()
                except StoreUnavailable as exc:
                    if self.health.up:  # (a failed checkpoint has counted itself)
                        self._failed("upkeep", exc)
                except Exception:
                    log.exception("session store upkeep failed; retrying")
                    await asyncio.sleep(tick)  # not at once, however overdue
        finally:
            self.renewal.stop()

    async def keep(self) -> None:
        """One round: drop what was lost, catch up what lags, checkpoint what changed,
        let idle sessions go. Raises :class:`StoreUnavailable` if the store fails."""
        host = self.host
        lost, retaken = self.renewal.take_found()
        with self._recovered_lock:
            recovered_at, self._recovered_at = self._recovered_at, None
        for sid in lost:
            session = host.live(sid)
            # A step in flight finds out itself, as it journals.
            if session is not None and not session.busy:
                self._drop(session, "lease_lost")
        if retaken:
            host.metrics.sessions_retaken.inc(len(retaken))
        for sid in retaken:
            if host.live(sid) is not None:
                self._fall_behind(sid)
        if recovered_at is not None:
            # The store may have come back empty: every session is stored again.
            self._recovering_since = recovered_at
            for sid in host.live_ids():
                self._fall_behind(sid)
        if not self.health.up:
            return
        await self._catch_up_all()
        await self._delete_pending()
        sessions = host.sessions()
        now = time.monotonic()
        live = [s for s in sessions if not self.backlog.lags(s.id)]
        idle = [s for s in live if now - s.last_active > self.handoff_idle_s and not s.busy]
        due = now - self._saved_at >= self._round_every
        changed = [s for s in live if self._saved.get(s.id) != s.version and (due or s in idle)]
        if due:
            self._saved_at = now
        for session in await self.save(changed):
            self._drop(session, "lease_lost")
        # Let idle sessions go, unless a frame arrived while they were being saved.
        gone = [s for s in idle if now - s.last_active > self.handoff_idle_s]
        gone = [
            s
            for s in gone
            if self._saved.get(s.id) == s.version and not s.busy and not self.backlog.lags(s.id)
        ]
        ids = [s.id for s in gone]
        self._releasing.update(ids)
        try:
            for session in gone:
                self._drop(session, None)
            await self._run(self.store.release, ids, self.owner)
        finally:
            self._releasing.difference_update(ids)

    async def _catch_up_all(self) -> None:
        """Checkpoint every session behind, a chunk at a time (``RECOVERY_CHUNK``)."""
        waiting = self.backlog.behind()
        behind = [s for s in self.host.sessions() if s.id in waiting]
        for start in range(0, len(behind), RECOVERY_CHUNK):
            chunk = [s for s in behind[start : start + RECOVERY_CHUNK] if self.host.live(s.id)]
            for session in await self.save(chunk):
                self._drop(session, "lease_lost")
        since = self._recovering_since
        if since is not None and not self.backlog:
            self._recovering_since = None
            took_s = self.clock.monotonic() - since
            self.host.metrics.store_recovery_seconds.set(took_s)
            log_event(
                "store_caught_up", sessions=len(self.host.live_ids()), took_s=round(took_s, 3)
            )

    async def _delete_pending(self) -> None:
        """Delete from the store what was deleted while it failed."""
        for sid in list(self._deletes):
            await self._run(self.store.delete, sid, self.idle_timeout_s)
            self._deletes.discard(sid)

    def _drop(self, session: Session, reason: str | None) -> None:
        self.host.forget(session)
        self._saved.pop(session.id, None)
        self._fences.pop(session.id, None)
        self.backlog.forget(session.id)
        self.host.metrics.sessions_behind.set(len(self.backlog))
        if reason is not None:
            log_event(f"session_{reason}", tag=session.tag, frames=session.frames)

    async def shutdown(self) -> None:
        """Checkpoint every session and release its lease (SIGTERM, clean stop).

        Runs after the manager answered every frame it accepted (no step in flight).
        While the store fails, the sessions it does not have are lost with this worker
        (a fault of both): said in the log, with their number.
        """
        self.stopping = True
        sessions = self.host.sessions()
        for session in sessions:
            self.host.forget(session)
        try:
            await self.save(sessions)
            await self._run(self.store.release, [s.id for s in sessions], self.owner)
        except StoreUnavailable as exc:
            log.error(
                "the session store is unreachable (%s): %d sessions could not be "
                "checkpointed and end with this worker",
                exc,
                len(sessions),
            )
        else:
            if sessions:
                log.info("checkpointed %d sessions and released their leases", len(sessions))
        await self.store.aclose()

    def close(self) -> None:
        self._io.shutdown(wait=True)
        self._lease_io.shutdown(wait=True)
        self.store.close()
