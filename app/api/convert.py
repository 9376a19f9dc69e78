"""Between the wire models (JSON, degrees) and the service's own types (radians).

The one place where a request body becomes a :class:`~app.service.types.SessionSpec`
or :class:`~app.service.types.FrameInput`, and a
:class:`~app.service.types.FrameOutcome` becomes the ``FrameResult`` of docs/API.md.
"""

from __future__ import annotations

import math
from typing import Any

import orjson

from app.api.schemas import (
    BoxIn,
    CameraIn,
    DestinationIn,
    DestinationOut,
    Frame,
    FrameResult,
    SessionCreate,
    SessionOut,
)
from app.feedback import FeedbackOptions, clock_from_bearing_deg
from app.guidance import DestinationSpec, Guidance, Target
from app.localization.camera import BoxError, Camera
from app.localization.compass import CompassReading
from app.localization.floors import AltitudeReading
from app.localization.types import Detection, InitialPose, Odometry, Pose
from app.maps.geometry import wrap_deg
from app.maps.levels import LevelLayout
from app.service.session import Session
from app.service.types import FrameInput, FrameOutcome, LevelRef, SensorSpec, SessionSpec


def camera_of(body: CameraIn | None) -> Camera | None:
    """The session's camera model, or None."""
    if body is None:
        return None
    if body.model == "pinhole":
        return Camera("pinhole", body.width_px, body.fx_px, body.cx_px, body.yaw_offset_deg)
    return Camera("equirectangular", body.width_px, yaw_offset_deg=body.yaw_offset_deg)


def session_spec(body: SessionCreate) -> SessionSpec:
    """The service's description of the session a ``SessionCreate`` asks for."""
    initial = None
    if body.initial_pose is not None:
        p = body.initial_pose
        initial = InitialPose(
            p.x, p.y, math.radians(p.theta_deg), p.std_xy_m, math.radians(p.std_theta_deg)
        )
    s = body.sensor
    fb = body.feedback
    level = None if body.initial_pose is None else body.initial_pose.level
    return SessionSpec(
        map_name=body.map,
        particles=body.particles,
        seed=body.seed,
        initial_pose=initial,
        sensor=SensorSpec(
            bearing_std_deg=s.bearing_std_deg,
            fov_deg=s.fov_deg,
            class_bearing_std_deg=dict(s.class_bearing_std_deg),
            class_error=s.class_error,
        ),
        feedback=FeedbackOptions(fb.style, fb.units, fb.max_items),
        camera=camera_of(body.camera),
        share_view=body.share_view,
        odometry_source=body.odometry.source,
        initial_level=level,
    )


def _box_bearing_deg(i: int, box: BoxIn, camera: Camera | None) -> float:
    """Detection ``i``'s bearing in degrees from its pixel ``box`` through ``camera``.

    Raises:
        BoxError: no session camera, or a box that does not fit the image; the message
            names the detection.
    """
    if camera is None:
        raise BoxError(
            f"detections.{i}.box: this session has no camera, so a pixel box cannot be "
            "turned into a bearing; create the session with a camera (e.g. "
            '{"model": "equirectangular", "width_px": 3840}) or send bearing_deg'
        )
    try:
        return camera.box_bearing_deg(box.u_min_px, box.u_max_px)
    except BoxError as exc:
        raise BoxError(f"detections.{i}.{exc}") from None


def frame_input(frame: Frame, camera: Camera | None = None) -> FrameInput:
    """A ``Frame`` in the service's units: radians, bearings wrapped to (-pi, pi].

    Pixel boxes become bearings through the session's ``camera`` (raises
    :class:`~app.localization.camera.BoxError` when that cannot be done). It runs for
    every frame on the event loop, so the detections are converted in one plain loop.
    """
    detections = []
    for i, d in enumerate(frame.detections):
        bearing = d.bearing_deg if d.box is None else _box_bearing_deg(i, d.box, camera)
        # (bearing_deg is a number when there is no box: the model checks one of the two)
        detections.append(Detection(d.cls, math.radians(wrap_deg(bearing)), d.score))  # type: ignore[arg-type]
    odometry = None
    if frame.odometry is not None:
        o = frame.odometry
        odometry = Odometry(o.forward_m, o.left_m, math.radians(o.turn_deg))
    truth = None
    if frame.truth is not None:
        t = frame.truth
        truth = Pose(t.x, t.y, math.radians(t.theta_deg))
    heading = None
    if frame.heading is not None:
        heading = CompassReading(
            math.radians(wrap_deg(frame.heading.heading_deg)), math.radians(frame.heading.std_deg)
        )
    altitude = None
    if frame.altitude is not None:
        altitude = AltitudeReading(frame.altitude.relative_m, frame.altitude.std_m)
    return FrameInput(
        timestamp=frame.timestamp,
        odometry=odometry,
        detections=tuple(detections),
        describe=frame.describe,
        truth=truth,
        heading=heading,
        detections_age_s=frame.detections_age_s,
        altitude=altitude,
    )


def _deg(rad: float) -> float:
    return round(wrap_deg(math.degrees(rad)), 3)


def _round(value: float, digits: int) -> float:
    """``value`` rounded, as a plain float whatever number it was."""
    return round(float(value), digits)


def destination_spec(body: DestinationIn) -> DestinationSpec:
    """The service's description of a destination request."""
    if body.label is not None:
        return DestinationSpec("label", body.label, level=body.level, step_free=body.step_free)
    if body.cls is not None:
        return DestinationSpec("class", body.cls, level=body.level, step_free=body.step_free)
    if body.region is not None:
        return DestinationSpec("region", body.region, level=body.level, step_free=body.step_free)
    return DestinationSpec(
        "point",
        x=float(body.x),  # type: ignore[arg-type]
        y=float(body.y),  # type: ignore[arg-type]
        level=body.level,
        step_free=body.step_free,
    )


