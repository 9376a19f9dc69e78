"""Per-map visibility grid: which objects are in line of sight from each cell.

Ray-testing every particle against every wall for every object would dominate a
filter step, so each map gets a grid, computed once and cached on the map: for
each cell of the free-space grid (coarsened for large maps), a boolean row saying
which objects a person standing at the cell centre could see. Particles look up
their cell's row. Objects mounted in a wall (doors, windows) are not hidden by it
(see :meth:`SemanticMap.line_of_sight`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from app.maps.geometry import grid_cells
from app.maps.model import SemanticMap

#: Upper bound on grid cells x objects (bytes of the boolean table).
MAX_TABLE_BYTES = 24_000_000

_lock = threading.Lock()


@dataclass(frozen=True)
class VisibilityGrid:
    """Line-of-sight table over a regular grid.

    Attributes:
        origin_x, origin_y: lower-left corner of cell (0, 0), metres.
        resolution_m: cell side, metres.
        shape: (rows, cols).
        table: ``table[cell, object]`` is True when the object is visible from the
            cell centre, shape (rows * cols, N), row-major cells.
    """

    origin_x: float
    origin_y: float
    resolution_m: float
    shape: tuple[int, int]
    table: NDArray[np.bool_]
    #: The same table packed in bits, shape (rows * cols, ceil(N / 64)): bit ``o % 64``
    #: of word ``o // 64`` is object ``o``. One load per particle serves 64 objects.
    bits: NDArray[np.uint64]

    def cells(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]:
        """Flat cell index per point, clipped onto the grid, shape (M,)."""
        return grid_cells(x, y, self.origin_x, self.origin_y, self.resolution_m, self.shape)[0]

    def visible(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.bool_]:
        """Visibility rows for each point, shape (M, N)."""
        return self.table[self.cells(x, y)]


def build_visibility_grid(semantic_map: SemanticMap) -> VisibilityGrid:
    """Compute the table for a map (cell centres ray-tested against every wall)."""
    fs = semantic_map.free_space
    n_obj = max(semantic_map.object_count, 1)
    res = fs.resolution_m
    rows, cols = fs.mask.shape
    # Coarsen until the table fits the budget.
    factor = 1
    while (rows // factor + 1) * (cols // factor + 1) * n_obj > MAX_TABLE_BYTES:
        factor += 1
    res *= factor
    rows = int(np.ceil(fs.mask.shape[0] / factor))
    cols = int(np.ceil(fs.mask.shape[1] / factor))
    cx = fs.origin_x + (np.arange(cols) + 0.5) * res
    cy = fs.origin_y + (np.arange(rows) + 0.5) * res
    gx, gy = np.meshgrid(cx, cy)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    table = np.zeros((centres.shape[0], semantic_map.object_count), dtype=bool)
    # Only cells that contain free space matter; the rest stay False.
    coarse_free = np.zeros(rows * cols, dtype=bool)
    fr, fc = np.divmod(fs.free_cells, fs.mask.shape[1])
    coarse_free[(fr // factor) * cols + (fc // factor)] = True
    idx = np.flatnonzero(coarse_free)
    step = 20_000
    for start in range(0, idx.size, step):
        part = idx[start : start + step]
        table[part] = semantic_map.line_of_sight(centres[part])
    return VisibilityGrid(fs.origin_x, fs.origin_y, res, (rows, cols), table, pack_bits(table))


def pack_bits(table: NDArray[np.bool_]) -> NDArray[np.uint64]:
    """Pack a boolean (cells, N) table into (cells, ceil(N / 64)) little-endian words."""
    cells, n = table.shape
    words = max((n + 63) // 64, 1)
    padded = np.zeros((cells, words * 64), dtype=bool)
    padded[:, :n] = table
    packed = np.packbits(padded.reshape(cells, words, 64), axis=2, bitorder="little")
    return packed.view("<u8").reshape(cells, words).astype(np.uint64)


def visibility_grid(semantic_map: SemanticMap) -> VisibilityGrid:
    """The map's visibility grid, built on first use and cached on the map (thread-safe)."""
    grid = getattr(semantic_map, "_visibility_grid", None)
    if grid is None:
        with _lock:
            grid = getattr(semantic_map, "_visibility_grid", None)
            if grid is None:
                grid = build_visibility_grid(semantic_map)
                # Cached on the map object itself (SemanticMap declares no such field).
                semantic_map._visibility_grid = grid  # type: ignore[attr-defined]
    return grid
