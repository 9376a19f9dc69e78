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

import numpy as np
from numpy.typing import NDArray

#: Bin sizes: metres, metres, radians.
BIN_XY_M = 0.2
BIN_THETA_RAD = np.radians(15.0)
EPSILON = 0.05
Z_QUANTILE = 2.326  # delta = 0.01


def kld_bound(k: int, epsilon: float = EPSILON, z: float = Z_QUANTILE) -> int:
    """Fox's sample-size bound for ``k`` occupied bins."""
    if k <= 1:
        return 1
    a = 2.0 / (9.0 * (k - 1))
    return int(np.ceil((k - 1) / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3))


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
    bx = np.floor(x / BIN_XY_M).astype(np.int64)
    by = np.floor(y / BIN_XY_M).astype(np.int64)
    bt = np.floor((theta + np.pi) / BIN_THETA_RAD).astype(np.int64)
    bx -= bx.min()
    by -= by.min()
    key = (by * (bx.max() + 1) + bx) * (int(2 * np.pi / BIN_THETA_RAD) + 1) + bt
    _, inverse = np.unique(key, return_inverse=True)
    mass = np.bincount(inverse, weights=weights)
    k = int(np.count_nonzero(mass >= 1.0 / n_max))
    return int(np.clip(kld_bound(k), n_min, n_max))
