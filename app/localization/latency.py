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

An app that does not say the age (``detections_age_s`` 0) still has one. It shows in
turns: a static object's bearing seen ``L`` seconds late is off by the turn rate times
``L`` (turning left the heading grows, so an older view puts every object further left).
:class:`LatencyEstimate` fits ``L`` by least squares to the median bearing residual of
converged frames against the frame's turn rate, adding back the age already applied, and
the filter applies the learnt age to frames that give none.
"""

from __future__ import annotations

import math
import statistics
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


#: Frames turning slower than this (rad/s) say little of the latency: walking straight
#: the residuals are the detector's noise and its boxes' bias.
LAG_MIN_TURN_RAD_S = 0.3
#: The sum of squared turn rates (rad^2/s^2) before the latency learnt is applied: about
#: ten frames of a brisk turn (1 rad/s).
LAG_MIN_EVIDENCE = 2.0
#: Residuals wider than this (rad) are another object's, or clutter: not a lag.
LAG_MAX_RESIDUAL_RAD = math.radians(15.0)
#: A frame needs this many matched detections to measure a lag (one can be a box's bias).
LAG_MIN_DETECTIONS = 2
#: The longest latency learnt (s).
LAG_MAX_S = 0.5
#: A learnt latency below this (s) is not applied: a walk's residuals learn 0-0.012 s
#: with no latency at all (the phone suite's ideal and stale-map walks), and applied, so
#: small an age changed nothing but which frames of a marginal walk went wrong (the
#: stale map alone at 10 frames/s: 15 -> 57 confidently-wrong frames). Walks 0.1-0.3 s
#: late learnt 0.02-0.14 s (all measured before this floor).
LAG_MIN_S = 0.02


class LatencyEstimate:
    """The detections' age of an app that does not say it, learnt from turns (module
    docstring): ``sum(lag * w) / sum(w^2)`` over converged frames turning at ``w``, the
    lag being the median bearing residual plus the age already applied times ``w``."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.lag_turn = 0.0  # sum of (residual + applied age * turn rate) * turn rate
        self.turn_sq = 0.0  # sum of squared turn rates

    def update(self, residuals_rad: list[float], turn_rad_s: float, applied_s: float) -> None:
        """One converged frame: its matched detections' bearing residuals at the estimate
        (observed minus predicted), its turn rate, and the age it was weighed with."""
        if not self.turning(turn_rad_s):
            return
        near = [r for r in residuals_rad if abs(r) <= LAG_MAX_RESIDUAL_RAD]
        if len(near) < LAG_MIN_DETECTIONS:
            return
        lag = float(statistics.median(near)) + applied_s * turn_rad_s
        self.lag_turn += lag * turn_rad_s
        self.turn_sq += turn_rad_s * turn_rad_s

    @staticmethod
    def turning(turn_rad_s: float) -> bool:
        """Whether a frame turns fast enough to say something of the latency."""
        return abs(turn_rad_s) >= LAG_MIN_TURN_RAD_S

    @property
    def age_s(self) -> float | None:
        """The learnt age (s), or None before enough turning or below ``LAG_MIN_S``."""
        if self.turn_sq < LAG_MIN_EVIDENCE:
            return None
        age = min(self.lag_turn / self.turn_sq, LAG_MAX_S)
        return age if age >= LAG_MIN_S else None

    def checkpoint(self) -> dict[str, Any]:
        return {"lag_turn": self.lag_turn, "turn_sq": self.turn_sq}

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it was learnt)."""
        self.reset()
        if state is not None:
            self.lag_turn, self.turn_sq = float(state["lag_turn"]), float(state["turn_sq"])
