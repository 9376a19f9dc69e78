"""Systematic resampling against a naive loop, and the log-weight guards."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.resampling import (
    effective_sample_size,
    log_sum_exp,
    normalized_weights,
    systematic_resample,
)


def naive_systematic(weights: np.ndarray, n: int, u0: float) -> np.ndarray:
    """The textbook loop (Probabilistic Robotics, Table 4.4)."""
    out = []
    c = weights[0]
    i = 0
    for m in range(n):
        u = (u0 + m) / n
        while u > c and i < len(weights) - 1:
            i += 1
            c += weights[i]
        out.append(i)
    return np.array(out)


@settings(max_examples=50, deadline=None)
@given(
    w=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=60).filter(lambda v: sum(v) > 1e-6),
    n=st.integers(1, 200),
    seed=st.integers(0, 2**31),
)
def test_matches_the_naive_loop(w: list[float], n: int, seed: int) -> None:
    weights = np.array(w) / np.sum(w)
    u0 = np.random.default_rng(seed).random()
    fast = systematic_resample(weights, n, np.random.default_rng(seed))
    assert np.array_equal(fast, naive_systematic(weights, n, u0))
    assert fast.min() >= 0 and fast.max() < len(w)
    assert (weights[fast] > 0).all()


def test_low_variance_counts() -> None:
    weights = np.array([0.5, 0.25, 0.125, 0.125])
    idx = systematic_resample(weights, 8, np.random.default_rng(3))
    assert np.bincount(idx, minlength=4).tolist() == [4, 2, 1, 1]


def test_weights_never_nan_nor_all_zero() -> None:
    w = normalized_weights(np.array([-np.inf, -np.inf, -np.inf]))
    assert np.allclose(w, 1 / 3)
    w = normalized_weights(np.array([-1e6, -1e6 - 1.0, -np.inf]))
    assert np.isclose(w.sum(), 1.0) and not np.isnan(w).any() and w[0] > w[1] > w[2] == 0
    assert log_sum_exp(np.array([-np.inf])) == -np.inf
    assert np.isclose(log_sum_exp(np.array([1000.0, 1000.0])), 1000.0 + np.log(2))


def test_effective_sample_size() -> None:
    assert np.isclose(effective_sample_size(np.full(10, 0.1)), 10)
    assert np.isclose(effective_sample_size(np.array([1.0, 0.0, 0.0])), 1)
