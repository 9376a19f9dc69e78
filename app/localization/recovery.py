"""Recovery from a lost or kidnapped state: augmented MCL with sensor resetting.

Augmented MCL (Probabilistic Robotics, Table 8.3) keeps two running averages of the
measurement likelihood, a slow one ``w_slow`` and a fast one ``w_fast``. When the
fast one falls below the slow one, the observations stopped fitting the particles,
and a share ``max(0, 1 - w_fast / (threshold * w_slow))`` of the particles is replaced
with fresh ones (Thrun's rule with a dead band, ``threshold`` = 0.5, against the jitter
of noisy detections). The fresh particles are drawn from the current observation
(sensor resetting, Lenser & Veloso 2000): a position uniform over the free space, and
the heading that makes one detection point at a randomly chosen map object of its class.

The likelihood fed to the averages is the mean per observed class, exponentiated,
so that frames with many or few classes are comparable. A frame with no usable
detections is no evidence: it leaves the averages untouched and injects nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.localization.sensor import Observation
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap

#: Never replace more than this share of the particles in one frame.
MAX_INJECTION = 0.5


@dataclass
class AugmentedMCL:
    """The w_slow / w_fast bookkeeping of augmented MCL."""

    alpha_slow: float
    alpha_fast: float
    #: Dead band: inject only once w_fast falls below this share of w_slow, so the
    #: frame-to-frame jitter of noisy or cluttered detections never injects.
    threshold: float = 0.5
    w_slow: float = 0.0
    w_fast: float = 0.0

    def update(self, mean_log_likelihood_per_class: float) -> float:
        """Feed one frame's average likelihood; return the share of particles to inject."""
        w_avg = float(np.exp(mean_log_likelihood_per_class))
        if self.w_slow <= 0.0:  # first evidence: start both averages here
            self.w_slow = self.w_fast = w_avg
            return 0.0
        self.w_slow += self.alpha_slow * (w_avg - self.w_slow)
        self.w_fast += self.alpha_fast * (w_avg - self.w_fast)
        if self.w_slow <= 0.0:
            return 0.0
        ratio = self.w_fast / (self.threshold * self.w_slow)
        return float(min(max(1.0 - ratio, 0.0), MAX_INJECTION))

    def reset(self) -> None:
        self.w_slow = self.w_fast = 0.0


def sample_from_observation(
    n: int,
    obs: Observation,
    semantic_map: SemanticMap,
    rng: np.random.Generator,
    heading_noise_rad: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``n`` poses consistent with one detection each (sensor resetting).

    Args:
        obs: the frame's grouped detections (not empty).
        heading_noise_rad: standard deviation added to the derived heading.

    Returns:
        (x, y, theta), each shape (n,).
    """
    pts = semantic_map.free_space.sample(n, rng)
    x, y = pts[:, 0], pts[:, 1]
    # Detections drawn in proportion to their scores (inverse CDF of the scores); one
    # whose class has no object left in the session's map (each excluded,
    # BearingSensorModel.exclude) points at nothing, and a frame of only such
    # detections gives no heading.
    score = obs.det_score
    sizes = np.diff(obs.member_start)
    if not sizes.all():
        score = np.where(sizes[obs.det_group] > 0, score, 0.0)
        if not score.any():
            return x, y, rng.uniform(-np.pi, np.pi, n)
    cumulative = np.cumsum(score)
    k = np.searchsorted(cumulative, rng.random(n) * cumulative[-1], side="right")
    k = np.minimum(k, obs.det_cos.size - 1)
    g = obs.det_group[k]
    start = obs.member_start[g]
    count = obs.member_start[g + 1] - start
    obj = obs.members[start + (rng.random(n) * count).astype(np.int64)]
    towards = np.arctan2(semantic_map.object_xy[obj, 1] - y, semantic_map.object_xy[obj, 0] - x)
    theta = wrap_angle(towards - obs.det_bearing[k] + rng.normal(0.0, heading_noise_rad, n))
    return x, y, theta
