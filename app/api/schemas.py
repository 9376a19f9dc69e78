"""Request and response bodies of the HTTP and WebSocket API, as docs/API.md describes them.

Units are in the names: ``*_deg`` degrees, ``*_m`` metres, map coordinates ``x, y``
in metres. Every number must be a finite JSON number (booleans and numeric strings are
refused); unknown fields are refused so typos surface.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, model_validator
from pydantic.json_schema import JsonDict, JsonValue

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


class BoxIn(StrictInput):
    """A detector's box, horizontally: its left and right image columns (pixels).

    Columns grow to the right from 0 at the left edge. On a 360-degree image a box with
    ``u_min_px > u_max_px`` runs over the right edge and continues at the left one.
    """

    u_min_px: Finite = Field(ge=0, description="left column of the box, pixels")
    u_max_px: Finite = Field(ge=0, description="right column of the box, pixels")


def _exactly_one(*branches: JsonDict) -> JsonDict:
    """JSON Schema ``oneOf`` for "exactly one of these": each branch names its required
    fields (and their types), the others must be null or absent."""
    names = sorted({name for branch in branches for name in branch})
    one_of: list[JsonValue] = []
    for branch in branches:
        required: list[JsonValue] = list(sorted(branch))
        properties: JsonDict = {n: branch.get(n, {"type": "null"}) for n in names}
        one_of.append({"required": required, "properties": properties})
    return {"oneOf": one_of}


class DetectionIn(StrictInput):
    """One detection from the camera's object detector: a bearing or a pixel box."""

    # The rule of _bearing_or_box, stated in the JSON schema as well.
    model_config = ConfigDict(
        json_schema_extra=_exactly_one(
            {"bearing_deg": {"type": "number"}}, {"box": {"type": "object"}}
        )
    )

    cls: str = Field(
        alias="class",
        min_length=1,
        max_length=64,
        description="object class, a lower-case word such as door; classes the map "
        "lacks are ignored and reported in warnings",
    )
    bearing_deg: Finite | None = Field(
        None,
        description="direction of the object's centre relative to straight ahead, degrees, "
        "counter-clockwise positive (left +90, right -90); any real value, wrapped to "
        "(-180, 180]. Give this or box.",
    )
    box: BoxIn | None = Field(
        None,
        description="addition: the detector's pixel box instead of bearing_deg; its "
        "horizontal centre becomes the bearing through the session's camera",
    )
    score: Finite = Field(1.0, ge=0.0, le=1.0, description="detection confidence in [0, 1]")

    @model_validator(mode="after")
    def _bearing_or_box(self) -> DetectionIn:
        if (self.bearing_deg is None) == (self.box is None):
            raise ValueError("give exactly one of bearing_deg and box")
        return self


class HeadingIn(StrictInput):
    """The phone compass: an absolute heading in the map frame."""

    heading_deg: Finite = Field(
        ge=-3600, le=3600, description="heading, degrees counter-clockwise from the map's +x"
    )
    std_deg: Finite = Field(
        20.0, gt=0.0, le=180.0, description="the compass's accuracy (standard deviation), degrees"
    )


class AltitudeIn(StrictInput):
    """The phone barometer's altitude, relative to a reference the phone keeps fixed."""

    relative_m: Finite = Field(
        ge=-10_000, le=10_000, description="relative altitude, metres (up positive)"
    )
    std_m: Finite = Field(0.5, gt=0.0, le=100.0, description="its standard deviation, metres")


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
    heading: HeadingIn | None = Field(
        None, description="the phone compass's heading, or null (heavy-tailed: may be off)"
    )
    detections_age_s: Finite = Field(
        0.0,
        ge=0.0,
        le=2.0,
        description="how long before the end of this frame's odometry the detections were "
        "captured (camera and detector latency), seconds; they are weighed at that pose",
    )
    altitude: AltitudeIn | None = Field(
        None, description="the phone barometer's relative altitude, or null (maps with levels)"
    )


class SensorSettings(StrictInput):
    """The camera and detector: bearing noise and field of view."""

    bearing_std_deg: Finite = Field(
        2.0, gt=0.0, le=90.0, description="bearing noise standard deviation, degrees"
    )
    fov_deg: Finite = Field(360.0, gt=0.0, le=360.0, description="camera field of view, degrees")
    class_bearing_std_deg: dict[
        str, Annotated[float, Field(gt=0, le=90, allow_inf_nan=False, strict=True)]
    ] = Field(default_factory=dict, description="addition: per-class bearing std, degrees")
    class_error: Finite = Field(
        0.03,
        ge=0.0,
        le=0.5,
        description="probability that a detection's class is not the object's (confusion)",
    )


class OdometrySettings(StrictInput):
    """Where the frames' odometry comes from: tightens the motion model when known."""

    source: Literal["vio", "pdr", "unknown"] = Field(
        "unknown",
        description="vio: visual-inertial tracking (scale within about 2 %, heading drift a "
        "few degrees a minute); pdr: pedestrian dead reckoning (step length off by up to "
        "about 10 %, heading drift up to about 10 degrees a minute); unknown: not said",
    )


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
    level: str | None = Field(
        None,
        max_length=64,
        description="the level id on a map with levels; null: any level where the pose is free",
    )


