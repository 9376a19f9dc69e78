"""The filter's sensor and motion models, as objects it is given.

Beluga (Ekumen's Monte Carlo localization library) builds a particle filter from a
motion model and a sensor model, each hiding its map, its noise and its arithmetic
behind a few calls; the filter only moves, weighs, estimates and resamples. The same
split here: :class:`~app.localization.filter.ParticleFilter` and
:class:`~app.localization.evidence.EvidenceTracker` receive a :class:`SensorModel` and
a :class:`MotionModel` (by default :class:`BearingSensorModel` and
:class:`OdometryMotionModel`, built from the map and the :class:`FilterConfig`), and
never call a compiled kernel with its long argument list themselves. The map's part of
those arguments (visibility bits, field of view, range, free space, walls) is made
once, when the model is built, instead of at every call.

Another detector (a model for a depth camera, say) or another odometry (one that
estimates its own scale) is another class with the same methods, handed to the filter.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.config import FilterConfig
from app.localization.motion import penalized, sample_motion
from app.localization.recovery import sample_from_observation
from app.localization.sensor import Observation, observations_from_columns, prepare_observation
from app.localization.sensor_kernel import ObservationWindow
from app.localization.types import Detection, Odometry
from app.maps.model import SemanticMap
from app.maps.visibility import VisibilityGrid

#: The filter weighs its particles with an object a candidate for a detection up to this
#: many bearing standard deviations beyond the field of view's edges. An object at the
#: edge is seen from the person's pose; from a pose a decimetre ahead (the object's
#: bearing a little wider) a hard edge puts it out of view and calls its detection
#: clutter, while a pose behind keeps it in view (and is not charged for what it sees
#: that the camera does not report: the model weighs reported objects only), so a narrow
#: camera's cloud sits behind the person, and a phone's step length is learnt short
#: (app.localization.odometry_bias). Measured on the office suite through a 66-degree
#: camera with every phone effect off (3 walks, 963 frames, each weighed at the true
#: pose and 0.1 m ahead and behind it): a pose ahead lost 0.089 of log-likelihood a frame
#: with the hard edge, 0.048 with this one, a pose behind 0.013 with either; converged
#: estimates sat 0.099 m behind the person on average, 0.076 m with this edge. On the
#: venue suite it ended the PDR 66-degree walks' confidently-wrong frames (12 -> 0:
#: a fix that lagged 1.0-1.2 m on a step length learnt 5 % short). The evidence tracker
#: keeps the hard edge: with the soft one too, places one door apart along the door
#: corridor kept a 66-degree walk's fix back for most of it in 4 of 10 walks (seed 1:
#: 190 of its 265 frames within 0.5 m of the person, against 55 with the hard edge).
FOV_EDGE_STDS = 1.0

Array = NDArray[np.float64]
Poses = tuple[Array, Array, Array]
#: Poses with their window scores: x, y, theta, score.
ScoredPoses = tuple[Array, Array, Array, Array]
#: Per round of a jitter search, the offsets in x, y and heading, each shape (N, K).
Jitter = Sequence[tuple[Array, Array, Array]]


class SensorModel(Protocol):
    """What the filter asks of a sensor model: how likely each pose makes what was seen."""

    semantic_map: SemanticMap
    config: FilterConfig
    grid: VisibilityGrid | None

    def observe(self, detections: Sequence[Detection]) -> Observation:
        """This frame's detections in the form the other methods read (may be empty)."""
        ...

    def log_likelihood(self, x: Array, y: Array, theta: Array, obs: Observation) -> Array:
        """log P(Z | pose, M) for every pose, shape (N,)."""
        ...

    def window_log_likelihood(
        self, x: Array, y: Array, theta: Array, window: ObservationWindow
    ) -> Array:
        """Sum of log P over a window of recent frames, the poses chained back, shape (N,)."""
        ...

    def pattern_search(
        self,
        x: Array,
        y: Array,
        theta: Array,
        pattern: Array,
        step_m: float,
        step_rad: float,
        rounds: int,
        window: ObservationWindow,
    ) -> ScoredPoses:
        """Each pose polished onto the window by a pattern search (halving steps)."""
        ...

    def jitter_search(
        self, x: Array, y: Array, theta: Array, jitter: Jitter, window: ObservationWindow
    ) -> ScoredPoses:
        """Each pose moved to the best of its jittered copies over the window."""
        ...

    def sample_poses(self, n: int, obs: Observation, rng: np.random.Generator) -> Poses:
        """``n`` poses that explain one of the frame's detections each (obs not empty)."""
        ...

    def exclude(self, objects: Sequence[int]) -> None:
        """From now on, the map's ``objects`` explain no detection in what :meth:`observe`
        and :meth:`observations_from_columns` make (a stale map's objects the filter
        took for moved, :attr:`app.localization.unseen.UnseenObjects.moved`)."""
        ...

    def observations_from_columns(self, columns: Mapping[str, Any]) -> list[Observation]:
        """Observations kept as :func:`~app.localization.sensor.observation_columns`,
        as :meth:`observe` would make them now."""
        ...


