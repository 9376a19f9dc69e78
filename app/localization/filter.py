"""The particle filter: Monte Carlo localization on a semantic map (paper, eq. 1).

Each step predicts with odometry (:mod:`~app.localization.motion`), corrects with the
bearing-only semantic sensor model (:mod:`~app.localization.sensor`), summarizes the
weighted belief (:mod:`~app.localization.estimate`), then resamples when the effective
sample size drops (:mod:`~app.localization.resampling`), optionally injecting particles
drawn from the observation (:mod:`~app.localization.recovery`). Particles are a
structure of arrays (x, y, theta, log-weight); nothing loops over particles in Python.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.compass import CompassReading, compass_log_likelihood
from app.localization.config import ALL_AROUND_FOV_DEG, FilterConfig
from app.localization.continuation import Continuation, doubt_frames
from app.localization.convergence import (
    GAIN_PROTECTION_M,
    ConvergenceGate,
    FitQuality,
    cluster_radius,
    protection_radius,
    widened_radius,
)
from app.localization.dilution import JUMP_M as GEOMETRY_JUMP_M
from app.localization.dilution import BearingGeometry
from app.localization.dilution import warm_up as warm_up_dilution
from app.localization.estimate import (
    estimate_pose,
    only_alike_levels,
    only_twins,
    with_alternatives,
    with_twins,
)
from app.localization.evidence import EvidenceTracker
from app.localization.fastmath import PAIRWISE_BLOCK, hypot, pairwise_sum
from app.localization.floors import (
    ARRIVAL_SHARE,
    LEVEL_SURE_SHARE,
    AltitudeReading,
    FloorTracker,
)
from app.localization.gap import OdometryGap
from app.localization.kld import kld_sample_size
from app.localization.latency import (
    DEFAULT_FRAME_S,
    CaptureClock,
    LatencyEstimate,
    moved_forward,
)
from app.localization.models import (
    FOV_EDGE_STDS,
    BearingSensorModel,
    MotionModel,
    OdometryMotionModel,
    SensorModel,
)
from app.localization.motion import implausible
from app.localization.odometry_bias import BIAS_PRIORS, OdometryBias
from app.localization.pacing import Pacing
from app.localization.recovery import AugmentedMCL
from app.localization.resampling import (
    effective_sample_size,
    log_sum_exp,
    normalized_weights,
    systematic_resample,
    weights_and_log_sum_exp,
)
from app.localization.search import PATTERN
from app.localization.sensor import (
    Observation,
    match_detections,
    normalized_residuals,
    observation_columns,
    prepare_observation,
)
from app.localization.slide import SLIP_SCALE_STDS, OdometryCheck
from app.localization.told_heading import TURNED_GAIN_FRAMES, ToldHeading
from app.localization.types import Detection, Estimate, InitialPose, Odometry
from app.localization.unseen import UnseenObjects
from app.localization.walked import WANDER_SHARE, WalkedPath
from app.maps.geometry import wrap_angle, wrap_rad
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared
from app.maps.symmetry import alike_levels, rotational_symmetries, twin_pose
from app.state import from_plain

#: Share of a global start's particles drawn from the first observation.
SEED_SHARE = 0.9
#: Most particles a checkpoint keeps (a converged filter runs on 2,000: kept whole).
CHECKPOINT_PARTICLES = 2_000
#: Weight of the newest frame in the smoothed fit that gates ``converged`` ...
FIT_SMOOTHING = 0.3
#: ... when it brings at least this much detection score (a frame with less moves the
#: smoothed fit proportionally less: a lone weak detection, often a false one, where the
#: camera sees little else, says little either way).
FIT_FULL_SCORE = 2.0
#: Stds of bearing noise added to each side of the field of view when checking the fit:
#: an object just outside the estimate's view may be just inside the camera's.
FIT_FOV_MARGIN_STDS = 3.0
#: The fit is measured while the heaviest cluster is at most this wide (m).
FIT_MAX_SPREAD_M = 0.7
#: Without a clutter floor, residuals beyond this many stds count as unexplained.
PAPER_RESIDUAL_CUTOFF = 3.0
#: Score-weighted mean of the clipped squared residuals that makes one frame bad ...
BAD_FRAME_FIT = 8.0
#: ... and bad frames with detections in a row that veto converged.
BAD_FRAMES_IN_A_ROW = 2
#: Steps of the heading slack a bad frame is re-checked with (degrees).
SLACK_STEP_DEG = 2.0
#: Where a ride between levels lets the person off, as a known start for the evidence
#: tracker's alternatives: the cloud rode along (an escalator or a flight of stairs is
#: a metre or so wide, a lift car one or two across), its heading carried by the
#: odometry. Three stds (2.25 m) keep every place the ride could have ended at; the top
#: of the parallel escalator 3.3 m away (measured: a look-alike holding 0.14-0.32 of
#: the probability for 3 s after the ride) is excluded.
RIDE_START_STD_M = 0.75
RIDE_START_STD_RAD = math.radians(45.0)
#: After a ride the belief was pinned to one connector for without a fix
#: (FloorTracker.pinned_stop), the exit's position std for the evidence tracker's
#: alternatives, a share of the radius of the circle holding the stop: one std reaches
#: its edge. Measured on the venue suite's 66-degree cameras, seeds 0-19, against no
#: prior: VIO availability per level 0.38 / 0.88 / 0.90 -> 0.43 / 0.91 / 0.90, PDR
#: 0.40 / 0.78 / 0.78 -> 0.42 / 0.80 / 0.82; half the radius gained more at VIO but
#: lost at PDR (the Second Floor 0.69 on seeds 10-19).
PINNED_START_STDS = 1.0
#: Alternatives are searched for while the heaviest cluster is at most this wide (m).
SEARCH_MAX_SPREAD_M = 0.5
#: An unreported object in clear view of a converged estimate is taken for gone from
#: the world (a stale map) when a global search at most this many frames ago found no
#: other place (``ParticleFilter._place_is_unique``): the evidence tracker searches
#: every 25 frames while it finds nothing.
UNIQUE_SEARCH_FRAMES = 25
#: ... and when the fix is known well enough to tell an object moved since the map was
#: drawn from its own error: its protection radius at most this (m; a metre, what the
#: integrity suites call wrong) ...
FORGIVE_PROTECTION_M = 1.0
#: ... and it is not being dragged: at most this far (m) off where the odometry carries
#: it (half of the gate's ``hold_slide_m``). Measured on the phone suite's stale office
#: map, a fix dragged 0.8 m off took a present door for gone and went on 1.3-1.8 m off.
FORGIVE_SLIDE_M = 0.25
#: ... and, before any fix is told, only once the candidate has stayed put for this many
#: frames (no jump farther than the odometry's move and the gate's ``unseen_place_m``):
#: a place the estimate has just jumped to has had no time to be found wanting.
#: Measured on the phone suite's stale office (360 deg camera, seed 20; Intel Xeon): a
#: right place was contradicted by an object taken away since the map was drawn, the
#: estimate jumped 7 m to a look-alike place, and 8 frames later, the search having
#: dropped the truth, the candidate there forgave the object in its view that was not
#: seen (the person was elsewhere) and was told 4.8 m off for 18 frames. The seven
#: stale-map rows over 30 seeds: 44 -> 26 confidently-wrong frames with 10, availability
#: 0.6951 -> 0.6941; seeds 30-59, 48 -> 48 and 0.7017 -> 0.7013. The cost: a first fix
#: after a global start waits until the cloud has stayed put 2 s where a detector's
#: misses flag an object (the paper office at 360 deg: first fix 16 -> 20 frames, median).
#: 15 and 25 frames caught more of seeds 0-29 (15 frames each) but nothing more of
#: 30-59, and cost the symmetric paper office up to 0.05 of its availability.
SETTLED_CANDIDATE_FRAMES = 10
#: Frames with detections that contradict a start given (each failing the fit by
#: itself) before its first fix, after which the start is taken for wrong and the
#: filter starts again from no knowledge. (An object in clear view never reported is no
#: such sign: on a stale map a start given right goes on missing the objects taken
#: away, and counting it gave up right starts there; measured with
#: tools/wrong_start.py, the same starts given wrong are caught without it.)
START_CONTRADICTED_FRAMES = 5
#: A known start tells a map's twins apart (app.maps.symmetry) when each twin lies more
#: than this many of the start's stds from it, in position or in heading.
TWIN_START_STDS = 3.0
#: Frames in a row a first fix's radius must be narrow (GAIN_PROTECTION_M) before it is
#: told. Through a 66-degree camera the bearings' geometry swings the radius between 1.5
#: and 6 m from one frame to the next: measured on the phone suite's stale office, fixes
#: 7 m off (a look-alike place a moved object favoured) were told on the one frame it
#: dipped to 1.44-1.48 m, and held at 5-6 m from the next. Phone suite, 97 -> 11
#: confidently-wrong frames with 2, availability 0.88 as before; with 3, 25 frames and
#: 66-degree cameras 0.05-0.08 less available.
NARROW_FRAMES = 2
#: ... and only if no one movable object pulls it farther than this (m) or than its
#: radius: the place that best explains the tracker's window, found again with each such
#: object left out in turn, moves at most that far (solution separation,
#: :meth:`~app.localization.evidence.EvidenceTracker.separation_m`). Measured on the phone
#: suite's stale office through a 180-degree camera: a fix told 1.38 m off (radius
#: 0.76 m) while a table moved since the map was drawn pulled it by 1.08 m; of 11 gains
#: traced there within 0.5 m of the truth, 9 were pulled by 0.0-0.42 m and 2 by about
#: 1.0 m, within their radius of 1.2-1.4 m. Phone suite at 5 frames/s: confidently wrong 32 -> 22,
#: availability 0.890 as before. Against 0.5 m alone, 66-degree cameras (few objects in
#: view, each pulling far) were up to 0.06 less available. Every movable object of one
#: class is also left out together (the separation's groups): two plants moved the same
#: way held a fix 1.2 m off (radius 0.77 m) that neither pulled far alone.
GAIN_SEPARATION_M = 0.5
#: ... nor, however wide its radius, farther than this (m): a fix that one object moved
#: since the map was drawn would leave more than a metre off is not yet a place to tell
#: (the integrity suite calls a fix a metre off confidently wrong). Traced on the phone
#: suite's stale office through a 180-degree camera (VIO grade, seed 1): a first fix
#: told 1.19 m off with a radius of 1.32 m while a moved plant pulled it 1.09 m. Same
#: machine, against the radius alone: phone suite confidently wrong 3 -> 1 (seeds 0-9),
#: 38 -> 38 (10-29, every row but the office's single effects), at 10 frames/s the
#: stale-map rows 55 -> 29 (the office's 66-degree row 30 -> 0, its 180-degree one
#: 5 -> 9 on a course changed later in a walk); availability 0.8963 -> 0.8955 and
#: 0.8543 -> 0.8534; the stale-map rows on seeds 30-59 47 -> 47 (0.7030 -> 0.6997);
#: integrity suite 3 -> 3; venue suite unchanged.
GAIN_SEPARATION_MAX_M = 1.0
#: A held fix let go for sliding off the odometry blames a movable object whose absence
#: moves the place the tracker's window fits best this far (m) back towards where the
#: odometry carried the fix: see ``_blame_the_slide``.
SLIDE_BLAME_M = 0.45
#: ... when the place let go lies at most this far (m) from where the odometry carried
#: the fix: a moved object drags a fix by about its move (1-1.5 m on the phone suite's
#: stale maps), a jump takes it anywhere.
SLIDE_BLAME_SPAN_M = 2.0


def separation_allows_gain(pull_m: float, protection_m: float) -> bool:
    """Whether a first fix pulled ``pull_m`` by one movable object left out (solution
    separation) may be told with protection radius ``protection_m``: the pull is within
    :data:`GAIN_SEPARATION_M`, or within the radius up to :data:`GAIN_SEPARATION_MAX_M`."""
    return pull_m <= max(GAIN_SEPARATION_M, min(protection_m, GAIN_SEPARATION_MAX_M))


#: Cameras at least this wide (deg) seek the separation's places from rings around the
#: fix as well (``Separation.far_m``): a search from the fix alone can stop in the fix's
#: own local optimum. Measured on the phone suite's stale office (360 deg camera, VIO
#: grade; Intel Xeon, LLVM ``rocketlake``): a fix told 0.96 m off, then held 1.0-1.13 m
#: off for 3 s, where one plant had moved 1.2 m since the map was drawn and another,
#: taken away, had a new one beside it; with either left out the search from the fix
#: stayed within 0.05 m, while the truth, 1.2 m away, explained the rest of the window
#: better. With objects all around, the rest pin a place down, and a better one a metre
#: away is a moved object's mark; through a narrower camera the few objects left fit
#: places a metre or two along the view about as well (66-degree cameras lost 0.03-0.09
#: of availability with rings, 180-degree ones up to 0.03, for 12 -> 10 wrong frames).
#: Phone suite, same machine: confidently wrong 42 -> 27 of 231,363 frames (that row
#: 18 -> 3), availability 0.8927 -> 0.8926; tools/unmodelled.py 307 -> 206, but its VIO
#: 360 deg walks without timestamps 0.750 -> 0.691 available. The rings' places held to
#: a metre instead of GAIN_SEPARATION_M caught 8 of the 15 (0.75 m: the same as 0.5).
SEPARATION_RINGS_FOV_DEG = ALL_AROUND_FOV_DEG
#: A camera at least SEPARATION_RINGS_FOV_DEG wide sees objects all around and pins a
#: right place to well under a metre: its first fix is told only with a radius of at
#: most this (m), not GAIN_PROTECTION_M. Measured on the phone suite (seeds 0-9, Intel
#: Xeon): of 200 fixes told through 270 and 360 deg cameras, 5 had a radius over 1 m,
#: 0.05-0.72 m off (the other 195: median 0.09 m, 177 under 0.2 m); one of them, on the
#: stale office, drifted on to 1.09 m.
WIDE_VIEW_GAIN_PROTECTION_M = 1.0
#: How much farther than the odometry's path a person may have walked since the last fix
#: told (PDR-grade step lengths are off by up to 10 %; dropped frames are carried by the
#: next frame's odometry).
WALK_BOUND_SCALE = 1.25
#: A fix held this long (s) gets no injected particles (see ``_step``); a younger one
#: does, as a lost belief does.
SETTLED_FIX_S = 10.0


class ParticleFilter:
    """Monte Carlo localization of one person on one map.

    Args:
        semantic_map: the annotated floor map.
        config: model switches and noise; :meth:`FilterConfig.paper` for the paper's model.
        rng: the filter's own random generator (same seed, same result).
        initial_pose: a known start, or None for global localization (uniform over the
            free space, any heading).
        state: a :meth:`checkpoint` to go on from instead (``initial_pose`` is ignored).
        sensor_model, motion_model: the models the filter weighs and moves its particles
            with (:mod:`~app.localization.models`); by default the bearing-only semantic
            sensor model and the odometry motion model of ``config``.
    """

    def __init__(
        self,
        semantic_map: SemanticMap,
        config: FilterConfig | None = None,
        *,
        rng: np.random.Generator,
        initial_pose: InitialPose | None = None,
        state: Mapping[str, Any] | None = None,
        sensor_model: SensorModel | None = None,
        motion_model: MotionModel | None = None,
    ) -> None:
        self.map = ensure_prepared(semantic_map)  # its grids, built now if need be
        self.config = config or FilterConfig()
        self.rng = rng
        self._vis = semantic_map.visibility if self.config.visibility else None
        edge = FOV_EDGE_STDS * self.config.bearing_std_deg if self.config.fov_deg < 360.0 else 0.0
        self.sensor = sensor_model or BearingSensorModel(
            semantic_map, self.config, self._vis, fov_margin_deg=edge
        )
        #: The evidence tracker's sensor model: the filter's, with the field of view's
        #: hard edge (models.FOV_EDGE_STDS).
        self._tracker_sensor = (
            self.sensor
            if sensor_model is not None or edge == 0.0
            else BearingSensorModel(semantic_map, self.config, self._vis)
        )
        self.motion = motion_model or OdometryMotionModel(semantic_map, self.config)
        self._recovery = AugmentedMCL(self.config.alpha_slow, self.config.alpha_fast)
        self._gate = ConvergenceGate()
        margin = 2.0 * FIT_FOV_MARGIN_STDS * self.config.bearing_std_deg
        self._fit_config = replace(self.config, fov_deg=min(360.0, self.config.fov_deg + margin))
        #: Residuals in the noise's stds, rescaled to the noise plus a real detector's
        #: steady bias (``config.fit_bias_deg``) when the fit is judged.
        std = self.config.bearing_std_deg
        self._fit_scale = std / float(np.hypot(std, self.config.fit_bias_deg))
        #: Alternative places and their evidence (None with ``config.evidence`` off).
        self.evidence = (
            EvidenceTracker(self._tracker_sensor, self.motion, rng)
            if self.config.evidence
            else None
        )
        #: Objects in clear view that the camera keeps not reporting (gates converged).
        self.unseen = (
            UnseenObjects(semantic_map, self.config)
            if self.config.evidence and self.config.visibility
            else None
        )
        #: Level changes (maps with several levels only, app.localization.floors).
        self.floors = FloorTracker(semantic_map) if len(semantic_map.layout.levels) > 1 else None
        if self.floors is not None and self.evidence is not None:
            self.evidence.place_allowed = self.floors.place_allowed
        self.last_observation: Observation | None = None
        #: Frames without odometry: walked through when short (:mod:`~app.localization.gap`).
        self.gap = OdometryGap(self.config.fov_deg)
        #: Motion between detection captures (:mod:`~app.localization.latency`).
        self.capture = CaptureClock()
        #: The detections' age of an app that does not say it, learnt from turns.
        self.latency = LatencyEstimate()
        #: The same for an app that sends no timestamps, learnt in frames: each taken to
        #: last ``DEFAULT_FRAME_S`` (as the capture clock takes an untimed frame).
        self.latency_untimed = LatencyEstimate()
        #: What systematic bearing errors can do to the fix (:mod:`~app.localization.dilution`).
        self.geometry = BearingGeometry(semantic_map, self.config)
        #: The odometry's scale and heading drift (:mod:`~app.localization.odometry_bias`).
        source = self.config.odometry_source
        self.odometry_bias = (
            None if source is None else OdometryBias(BIAS_PRIORS[source], self.config.fov_deg)
        )
        #: Whether the estimate keeps to the odometry (:mod:`~app.localization.slide`).
        self.odometry_check = OdometryCheck(
            self.config.trans_noise_frac,
            self.config.heading_slack_deg,
            None if source is None else SLIP_SCALE_STDS * BIAS_PRIORS[source].scale_std,
        )
        # (A source not said is held to the widest prior.)
        said = source or "unknown"
        #: The heading the last told fixes had, carried by the odometry
        #: (:mod:`~app.localization.told_heading`).
        self.told_heading = ToldHeading(BIAS_PRIORS[said])
        #: The walk the odometry recorded, to test a place before it is told
        #: (:mod:`~app.localization.walked`).
        self.walked = WalkedPath(WANDER_SHARE[said], SLIP_SCALE_STDS * BIAS_PRIORS[said].scale_std)
        #: The fixes a gain would continue, not held to GAIN_PROTECTION_M (_step).
        self.continuation = Continuation()
        if state is None:
            self.reset(initial_pose)
        else:  # from a checkpoint (:meth:`checkpoint`): no cloud to draw first
            self.restore(state)

    # ----------------------------------------------------------------- state
    def reset(self, initial_pose: InitialPose | None = None) -> None:
        """Start again: around ``initial_pose`` or, when None, anywhere."""
        n = self.config.particles
        if initial_pose is None:
            self.x, self.y, self.theta = self._anywhere(n)
        else:
            self.x = self.rng.normal(initial_pose.x, initial_pose.std_xy_m, n)
            self.y = self.rng.normal(initial_pose.y, initial_pose.std_xy_m, n)
            self.theta = wrap_angle(
                self.rng.normal(initial_pose.theta_rad, initial_pose.std_theta_rad, n)
            )
        self.log_w = np.zeros(n, dtype=np.float64)
        self.capture.reset()
        self.latency.reset()
        self.latency_untimed.reset()
        self.geometry.reset()
        self.odometry_check.reset()
        self.told_heading.reset()
        self.walked.reset()
        if self.odometry_bias is not None:
            self.odometry_bias.reset()
        if initial_pose is not None:
            start = (initial_pose.x, initial_pose.y, initial_pose.theta_rad)
            self.geometry.set_prior(start, initial_pose.std_xy_m)
        # A global start with recovery on seeds its cloud from the first evidence.
        self._seed_from_observation = initial_pose is None and self.config.recovery
        # ... and on a map with several levels weighs a draw as dense as a one-level
        # map's first (see _wide_start).
        self._wide_first = initial_pose is None and self.floors is not None
        self._recovery.reset()
        self._gate.reset()
        self._search_at_base = False
        if self.evidence is not None:
            self.evidence.reset()
            self.evidence.set_prior(initial_pose)
        if self.unseen is not None:
            self.unseen.reset()
        if self.floors is not None:
            self.floors.reset()
        #: How well the estimate explains the detections (smoothed); None before any.
        self.quality: FitQuality | None = None
        self.gap.reset()
        #: Whether the last frame's odometry was refused as faster than a person on foot
        #: (:func:`~app.localization.motion.implausible`: its translation refused, its
        #: turn kept).
        self.odometry_refused = False
        #: Whether the last frame gave up the start given (START_CONTRADICTED_FRAMES).
        self.start_given_up = False
        #: Frames with detections in a row that were bad on their own (see _update_fit).
        self._bad_run = 0
        #: The last frame's estimate had nothing in clear view and explained nothing
        #: (see _update_fit): its detections are clutter wherever the person is.
        self._sees_nothing = False
        #: A fix held in a connector's stop (a lift car) as its view went blind, still
        #: seeing nothing there: detections are not weighed (see _step).
        self._blind_hold = False
        #: Frames in a row a gain was tested with a narrow radius (NARROW_FRAMES).
        self._narrow_frames = 0
        #: Whether the gate's run towards a gain has faced otherwise than the last told
        #: fixes (app.localization.told_heading).
        self._turned_run = False
        #: Whether a fix has been told since the filter last started from what it was
        #: given (see _place_is_unique).
        self._told_since_start = False
        #: Frames in a row the estimate has not jumped (see SETTLED_CANDIDATE_FRAMES).
        self._settled_frames = 0
        #: The last fix told (plane x, y) and a radius that holds the person since: its
        #: protection radius plus the walk since, WALK_BOUND_SCALE times what the
        #: odometry says (None: none on this level, or a frame without odometry since).
        #: A level change the barometer shows far from every connector within it is
        #: the barometer's reference moving (FloorTracker.apply), also once the fix was
        #: let go.
        self._last_fix: tuple[float, float, float] | None = None
        self.frames_without_evidence = 0
        #: How often every particle became impossible and the filter started again.
        self.restarts = 0
        self.steps = 0
        #: Frames answered by dead reckoning since the last step (pacing.WEIGH_PERIOD_S).
        self._pacing = Pacing()
        #: Whether the convergence gate held a fix when the last ride between levels began.
        self._located_at_ride = False
        #: Until the next fix, a gain waiting for the evidence search asks for it at the
        #: base interval (see _weigh_alternatives): since a ride (_rode; without a
        #: barometer, since the view settled the floor in a connector's stop), or since
        #: a moved object was blamed for a slide (_blame_the_slide).
        self._search_at_base = False
        #: Seconds the current fix has been held (0: none held).
        self._held_s = 0.0
        self.continuation.reset(known_start=initial_pose is not None)
        #: Frames that contradicted the start given so far (START_CONTRADICTED_FRAMES),
        #: and whether this frame's fit, taken by itself, did (_update_fit).
        self._start_contradicted = 0
        self._frame_misfit = False
        #: Whether a twin of the person's place (app.maps.symmetry) is as likely as the
        #: place itself: from a start that does not tell them apart, until a compass does.
        self._twins_possible = self._start_has_twins(initial_pose)
        #: The last step's fix was kept from being told by the map's twins alone.
        self.twins_undecided = False
        #: The last step's belief was one place on floors that look alike, and nothing
        #: else (app.maps.symmetry.alike_levels).
        self.levels_undecided = False
        self.estimate: Estimate = estimate_pose(self.x, self.y, self.theta, self.weights)

    @functools.cached_property
    def _twins(self) -> tuple[tuple[float, float, float], ...]:
        """The map's rotations onto itself (:func:`~app.maps.symmetry.rotational_symmetries`)."""
        return rotational_symmetries(self.map)

    @functools.cached_property
    def _alike_levels(self) -> tuple[tuple[int, ...], ...]:
        """The map's levels that look the same (:func:`~app.maps.symmetry.alike_levels`)."""
        return alike_levels(self.map)

    def _start_has_twins(self, start: InitialPose | None) -> bool:
        """Whether a start leaves the map's twins (if any) as likely as the place itself:
        no start at all, or one with a twin (the start turned with the map) within
        ``TWIN_START_STDS`` of its stds in position and in heading."""
        if not self._twins:
            return False
        if start is None:
            return True
        for twin in self._twins:
            tx, ty, _ = twin_pose(start.x, start.y, start.theta_rad, twin, self.map.layout)
            angle = twin[2]
            far = math.hypot(tx - start.x, ty - start.y) > TWIN_START_STDS * start.std_xy_m
            turned = abs(wrap_rad(angle)) > TWIN_START_STDS * start.std_theta_rad
            if not (far or turned):
                return True
        return False

    @functools.cached_property
    def _map_span_m(self) -> float:
        """The map's diagonal (m): the largest protection radius worth stating."""
        x0, y0, x1, y1 = self.map.bounds
        return float(np.hypot(x1 - x0, y1 - y0))

    @property
    def gate(self) -> ConvergenceGate:
        """The convergence gate, to read why a fix was let go or not given
        (``lost_because``, ``not_gained_because``); the filter alone drives it."""
        return self._gate

    @property
    def n(self) -> int:
        """Current number of particles."""
        return int(self.x.shape[0])

    @property
    def weights(self) -> NDArray[np.float64]:
        """Normalized particle weights, shape (N,)."""
        return normalized_weights(self.log_w)

    # ----------------------------------------------------------------- steps
    def predict(self, odometry: Odometry | None, steps: int = 1) -> None:
        """Move every particle by the noisy odometry (adding up ``steps`` frames' motion);
        impossible moves lose their weight."""
        x0, y0 = self.x, self.y
        self.x, self.y, self.theta = self.motion.sample(
            self.x, self.y, self.theta, odometry, self.rng, steps=steps
        )
        self.log_w, possible = self.motion.weigh_moves(x0, y0, self.x, self.y, self.log_w)
        if not possible:
            # Every hypothesis walked through a wall or off the map: the belief is
            # wrong everywhere. Start again from no knowledge rather than keep ghosts.
            self._restart_global()

    def _give_up_the_start(self) -> bool:
        """Whether the start given (``initial_pose``, not told yet: the continuation's
        ``known_start``) is given up on this frame: ``START_CONTRADICTED_FRAMES`` frames
        have now failed the fit by themselves (``_frame_misfit``: the smoothed fit is no
        such sign, one false box on the first frame keeps it past the threshold for a
        second). The filter then starts again from no knowledge."""
        self._start_contradicted += self._frame_misfit
        if self._start_contradicted < START_CONTRADICTED_FRAMES:
            return False
        self._restart_global()
        self.start_given_up = True
        return True

    def _anywhere(self, n: int) -> tuple[NDArray[np.float64], ...]:
        """``n`` poses uniform over the free space with uniform headings."""
        pts = self.map.free_space.sample(n, self.rng)
        return pts[:, 0].copy(), pts[:, 1].copy(), self.rng.uniform(-np.pi, np.pi, n)

    def _restart_global(self, after_ride: bool = False) -> None:
        """Start again from no knowledge; ``after_ride``: a level change the belief
        could not make, whose rider stands where a connector let them off
        (:meth:`FloorTracker.arrivals`, a share ``ARRIVAL_SHARE`` of the new cloud)."""
        n = self.config.particles
        self.x, self.y, self.theta = self._anywhere(n)
        if after_ride and self.floors is not None:
            ax, ay = self.floors.arrivals(int(ARRIVAL_SHARE * n), self.rng)
            k = ax.shape[0]
            self.x[:k], self.y[:k] = ax, ay
        self.log_w = np.zeros(n, dtype=np.float64)
        self._seed_from_observation = self.config.recovery
        self._wide_first = self.floors is not None
        self._recovery.reset()
        self._gate.reset()
        self._blind_hold = False
        self._search_at_base = False
        self._told_since_start = False
        self._settled_frames = 0
        self._twins_possible = bool(self._twins)
        self.twins_undecided = False
        self.levels_undecided = False
        self.continuation.reset()
        self.geometry.reset()
        self.odometry_check.reset()
        self.told_heading.reset()
        self._start_contradicted = 0
        if self.evidence is not None:
            self.evidence.reset()
            self.evidence.set_prior(None)  # a start from no knowledge has no known start
        if self.unseen is not None:
            self.unseen.reset()
        self.restarts += 1

    def observation_log_likelihood(self, obs: Observation) -> NDArray[np.float64]:
        """log P(Z | s, M) for every particle, shape (N,)."""
        return self.sensor.log_likelihood(self.x, self.y, self.theta, obs)

    def correct(self, detections: Sequence[Detection]) -> float:
        """Weight particles by the detections; return the injection share asked for.

        A frame without usable detections changes nothing (no evidence).
        """
        mean_ll, _ = self._correct(detections)
        return 0.0 if mean_ll is None else self._recover(mean_ll)

    def _correct(
        self, detections: Sequence[Detection], weigh: bool = True, riding: bool = False
    ) -> tuple[float | None, NDArray[np.float64] | None]:
        """The log of this frame's mean likelihood (None: no detections, nothing
        weighed), for the recovery (:meth:`_recover`), and the normalized weights
        computed on the way (None when it did not weigh: :attr:`weights` then computes
        them). With ``weigh`` false the detections are kept as the frame's observation
        (what the estimate is checked against) and weigh nothing: no evidence. While
        ``riding`` (the barometer has the person between floors) a frame without
        evidence is not counted as dead reckoning: the barometer carries them then,
        not the odometry, and a lift car's walls show nothing."""
        obs = self.sensor.observe(detections)
        self.last_observation = obs
        if obs.empty or not weigh:
            if not riding:
                self.frames_without_evidence += 1
            return None, None
        self.frames_without_evidence = 0
        if self._wide_first:
            return self._wide_start(obs), None
        if self._seed_from_observation:
            self._seed_cloud(obs)
        log_lik = self.observation_log_likelihood(obs)
        # Right after a resampling the log-weights are all zero (about 60 % of a
        # localized walk's frames): their log-sum is then the one kept for that size.
        nonzero = np.logical_or.reduce(self.log_w)  # .any() without its Python wrapper
        before = log_sum_exp(self.log_w) if nonzero else _log_sum_exp_of_zeros(self.n)
        self.log_w = self.log_w + log_lik
        # log of the prior-weighted mean likelihood: lse(w + l) - lse(w)
        w, after = weights_and_log_sum_exp(self.log_w)
        return after - before, w

    def _recover(self, mean_ll: float) -> float:
        """The share of particles to inject (augmented MCL), from the log of this
        frame's mean likelihood, per class seen (of :attr:`last_observation`); 0 with
        recovery off."""
        obs = self.last_observation
        assert obs is not None
        per_class = mean_ll / max(obs.group_kappa.size, 1)
        if not math.isfinite(per_class):
            per_class = -1e3
        if not self.config.recovery:
            return 0.0
        return self._recovery.update(per_class)

    def _seed_cloud(self, obs: Observation) -> None:
        """Global start, first evidence: draw most particles from the observation.

        Anywhere in the free space, but with the heading that points one detection at
        an object of its class (sensor resetting); the rest stay uniform, so a false
        first detection cannot trap the filter. Many more particles then start near
        the true heading than a uniform draw would put there.
        """
        self._seed_from_observation = False
        n_obs = int(SEED_SHARE * self.n)
        x, y, th = self.sensor.sample_poses(n_obs, obs, self.rng)
        self.x[:n_obs], self.y[:n_obs], self.theta[:n_obs] = x, y, th
        self.log_w[:] = 0.0

    def _wide_start(self, obs: Observation) -> float:
        """Global start on a map with several levels, first evidence: importance
        sampling at a one-level map's density.

        ``config.particles`` spread over every level put a level's share of them on the
        person's floor, and the first fix came later than on that floor's map alone.
        Here (levels x particles) candidates are drawn as a global start draws its
        particles (``SEED_SHARE`` of them from this observation, the rest uniform over
        the free space of every level), weighed by this frame's detections, and
        ``config.particles`` of them drawn by systematic resampling: the cloud the
        larger filter would hold after this frame, at the steady filter's size and
        cost from the next frame on. The frame is weighed once (the drawn particles
        come with equal weights) and only when it has detections; with few or
        ambiguous ones the weights stay flat and so does the share of every level.
        Returns the log of the candidates' mean likelihood (what the recovery's
        averages take)."""
        self._wide_first = False
        m = len(self.map.layout.levels) * self.n
        x, y, theta = self._anywhere(m)
        if self._seed_from_observation:
            self._seed_from_observation = False
            n_obs = int(SEED_SHARE * m)
            x[:n_obs], y[:n_obs], theta[:n_obs] = self.sensor.sample_poses(n_obs, obs, self.rng)
        w, lse = weights_and_log_sum_exp(self.sensor.log_likelihood(x, y, theta, obs))
        idx = systematic_resample(w, self.n, self.rng)
        self.x, self.y, self.theta = x[idx], y[idx], theta[idx]
        self.log_w = np.zeros(self.n, dtype=np.float64)
        return lse - float(np.log(m))

    def resample(self, inject_share: float = 0.0) -> bool:
        """Resample when the ESS is low or particles are to be injected; True if done."""
        w = self.weights
        return self._resample(w, effective_sample_size(w), inject_share)

    def _resample(self, w: NDArray[np.float64], ess: float, inject_share: float) -> bool:
        """:meth:`resample` with the normalized weights and their ESS already at hand."""
        n_target = self.n
        if self.config.adaptive and not self._blind_hold:
            # Lost: keep every particle. Localized: as few as KLD-sampling allows. (A
            # blind hold weighs nothing: its cloud only spreads by the motion's noise,
            # and is kept as it is.)
            n_target = self.config.particles
            if self.estimate.converged:
                n_min = min(self.config.min_particles, self.config.particles)
                n_target = kld_sample_size(
                    self.x, self.y, self.theta, w, n_min, self.config.particles
                )
        due = ess < self.config.resample_threshold * self.n or not np.isfinite(self.log_w).any()
        if not (due or inject_share > 0.0 or n_target != self.n):
            return False
        idx = systematic_resample(w, n_target, self.rng)
        self.x, self.y, self.theta = self.x[idx], self.y[idx], self.theta[idx]
        self.log_w = np.zeros(n_target, dtype=np.float64)
        obs = self.last_observation
        n_new = round(inject_share * n_target)
        if n_new > 0 and obs is not None and not obs.empty:
            nx, ny, nt = self.sensor.sample_poses(n_new, obs, self.rng)
            slots = self.rng.choice(n_target, size=n_new, replace=False)
            self.x[slots], self.y[slots], self.theta[slots] = nx, ny, nt
            if self.floors is not None:
                self.log_w[slots] = self.floors.injected_log_w(nx)
        return True

    def step(
        self,
        odometry: Odometry | None,
        detections: Sequence[Detection],
        heading: CompassReading | None = None,
        altitude: AltitudeReading | None = None,
        *,
        detections_age_s: float = 0.0,
        frame_s: float | None = None,
    ) -> Estimate:
        """One full filter step: predict, correct, estimate, resample when due.

        ``heading``, a compass reading, weights the particles' headings too
        (:mod:`~app.localization.compass`); ``altitude``, the barometer's, moves
        particles between levels (:mod:`~app.localization.floors`). ``detections_age_s``:
        how long before the end of this frame's ``odometry`` (lasting ``frame_s``, None:
        not known) the detections were captured; the particles stand for the pose at
        that moment (:mod:`~app.localization.latency`), and the estimate returned is
        moved on to the frame's end (:attr:`estimate` stays at the capture).

        The estimate summarizes the weighted particles before resampling: resampling
        only adds noise to what they say (and to what the injected particles say).

        A frame that comes less than :data:`~app.localization.pacing.WEIGH_PERIOD_S` after
        the last one weighed
        (less half its own ``frame_s``), with odometry, is not weighed: the answer is the
        last one moved on by the motion since (its convergence and radius as they were),
        and the motion waits for the next frame weighed, as frames merged in a queue do
        (its detections are not weighed: the next frame's are a 0.1 s newer view of the
        same). Its compass and barometer readings go with the motion to the next frame
        weighed when that one has none of its own (the compass turned on by the turns
        since): an app that sends a reading only when it changes loses none.
        """
        # A frame whose odometry outruns a person on foot (a tracker relocalizing, a
        # stride counted twice) did not move the person that far (motion.implausible):
        # its translation is refused, its turn kept, so that nothing carries the cloud,
        # the fix, the walk or the odometry's own estimates by that jump. (Not taken for
        # a frame without odometry: that lets a held fix go, and the fix is as good as
        # it was a frame ago.)
        self.odometry_refused = implausible(odometry, frame_s)
        self.start_given_up = False
        if self.odometry_refused:
            assert odometry is not None
            odometry = Odometry(0.0, 0.0, odometry.turn_rad)
        answer = self._last_answer()
        if (
            answer is not None
            and self._pacing.waits(odometry, frame_s)
            and not self._near_a_ride(answer)
            and not self._awaiting_known_start()
        ):
            assert odometry is not None and frame_s is not None  # (waits says so)
            motion = self._pacing.hold(odometry, frame_s, heading, altitude)
            self.last_observation = None  # (this frame's detections were not prepared)
            if self.floors is not None:
                self.floors.quiet_frame()
            return moved_forward(answer, motion)
        weighed = self._pacing.release(odometry, frame_s, heading, altitude)
        odometry, frame_s = weighed.odometry, weighed.frame_s
        heading, altitude = weighed.heading, weighed.altitude
        raw_odometry = odometry
        known_s = frame_s if frame_s is not None and frame_s > 0.0 else None
        seconds = DEFAULT_FRAME_S if known_s is None else known_s
        if self.odometry_bias is not None:
            odometry = self.odometry_bias.correct(odometry, seconds)
        # An app that does not say its latency still has one: learnt from turns.
        unsaid = detections_age_s == 0.0
        if known_s is None:
            # How long the frame lasted is not known, so neither is how much of its
            # motion came after its detections were captured: a said age a frame or
            # more long would put every capture at the frame's start and the particles
            # would stand still while the person walks (measured, a phone at 5 frames/s
            # whose app sent ages but no timestamps: availability 0.957 -> 0.600). The
            # age is learnt from turns instead, in frames (each taken to last
            # DEFAULT_FRAME_S, as the capture clock takes it): a phone sending at a
            # steady rate lags by about as many frames all along.
            detections_age_s = self.latency_untimed.age_s or 0.0
        elif unsaid and (learnt := self.latency.age_s) is not None:
            detections_age_s = learnt
        odometry = self.capture.step(odometry, frame_s, detections_age_s)
        self._step(odometry, detections, heading, altitude, known_s, weighed.steps)
        est = self._last_answer()
        assert est is not None
        if raw_odometry is not None and known_s is None:
            turn_rad_frame = raw_odometry.turn_rad / DEFAULT_FRAME_S
            self._learn_latency(self.latency_untimed, turn_rad_frame, detections_age_s)
        elif unsaid and raw_odometry is not None:
            # (An app that says its latency has nothing to learn: no matching per frame.)
            assert known_s is not None
            self._learn_latency(self.latency, raw_odometry.turn_rad / known_s, detections_age_s)
        if self.odometry_bias is not None:
            rode = self.floors is not None and self.floors.changed
            self.odometry_bias.observe(
                None if rode else raw_odometry,
                seconds,
                (est.x, est.y, est.theta_rad),
                est.converged,
                max(est.std_x_m, est.std_y_m),
                est.std_theta_rad,
            )
        return est

    def _learn_latency(self, learner: LatencyEstimate, turn_rad_s: float, applied_s: float) -> None:
        """A converged frame's bearing residuals at the estimate, against its turn rate,
        weighed with an age of ``applied_s``
        (:class:`~app.localization.latency.LatencyEstimate`)."""
        e = self.estimate
        obs = self.last_observation
        if not e.converged or obs is None or obs.empty or not learner.turning(turn_rad_s):
            return
        _, index = match_detections(
            np.array([e.x]), np.array([e.y]), np.array([e.theta_rad]), obs, self.map, self.config
        )
        residuals = []
        for k, o in enumerate(index[:, 0].tolist()):
            if o < 0:
                continue
            ox, oy = self.map.object_xy[o]
            seen = obs.det_bearing[k] - (math.atan2(oy - e.y, ox - e.x) - e.theta_rad)
            residuals.append(float(wrap_angle(seen)))
        learner.update(residuals, turn_rad_s, applied_s)

    def _last_answer(self) -> Estimate | None:
        """What the last step answered (None before the first): :attr:`estimate`, at the
        detections' capture, moved on to the frame's end."""
        if not self.steps:
            return None
        back = self.capture.back
        if back.forward_m == 0.0 and back.left_m == 0.0 and back.turn_rad == 0.0:
            return self.estimate
        return moved_forward(self.estimate, back)

    def _awaiting_known_start(self) -> bool:
        """Whether a known start that rules out every other place (the evidence
        tracker's ``prior_confines``) has not been told yet: every frame is weighed
        until it is, so that the gate's steady frames are frames, not paced steps
        (standing still at a known start at 10 frames/s, paced: told on the 9th frame;
        weighing each: the 5th, as at 5 frames/s)."""
        ev = self.evidence
        return not self._told_since_start and ev is not None and ev.prior_confines

    def _near_a_ride(self, answer: Estimate) -> bool:
        """Whether the person may be riding between floors, or about to: the barometer
        says so, or the last answer stands in a connector's stop. Every frame is
        weighed there (:mod:`~app.localization.pacing`): a lift car's door opening on another
        floor is news that cannot wait a frame."""
        floors = self.floors
        return floors is not None and (floors.in_transit or floors.in_stop(answer.x, answer.y))

    def _step(
        self,
        odometry: Odometry | None,
        detections: Sequence[Detection],
        heading: CompassReading | None,
        altitude: AltitudeReading | None = None,
        frame_s: float | None = None,
        steps: int = 1,
    ) -> None:
        """:meth:`step` in capture time: ``odometry`` is the motion between captures,
        ``frame_s`` the time since the previous frame (None: not known), adding up
        ``steps`` frames (:mod:`~app.localization.pacing`)."""
        # A frame without odometry inside a short gap moves by a guess (gap.py), but not
        # near a ride: stairs, an escalator or a lift car move a person otherwise than
        # the walk before them (and without a barometer, nothing says a ride began).
        floors = self.floors
        rides = (
            odometry is None
            and floors is not None
            and (floors.blind or self._near_a_ride(self.estimate))
        )
        moving, lost = self.gap.frame(odometry, frame_s, may_guess=not rides)
        self.predict(moving, steps)
        if odometry is None:
            self._last_fix = None
        elif self._last_fix is not None:
            lx, ly, lr = self._last_fix
            walked = WALK_BOUND_SCALE * hypot(odometry.forward_m, odometry.left_m)
            self._last_fix = (lx, ly, lr + walked)
        # (An untimed frame is taken to last DEFAULT_FRAME_S, as the capture clock takes it.)
        elapsed_s = DEFAULT_FRAME_S * steps if frame_s is None else frame_s
        self.told_heading.moved(odometry, elapsed_s)
        if odometry is not None:
            self.geometry.moved(odometry)
            self.odometry_check.moved(odometry)
            self.walked.moved(odometry)
        else:  # the person may have been carried anywhere: nothing to compare with
            self.odometry_check.reset()
            self.walked.reset()
            # ... nor to hold blind: out of the car, the detections are evidence again
            self._blind_hold = False
        rode, pinned = self._change_level(altitude, frame_s)
        # During a blind hold (decided below) the detections weigh nothing; between
        # floors a blank view is no dead reckoning, so a fix held into a ride is not let
        # go for the car's walls.
        riding = floors is not None and not floors.blind and floors.in_transit
        mean_ll, w = self._correct(detections, weigh=not self._blind_hold, riding=riding)
        if heading is not None:
            self._twins_possible = False  # a heading from outside tells the twins apart
            self.log_w = self.log_w + compass_log_likelihood(self.theta, heading)
            w = None  # the correction's weights no longer hold
        if w is None:
            w = self.weights
        ess = effective_sample_size(w)
        raw = estimate_pose(self.x, self.y, self.theta, w, ess=ess, rng=self.rng)
        self._leave_connector(raw, rode, pinned, odometry)
        share, confirmed, gain_share = 0.0, 0.0, 0.0
        searched_ago: int | None = 0
        transit = floors is not None and floors.between_floors(raw.x, raw.y)
        # Without a barometer the stop alone says "between floors"; the view may still
        # have put all but ``LEVEL_SURE_SHARE`` of the belief on one floor (below).
        settled = (
            transit
            and floors is not None
            and floors.blind
            and floors.share_on_level(self.x, w, raw.x) >= LEVEL_SURE_SHARE
        )
        kept = False
        if transit:
            # Between floors nobody is located (converged is withheld below), and the
            # convergence test starts afresh, except that a fix held as the barometer
            # called the person between floors keeps being tested by the hold rules
            # until a level does change: a poor barometer's noise calls a walking
            # person between floors for a frame or two now and then, and that fix,
            # never moved, is as good after as before.
            assert floors is not None
            if settled:
                # Without a barometer, while the view keeps the belief on one floor,
                # the person is taken to be on it: the particles that took the
                # connector (BLIND_RATE a frame) are weighed by the view like the rest,
                # and a person walking past the foot of the stairs sees their own
                # floor, one stepping out of a lift car the floor it opened on. A fix
                # held into the stop is even kept converged there (measured on the
                # venue suite: every pass by a stop cost 3-5 s of "not sure" at 2-10
                # cm of error). One not held is not gained in the stop, since riding an
                # escalator or the stairs the view shows the floor being left until
                # the top (measured: a gain on the Ground Floor the frame the person
                # reached the First), but the test towards it runs, its search comes at
                # the base interval as after a ride (_weigh_alternatives), and it is
                # gained on the first frame out of the stop instead of five frames and
                # a search later (venue suite without a barometer: located 1.5 s after
                # a ride, median, and the First Floor available 96.9 % of its frames
                # against 98.2 % for the floor alone).
                # (A gain made in the stop is held by the gate but was not reported:
                # the estimate of the last frame says which.) A ride shows a lift car
                # (the same on every floor) or stairs leading away, and leaves the
                # floors the connector reaches their share within a frame or two: then
                # the test starts afresh, below.
                kept = self._gate.held and self.estimate.converged
                if not kept:
                    self._search_at_base = True
            elif not (self._gate.held and (rode or not floors.changed) and not floors.blind):
                # A level change resets the test, except for a ride the belief was
                # located for (rode): its fix rides along with the barometer's count,
                # as the exit's known start does (_start_at_ride_exit), and is told
                # again on the first frame out of the stop if the hold's tests held.
                self._gate.reset()
        if self.evidence is not None and transit and (kept or not settled):
            # Carried along all the same, or the first frame after would find the
            # filter's cloud walked away from the tracker's anchor and take the fix's
            # own place for an alternative (measured: a fix held through a stop without
            # a barometer, swapped out on the frame it stepped out).
            self._weigh_alternatives(moving, raw, w, ess, heading, carry_only=True, steps=steps)
        elif self.evidence is not None:
            raw, w, ess = self._weigh_alternatives(moving, raw, w, ess, heading, steps=steps)
            share, searched_ago = self.evidence.alternative_share, self.evidence.searched_ago
            confirmed, gain_share = self.evidence.confirmed_share, self.evidence.gain_share
            if self.evidence.prior_confines:
                searched_ago = 0  # a tight known start rules out every other place
        moved = 1.0 if odometry is None else hypot(odometry.forward_m, odometry.left_m)
        jump_m = hypot(raw.x - self.estimate.x, raw.y - self.estimate.y)
        jumped = jump_m > moved + self._gate.unseen_place_m
        self._settled_frames = 0 if jumped else self._settled_frames + 1
        evidence_share = share
        if self._twins_possible:
            # A map that turns onto itself: each twin of the place is as likely as the
            # place, whatever is seen (app.maps.symmetry).
            twins = len(self._twins) / (len(self._twins) + 1.0)
            share, confirmed, gain_share = (max(v, twins) for v in (share, confirmed, gain_share))
        self._update_fit(raw)
        if self._bad_run and self.gap.guessed:
            # Most detections contradict a fix walked on a guess: the gap may have
            # carried the person after all (gap.py).
            lost = self.gap.break_off()
        turned = np.pi if odometry is None else odometry.turn_rad
        slide_m = self.odometry_check.slide_m(raw.x, raw.y)
        was_held = self._gate.held
        clustered = raw
        if (
            not raw.converged
            and self.continuation.since_doubt is not None
            and self._gate.cluster_holds(raw)
        ):
            # A fix let go for doubt alone is taken up again, while that doubt's
            # continuation lasts, with the cluster a held fix keeps (the gate's hold_mass
            # and hold_std_*), not the tighter one of a first gain: the cloud spread a
            # held fix was allowed a moment ago is no reason to doubt the place once the
            # doubt is gone (the gain's other tests, the slide from the told fix among
            # them, still apply). Traced on the venue suite through a 66-degree camera
            # with PDR odometry (seed 0, First Floor): a fix let go for an alternative
            # that a search refuted 4 frames later, the whole weight in one cluster
            # 0.3 m from the person but 0.29-0.31 m wide along one axis, "not sure" for
            # 46 s where the floor's own map kept its fix.
            clustered = raw.with_converged(True)
        est = self._gate.confirm(
            clustered,
            moved,
            turned,
            self.quality,
            self.frames_without_evidence,
            share,
            searched_ago,
            motion_lost=lost,
            confirmed_alternatives=confirmed,
            evidence_frame=self.frames_without_evidence == 0,
            lone_detection=len(detections) == 1,
            geometry_m=(fix_m := self.geometry.radius_m(raw.x, raw.y, raw.theta_rad)),
            slide_m=slide_m,
            gain_share=gain_share,
        )
        # A run towards a gain that faced otherwise than the last told fixes on any of
        # its frames (app.localization.told_heading): a run's headings wander by a few
        # degrees, and one frame that happens to agree does not clear it.
        streak = self._gate.streak
        if streak <= 1 or was_held:
            self._turned_run = False
        if streak > 0 and not was_held and self.told_heading.disagrees(raw.theta_rad):
            self._turned_run = True
        gained = est.converged and not was_held
        if est.converged and transit and not kept:  # the stop's rules above
            est = est.with_converged(False)
        if not gained:
            self._narrow_frames = 0
        est, protection, withheld = self._protect(
            est, raw, w, share, fix_m, slide_m, gained=gained, streak=streak
        )
        if self.continuation.known_start and self._give_up_the_start():
            est = est.with_converged(False).with_protection(None)
        # (A told frame never reads in_stop: the guard only spares the stop lookup.)
        self.continuation.after_frame(
            let_go_for_doubt=was_held and self._gate.let_go_for_doubt,
            doubt_frames=doubt_frames(self._gate.lost_because),
            told=est.converged,
            in_stop=not est.converged
            and (transit or (floors is not None and floors.in_stop(raw.x, raw.y))),
            was_told=self.estimate.converged,
            search_wait=self._gate.not_gained_because == ("no search yet",),
        )
        if est.converged:
            self._search_at_base = False
            self._told_since_start = True
            assert protection is not None
            self._last_fix = (est.x, est.y, protection)
            self.told_heading.told(est.theta_rad)
        # Where a held fix has nothing in clear view (a lift car, a bare wall ahead of a
        # narrow camera), every detection is clutter wherever the person stands, yet
        # weighing them lets the few particles elsewhere that one happens to fit outweigh
        # the whole fix (the sensor model has no term for the objects such a place would
        # have shown and did not), and augmented MCL reads the poor frame as a kidnap and
        # injects where the boxes point. Measured on the venue suite: a fix in a lift car
        # thrown 14-100 m away by one frame of three false boxes during the door wait,
        # then carried upstairs from the wrong place. So such a frame feeds no recovery,
        # anywhere; and in a connector's stop the fix goes on in a blind hold until it
        # sees something again: no weighing (above), no weighing of the alternatives and
        # no search (_weigh_alternatives), no resizing (_resample). Only in a stop: along
        # a bare wall the odometry drifts, and what the estimate does not explain may be
        # what corrects it (measured, holding there too cost 45-52 confidently-wrong
        # frames at PDR grade through a 66-degree camera on the phone suite).
        # (Between floors the frames feed no recovery either: the barometer, not the
        # view, moves the cloud then.)
        inject = 0.0
        if mean_ll is not None and not transit and not (self._sees_nothing and self._gate.held):
            inject = self._recover(mean_ll)
            if est.converged and self._held_s >= SETTLED_FIX_S:
                # A fix held for SETTLED_FIX_S has passed every test of the gate all
                # that while, and the gate lets it go on the signs of a kidnap (a bad
                # frame, a slide, an alternative the evidence search found); the
                # recovery injects again from that frame on. Until then particles drawn
                # from one frame's boxes carry none of the history behind the fix, yet
                # would enter with the survivors' weight, a fifth of the belief and
                # more. A stale map's moved object lowers the fit at the true place for
                # as long as it is in view (which is what the recovery's averages read
                # as a kidnap) and fits a look-alike place better: measured on the
                # phone suite's stale office at 360 deg (seed 2), injected particles
                # 6 m along the corridor took the belief off a fix 0.1 m from the truth,
                # held for 18 s, within three frames. A younger fix has little history
                # behind it and may have been gained wrong; injected particles are
                # what lets it go soonest (a look-alike wing of the two-wing floor at
                # 180 deg, seed 38, held wrong from its gain: let go after 29 frames
                # with them, 40 without; the stale office after an 8 s pause, seed 1:
                # 32 and 38).
                inject = 0.0
        self._held_s = self._held_s + elapsed_s if est.converged else 0.0
        obs = self.last_observation
        if obs is not None and not obs.empty:
            self._blind_hold = (
                self._sees_nothing
                and (self._gate.held or self._blind_hold)
                and self.floors is not None
                and self.floors.in_stop(raw.x, raw.y)
            )
        if was_held and not est.converged and "slide" in self._gate.lost_because:
            self._blame_the_slide(raw)
        # A run of frames on the way to a gain is held to the odometry as a fix is: its
        # estimates are anchors while it lasts (a new run starts without the last's).
        if not est.converged and streak <= 1:
            self.odometry_check.drop_candidates()
        candidate = not est.converged and streak > 0
        # While a fix let go for doubt may be taken up without a narrow radius
        # (continuation.DOUBT_FRAMES), every frame is an anchor as a told one is: the
        # regain is held to the told fix carried by the odometry (its slip counted over
        # the frames of doubt too), not to a run of candidates too young to compare with.
        doubt = self.continuation.since_doubt is not None
        self.odometry_check.add(
            raw.x, raw.y, raw.theta_rad, est.converged or doubt, candidate and not doubt
        )
        if self.evidence is not None:
            est = with_alternatives(est, self.evidence.hypotheses(), evidence_share)
        # Only the map's twins are left: neither turning nor walking tells them apart
        # (a compass heading or a start does).
        self.twins_undecided = self._twins_possible and only_twins(
            est, self._twins, self.map.layout
        )
        # ... or the same place on floors that look alike (the barometer counts storeys
        # from a known floor only, and there was none).
        self.levels_undecided = (
            not est.converged
            and bool(self._alike_levels)
            and only_alike_levels(est, self._alike_levels, self.map.layout)
        )
        if self._twins_possible:
            est = with_twins(est, self._twins, self.map.layout)
        if est.converged:
            assert protection is not None
            est = est.with_protection(protection)
        if self.floors is not None:
            # A gain taken back for its radius alone is a fix of the level all the same
            # (the gate's tests held, alternatives on other floors included): the floor
            # is confirmed, and the barometer's storeys are counted from it.
            self.floors.after_estimate(self.x, w, est.x, est.converged or withheld)
        self.estimate = est
        self._resample(w, ess, inject)
        self.steps += 1

    def _weigh_alternatives(
        self,
        odometry: Odometry | None,
        raw: Estimate,
        w: NDArray[np.float64],
        ess: float,
        heading: CompassReading | None = None,
        carry_only: bool = False,
        steps: int = 1,
    ) -> tuple[Estimate, NDArray[np.float64], float]:
        """Move and weigh the alternatives; swap the strongest in if the evidence says so.
        With ``carry_only`` (between floors) they are only moved: no weighing, no search,
        no swap. ``steps``: frames the odometry adds up."""
        assert self.evidence is not None and self.last_observation is not None
        top = raw.hypotheses[0] if raw.hypotheses else None
        tight = top is not None and top.std_xy_m <= SEARCH_MAX_SPREAD_M
        # A search serves the gate: it is only worth its cost while the main mode
        # explains the detections well enough to be (or become) converged.
        q = self.quality
        # Nor during a blind hold (see _step): a place that happens to explain a false
        # box is no likelier for it.
        fits = (
            not carry_only
            and q is not None
            and q.fit <= self._gate.hold_fit
            and q.unexplained <= self._gate.hold_unexplained
            and not self._blind_hold
        )
        particles = (self.x, self.y, self.theta, w)
        obs = self.last_observation
        # After a ride (or a slide's blame), a run of steady frames long enough to gain
        # with no search since it began asks for the search it waits for
        # (ConvergenceGate.confirm) at the base interval, not the lengthened one of
        # searches that found nothing: that was up to 4 s more of "not sure" at a fix
        # the ride's known start had already placed
        # (venue suite, 66 deg cameras). Only then: elsewhere the wait is a stale map's
        # margin (the same rule everywhere gained fixes a metre off where a moved object
        # fits: phone suite 87 -> 105 confidently-wrong frames).
        gate, ago = self._gate, self.evidence.searched_ago
        gain_waits = (
            self._search_at_base
            and not gate.held
            and gate.streak >= gate.frames - 1
            and (ago is None or ago >= gate.streak)
        )
        swap = self.evidence.update(
            odometry, obs, top, tight, particles, heading, fits, gain_waits,
            steps=steps,
        )  # fmt: skip
        if swap and self._last_fix is not None:
            # A place the last told fix's circle holds, found by a search a few frames
            # ago, is no new place but a refinement the search's selection favours (the
            # best of thousands of candidates fits a short window better than the truth
            # by chance, alternatives.EvidenceSettings.probation): it is swapped in only
            # once it has kept its evidence through probation. Its probability counts
            # against the fix meanwhile. Measured over 410 walks (the phone suite's VIO
            # and PDR rows, the venue suite's phone conditions): each held fix swapped
            # onto such a place whose error was measured ended farther from the truth
            # (4 of 4: 0.05 -> 1.13, 0.18 -> 0.52, 0.18 -> 0.48, 0.31 -> 1.03 m; two
            # more, in the venue suite's one-level baseline filters, were not measured).
            lx, ly, lr = self._last_fix
            ax, ay, age = self.evidence.strongest()
            if age < self.evidence.settings.probation and hypot(ax - lx, ay - ly) <= lr:
                swap = False
        if carry_only or not swap:
            return raw, w, ess
        told = self.estimate
        self._last_fix = None  # the evidence says the told place was not the person's
        if told.converged:
            # ... nor, swapped out while told, its heading the person's. (A cloud
            # swapped out while nothing was told says nothing of the last fix.)
            self.told_heading.reset()
        self.x, self.y, self.theta = self.evidence.swap(self.n)
        self.log_w = np.zeros(self.n)
        self._gate.reset()
        self.geometry.clear_frames()
        self.odometry_check.reset()
        self.quality = None
        w = self.weights
        ess = effective_sample_size(w)
        est = estimate_pose(self.x, self.y, self.theta, w, ess=ess, rng=self.rng)
        # A swap onto a place the told fix's radius holds is doubt, not a new place
        # (continuation.DOUBT_FRAMES): its heading or a few decimetres were in question.
        radius = told.protection_m if told.converged else None
        if radius is not None and hypot(est.x - told.x, est.y - told.y) <= radius:
            self.continuation.doubted()
        return est, w, ess

    # ------------------------------------------------------------ checkpoints
    def checkpoint(self, max_particles: int = CHECKPOINT_PARTICLES) -> dict[str, Any]:
        """Everything the next step depends on, compactly: plain data, float32 arrays and
        frozen values (the estimate, the fit) as they are.

        A cloud larger than ``max_particles`` is resampled to that many (systematic,
        equal weights; drawn with its own generator so the filter's is untouched). A
        smaller one is kept whole, and the filter itself goes on from exactly what is
        stored (its poses and log-weights rounded to float32, a change of about 1e-7
        of their values): a filter restored from the checkpoint and fed the same frames
        then takes the very same steps. The random generator's state is kept too. The
        map and the configuration are not included: :meth:`restore` runs on a filter
        built from the same ones.
        """
        if self.n > max_particles:
            idx = systematic_resample(
                self.weights, max_particles, np.random.default_rng(self.steps)
            )
            x, y, theta = (v[idx].astype(np.float32) for v in (self.x, self.y, self.theta))
            log_w = None
        else:
            x, y, theta = (v.astype(np.float32) for v in (self.x, self.y, self.theta))
            top = self.log_w.max()
            log_w = None
            if np.isfinite(top) and not bool(np.all(self.log_w == top)):
                log_w = (self.log_w - top).astype(np.float32)
            self.x, self.y, self.theta = (v.astype(np.float64) for v in (x, y, theta))
            self.log_w = np.zeros(self.n) if log_w is None else log_w.astype(np.float64)
        state = {
            "x": x,
            "y": y,
            "theta": theta,
            "log_w": log_w,
            "rng": _rng_state_out(self.rng.bit_generator.state),
            "recovery": [self._recovery.w_slow, self._recovery.w_fast],
            "gate": self._gate.checkpoint(),
            "seed_from_observation": self._seed_from_observation,
            "quality": self.quality,
            # (also on its own, as a worker of the version before reads it)
            "had_odometry": self.gap.had_odometry,
            "gap": self.gap.checkpoint(),
            "bad_run": self._bad_run,
            "sees_nothing": self._sees_nothing,
            "blind_hold": self._blind_hold,
            "evidence": None if self.evidence is None else self.evidence.checkpoint(),
            "unseen": None if self.unseen is None else self.unseen.checkpoint(),
            "frames_without_evidence": self.frames_without_evidence,
            "restarts": self.restarts,
            "narrow_frames": self._narrow_frames,
            "turned_run": self._turned_run,
            "told_since_start": self._told_since_start,
            "start_contradicted": self._start_contradicted,
            "settled_frames": self._settled_frames,
            "held_s": self._held_s,
            "search_at_base": self._search_at_base,
            "twins_possible": self._twins_possible,
            "last_fix": None if self._last_fix is None else list(self._last_fix),
            **self.continuation.checkpoint(levels=self.floors is not None),
            "steps": self.steps,
            **self._pacing.checkpoint(),
            "estimate": self.estimate,
            "capture": self.capture.checkpoint(),
            "latency": self.latency.checkpoint(),
            "latency_untimed": self.latency_untimed.checkpoint(),
            "geometry": self.geometry.checkpoint(),
            "odometry_check": self.odometry_check.checkpoint(),
            "told_heading": self.told_heading.checkpoint(),
            "walked": self.walked.checkpoint(),
        }
        if self.odometry_bias is not None:
            state["odometry_bias"] = self.odometry_bias.checkpoint()
        if self.floors is not None:  # maps with several levels only
            state["floors"] = self.floors.checkpoint()
            state["located_at_ride"] = self._located_at_ride
            state["wide_first"] = self._wide_first
        return state

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a :meth:`checkpoint` (taken of a filter with this map and config)."""
        self.x = np.asarray(state["x"], dtype=np.float64)
        self.y = np.asarray(state["y"], dtype=np.float64)
        self.theta = np.asarray(state["theta"], dtype=np.float64)
        log_w = state["log_w"]
        self.log_w = (
            np.zeros(self.x.shape[0]) if log_w is None else np.asarray(log_w, dtype=np.float64)
        )
        self.rng.bit_generator.state = _rng_state_in(state["rng"])
        self._recovery.w_slow, self._recovery.w_fast = (float(v) for v in state["recovery"])
        self._gate.restore(state["gate"])
        self._seed_from_observation = bool(state["seed_from_observation"])
        self._wide_first = bool(state.get("wide_first", False))
        self.quality = from_plain(FitQuality | None, state["quality"])
        self.gap.restore(state.get("gap"), bool(state["had_odometry"]))
        self._bad_run = int(state.get("bad_run", 0))
        # (checkpoints from before these were kept hold neither)
        self._sees_nothing = bool(state.get("sees_nothing", False))
        self._blind_hold = bool(state.get("blind_hold", False))
        if self.unseen is not None and state.get("unseen") is not None:
            self.unseen.restore(state["unseen"])
            # (before the evidence tracker makes its window's observations again)
            self._exclude_from_models(np.flatnonzero(self.unseen.moved).tolist())
        if self.evidence is not None and state["evidence"] is not None:
            self.evidence.restore(state["evidence"])
        if self.floors is not None and state.get("floors") is not None:
            self.floors.restore(state["floors"])
        self._located_at_ride = bool(state.get("located_at_ride", False))
        self.frames_without_evidence = int(state["frames_without_evidence"])
        self.restarts = int(state["restarts"])
        self._narrow_frames = int(state.get("narrow_frames", 0))
        self._turned_run = bool(state.get("turned_run", False))
        # (An older checkpoint: as if told, so no candidate forgives.)
        self._told_since_start = bool(state.get("told_since_start", True))
        self._start_contradicted = int(state.get("start_contradicted", 0))
        self._frame_misfit = False
        self._settled_frames = int(state.get("settled_frames", 0))
        # (An older checkpoint: a fix as young as can be; it injects as before.)
        self._held_s = float(state.get("held_s", 0.0))
        # (Checkpoints of the last releases kept it as after_ride, or after_blame.)
        self._search_at_base = bool(
            state.get("search_at_base", state.get("after_ride") or state.get("after_blame"))
        )
        # (An older checkpoint: as before twins were known.)
        self._twins_possible = bool(state.get("twins_possible", False))
        last = state.get("last_fix")
        self._last_fix = None if last is None else (float(last[0]), float(last[1]), float(last[2]))
        self.steps = int(state["steps"])
        self._pacing = Pacing()
        self._pacing.restore(state)
        self.estimate = from_plain(Estimate, state["estimate"])
        self.continuation.restore(state)
        self.capture.restore(state.get("capture"))
        self.latency.restore(state.get("latency"))
        self.latency_untimed.restore(state.get("latency_untimed"))
        self.geometry.restore(state.get("geometry"))
        self.odometry_check.restore(state.get("odometry_check"))
        self.told_heading.restore(state.get("told_heading"))
        self.walked.restore(state.get("walked"))
        if self.odometry_bias is not None:
            self.odometry_bias.restore(state.get("odometry_bias"))
        self.last_observation = None

    def _update_fit(self, raw: Estimate) -> None:
        """Smooth how well the estimated pose explains this frame's detections.

        Each detection's bearing residual at the estimate (in stds, to the best visible
        object of its class) is either explained by an object, or better explained by
        the clutter floor (beyond the residual where the two densities cross; 3 stds
        without a floor): a false detection then does not count against the estimate.
        Tracked, score-weighted and smoothed (a frame with little detection score moves
        them little, see ``FIT_FULL_SCORE``): the mean squared residual of the explained
        detections (``fit``) and the share left to clutter (``unexplained``). Objects
        count a few stds beyond the field of view's edges (``FIT_FOV_MARGIN_STDS``).
        With the unseen-object check on, a frame in which the camera reported what the
        pose has in clear view counts nothing as unexplained (the rest is clutter), and
        one with nothing in clear view and nothing explained is no evidence either way.
        A frame is bad on its own (a kidnap shows at once) when at least three
        detections' worth of score arrived and their score-weighted mean squared
        residual, each clipped at the crossover, reaches ``BAD_FRAME_FIT``: a false
        detection costs at most the crossover squared (about 14.5 at 2 deg), so it takes
        mostly contradicting detections, and (with the unseen-object check on) at least
        half of the objects in the estimate's clear view going unreported in that frame:
        a burst of clutter leaves those reported.
        """
        obs = self.last_observation
        top = raw.hypotheses[0] if raw.hypotheses else None
        self._frame_misfit = False
        if obs is None or obs.empty:
            return  # (nor does a frame without detections say what is in view)
        self._sees_nothing = False
        if top is None or top.std_xy_m > FIT_MAX_SPREAD_M:
            return
        row = self._vis.row(raw.x, raw.y) if self._vis is not None else None
        if self.unseen is not None:
            self.unseen.update(raw.x, raw.y, raw.theta_rad, obs, row)
            if self.unseen.contradicted and self._place_is_unique(raw):
                # A stale map: the objects are moved or gone; the moved ones explain no
                # detection any more. A fixture (a door, a window) is never taken for
                # moved, only for gone: it stays in the sensor model (unseen.forgive).
                moved = int(self.unseen.moved.sum())
                self.unseen.forgive()
                if self.unseen.moved.sum() > moved:
                    self._exclude_moved()
                    obs = self.last_observation
                    assert obs is not None
        self.geometry.add(raw.x, raw.y, raw.theta_rad, obs, row)
        r = normalized_residuals(raw.x, raw.y, raw.theta_rad, obs, self.map, self._fit_config, row)
        if self._fit_scale != 1.0:
            r = r * self._fit_scale
        if self.config.clutter:
            g = obs.det_group
            cutoff = np.sqrt(2.0 * (obs.group_log_keep[g] - obs.group_log_floor[g]))
        else:
            cutoff = np.full(r.shape, PAPER_RESIDUAL_CUTOFF)
        score = obs.det_score
        total, good, explained_sq, clipped_sq = fit_sums(r, cutoff, score)
        fit = explained_sq / good if good > 0 else 9.0
        unexplained = 1.0 - good / total
        clipped = clipped_sq / total
        # A burst of false detections where the camera still reports what the pose
        # has in clear view is clutter, not a contradiction.
        missing = self.unseen is None or self.unseen.frame_contradicts
        bad_now = total >= 3.0 and clipped >= BAD_FRAME_FIT and missing
        if bad_now and self.config.heading_slack_deg > 0.0:
            bad_now = not self._turned_fits(raw, obs, row, score, cutoff, total)
        # One bad frame is a glitch a phone makes now and then (a burst of boxes while
        # turning, a person walking past); a kidnap stays bad.
        self._bad_run = self._bad_run + 1 if bad_now else 0
        bad = self._bad_run >= BAD_FRAMES_IN_A_ROW
        # This frame alone bad, or with at least two detections' worth of score failing
        # the gain's fit test (see _give_up_the_start).
        self._frame_misfit = bad_now or (
            total >= 2.0
            and (fit > self._gate.gain_fit or unexplained > self._gate.gain_unexplained)
        )
        a_share = FIT_SMOOTHING * min(1.0, total / FIT_FULL_SCORE)
        if self.unseen is not None:
            if self.unseen.frame_expected == 0 and good == 0.0:
                a_share = 0.0  # nothing in clear view, nothing explained: no evidence
                self._sees_nothing = True
            elif not self.unseen.frame_contradicts:
                unexplained = 0.0  # what the pose has in view was reported: clutter
        q = self.quality
        if q is not None:
            # The fit averages the explained detections, the share all of them: each
            # moves by the weight of what it averages.
            a_fit = FIT_SMOOTHING * min(1.0, good / FIT_FULL_SCORE)
            fit = q.fit + a_fit * (fit - q.fit)
            unexplained = q.unexplained + a_share * (unexplained - q.unexplained)
        contradicted = self.unseen is not None and self.unseen.contradicted
        never = contradicted and self.unseen is not None and self.unseen.never_reported
        resolved = self.unseen is not None and self.unseen.resolved
        self.quality = FitQuality(
            fit, unexplained, bad, contradicted=contradicted, never_reported=never,
            resolved=resolved,
        )  # fmt: skip

    def _exclude_from_models(self, objects: list[int]) -> None:
        """Take ``objects`` out of the filter's sensor model and the evidence tracker's."""
        self.sensor.exclude(objects)
        if self._tracker_sensor is not self.sensor:
            self._tracker_sensor.exclude(objects)

    def _protect(
        self,
        est: Estimate,
        raw: Estimate,
        w: NDArray[np.float64],
        share: float,
        fix_m: float,
        slide_m: float,
        *,
        gained: bool,
        streak: int,
    ) -> tuple[Estimate, float | None, bool]:
        """The protection radius of the gate's answer ``est`` (told, or ``gained`` on
        this frame), and a gain taken back for it: ``est`` (not converged when taken
        back), the radius (None while nothing is told or gained), and whether a gain
        was taken back. ``raw``: the frame's estimate before the gate; ``w``: the
        weights; ``share``: the alternatives' probability; ``fix_m``: the bearings'
        geometry's bound; ``slide_m``: the slide from the odometry; ``streak``: the
        gate's steady frames."""
        protection: float | None = None
        withheld = False
        if not (est.converged or gained):
            return est, protection, withheld
        reach = self.evidence.farthest_m(est.x, est.y) if self.evidence is not None else 0.0
        radius = protection_radius(self.x, self.y, w, est, self.rng, share, reach)
        # Errors the cloud cannot know of (a box's centre, an object drawn a little off)
        # repeat every frame; the geometry bounds what they can do (capped at the map's
        # size: a fix no geometry pins down is still somewhere on the map). Residuals
        # larger than the noise and bias explain, and a slide away from the odometry,
        # widen it (convergence.widened_radius).
        reach = self.geometry.reach_m(raw.x, raw.y, fix_m)
        radius = max(radius, min(max(fix_m, reach), self._map_span_m))
        fit = None if self.quality is None else self.quality.fit
        protection = widened_radius(radius, fit, slide_m)
        # Why a gain is taken back (ConvergenceGate.not_gained_because).
        withhold_because = "narrow frames"
        if gained:
            # ... and only where the recorded walk could have led (walked.py).
            wide_view = self.config.fov_deg >= SEPARATION_RINGS_FOV_DEG
            narrow = protection <= (WIDE_VIEW_GAIN_PROTECTION_M if wide_view else GAIN_PROTECTION_M)
            if not narrow:
                withhold_because = "wide radius"
            elif not self.walked.fits(self.map.free_space, est.x, est.y, est.theta_rad):
                narrow, withhold_because = False, "walk"
            if narrow and self.evidence is not None and not self.continuation.active:
                rings = self.config.fov_deg >= SEPARATION_RINGS_FOV_DEG
                sep = self.evidence.separation_m(est.x, est.y, est.theta_rad, rings)
                narrow = separation_allows_gain(max(sep.near_m, sep.far_m), protection)
                if not narrow:
                    withhold_because = "solution separation"
            self._narrow_frames = self._narrow_frames + 1 if narrow else 0
        if (
            gained
            and not self.continuation.active
            and self._narrow_frames >= NARROW_FRAMES
            and streak < TURNED_GAIN_FRAMES
            and self._turned_run
        ):
            # A fix facing otherwise than the last told ones, carried by the
            # odometry, waits until the gate has found it steady for longer
            # (app.localization.told_heading).
            self._gate.withhold("turned from the last fix")
            est = est.with_converged(False)
            withheld = True
        elif gained and not self.continuation.active and self._narrow_frames < NARROW_FRAMES:
            # A fix is gained only once its radius has been narrow (GAIN_PROTECTION_M)
            # for NARROW_FRAMES frames in a row; the gate tries again on the next
            # frame (ConvergenceGate.withhold). A fix the gate holds is not tested
            # again (held through a connector's stop, it is told on leaving it,
            # however its radius grew on the way), nor one that continues a fix or a
            # known start (app.localization.continuation).
            self._gate.withhold(withhold_because)
            est = est.with_converged(False)
            withheld = True
        return est, protection, withheld

    def _change_level(
        self, altitude: AltitudeReading | None, frame_s: float | None
    ) -> tuple[bool, tuple[float, float, float] | None]:
        """The level change this frame's altitude (or the view, without a barometer)
        makes (:meth:`~app.localization.floors.FloorTracker.apply`): whether a ride the
        belief was located for ended with it (``rode``), and for a ride it was not
        located for but placed the person in one connector for, that connector's stop
        (centre and radius, :meth:`~app.localization.floors.FloorTracker.pinned_stop`;
        else None)."""
        rode = False
        pinned: tuple[float, float, float] | None = None
        if self.floors is None:
            return rode, pinned
        told = self.estimate
        fix = self._last_fix
        if self._gate.held and told.converged and told.protection_m is not None:
            fix = (told.x, told.y, told.protection_m)
        self.x, self.log_w, contradicted = self.floors.apply(
            self.x, self.y, self.log_w, altitude, self.rng, fix, frame_s
        )
        if self.floors.changed:
            self._last_fix = None  # on the level left
        if contradicted:
            self._restart_global(after_ride=True)
        self.log_w = self.floors.rule_out_levels(self.x, self.log_w)
        if not contradicted and self.floors.changed:
            self._rode(self.floors.shift_x_m)
            # The gate's last estimate rides along too: a fix held through a ride the
            # barometer counted is no jump (without a barometer the view moves the
            # belief, and a held fix is tested afresh on the new floor: _step).
            self._gate.shift_x(self.floors.shift_x_m)
            if self.evidence is not None:
                # The exit is a known start only for a belief that was located as
                # the ride began: a cloud that had lost the person in the lift car
                # (its view blocked) rode along wherever it was, and a prior there
                # would rule out the true exit (measured through a 180-degree camera
                # on the venue suite: a fix 4.5 m off, gained after a lift ride).
                if self.floors.first_change:
                    self._located_at_ride = self._gate.held
                rode = self._located_at_ride
            if not rode:
                # Not located, but placed in one connector by a belief that rode it:
                # its whole stop (not the cloud's point in it) is where they are.
                pinned = self.floors.pinned_stop(self.x, self.y, self.weights)
        return rode, pinned

    def _leave_connector(
        self,
        raw: Estimate,
        rode: bool,
        pinned: tuple[float, float, float] | None,
        odometry: Odometry | None,
    ) -> None:
        """After :meth:`_change_level`: a ride's exit as a known start (``rode``: the
        belief was located as it began; ``pinned``: it was not, but placed the person in
        that connector's stop), and without a barometer, a level change the view made
        (:meth:`_follow_blind_level`); ``raw`` is this frame's estimate."""
        if pinned is not None:
            # The person left that connector: its stop is a fix to carry along, and the
            # first fix out of it continues it (the belief's heading rode along).
            cx, cy, radius = pinned
            self.geometry.offer_fix((cx, cy, raw.theta_rad), radius)
            self.continuation.rode_pinned()
            if self.evidence is not None:
                # ... and for the evidence tracker a known start of the stop's size,
                # whatever the heading (the belief was not located): a place the
                # walk since would have begun outside the stop is no alternative.
                # (Traced on the venue suite through a 66-degree camera: a look-alike
                # 2 m away took a fix away for over 30 s after such a ride, where the
                # floor's own map, started at the exit, never considered it.)
                self.evidence.set_prior(
                    InitialPose(cx, cy, raw.theta_rad, radius * PINNED_START_STDS, math.pi),
                    start=(raw.x, raw.y, raw.theta_rad),
                    drift=self.config.trans_noise_frac,
                )
        if rode:
            self._start_at_ride_exit(raw)
        self._follow_blind_level(raw, odometry)

    def _follow_blind_level(self, raw: Estimate, odometry: Odometry | None) -> None:
        """Without a barometer the belief changes level by itself (particles in a stop
        take its connector, and what is seen decides). When this frame's estimate ``raw``
        is on another level than the last answer's, at the same place of the level's map
        (a lift car is one on every floor), the person rode, and the filter's
        walk-bound parts follow as after a ride the barometer counted: the bearings'
        geometry moves with the estimate (``BearingGeometry.shift_x``), the odometry's
        checks and the told heading start again, and the evidence tracker starts afresh
        at the new floor (its alternatives, and a known start given on the floor left,
        were places in the plane of that floor), its search coming at the base interval
        until the next fix, as after a ride.

        Before, the estimate's jump of a level's width cleared the geometry and left its
        fix downstairs ("weak geometry" for seconds on leaving a lift: venue suite
        without a barometer), and a known start on the Ground Floor swapped every step
        of a belief that the First Floor's view had moved up straight back down: a
        session started at a known pose never left the floor it started on.
        """
        floors = self.floors
        if floors is None or not floors.blind:
            return
        layout = self.map.layout
        last = self.estimate
        was, now = layout.level_of(last.x), layout.level_of(raw.x)
        if was == now:
            return
        dx = float(layout.offsets(now) - layout.offsets(was))
        moved = 0.0 if odometry is None else hypot(odometry.forward_m, odometry.left_m)
        if hypot(raw.x - dx - last.x, raw.y - last.y) > moved + GEOMETRY_JUMP_M:
            return  # another place altogether, not a ride
        self._rode(dx)
        self._last_fix = None  # on the level left
        if last.converged:
            self._start_at_ride_exit(raw)

    def _rode(self, dx_m: float) -> None:
        """The person rode to another level, ``dx_m`` across the filter's plane (counted
        by the barometer, or without one seen): what the walk built follows or starts
        again.

        Until the next fix a gain's search comes at the base interval
        (``_search_at_base``), whether the belief was located as the ride began or not.
        Before, only a located ride and one the view made asked for it, and a ride the
        barometer counted for a belief not located kept the quiet searches' lengthened
        interval: traced on the venue suite (66-degree camera, PDR, seed 7), 4.4 s of
        "not sure" after the lift with every test of the gain passed but the search."""
        self._search_at_base = True
        # The fix the bearings' geometry gave rides along with the person.
        self.geometry.shift_x(dx_m)
        self.odometry_check.reset()  # the ride is no walk the odometry saw
        self.told_heading.reset()
        self.walked.reset()
        if self.evidence is not None:
            # The alternatives were carried by the walk's odometry, not the ride: none
            # of them rode along. The next search looks afresh, at what the ride says:
            # the person is where this connector let them off.
            self.evidence.reset()

    def _start_at_ride_exit(self, raw: Estimate) -> None:
        """A ride the belief was located for ended at ``raw``: a look-alike place
        elsewhere on the new level (the top of the other escalator) is no alternative
        for someone who just rode this connector, so the exit is a known start, as loose
        as a stop is wide (its prior odds exclude places far from it, as a known
        start's do). (Called after :meth:`_rode`, which asks for the gain's search at
        the base interval until the next fix.)"""
        if self.evidence is not None:
            self.evidence.set_prior(
                InitialPose(raw.x, raw.y, raw.theta_rad, RIDE_START_STD_M, RIDE_START_STD_RAD)
            )

    def _exclude_moved(self) -> None:
        """Take the objects the unseen-object check forgave as moved out of the sensor
        model, and make the frames it holds again without them (the evidence tracker's
        window and this frame's observation), as a checkpoint's round trip would."""
        assert self.unseen is not None
        self._exclude_from_models(np.flatnonzero(self.unseen.moved).tolist())
        if self.evidence is not None:
            self.evidence.reobserve()
        if self.last_observation is not None:
            columns = observation_columns([self.last_observation])
            self.last_observation = self.sensor.observations_from_columns(columns)[0]

    def _blame_the_slide(self, raw: Estimate) -> None:
        """A held fix was let go for sliding off the odometry: if, without one movable
        object, the place that best explains the evidence tracker's window goes back
        to where the odometry carried the fix, take that object for moved since the map
        was drawn, weigh on without it, and move half the cloud by the rigid motion
        from the full place to the one without it (the frames after choose).

        Blamed: of the objects whose absence moves the place at least
        ``SLIDE_BLAME_M`` and at least half that way towards the carried fix, the one
        that leaves it nearest the carried fix; nothing when the place let go lies more
        than ``SLIDE_BLAME_SPAN_M`` from it (a jump, not a drag)."""
        if self.unseen is None or self.evidence is None:
            return
        carried = self.odometry_check.carried_xy()
        if carried is None:
            return
        cx, cy = carried
        full, slides = self.evidence.places_without(raw.x, raw.y, raw.theta_rad)
        fx, fy, ft = full
        off_m = hypot(fx - cx, fy - cy)
        if off_m > SLIDE_BLAME_SPAN_M:
            return
        best: tuple[float, int, tuple[float, float, float]] | None = None
        for obj, (sx, sy, st) in slides:
            moved_m = hypot(sx - fx, sy - fy)
            left_m = hypot(sx - cx, sy - cy)
            toward = moved_m >= SLIDE_BLAME_M and off_m - left_m >= 0.5 * moved_m
            if toward and (best is None or left_m < best[0]):
                best = (left_m, obj, (sx, sy, st))
        if best is None:
            return
        _, culprit, (sx, sy, st) = best
        self.unseen.take_moved(culprit)
        self._exclude_moved()
        # Its detections are clutter from now on, everywhere: the fit drops, which is
        # no kidnap (augmented MCL would inject where the boxes point). The estimates
        # it dragged are no anchors for the slide test any more, and the gain's search
        # comes at the base interval until the next fix (_weigh_alternatives).
        self._recovery.reset()
        self.odometry_check.reset()
        self._search_at_base = True
        # (The rigid motion written out, not alternatives.carry: the same motion, but
        # carry's arithmetic rounds otherwise, and the results quoted in the CHANGELOG
        # were measured with this.)
        turn = st - ft
        c, s = math.cos(turn), math.sin(turn)
        half = slice(0, None, 2)
        dx, dy = self.x[half] - fx, self.y[half] - fy
        self.x[half] = sx + c * dx - s * dy
        self.y[half] = sy + s * dx + c * dy
        self.theta[half] = wrap_angle(self.theta[half] + turn)

    def _place_is_unique(self, raw: Estimate) -> bool:
        """Whether the place is the only one that explains what was seen (a global
        search of the last ``UNIQUE_SEARCH_FRAMES`` frames found no alternative, none is
        tracked, and the last frame's fit was good), known within
        ``FORGIVE_PROTECTION_M``, and this frame's estimate ``raw`` is not sliding off
        the odometry (by more than ``FORGIVE_SLIDE_M``). An object in clear view that
        goes unreported there has been moved or taken away since the map was drawn, and
        is no sign of another place (unseen.UnseenObjects.forgive).

        The place is the told fix of the last frame, or, before the first fix since the
        filter started from what it was given (a global start, a restart, a ride it
        could not make), this frame's candidate ``raw`` (:meth:`_candidate_radius_m`,
        with the gain's fit): a removed object that comes into view before the first
        fix would otherwise keep that fix from ever being gained (the contradiction
        blocks the gain, and only a told fix could forgive it; measured on the phone
        suite's stale office at 360 deg: 20 s and more at 0.1 m from the truth with no
        alternative, "not sure"). Once a fix has been told, only by a candidate within
        ``FORGIVE_PROTECTION_M`` of where the last one was told (and within its radius,
        grown by the walk since): elsewhere an object that took a fix away, or keeps one
        from coming back, is evidence against that place, and a candidate forgiving it
        there took a look-alike corridor 7 m away for the truth (measured on the same
        suite: 2 -> 23 confidently-wrong frames); at the told place itself it is the
        object the told fix would have forgiven, had its radius been a little narrower
        or the search's last look a little more recent. Nor by a candidate the estimate
        has only just jumped to (SETTLED_CANDIDATE_FRAMES)."""
        ev = self.evidence
        q = self.quality
        est = self.estimate
        if not (
            ev is not None
            and ev.count == 0
            and ev.searched_ago is not None
            and ev.searched_ago <= UNIQUE_SEARCH_FRAMES
            and q is not None
            and not q.bad_frame
            and self.odometry_check.slide_m(raw.x, raw.y) <= FORGIVE_SLIDE_M
        ):
            return False
        if est.converged:
            return (
                est.protection_m is not None
                and est.protection_m <= FORGIVE_PROTECTION_M
                and q.fit <= self._gate.hold_fit
            )
        gate = self._gate
        last = self._last_fix
        continues = last is not None and hypot(raw.x - last[0], raw.y - last[1]) <= min(
            last[2], FORGIVE_PROTECTION_M
        )
        return (
            (not self._told_since_start or continues)
            and self._settled_frames >= SETTLED_CANDIDATE_FRAMES
            and raw.converged
            and q.fit <= gate.gain_fit
            and q.unexplained <= gate.gain_unexplained
            and self._candidate_radius_m(raw) <= FORGIVE_PROTECTION_M
        )

    def _candidate_radius_m(self, raw: Estimate) -> float:
        """A protection radius for the untold estimate ``raw``, asked without drawing from
        the filter's generator or moving the geometry's carried fix: its heaviest
        cluster's (:func:`~app.localization.convergence.cluster_radius`) or the bearings'
        geometry's (:meth:`~app.localization.dilution.BearingGeometry.bound_m`),
        whichever is wider."""
        return max(cluster_radius(raw), self.geometry.bound_m(raw.x, raw.y))

    def _turned_fits(
        self,
        raw: Estimate,
        obs: Observation,
        row: NDArray[np.bool_] | None,
        score: NDArray[np.float64],
        cutoff: NDArray[np.float64],
        total: float,
    ) -> bool:
        """Whether the estimate, its heading turned by up to ``config.heading_slack_deg``
        (steps of ``SLACK_STEP_DEG``), explains the frame (``config.heading_slack_deg``
        says why); runs only on a frame that would otherwise be bad."""
        slack = self.config.heading_slack_deg
        for turn_deg in np.arange(-slack, slack + 1e-9, SLACK_STEP_DEG):
            theta = raw.theta_rad + np.radians(turn_deg)
            r = normalized_residuals(raw.x, raw.y, theta, obs, self.map, self._fit_config, row)
            r = r * self._fit_scale
            if float(np.add.reduce(score * np.minimum(r, cutoff) ** 2) / total) < BAD_FRAME_FIT:
                return True
        return False