def destination_out(target: Target, layout: LevelLayout) -> DestinationOut:
    """The resolved destination, its points in their levels' frames (as in the map file)."""
    xy, level = layout.from_plane(target.points)
    return DestinationOut(
        target=target.name,
        kind=target.kind,
        points=[(round(float(x), 4), round(float(y), 4)) for x, y in xy],
        levels=[layout.levels[int(k)].id for k in level] if layout.has_levels else None,
        step_free=target.step_free,
    )


def _guidance_data(g: Guidance | None) -> dict[str, Any] | None:
    """The ``guidance`` of docs/API.md as plain data: clock directions from the bearings."""
    if g is None:
        return None
    turn = None
    if g.next is not None:
        turn = {
            "clock": clock_from_bearing_deg(g.next.bearing_deg),
            "bearing_deg": float(g.next.bearing_deg),
            "distance_m": float(g.next.distance_m),
            "then_clock": clock_from_bearing_deg(g.next.then_deg),
        }
    connector = None
    if g.connector is not None:
        c = g.connector
        connector = {
            "id": c.id,
            "kind": c.kind,
            "label": c.label,
            "direction": c.direction,
            "to_level": {
                "id": c.to_level.id,
                "name": c.to_level.name,
                "ordinal": c.to_level.ordinal,
            },
            "at_stop": bool(c.at_stop),
        }
    return {
        "target": g.target,
        "clock": clock_from_bearing_deg(g.bearing_deg),
        "bearing_deg": float(g.bearing_deg),
        "distance_m": float(g.distance_m),
        "path_m": float(g.path_m),
        "next": turn,
        "arrived": bool(g.arrived),
        "connector": connector,
    }


def _level_data(level: LevelRef | None) -> dict[str, Any] | None:
    if level is None:
        return None
    return {"id": level.id, "name": level.name, "ordinal": int(level.ordinal)}


def frame_result_data(outcome: FrameOutcome) -> dict[str, Any]:
    """One step's outcome as the plain data of a ``FrameResult`` (docs/API.md): its
    fields in the model's order, under their wire names, every number a plain float
    or int as the model would hold it (orjson writes an int without ".0" and refuses
    numpy's scalars). The one place a result is shaped; :func:`frame_result`
    validates it into the model, :func:`frame_result_json` writes it for a stream."""
    estimate = outcome.estimate
    feedback = outcome.feedback
    level = outcome.level
    # On a map with levels the filter's x is in its plane (app.maps.levels): the
    # level's offset comes off. Without levels there is none.
    shift = 0.0 if level is None else level.offset_x
    levels = outcome.hypothesis_levels or (None,) * len(estimate.hypotheses)
    return {
        "seq": int(outcome.seq),
        "pose": {
            "x": _round(estimate.x - shift, 4),
            "y": _round(estimate.y, 4),
            "theta_deg": _deg(estimate.theta_rad),
            "level": _level_data(level),
        },
        "uncertainty": {
            "std_x_m": _round(min(estimate.std_x_m, 1e6), 4),
            "std_y_m": _round(min(estimate.std_y_m, 1e6), 4),
            "std_theta_deg": _round(math.degrees(estimate.std_theta_rad), 3),
            "level_probability": None
            if outcome.level_probability is None
            else _round(outcome.level_probability, 4),
        },
        "converged": bool(estimate.converged),
        "protection_m": None if estimate.protection_m is None else _round(estimate.protection_m, 3),
        "hypotheses": [
            {
                "x": _round(h.x - (0.0 if lv is None else lv.offset_x), 4),
                "y": _round(h.y, 4),
                "theta_deg": _deg(h.theta_rad),
                "weight": _round(h.weight, 4),
                "region": region,
                "level": _level_data(lv),
            }
            for h, region, lv in zip(estimate.hypotheses[:3], outcome.regions, levels, strict=False)
        ],
        "feedback": {
            "text": feedback.text,
            "items": [
                {
                    "class": i.cls,
                    "label": i.label,
                    "clock": None if i.clock is None else int(i.clock),
                    "bearing_deg": None if i.bearing_deg is None else _round(i.bearing_deg, 1),
                    "distance_m": None if i.distance_m is None else _round(i.distance_m, 2),
                }
                for i in feedback.items
            ],
            "suggestion": feedback.suggestion,
        },
        "warnings": list(outcome.warnings),
        "guidance": _guidance_data(outcome.guidance),
    }


def frame_result(outcome: FrameOutcome) -> FrameResult:
    """Shape one step's outcome as the ``FrameResult`` of docs/API.md (validated: one
    call into pydantic's core for the whole tree)."""
    return FrameResult.model_validate(frame_result_data(outcome))


def frame_result_json(outcome: FrameOutcome) -> str:
    """The JSON text of :func:`frame_result`, without building the model: orjson writes
    the plain data (the same text as the model's ``model_dump_json(by_alias=True)``, a
    test holds them equal; a stream answers every frame with it, at half the cost)."""
    return orjson.dumps(frame_result_data(outcome)).decode()


def session_out(session: Session) -> SessionOut:
    """The public view of a session, with its latest result."""
    last = session.last_outcome
    return SessionOut(
        id=session.id,
        map=session.map.name,
        particles=session.particles,
        created_at=session.created_at,
        frames=session.frames,
        last_result=None if last is None else frame_result(last),
    )
