"""Detections weighed at the pose they were captured from, not at the frame's end.

A phone's camera and detector lag its odometry: a frame's detections describe the camera
``detections_age_s`` (typically 0.1-0.3 s) before the end of the frame's motion. Walking
at 1.4 m/s that is 0.3 m; turning at 90 deg/s it is 20 degrees of bearing, far beyond the
sensor model's 2-degree noise.

The filter therefore runs in *capture time*: its particles stand for the pose at the
moment the detections were captured. With ``back_k`` the body-frame motion from frame
k's capture to its end (the trailing ``age`` seconds of the odometry received so far),
the motion between two captures is ``back_{k-1} . odo_k . back_k^-1`` (SE(2)
composition), and the pose reported for the frame's end is the capture pose moved by
``back_k``. Everything downstream of the particles (the sensor model, the evidence
window, the convergence gate) then sees detections and poses of one instant, and no
kernel changes. The trailing motion assumes constant velocity within a frame; a frame
without a timestamp is taken to last ``DEFAULT_FRAME_S``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

from app.localization.motion import compose_odometry
from app.localization.types import Estimate, Hypothesis, Odometry

#: Duration assumed for a frame whose timestamps do not say (10 frames/s, seconds).
DEFAULT_FRAME_S = 0.1
#: Longest latency taken into account (docs/API.md: detections_age_s is at most 2 s).
MAX_AGE_S = 2.0
#: Recent frames kept to find the trailing motion of an age longer than one frame.
HISTORY_FRAMES = 64
#: No motion.
ZERO = Odometry(0.0, 0.0, 0.0)


def inverse(motion: Odometry) -> Odometry:
    """The motion that undoes ``motion`` (its SE(2) inverse, in the reached body frame)."""
    c, s = math.cos(motion.turn_rad), math.sin(motion.turn_rad)
    return Odometry(
        forward_m=-(c * motion.forward_m + s * motion.left_m),
        left_m=s * motion.forward_m - c * motion.left_m,
        turn_rad=-motion.turn_rad,
    )


def fraction(motion: Odometry, share: float) -> Odometry:
    """The last ``share`` (0..1) of ``motion``, at constant velocity (small steps: the
    translation and the turn scale alike; the part's translation is turned into the
    body frame it starts from)."""
    lead = 1.0 - share
    turn_before = lead * motion.turn_rad
    c, s = math.cos(-turn_before), math.sin(-turn_before)
    f, left = share * motion.forward_m, share * motion.left_m
    return Odometry(c * f - s * left, s * f + c * left, share * motion.turn_rad)


def moved_forward(est: Estimate, motion: Odometry) -> Estimate:
    """``est`` with its pose and every hypothesis moved by the body-frame ``motion``."""

    def move(x: float, y: float, theta: float) -> tuple[float, float, float]:
        c, s = math.cos(theta), math.sin(theta)
        return (
            x + c * motion.forward_m - s * motion.left_m,
            y + s * motion.forward_m + c * motion.left_m,
            theta + motion.turn_rad,
        )

    x, y, theta = move(est.x, est.y, est.theta_rad)
    hyps = tuple(
        Hypothesis(*move(h.x, h.y, h.theta_rad), h.weight, h.std_xy_m) for h in est.hypotheses
    )
    return Estimate(
        x, y, theta, est.std_x_m, est.std_y_m, est.std_theta_rad, est.converged, hyps,
        est.n_particles, est.ess, est.protection_m,
    )  # fmt: skip


class CaptureClock:
    """Turns each frame's odometry into motion between detection captures.

    :meth:`step` takes a frame's odometry, its duration and its detections' age, and
    returns the motion from the previous capture to this one; :attr:`back` is then the
    motion from this capture to the frame's end (what :func:`moved_forward` applies to
    the reported estimate).
    """

    def __init__(self) -> None:
        self.back = ZERO
        self._recent: deque[tuple[Odometry, float]] = deque(maxlen=HISTORY_FRAMES)

    def reset(self) -> None:
        self.back = ZERO
        self._recent.clear()

    def step(
        self, odometry: Odometry | None, frame_s: float | None, age_s: float
    ) -> Odometry | None:
        """The motion between the previous capture and this frame's (None: unknown)."""
        if odometry is None:
            # Unknown motion: the capture poses are unrelated anyway; start afresh.
            self.reset()
            return None
        duration = frame_s if frame_s is not None and frame_s > 0.0 else DEFAULT_FRAME_S
        self._recent.append((odometry, duration))
        if age_s <= 0.0 and self.back == ZERO:
            return odometry  # detections of the frame's end, as before: nothing to move
        back = self._trailing(min(max(age_s, 0.0), MAX_AGE_S))
        between = compose_odometry(compose_odometry(self.back, odometry), inverse(back))
        self.back = back
        return between

    def _trailing(self, age_s: float) -> Odometry:
        """The motion over the last ``age_s`` seconds of the frames received."""
        total = Odometry(0.0, 0.0, 0.0)
        left = age_s
        for motion, duration in reversed(self._recent):
            if left <= 0.0:
                break
            part = motion if left >= duration else fraction(motion, left / duration)
            composed = compose_odometry(part, total)
            assert composed is not None
            total = composed
            left -= duration
        return total

    def checkpoint(self) -> dict[str, Any]:
        return {
            "back": (self.back.forward_m, self.back.left_m, self.back.turn_rad),
            "recent": [(m.forward_m, m.left_m, m.turn_rad, d) for m, d in self._recent],
        }

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before detections had an age)."""
        self.reset()
        if state is None:
            return
        self.back = Odometry(*(float(v) for v in state["back"]))
        for f, left, turn, d in state["recent"]:
            self._recent.append((Odometry(float(f), float(left), float(turn)), float(d)))
