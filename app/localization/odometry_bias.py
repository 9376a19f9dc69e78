"""The odometry's own errors, estimated: its scale and its heading drift.

A phone's odometry is not exact up to white noise. Visual-inertial tracking gets the
scale of the world within about 2 % and its heading wanders a few degrees a minute;
pedestrian dead reckoning (steps counted, a step length assumed) is off by up to a tenth
of every distance and drifts up to ten degrees a minute. Those errors do not average out
over frames: they are the same all walk long, so the motion model's noise, which draws
each frame's error afresh, has to be wide enough to cover them, and between sightings
the cloud still walks the wrong length in a slowly turning direction.

This module treats them as what they are, two unknown constants of the session (slowly
varying), and estimates them from the walk itself. While the filter is converged its
estimate is where the person is, pinned by what the camera sees rather than by the
odometry, so the two can be compared:

* **Scale**, over stretches of ``SEGMENT_S`` seconds covering at least ``SEGMENT_M``
  metres (each converged run's first stretch excepted, while the fix settles): the
  odometry's own account of the stretch (chained, its turns corrected by the drift
  estimated) against the estimate's; the length of the estimate's displacement as a
  share of the odometry's is one measurement of the scale (lengths, not a projection:
  a heading a few degrees off turns the odometry's account without changing its
  length), weighed against the estimate's spread at both ends; through a narrow camera
  raised by the share the estimate is measured to fall short by (``NARROW_SHORTFALL``).
* **Drift**, over a whole converged run: the turn the odometry counted beyond the turn
  the estimate made, divided by the run's length, plus the drift that was taken out
  meanwhile. The odometry's own turn noise adds up like a random walk
  (``BiasPrior.turn_noise_deg``) and the estimate's heading is a few degrees off at
  either end (``MIN_HEADING_STD_RAD`` at least: the hand sways the camera), so a few
  seconds say little and a minute says a lot; the run's measurement is recomputed every
  frame against what was known when the run began. An estimate that merely follows the
  corrected odometry (nothing pinning its heading) measures the drift being taken out:
  it confirms it rather than running away with it.

Both refine a Gaussian whose prior is the odometry source's (docs/API.md,
``SessionCreate.odometry``): 2 % and 2 degrees a minute for VIO, 10 % and 10 degrees a
minute for PDR or a source not said. A measurement further than ``OUTLIER_STDS`` from the
estimate so far is left out (a stretch whose estimate jumped), and the estimates stay
within ``CLAMP_STDS`` of the prior, so a converged estimate dragged off by a moved object
cannot teach the odometry a scale it never had.

The filter corrects each frame's odometry with the estimates before anything uses it
(:meth:`OdometryBias.correct`): the motion model, the slide check, the bearing geometry
and the evidence tracker all see the corrected motion. Anything that breaks the link
between estimate and odometry (a lost fix, a frame without odometry, a ride between
floors, a restart) ends the stretch and the run being measured; what they taught stays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from app.localization.config import NARROW_CAMERA_FOV_DEG
from app.localization.types import Odometry
from app.maps.geometry import wrap_rad

#: A stretch measuring the scale lasts this long (s) ...
SEGMENT_S = 10.0
#: ... and counts when it covers at least this much of the odometry's distance (m).
SEGMENT_M = 3.0
#: How far off (m, rad) a converged estimate's position and heading may be at either
#: end of a stretch or run, at least: the position a converged cloud's typical spread,
#: the heading a phone's sway (about +-8 degrees around the walking direction) averaged.
MIN_POSITION_STD_M = 0.15
MIN_HEADING_STD_RAD = math.radians(4.0)
#: The position's at least through a camera narrower than ``NARROW_CAMERA_FOV_DEG``
#: (m): objects ahead say "not farther than here" and little else, so such a fix's
#: place along the walk is known to a few decimetres whatever its cloud's spread.
#: Measured with perfect data (no phone effect, no bearing noise, exact odometry) on the
#: office suite at 66 deg: a pose 0.1 m behind the person loses 0.011 of
#: log-likelihood on average, 0.1 m ahead 0.087, and the cloud sits 0.10 m behind.
#: With tools/odometry_scale.py (100 walks at 66 and 180 deg), one floor for every
#: camera: the learnt scale's mean error 0.0250 at 0.15 m, 0.0232 at 0.3 m (on 50 walks
#: 0.22, 0.4 and 0.5 m gave 0.0283, 0.0290, 0.0313 against 0.0292 and 0.0278); at 270
#: and 360 deg 0.3 m was worse (32 walks: 0.0121 -> 0.0152). Cameras of 180 deg and wider
#: keep 0.15 m (the filter's one line between narrow and wide cameras, though 180 deg
#: gained too): 0.0250 -> 0.0240 on the 100 walks.
NARROW_POSITION_STD_M = 0.3
#: Through a camera narrower than ``NARROW_CAMERA_FOV_DEG`` the converged estimate's
#: displacement falls short of the person's, and each stretch's measurement is raised by
#: this share of the odometry's length. Measured (the scale in use logged frame by frame
#: against the truth, converged frames 3 m of odometry apart, PDR grade): the estimate's
#: displacement over the odometry's is about the scale in use plus 0.56 of (truth -
#: scale in use), less a shortfall of 0.019 on the venue suite through a 66-degree camera
#: (225 pairs, 12 walks), 0.028 and 0.036 on the office suite (without and with 30 %
#: missed), 0.044 on the two-wing floor, 0.002 in the door corridor, and 0.002 on the
#: venue at 180 degrees: the fix is pinned along the walk only now and then, the odometry
#: carries it between, and it gains a little lag each time. A learner that takes a
#: stretch at its word settles where the two terms cancel, a scale short by the shortfall
#: over the 0.56 (3.4 % at the venue, where it learnt 1.037 for a walk asking 1.072 and
#: a fix lagged over a metre). Shares tried (per walk, the learnt scale's mean over its
#: second half against the walk's own; seeds 0-5 of the venue's PDR 66 deg walks and of
#: four phone-suite PDR 66 deg rows): 0.01 brought the mean error 0.0320 -> 0.0304 (the
#: venue's 0.0212 -> 0.0102, and 0.0305 -> 0.0210 on seeds 6-11), 0.02 and 0.03
#: overshot (0.0344, 0.0393: the learnt scales then too long). CHANGELOG: the suites.
NARROW_SHORTFALL = 0.01
#: A converged run measures the drift once it has lasted this long (s).
MIN_RUN_S = 10.0
#: A measurement this many stds from the estimate so far is left out.
OUTLIER_STDS = 4.0
#: The estimates stay within this many of the prior's stds of the prior's mean.
CLAMP_STDS = 3.0
#: The errors may change slowly (a person's step length with their pace, a drift with
#: the temperature): the estimates' variances grow by the prior's over this many seconds.
FORGET_S = 600.0


@dataclass(frozen=True)
class BiasPrior:
    """How far off an odometry source's scale (a share) and heading drift (degrees a
    minute) may be, one standard deviation each; and how much its turn wanders at
    random (degrees, one standard deviation after a second)."""

    scale_std: float
    drift_deg_per_min: float
    turn_noise_deg: float

    @property
    def drift_std_rad_s(self) -> float:
        return math.radians(self.drift_deg_per_min) / 60.0


#: By ``SessionCreate.odometry.source`` (docs/API.md): the figures the API states; the
#: turn noise of a gyro (VIO: about 0.1 degree a frame at 5 frames a second; a PDR
#: heading about 0.4 a frame; a source not said, the motion model's 1 degree a frame).
BIAS_PRIORS: dict[str, BiasPrior] = {
    "vio": BiasPrior(0.02, 2.0, 0.25),
    "pdr": BiasPrior(0.10, 10.0, 1.0),
    "unknown": BiasPrior(0.10, 10.0, 2.2),
}


class OdometryBias:
    """The odometry's scale and heading drift as estimated state (module docstring).

    ``scale``: the factor the odometry's distances are multiplied by to be right (1 for
    an exact one); ``drift_rad_s``: the turn per second the odometry adds that the person
    did not make (subtracted from each frame's turn).
    """

    def __init__(self, prior: BiasPrior, fov_deg: float = 360.0) -> None:
        """``prior``: the odometry source's; ``fov_deg``: the camera's field of view."""
        self.prior = prior
        #: How far off a converged estimate's position may be, at least (m).
        narrow = fov_deg < NARROW_CAMERA_FOV_DEG
        self.min_position_std_m = NARROW_POSITION_STD_M if narrow else MIN_POSITION_STD_M
        #: The share each stretch's measurement is raised by (``NARROW_SHORTFALL``).
        self.shortfall = NARROW_SHORTFALL if narrow else 0.0
        self.reset()

    def reset(self) -> None:
        """Back to the prior (a new session)."""
        self.scale = 1.0
        self.scale_var = self.prior.scale_std**2
        self.drift_rad_s = 0.0
        self.drift_var = self.prior.drift_std_rad_s**2
        #: Measurements taken into the estimates (scale stretches, drift frames).
        self.updates = 0
        self._end_run()

    def _end_run(self) -> None:
        """Forget the run and the stretch being measured (what they taught stays)."""
        #: The drift known when the run began (mean, variance).
        self._before = (self.drift_rad_s, self.drift_var)
        #: The run: seconds, the odometry's turn beyond the estimate's (corrected turns),
        #: the drift taken out meanwhile (rad), the estimate's last heading (None: no run).
        self._run_s = self._excess = self._taken_out = 0.0
        self._last_heading: float | None = None
        self._end_stretch()

    def _end_stretch(self) -> None:
        #: The converged estimate the stretch started at (x, y, theta), or None.
        self._start: tuple[float, float, float] | None = None
        #: The raw odometry since, chained in the start's frame with the corrected turns:
        #: forward and left sums, heading, seconds, distance walked.
        self._dx = self._dy = self._heading = self._seconds = self._walked = 0.0

    def correct(self, odometry: Odometry | None, seconds: float) -> Odometry | None:
        """``odometry`` (lasting ``seconds``) with the scale and drift taken out."""
        if odometry is None:
            return None
        s = self.scale
        return Odometry(
            forward_m=odometry.forward_m * s,
            left_m=odometry.left_m * s,
            turn_rad=odometry.turn_rad - self.drift_rad_s * seconds,
        )

    def observe(
        self,
        raw: Odometry | None,
        seconds: float,
        pose: tuple[float, float, float],
        converged: bool,
        position_std_m: float,
        heading_std_rad: float,
    ) -> None:
        """One frame: its raw odometry (lasting ``seconds``, corrected with the drift
        now) and the filter's estimate after it."""
        self._forget(seconds)
        if raw is None or not converged:
            if self._last_heading is not None:
                self._end_run()
            return
        if self._last_heading is None or self._start is None:
            if self._last_heading is None:
                self._last_heading = pose[2]
            self._start = pose
            return
        taken = self.drift_rad_s * seconds
        turn = raw.turn_rad - taken
        self._run_s += seconds
        self._taken_out += taken
        self._excess += turn - wrap_rad(pose[2] - self._last_heading)
        self._last_heading = pose[2]
        self._measure_drift(heading_std_rad)
        c, s = math.cos(self._heading), math.sin(self._heading)
        self._dx += c * raw.forward_m - s * raw.left_m
        self._dy += s * raw.forward_m + c * raw.left_m
        self._heading += turn
        self._seconds += seconds
        self._walked += math.hypot(raw.forward_m, raw.left_m)
        if self._seconds >= SEGMENT_S:
            # The first stretch of a converged run is not measured: a fix's first seconds
            # are its least sure (it forms where it first fits, then settles), and one
            # such stretch taught a PDR phone's odometry a scale of 0.92 where the truth
            # asked for 1.11 (the phone suite's two-wing floor, 30 % missed, 66 deg); a
            # fix then lagged 1.0-1.1 m along a corridor, converged, for 7 s.
            settled = self._run_s - self._seconds >= SEGMENT_S / 2.0
            if self._walked >= SEGMENT_M and settled:
                self._measure_scale(pose, position_std_m)
            self._end_stretch()
            self._start = pose

    def _measure_drift(self, heading_std_rad: float) -> None:
        """The run so far as one measurement of the drift, against the drift known when
        it began."""
        t = self._run_s
        if t < MIN_RUN_S:
            return
        meas = (self._taken_out + self._excess) / t
        sig_h = max(heading_std_rad, MIN_HEADING_STD_RAD)
        walk_var = math.radians(self.prior.turn_noise_deg) ** 2 * t
        noise = (walk_var + 2.0 * sig_h**2) / t**2
        mean, var = self._before
        if abs(meas - mean) > OUTLIER_STDS * math.sqrt(var + noise):
            return
        gain = var / (var + noise)
        bound = CLAMP_STDS * self.prior.drift_std_rad_s
        self.drift_rad_s = min(max(mean + gain * (meas - mean), -bound), bound)
        self.drift_var = (1.0 - gain) * var
        self.updates += 1

    def _measure_scale(self, pose: tuple[float, float, float], position_std_m: float) -> None:
        """The stretch's measurement of the scale: one Kalman update."""
        assert self._start is not None
        x0, y0, _ = self._start
        x1, y1, _ = pose
        # The lengths of the estimate's displacement and the odometry's: a heading off
        # by a few degrees at the start turns the odometry's account of the stretch, but
        # keeps its length (its projection on the estimate's is short by the cosine, a
        # bias towards too short a scale: measured with tools/odometry_scale.py, the
        # venue's PDR walks through a 66-degree camera learnt it 3.4 % short on average
        # with the projection, 2.8 % with lengths; the rest is the narrow camera's).
        norm_sq = self._dx**2 + self._dy**2
        if norm_sq < SEGMENT_M**2 / 4.0:  # walked back and forth: too short a baseline
            return
        meas = math.hypot(x1 - x0, y1 - y0) / math.sqrt(norm_sq) + self.shortfall
        noise = 2.0 * max(position_std_m, self.min_position_std_m) ** 2 / norm_sq
        if not math.isfinite(meas) or abs(meas - self.scale) > OUTLIER_STDS * math.sqrt(
            self.scale_var + noise
        ):
            return
        gain = self.scale_var / (self.scale_var + noise)
        bound = CLAMP_STDS * self.prior.scale_std
        self.scale = min(max(self.scale + gain * (meas - self.scale), 1.0 - bound), 1.0 + bound)
        self.scale_var = (1.0 - gain) * self.scale_var
        self.updates += 1

    def _forget(self, seconds: float) -> None:
        """The variances grow slowly towards the prior's (the errors may change)."""
        share = max(seconds, 0.0) / FORGET_S
        scale_prior = self.prior.scale_std**2
        self.scale_var = min(self.scale_var + share * scale_prior, scale_prior)
        drift_prior = self.prior.drift_std_rad_s**2
        mean, var = self._before
        self._before = (mean, min(var + share * drift_prior, drift_prior))
        if self._last_heading is None:
            self.drift_var = self._before[1]

    def checkpoint(self) -> dict[str, Any]:
        return {
            "scale": (self.scale, self.scale_var),
            "drift": (self.drift_rad_s, self.drift_var),
            "before": self._before,
            "updates": self.updates,
            "run": (self._run_s, self._excess, self._taken_out, self._last_heading),
            "start": self._start,
            "stretch": (self._dx, self._dy, self._heading, self._seconds, self._walked),
        }

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before this was kept)."""
        self.reset()
        if state is None:
            return
        self.scale, self.scale_var = (float(v) for v in state["scale"])
        self.drift_rad_s, self.drift_var = (float(v) for v in state["drift"])
        mean, var = state["before"]
        self._before = (float(mean), float(var))
        self.updates = int(state["updates"])
        run_s, excess, taken, last = state["run"]
        self._run_s, self._excess, self._taken_out = float(run_s), float(excess), float(taken)
        self._last_heading = None if last is None else float(last)
        start = state["start"]
        self._start = None if start is None else (float(start[0]), float(start[1]), float(start[2]))
        self._dx, self._dy, self._heading, self._seconds, self._walked = (
            float(v) for v in state["stretch"]
        )
