"""The places the evidence tracker keeps, and how they are compared and carried.

An alternative place is a rigid motion (turn, shift x, shift y) of the anchor, the small
cloud drawn from the filter's main mode (:mod:`~app.localization.evidence`): carrying a
pose by it is :func:`carry`, finding the motion onto a pose is :func:`moves_onto`. Two
poses are the same place within ``distinct_m`` and ``distinct_rad``
(:func:`same_place`, :func:`near`, :func:`near_pairs`). :class:`EvidenceSettings` holds
the rates, sizes and thresholds of the tracker and of its search
(:mod:`~app.localization.search`).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.localization.types import Hypothesis
from app.maps.geometry import wrap_angle, wrap_deg


@dataclass(frozen=True)
class EvidenceSettings:
    """Rates, sizes and thresholds of the alternative-hypothesis bookkeeping."""

    #: Frames between global searches (1 s at 5 frames/s).
    search_every: int = 5
    #: With no alternative tracked, each search that finds none doubles the interval, up
    #: to this many frames (5 s): a converged walk through a building without look-alikes
    #: pays for a search every 5 s, not every second.
    max_search_every: int = 25
    #: Frames of history a search scores, chained back by the odometry.
    window: int = 10
    #: No search before this many frames: places fitted to a shorter history are often
    #: a metre off, and lose evidence for it before they are polished onto the spot.
    min_history: int = 6
    #: Score every ``window_stride``-th frame of the window.
    window_stride: int = 2
    #: Candidate poses per square metre of free space, and the bounds of their count.
    candidates_per_m2: float = 25.0
    min_candidates: int = 1_000
    max_candidates: int = 6_000
    #: Best candidates refined and scored on the window.
    shortlist: int = 32
    #: Jittered copies per coarse refinement round of the shortlist: (count, position
    #: std m, heading std rad).
    refine: tuple[tuple[int, float, float], ...] = ((16, 0.2, float(np.radians(5.0))),)
    #: The best ``finalists`` (distinct places) are then refined finely, and so is the
    #: main mode: a newcomer placed 0.2 m off would start several units of evidence
    #: behind a main mode that the filter has had time to centre.
    finalists: int = 6
    #: Pattern search that polishes a pose (the finalists, the main mode, every
    #: alternative): first steps (m, rad), halved this many times. Deterministic, so
    #: that the two sides of an exact symmetry land on exactly symmetric poses.
    polish_step_m: float = 0.25
    polish_step_rad: float = float(np.radians(4.0))
    polish_rounds: int = 8
    #: Particles of the anchor (each alternative carries a copy).
    particles: int = 150
    max_alternatives: int = 8
    #: Frames an alternative is tracked before it can take ``converged`` away.
    probation: int = 5
    #: Frames an alternative's place is polished every frame after it appears.
    young: int = 15
    #: A candidate within this log-evidence of the main mode over the window is kept.
    seed_llr: float = -6.0
    #: An alternative still tracked after ``rival_frames`` (10 s at 5 frames/s) has been
    #: weighed that long without being refuted: a look-alike, whose evidence of a few
    #: units either way is mostly the walk's repeated errors (step-counting odometry, a
    #: detector that misses a third of what is in view, a box's bias) rather than the
    #: place's. ``converged`` is gained against it only on ``1 / rival_weight`` times the
    #: evidence (held as before). Measured on the phone suite: a 66-degree camera, PDR
    #: odometry and a detector missing 30 % followed a corridor 7 m from the truth for
    #: 30 s; the true place, tracked all along, drifted to 0.15 % and a gain 7 m off,
    #: beyond its radius, followed. With the rule: none; availability elsewhere at most
    #: 0.03 lower (docs/results/phone.md).
    rival_frames: int = 50
    rival_weight: float = 0.5
    #: An alternative whose evidence against falls below this is dropped.
    drop_llr: float = -20.0
    #: An alternative this much more likely than the main belief replaces it.
    switch_llr: float = float(np.log(20.0))
    #: Frames of the main mode's walk kept to test a newcomer against (60 s).
    trail: int = 300
    #: Dropped alternatives remembered (while the main mode stays the same).
    max_graves: int = 32
    #: Distinct from the main mode (and from each other) beyond these.
    distinct_m: float = 1.0
    distinct_rad: float = float(np.radians(45.0))


DEFAULT_EVIDENCE = EvidenceSettings()


def log_mean_exp_rows(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """log of the mean of exp over each row, shape (A,); -inf for an all -inf row."""
    m = a.max(axis=1)
    safe = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return safe + np.log(np.exp(a - safe[:, None]).mean(axis=1))


class Trail:
    """The main mode's last ``size`` positions (x, y), oldest first, kept as flat doubles:
    a checkpoint (once a second) copies them as one buffer instead of walking 300
    pairs (43 us)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._xy = array("d")

    def append(self, x: float, y: float) -> None:
        xy = self._xy
        xy.append(x)
        xy.append(y)
        if len(xy) > 4 * self.size:  # drop the oldest now and then, not at every frame
            del xy[: len(xy) - 2 * self.size]

    def clear(self) -> None:
        del self._xy[:]

    def __len__(self) -> int:
        return min(len(self._xy) // 2, self.size)

    def points(self) -> NDArray[np.float64]:
        """The positions, shape (len, 2) (a copy)."""
        xy = self._xy
        kept = xy[-2 * self.size :] if len(xy) > 2 * self.size else xy
        return np.array(kept, dtype=np.float64).reshape(-1, 2)


def same_place(x: float, y: float, t: float, h: Hypothesis, st: EvidenceSettings) -> bool:
    """:func:`near` for one pose, in plain float arithmetic (it runs several times a
    frame, where numpy's overhead on scalars was most of its cost)."""
    turn = abs(wrap_deg(math.degrees(t - h.theta_rad)))
    return math.hypot(x - h.x, y - h.y) < st.distinct_m and math.radians(turn) < st.distinct_rad


def near(
    x: NDArray[np.float64] | float,
    y: NDArray[np.float64] | float,
    t: NDArray[np.float64] | float,
    h: Hypothesis,
    st: EvidenceSettings,
) -> NDArray[np.bool_]:
    """Whether poses are the same place as ``h`` (within ``distinct_m`` and ``_rad``)."""
    return (np.hypot(np.asarray(x) - h.x, np.asarray(y) - h.y) < st.distinct_m) & (
        np.abs(wrap_angle(np.asarray(t) - h.theta_rad)) < st.distinct_rad
    )


def near_pairs(
    x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64], st: EvidenceSettings
) -> NDArray[np.bool_]:
    """:func:`near` of every pose against every pose, shape (N, N): row ``i`` is
    ``near(x, y, t, pose i)``, with the same arithmetic (one call instead of one a
    pose)."""
    return (np.hypot(x[None, :] - x[:, None], y[None, :] - y[:, None]) < st.distinct_m) & (
        np.abs(wrap_angle(t[None, :] - t[:, None])) < st.distinct_rad
    )


def carry(
    moves: NDArray[np.float64],
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Poses carried by each rigid motion (turn, shift x, shift y), each shape (A, N)."""
    turn, sx, sy = moves[:, 0:1], moves[:, 1:2], moves[:, 2:3]
    c, s = np.cos(turn), np.sin(turn)
    return c * x - s * y + sx, s * x + c * y + sy, wrap_angle(t + turn)


def moves_onto(
    source: tuple[float, float, float],
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The rigid motions carrying the pose ``source`` onto each pose (x, y, t), (A, 3)."""
    sx, sy, st = source
    turn = wrap_angle(np.asarray(t) - st)
    c, s = np.cos(turn), np.sin(turn)
    return np.column_stack([turn, x - (c * sx - s * sy), y - (s * sx + c * sy)])
