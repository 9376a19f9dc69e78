"""Filter configuration: the paper's model plus each of Bearings' additions as a switch."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

#: A camera narrower than this (degrees) sees its objects in a cone on one side: their
#: steady errors shift a fix together, along the line of sight, instead of cancelling
#: (FilterConfig.likelihood_share, app.localization.dilution's ridge search).
NARROW_CAMERA_FOV_DEG = 180.0
#: A camera at least this wide (degrees) sees objects all around: their bearings pin a
#: place on their own, where a narrower view's leave it loose along the line of sight and
#: lean on the odometry (the separation's rings, the first fix's narrower radius, a gap
#: in the odometry walked through: app.localization.filter, app.localization.gap).
ALL_AROUND_FOV_DEG = 270.0


@dataclass(frozen=True)
class FilterConfig:
    """Every knob of the particle filter.

    Angles given in degrees here (this is a user-facing configuration); the filter
    converts them to radians once.
    """

    #: Number of particles (the maximum when ``adaptive`` is on).
    particles: int = 10_000
    #: Bearing standard deviation for every class without its own entry (degrees).
    bearing_std_deg: float = 2.0
    #: Per-class bearing standard deviations (degrees), e.g. {"table": 4.0}.
    class_bearing_std_deg: dict[str, float] = field(default_factory=dict)
    #: Camera field of view centred on the heading (degrees, 0 < fov <= 360).
    fov_deg: float = 360.0
    #: Direction of the middle of the field of view relative to the body's forward
    #: (degrees, CCW positive): a yawed or off-centre camera (app.localization.camera).
    fov_centre_deg: float = 0.0
    #: Maximum detection range in metres (None: unlimited).
    max_range_m: float | None = None

    # --- Bearings' additions; all off gives the paper's model ------------------------
    #: Only objects in the field of view and in line of sight can explain a detection.
    visibility: bool = True
    #: A detection that nothing visible explains gets a floor instead of zero.
    clutter: bool = True
    #: Probability that a detection is clutter (false positive), used for the floor.
    clutter_prob: float = 0.05
    #: Probability that a detection's class is not its object's (detector confusion). A
    #: confused detection is explained by no object of the class it names, so the model
    #: counts it with the clutter: the floor's share is 1 - (1 - clutter)(1 - class error).
    class_error: float = 0.0
    #: Augmented MCL with sensor resetting (w_slow / w_fast).
    recovery: bool = True
    alpha_slow: float = 0.02
    alpha_fast: float = 0.3
    #: Alternative places kept alive and weighed by their evidence over the walk, so
    #: that ``converged`` means no other place explains the walk nearly as well
    #: (:mod:`~app.localization.evidence`).
    evidence: bool = True
    #: Share of the alternatives' summed log-likelihood ratios that counts when their
    #: probability is taken (gating ``converged``): 1 for a detector whose errors are
    #: independent from frame to frame (the simulator's); less for a real one, whose
    #: errors repeat (a box's bias, an object moved since the map was drawn), so that
    #: many frames of the same small misfit do not add up to certainty. The service
    #: uses ``REAL_DETECTOR_TEMPER``.
    evidence_temper: float = 1.0
    #: A steady bearing error (degrees) the check of how well the estimate explains the
    #: detections allows for besides the noise (a box's centre is not the object's): 0 for
    #: the simulator's detector; the service uses ``REAL_DETECTOR_FIT_BIAS_DEG``.
    fit_bias_deg: float = 0.0
    #: A steady bearing error (degrees) the particles' likelihood allows for through a
    #: narrow camera: each class's log-likelihood counts with std^2 / (std^2 + bias^2)
    #: of itself (:meth:`likelihood_share`), as a Gaussian widened by the bias would
    #: weigh the same residuals, while what counts as explained (the clutter floor's
    #: crossing) stays where the noise puts it. A real detector's box centre and a map's
    #: drawing put each object's bearing a few degrees off for many frames; weighed at
    #: the bare noise, a pose a metre away that such a bias favours outweighs the true
    #: one by orders of magnitude within a second and the true pose's particles die
    #: (measured through a 66-degree camera on the phone suite: a first fix 1.0 m off).
    #: The alternatives' evidence keeps counting at ``evidence_temper`` of the bare
    #: noise's (:attr:`evidence_weight`), so places far apart are told apart as before.
    #: 0 for the simulator; the service: ``REAL_DETECTOR_LIKELIHOOD_BIAS_DEG``.
    likelihood_bias_deg: float = 0.0
    #: How far (std, m) a movable object may stand from where the map drew it: its
    #: bearing's variance grows by (spread / distance)^2, so a chair or a table seen up
    #: close pins the pose less (app.localization.sensor.spread_match). 0 (off) in every
    #: suite and in the service. Measured on the phone suite (610 walks, same machine,
    #: against 0): at 5 frames/s 0.3 m took the confidently-wrong frames from 22 to 0 but
    #: 0.2 m to 77, and at 10 frames/s 0.3 m took them from 151 to 204 (availability
    #: 0.890 -> 0.886 and 0.894 -> 0.885): the rare wrong fixes move with it, they do not
    #: go, so it is not switched on; a moved table seen close does pull less (tests).
    object_spread_m: float = 0.0
    #: A frame whose detections all disagree with the estimate is not taken for a kidnap
    #: when turning the estimate's heading by up to this much (degrees) explains them: a
    #: common shift of every bearing is a camera's latency while turning, or the hand's
    #: sway, not another place. 0 for the simulator; the service: REAL_DETECTOR_SLACK_DEG.
    heading_slack_deg: float = 0.0
    #: Adaptive particle count: all ``particles`` while lost, KLD-sampling (at least
    #: ``min_particles``) once converged. 2,000 rather than fewer: on the paper's walks
    #: 500 cost 1.0 mm of mean error against a fixed 10,000, 2,000 cost none measurable
    #: (benchmarks/README.md).
    adaptive: bool = True
    min_particles: int = 2_000

    # --- Motion model (odometry, Probabilistic Robotics sample_motion_odometry) ---------
    #: Translation noise as a fraction of the distance moved.
    trans_noise_frac: float = 0.1
    #: Rotation noise as a fraction of the turn.
    rot_noise_frac: float = 0.1
    #: Noise floors per frame, so a standing person still diffuses a little.
    trans_noise_floor_m: float = 0.02
    rot_noise_floor_deg: float = 1.0
    #: Estimate the odometry's scale and heading drift and take them out of every frame's
    #: odometry (:mod:`~app.localization.odometry_bias`), with the prior of this source
    #: ("vio", "pdr" or "unknown"; docs/API.md, ``SessionCreate.odometry``). None: the
    #: odometry is taken as it comes (the paper's and the simulator's suites). The
    #: service always estimates them.
    odometry_source: str | None = None

    #: Resample when the effective sample size falls below this fraction of N.
    resample_threshold: float = 0.5

    @property
    def floor_prob(self) -> float:
        """Probability that a detection is explained by no object of its class."""
        return 1.0 - (1.0 - self.clutter_prob) * (1.0 - self.class_error)

    def bearing_std_rad(self, cls: str) -> float:
        """The bearing standard deviation for one class, in radians."""
        return float(np.radians(self.class_bearing_std_deg.get(cls, self.bearing_std_deg)))

    def likelihood_share(self, cls: str) -> float:
        """The share of one class's log-likelihood that counts: 1 without a bias, and
        for a camera of ``NARROW_CAMERA_FOV_DEG`` or wider (objects on every side: their
        biases pull a fix every way and cancel, and the bare noise weighs the poses
        right; measured, a share there let a stale map's moved object drag unconverged
        clouds a metre off and gain there: 8 confidently-wrong frames on the phone
        suite's stale office, 0 without)."""
        if self.fov_deg >= NARROW_CAMERA_FOV_DEG:
            return 1.0
        std = self.class_bearing_std_deg.get(cls, self.bearing_std_deg)
        return 1.0 / (1.0 + (self.likelihood_bias_deg / std) ** 2)

    @property
    def evidence_weight(self) -> float:
        """The share of the alternatives' summed log-likelihood ratios (each made of
        the likelihood's shares, :meth:`likelihood_share`) that counts: ``evidence_temper``
        of what the whole ratios would be, at most all of them."""
        return min(1.0, self.evidence_temper / self.likelihood_share(""))

    @classmethod
    def paper(cls, **overrides: Any) -> FilterConfig:
        """The paper's model only: no visibility, no clutter floor, no recovery."""
        base = cls(visibility=False, clutter=False, recovery=False, adaptive=False, evidence=False)
        return replace(base, **overrides)


#: FilterConfig.evidence_temper for a real phone's detector (the service's; measured on
#: the phone suite, docs/results/phone.md).
REAL_DETECTOR_TEMPER = 0.25
#: A real detector's steady bearing error per object (degrees): about a third of the
#: half-width of a 1 m wide object 2-3 m away, or an object drawn 0.2 m off seen from 4 m.
#: The protection radius allows for it (app.localization.dilution), and so does the
#: service's fit check (FilterConfig.fit_bias_deg).
STEADY_BIAS_DEG = 3.0
REAL_DETECTOR_FIT_BIAS_DEG = STEADY_BIAS_DEG
#: FilterConfig.likelihood_bias_deg for a real phone's detector: the same steady error.
REAL_DETECTOR_LIKELIHOOD_BIAS_DEG = STEADY_BIAS_DEG
#: FilterConfig.heading_slack_deg for a real phone's detector.
REAL_DETECTOR_SLACK_DEG = 20.0

#: Motion noise by odometry source (docs/API.md, ``SessionCreate.odometry``): the share of
#: each motion (translation, turn) the noise may reach. VIO and an unknown source keep
#: the defaults every suite was measured with; PDR's coarser steps get more.
ODOMETRY_NOISE: dict[str, tuple[float, float]] = {
    "vio": (0.1, 0.1),
    "pdr": (0.15, 0.15),
    "unknown": (0.1, 0.1),
}
