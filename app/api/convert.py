"""Between the wire models (JSON, degrees) and the service's own types (radians).

The one place where a request body becomes a :class:`~app.service.types.SessionSpec`
or :class:`~app.service.types.FrameInput`, and a
:class:`~app.service.types.FrameOutcome` becomes the ``FrameResult`` of docs/API.md.
"""

from __future__ import annotations

import math

from app.api.schemas import (
    FeedbackItemOut,
    FeedbackOut,
    Frame,
    FrameResult,
    HypothesisOut,
    PoseOut,
    SessionCreate,
    SessionOut,
    Uncertainty,
)
from app.feedback import FeedbackOptions
from app.localization.types import Detection, InitialPose, Odometry, Pose
from app.maps.geometry import wrap_deg
from app.service.sessions import Session
from app.service.types import FrameInput, FrameOutcome, SensorSpec, SessionSpec


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
    return SessionSpec(
        map_name=body.map,
        particles=body.particles,
        seed=body.seed,
        initial_pose=initial,
        sensor=SensorSpec(
            bearing_std_deg=s.bearing_std_deg,
            fov_deg=s.fov_deg,
            class_bearing_std_deg=dict(s.class_bearing_std_deg),
        ),
        feedback=FeedbackOptions(fb.style, fb.units, fb.max_items),
        share_view=body.share_view,
    )


def frame_input(frame: Frame) -> FrameInput:
    """A ``Frame`` in the service's units: radians, bearings wrapped to (-pi, pi]."""
    odometry = None
    if frame.odometry is not None:
        o = frame.odometry
        odometry = Odometry(o.forward_m, o.left_m, math.radians(o.turn_deg))
    truth = None
    if frame.truth is not None:
        t = frame.truth
        truth = Pose(t.x, t.y, math.radians(t.theta_deg))
    return FrameInput(
        timestamp=frame.timestamp,
        odometry=odometry,
        detections=tuple(
            Detection(d.cls, math.radians(wrap_deg(d.bearing_deg)), d.score)
            for d in frame.detections
        ),
        describe=frame.describe,
        truth=truth,
    )


def _deg(rad: float) -> float:
    return round(wrap_deg(math.degrees(rad)), 3)


def frame_result(outcome: FrameOutcome) -> FrameResult:
    """Shape one step's outcome as the ``FrameResult`` of docs/API.md."""
    estimate = outcome.estimate
    feedback = outcome.feedback
    return FrameResult(
        seq=outcome.seq,
        pose=PoseOut(
            x=round(estimate.x, 4), y=round(estimate.y, 4), theta_deg=_deg(estimate.theta_rad)
        ),
        uncertainty=Uncertainty(
            std_x_m=round(min(estimate.std_x_m, 1e6), 4),
            std_y_m=round(min(estimate.std_y_m, 1e6), 4),
            std_theta_deg=round(math.degrees(estimate.std_theta_rad), 3),
        ),
        converged=estimate.converged,
        hypotheses=[
            HypothesisOut(
                x=round(h.x, 4),
                y=round(h.y, 4),
                theta_deg=_deg(h.theta_rad),
                weight=round(h.weight, 4),
                region=region,
            )
            for h, region in zip(estimate.hypotheses[:3], outcome.regions, strict=False)
        ],
        feedback=FeedbackOut(
            text=feedback.text,
            items=[
                FeedbackItemOut(
                    cls=i.cls,
                    label=i.label,
                    clock=i.clock,
                    bearing_deg=None if i.bearing_deg is None else round(i.bearing_deg, 1),
                    distance_m=None if i.distance_m is None else round(i.distance_m, 2),
                )
                for i in feedback.items
            ],
        ),
        warnings=list(outcome.warnings),
    )


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
