"""Angle wrapping, segment crossings, points against walls, polygons."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from app.maps.geometry import (
    enclosed,
    nearest_walls,
    point_segment_distance,
    points_in_polygon,
    points_in_polygons,
    polygon_edges,
    segments_cross_walls,
    wrap_angle,
    wrap_deg,
    wrap_rad,
)


@given(st.floats(min_value=-1e4, max_value=1e4, allow_nan=False))
def test_wrap_angle_lands_in_half_open_interval_and_keeps_direction(a: float) -> None:
    w = float(wrap_angle(a))
    assert -np.pi < w <= np.pi
    assert np.isclose(np.cos(w), np.cos(a), atol=1e-6)
    assert np.isclose(np.sin(w), np.sin(a), atol=1e-6)


def _numpy_wrap(a: np.ndarray) -> np.ndarray:
    """The wrap as numpy's ufuncs compute it (what the compiled one must match)."""
    with np.errstate(invalid="ignore"):
        w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w <= -np.pi, np.pi, w)


def test_wrap_angle_matches_numpy_mod_to_the_bit_in_any_shape() -> None:
    rng = np.random.default_rng(3)
    edges = np.array(
        [0.0, -0.0, np.pi, -np.pi, 2 * np.pi, -2 * np.pi, 3 * np.pi, 1e300, -1e300, 5e-324,
         np.nextafter(np.pi, 0), np.nextafter(-np.pi, 0), np.nextafter(np.pi, 4),
         np.nextafter(-np.pi, -4), np.nan, np.inf, -np.inf]
    )  # fmt: skip
    cases = [
        edges,
        rng.uniform(-10.0, 10.0, 5000),
        rng.normal(0.0, 1e6, 5000),
        rng.uniform(-7.0, 7.0, (30, 40))[:, ::3],  # not contiguous
        np.zeros((0, 3)),
    ]
    for a in cases:
        got, want = wrap_angle(a), _numpy_wrap(a)
        assert got.shape == want.shape
        bits = np.ascontiguousarray(got).view(np.int64)
        assert np.array_equal(bits, np.ascontiguousarray(want).view(np.int64))
    for v in edges.tolist():  # a scalar gives a scalar, the same bits
        got_one = wrap_angle(v)
        assert np.ndim(got_one) == 0
        assert np.float64(got_one).view(np.int64) == np.float64(_numpy_wrap(np.array(v))).view(
            np.int64
        )


def test_wrap_rad_matches_the_array_wrap_to_the_bit() -> None:
    rng = np.random.default_rng(4)
    values = np.concatenate(
        [
            [0.0, -0.0, np.pi, -np.pi, 2 * np.pi, -2 * np.pi, 3 * np.pi, 1e300, -1e300],
            [5e-324, np.nextafter(np.pi, 0), np.nextafter(-np.pi, 0), np.nextafter(np.pi, 4)],
            [np.nextafter(-np.pi, -4), np.nan, np.inf, -np.inf],
            rng.uniform(-10.0, 10.0, 5000),
            rng.normal(0.0, 1e6, 2000),
        ]
    )
    for v in values.tolist():
        got = wrap_rad(v)
        assert isinstance(got, float)
        want = float(wrap_angle(v))
        if np.isnan(want):
            assert np.isnan(got)
        else:
            assert np.float64(got).view(np.int64) == np.float64(want).view(np.int64), v


def test_wrap_deg_edges() -> None:
    assert wrap_deg(180.0) == 180.0
    assert wrap_deg(-180.0) == 180.0
    assert np.isclose(wrap_deg(540.0), 180.0)
    assert np.isclose(wrap_deg(-90.0), -90.0)
    assert np.isclose(wrap_deg(370.0), 10.0)


def test_segment_crossing_cases() -> None:
    wall = np.array([[1.0, -1.0, 1.0, 1.0]])
    start = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 2.0], [2.0, 0.0]])
    end = np.array([[2.0, 0.0], [0.9, 0.0], [2.0, 2.0], [1.0, 0.0]])
    assert segments_cross_walls(start, end, wall).tolist() == [True, False, False, False]
    ignored = segments_cross_walls(start, end, wall, ignore=np.array([True]))
    assert not ignored.any()


def test_points_in_polygon_square() -> None:
    square = [[0, 0], [2, 0], [2, 2], [0, 2]]
    inside = points_in_polygon([[1, 1], [3, 1], [-0.1, 1], [1.9, 1.9]], square)
    assert inside.tolist() == [True, False, False, True]


def test_points_in_several_polygons_at_once() -> None:
    """Every region at once answers as each polygon alone; no polygon, or one without
    edges, holds no point."""
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    triangle = np.array([[5.0, 5.0], [7.0, 5.0], [6.0, 7.0]])
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1.0, 8.0, (500, 2))
    inside = points_in_polygons(pts, *polygon_edges([square, np.empty((0, 2)), triangle]))
    assert inside.shape == (500, 3)
    assert np.array_equal(inside[:, 0], points_in_polygon(pts, square))
    assert not inside[:, 1].any()
    assert np.array_equal(inside[:, 2], points_in_polygon(pts, triangle))
    assert inside[:, 0].any() and inside[:, 2].any()
    assert points_in_polygons(pts, *polygon_edges([])).shape == (500, 0)


def test_nearest_walls_kernel_matches_the_numpy_distances() -> None:
    """The compiled kernel against :func:`point_segment_distance` (the reference): the
    same float64 operations in the same order, each correctly rounded (no fastmath, so
    no fused multiply-adds), hence the same bits; the index is the reference's argmin
    and ``near`` its comparison."""
    rng = np.random.default_rng(4)
    walls = rng.uniform(-1.0, 11.0, (40, 4))
    walls[:3, 2:] = walls[:3, :2]  # degenerate walls (points) too
    points = rng.uniform(-2.0, 12.0, (300, 2))
    dist, index, near = nearest_walls(points, walls, tolerance=0.5)
    ref = point_segment_distance(points, walls)
    assert np.array_equal(dist, ref.min(axis=1))
    assert np.array_equal(index, ref.argmin(axis=1))
    assert np.array_equal(near, ref < 0.5)
    none_d, none_i, none_near = nearest_walls(points, np.empty((0, 4)))
    assert np.isinf(none_d).all() and (none_i == -1).all() and none_near.shape == (300, 0)


def test_enclosed_needs_a_wall_on_all_four_sides() -> None:
    box = np.array([[0, 0, 4, 0], [4, 0, 4, 3], [4, 3, 0, 3], [0, 3, 0, 0]], dtype=float)
    pts = np.array([[2.0, 1.5], [5.0, 1.5], [2.0, -1.0], [0.5, 2.5]])
    assert enclosed(pts, box).tolist() == [True, False, False, True]
    open_side = box[:3]  # no west wall: nothing is enclosed
    assert not enclosed(pts, open_side).any()
    assert enclosed(pts, np.empty((0, 4))).all()  # a map without walls: everywhere
