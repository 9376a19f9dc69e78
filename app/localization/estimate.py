"""An honest summary of the particle cloud: clusters, the best pose, and ``converged``.

A weighted mean of all particles is meaningless when the belief has several modes
(a symmetric room gives mirror-image hypotheses; the mean between them is a place
where nobody is). So the cloud is split into clusters by greedy mode seeking:

1. histogram the remaining weight over coarse (x, y, heading) cells;
2. start at the heaviest cell's weighted mean and re-centre a few times on the
   particles within ``radius_m`` and ``heading_window_rad`` of the centre;
3. those particles form a hypothesis; remove them and repeat (up to three).

The pose reported is the heaviest cluster's weighted mean (circular mean for the
heading). ``converged`` is true only when that cluster holds at least
``min_mass`` of the weight and is tight in position and heading.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.fastmath import FAST, sincos
from app.localization.resampling import systematic_resample
from app.localization.types import Estimate, Hypothesis
from app.maps.geometry import wrap_angle


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


@njit(cache=True, nogil=True, error_model="numpy")
def _cluster(
    x, y, theta, w, cell_m, heading_bins, radius_m, heading_window_rad, out
):  # fmt: skip  # pragma: no cover - compiled
    """Greedy mode seeking (module docstring); fills ``out`` rows, returns how many.

    Each row of ``out`` is (mass, mean x, mean y, circular mean heading, std x, std y,
    circular std) of one hypothesis, in the order found.
    """
    n = x.shape[0]
    cos_t, sin_t = _unit_vectors(theta)
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
        ct = int(np.floor((theta[i] + np.pi) / bin_width)) % heading_bins
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
            if not near.any():
                break
            same = (near == members).all()
            members[:] = near
            if same:
                break
            mx, my, mc, ms = _centre(w, x, y, cos_t, sin_t, members)
        _summary(w, x, y, cos_t, sin_t, members, out[found])
        found += 1
        for i in range(n):
            remaining[i] = remaining[i] and not members[i]
    return found


@njit(cache=True, nogil=True, error_model="numpy")
def _refine(x, y, theta, w, rows, found, radius_m, heading_window_rad):  # pragma: no cover
    """Re-summarize hypotheses found on a subsample over every weighted particle.

    Each hypothesis, in the order found, takes the particles not yet taken that lie
    within ``radius_m`` and ``heading_window_rad`` of its centre; its row of ``rows``
    becomes their weighted summary (no resampling noise left in the reported pose).
    """
    n = x.shape[0]
    cos_t, sin_t = _unit_vectors(theta)
    remaining = w > 0.0
    members = np.zeros(n, dtype=np.bool_)
    cos_window = np.cos(heading_window_rad)
    r2 = radius_m * radius_m
    for h in range(found):
        mx, my, mt = rows[h, 1], rows[h, 2], rows[h, 3]
        mc, ms = np.cos(mt), np.sin(mt)
        _near(x, y, cos_t, sin_t, remaining, mx, my, mc, ms, r2, cos_window, members)
        if w[members].sum() <= 0.0:
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
    x, y, theta, weights = (
        np.ascontiguousarray(v, dtype=np.float64) for v in (x, y, theta, weights)
    )
    sub = rng is not None and n > max_points
    if rng is not None and sub:
        idx = systematic_resample(weights, max_points, rng)
        cx, cy, ct = x[idx], y[idx], theta[idx]
        cw = np.full(max_points, 1.0 / max_points)
    else:
        cx, cy, ct, cw = x, y, theta, weights
    rows = np.empty((settings.max_hypotheses, 7))
    found = (
        _cluster(
            cx,
            cy,
            ct,
            cw,
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
    if sub:
        r, window = float(settings.radius_m), float(settings.heading_window_rad)
        _refine(x, y, theta, weights, rows, found, r, window)
    hyps = sorted(rows[:found].tolist(), key=lambda h: -h[0])
    mass, mx, my, mt, sx, sy, st = hyps[0]
    converged = (
        mass >= settings.min_mass
        and max(sx, sy) <= settings.max_std_xy_m
        and st <= settings.max_std_theta_rad
    )
    hypotheses = tuple(
        Hypothesis(h[1], h[2], h[3], h[0], float(np.hypot(h[4], h[5]))) for h in hyps
    )
    return Estimate(mx, my, mt, sx, sy, st, bool(converged), hypotheses, n, ess)


class ConvergenceGate:
    """Confirms ``converged`` only after the belief has held steady for a while.

    Right after a global start a single update can collapse the cloud onto one wrong
    spot that looks tight; telling a blind person that position with confidence is
    the worst failure. So a tight, heavy cluster counts as converged only after it
    has stayed put (moving no more than the odometry allows plus ``tolerance_m``, and
    turning no more than ``tolerance_rad``) for ``frames`` consecutive frames, and
    while the estimate explains what the camera sees: the smoothed mean of the
    squared bearing residuals (in standard deviations) must stay below ``max_fit``
    (below 1 when the pose is right and the noise is as configured; residuals are
    clipped at 3 standard deviations so a false detection costs at most 9), and only
    while detections keep coming: dead reckoning alone is not a confirmed position.
    """

    max_fit: float = 2.0
    #: Dead reckoning alone (frames without usable detections) for longer than this
    #: is not a confirmed position: 10 frames is 2 s at 5 frames/s.
    max_frames_without_evidence: int = 10

    def __init__(
        self, frames: int = 5, tolerance_m: float = 0.3, tolerance_rad: float = np.radians(15.0)
    ) -> None:
        self.frames = frames
        self.tolerance_m = tolerance_m
        self.tolerance_rad = tolerance_rad
        self._streak = 0
        self._last: Estimate | None = None

    def reset(self) -> None:
        self._streak = 0
        self._last = None

    def confirm(
        self,
        raw: Estimate,
        moved_m: float = 0.0,
        turned_rad: float = 0.0,
        fit: float | None = None,
        frames_without_evidence: int = 0,
    ) -> Estimate:
        """``raw`` with ``converged`` true only if it held for ``frames`` frames and fits."""
        last = self._last
        fits = (
            fit is not None
            and fit <= self.max_fit
            and frames_without_evidence <= self.max_frames_without_evidence
        )
        steady = (
            raw.converged
            and fits
            and last is not None
            and np.hypot(raw.x - last.x, raw.y - last.y) <= moved_m + self.tolerance_m
            and abs(float(wrap_angle(raw.theta_rad - last.theta_rad)))
            <= abs(turned_rad) + self.tolerance_rad
        )
        self._streak = self._streak + 1 if steady else (1 if raw.converged and fits else 0)
        self._last = raw
        if raw.converged and (self._streak < self.frames or not fits):
            return replace(raw, converged=False)
        return raw
