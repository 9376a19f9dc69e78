"""Request and response bodies of the HTTP and WebSocket API, as docs/API.md describes them.

Units are in the names: ``*_deg`` degrees, ``*_m`` metres, map coordinates ``x, y``
in metres. Every number must be a finite JSON number (booleans and numeric strings are
refused); unknown fields are refused so typos surface.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

from app.validation import NUMBER_ONLY, Finite, Integer, StrictInput


class _Out(BaseModel):
    model_config = ConfigDict(populate_by_name=True)


# ----------------------------------------------------------------------------- input
class OdometryIn(StrictInput):
    """Motion since the previous frame, in the previous body frame (+x forward, +y left)."""

    forward_m: Finite = Field(0.0, ge=-10, le=10, description="forward motion, metres")
    left_m: Finite = Field(0.0, ge=-10, le=10, description="leftward motion, metres")
    turn_deg: Finite = Field(
        0.0, ge=-360, le=360, description="turn, degrees, counter-clockwise positive"
    )


class DetectionIn(StrictInput):
    """One detection from the 360-degree camera's object detector."""

    cls: str = Field(
        alias="class",
        min_length=1,
        max_length=64,
        description="object class, a lower-case word such as door; classes the map "
        "lacks are ignored and reported in warnings",
    )
    bearing_deg: Finite = Field(
        description="direction of the object's centre relative to straight ahead, degrees, "
        "counter-clockwise positive (left +90, right -90); any real value, wrapped to "
        "(-180, 180]"
    )
    score: Finite = Field(1.0, ge=0.0, le=1.0, description="detection confidence in [0, 1]")


class TruthIn(StrictInput):
    """Ground truth sent by simulations (an addition to the contract; never used by the filter)."""

    x: Finite = Field(description="metres")
    y: Finite = Field(description="metres")
    theta_deg: Finite = Field(description="heading, degrees CCW from +x")


class Frame(StrictInput):
    """One camera frame with the motion since the previous one."""

    timestamp: Finite | None = Field(None, description="client time of the frame, seconds")
    odometry: OdometryIn | None = Field(
        None, description="motion since the previous frame; null means unknown motion"
    )
    detections: list[DetectionIn] = Field(default_factory=list, description="what the camera sees")
    describe: StrictBool = Field(
        False, description="ask for a full description now ('Where am I?')"
    )
    truth: TruthIn | None = Field(
        None, description="addition: a simulation's ground truth, shown in the view only"
    )


class SensorSettings(StrictInput):
    """The camera and detector: bearing noise and field of view."""

    bearing_std_deg: Finite = Field(
        2.0, gt=0.0, le=90.0, description="bearing noise standard deviation, degrees"
    )
    fov_deg: Finite = Field(360.0, gt=0.0, le=360.0, description="camera field of view, degrees")
    class_bearing_std_deg: dict[
        str, Annotated[float, Field(gt=0, le=90, allow_inf_nan=False), NUMBER_ONLY]
    ] = Field(default_factory=dict, description="addition: per-class bearing std, degrees")


class FeedbackSettings(StrictInput):
    style: Literal["clock", "left_right", "degrees"] = Field(
        "clock", description="how directions are spoken"
    )
    units: Literal["metric", "imperial"] = Field("metric", description="metres or feet")
    max_items: Integer = Field(3, ge=1, le=10, description="most objects per feedback")


class InitialPoseIn(StrictInput):
    x: Finite = Field(description="metres")
    y: Finite = Field(description="metres")
    theta_deg: Finite = Field(description="heading, degrees CCW from +x")
    std_xy_m: Finite = Field(0.3, gt=0.0, le=100.0, description="position std, metres")
    std_theta_deg: Finite = Field(10.0, gt=0.0, le=360.0, description="heading std, degrees")


