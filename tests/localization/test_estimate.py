"""The estimate: weighted particles clustered into hypotheses, and an honest ``converged``."""

from __future__ import annotations

import numpy as np

from app.localization.convergence import (
    PROTECTION_FLOOR_M,
    PROTECTION_PROBABILITY,
    PROTECTION_SAMPLE,
    PROTECTION_SCALE,
    protection_radius,
)
from app.localization.estimate import DEFAULT_CLUSTERING, estimate_pose
from app.localization.types import Estimate
from app.maps.geometry import wrap_angle


def cloud(rng: np.random.Generator, centre: tuple[float, float, float], n: int, std: float):
    cx, cy, ct = centre
    return rng.normal(cx, std, n), rng.normal(cy, std, n), wrap_angle(rng.normal(ct, 0.03, n))


def test_two_separated_clouds_are_two_hypotheses_with_their_weights() -> None:
    rng = np.random.default_rng(0)
    a = cloud(rng, (2.0, 2.0, 0.5), 3000, 0.05)
    b = cloud(rng, (7.0, 4.0, -2.0), 1000, 0.05)
    x, y, th = (np.concatenate([p, q]) for p, q in zip(a, b, strict=True))
    w = np.concatenate([np.full(3000, 0.7 / 3000), np.full(1000, 0.3 / 1000)])
    e = estimate_pose(x, y, th, w)
    assert len(e.hypotheses) == 2
    heavy, light = e.hypotheses
    # Far apart, each cluster holds exactly its own cloud's weight.
    assert abs(heavy.weight - 0.7) < 1e-9 and abs(light.weight - 0.3) < 1e-9
    assert np.hypot(heavy.x - 2.0, heavy.y - 2.0) < 0.01
    assert np.hypot(light.x - 7.0, light.y - 4.0) < 0.01
    assert (e.x, e.y) == (heavy.x, heavy.y)  # the pose is the heaviest mode, not a blend
    assert not e.converged  # 30 % of the belief is elsewhere


def test_one_tight_cloud_is_converged_and_a_wide_one_is_not() -> None:
    rng = np.random.default_rng(1)
    n = 4000
    w = np.full(n, 1.0 / n)
    tight = estimate_pose(*cloud(rng, (3.0, 1.0, 2.0), n, 0.05), w)
    assert tight.converged and len(tight.hypotheses) == 1
    assert abs(tight.std_x_m - 0.05) < 0.005 and abs(tight.std_y_m - 0.05) < 0.005
    wide_std = 2 * DEFAULT_CLUSTERING.max_std_xy_m
    wide = estimate_pose(*cloud(rng, (3.0, 1.0, 2.0), n, wide_std), w)
    assert not wide.converged


def test_no_weight_anywhere_is_said_honestly() -> None:
    x = np.linspace(0.0, 5.0, 100)
    e = estimate_pose(x, x, np.zeros(100), np.zeros(100))
    assert not e.converged and e.hypotheses == ()
    assert np.isinf(e.std_x_m) and np.isinf(e.std_y_m)


def test_subsampled_mode_seeking_reports_the_full_weighted_pose() -> None:
    """With an rng, clustering runs on 1,000 resampled particles; the summary does not."""
    rng = np.random.default_rng(2)
    a = cloud(rng, (1.0, 5.0, 1.0), 6000, 0.1)
    b = cloud(rng, (6.0, 1.0, 3.0), 4000, 0.1)
    x, y, th = (np.concatenate([p, q]) for p, q in zip(a, b, strict=True))
    w = rng.random(10_000)
    w /= w.sum()
    full = estimate_pose(x, y, th, w)
    fast = estimate_pose(x, y, th, w, rng=np.random.default_rng(3), max_points=1000)
    assert len(fast.hypotheses) == len(full.hypotheses) == 2
    for f, s in zip(full.hypotheses, fast.hypotheses, strict=True):
        assert abs(f.weight - s.weight) < 1e-9
        assert np.hypot(f.x - s.x, f.y - s.y) < 1e-9


def test_mirror_modes_are_never_converged() -> None:
    rng = np.random.default_rng(0)
    n = 4000
    x = np.concatenate([rng.normal(2.0, 0.05, n), rng.normal(8.0, 0.05, n)])
    y = np.concatenate([rng.normal(2.0, 0.05, n), rng.normal(5.0, 0.05, n)])
    th = np.concatenate([rng.normal(0.0, 0.02, n), rng.normal(np.pi, 0.02, n)])
    w = np.full(2 * n, 1.0 / (2 * n))
    e = estimate_pose(x, y, wrap_angle(th), w)
    assert not e.converged
    assert len(e.hypotheses) == 2
    assert np.isclose(e.hypotheses[0].weight, 0.5, atol=0.01)
    # The pose reported is one of the modes, not the point between them.
    assert min(np.hypot(e.x - 2, e.y - 2), np.hypot(e.x - 8, e.y - 5)) < 0.1
    # One heavy tight mode is converged.
    w2 = np.concatenate([np.full(n, 0.95 / n), np.full(n, 0.05 / n)])
    assert estimate_pose(x, y, wrap_angle(th), w2).converged


