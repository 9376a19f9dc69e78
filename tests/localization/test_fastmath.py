"""The compiled building blocks: sincos, softplus, tabulated normal noise, grid cells."""

from __future__ import annotations

import numpy as np
from numba import njit

from app.localization.fastmath import (
    FAST,
    NORMAL_TAIL_SIGMA,
    SINCOS_MAX_ERROR,
    SOFTPLUS_MAX_ERROR,
    fill_normal,
    grid_cell,
    sincos,
    softplus,
)
from app.maps.geometry import grid_cells


@njit(fastmath=FAST, error_model="numpy")
def _sincos_all(t, s, c):  # fmt: skip
    for i in range(t.shape[0]):
        s[i], c[i] = sincos(t[i])


@njit(fastmath=FAST, error_model="numpy")
def _softplus_all(z, out):  # fmt: skip
    for i in range(z.shape[0]):
        out[i] = softplus(z[i])


def test_sincos_matches_the_library_everywhere() -> None:
    t = np.concatenate(
        [
            np.random.default_rng(0).uniform(-100.0, 100.0, 100_000),
            np.arange(-8, 9) * np.pi / 4,  # quadrant boundaries
            [np.pi, -np.pi, 0.0, 1e-12, -1e-12],
        ]
    )
    s, c = np.empty_like(t), np.empty_like(t)
    _sincos_all(t, s, c)
    # The documented bound (numpy's own sin and cos are within an ulp or two of exact).
    assert np.abs(s - np.sin(t)).max() <= SINCOS_MAX_ERROR
    assert np.abs(c - np.cos(t)).max() <= SINCOS_MAX_ERROR


def test_softplus_matches_logaddexp_over_the_whole_range() -> None:
    z = np.concatenate([np.linspace(-2000.0, 50.0, 200_001), [0.0, -20.0, 20.0]])
    out = np.empty_like(z)
    _softplus_all(z, out)
    assert np.abs(out - np.logaddexp(0.0, z)).max() <= SOFTPLUS_MAX_ERROR
    assert (out >= 0.0).all()


def test_tabulated_normal_has_the_normal_moments_and_quantiles() -> None:
    z = fill_normal(np.random.default_rng(3), 1_000_000).astype(np.float64)
    assert abs(z.mean()) < 0.005
    assert abs(z.std() - 1.0) < 0.005
    assert np.abs(z).max() <= NORMAL_TAIL_SIGMA * 1.01
    # Shares inside 1, 2 and 3 standard deviations: 68.27 %, 95.45 %, 99.73 %.
    for k, share in [(1, 0.6827), (2, 0.9545), (3, 0.9973)]:
        assert abs(np.mean(np.abs(z) < k) - share) < 0.003


def test_tabulated_normal_is_reproducible_and_uses_the_given_generator() -> None:
    a = fill_normal(np.random.default_rng(7), 1001)
    b = fill_normal(np.random.default_rng(7), 1001)
    c = fill_normal(np.random.default_rng(8), 1001)
    assert a.shape == (1001,) and np.array_equal(a, b) and not np.array_equal(a, c)


@njit(error_model="numpy")
def _grid_cell_all(x, y, res, rows, cols, cells, inside):  # fmt: skip
    for i in range(x.shape[0]):
        c, ok = grid_cell(x[i], y[i], 0.0, 0.0, 1.0 / res, rows, cols)
        cells[i], inside[i] = int(c), ok


def test_grid_cells_put_points_on_their_cell_and_clip_the_rest() -> None:
    """The one cell lookup: row-major, lower-left corners inclusive, off-grid flagged;
    compiled and numpy callers put every point (boundaries too) in the same cell."""
    x = np.array([0.0, 0.49, 0.5, 1.99, -0.1, 2.5, 1.2])
    y = np.array([0.0, 0.0, 0.7, 1.4, 0.2, 0.2, -3.0])
    cells, inside = grid_cells(x, y, 0.0, 0.0, 0.5, (3, 4))
    assert cells.tolist() == [0, 0, 5, 11, 0, 3, 2]
    assert inside.tolist() == [True, True, True, True, False, False, False]
    res = 0.1  # not a binary fraction: boundaries are where rounding could disagree
    edges = np.arange(-3, 40) * res
    bx, by = np.meshgrid(np.concatenate([edges, np.nextafter(edges, -1)]), edges)
    bx, by = bx.ravel(), by.ravel()
    numpy_cells, numpy_inside = grid_cells(bx, by, 0.0, 0.0, res, (30, 35))
    compiled_cells = np.empty(bx.size, dtype=np.int64)
    compiled_inside = np.empty(bx.size, dtype=np.bool_)
    _grid_cell_all(bx, by, res, 30.0, 35.0, compiled_cells, compiled_inside)
    assert np.array_equal(numpy_cells, compiled_cells)
    assert np.array_equal(numpy_inside, compiled_inside)