class MotionModel(Protocol):
    """What the filter asks of a motion model: where each pose goes, and whether it can."""

    def sample(
        self,
        x: Array,
        y: Array,
        theta: Array,
        odometry: Odometry | None,
        rng: np.random.Generator,
        out: Array | None = None,
        steps: int = 1,
    ) -> Poses:
        """New poses after one noisy step of ``odometry`` (None: unknown motion) that
        adds up ``steps`` frames' motion (their noise floors add up too)."""
        ...

    def weigh_moves(
        self, x0: Array, y0: Array, x1: Array, y1: Array, log_w: Array
    ) -> tuple[Array, bool]:
        """``log_w`` with every impossible move (through a wall, off the free space) at
        -inf, and whether any weight is left."""
        ...


class BearingSensorModel:
    """The bearing-only semantic sensor model (paper, eq. 3, with this project's
    extensions: clutter floor, visibility, field of view, detector classes), run by the
    compiled kernels of :mod:`~app.localization.sensor_kernel`."""

    def __init__(
        self,
        semantic_map: SemanticMap,
        config: FilterConfig,
        grid: VisibilityGrid | None,
        fov_margin_deg: float = 0.0,
    ) -> None:
        """``fov_margin_deg``: how far beyond each edge of the field of view an object
        is still a candidate for a detection (the soft edge of :data:`FOV_EDGE_STDS`)."""
        self.semantic_map = semantic_map
        self.config = config
        self.grid = grid
        self.fov_margin_deg = fov_margin_deg
        widened = min(360.0, config.fov_deg + 2.0 * fov_margin_deg)
        candidates = config if widened == config.fov_deg else replace(config, fov_deg=widened)
        self._setup = sensor_kernel._sensor_setup(semantic_map, candidates, grid)
        self._free = sensor_kernel._free_space_setup(semantic_map)
        self._seed_std_rad = config.bearing_std_rad("")
        #: The objects excluded (sorted indices, :meth:`exclude`).
        self.excluded: tuple[int, ...] = ()

    def observe(self, detections: Sequence[Detection]) -> Observation:
        return prepare_observation(detections, self.semantic_map, self.config, self.excluded)

    def exclude(self, objects: Sequence[int]) -> None:
        self.excluded = tuple(sorted({int(o) for o in objects}))

    def observations_from_columns(self, columns: Mapping[str, Any]) -> list[Observation]:
        return observations_from_columns(columns, self.semantic_map, self.config, self.excluded)

    def log_likelihood(self, x: Array, y: Array, theta: Array, obs: Observation) -> Array:
        return sensor_kernel.likelihood_with(self._setup, x, y, theta, obs)

    def window_log_likelihood(
        self, x: Array, y: Array, theta: Array, window: ObservationWindow
    ) -> Array:
        return sensor_kernel.window_likelihood_with(self._setup, x, y, theta, window)

    def pattern_search(
        self,
        x: Array,
        y: Array,
        theta: Array,
        pattern: Array,
        step_m: float,
        step_rad: float,
        rounds: int,
        window: ObservationWindow,
    ) -> ScoredPoses:
        return sensor_kernel.pattern_search_with(
            self._free, self._setup, x, y, theta, pattern, step_m, step_rad, rounds, window
        )

    def jitter_search(
        self, x: Array, y: Array, theta: Array, jitter: Jitter, window: ObservationWindow
    ) -> ScoredPoses:
        free, setup = self._free, self._setup
        return sensor_kernel.jitter_search_with(free, setup, x, y, theta, jitter, window)

    def sample_poses(self, n: int, obs: Observation, rng: np.random.Generator) -> Poses:
        return sample_from_observation(n, obs, self.semantic_map, rng, self._seed_std_rad)


class OdometryMotionModel:
    """Body-frame odometry with noise growing with the motion
    (:mod:`~app.localization.motion`); moves through walls or off the free space are
    impossible."""

    def __init__(self, semantic_map: SemanticMap, config: FilterConfig) -> None:
        self.semantic_map = semantic_map
        self.config = config

    def sample(
        self,
        x: Array,
        y: Array,
        theta: Array,
        odometry: Odometry | None,
        rng: np.random.Generator,
        out: Array | None = None,
        steps: int = 1,
    ) -> Poses:
        return sample_motion(x, y, theta, odometry, self.config, rng, out=out, steps=steps)

    def weigh_moves(
        self, x0: Array, y0: Array, x1: Array, y1: Array, log_w: Array
    ) -> tuple[Array, bool]:
        return penalized(x0, y0, x1, y1, self.semantic_map, log_w)
