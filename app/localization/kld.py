"""KLD-sampling: how many particles the belief needs right now (Fox, IJRR 2003).

Fox bounds the Kullback-Leibler distance between the particle approximation and
the true posterior: with k histogram bins holding probability mass, about

    n = (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3

samples keep that distance below ``epsilon`` with probability 1 - delta (z is the
upper 1 - delta quantile of the standard normal). A lost filter spreads over many
bins and keeps many particles; a localized one fits in a few bins and needs few.
Here k counts the (x, y, heading) bins whose weight is at least one particle's share.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Bin sizes: metres, metres, radians.
BIN_XY_M = 0.2
BIN_THETA_RAD = np.radians(15.0)
EPSILON = 0.05
Z_QUANTILE = 2.326  # delta = 0.01


@functools.lru_cache(maxsize=4096)
def kld_bound(k: int, epsilon: float = EPSILON, z: float = Z_QUANTILE) -> int:
    """Fox's sample-size bound for ``k`` occupied bins (kept: a localized filter asks
    for the same few counts every frame)."""
    if k <= 1:
        return 1
    a = 2.0 / (9.0 * (k - 1))
    return int(np.ceil((k - 1) / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3))


#: Largest dense (x, y, heading) histogram, in bins; beyond it the bins are sorted.
MAX_DENSE_BINS = 1 << 21


@njit(cache=True, nogil=True, error_model="numpy")
def _occupied_bins(x, y, theta, w, bin_xy, bin_theta, min_mass):  # fmt: skip  # pragma: no cover
    """How many (x, y, heading) bins hold at least ``min_mass`` (> 0) of the weight."""
    n = x.shape[0]
    if n == 0:
        return 0
    n_theta = int(2.0 * np.pi / bin_theta) + 1
    bx = np.empty(n, dtype=np.int64)
    by = np.empty(n, dtype=np.int64)
    for i in range(n):
        bx[i] = int(np.floor(x[i] / bin_xy))
        by[i] = int(np.floor(y[i] / bin_xy))
    x0, y0 = bx.min(), by.min()
    width = bx.max() - x0 + 1
    height = by.max() - y0 + 1
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        bt = int(np.floor((theta[i] + np.pi) / bin_theta))
        key[i] = ((by[i] - y0) * width + (bx[i] - x0)) * n_theta + bt
    count = 0
    if width * height * n_theta <= MAX_DENSE_BINS:
        mass = np.zeros(width * height * n_theta)
        for i in range(n):
            mass[key[i]] += w[i]
        for b in range(mass.shape[0]):
            count += mass[b] >= min_mass
        return count
    order = np.argsort(key)  # a huge, sparse cloud: sort the keys instead
    run = 0.0
    for j in range(n):
        i = order[j]
        run += w[i]
        if j == n - 1 or key[order[j + 1]] != key[i]:
            count += run >= min_mass
            run = 0.0
    return count


def kld_sample_size(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    weights: NDArray[np.float64],
    n_min: int,
    n_max: int,
) -> int:
    """Particles to draw at the next resampling, clipped to [n_min, n_max].

    Args:
        x, y, theta: particle poses, shape (N,).
        weights: normalized weights, shape (N,).
    """
    k = _occupied_bins(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64),
        BIN_XY_M,
        float(BIN_THETA_RAD),
        1.0 / n_max,
    )
    return min(max(int(kld_bound(int(k))), n_min), n_max)
