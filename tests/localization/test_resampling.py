"""Systematic resampling against a naive loop, and the log-weight guards."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.resampling import (
    effective_sample_size,
    log_sum_exp,
    normalized_weights,
    systematic_indexes,
    systematic_resample,
    weights_and_log_sum_exp,
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


def test_matches_the_naive_loop_on_filter_like_weights() -> None:
    """Peaked, sparse, one-hot and equal weights of up to 2,000 particles, pointers at
    the ends of [0, 1): equal weights put running sums right on the pointers, where the
    compiled count's guesses from c * n are off by one both ways."""
    rng = np.random.default_rng(11)
    for m in (3, 7, 10, 49, 100, 999, 2000):
        for n in (m, 2 * m, max(m // 3, 1), 7):
            weights = np.full(m, 1.0 / m)
            for u0 in (0.0, 0.5, float(np.nextafter(1.0, 0.0))):
                got = systematic_indexes(weights, n, u0)
                assert np.array_equal(got, naive_systematic(weights, n, u0)), (m, n, u0)
    for trial in range(300):
        m = int(rng.choice([1, 2, 3, 40, 2000]))
        n = int(rng.choice([1, 3, 150, 1000, m]))
        w = [
            rng.random(m),
            rng.random(m) ** 30,
            np.exp(-rng.exponential(300.0, m)),
            np.eye(1, m, int(rng.integers(m)))[0],
            rng.random(m) * (rng.random(m) < 0.1),
        ][trial % 5]
        w[0] += 1e-300  # never all zero
        weights = w / w.sum()
        u0 = [float(rng.random()), 0.0, float(np.nextafter(1.0, 0.0))][trial % 3]
        got = systematic_indexes(weights, n, u0)
        assert np.array_equal(got, naive_systematic(weights, n, u0)), (trial, m, n, u0)


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


def test_weights_and_their_log_sum_come_from_one_set_of_exponentials() -> None:
    """Both are numpy's max-shifted exponentials, bit for bit (the filter takes its
    weights from the correction's log-sum), and agree with the functions alone."""
    rng = np.random.default_rng(5)
    for m in (1, 7, 130, 2000, 10_000):
        lw = rng.normal(-50.0, 30.0, m)
        lw[rng.random(m) < 0.1] = -np.inf
        lw[0] = -3.0  # at least one finite
        w, lse = weights_and_log_sum_exp(lw)
        e = np.exp(lw - lw.max())
        assert np.array_equal(w, e / e.sum()) and lse == lw.max() + np.log(e.sum())
        assert np.array_equal(w, normalized_weights(lw)) and lse == log_sum_exp(lw)
    w, lse = weights_and_log_sum_exp(np.full(4, -np.inf))
    assert w.tolist() == [0.25] * 4 and lse == -np.inf
    w, lse = weights_and_log_sum_exp(np.empty(0))
    assert w.shape == (0,) and lse == -np.inf


def test_effective_sample_size() -> None:
    assert np.isclose(effective_sample_size(np.full(10, 0.1)), 10)
    assert np.isclose(effective_sample_size(np.array([1.0, 0.0, 0.0])), 1)
