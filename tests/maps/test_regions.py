"""Region lookups: the grid behind ``region_at`` gives the exact polygon test's answer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from app.maps.check import load_map
from app.maps.geometry import PolygonCells, first_polygon, polygon_edges
from app.maps.model import parse_map
from app.resources import bundled_maps_dir

# The exact test meets infinities in its arithmetic (its answer is still "in none").
pytestmark = pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")

NON_FINITE = [(math.nan, 1.0), (1.0, math.nan), (math.inf, 1.0), (-math.inf, 1.0), (1.0, -math.inf)]


def hard_points(edges: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    """Points where a lookup can go wrong: on and next to edges and vertices, on round
    numbers (cell borders), and anywhere around the polygons."""
    a, b = edges[:, :2], edges[:, 2:]
    lo, hi = edges.reshape(-1, 2).min(axis=0) - 1.0, edges.reshape(-1, 2).max(axis=0) + 1.0
    on = a + rng.random((a.shape[0], 1)) * (b - a)
    parts = [rng.uniform(lo, hi, (3000, 2)), np.round(rng.uniform(lo, hi, (3000, 2)) * 20) / 20]
    for eps in (0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.05):
        parts += [on + eps * rng.normal(size=on.shape), a + eps * rng.normal(size=a.shape)]
    parts.append(np.column_stack([np.nextafter(a[:, 0], np.inf), np.nextafter(a[:, 1], -np.inf)]))
    return np.vstack(parts)


def assert_exact(
    polygons: list[NDArray[np.float64]], rng: np.random.Generator, most: int = 50_000
) -> PolygonCells:
    edges, starts = polygon_edges(polygons)
    cells = PolygonCells(edges, starts)
    points = hard_points(edges, rng)
    points = points[rng.permutation(points.shape[0])[:most]]
    want = first_polygon(points, edges, starts).tolist()
    assert [cells.first(x, y) for x, y in points.tolist()] == want
    for x, y in NON_FINITE:
        assert cells.first(x, y) == int(first_polygon([[x, y]], edges, starts)[0])
    return cells


@pytest.mark.parametrize("name", ["paper_office", "two_wing_office"])
def test_bundled_maps_answer_as_the_exact_test(name: str) -> None:
    m = load_map(bundled_maps_dir() / f"{name}.json")
    points = hard_points(polygon_edges(m.region_polygons)[0], np.random.default_rng(1))
    want = [m.region_names[i] if i >= 0 else None for i in m.region_index(points)]
    assert [m.region_at(x, y) for x, y in points.tolist()] == want
    assert m._region_cells.gridded


def test_shared_borders_overlaps_and_odd_polygons() -> None:
    rng = np.random.default_rng(2)
    polygons = [
        np.array([[0, 0], [5, 0], [5, 5], [0, 5]], dtype=float),  # shares x = 5 with the next
        np.array([[5, 0], [10, 0], [10, 5], [5, 5]], dtype=float),
        np.array([[4, 4], [6, 4], [6, 6], [4, 6]], dtype=float),  # overlaps both
        np.array([[1, 1], [3, 3], [1, 3], [3, 1]], dtype=float),  # crosses itself
        np.array([[6, 1], [9, 1 + 1e-300], [9, 3]]),  # an almost level edge
        np.array([[7, 2], [8, 2], [8, 2.5], [8, 2.5], [7, 2.5]]),  # a repeated vertex
    ]
    assert assert_exact(polygons, rng).gridded


def test_random_polygons() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        polygons = [rng.uniform(0, 12, (int(rng.integers(3, 9)), 2)) for _ in range(3)]
        assert_exact(polygons, rng)


def test_huge_coordinates_take_the_exact_test() -> None:
    """Far from the origin rounding is not small against a cell: no grid, same answers."""
    square = np.array([[0, 0], [3, 0], [3, 3], [0, 3]], dtype=float)
    cells = assert_exact([square + 1e12], np.random.default_rng(4))
    assert not cells.gridded


def test_a_grid_too_costly_to_build_is_skipped() -> None:
    rng = np.random.default_rng(5)
    cells = assert_exact([rng.uniform(0, 1000, (3000, 2))], rng, most=300)
    assert not cells.gridded


def test_no_regions() -> None:
    m = parse_map({"name": "bare", "objects": [{"class": "door", "x": 1, "y": 1}]})
    assert m.region_at(1.0, 1.0) is None and m.region_at(math.nan, 0.0) is None
