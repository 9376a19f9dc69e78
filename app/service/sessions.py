"""Live sessions: each owns one particle filter and one narrator.

Frames of one session run strictly in order, one at a time (an asyncio lock per
session), and the filter work runs in a worker thread so the event loop, other
sessions and ``/healthz`` stay responsive. A WebSocket disconnect does not end a
session; ``DELETE`` or the idle timeout does.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import secrets
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from app.config import Settings
from app.feedback import Feedback, Narrator
from app.feedback.guidance import GuidanceSpeaker
from app.guidance import DestinationSpec, Guidance, Plan, Target, Unreachable, guide, plan_for
from app.localization.camera import Camera
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.types import Detection, Estimate, Pose
from app.maps.model import SemanticMap
from app.service.metrics import Metrics
from app.service.types import FrameInput, FrameOutcome, SessionSpec

log = logging.getLogger("bearings.sessions")


class SessionNotFound(KeyError):
    """No live session has that id."""

    def __init__(self, session_id: str) -> None:
        super().__init__(session_id)
        self.message = f"no session {session_id!r}: it never existed, was deleted or expired"

    def __str__(self) -> str:
        return self.message


class LimitReached(RuntimeError):
    """A service limit was hit; ``code`` names the limit in a machine-readable word."""

    def __init__(self, message: str, code: str = "limit") -> None:
        super().__init__(message)
        self.code = code


class CapacityReached(LimitReached):
    """The service (or a client's share of it) is full now; it may have room later."""


class RequestTooLarge(LimitReached):
    """One request asks for more than the service ever allows (particles, detections)."""


class InvalidSessionSpec(ValueError):
    """A session cannot be built as asked (e.g. a start pose outside the free space)."""


class UnknownMap(LookupError):
    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(f"no map {name!r}; known maps: {', '.join(known) or 'none'}")


def unknown_class_warnings(
    detections: tuple[Detection, ...], semantic_map: SemanticMap
) -> list[str]:
    """A warning for each detected class the map lacks (those detections are ignored)."""
    unknown = sorted({d.cls for d in detections} - set(semantic_map.classes))
    return [
        f"class {c!r} is not on map {semantic_map.name!r}; its detections were ignored"
        for c in unknown
    ]


def log_event(event: str, **fields: object) -> None:
    """One structured (JSON) log line per session event."""
    log.info(json.dumps({"event": event, **fields}, default=str))


@dataclass(frozen=True)
class SessionSnapshot:
    """A consistent copy of a session's state for readers on other threads (the view)."""

    id: str
    map_name: str
    version: int
    frames: int
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    weights: np.ndarray
    estimate: Estimate | None
    detections: list[Detection]
    truth: Pose | None
    #: The path to the destination from the estimate (metres, (P, 2)), or None.
    route: np.ndarray | None = None


@dataclass
class Session:
    """One person's localization: filter, narrator and the latest result."""

    id: str
    map: SemanticMap
    filter: ParticleFilter
    narrator: Narrator
    particles: int
    created_at: datetime
    last_active: float = field(default_factory=time.monotonic)
    frames: int = 0
    last_outcome: FrameOutcome | None = None
    last_detections: list[Detection] = field(default_factory=list)
    truth: Pose | None = None
    version: int = 0
    last_timestamp: float | None = None
    order: asyncio.Lock = field(default_factory=asyncio.Lock)
    state_lock: threading.Lock = field(default_factory=threading.Lock)
    camera: Camera | None = None
    #: The destination's plan (None: no destination) and what was said about the way.
    destination: Plan | None = None
    speaker: GuidanceSpeaker = field(default_factory=GuidanceSpeaker)
    last_guidance: Guidance | None = None

    def set_destination(self, plan: Plan | None) -> None:
        """Guide to ``plan``'s target from the next frame on (None: stop guiding)."""
        with self.state_lock:
            self.destination = plan
            self.speaker.reset()
            self.last_guidance = None

    def _guide(
        self, estimate: Estimate, now: float, warnings: list[str]
    ) -> tuple[Guidance | None, str]:
        """Directions from the estimate (only when converged) and what to say of them."""
        if self.destination is None:
            return None, ""
        if not estimate.converged:
            return None, self.speaker.update(None, False, now, estimate.x, estimate.y)
        try:
            guidance = guide(self.destination, estimate.x, estimate.y, estimate.theta_rad)
        except Unreachable as exc:
            warnings.append(f"guidance: {exc}")
            return None, self.speaker.no_way(self.destination.target.name, now)
        return guidance, self.speaker.update(guidance, True, now, estimate.x, estimate.y)

    def process_sync(self, frame: FrameInput) -> FrameOutcome:
        """Run one frame through the filter and the narrator (worker thread)."""
        detections = list(frame.detections)
        warnings = unknown_class_warnings(frame.detections, self.map)
        if (
            frame.timestamp is not None
            and self.last_timestamp is not None
            and frame.timestamp < self.last_timestamp
        ):
            warnings.append(
                f"timestamp {frame.timestamp} is earlier than the previous frame's "
                f"{self.last_timestamp}; frames are processed in the order received"
            )
        with self.state_lock:
            estimate = self.filter.step(frame.odometry, detections, frame.heading)
            feedback = self.narrator.update(
                estimate,
                detections,
                timestamp_s=frame.timestamp,
                describe=frame.describe,
                fov_deg=self.filter.config.fov_deg,
                fov_centre_deg=self.filter.config.fov_centre_deg,
            )
            now = time.monotonic() if frame.timestamp is None else frame.timestamp
            guidance, said = self._guide(estimate, now, warnings)
            if said:
                joined = f"{feedback.text} {said}" if feedback.text else said
                feedback = Feedback(joined, feedback.items)
            self.last_guidance = guidance
            self.frames += 1
            result = FrameOutcome(
                seq=self.frames,
                estimate=estimate,
                feedback=feedback,
                warnings=tuple(warnings),
                regions=tuple(self.map.region_at(h.x, h.y) for h in estimate.hypotheses),
                guidance=guidance,
            )
            self.last_outcome = result
            self.last_detections = detections
            self.truth = frame.truth
            if frame.timestamp is not None:
                self.last_timestamp = frame.timestamp
            self.version += 1
        return result

    def snapshot(self) -> SessionSnapshot:
        """Copies of the particles and latest state, safe to call from any thread."""
        with self.state_lock:
            pf = self.filter
            return SessionSnapshot(
                id=self.id,
                map_name=self.map.name,
                version=self.version,
                frames=self.frames,
                x=pf.x.copy(),
                y=pf.y.copy(),
                theta=pf.theta.copy(),
                weights=pf.weights,
                estimate=pf.estimate if self.frames else None,
                detections=list(self.last_detections),
                truth=self.truth,
                route=None if self.last_guidance is None else self.last_guidance.path.copy(),
            )


class SessionManager:
    """Creates, finds, feeds and expires sessions, within the service's limits."""

    def __init__(self, maps: dict[str, SemanticMap], settings: Settings, metrics: Metrics) -> None:
        self.maps = maps
        self.settings = settings
        self.metrics = metrics
        self._sessions: dict[str, Session] = {}
        # Filter steps are CPU-bound and release the GIL inside their kernels: one
        # thread per core runs them, so they never crowd out the event loop's thread
        # (a larger default pool measured higher latency under load, same throughput).
        self._steps = ThreadPoolExecutor(max_workers=os.cpu_count() or 1, thread_name_prefix="step")

    def close(self) -> None:
        """Stop the step threads (at shutdown); frames still queued are dropped."""
        self._steps.shutdown(wait=False, cancel_futures=True)

    def sessions(self) -> list[Session]:
        """Live sessions, oldest first."""
        return list(self._sessions.values())

    def get(self, session_id: str) -> Session:
        try:
            return self._sessions[session_id]
        except KeyError:
            raise SessionNotFound(session_id) from None

    def _build(self, request: SessionSpec) -> Session:
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
        sensor = request.sensor
        camera = request.camera
        config = FilterConfig(
            particles=particles,
            bearing_std_deg=sensor.bearing_std_deg,
            class_bearing_std_deg=dict(sensor.class_bearing_std_deg),
            # A camera fixes the field of view (and where its middle points).
            fov_deg=sensor.fov_deg if camera is None else camera.fov_deg,
            fov_centre_deg=0.0 if camera is None else camera.fov_centre_deg,
        )
        seed = request.seed if request.seed is not None else secrets.randbits(63)
        initial = request.initial_pose
        if initial is not None and not bool(semantic_map.free_space.is_free(initial.x, initial.y)):
            raise InvalidSessionSpec(
                f"initial_pose: ({initial.x:g}, {initial.y:g}) is not in the free space of map "
                f"{semantic_map.name!r} (inside a wall, outside the building or off the map); "
                "give a pose where a person can stand, or null for a global start"
            )
        pf = ParticleFilter(
            semantic_map, config, rng=np.random.default_rng(seed), initial_pose=initial
        )
        narrator = Narrator(semantic_map, request.feedback)
        return Session(
            id=secrets.token_urlsafe(24),  # 192 random bits
            map=semantic_map,
            filter=pf,
            narrator=narrator,
            particles=particles,
            created_at=datetime.now(UTC),
            camera=camera,
            speaker=GuidanceSpeaker(request.feedback.style, request.feedback.units),
        )

    async def create(self, request: SessionSpec) -> Session:
        """A new session; the filter is built off the event loop."""
        if len(self._sessions) >= self.settings.max_sessions:
            raise CapacityReached(
                f"the service already runs its maximum of {self.settings.max_sessions} sessions; "
                "delete one or try again later",
                code="too_many_sessions",
            )
        session = await asyncio.to_thread(self._build, request)
        if len(self._sessions) >= self.settings.max_sessions:  # raced with another create
            raise CapacityReached(
                f"the service already runs its maximum of {self.settings.max_sessions} sessions",
                code="too_many_sessions",
            )
        self._sessions[session.id] = session
        self.metrics.active_sessions.set(len(self._sessions))
        self.metrics.sessions_created.inc()
        log_event(
            "session_created",
            session=session.id[:8],
            map=session.map.name,
            particles=session.particles,
            global_start=request.initial_pose is None,
        )
        return session

    async def process(self, session_id: str, frame: FrameInput) -> FrameOutcome:
        """Run one frame, strictly after the session's previous ones."""
        session = self.get(session_id)
        if len(frame.detections) > self.settings.max_detections:
            raise RequestTooLarge(
                f"detections: {len(frame.detections)} detections in one frame; the limit is "
                f"{self.settings.max_detections}",
                code="too_many_detections",
            )
        async with session.order:
            if session_id not in self._sessions:
                raise SessionNotFound(session_id)
            started = time.perf_counter()
            loop = asyncio.get_running_loop()
            result = await loop.run_in_executor(self._steps, session.process_sync, frame)
            self.metrics.step_seconds.observe(time.perf_counter() - started)
            self.metrics.frames.inc()
            session.last_active = time.monotonic()
            return result

    async def set_destination(self, session_id: str, spec: DestinationSpec) -> Target:
        """Guide the session to ``spec`` (the plan is built off the event loop).

        Raises:
            SessionNotFound, UnknownDestination (nothing by that name: says what the
            map has), Unreachable (no walkable path leads there).
        """
        session = self.get(session_id)
        plan = await asyncio.to_thread(plan_for, session.map, spec)
        session.set_destination(plan)
        log_event("destination_set", session=session_id[:8], kind=spec.kind)
        return plan.target

    def clear_destination(self, session_id: str) -> None:
        """Stop guiding the session."""
        self.get(session_id).set_destination(None)

    async def delete(self, session_id: str, *, reason: str = "deleted") -> None:
        session = self._sessions.pop(session_id, None)
        if session is None:
            raise SessionNotFound(session_id)
        self.metrics.active_sessions.set(len(self._sessions))
        log_event(f"session_{reason}", session=session_id[:8], frames=session.frames)

    async def expire_idle(self) -> int:
        """Remove sessions idle longer than the timeout; return how many."""
        limit = self.settings.session_idle_timeout_s
        now = time.monotonic()
        stale = [
            s.id
            for s in self._sessions.values()
            if now - s.last_active > limit and not s.order.locked()
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
