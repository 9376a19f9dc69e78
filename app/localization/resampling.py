"""Weights in log space, effective sample size, and systematic resampling.

Systematic (low-variance) resampling draws one uniform offset and takes N evenly
spaced pointers through the cumulative weights (Thrun, Burgard & Fox, *Probabilistic
Robotics*, Table 4.4). It keeps the sample's diversity better than multinomial draws
and costs one ``searchsorted``.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


def normalized_weights(log_weights: NDArray[np.floating]) -> NDArray[np.float64]:
    """Normalized weights from log-weights, shape (N,).

    Never NaN and never all zero: when every log-weight is -inf (no particle is
    possible), the weights fall back to uniform so the caller can recover.
    """
    lw = np.asarray(log_weights, dtype=np.float64)
    top = np.max(lw) if lw.size else -np.inf
    if not np.isfinite(top):
        return np.full(lw.shape, 1.0 / max(lw.size, 1))
    w = np.exp(lw - top)
    return w / w.sum()


def log_sum_exp(values: NDArray[np.floating]) -> float:
    """log(sum(exp(values))) without overflow; -inf for an empty or all -inf input."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return float("-inf")
    top = np.max(v)
    if not np.isfinite(top):
        return float(top)
    return float(top + np.log(np.sum(np.exp(v - top))))


def effective_sample_size(weights: NDArray[np.floating]) -> float:
    """Kish's effective sample size 1 / sum(w^2) of normalized weights."""
    w = np.asarray(weights, dtype=np.float64)
    return float(1.0 / np.sum(w * w))


@njit(cache=True, nogil=True)
def _systematic(weights: NDArray[np.float64], n: int, u0: float) -> NDArray[np.int64]:
    out = np.empty(n, dtype=np.int64)
    m = weights.shape[0]
    i = 0
    c = weights[0]
    for k in range(n):
        u = (u0 + k) / n
        while u > c and i < m - 1:  # one merge pass over weights and pointers
            i += 1
            c += weights[i]
        out[k] = i
    return out


def systematic_resample(
    weights: NDArray[np.floating], n: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """Indexes of ``n`` particles drawn by systematic resampling.

    One uniform offset ``u0``, pointers ``(u0 + k) / n``, and a single merge pass of
    the pointers against the running sum of the weights (O(N + n)). The last pointer
    can never run past the end, even when round-off leaves the weights summing to a
    little under one.

    Args:
        weights: normalized weights, shape (M,).
        n: how many indexes to draw (may differ from M for adaptive sample sizes).
        rng: random generator for the single offset.

    Returns:
        Indexes into ``weights``, sorted ascending, shape (n,).
    """
    return _systematic(np.ascontiguousarray(weights, dtype=np.float64), int(n), rng.random())
