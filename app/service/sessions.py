"""The session manager: creates, finds, feeds and expires sessions (:mod:`app.service.session`).

Frames of one session run strictly in order, one step at a time: a session's frames
wait in a short queue that merges them when they come faster than the filter runs
(:mod:`app.service.queueing`), and one task per busy session feeds them to the step
threads, which are shared fairly between clients (:mod:`app.service.scheduler`). The
event loop, other sessions and ``/healthz`` stay responsive. A session belongs to the
principal (API key) that created it; to any other it does not exist. A WebSocket
disconnect does not end a session; ``DELETE``, the idle timeout or a restart does.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import time
from collections.abc import Mapping
from dataclasses import replace
from datetime import UTC, datetime
from typing import Any

import numpy as np

from app.config import Settings
from app.feedback import Narrator
from app.feedback.guidance import GuidanceSpeaker
from app.guidance import DestinationSpec, Plan, plan_for
from app.localization.config import (
    ODOMETRY_NOISE,
    REAL_DETECTOR_FIT_BIAS_DEG,
    REAL_DETECTOR_LIKELIHOOD_BIAS_DEG,
    REAL_DETECTOR_SLACK_DEG,
    REAL_DETECTOR_TEMPER,
    FilterConfig,
)
from app.localization.filter import ParticleFilter
from app.localization.floors import spread_over_levels
from app.localization.types import InitialPose
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared
from app.service.access import OPEN, Principal, TokenBucket
from app.service.backlog import STATE_NOT_PERSISTED
from app.service.errors import (
    CapacityReached,
    InvalidSessionSpec,
    QuotaReached,
    RequestTooLarge,
    SessionNotFound,
    SessionUnavailable,
    UnknownMap,
    log_event,
    session_tag,
)
from app.service.metrics import Metrics
from app.service.queueing import Waiting
from app.service.scheduler import FairStepper
from app.service.session import Session
from app.service.sharing import SessionSharing
from app.service.store import MemoryStore, SessionStore
from app.service.types import FrameInput, FrameOutcome, SessionSpec

log = logging.getLogger("bearings.sessions")


def initial_on_levels(
    semantic_map: SemanticMap, request: SessionSpec
) -> tuple[InitialPose | None, tuple[int, ...]]:
    """The initial pose in the filter's plane and the levels it may be on.

    On a map with levels, ``initial_level`` names the level (unknown: a level the map
    lacks, or a level on a map without levels, is refused); without it the pose may be
    on any level where it is in the free space.

    Raises:
        InvalidSessionSpec: saying what is wrong.
    """
    initial = request.initial_pose
    layout = semantic_map.layout
    name = semantic_map.name
    if request.initial_level is not None and not layout.has_levels:
        raise InvalidSessionSpec(f"initial_pose.level: map {name!r} has no levels; leave level out")
    if initial is None:
        return None, ()
    if not layout.has_levels:
        candidates: tuple[int, ...] = (0,)
    elif request.initial_level is not None:
        try:
            candidates = (layout.level_index(request.initial_level),)
        except KeyError as exc:
            raise InvalidSessionSpec(f"initial_pose.level: {exc.args[0]}") from None
    else:
        candidates = tuple(lv.index for lv in layout.levels)
    free = [
        k
        for k in candidates
        if bool(semantic_map.free_space.is_free(initial.x + layout.offsets(k), initial.y))
    ]
    if not free:
        where = (
            ""
            if len(candidates) != 1 or not layout.has_levels
            else (f" on level {layout.levels[candidates[0]].id!r}")
        )
        raise InvalidSessionSpec(
            f"initial_pose: ({initial.x:g}, {initial.y:g}) is not in the free space of map "
            f"{name!r}{where} (inside a wall, outside the building or off the map); "
            "give a pose where a person can stand, or null for a global start"
        )
    first = free[0]
    return replace(initial, x=initial.x + float(layout.offsets(first))), tuple(free)


def filter_config(request: SessionSpec, particles: int) -> FilterConfig:
    """The filter a session of ``request`` runs with ``particles``: the sensor (or camera)
    as the client describes it, a real phone detector's tolerances, and the motion noise
    and odometry bias prior of the declared odometry source. The one place the service's
    filter is configured (the experiments that stand for a real phone use it too)."""
    sensor = request.sensor
    camera = request.camera
    return FilterConfig(
        particles=particles,
        bearing_std_deg=sensor.bearing_std_deg,
        class_bearing_std_deg=dict(sensor.class_bearing_std_deg),
        # A camera fixes the field of view (and where its middle points).
        fov_deg=sensor.fov_deg if camera is None else camera.fov_deg,
        fov_centre_deg=0.0 if camera is None else camera.fov_centre_deg,
        class_error=sensor.class_error,
        evidence_temper=REAL_DETECTOR_TEMPER,
        fit_bias_deg=REAL_DETECTOR_FIT_BIAS_DEG,
        likelihood_bias_deg=REAL_DETECTOR_LIKELIHOOD_BIAS_DEG,
        heading_slack_deg=REAL_DETECTOR_SLACK_DEG,
        trans_noise_frac=ODOMETRY_NOISE[request.odometry_source][0],
        rot_noise_frac=ODOMETRY_NOISE[request.odometry_source][1],
        odometry_source=request.odometry_source,
    )


class SessionManager:
    """Creates, finds, feeds and expires sessions, within the service's limits and quotas."""

    def __init__(
        self,
        maps: dict[str, SemanticMap],
        settings: Settings,
        metrics: Metrics,
        store: SessionStore | None = None,
    ) -> None:
        #: The maps served, each prepared (its grids built now if the caller had not).
        self.maps = {name: ensure_prepared(m) for name, m in maps.items()}
        self.settings = settings
        self.metrics = metrics
        self._sessions: dict[str, Session] = {}
        self.store = store or MemoryStore()
        #: With a shared store (Redis): checkpoints, journal and leases; else None.
        self.sharing = (
            SessionSharing(
                self,
                self.store,
                lease_s=settings.store_lease_s,
                checkpoint_interval_s=settings.checkpoint_interval_s,
                idle_timeout_s=settings.session_idle_timeout_s,
            )
            if self.store.shared
            else None
        )
        self._buckets: dict[str, TokenBucket] = {}
        #: Set by :meth:`shutdown`: no new sessions or frames are taken.
        self.closing = False
        # Filter steps run on the event loop's thread, taking turns between keys
        # (app/service/scheduler.py says why not on threads).
        self._steps = FairStepper(fair=settings.fair_steps)

    def close(self) -> None:
        """Stop stepping (at shutdown); steps not started are dropped."""
        self._steps.shutdown()
        if self.sharing is not None:
            self.sharing.close()

    async def shutdown(self) -> None:
        """Take no new sessions or frames, and answer every frame already accepted.

        Returns once every session's queue is empty and its last step answered. Whatever
        must outlive the process (a checkpoint of each session) can run after this.
        """
        self.closing = True
        pumps = [s.pump for s in self._sessions.values() if s.pump is not None]
        if pumps:
            await asyncio.gather(*pumps, return_exceptions=True)

    def sessions(self) -> list[Session]:
        """Live sessions, oldest first."""
        return list(self._sessions.values())

    def live(self, session_id: str) -> Session | None:
        """The session if this worker serves it now, whoever owns it (else None)."""
        return self._sessions.get(session_id)

    def live_ids(self) -> list[str]:
        """The ids of the sessions served here (safe to call from another thread)."""
        return list(self._sessions)

    def get(self, session_id: str, owner: Principal | None = None) -> Session:
        """The session, if ``owner`` may see it (None: the service itself, which sees all)."""
        session = self._sessions.get(session_id)
        if session is None or (
            owner is not None and owner.name is not None and session.owner != owner.name
        ):
            raise SessionNotFound(session_id)
        return session

    async def find(self, session_id: str, owner: Principal | None = None) -> Session:
        """:meth:`get`, or with a shared store, the session resumed from it."""
        if self.sharing is None or session_id in self._sessions:
            return self.get(session_id, owner)
        await self.sharing.resume(session_id)
        return self.get(session_id, owner)

    async def settled(self, session_id: str, owner: Principal | None = None) -> Session:
        """:meth:`find`, once the frames waiting for it are answered: with a shared store,
        what it reports (frames, last result) is then also what the store holds."""
        for _ in range(3):
            session = await self.find(session_id, owner)
            if self.sharing is None:
                return session
            if session.pump is not None:
                await asyncio.wait({session.pump}, timeout=5.0)
            # A copy in memory may be stale if this worker stalled past its lease.
            if self._sessions.get(session_id) is session and await self.sharing.confirm(session):
                return session
        raise SessionUnavailable(
            "the session moved while being read; ask again", "session_moved", 1.0
        )

    def adopt(self, session: Session) -> None:
        """Serve a session resumed from the store."""
        self._sessions[session.id] = session
        self.metrics.active_sessions.set(len(self._sessions))

    def forget(self, session: Session) -> None:
        """Stop serving a session here (it lives on in the store)."""
        if self._sessions.get(session.id) is session:
            del self._sessions[session.id]
            self.metrics.active_sessions.set(len(self._sessions))

    async def let_go(self, session_id: str) -> None:
        """Its client went away (WebSocket closed): with a shared store, checkpoint the
        session and release it, so that its next connection may land on any worker."""
        if self.sharing is not None:
            await self.sharing.let_go(session_id)

    def _refuse_when_closing(self) -> None:
        if self.closing:
            raise CapacityReached(
                "the service is restarting; reconnect in a moment", "restarting", 1.0
            )

    def _next_expiry_s(self, sessions: list[Session]) -> float:
        """Seconds until the first of ``sessions`` would expire if it stays idle."""
        now = time.monotonic()
        limit = self.settings.session_idle_timeout_s
        return max(1.0, min((limit - (now - s.last_active) for s in sessions), default=1.0))

    def _check_room(self, owner: Principal, particles: int) -> None:
        """Raise if the service or ``owner``'s quota has no room for one more session."""
        self._refuse_when_closing()
        if owner.max_particles is not None and particles > owner.max_particles:
            raise RequestTooLarge(
                f"particles: {particles} is more than this key's quota of "
                f"{owner.max_particles} particles",
                code="too_many_particles",
            )
        mine = [s for s in self._sessions.values() if s.owner == owner.name]
        if owner.max_sessions is not None and len(mine) >= owner.max_sessions:
            raise QuotaReached(
                f"this key already has its quota of {owner.max_sessions} sessions; "
                "delete one or try again when one has expired",
                "session_quota",
                self._next_expiry_s(mine),
            )
        held = sum(s.particles for s in mine)
        if owner.max_particles is not None and held + particles > owner.max_particles:
            raise QuotaReached(
                f"this key's sessions already hold {held} of its {owner.max_particles} "
                f"particles, so {particles} more do not fit; delete a session or ask for fewer",
                "particle_quota",
                self._next_expiry_s(mine),
            )
        if len(self._sessions) >= self.settings.max_sessions:
            raise CapacityReached(
                f"the service already runs its maximum of {self.settings.max_sessions} "
                "sessions; try again later",
                "too_many_sessions",
                self._next_expiry_s(list(self._sessions.values())),
            )
        if self._steps.waiting >= self.settings.max_waiting_steps:
            raise CapacityReached(
                f"the service is at capacity ({self._steps.waiting} filter steps are waiting "
                "their turn); try again shortly",
                "busy",
                1.0,
            )

    def build(
        self,
        request: SessionSpec,
        *,
        session_id: str | None = None,
        created_at: datetime | None = None,
        filter_state: Mapping[str, Any] | None = None,
    ) -> Session:
        if request.map_name not in self.maps:
            raise UnknownMap(request.map_name, sorted(self.maps))
        semantic_map = self.maps[request.map_name]
        particles = request.particles or self.settings.default_particles
        if particles > self.settings.max_particles:
            raise RequestTooLarge(
                f"particles: {particles} is more than this service allows "
                f"({self.settings.max_particles})",
                code="too_many_particles",
            )
        camera = request.camera
        config = filter_config(request, particles)
        seed = request.seed if request.seed is not None else secrets.randbits(63)
        initial, levels = initial_on_levels(semantic_map, request)
        pf = ParticleFilter(
            semantic_map,
            config,
            rng=np.random.default_rng(seed),
            initial_pose=initial,
            state=filter_state,
        )
        if filter_state is None and len(levels) > 1:
            pf.x = spread_over_levels(pf.x, semantic_map, levels, pf.rng)
        narrator = Narrator(semantic_map, request.feedback)
        return Session(
            id=session_id or secrets.token_urlsafe(24),  # 192 random bits
            map=semantic_map,
            filter=pf,
            narrator=narrator,
            particles=particles,
            created_at=created_at or datetime.now(UTC),
            spec=replace(request, seed=seed),  # rebuilds this very filter
            camera=camera,
            speaker=GuidanceSpeaker(request.feedback.style, request.feedback.units),
            shared=request.share_view,
            queue_limit=self.settings.max_queued_frames,
        )

    async def create(self, request: SessionSpec, owner: Principal = OPEN) -> Session:
        """A new session owned by ``owner``; the filter is built off the event loop."""
        particles = request.particles or self.settings.default_particles
        self._check_room(owner, particles)
        session = await asyncio.to_thread(self.build, request)
        self._check_room(owner, particles)  # another create may have won the race
        session.owner = owner.name
        if self.sharing is not None:
            await self.sharing.publish(session)  # any worker may get its frames
        else:
            self._sessions[session.id] = session
            self.metrics.active_sessions.set(len(self._sessions))
        self.metrics.sessions_created.inc()
        log_event(
            "session_created",
            tag=session.tag,
            map=session.map.name,
            particles=session.particles,
            global_start=request.initial_pose is None,
            shared=session.shared,
        )
        return session

    def _bucket(self, owner: Principal) -> TokenBucket | None:
        if owner.name is None or owner.max_frames_per_s is None:
            return None
        bucket = self._buckets.get(owner.name)
        if bucket is None:
            bucket = self._buckets[owner.name] = TokenBucket(owner.max_frames_per_s)
        return bucket

    def submit(
        self, session_id: str, frame: FrameInput, owner: Principal | None = None
    ) -> asyncio.Future[FrameOutcome]:
        """Accept one frame now (in order) and return the future of its result.

        Raises at once when the frame is refused: unknown session, too many detections,
        the owner's frame rate used up, or the service restarting.
        """
        session = self.get(session_id, owner)
        if len(frame.detections) > self.settings.max_detections:
            raise RequestTooLarge(
                f"detections: {len(frame.detections)} detections in one frame; the limit is "
                f"{self.settings.max_detections}",
                code="too_many_detections",
            )
        self._refuse_when_closing()
        bucket = self._bucket(owner) if owner is not None else None
        if bucket is not None:
            wait = bucket.take()
            if wait > 0:
                self.metrics.frames_refused.inc()
                raise QuotaReached(
                    f"this key may send {owner.max_frames_per_s:g} frames per second "  # type: ignore[union-attr]
                    "over all its sessions; slow down",
                    "rate_limited",
                    wait,
                )
        waiter: asyncio.Future[FrameOutcome] = asyncio.get_running_loop().create_future()
        self.metrics.frames_accepted.inc()
        if session.queue.put(frame, waiter):
            self.metrics.frames_merged.inc()
        if session.pump is None:
            session.pump = asyncio.create_task(self._pump(session))
        return waiter

    async def set_destination(
        self, session_id: str, spec: DestinationSpec, owner: Principal | None = None
    ) -> Plan:
        """Guide the session to ``spec`` (the plan is built off the event loop); the plan
        (its target, and the map it was resolved on).

        Raises:
            SessionNotFound, UnknownDestination (nothing by that name: says what the
            map has), Unreachable (no walkable path leads there).
        """
        session = await self.find(session_id, owner)
        plan = await asyncio.to_thread(plan_for, session.map, spec)
        session.set_destination(plan)
        log_event("destination_set", tag=session.tag, kind=spec.kind)
        return plan

    async def clear_destination(self, session_id: str, owner: Principal | None = None) -> None:
        """Stop guiding the session."""
        (await self.find(session_id, owner)).set_destination(None)

    async def process(
        self, session_id: str, frame: FrameInput, owner: Principal | None = None
    ) -> FrameOutcome:
        """Run one frame, strictly after the session's previous ones (maybe merged with others)."""
        await self.find(session_id, owner)  # with a shared store: resumed here if need be
        return await self.submit(session_id, frame, owner)

    @staticmethod
    def _turn_of(session: Session) -> str:
        """Whose turn a step counts for: its key, or (open service) the session itself."""
        return session.owner if session.owner is not None else session.id

    async def _pump(self, session: Session) -> None:
        """Feed the session's waiting frames to the stepper, one step at a time.

        Every accepted frame's future is resolved exactly once: with the step's result
        (shared by frames merged into one), with the step's error, or, when the pump ends
        any other way (cancelled at shutdown, its step dropped by the stepper), with
        :class:`SessionUnavailable` for that frame and every frame still waiting.
        """
        item: Waiting | None = None
        try:
            while (item := session.queue.pop()) is not None:
                live = [w for w in item.waiters if not w.done()]
                if self._sessions.get(session.id) is not session:
                    for w in live:
                        w.set_exception(SessionNotFound(session.id))
                    continue
                started = time.perf_counter()
                job = self._steps.submit(
                    self._turn_of(session), self._step_sync, session, item.frame, item.count
                )
                try:
                    result, entry = await job
                    # With a shared store the answer leaves once the frame is journalled
                    # (or says it is not: the store fails; raises if the session moved).
                    if entry is not None and not await self.sharing.journal(session, entry):  # type: ignore[union-attr]
                        warnings = (*result.warnings, STATE_NOT_PERSISTED)
                        result = replace(result, warnings=warnings)
                except Exception as exc:
                    for w in item.waiters:
                        if not w.done():
                            w.set_exception(exc)
                    continue
                self.metrics.step_seconds.observe(time.perf_counter() - started)
                self.metrics.frames.inc(item.count)
                session.last_active = time.monotonic()
                for w in item.waiters:
                    if not w.done():
                        w.set_result(result)
        finally:
            session.pump = None
            unanswered = [item] if item is not None else []
            while (rest := session.queue.pop()) is not None:
                unanswered.append(rest)
            for left in unanswered:
                for w in left.waiters:
                    if not w.done():
                        w.set_exception(
                            SessionUnavailable(
                                "this frame was not processed (the service is stopping); "
                                "reconnect and send it again",
                                "restarting",
                                1.0,
                            )
                        )

    def _step_sync(
        self, session: Session, frame: FrameInput, merged: int
    ) -> tuple[FrameOutcome, bytes | None]:
        """One step (run by the stepper); with a shared store, also its journal entry."""
        result = session.process_sync(frame, merged)
        entry = None if self.sharing is None else self.sharing.entry(result.seq, frame, merged)
        return result, entry

    async def delete(
        self, session_id: str, *, reason: str = "deleted", owner: Principal | None = None
    ) -> None:
        if self.sharing is not None and session_id not in self._sessions:
            # Only in the store: no need to build it to delete it.
            frames = await self.sharing.delete_stored(session_id, owner)
            log_event(f"session_{reason}", tag=session_tag(session_id), frames=frames)
            return
        session = self.get(session_id, owner)
        del self._sessions[session_id]
        if self.sharing is not None:
            await self.sharing.delete(session_id)
        self.metrics.active_sessions.set(len(self._sessions))
        log_event(f"session_{reason}", tag=session.tag, frames=session.frames)

    async def expire_idle(self) -> int:
        """Remove sessions idle longer than the timeout; return how many."""
        limit = self.settings.session_idle_timeout_s
        now = time.monotonic()
        stale = [
            s.id for s in self._sessions.values() if now - s.last_active > limit and not s.busy
        ]
        for sid in stale:
            await self.delete(sid, reason="expired")
        return len(stale)

    async def run_sweeper(self) -> None:
        """Forever: expire idle sessions every few seconds (cancel to stop)."""
        period = max(0.5, min(30.0, self.settings.session_idle_timeout_s / 4))
        while True:
            await asyncio.sleep(period)
            await self.expire_idle()
