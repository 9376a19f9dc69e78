"""How far a compiled kernel may differ from its float64 reference: derived, not tuned.

The sensor kernel (:mod:`app.localization.sensor_kernel`) computes bearing geometry in
float32 with compiler liberties (fused multiply-add, reassociation, an approximate
reciprocal square root refined by one Newton step); its numpy reference
(:func:`app.localization.sensor.log_likelihood_reference`) works in float64. Which
instructions the compiler picks depends on the CPU numba targets (SSE2 only, AVX2,
AVX-512 ...), so the tests may not compare against what one machine happened to
produce: they compare against the bounds below, which hold for any correctly rounded
float32 arithmetic and follow from counting roundings. Each bound is first order in
the unit roundoff (its square terms are below 1e-13 here) and is used by every test
that holds a kernel to its reference.

Units: the *match* is the cosine of the bearing error, 1 for a perfect match (eq. 3);
log-likelihoods are natural logs (eq. 2); distances are metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from app.localization.config import FilterConfig
from app.localization.fastmath import SINCOS_MAX_ERROR, SOFTPLUS_MAX_ERROR
from app.localization.sensor import (
    SPREAD_MIN_R,
    Observation,
    candidate_mask,
    object_spread_sq,
    spread_match,
)
from app.maps.model import SemanticMap

#: Unit roundoff of float32 and float64 (round to nearest): |fl(a op b) - a op b| <= u |a op b|.
U32 = 2.0**-24
U64 = 2.0**-53

#: Relative error of the kernel's 1 / sqrt(s) in float32. On x86 the compiler may use the
#: hardware estimate (relative error at most 1.5 * 2^-12, the smallest guarantee of
#: RSQRTPS; AVX-512's estimate is better) refined by one Newton step, which leaves
#: 1.5 * (1.5 * 2^-12)^2 = 3.4 U32, plus the step's own four roundings (4 U32); a true
#: square root and division leave 2 U32. The bound takes the larger.
RSQRT_REL_ERROR = 1.5 * (1.5 * 2.0**-12) ** 2 + 4 * U32

#: Roundings in one match value that do not depend on the geometry, each counted as
#: an error of U32 on a unit-length quantity: the squared distance (2 products, 2 sums,
#: half of it reaches 1/sqrt: 2), the product by 1/sqrt (2, one per component), the
#: heading's cos and sin stored in float32 (2), the rotation's products and sums (4),
#: the detection's cos and sin stored in float32 (2), the final dot product (3).
MATCH_ROUNDINGS = 2 + 2 + 2 + 4 + 2 + 3


def match_error(
    coordinate_m: ArrayLike, distance_m: ArrayLike, unit_roundoff: float = U32
) -> NDArray[np.float64]:
    """Bound on |computed - exact| cosine of the bearing error towards one object.

    Args:
        coordinate_m: bound on the distance from the map origin of the particle plus
            that of the object (both are rounded where they lie, not where they meet).
        distance_m: particle-to-object distance. Close to an object its direction is
            ill-conditioned: the rounding of both positions (u * coordinate_m) turns
            the direction by up to that over the distance.
        unit_roundoff: U32 for the float32 kernel, U64 for a float64 one.
    """
    u = unit_roundoff
    coordinate = np.asarray(coordinate_m, dtype=np.float64)
    distance = np.maximum(np.asarray(distance_m, dtype=np.float64), 1e-9)
    direction = u * (coordinate + distance) / distance  # rounding of the two positions
    rsqrt = RSQRT_REL_ERROR if unit_roundoff == U32 else 2 * u
    # 1e-20 is added under the square root against division by zero: relative 1e-20 / d^2.
    return direction + MATCH_ROUNDINGS * u + rsqrt + 2 * SINCOS_MAX_ERROR + 0.5e-20 / distance**2


def log_likelihood_tolerance(
    x: ArrayLike,
    y: ArrayLike,
    theta: ArrayLike,
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    value: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """Bound on |kernel - reference| log-likelihood per particle, shape (N,).

    Detection k enters eq. 2 as ``weight * score * log_p`` with
    ``log_p = kappa * (match - 1) + log(1 - eps)``, or with the clutter floor
    ``log_floor + softplus(kappa * (match - 1) + ...)``; softplus has slope at most 1,
    so either way an error e in the best match moves log_p by at most kappa * e (plus
    softplus's own error). The best match is a maximum over the candidates (eq. 3):
    its error is at most the largest :func:`match_error` among the candidates that
    could win once rounded (those within their own error plus the winner's of the
    exact best); a movable object's with a place spread, :func:`spread_match_error`.
    The float64 sum over detections adds K + 2 roundings of ``value``.
    """
    px = np.atleast_1d(np.asarray(x, dtype=np.float64))
    py = np.atleast_1d(np.asarray(y, dtype=np.float64))
    th = np.atleast_1d(np.asarray(theta, dtype=np.float64))
    rows = semantic_map.visibility.visible(px, py) if config.visibility else None
    spread = object_spread_sq(semantic_map, config)
    bound = np.zeros(px.shape)
    cos_t, sin_t = np.cos(th)[:, None], np.sin(th)[:, None]
    for g in range(obs.group_kappa.size):
        objs = obs.members[obs.member_start[g] : obs.member_start[g + 1]]
        ox, oy = semantic_map.object_xy[objs, 0][None, :], semantic_map.object_xy[objs, 1][None, :]
        dx, dy = ox - px[:, None], oy - py[:, None]
        dist = np.maximum(np.hypot(dx, dy), 1e-12)
        coordinate = np.hypot(px, py)[:, None] + np.hypot(ox, oy)
        err = match_error(coordinate, dist)
        bx, by = (cos_t * dx + sin_t * dy) / dist, (cos_t * dy - sin_t * dx) / dist
        cand = candidate_mask(px, py, th, objs, semantic_map, config, rows)
        floor_err = SOFTPLUS_MAX_ERROR if np.isfinite(obs.group_log_floor[g]) else 0.0
        kappa = float(obs.group_kappa[g])
        spread_sq = spread[objs][None, :]
        if (spread_sq > 0.0).any():
            err = spread_match_error(err, coordinate, dist, kappa, spread_sq)
        for k in np.flatnonzero(obs.det_group == g):
            cos_err = obs.det_cos[k] * bx + obs.det_sin[k] * by
            match = np.where(
                cand, spread_match(cos_err, dist**2, np.array(kappa), spread_sq), -np.inf
            )
            win = np.argmax(match, axis=1)
            best = match[np.arange(px.size), win]
            could_win = cand & (match + err >= (best - err[np.arange(px.size), win])[:, None])
            worst = np.where(could_win, err, 0.0).max(axis=1)
            scale = obs.group_weight[g] * obs.det_score[k]
            bound += scale * (obs.group_kappa[g] * worst + floor_err)
    return bound + summation_rtol(obs.det_cos.size) * np.abs(np.asarray(value, dtype=np.float64))


def spread_match_error(
    cos_error: NDArray[np.float64],
    coordinate_m: NDArray[np.float64],
    distance_m: NDArray[np.float64],
    kappa: float,
    spread_sq: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Bound on a spread object's match error in the kernel (float32), given the bound
    ``cos_error`` on its cosine (:func:`match_error`); the cosine's where ``spread_sq``
    is 0. The match is 1 + r (cos - 1) + log(r) / (2 kappa) (sensor.spread_match), r =
    d^2 / (d^2 + kappa s^2): r's relative error rho comes from the squared distance (its
    coordinates rounded: 2 u (coordinate + d) / d, and 3 roundings), kappa s^2 rounded
    (u) and the sum and quotient (2 u), scaled by 1 - r; it moves r cos and 1 - r by
    r rho each and log(r) by rho. The log is the C library's (within 2 ulp: 2 u |log r|
    relative), times 1 / (2 kappa) rounded (2 u); the scaling of the unit vector (2),
    and the sums of the three parts (3) round once each on values within 2."""
    u = U32
    d = np.maximum(distance_m, 1e-9)
    d2 = d * d
    r = np.maximum(d2 / (d2 + kappa * spread_sq), SPREAD_MIN_R)
    rel_d2 = 2 * u * (coordinate_m + d) / d + 3 * u
    rho = (1.0 - r) * (rel_d2 + u) + 2 * u
    norm = np.abs(np.log(r)) / (2.0 * kappa)
    spread_err = r * cos_error + rho * (2.0 * r + 1.0 / (2.0 * kappa)) + 4 * u * norm + 10 * u
    return np.where(spread_sq > 0.0, spread_err, cos_error)


def summation_rtol(terms: int) -> float:
    """Relative difference between two float64 sums of the same ``terms`` numbers of one sign.

    Summed in different orders (or grouped differently), each sum is within
    (terms - 1) U64 of the exact one, after forming each term (a weight times a score
    times a log, 3 roundings); two such sums are within twice that. Every term of a
    log-likelihood is <= 0, so relative to the sum's magnitude.
    """
    return 2 * (max(terms - 1, 0) + 3) * U64


def candidate_flip_mask(
    x: ArrayLike,
    y: ArrayLike,
    theta: ArrayLike,
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
) -> NDArray[np.bool_]:
    """Particles for which float32 rounding may change which objects are candidates.

    The kernel decides "inside the field of view" from its float32 body-frame
    direction (error :func:`match_error`) and "within range" from a float32 squared
    distance; a particle with an object closer to either edge than that error may
    legitimately get a different candidate set from the reference, and with it a
    different likelihood. Tests leave these (rare) particles out and check they are rare.
    """
    px = np.atleast_1d(np.asarray(x, dtype=np.float64))
    py = np.atleast_1d(np.asarray(y, dtype=np.float64))
    th = np.atleast_1d(np.asarray(theta, dtype=np.float64))
    flip = np.zeros(px.shape, dtype=bool)
    if not config.visibility:
        return flip  # the paper's model: every object of the class is a candidate
    objs = semantic_map.object_xy[np.unique(obs.members)].reshape(-1, 2)
    if objs.shape[0] == 0:
        return flip
    dx = objs[None, :, 0] - px[:, None]
    dy = objs[None, :, 1] - py[:, None]
    dist = np.hypot(dx, dy)
    coordinate = np.hypot(px, py)[:, None] + np.hypot(objs[:, 0], objs[:, 1])[None, :]
    err = match_error(coordinate, dist)
    if config.fov_deg < 360.0:
        cos_half_fov = float(np.cos(np.radians(config.fov_deg) / 2.0))
        forward = (np.cos(th)[:, None] * dx + np.sin(th)[:, None] * dy) / np.maximum(dist, 1e-12)
        # + U32: the kernel compares against cos(fov / 2) stored in float32.
        flip |= (np.abs(forward - cos_half_fov) <= err + U32).any(axis=1)
    max_range_m = config.max_range_m
    if max_range_m is not None:
        # d^2 in float32 from rounded differences: 2 d * u (coordinate + d) + 3 u d^2,
        # against the float32 rounding of range^2.
        d2_err = 2 * dist * U32 * (coordinate + dist) + 3 * U32 * dist**2 + U32 * max_range_m**2
        flip |= (np.abs(dist**2 - max_range_m**2) <= d2_err).any(axis=1)
    return flip


def motion_position_tolerance(step_m: float, coordinate_m: float) -> float:
    """Bound on the motion kernel's position error against exact float64 motion.

    The body-frame step turns through :func:`~app.localization.fastmath.sincos`
    (error SINCOS_MAX_ERROR per factor, two factors per coordinate), then a float64
    multiply-add onto a coordinate.
    """
    return 2 * SINCOS_MAX_ERROR * step_m + 4 * U64 * (coordinate_m + step_m)
