"""Frames without odometry: a short gap is walked through, a long one breaks the fix.

A phone's visual-inertial tracker stops now and then for a second or three ("limited
tracking" in ARKit and ARCore: a blank wall, a quick turn, a dark corridor), and the app
then sends frames without ``odometry`` (docs/API.md) while the person walks on. Taking
each such frame for "the person may have been carried anywhere" let every held fix go at
the gap's first frame and made the person wait for a fresh gain after it: measured on the
phone suite's office walks at VIO grade through a 360 deg camera with the tracker lost for
3 s of every 20 s (``tools/unmodelled.py``, effect ``tracking-lost-3s``), no frame of
the gap and 0.00-0.60 of those in each of the five seconds after it were told, though
the estimate stayed within 0.5 m of the person on most of them (0.85-0.96 told now).

A person on foot cannot be carried far in a few seconds, so :class:`OdometryGap` lets
the fix go only once the frames without odometry have lasted longer than
:data:`GAP_HOLD_S` by their timestamps, or at once when a frame's duration is not known
(no timestamps, or a pause: nothing bounds how far the person went). Until then each
frame's motion is guessed from the walk just before (:class:`~app.localization.motion.
GuessedMotion`: the recent velocity, in the body frame, as a mean, with the unknown
motion's noise and more): the filter's cloud and the evidence tracker's places move
with the person instead of standing still while the detections drag them, and the held
fix goes on being tested by everything that tests it (fit, alternatives, geometry, dead
reckoning without detections), and a frame that most of its detections contradict
(a frame bad on its own, ``_bad_run`` in the filter) ends the gap there and lets the fix
go (:meth:`OdometryGap.break_off`): the person may have been carried after all. The
checks that compare the estimate with the odometry
(the slide, the walk, the told heading) are not fed the guess: it is no measurement.

Only through a camera that sees all around (:data:`~app.localization.config.
ALL_AROUND_FOV_DEG`): its bearings pin the place on their own. A narrower view leaves the
place loose along the line of sight, where the odometry held it; walked through on a
guess, the cloud stayed tight while it fell behind the person (measured, the same walks
through a 180 deg camera: a held fix 1.1-1.2 m off within three seconds, two frames
confidently wrong, and as many through a 66 deg one), so there the gap's first frame
lets the fix go, as before.

Nor near a ride (a map with levels: the barometer says the person is between floors, or
the estimate stands in a connector's stop) or on a map with levels without a barometer
(nothing says a ride began): stairs, an escalator or a lift car move a person otherwise
than the walk before them. Measured on the venue suite's VIO walks (360 deg, barometer)
with the tracker lost for every ride and a second after it: walked through, 24 frames
1.0-1.4 m off on the stairs in 10 walks; not, none.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from app.localization.config import ALL_AROUND_FOV_DEG
from app.localization.motion import GuessedMotion
from app.localization.types import Odometry

#: Longest run of frames without odometry (s, by their timestamps) a held fix is kept
#: through: a tracker's "limited tracking" lasts a few seconds, while a person walking
#: at 1.4 m/s is 7 m away after five.
GAP_HOLD_S = 5.0
#: Weight of each timed frame with odometry in the walk's recent velocity (an
#: exponential mean over about the last second at 5 frames/s).
VELOCITY_SMOOTHING = 0.3


class OdometryGap:
    """The walk's recent velocity and the current run of frames without odometry, for a
    camera ``fov_deg`` wide: one narrower than
    :data:`~app.localization.config.ALL_AROUND_FOV_DEG` walks no gap through."""

    def __init__(self, fov_deg: float) -> None:
        #: Longest gap walked through (s).
        self.hold_s = GAP_HOLD_S if fov_deg >= ALL_AROUND_FOV_DEG else 0.0
        self.reset()

    def reset(self) -> None:
        #: Recent body-frame velocity (forward, left), m/s, from timed frames.
        self.velocity = (0.0, 0.0)
        #: Seconds of frames without odometry since the last one with it (None: one of
        #: unknown duration among them).
        self.gap_s: float | None = 0.0
        #: Whether a frame with odometry came since the fix was last let go for a gap.
        self.had_odometry = False
        self._guessed = False

    def frame(
        self, odometry: Odometry | None, frame_s: float | None, may_guess: bool = True
    ) -> tuple[Odometry | None, bool]:
        """This frame's motion for the particles (``odometry`` itself, or a guess for a
        frame without it inside a short gap, or None) and whether the odometry broke off
        on it (a held fix is then let go). ``frame_s``: the frame's duration (None: not
        known); ``may_guess`` False: no gap is walked through on this frame (the person
        may be riding between floors)."""
        self._guessed = False
        if odometry is not None:
            if frame_s is not None and frame_s > 0.0:
                a = VELOCITY_SMOOTHING
                vf, vl = self.velocity
                self.velocity = (
                    (1.0 - a) * vf + a * odometry.forward_m / frame_s,
                    (1.0 - a) * vl + a * odometry.left_m / frame_s,
                )
            self.gap_s = 0.0
            self.had_odometry = True
            return odometry, False
        if self.gap_s is not None:
            self.gap_s = None if frame_s is None else self.gap_s + frame_s
        short = may_guess and self.gap_s is not None and self.gap_s <= self.hold_s
        broke = self.had_odometry and not short
        if not short:
            # Broken off (or never walked through): no guess until odometry is back.
            self.gap_s = None
        if broke:
            self.had_odometry = False
        if not short or frame_s is None:
            return None, broke
        self._guessed = True
        vf, vl = self.velocity
        return GuessedMotion(vf * frame_s, vl * frame_s, 0.0), broke

    @property
    def guessed(self) -> bool:
        """Whether the last frame was one without odometry moved by a guess."""
        return self._guessed

    def break_off(self) -> bool:
        """The gap is taken for a break after all (a frame walked through it on a guess
        was bad on its own): no more guesses until odometry comes back. Returns True,
        the fix is to be let go."""
        self.gap_s = None
        self.had_odometry = False
        self._guessed = False
        return True

    def checkpoint(self) -> dict[str, Any]:
        return {
            "velocity": list(self.velocity),
            "gap_s": self.gap_s,
            "had": self.had_odometry,
            "guessed": self._guessed,
        }

    def restore(self, state: Mapping[str, Any] | None, had_odometry: bool) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before gaps were walked
        through; ``had_odometry`` is then its filter's own flag)."""
        self.reset()
        if state is None:
            self.had_odometry = had_odometry
            return
        vf, vl = state["velocity"]
        self.velocity = (float(vf), float(vl))
        gap = state["gap_s"]
        self.gap_s = None if gap is None else float(gap)
        self.had_odometry = bool(state["had"])
        self._guessed = bool(state["guessed"])
