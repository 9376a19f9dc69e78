"""One person's session: a particle filter, a narrator, the latest result.

A :class:`Session` steps its filter one frame at a time (:meth:`Session.process_sync`),
gives a consistent copy of its state to readers on other threads
(:meth:`Session.snapshot`), and captures and restores its own state for a checkpoint
(:meth:`Session.capture`, :meth:`Session.restore`; :mod:`app.service.checkpoint` packs
it into bytes). Creating, finding and expiring sessions is the manager's job
(:mod:`app.service.sessions`); keeping them in a shared store is
:mod:`app.service.sharing`'s.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

import app.service.checkpoint as checkpoint
from app.feedback import Feedback, Narrator
from app.feedback.guidance import GuidanceSpeaker
from app.feedback.levels import level_sentence
from app.guidance import Guidance, Plan, Target, Unreachable, guide
from app.localization.camera import Camera
from app.localization.filter import ParticleFilter
from app.localization.motion import MAX_SPEED_M_S
from app.localization.types import Detection, Estimate, Odometry, Pose
from app.maps.model import SemanticMap
from app.service.conventions import TurnSignCheck
from app.service.errors import session_tag
from app.service.queueing import FrameQueue, merged_warning
from app.service.types import FrameInput, FrameOutcome, LevelRef, SessionSpec
from app.state import from_plain, to_plain


def unknown_class_warnings(
    detections: tuple[Detection, ...], semantic_map: SemanticMap
) -> list[str]:
    """A warning for each detected class the map lacks (those detections are ignored)."""
    known = semantic_map.class_members  # keyed by the map's classes
    unknown = sorted({d.cls for d in detections if d.cls not in known})
    return [
        f"class {c!r} is not on map {semantic_map.name!r}; its detections were ignored"
        for c in unknown
    ]


#: Frames further apart than this (s) are slow: a live session sends several a second. A
#: pause (the app in the background) makes one such gap; several in a row are a clock in
#: other units (JavaScript's Date.now() and Android's elapsedRealtime() count
#: milliseconds). A slow frame's duration is not used (docs/API.md, timestamp).
SLOW_FRAME_S = 10.0
#: Slow frames in a row that are warned about.
SLOW_FRAMES_IN_A_ROW = 3


def slow_frames_warning(frame_s: float, count: int) -> str:
    """What the client hears when its frames keep coming ``frame_s`` seconds apart."""
    return (
        f"timestamps {frame_s:g} s apart, {count} frames in a row: timestamp is in seconds "
        f"(milliseconds?); a frame's duration over {SLOW_FRAME_S:g} s is not used"
    )


#: What the client hears when a frame gives its detections' age without the timestamps
#: that say how long the frame lasted (docs/API.md, detections_age_s).
AGE_WITHOUT_TIMESTAMPS = (
    "detections_age_s needs timestamp on this frame and the previous one (how long the "
    "frame lasted): without, it is not used, and the lag is learnt from turns in frames "
    "instead"
)


#: What the client hears on the frame the session gave up its ``initial_pose``
#: (docs/API.md, InitialPose).
START_GIVEN_UP = (
    "initial_pose: what the camera sees contradicts the start given, so the session "
    "now looks for the person everywhere on the map (as without initial_pose)"
)


def refused_odometry_warning(odometry: Odometry | None, frame_s: float | None) -> str:
    """What the client hears when the filter refused a frame's translation as faster
    than a person on foot (:func:`~app.localization.motion.implausible`)."""
    moved = 0.0 if odometry is None else math.hypot(odometry.forward_m, odometry.left_m)
    return (
        f"odometry moved {moved:.2f} m in {frame_s or 0.0:.2f} s, faster than "
        f"{MAX_SPEED_M_S:g} m/s: taken for a tracking jump, its translation ignored "
        "(its turn kept)"
    )


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
    #: What the session was built from (a checkpoint rebuilds it from this).
    spec: SessionSpec | None = None
    owner: str | None = None
    shared: bool = False
    queue_limit: int = 2
    last_active: float = field(default_factory=time.monotonic)
    frames: int = 0
    last_outcome: FrameOutcome | None = None
    last_detections: list[Detection] = field(default_factory=list)
    truth: Pose | None = None
    version: int = 0
    last_timestamp: float | None = None
    #: Frames in a row that came more than SLOW_FRAME_S after the previous one.
    slow_frames: int = 0
    #: Whether the client's bearings and turns share a sign (app.service.conventions).
    turn_signs: TurnSignCheck = field(default_factory=TurnSignCheck)
    state_lock: threading.Lock = field(default_factory=threading.Lock)
    camera: Camera | None = None
    #: The destination's plan (None: no destination) and what was said about the way.
    destination: Plan | None = None
    speaker: GuidanceSpeaker = field(default_factory=GuidanceSpeaker)
    last_guidance: Guidance | None = None

    queue: FrameQueue = field(init=False)
    #: The task feeding queued frames to the filter (None: idle).
    pump: asyncio.Task[None] | None = None

    def set_destination(self, plan: Plan | None) -> None:
        """Guide to ``plan``'s target from the next frame on (None: stop guiding)."""
        with self.state_lock:
            self.destination = plan
            self.speaker.reset()
            self.last_guidance = None
            self.version += 1  # a checkpoint keeps it

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
            target = self.destination.target
            return None, self.speaker.no_way(target.name, now, target.step_free)
        return guidance, self.speaker.update(guidance, True, now, estimate.x, estimate.y)

    def __post_init__(self) -> None:
        self.queue = FrameQueue(self.queue_limit)

    @property
    def tag(self) -> str:
        return session_tag(self.id)

    @property
    def busy(self) -> bool:
        """A step is running or frames are waiting."""
        return self.pump is not None

    def _levels_of(self, estimate: Estimate) -> dict[str, Any]:
        """The estimate's level, each hypothesis's and the level's probability (a map
        with levels only: empty otherwise)."""
        floors = self.filter.floors
        if floors is None:
            return {}
        refs = level_refs(self.map)
        layout = self.map.layout
        xs = np.array([estimate.x, *(h.x for h in estimate.hypotheses)])
        levels = layout.level_of_plane_x(xs)
        return {
            "level": refs[int(levels[0])],
            "hypothesis_levels": tuple(refs[int(k)] for k in levels[1:]),
            "level_probability": floors.level_probability,
        }

    def process_sync(self, frame: FrameInput, merged: int = 1) -> FrameOutcome:
        """Run one frame (``merged`` frames merged into one) through the filter and narrator."""
        detections = list(frame.detections)
        warnings = unknown_class_warnings(frame.detections, self.map)
        if merged > 1:
            warnings.append(merged_warning(merged))
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
            frame_s = (
                frame.timestamp - self.last_timestamp
                if frame.timestamp is not None and self.last_timestamp is not None
                else None
            )
            if frame.detections_age_s > 0.0 and frame.timestamp is None:
                warnings.append(AGE_WITHOUT_TIMESTAMPS)
            mirrored = self.turn_signs.update(frame.odometry, detections)
            if mirrored is not None:
                warnings.append(mirrored)
            if frame_s is not None:
                self.slow_frames = self.slow_frames + 1 if frame_s > SLOW_FRAME_S else 0
                if self.slow_frames:
                    # A pause, or a clock in other units (several in a row): either way the
                    # duration says nothing of the motion, and taken for it a few frames'
                    # odometry would teach the filter its heading drift over minutes.
                    if self.slow_frames >= SLOW_FRAMES_IN_A_ROW:
                        warnings.append(slow_frames_warning(frame_s, self.slow_frames))
                    frame_s = None
            estimate = self.filter.step(
                frame.odometry,
                detections,
                frame.heading,
                frame.altitude,
                detections_age_s=frame.detections_age_s,
                frame_s=frame_s,
            )
            if self.filter.odometry_refused:
                warnings.append(refused_odometry_warning(frame.odometry, frame_s))
            if self.filter.start_given_up:
                warnings.append(START_GIVEN_UP)
            feedback = self.narrator.update(
                estimate,
                detections,
                timestamp_s=frame.timestamp,
                describe=frame.describe,
                fov_deg=self.filter.config.fov_deg,
                fov_centre_deg=self.filter.config.fov_centre_deg,
                observation=self.filter.last_observation,
                odometry=frame.odometry,
                gone=None if self.filter.unseen is None else self.filter.unseen.absent,
                twins=self.filter.twins_undecided,
                levels_alike=self.filter.levels_undecided,
            )
            now = time.monotonic() if frame.timestamp is None else frame.timestamp
            guidance, said = self._guide(estimate, now, warnings)
            floors = self.filter.floors
            if floors is not None and floors.newly_confirmed and floors.confirmed_level is not None:
                where = level_sentence(self.map.layout.levels[floors.confirmed_level].name)
                text = f"{where} {feedback.text}".strip()
                feedback = Feedback(text, feedback.items, feedback.suggestion)
            if said:
                joined = f"{feedback.text} {said}" if feedback.text else said
                feedback = Feedback(joined, feedback.items, feedback.suggestion)
            self.last_guidance = guidance
            self.frames += 1
            result = FrameOutcome(
                seq=self.frames,
                estimate=estimate,
                feedback=feedback,
                warnings=tuple(warnings),
                regions=tuple(self.map.region_at(h.x, h.y) for h in estimate.hypotheses),
                guidance=guidance,
                **self._levels_of(estimate),
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

    # ------------------------------------------------------------ checkpoints
    def capture(self) -> dict[str, Any]:
        """This session's state, for :func:`~app.service.checkpoint.pack` (call under
        ``state_lock``, or when no step can run), packed before the session steps again:
        frozen values (spec, outcome, estimates) and some of the filter's arrays are the
        session's own, not copies.

        Before its first frame a session is exactly what its spec (with the seed drawn at
        creation) builds, so its filter and narrator are left out.
        """
        fresh = self.frames == 0
        plan = self.destination
        return {
            "format": checkpoint.FORMAT_VERSION,
            "id": self.id,
            "spec": self.spec,
            "created_at": self.created_at.isoformat(),
            "particles": self.particles,
            "frames": self.frames,
            "owner": self.owner,
            "shared": self.shared,
            "speaker": to_plain(self.speaker),
            "destination": None if plan is None else plan.target,
            "last_timestamp": self.last_timestamp,
            "slow_frames": self.slow_frames,
            "turn_signs": self.turn_signs.checkpoint(),
            "last_outcome": self.last_outcome,
            "last_detections": [[d.cls, d.bearing_rad, d.score] for d in self.last_detections],
            "truth": self.truth,
            "filter": None if fresh else self.filter.checkpoint(),
            "narrator": None if fresh else self.narrator.checkpoint(),
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Take on a checkpoint's state (:meth:`capture`, unpacked). The session must be
        built from the same spec with the checkpoint's filter state, which the filter
        restores itself (``ParticleFilter(..., state=state["filter"])``)."""
        if state["narrator"] is not None:
            self.narrator.restore(state["narrator"])
        self.frames = int(state["frames"])
        self.owner = state["owner"]
        self.shared = bool(state["shared"])
        self.speaker = from_plain(GuidanceSpeaker, state["speaker"])
        if state["destination"] is not None:
            self.destination = Plan(self.map, from_plain(Target, state["destination"]))
        self.last_timestamp = state["last_timestamp"]
        self.slow_frames = int(state.get("slow_frames", 0))  # (none before it was kept)
        self.turn_signs.restore(state.get("turn_signs"))
        self.last_outcome = from_plain(FrameOutcome | None, state["last_outcome"])
        self.last_detections = [  # rows since format 4, records before
            Detection(*d) if isinstance(d, list) else from_plain(Detection, d)
            for d in state["last_detections"]
        ]
        self.truth = from_plain(Pose | None, state["truth"])
        self.version += 1


def level_refs(semantic_map: SemanticMap) -> tuple[LevelRef, ...]:
    """The map's levels as results name them (kept with the map)."""
    return semantic_map.derived_value(
        ("level_refs",),
        lambda: tuple(
            LevelRef(lv.id, lv.name, lv.ordinal, lv.offset_x) for lv in semantic_map.layout.levels
        ),
    )
