"""An honest summary of the particle cloud: its clusters and the best pose.

A weighted mean of all particles is meaningless when the belief has several modes
(a symmetric room gives mirror-image hypotheses; the mean between them is a place
where nobody is). So the cloud is split into clusters by greedy mode seeking:

1. histogram the remaining weight over coarse (x, y, heading) cells;
2. start at the heaviest cell's weighted mean and re-centre a few times on the
   particles within ``radius_m`` and ``heading_window_rad`` of the centre;
3. those particles form a hypothesis; remove them and repeat (up to three).

The pose reported is the heaviest cluster's weighted mean (circular mean for the
heading). :func:`estimate_pose` calls that pose converged when its cluster holds at
least ``min_mass`` of the weight and is tight in position and heading; that is only the
first condition: the ``converged`` a client is told, and the protection radius, are
:mod:`~app.localization.convergence`'s. :func:`with_alternatives` joins the alternatives
of :mod:`~app.localization.evidence` to the hypotheses.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.fastmath import FAST, hypot, sincos
from app.localization.resampling import systematic_indexes
from app.localization.types import Estimate, Hypothesis
from app.maps.geometry import wrap_rad
from app.maps.levels import LevelLayout
from app.maps.symmetry import twin_pose


@dataclass(frozen=True)
class ClusterSettings:
    """Thresholds of the clustering and of the ``converged`` test."""

    cell_m: float = 0.5
    heading_bins: int = 8
    radius_m: float = 1.0
    heading_window_rad: float = np.radians(45.0)
    max_hypotheses: int = 3
    min_mass: float = 0.9
    max_std_xy_m: float = 0.25
    max_std_theta_rad: float = np.radians(10.0)


DEFAULT_CLUSTERING = ClusterSettings()


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cluster(
    x, y, theta, cos_t, sin_t, w, cell_m, heading_bins, radius_m, heading_window_rad, out
):  # fmt: skip  # pragma: no cover - compiled
    """Greedy mode seeking (module docstring); fills ``out`` rows, returns how many.

    ``cos_t``, ``sin_t``: the headings' unit vectors (:func:`_unit_vectors`). Each row
    of ``out`` is (mass, mean x, mean y, circular mean heading, std x, std y, circular
    std) of one hypothesis, in the order found.
    """
    n = x.shape[0]
    bin_width = 2.0 * np.pi / heading_bins
    x0 = x.min()
    y0 = y.min()
    flat = np.empty(n, dtype=np.int64)
    cx = np.empty(n, dtype=np.int64)
    for i in range(n):
        cx[i] = int(np.floor((x[i] - x0) / cell_m))
    width = cx.max() + 1
    for i in range(n):
        cy = int(np.floor((y[i] - y0) / cell_m))
        ct = int(np.floor((theta[i] + np.pi) / bin_width))
        # Python's modulo only for a heading outside [-pi, pi): an integer division by
        # a number known at run time cost more than the rest of the loop (binning 2,000
        # particles took 13.0 us with it on every one, 5.5 us so; the same bins).
        if ct < 0 or ct >= heading_bins:
            ct %= heading_bins
        flat[i] = (cy * width + cx[i]) * heading_bins + ct
    hist = np.zeros(flat.max() + 1)
    remaining = w > 0.0
    members = np.zeros(n, dtype=np.bool_)
    near = np.zeros(n, dtype=np.bool_)
    cos_window = np.cos(heading_window_rad)
    r2 = radius_m * radius_m
    found = 0
    for _ in range(out.shape[0]):
        left = 0.0
        hist[:] = 0.0
        for i in range(n):
            if remaining[i]:
                left += w[i]
                hist[flat[i]] += w[i]
        if left < 0.01:
            break
        top = np.argmax(hist)
        for i in range(n):
            members[i] = remaining[i] and flat[i] == top
        mx, my, mc, ms = _centre(w, x, y, cos_t, sin_t, members)
        for _ in range(3):  # re-centre on the particles near the centre
            _near(x, y, cos_t, sin_t, remaining, mx, my, mc, ms, r2, cos_window, near)
            anyone = False
            same = True
            for i in range(n):  # near.any() and (near == members).all(), in one pass
                anyone = anyone or near[i]
                same = same and near[i] == members[i]
            if not anyone:
                break
            members[:] = near
            if same:
                break
            mx, my, mc, ms = _centre(w, x, y, cos_t, sin_t, members)
        _summary(w, x, y, cos_t, sin_t, members, out[found])
        found += 1
        for i in range(n):
            remaining[i] = remaining[i] and not members[i]
    return found


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _refine(
    x, y, cos_t, sin_t, w, rows, found, radius_m, heading_window_rad
):  # fmt: skip  # pragma: no cover - compiled
    """Re-summarize hypotheses found on a subsample over every weighted particle.

    Each hypothesis, in the order found, takes the particles not yet taken that lie
    within ``radius_m`` and ``heading_window_rad`` of its centre; its row of ``rows``
    becomes their weighted summary (no resampling noise left in the reported pose).
    """
    n = x.shape[0]
    remaining = w > 0.0
    members = np.zeros(n, dtype=np.bool_)
    cos_window = np.cos(heading_window_rad)
    r2 = radius_m * radius_m
    for h in range(found):
        mx, my, mt = rows[h, 1], rows[h, 2], rows[h, 3]
        mc, ms = np.cos(mt), np.sin(mt)
        _near(x, y, cos_t, sin_t, remaining, mx, my, mc, ms, r2, cos_window, members)
        weighed = False  # w[members].sum() > 0 (the weights are never negative)
        for i in range(n):
            weighed = weighed or (members[i] and w[i] > 0.0)
        if not weighed:
            continue  # keep the subsample's summary
        _summary(w, x, y, cos_t, sin_t, members, rows[h])
        for i in range(n):
            remaining[i] = remaining[i] and not members[i]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _near(x, y, cos_t, sin_t, remaining, mx, my, mc, ms, r2, cos_window, out):  # pragma: no cover
    """out = particles still remaining within sqrt(r2) of (mx, my) and the heading window
    (cosine at least ``cos_window``) around the direction (mc, ms)."""
    for i in range(x.shape[0]):
        dx = x[i] - mx
        dy = y[i] - my
        out[i] = (
            remaining[i] and dx * dx + dy * dy <= r2 and cos_t[i] * mc + sin_t[i] * ms >= cos_window
        )


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST, inline="always")
def _unit_vectors(theta):  # fmt: skip  # pragma: no cover - compiled
    """(cos theta, sin theta) arrays, vectorized (see :func:`fastmath.sincos`)."""
    cos_t = np.empty_like(theta)
    sin_t = np.empty_like(theta)
    for i in range(theta.shape[0]):
        sin_t[i], cos_t[i] = sincos(theta[i])
    return cos_t, sin_t


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _summary(w, x, y, cos_t, sin_t, members, row):  # fmt: skip  # pragma: no cover - compiled
    """row = (mass, mean x, mean y, circular mean heading, std x, std y, circular std)."""
    mass, mx, my, mcos, msin = _moments(w, x, y, cos_t, sin_t, members)
    vx = vy = 0.0
    for i in range(x.shape[0]):
        if members[i]:
            vx += w[i] * (x[i] - mx) ** 2
            vy += w[i] * (y[i] - my) ** 2
    r = min(max(np.hypot(mcos, msin), 1e-300), 1.0)
    row[0] = mass
    row[1] = mx
    row[2] = my
    row[3] = np.arctan2(msin, mcos)
    row[4] = np.sqrt(max(vx / mass, 0.0))
    row[5] = np.sqrt(max(vy / mass, 0.0))
    row[6] = np.sqrt(-2.0 * np.log(r))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _moments(w, x, y, cos_t, sin_t, members):  # fmt: skip  # pragma: no cover - compiled
    """Mass and weighted means of x, y, cos(theta), sin(theta) over the members."""
    mass = sx = sy = c = s = 0.0
    for i in range(x.shape[0]):
        if members[i]:
            mass += w[i]
            sx += w[i] * x[i]
            sy += w[i] * y[i]
            c += w[i] * cos_t[i]
            s += w[i] * sin_t[i]
    return mass, sx / mass, sy / mass, c / mass, s / mass


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _centre(w, x, y, cos_t, sin_t, members):  # fmt: skip  # pragma: no cover - compiled
    """Weighted mean position and mean heading direction (cos, sin) of the members."""
    _, mx, my, c, s = _moments(w, x, y, cos_t, sin_t, members)
    norm = max(np.hypot(c, s), 1e-300)
    return mx, my, c / norm, s / norm


@njit(cache=True, nogil=True, error_model="numpy")
def _clusters(x, y, theta, w, points, u0, cell_m, heading_bins, radius_m, heading_window_rad, out):  # fmt: skip  # noqa: E501  # pragma: no cover - compiled
    """:func:`estimate_pose`'s compiled part in one call: mode seeking on the particles
    themselves (``points`` 0), or on a systematic resample of ``points`` of them (offset
    ``u0``, equal weights) whose hypotheses are then re-summarized over every weighted
    particle (:func:`_refine`). Fills ``out`` like :func:`_cluster`; returns how many."""
    # Every particle's unit vectors once: the subsample takes its own from them (the
    # same numbers as computing them again from its headings, a call's worth less).
    cos_t, sin_t = _unit_vectors(theta)
    if points == 0:
        return _cluster(
            x, y, theta, cos_t, sin_t, w, cell_m, heading_bins, radius_m, heading_window_rad, out
        )
    idx = systematic_indexes(w, points, u0)
    cw = np.empty(points)
    cw[:] = 1.0 / points
    found = _cluster(
        x[idx], y[idx], theta[idx], cos_t[idx], sin_t[idx], cw,
        cell_m, heading_bins, radius_m, heading_window_rad, out,
    )  # fmt: skip
    if found:
        _refine(x, y, cos_t, sin_t, w, out, found, radius_m, heading_window_rad)
    return found


def estimate_pose(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    weights: NDArray[np.float64],
    settings: ClusterSettings = DEFAULT_CLUSTERING,
    ess: float = 0.0,
    rng: np.random.Generator | None = None,
    max_points: int = 1_000,
) -> Estimate:
    """Cluster the weighted particles and summarize the belief.

    With more than ``max_points`` particles and an ``rng``, the mode seeking runs on a
    systematic resample of ``max_points`` of them (equal weights), a tenth of the work
    at 10,000 particles; each hypothesis found is then summarized over every weighted
    particle near its centre, so the reported pose carries no resampling noise.

    Args:
        x, y, theta: particle poses, shape (N,), metres and radians.
        weights: normalized weights, shape (N,).

    Returns:
        The :class:`Estimate` (pose of the heaviest cluster, up to three hypotheses).
    """
    n = x.shape[0]
    sub = rng is not None and n > max_points
    rows = np.empty((settings.max_hypotheses, 7))
    found = (
        _clusters(
            np.ascontiguousarray(x, dtype=np.float64),
            np.ascontiguousarray(y, dtype=np.float64),
            np.ascontiguousarray(theta, dtype=np.float64),
            np.ascontiguousarray(weights, dtype=np.float64),
            max_points if sub else 0,
            rng.random() if rng is not None and sub else 0.0,
            float(settings.cell_m),
            int(settings.heading_bins),
            float(settings.radius_m),
            float(settings.heading_window_rad),
            rows,
        )
        if n
        else 0
    )
    if not found:  # no weight anywhere: say so honestly
        return Estimate(0.0, 0.0, 0.0, np.inf, np.inf, np.pi, False, (), n, ess)
    hyps = sorted(rows[:found].tolist(), key=lambda h: -h[0])
    mass, mx, my, mt, sx, sy, st = hyps[0]
    converged = (
        mass >= settings.min_mass
        and max(sx, sy) <= settings.max_std_xy_m
        and st <= settings.max_std_theta_rad
    )
    hypotheses = tuple(Hypothesis(h[1], h[2], h[3], h[0], hypot(h[4], h[5])) for h in hyps)
    return Estimate(mx, my, mt, sx, sy, st, bool(converged), hypotheses, n, ess)


def with_alternatives(
    estimate: Estimate, alternatives: list[Hypothesis], alternative_share: float
) -> Estimate:
    """The estimate's hypotheses joined with the alternatives (their weights the
    probabilities under the whole belief), heaviest first, at most three."""
    if not alternatives:
        return estimate
    scale = 1.0 - alternative_share
    own = [replace(h, weight=h.weight * scale) for h in estimate.hypotheses]
    merged = sorted(own + alternatives, key=lambda h: -h.weight)[:3]
    return replace(estimate, hypotheses=tuple(merged))


#: Two modes of a belief spread over a map's twin places are one when this close.
TWIN_MERGE_M = 1.0
TWIN_MERGE_RAD = float(np.radians(30.0))


def _same_mode(a: tuple[float, float, float], b: Hypothesis) -> bool:
    return (
        math.hypot(a[0] - b.x, a[1] - b.y) <= TWIN_MERGE_M
        and abs(wrap_rad(a[2] - b.theta_rad)) <= TWIN_MERGE_RAD
    )


def only_twins(
    estimate: Estimate,
    twins: Sequence[tuple[float, float, float]],
    layout: LevelLayout | None = None,
    mass: float = 0.9,
) -> bool:
    """Whether the belief is the heaviest mode and its twins (``twins`` and ``layout`` as
    in :func:`with_twins`) and nothing else: modes within a metre of one of them, each
    no wider than a metre, hold at least ``mass`` of the weight. Then only something
    from outside the view (a compass, a start) can tell the places apart."""
    if not twins or not estimate.hypotheses:
        return False
    top = estimate.hypotheses[0]
    places = [(top.x, top.y, top.theta_rad)] + [
        twin_pose(top.x, top.y, top.theta_rad, t, layout) for t in twins
    ]
    held = sum(
        h.weight
        for h in estimate.hypotheses
        if h.std_xy_m <= TWIN_MERGE_M and any(_same_mode(p, h) for p in places)
    )
    return held >= mass


def only_alike_levels(
    estimate: Estimate,
    groups: Sequence[Sequence[int]],
    layout: LevelLayout,
    mass: float = 0.9,
) -> bool:
    """Whether the belief is one place of the floor on two or more levels that look the
    same (``groups``: :func:`app.maps.symmetry.alike_levels` of the map whose ``layout``
    places its levels in the plane) and nothing else: modes at the heaviest one's place
    on the levels of its group, each no wider than a metre, hold at least ``mass`` of
    the weight, on at least two levels. Then neither turning nor walking on that floor
    tells which floor it is."""
    if not groups or not estimate.hypotheses:
        return False
    top = estimate.hypotheses[0]
    level = layout.level_of(top.x)
    group = next((g for g in groups if level in g), None)
    if group is None:
        return False
    pitch = layout.pitch_m
    places = {k: (top.x + (k - level) * pitch, top.y, top.theta_rad) for k in group}
    held, levels = 0.0, set()
    for h in estimate.hypotheses:
        k = layout.level_of(h.x)
        if k in places and h.std_xy_m <= TWIN_MERGE_M and _same_mode(places[k], h):
            held += h.weight
            levels.add(k)
    return held >= mass and len(levels) >= 2


def with_twins(
    estimate: Estimate,
    twins: Sequence[tuple[float, float, float]],
    layout: LevelLayout | None = None,
) -> Estimate:
    """The estimate's hypotheses spread over a map's twin places (``twins``: its turns
    onto itself, ``(cx, cy, angle_rad)``; :func:`app.maps.symmetry.rotational_symmetries`;
    ``layout``: the map's, when it has levels: each twin on its mode's level).

    Where nothing tells the twins apart, each mode is as likely at each of its twins:
    its weight is shared evenly between itself and its images turned about the centre,
    and modes that then fall together are one (their weights summed, the heavier's pose
    kept). Heaviest first, at most three."""
    if not twins or not estimate.hypotheses:
        return estimate
    share = 1.0 / (len(twins) + 1)
    spread: list[Hypothesis] = []
    for h in estimate.hypotheses:
        spread.append(replace(h, weight=h.weight * share))
        for twin in twins:
            x, y, theta = twin_pose(h.x, h.y, h.theta_rad, twin, layout)
            spread.append(replace(h, x=x, y=y, theta_rad=theta, weight=h.weight * share))
    merged: list[Hypothesis] = []
    for h in sorted(spread, key=lambda h: -h.weight):
        for i, m in enumerate(merged):
            if _same_mode((h.x, h.y, h.theta_rad), m):
                merged[i] = replace(m, weight=m.weight + h.weight)
                break
        else:
            merged.append(h)
    merged.sort(key=lambda h: -h.weight)
    return replace(estimate, hypotheses=tuple(merged[:3]))
