"""Whether a new fix faces the way the last told ones, carried by the odometry, faced.

The odometry turns with the person, so a right estimate's heading keeps the same offset
from the odometry's own heading for the whole walk, give or take the gyro's drift and
wander; a place that fits the bearings only turned by a few tens of degrees keeps
another. A bearing-only fix can be such a place: on a map whose furniture moved since it
was drawn, a pose a metre or two off and turned by 15-20 degrees explains the detections
about as well as the truth, with a cloud a few centimetres and a degree or two wide and
a protection radius of a metre. Measured on the phone suite's stale maps (seeds 0-59,
every camera, VIO grade, Intel Xeon ``rocketlake``): of the 237 fixes gained after an
earlier told one, the 218 whose heading agreed with the last told fix's, carried by the
odometry, to within 10 degrees included 2 spans more than a metre off; the 19 that
disagreed by more included 5 (seeds 3, 14, 39, 47 and 57 of the office suite and the
paper office through a 180-degree camera), told 1.0-1.6 m off at radii of 0.5-1.3 m. On
the other phone scenarios (seeds 0-9, 115 such gains) one disagreed by more than 10
degrees: 55 s after the last fix at PDR grade, whose gyro drifts up to 10 degrees a
minute.

So :class:`ToldHeading` carries the heading the last told frames had (their median
offset from the odometry's own heading, the odometry's turns with their estimated drift
taken out: :mod:`~app.localization.odometry_bias`) and says whether a candidate, at
least ``MIN_SINCE_S`` after the last told frame, disagrees with it by more than
``BASE_DEG`` plus what the source's drift and wander can do since (``DRIFT_STDS`` of
each, by the source's prior, ``BiasPrior``). The filter then tells such a fix only
after the gate has found it steady for ``TURNED_GAIN_FRAMES`` frames
(:class:`~app.localization.filter.ParticleFilter`; one frame of the run that disagrees
holds the whole run to it): a right place that the told heading happened to disagree
with is told a few seconds later; a turned one has them to fail. The heading is
forgotten wherever the carried one means nothing: the odometry broke off, the person
rode between levels, the evidence swapped a told fix out for another place, or the
belief started over.

What it cannot tell apart: an odometry whose own heading jumps (a compass-fused heading
pulled by steel in a wall, a visual-inertial tracker turning its world frame as it
relocalizes) turns the carried heading with it, and a right fix taken up more than
``MIN_SINCE_S`` later waits its ``TURNED_GAIN_FRAMES``. Measured with
``tools/unmodelled.py``'s 20-degree jump every 20 s: docs/results/unmodelled.md.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from app.localization.odometry_bias import BiasPrior
from app.localization.types import Odometry
from app.maps.geometry import wrap_rad

#: What a right fix's heading may be off by on its own, either one (degrees): a hand's
#: sway and a real detector's latency while turning move a told heading by a few degrees.
BASE_DEG = 10.0
#: The drift's and the wander's allowance, in standard deviations of the source's prior.
DRIFT_STDS = 3.0
#: Told frames whose headings the told heading is the median of (5 s at 5 frames/s).
TOLD_FRAMES = 25
#: The check waits this long (s) after the last told frame: a fix taken up again
#: within seconds of one let go continues it, and the told heading is at its least
#: sure then (an odometry whose own heading jumps 20 degrees, as a compass-fused one
#: pulled by steel does, turns the carried heading with it, and the fix it turned is
#: let go). Measured (the stale maps, seeds 0-59): every fix the check caught came 7.6
#: s or more after the last told frame.
MIN_SINCE_S = 5.0
#: Frames a fix that disagrees must have stayed steady (the gate's streak) before it is
#: told: 5 s at 5 frames/s, as long as the gate waits after an unseen object.
TURNED_GAIN_FRAMES = 25


class ToldHeading:
    """The heading told fixes had, carried by the odometry (module docstring).

    Kept as offsets from the odometry's own heading (its turns added up since the last
    :meth:`reset`; its own sum, not :class:`~app.localization.slide.OdometryCheck`'s,
    which starts again at every swap of the belief, told or not: measured, forgetting
    the told heading at a swap made while nothing was told left the stale office at
    180 deg with 12 confidently-wrong frames instead of 2, seed 3's turned fix coming
    right after one), one per told frame for the last ``TOLD_FRAMES`` of them; the told
    heading is their median carried to now. The median, not the last told frame's: a
    span of told frames ends for a reason, and its last frames are its worst (measured
    with an app that does not say its latency: a fix let go while turning faced 18-20
    degrees off the truth on its last told frame, and the right fix that followed would
    have waited on it).
    """

    def __init__(self, prior: BiasPrior) -> None:
        self.prior = prior
        self.reset()

    def reset(self) -> None:
        """Forget the told headings (nothing to compare with until the next fix)."""
        #: The odometry's turns added up since the reset (rad).
        self._reckoned = 0.0
        #: Per told frame (the last TOLD_FRAMES): its heading less ``_reckoned`` then.
        self._offsets: deque[float] = deque(maxlen=TOLD_FRAMES)
        #: Seconds walked since the last told frame.
        self.since_s = 0.0

    def told(self, heading_rad: float) -> None:
        """A fix facing ``heading_rad`` was told this frame."""
        self._offsets.append(wrap_rad(heading_rad - self._reckoned))
        self.since_s = 0.0

    def moved(self, odometry: Odometry | None, seconds: float) -> None:
        """The person turned by ``odometry`` (None: the odometry broke off) over ``seconds``."""
        if odometry is None:
            self.reset()
            return
        self._reckoned = wrap_rad(self._reckoned + odometry.turn_rad)
        if self._offsets:
            self.since_s += seconds

    @property
    def heading_rad(self) -> float | None:
        """The told heading carried to now (rad; None: none to compare with)."""
        offsets = self._offsets
        if not offsets:
            return None
        ref = offsets[-1]
        around = sorted(wrap_rad(o - ref) for o in offsets)
        k = len(around) // 2
        middle = around[k] if len(around) % 2 else 0.5 * (around[k - 1] + around[k])
        return wrap_rad(ref + middle + self._reckoned)

    def allowance_rad(self) -> float:
        """How far a right fix's heading may now lie from the told one (rad)."""
        t = self.since_s
        drift = self.prior.drift_std_rad_s * t
        wander = math.radians(self.prior.turn_noise_deg) * math.sqrt(t)
        return math.radians(BASE_DEG) + DRIFT_STDS * math.hypot(drift, wander)

    def disagrees(self, heading_rad: float) -> bool:
        """Whether a fix facing ``heading_rad`` disagrees with the told heading (never
        within ``MIN_SINCE_S`` of the last told frame)."""
        told = self.heading_rad
        if told is None or self.since_s < MIN_SINCE_S:
            return False
        return abs(wrap_rad(heading_rad - told)) > self.allowance_rad()

    def checkpoint(self) -> dict[str, Any] | None:
        if not self._offsets:
            return None
        return {"reckoned": self._reckoned, "offsets": list(self._offsets), "since_s": self.since_s}

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: none kept, or a checkpoint from before it)."""
        self.reset()
        if state is not None:
            self._reckoned = float(state["reckoned"])
            self._offsets.extend(float(o) for o in state["offsets"])
            self.since_s = float(state["since_s"])
