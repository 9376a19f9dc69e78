"""Odometry motion model: move every particle by the reported body-frame motion.

The motion (forward, left, turn) is perturbed per particle with zero-mean Gaussian
noise whose standard deviation grows with the motion and never falls below a floor,
in the spirit of *sample_motion_odometry* (Probabilistic Robotics, Table 5.6), but
parameterized directly in the body frame that the API's odometry uses (docs/API.md). The
Gaussian draws come from :func:`~app.localization.fastmath.fill_normal` (a tabulated
inverse CDF, four times faster here than numpy's sampler) and the particle loop is
compiled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import FilterConfig
from app.localization.fastmath import FAST, fill_normal, grid_cell, hypot, sincos
from app.localization.types import Odometry
from app.maps.geometry import GEOMETRY_EPS, crosses_wall
from app.maps.model import WALL_CLEARANCE_M, SemanticMap

#: When a frame carries no odometry the person may still have moved: diffuse this much.
NO_ODOMETRY_STD_M = 0.15
NO_ODOMETRY_STD_RAD = np.radians(10.0)
#: A guessed motion's translation noise grows by this share of its length, beyond the
#: unknown motion's own (:class:`GuessedMotion`).
GUESS_NOISE_FRAC = 0.5


@dataclass(frozen=True, slots=True)
class GuessedMotion(Odometry):
    """The motion of a frame without odometry, guessed (from the walk just before: a
    person walking on keeps walking): moved by as a mean, with the noise of unknown
    motion and more (:data:`GUESS_NOISE_FRAC`), since the person may as well have
    stopped or turned (:mod:`~app.localization.gap`)."""


#: Twice the free space's clearance from walls (see :meth:`SemanticMap.free_space`).
LONG_MOVE_M = 2 * WALL_CLEARANCE_M
#: The fastest a person on foot is taken to move (m/s): a brisk walk is under 2 m/s, a
#: blind pedestrian with a cane or a guide dog walks about 1 m/s, a moving walkway adds
#: under 1 m/s. A frame whose odometry covers more in the time since the previous frame
#: is no step the person took: a visual-inertial tracker relocalizing (ARKit and ARCore
#: move their world frame when they recognise a place again), a step counter counting a
#: stride twice, a stalled app's backlog.
MAX_SPEED_M_S = 3.0
#: ... and never less than this (m): frame times jitter, and a frame 0.05 s after the
#: last is no measure of a speed.
MIN_JUMP_M = 0.5


@njit(cache=True, nogil=True, fastmath=FAST, error_model="numpy")
def _move(x, y, theta, fwd, left, turn, std_t, std_r, noise, new_x, new_y, new_theta):  # fmt: skip
    """Apply the body-frame motion plus scaled standard-normal noise (3N,) to new arrays."""
    two_pi = 2.0 * np.pi
    n = x.shape[0]
    for i in range(n):
        f = fwd + std_t * noise[i]
        lft = left + std_t * noise[n + i]
        s, c = sincos(theta[i])
        new_x[i] = x[i] + c * f - s * lft
        new_y[i] = y[i] + s * f + c * lft
        t = theta[i] + turn + std_r * noise[2 * n + i]
        t = t - two_pi * np.floor((t + np.pi) / two_pi)
        new_theta[i] = np.pi if t <= -np.pi else t


def sample_motion(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    odometry: Odometry | None,
    config: FilterConfig,
    rng: np.random.Generator,
    out: NDArray[np.float64] | None = None,
    steps: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """New particle poses after one noisy odometry step (the inputs are not modified).

    Args:
        x, y, theta: particle poses, shape (N,), metres and radians.
        odometry: motion in the previous body frame, or None (unknown motion), or a
            :class:`GuessedMotion` (unknown motion about a mean).
        out: optional array of shape (3, N), each row C-contiguous and none an input, to
            write the new poses into (its rows are returned): saves stacking them.
        steps: frames the odometry adds up (a filter weighing every other frame): the
            noise floors, each frame's own, add up over them (``sqrt(steps)`` times).

    Returns:
        New (x, y, theta), each shape (N,); theta wrapped to (-pi, pi].
    """
    if odometry is None:
        fwd = left = turn = 0.0
        std_t, std_r = NO_ODOMETRY_STD_M, float(NO_ODOMETRY_STD_RAD)
    elif isinstance(odometry, GuessedMotion):
        fwd, left, turn = odometry.forward_m, odometry.left_m, odometry.turn_rad
        std_t = NO_ODOMETRY_STD_M + GUESS_NOISE_FRAC * hypot(fwd, left)
        std_r = float(NO_ODOMETRY_STD_RAD)
    else:
        dist = hypot(odometry.forward_m, odometry.left_m)
        floors = 1.0 if steps == 1 else math.sqrt(steps)
        std_t = config.trans_noise_frac * dist + config.trans_noise_floor_m * floors
        # (math.radians multiplies by the same pi / 180 as np.radians: the same bits)
        std_r = (
            config.rot_noise_frac * abs(odometry.turn_rad)
            + math.radians(config.rot_noise_floor_deg) * floors
        )
        fwd, left, turn = odometry.forward_m, odometry.left_m, odometry.turn_rad
    n = x.shape[0]
    noise = fill_normal(rng, 3 * n)
    new_x, new_y, new_theta = (np.empty(n), np.empty(n), np.empty(n)) if out is None else out
    _move(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        float(fwd), float(left), float(turn), float(std_t), float(std_r), noise,
        new_x, new_y, new_theta,
    )  # fmt: skip
    return new_x, new_y, new_theta


def implausible(odometry: Odometry | None, frame_s: float | None) -> bool:
    """Whether ``odometry``, lasting ``frame_s`` seconds (None: not known), moves faster
    than a person on foot (:data:`MAX_SPEED_M_S`, at least :data:`MIN_JUMP_M`): such a
    frame's motion is unknown, not that motion. Without the frame's duration nothing is
    implausible."""
    if odometry is None or frame_s is None or frame_s <= 0.0:
        return False
    reach = max(MAX_SPEED_M_S * frame_s, MIN_JUMP_M)
    return hypot(odometry.forward_m, odometry.left_m) > reach


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _crosses_a_wall(px, py, qx, qy, walls, eps):  # fmt: skip  # pragma: no cover - compiled
    """Whether segment p->q properly crosses a wall: :func:`segments_cross_walls`, one segment."""
    for w in range(walls.shape[0]):
        if crosses_wall(px, py, qx, qy, walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3], eps):
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy")
def _free_check(x0, y0, x1, y1, mask, ox, oy, res, long_sq, walls, eps, base, penalty):  # fmt: skip
    """In place: ``penalty`` = ``base`` plus the move's penalty (-inf off the free space
    or through a wall, else 0). Returns whether any result is finite."""
    rows, cols = mask.shape
    flat = mask.reshape(-1)
    inv = 1.0 / res
    finite = False
    for i in range(x1.shape[0]):
        cell, inside = grid_cell(x1[i], y1[i], ox, oy, inv, rows, cols)
        free = inside and flat[int(cell)]
        dx = x1[i] - x0[i]
        dy = y1[i] - y0[i]
        if free and dx * dx + dy * dy > long_sq:
            free = not _crosses_a_wall(x0[i], y0[i], x1[i], y1[i], walls, eps)
        penalty[i] = base[i] + (0.0 if free else -np.inf)
        finite = finite or np.isfinite(penalty[i])
    return finite


def penalized(
    x0: NDArray[np.float64],
    y0: NDArray[np.float64],
    x1: NDArray[np.float64],
    y1: NDArray[np.float64],
    semantic_map: SemanticMap,
    log_w: NDArray[np.float64],
) -> tuple[NDArray[np.float64], bool]:
    """``log_w`` plus each move's penalty (0 for a possible move, -inf for one that ends
    off the free space or crosses a wall) and whether any of it is finite, in one pass.

    Free space keeps a clearance of 0.1 m from every wall, so a move that starts and
    ends in free space can only cross a wall if it is longer than twice that
    (``LONG_MOVE_M``); only those are ray-tested.
    """
    fs = semantic_map.free_space
    out = np.empty(x1.shape[0])
    walls = np.ascontiguousarray(semantic_map.walls, dtype=np.float64).reshape(-1, 4)
    finite = _free_check(
        x0, y0, x1, y1, fs.mask, fs.origin_x, fs.origin_y, fs.resolution_m, LONG_MOVE_M**2,
        walls, GEOMETRY_EPS, np.ascontiguousarray(log_w, dtype=np.float64), out,
    )  # fmt: skip
    return out, bool(finite)


def compose_odometry(first: Odometry | None, then: Odometry | None) -> Odometry | None:
    """One odometry equal to moving by ``first`` and then by ``then`` (composition in SE(2)).

    ``then`` is expressed in the body frame reached after ``first``, so it is rotated by
    ``first``'s turn before the translations add up; the turns add (not wrapped, so a
    long turn keeps its size for the motion noise). Unknown motion (None) on either side
    makes the whole motion unknown.
    """
    if first is None or then is None:
        return None
    c, s = math.cos(first.turn_rad), math.sin(first.turn_rad)
    return Odometry(
        forward_m=float(first.forward_m + c * then.forward_m - s * then.left_m),
        left_m=float(first.left_m + s * then.forward_m + c * then.left_m),
        turn_rad=float(first.turn_rad + then.turn_rad),
    )
