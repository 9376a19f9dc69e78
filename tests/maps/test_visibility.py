"""The visibility grid: what a person standing in a cell can see."""

from __future__ import annotations

import numpy as np

from app.maps.visibility import _unpack_row, pack_bits, unpack_bits
from tests.helpers import room

#: An inner wall at x = 3 with a door in it at (3, 2); a window on the west wall, a table
#: in each half of the room.
SPLIT = room(
    [
        {"class": "door", "x": 3, "y": 2},
        {"class": "window", "x": 0, "y": 3},
        {"class": "table", "x": 1.5, "y": 1},
        {"class": "table", "x": 4.5, "y": 1},
    ],
    walls=[{"x1": 3, "y1": 0, "x2": 3, "y2": 4}],
)
DOOR, WINDOW, WEST_TABLE, EAST_TABLE = range(4)


def test_a_wall_hides_what_is_behind_it() -> None:
    east = SPLIT.visibility.visible([4.5], [3.0])[0]
    west = SPLIT.visibility.visible([1.5], [3.0])[0]
    assert east[EAST_TABLE] and not east[WEST_TABLE] and not east[WINDOW]
    assert west[WEST_TABLE] and west[WINDOW] and not west[EAST_TABLE]


def test_a_door_is_not_hidden_by_its_own_wall() -> None:
    """Mounted in the inner wall, the door is seen from both halves of the room."""
    assert SPLIT.mounted_walls[DOOR].any()
    for x in (1.0, 2.5, 3.5, 5.0):
        assert SPLIT.visibility.visible([x], [2.5])[0][DOOR], x


def test_every_free_cell_sees_what_its_centre_sees() -> None:
    grid = SPLIT.visibility
    pts = SPLIT.free_space.sample(300, np.random.default_rng(0))
    cells = grid.cells(pts[:, 0], pts[:, 1])
    rows, cols = grid.shape
    centres = np.column_stack(
        [
            grid.origin_x + (cells % cols + 0.5) * grid.resolution_m,
            grid.origin_y + (cells // cols + 0.5) * grid.resolution_m,
        ]
    )
    assert np.array_equal(grid.visible(pts[:, 0], pts[:, 1]), SPLIT.line_of_sight(centres))
    assert cells.max() < rows * cols


def test_packed_bits_hold_the_table() -> None:
    table = np.random.default_rng(1).random((7, 130)) < 0.5
    bits = pack_bits(table)
    assert bits.shape == (7, 3) and bits.dtype == np.uint64
    objects = np.arange(130)
    unpacked = (bits[:, objects // 64] >> (objects % 64).astype(np.uint64)) & np.uint64(1)
    assert np.array_equal(unpacked.astype(bool), table)
    assert np.array_equal(SPLIT.visibility.bits, pack_bits(SPLIT.visibility.table))


def test_one_point_rows_are_the_grid_cells_rows() -> None:
    """``row`` computes the cell in Python floats; it must be grid_cell's cell everywhere:
    on cell edges, off the grid and far off (overflowing the cell arithmetic)."""
    grid = SPLIT.visibility
    res = grid.resolution_m
    edges = [
        (grid.origin_x + i * res, grid.origin_y + j * res)
        for i in range(-2, 80, 3)
        for j in range(-2, 50, 3)
    ]
    odd = [(-1e308, 2.0), (1e308, -1e308), (3.0, 1e300), (float("inf"), 0.0)]
    rng = np.random.default_rng(1)
    points = [*rng.uniform(-3, 9, (500, 2)).tolist(), *edges, *odd]
    for x, y in points:
        with np.errstate(over="ignore"):
            assert np.array_equal(grid.row(x, y), grid.visible([x], [y])[0]), (x, y)
            # The same point again (answered from the last point's memo), as numpy floats.
            again = grid.row(np.float64(x), np.float64(y))
            assert np.array_equal(again, grid.visible([x], [y])[0]), (x, y)


def test_a_cells_row_unpacks_like_the_table() -> None:
    """The compiled one-row unpacking against numpy's, for tables of 1 to 200 objects
    (one word, a word's edge, several words)."""
    rng = np.random.default_rng(5)
    for n in (1, 2, 63, 64, 65, 127, 128, 129, 200):
        table = rng.random((40, n)) < 0.5
        bits = pack_bits(table)
        for cell in range(40):
            row = _unpack_row(bits[cell], n)
            assert row.dtype == np.bool_
            assert np.array_equal(row, unpack_bits(bits[cell : cell + 1], n)[0]), (n, cell)
            assert np.array_equal(row, table[cell])