class SessionCreate(StrictInput):
    map: str = Field(min_length=1, max_length=200, description="name of a map from GET /maps")
    # Bounds inside the annotation, before the number check: on an optional field
    # pydantic would otherwise leave them out of the JSON schema.
    particles: Annotated[int, Field(ge=100), NUMBER_ONLY] | None = Field(
        None, description="particle count (default and maximum: service settings)"
    )
    seed: Annotated[int, Field(ge=0, le=2**53 - 1), NUMBER_ONLY] | None = Field(
        None,
        description="random seed, for replays (at most 2^53 - 1: exact in every JSON parser)",
    )
    initial_pose: InitialPoseIn | None = Field(
        None, description="known start; null starts with no knowledge (global localization)"
    )
    sensor: SensorSettings = Field(default_factory=SensorSettings)
    feedback: FeedbackSettings = Field(default_factory=FeedbackSettings)


# ----------------------------------------------------------------------------- output
class PoseOut(_Out):
    x: float = Field(description="metres")
    y: float = Field(description="metres")
    theta_deg: float = Field(description="heading, degrees CCW from +x, (-180, 180]")


class Uncertainty(_Out):
    std_x_m: float = Field(description="standard deviation of x in the best cluster, metres")
    std_y_m: float = Field(description="standard deviation of y in the best cluster, metres")
    std_theta_deg: float = Field(description="circular standard deviation of heading, degrees")


class HypothesisOut(_Out):
    x: float = Field(description="metres")
    y: float = Field(description="metres")
    theta_deg: float = Field(description="heading, degrees CCW from +x")
    weight: float = Field(description="share of the belief's weight, 0..1")
    region: str | None = Field(description="named region containing it, or null")


class FeedbackItemOut(_Out):
    cls: str = Field(alias="class", serialization_alias="class", description="object class")
    label: str | None = Field(description="the map's label for the object, or null")
    clock: int | None = Field(description="clock direction 1..12 (12 ahead), null if unknown")
    bearing_deg: float | None = Field(description="degrees, CCW positive, null if unknown")
    distance_m: float | None = Field(description="metres, null if unknown")


class FeedbackOut(_Out):
    text: str = Field(description="what to speak now (may be empty)")
    items: list[FeedbackItemOut]


class FrameResult(_Out):
    seq: int = Field(description="1-based number of this frame in the session")
    pose: PoseOut
    uncertainty: Uncertainty
    converged: bool = Field(description="true only when the belief is a single tight mode")
    hypotheses: list[HypothesisOut]
    feedback: FeedbackOut
    warnings: list[str]


class SessionOut(_Out):
    id: str = Field(description="random, unguessable session id (192 bits)")
    map: str = Field(description="map name")
    particles: int = Field(description="particle count (the maximum when adaptive)")
    created_at: datetime = Field(description="creation time, UTC")
    frames: int = Field(description="frames processed so far")
    last_result: FrameResult | None = Field(description="latest result, or null")


class Bounds(_Out):
    min_x: float = Field(description="metres")
    min_y: float = Field(description="metres")
    max_x: float = Field(description="metres")
    max_y: float = Field(description="metres")


class MapSummary(_Out):
    name: str = Field(description="map name, also its file name without .json")
    description: str = Field(description="free text")
    classes: list[str] = Field(description="object classes on the map")
    object_count: int = Field(description="number of objects")
    bounds: Bounds = Field(description="extent of walls and objects, metres")


class ValidationIssue(_Out):
    """One problem pydantic found in a request body."""

    type: str = Field(description="machine-readable kind, e.g. missing, float_type")
    loc: list[str | int] = Field(description="where: body, field names and list indices")
    msg: str = Field(description="what was wrong, in words")


class ErrorBody(_Out):
    """Every error answer (4xx, 5xx): what was wrong, for programs and for people."""

    detail: str | list[ValidationIssue] = Field(
        description="the problem in words, or for a body that fails validation the list of problems"
    )
    message: str = Field(description="one readable sentence covering every problem")
    code: str | None = Field(
        None, description="for a service limit: which one, e.g. too_many_sessions"
    )


class SpeechRequest(StrictInput):
    # Python's regular expressions, so that "white space" means what str.strip() and
    # the speech module mean by it.
    model_config = ConfigDict(regex_engine="python-re")

    text: str = Field(
        min_length=1,
        max_length=2000,
        pattern=r"\S",
        description="text to speak: 1 to 2000 characters, not only white space",
    )