class EquirectangularCameraIn(StrictInput):
    """A 360-degree camera: ``bearing = 360 * (W/2 - u) / W`` degrees."""

    model: Literal["equirectangular"]
    width_px: Integer = Field(ge=2, le=1_000_000, description="image width, pixels")
    yaw_offset_deg: Finite = Field(
        0.0, ge=-360, le=360, description="camera forward relative to body forward, CCW positive"
    )


class PinholeCameraIn(StrictInput):
    """An ordinary phone camera: ``bearing = atan((cx - u) / fx)``; the FOV follows."""

    model: Literal["pinhole"]
    width_px: Integer = Field(ge=2, le=1_000_000, description="image width, pixels")
    fx_px: Finite = Field(gt=0, le=1e7, description="horizontal focal length, pixels")
    cx_px: Finite = Field(description="principal point column, pixels (0 to width_px)")
    yaw_offset_deg: Finite = Field(
        0.0, ge=-360, le=360, description="camera forward relative to body forward, CCW positive"
    )

    @model_validator(mode="after")
    def _centre_in_image(self) -> PinholeCameraIn:
        if not 0 <= self.cx_px <= self.width_px:
            raise ValueError(
                f"cx_px {self.cx_px:g} must lie within the image (0 to width_px {self.width_px})"
            )
        return self


CameraIn = Annotated[EquirectangularCameraIn | PinholeCameraIn, Field(discriminator="model")]


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
    odometry: OdometrySettings = Field(default_factory=OdometrySettings)
    feedback: FeedbackSettings = Field(default_factory=FeedbackSettings)
    camera: CameraIn | None = Field(
        None,
        description="the phone camera, so detections may give pixel boxes; its field of "
        "view replaces sensor.fov_deg",
    )
    share_view: bool = Field(
        False,
        description="addition: list this session in the live view (private by default); "
        "see docs/SECURITY.md",
    )


class DestinationIn(StrictInput):
    """Where to guide to: exactly one of label, class, region, or a point x, y."""

    # The rule of _one_target, stated in the JSON schema as well.
    model_config = ConfigDict(
        json_schema_extra=_exactly_one(
            {"label": {"type": "string"}},
            {"class": {"type": "string"}},
            {"region": {"type": "string"}},
            {"x": {"type": "number"}, "y": {"type": "number"}},
        )
    )

    label: str | None = Field(None, min_length=1, max_length=200, description="an object's label")
    cls: str | None = Field(
        None, alias="class", min_length=1, max_length=64, description="nearest object of a class"
    )
    region: str | None = Field(None, min_length=1, max_length=200, description="a region's name")
    x: Finite | None = Field(None, description="a point, metres (with y)")
    y: Finite | None = Field(None, description="a point, metres (with x)")
    level: str | None = Field(
        None,
        min_length=1,
        max_length=64,
        description="addition: the level (its id) the destination is on; a point on a map "
        "with levels needs it, a label, class or region is then looked for on that level only",
    )
    step_free: bool = Field(
        False,
        description="addition: a way without steps: lifts and ramps only, no stairs or escalators",
    )

    @model_validator(mode="after")
    def _one_target(self) -> DestinationIn:
        given = [self.label is not None, self.cls is not None, self.region is not None]
        point = self.x is not None or self.y is not None
        if point and (self.x is None or self.y is None):
            raise ValueError("a point destination needs both x and y")
        if sum(given) + point != 1:
            raise ValueError("give exactly one of label, class, region, or x and y")
        return self


# ----------------------------------------------------------------------------- output
class LevelOut(_Out):
    id: str = Field(description="the level's id in the map file")
    name: str = Field(description="its spoken name")
    ordinal: int = Field(description="0 the ground floor, negative below it")


class PoseOut(_Out):
    x: float = Field(description="metres")
    y: float = Field(description="metres")
    theta_deg: float = Field(description="heading, degrees CCW from +x, (-180, 180]")
    level: LevelOut | None = Field(None, description="the level; null on a map without levels")


class Uncertainty(_Out):
    std_x_m: float = Field(description="standard deviation of x in the best cluster, metres")
    std_y_m: float = Field(description="standard deviation of y in the best cluster, metres")
    std_theta_deg: float = Field(description="circular standard deviation of heading, degrees")
    level_probability: float | None = Field(
        None, description="probability of the pose's level; null on a map without levels"
    )


class HypothesisOut(_Out):
    x: float = Field(description="metres")
    y: float = Field(description="metres")
    theta_deg: float = Field(description="heading, degrees CCW from +x")
    weight: float = Field(description="share of the belief's weight, 0..1")
    region: str | None = Field(description="named region containing it, or null")
    level: LevelOut | None = Field(None, description="its level; null on a map without levels")