def test_estimate_summarizes_each_mode_by_its_weighted_moments() -> None:
    """Three separated modes (one across the +-pi seam), zero-weight outliers ignored."""
    rng = np.random.default_rng(2)
    centres = [(1.0, 1.0, np.pi - 0.01, 0.5), (6.0, 1.0, 0.5, 0.3), (1.0, 6.0, -1.0, 0.2)]
    xs, ys, ths, ws = [], [], [], []
    for cx, cy, ct, mass in centres:
        n = 3000
        xs.append(rng.normal(cx, 0.05, n))
        ys.append(rng.normal(cy, 0.08, n))
        ths.append(rng.normal(ct, 0.05, n))
        ws.append(np.full(n, mass / n))
    xs.append(np.full(50, 20.0))  # far away but weightless: never a hypothesis
    ys.append(np.full(50, 20.0))
    ths.append(np.zeros(50))
    ws.append(np.zeros(50))
    x, y, th, w = (np.concatenate(v) for v in (xs, ys, ths, ws))
    e = estimate_pose(x, y, wrap_angle(th), w)
    assert [round(h.weight, 3) for h in e.hypotheses] == [0.5, 0.3, 0.2]
    for h, (cx, cy, ct, _) in zip(e.hypotheses, centres, strict=True):
        assert np.hypot(h.x - cx, h.y - cy) < 0.01
        assert abs(wrap_angle(h.theta_rad - ct)) < 0.01
        assert abs(h.std_xy_m - np.hypot(0.05, 0.08)) < 0.01
    assert (e.x, e.y) == (e.hypotheses[0].x, e.hypotheses[0].y)
    assert abs(e.std_x_m - 0.05) < 0.005 and abs(e.std_y_m - 0.08) < 0.005
    assert abs(e.std_theta_rad - 0.05) < 0.005
    assert not e.converged  # half the mass is elsewhere


def reference_protection_quantile(
    x: np.ndarray, y: np.ndarray, w: np.ndarray, ex: float, ey: float, need: float, u0: float
) -> float:
    """The particles' part of the protection radius in plain numpy: the distances of a
    systematic resample, sorted, and np.quantile's linear interpolation at ``need``
    (written out: np.quantile rounds its interpolation differently)."""
    n = PROTECTION_SAMPLE
    cum = np.cumsum(w)
    idx = np.minimum(np.searchsorted(cum, (u0 + np.arange(n)) / n), w.size - 1)
    d = np.sort(np.hypot(x[idx] - ex, y[idx] - ey))
    pos = min(need, 1.0) * (n - 1)
    lo, hi = int(np.floor(pos)), int(np.ceil(pos))
    return float(d[lo] + (pos - lo) * (d[hi] - d[lo]))


def test_protection_radius_takes_the_quantile_of_a_systematic_resample() -> None:
    """The compiled draw, distances and selection give the sorted distances' number
    exactly, whatever the quantile (order statistics at, between or next to the last
    ones), also where distances tie or differ in their last bits only (points on a
    circle, or mirrored about the estimate), where ranking squared distances alone
    could pick a neighbour of the right one."""
    rng = np.random.default_rng(7)
    for trial in range(300):
        m = int(rng.integers(1, 3000))
        ex, ey = rng.normal(0.0, 0.5, 2)
        kind = trial % 3
        if kind == 0:  # a cloud
            x, y = rng.normal(0.0, rng.uniform(0.01, 3.0), (2, m))
        elif kind == 1:  # a circle: distances equal but for rounding
            a = rng.uniform(-np.pi, np.pi, m)
            radius = rng.uniform(1e-3, 5.0)
            x, y = ex + radius * np.cos(a), ey + radius * np.sin(a)
        else:  # mirrored pairs: exact ties
            h = (m + 1) // 2
            dx, dy = rng.normal(0.0, 0.3, (2, h))
            x = np.concatenate([ex + dx, ex - dx])[:m]
            y = np.concatenate([ey + dy, ey - dy])[:m]
        w = rng.random(m) ** 4
        w /= w.sum()
        share = [0.0, 0.005, 0.0099, 0.02, float(rng.uniform(0.0, 0.01))][trial % 5]
        est = Estimate(float(ex), float(ey), 0.0, 1e-6, 1e-6, 0.1, True, (), m, 1.0)
        u0 = float(np.random.default_rng(trial).random())
        got = protection_radius(x, y, w, est, np.random.default_rng(trial), share)
        need = 1.0 if share >= 1.0 - PROTECTION_PROBABILITY else 0.99 / (1.0 - share)
        want = PROTECTION_SCALE * reference_protection_quantile(x, y, w, ex, ey, need, u0)
        assert got == want + PROTECTION_FLOOR_M, (trial, m, share)


def test_a_subsamples_unit_vectors_are_the_whole_clouds_gathered() -> None:
    """The subsample takes its headings' unit vectors from the whole cloud's
    (estimate._clusters): the same bits as computing them from its own headings,
    whatever the arrays' lengths (a vectorized loop and its remainder alike)."""
    from numba import njit

    from app.localization.estimate import _unit_vectors

    @njit
    def unit_vectors(theta):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
        return _unit_vectors(theta)

    rng = np.random.default_rng(11)
    for n in (*range(1, 70), 999, 1_000, 2_000, 2_001):
        theta = rng.uniform(-np.pi, np.pi, n)
        idx = np.sort(rng.integers(0, n, max(1, n // 2)))
        cos_all, sin_all = unit_vectors(theta)
        cos_sub, sin_sub = unit_vectors(np.ascontiguousarray(theta[idx]))
        assert np.array_equal(cos_all[idx], cos_sub)
        assert np.array_equal(sin_all[idx], sin_sub)