@functools.lru_cache(maxsize=64)
def _log_sum_exp_of_zeros(n: int) -> float:
    """:func:`log_sum_exp` of ``n`` zeros (the same function on the same input, kept)."""
    return log_sum_exp(np.zeros(n))


def _rng_state_out(state: Mapping[str, Any]) -> dict[str, Any]:
    """A generator's state with its integers wider than 63 bits as decimal text (PCG64
    keeps 128-bit ones): a checkpoint's serializer holds at most 64 bits, as do most
    JSON readers."""
    inner = {
        k: str(v) if isinstance(v, int) and v.bit_length() > 63 else v
        for k, v in state["state"].items()
    }
    return {**state, "state": inner}


def _rng_state_in(state: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`_rng_state_out` undone (checkpoints of format 2 and older hold integers)."""
    inner = {k: int(v) if isinstance(v, str) else v for k, v in state["state"].items()}
    return {**state, "state": inner}


def fit_sums(
    r: NDArray[np.float64], cutoff: NDArray[np.float64], score: NDArray[np.float64]
) -> tuple[float, float, float, float]:
    """A frame's fit sums (:meth:`ParticleFilter._update_fit`): the detections' total
    score, the score of those explained (residual ``r`` within ``cutoff``), their
    score-weighted squared residuals, and every detection's score-weighted squared
    residual clipped at the cutoff. Compiled (:func:`_fit_sums_compiled`): numpy's
    eight small calls cost about 8 us a frame; numpy's (:func:`fit_sums_reference`)
    beyond ``PAIRWISE_BLOCK`` detections."""
    if r.shape[0] > PAIRWISE_BLOCK:
        return fit_sums_reference(r, cutoff, score)
    return _fit_sums_compiled(r, cutoff, score)


def fit_sums_reference(
    r: NDArray[np.float64], cutoff: NDArray[np.float64], score: NDArray[np.float64]
) -> tuple[float, float, float, float]:
    """:func:`fit_sums` in numpy (the compiled form is held to it to the last bit)."""
    explained = r <= cutoff
    add = np.add.reduce  # .sum() without its Python wrapper
    return (
        float(add(score)),
        float(add(score[explained])),
        float(add(score[explained] * r[explained] ** 2)),
        float(add(score * np.minimum(r, cutoff) ** 2)),
    )


@njit(cache=True, nogil=True)
def _fit_sums_compiled(r, cutoff, score):  # fmt: skip  # pragma: no cover - compiled
    """:func:`fit_sums_reference` for at most ``PAIRWISE_BLOCK`` detections: the same
    products (``x ** 2`` is numpy's ``x * x``; ``np.minimum`` keeps a NaN of either
    side), each sum numpy's pairwise one (the explained ones' over them alone, in turn)."""
    n = r.shape[0]
    kept = np.empty(max(n, 1))
    kept_sq = np.empty(max(n, 1))
    clipped_sq = np.empty(max(n, 1))
    m = 0
    for i in range(n):
        ri = r[i]
        ci = cutoff[i]
        if ri <= ci:
            kept[m] = score[i]
            kept_sq[m] = score[i] * (ri * ri)
            m += 1
        low = ri if (ri < ci or ri != ri) else ci
        clipped_sq[i] = score[i] * (low * low)
    return (
        pairwise_sum(score, n), pairwise_sum(kept, m), pairwise_sum(kept_sq, m),
        pairwise_sum(clipped_sq, n),
    )  # fmt: skip


def warm_up() -> None:
    """Compile every numba kernel now (or load it from the disk cache).

    Runs each compiled path once on a tiny map, so no request waits for a compiler:
    both sensor configurations, motion with and without odometry (and a move long
    enough for the wall test), resampling, clustering, KLD-sampling, the residual
    check, the evidence window's scoring and the visibility grid's rows.
    """
    from app.maps.model import parse_map

    tiny = parse_map(
        {
            "name": "warmup",
            "walls": [
                {"x1": 0, "y1": 0, "x2": 2, "y2": 0},
                {"x1": 2, "y1": 0, "x2": 2, "y2": 2},
                {"x1": 2, "y1": 2, "x2": 0, "y2": 2},
                {"x1": 0, "y1": 2, "x2": 0, "y2": 0},
            ],
            "objects": [{"class": "door", "x": 2, "y": 1}],
        }
    )
    door = [Detection("door", 0.0, 1.0)]
    for cfg in (FilterConfig(particles=50), FilterConfig.paper(particles=50)):
        pf = ParticleFilter(tiny, cfg, rng=np.random.default_rng(0))
        pf.step(Odometry(0.5, 0.0, 0.0), door)
        pf.step(None, door)
        pf.resample()
        obs = prepare_observation(door, tiny, cfg)
        normalized_residuals(1.0, 1.0, 0.0, obs, tiny, cfg)
        compass = CompassReading(0.0, 0.1)
        window = sensor_kernel.pack_window([((0.0, 0.0, 0.0), obs, compass)])
        pf.sensor.window_log_likelihood(pf.x, pf.y, pf.theta, window)
        pf.sensor.pattern_search(pf.x[:2], pf.y[:2], pf.theta[:2], PATTERN, 0.1, 0.1, 1, window)
        est = estimate_pose(pf.x, pf.y, pf.theta, pf.weights, rng=pf.rng, max_points=10)
        protection_radius(pf.x, pf.y, pf.weights, est, pf.rng)
        tiny.visibility.row(1.0, 1.0)  # a cell's row unpacked (the fit check's, the narrator's)
        kld_sample_size(pf.x, pf.y, pf.theta, pf.weights, 10, 50)
    # The unseen-object check's answer from its counts alone (a restored session's), its
    # learnt miss rates, and a checkpoint from before the misses were weighed restored;
    # not an assert, which python -O would strip with the compile.
    unseen = UnseenObjects(tiny, FilterConfig())
    _ = unseen.contradicted, unseen.miss_rates()
    unseen.restore({k: v for k, v in unseen.checkpoint().items() if k != "miss"})
    # The narrow camera's ridge search of the protection radius (dilution._ridge).
    ridge_points = tuple(np.array([v]) for v in (0.0, 0.0, 2.0, 1.0, 1.0))
    _ = BearingGeometry(tiny, FilterConfig(fov_deg=66.0))._ridge_m(
        ridge_points, 0.0, 0.0, 1.0, 0.0, 0.5
    )
    warm_up_dilution()  # a frame's sums of the bearing geometry
    # The fit's sums, with the observation's scores as a step makes them and read-only.
    ones = np.ones(2)
    fit_sums(ones, ones, ones)
    scores = np.ones(2)
    scores.flags.writeable = False
    fit_sums(ones, ones, scores)