class FeedbackItemOut(_Out):
    cls: str = Field(alias="class", serialization_alias="class", description="object class")
    label: str | None = Field(description="the map's label for the object, or null")
    clock: int | None = Field(description="clock direction 1..12 (12 ahead), null if unknown")
    bearing_deg: float | None = Field(description="degrees, CCW positive, null if unknown")
    distance_m: float | None = Field(description="metres, null if unknown")


class FeedbackOut(_Out):
    text: str = Field(description="what to speak now (may be empty)")
    items: list[FeedbackItemOut]
    suggestion: Literal["turn", "walk"] | None = Field(
        None,
        description="while not located, what would help most: turn on the spot to see more, "
        "or walk a few steps; null once located",
    )


class NextTurnOut(_Out):
    clock: int = Field(description="clock direction 1..12 of the next turn of the path")
    bearing_deg: float = Field(description="its bearing, degrees CCW positive")
    distance_m: float = Field(description="straight-line distance to the turn, metres")
    then_clock: int = Field(
        description="addition: the turn to take there, as a clock direction relative to "
        "the direction walked until then"
    )


class GuidanceConnectorOut(_Out):
    id: str = Field(description="the connector's id in the map file")
    kind: Literal["elevator", "stairs", "escalator", "ramp"]
    label: str | None = Field(description="the connector's label in the map file, or null")
    direction: Literal["up", "down"] = Field(description="the way the ride goes")
    to_level: LevelOut = Field(description="the level the ride ends on")
    at_stop: bool = Field(description="the person is at the connector: time to take it")


class GuidanceOut(_Out):
    target: str = Field(description="the destination as spoken")
    clock: int = Field(description="clock direction 1..12 of the target")
    bearing_deg: float = Field(description="bearing of the target, degrees CCW positive")
    distance_m: float = Field(description="straight-line distance to the target, metres")
    path_m: float = Field(description="walking distance along the shortest path, metres")
    next: NextTurnOut | None = Field(
        description="the next turn of the path; null when the target is in a straight line"
    )
    arrived: bool = Field(description="within 1 m of the target (walking distance)")
    connector: GuidanceConnectorOut | None = Field(
        None,
        description="while the way changes level next: the connector it takes (the "
        "directions above then lead to it); null otherwise",
    )


class DestinationOut(_Out):
    target: str = Field(description="the destination as it will be spoken")
    kind: Literal["label", "class", "region", "point"]
    points: list[tuple[float, float]] = Field(
        description="candidate end points (x, y) in metres; empty for a region"
    )
    levels: list[str] | None = Field(
        None, description="addition: the level (id) of each point; null on a map without levels"
    )
    step_free: bool = Field(False, description="addition: lifts and ramps only")


class FrameResult(_Out):
    seq: int = Field(description="1-based number of this frame in the session")
    pose: PoseOut
    uncertainty: Uncertainty
    converged: bool = Field(description="true only when the belief is a single tight mode")
    protection_m: float | None = Field(
        default=None,
        description="metres: radius around pose holding the true position with at least "
        "99 % probability under the whole belief, far modes included; null while not "
        "converged",
    )
    hypotheses: list[HypothesisOut]
    feedback: FeedbackOut
    warnings: list[str]
    guidance: GuidanceOut | None = Field(
        None, description="directions to the destination; null without one or while not converged"
    )


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


class ConnectorStopOut(_Out):
    level: str = Field(description="level id")
    polygon: list[tuple[float, float]] = Field(description="where it is entered and left, metres")


class ConnectorOut(_Out):
    id: str
    kind: Literal["elevator", "stairs", "escalator", "ramp"]
    label: str | None
    direction: Literal["both", "up", "down"]
    stops: list[ConnectorStopOut]


class MapLevelOut(LevelOut):
    elevation_m: float = Field(description="metres")


class MapSummary(_Out):
    name: str = Field(description="map name, also its file name without .json")
    description: str = Field(description="free text")
    classes: list[str] = Field(description="object classes on the map")
    object_count: int = Field(description="number of objects")
    bounds: Bounds = Field(description="extent of walls and objects, metres")
    levels: list[MapLevelOut] = Field(
        default_factory=list, description="the venue's levels by ordinal; empty: one level"
    )
    connectors: list[ConnectorOut] = Field(
        default_factory=list, description="where a person changes level"
    )


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
    retry_after_s: float | None = Field(
        None,
        description="for a limit that passes: seconds after which trying again may succeed "
        "(also in the Retry-After header, whole seconds)",
    )


class SpeechRequest(StrictInput):
    # "Not only white space", written out so that Python's regular expressions and the
    # ECMAScript ones of JSON Schema (what clients and fuzzers read) agree character for
    # character: Python's \s also holds \x1c-\x1f and \x85 (as str.strip() does),
    # ECMAScript's also holds \ufeff; the class excludes the union of both.
    model_config = ConfigDict(regex_engine="python-re")

    text: str = Field(
        min_length=1,
        max_length=2000,
        pattern=r"[^\s\x1c-\x1f\x85\ufeff]",
        description="text to speak: 1 to 2000 characters, not only white space",
    )
