"""Weights in log space, effective sample size, and systematic resampling.

Systematic (low-variance) resampling draws one uniform offset and takes N evenly
spaced pointers through the cumulative weights (Thrun, Burgard & Fox, *Probabilistic
Robotics*, Table 4.4). It keeps the sample's diversity better than multinomial draws
and costs one ``searchsorted``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


def normalized_weights(log_weights: NDArray[np.floating]) -> NDArray[np.float64]:
    """Normalized weights from log-weights, shape (N,).

    Never NaN and never all zero: when every log-weight is -inf (no particle is
    possible), the weights fall back to uniform so the caller can recover.
    """
    return weights_and_log_sum_exp(log_weights)[0]


def log_sum_exp(values: NDArray[np.floating]) -> float:
    """log(sum(exp(values))) without overflow; -inf for an empty or all -inf input."""
    top, e = _shifted_exp(values)
    return float(top) if e is None else float(top + np.log(np.add.reduce(e)))


def weights_and_log_sum_exp(
    log_weights: NDArray[np.floating],
) -> tuple[NDArray[np.float64], float]:
    """:func:`normalized_weights` and :func:`log_sum_exp` of the same log-weights, from
    one set of exponentials (the very numbers each would compute alone)."""
    top, e = _shifted_exp(log_weights)
    if e is None:
        return np.full(np.shape(log_weights), 1.0 / max(np.size(log_weights), 1)), float(top)
    total = np.add.reduce(e)
    return e / total, float(top + np.log(total))


def _shifted_exp(values: NDArray[np.floating]) -> tuple[float, NDArray[np.float64] | None]:
    """The largest value and ``exp(values - largest)``; None instead of the exponentials
    when there is nothing finite to shift by (no value, or all -inf). The ufuncs' own
    reductions: the same as .max() and .sum(), without their Python wrappers (called
    several times a frame); ``math.isfinite`` of the largest, the same answer as
    ``np.isfinite`` of a float without a ufunc call on a scalar (about 1 us)."""
    v = np.asarray(values, dtype=np.float64)
    top = np.maximum.reduce(v) if v.size else -np.inf
    if not math.isfinite(top):
        return float(top), None
    return top, np.exp(v - top)


def effective_sample_size(weights: NDArray[np.floating]) -> float:
    """Kish's effective sample size 1 / sum(w^2) of normalized weights."""
    w = np.asarray(weights, dtype=np.float64)
    return float(1.0 / np.add.reduce(w * w))


@njit(cache=True, nogil=True)
def systematic_indexes(weights: NDArray[np.float64], n: int, u0: float) -> NDArray[np.int64]:
    """:func:`systematic_resample` with its offset ``u0`` given, compiled (callable
    from other kernels); ``weights`` C-contiguous float64."""
    # Index k goes to the first particle i whose running sum c_i reaches the pointer
    # (u0 + k) / n, the last particle when none does. Rather than merging pointers and
    # sums (two interleaved loops whose every branch depends on the data: a filter's
    # weights mispredict most of them, 16-25 us for 2,000 particles, against 3 us when
    # a benchmark repeats one input), each sum counts the pointers it reaches
    # (cnt_i, from c_i * n, made exact by the very comparison a merge makes) and k
    # goes to the number of sums with cnt_i <= k: a histogram of the counts and its
    # running total, the same indexes with branches that rarely change.
    m = weights.shape[0]
    reached = np.zeros(n + 1, dtype=np.int64)
    c = 0.0
    for i in range(m - 1):  # the last particle takes whatever no sum reaches
        c = weights[0] if i == 0 else c + weights[i]
        guess = c * n - u0
        cnt = n if guess >= n else (int(guess) + 1 if guess >= 0.0 else 0)
        while cnt < n and (u0 + cnt) / n <= c:
            cnt += 1
        while cnt > 0 and (u0 + (cnt - 1)) / n > c:
            cnt -= 1
        reached[cnt] += 1
    out = np.empty(n, dtype=np.int64)
    before = 0
    for k in range(n):
        before += reached[k]
        out[k] = before
    return out


def systematic_resample(
    weights: NDArray[np.floating], n: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """Indexes of ``n`` particles drawn by systematic resampling.

    One uniform offset ``u0``, pointers ``(u0 + k) / n``, each taking the first
    particle whose running sum of the weights reaches it (O(N + n), see
    :func:`systematic_indexes`). The last pointer can never run past the end, even when
    round-off leaves the weights summing to a little under one.

    Args:
        weights: normalized weights, shape (M,).
        n: how many indexes to draw (may differ from M for adaptive sample sizes).
        rng: random generator for the single offset.

    Returns:
        Indexes into ``weights``, sorted ascending, shape (n,).
    """
    return systematic_indexes(np.ascontiguousarray(weights, dtype=np.float64), int(n), rng.random())
