"""Between the API's JSON shapes (degrees) and the filter's types (radians)."""

from __future__ import annotations

import math

from app.api.schemas import (
    FeedbackItemOut,
    FeedbackOut,
    Frame,
    FrameResult,
    HypothesisOut,
    PoseOut,
    Uncertainty,
)
from app.feedback import Feedback
from app.localization.geometry import wrap_deg
from app.localization.map import SemanticMap
from app.localization.types import Detection, Estimate, Odometry, Pose


def odometry_of(frame: Frame) -> Odometry | None:
    if frame.odometry is None:
        return None
    o = frame.odometry
    return Odometry(o.forward_m, o.left_m, math.radians(o.turn_deg))


def detections_of(frame: Frame, semantic_map: SemanticMap) -> tuple[list[Detection], list[str]]:
    """The frame's detections in radians, and a warning per class the map lacks."""
    dets = [
        Detection(d.cls, math.radians(wrap_deg(d.bearing_deg)), d.score) for d in frame.detections
    ]
    unknown = sorted({d.cls for d in dets} - set(semantic_map.classes))
    warnings = [
        f"class {c!r} is not on map {semantic_map.name!r}; its detections were ignored"
        for c in unknown
    ]
    return dets, warnings


def truth_of(frame: Frame) -> Pose | None:
    if frame.truth is None:
        return None
    return Pose(frame.truth.x, frame.truth.y, math.radians(frame.truth.theta_deg))


def _deg(rad: float) -> float:
    return round(wrap_deg(math.degrees(rad)), 3)


def frame_result(
    seq: int,
    estimate: Estimate,
    feedback: Feedback,
    semantic_map: SemanticMap,
    warnings: list[str],
) -> FrameResult:
    """Shape one step's estimate and feedback as CONTRACT.md's ``FrameResult``."""
    return FrameResult(
        seq=seq,
        pose=PoseOut(
            x=round(estimate.x, 4), y=round(estimate.y, 4), theta_deg=_deg(estimate.theta_rad)
        ),
        uncertainty=Uncertainty(
            std_x_m=round(min(estimate.std_x_m, 1e6), 4),
            std_y_m=round(min(estimate.std_y_m, 1e6), 4),
            std_theta_deg=round(math.degrees(estimate.std_theta_rad), 3),
        ),
        converged=estimate.converged,
        protection_m=None if estimate.protection_m is None else round(estimate.protection_m, 3),
        hypotheses=[
            HypothesisOut(
                x=round(h.x, 4),
                y=round(h.y, 4),
                theta_deg=_deg(h.theta_rad),
                weight=round(h.weight, 4),
                region=semantic_map.region_at(h.x, h.y),
            )
            for h in estimate.hypotheses[:3]
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
        warnings=warnings,
    )
