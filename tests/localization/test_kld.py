"""KLD-sampling (Fox 2003): how many particles the belief needs."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization import kld
from app.localization.kld import BIN_THETA_RAD, BIN_XY_M, kld_bound, kld_sample_size


def occupied_bins_by_unique(x, y, theta, w, min_mass) -> int:
    """The plain numpy count: group by bin with np.unique, sum the weights."""
    keys = np.stack(
        [
            np.floor(x / BIN_XY_M),
            np.floor(y / BIN_XY_M),
            np.floor((theta + np.pi) / BIN_THETA_RAD),
        ],
        axis=1,
    )
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    mass = np.bincount(inverse.ravel(), weights=w)
    return int(np.count_nonzero(mass >= min_mass))


def test_bound_follows_fox_formula() -> None:
    assert kld_bound(1) == 1
    # k = 2: (1 / 0.1) * (1 - 2/9 + sqrt(2/9) * 2.326)^3
    a = 2.0 / 9.0
    assert kld_bound(2) == int(np.ceil(10.0 * (1.0 - a + np.sqrt(a) * 2.326) ** 3))
    assert kld_bound(100) < kld_bound(1000) < kld_bound(10_000)


@pytest.mark.parametrize("spread", [0.05, 0.5, 5.0])
def test_bin_count_agrees_with_a_plain_numpy_count(spread: float) -> None:
    rng = np.random.default_rng(int(spread * 100))
    n = 5000
    x, y = rng.normal(3.0, spread, n), rng.normal(-2.0, spread, n)
    theta = np.mod(rng.normal(3.0, spread, n) + np.pi, 2 * np.pi) - np.pi
    w = rng.random(n) ** 4
    w /= w.sum()
    for min_mass in (1e-12, 1.0 / 10_000, 1.0 / 1000):
        want = occupied_bins_by_unique(x, y, theta, w, min_mass)
        got = kld._occupied_bins(x, y, theta, w, BIN_XY_M, float(BIN_THETA_RAD), min_mass)
        assert got == want


def test_sparse_clouds_take_the_sorting_path_and_agree(monkeypatch) -> None:
    rng = np.random.default_rng(9)
    x, y = rng.uniform(-500, 500, 3000), rng.uniform(-500, 500, 3000)
    theta = rng.uniform(-np.pi, np.pi, 3000)
    w = np.full(3000, 1.0 / 3000)
    want = occupied_bins_by_unique(x, y, theta, w, 1e-4)
    got = kld._occupied_bins(x, y, theta, w, BIN_XY_M, float(BIN_THETA_RAD), 1e-4)
    assert got == want == 3000  # a million-bin box: no dense histogram is built


def test_tight_belief_needs_few_particles_and_a_spread_one_many() -> None:
    rng = np.random.default_rng(1)
    n = 10_000
    w = np.full(n, 1.0 / n)
    tight = kld_sample_size(
        rng.normal(2, 0.03, n), rng.normal(2, 0.03, n), rng.normal(0, 0.02, n), w, 300, n
    )
    spread = kld_sample_size(
        rng.uniform(0, 10, n), rng.uniform(0, 7, n), rng.uniform(-np.pi, np.pi, n), w, 300, n
    )
    assert tight == 300  # clipped at the floor
    assert spread == n  # clipped at the ceiling
