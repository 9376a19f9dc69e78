"""The service's own vocabulary: what a session is created from, what a frame brings in
and what a step gives back.

These types know nothing of HTTP or JSON: angles are radians (the filter's types), and
the API layer (:mod:`app.api.convert`) translates its wire models (degrees, aliases,
optional fields) to and from them. The simulator's demo walks and the tests use them
directly, without going through the wire.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from app.feedback import Feedback, FeedbackOptions
from app.guidance import Guidance
from app.localization.camera import Camera
from app.localization.compass import CompassReading
from app.localization.floors import AltitudeReading
from app.localization.types import Detection, Estimate, InitialPose, Odometry, Pose


@dataclass(frozen=True)
class SensorSpec:
    """The camera and detector as the filter sees them (degrees, as configured)."""

    bearing_std_deg: float = 2.0
    fov_deg: float = 360.0
    class_bearing_std_deg: Mapping[str, float] = field(default_factory=dict)
    #: Probability that a detection's class is not the object's.
    class_error: float = 0.03


@dataclass(frozen=True)
class SessionSpec:
    """Everything a new session is built from.

    ``particles`` and ``seed`` of None take the service's default and a fresh random
    seed; ``initial_pose`` of None starts with no knowledge (global localization).
    ``share_view`` lists the session in the live view (private by default).
    """

    map_name: str
    particles: int | None = None
    seed: int | None = None
    initial_pose: InitialPose | None = None
    sensor: SensorSpec = field(default_factory=SensorSpec)
    feedback: FeedbackOptions = field(default_factory=FeedbackOptions)
    #: The phone camera; its field of view replaces ``sensor.fov_deg`` when given.
    camera: Camera | None = None
    share_view: bool = False
    #: Where the odometry comes from: "vio", "pdr" or "unknown" (tightens the motion model).
    odometry_source: str = "unknown"
    #: The level id of ``initial_pose`` on a map with levels (None: any of them).
    initial_level: str | None = None


@dataclass(frozen=True)
class FrameInput:
    """One camera frame with the motion since the previous one (radians)."""

    timestamp: float | None = None
    odometry: Odometry | None = None
    detections: tuple[Detection, ...] = ()
    describe: bool = False
    truth: Pose | None = None
    #: The phone compass's heading (map frame), or None.
    heading: CompassReading | None = None
    #: How long before the end of the odometry the detections were captured (seconds).
    detections_age_s: float = 0.0
    #: The phone barometer's relative altitude, or None.
    altitude: AltitudeReading | None = None


@dataclass(frozen=True)
class LevelRef:
    """A level as results name it, and its x offset in the filter's plane (metres)."""

    id: str
    name: str
    ordinal: int
    offset_x: float = 0.0


@dataclass(frozen=True)
class FrameOutcome:
    """What one step gives back: the filter's estimate, what to say, and warnings.

    ``regions`` holds the named region of each hypothesis (None outside every region),
    in the order of ``estimate.hypotheses``.
    """

    seq: int
    estimate: Estimate
    feedback: Feedback
    warnings: tuple[str, ...]
    regions: tuple[str | None, ...]
    #: Directions to the destination; None without one or while not converged.
    guidance: Guidance | None = None
    #: On a map with levels: the estimate's level, each hypothesis's, and the
    #: probability of the estimate's level (None on a map without levels).
    level: LevelRef | None = None
    hypothesis_levels: tuple[LevelRef | None, ...] = ()
    level_probability: float | None = None
