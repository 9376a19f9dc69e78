"""Per-map visibility grid: which objects are in line of sight from each cell.

Ray-testing every particle against every wall for every object would dominate a
filter step, so each map gets a grid, built when the map is loaded
(:mod:`app.maps.prepare`): for each cell of the free-space grid (coarsened for large
maps), a boolean row saying which objects a person standing at the cell centre could
see. Particles look up their cell's row. Objects mounted in a wall (doors, windows) are
not hidden by it (see :meth:`SemanticMap.line_of_sight`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from app.maps.geometry import grid_cell, grid_cells

#: Unpacked rows kept per grid by :meth:`VisibilityGrid.row` (a walk stays in few cells).
ROW_CACHE = 256


@dataclass(frozen=True)
class VisibilityGrid:
    """Line-of-sight table over a regular grid.

    Attributes:
        origin_x, origin_y: lower-left corner of cell (0, 0), metres.
        resolution_m: cell side, metres.
        shape: (rows, cols).
        bits: the table packed in bits, shape (rows * cols, ceil(N / 64)): bit
            ``o % 64`` of word ``o // 64`` is object ``o`` seen from the cell centre
            (row-major cells). One load per particle serves 64 objects.
        n_objects: N.
    """

    origin_x: float
    origin_y: float
    resolution_m: float
    shape: tuple[int, int]
    bits: NDArray[np.uint64]
    n_objects: int

    @cached_property
    def table(self) -> NDArray[np.bool_]:
        """The unpacked table, ``table[cell, object]``, shape (rows * cols, N).

        Unpacked on first use only (a large floor's is tens of MB; the service reads
        single rows through :meth:`visible`).
        """
        return unpack_bits(self.bits, self.n_objects)

    def cells(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]:
        """Flat cell index per point, clipped onto the grid, shape (M,)."""
        return grid_cells(x, y, self.origin_x, self.origin_y, self.resolution_m, self.shape)[0]

    def visible(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.bool_]:
        """Visibility rows for each point, shape (M, N)."""
        return unpack_bits(self.bits[self.cells(x, y)], self.n_objects)

    def row(self, x: float, y: float) -> NDArray[np.bool_]:
        """The visibility row of one point, shape (N,), read-only.

        Same cell as :meth:`visible`; the unpacked rows of recently used cells are kept,
        since the estimate, the fit check and the narrator all ask for the same point
        every frame.
        """
        memo = self._last_row
        last = memo[0]
        if last is not None and last[0] == x and last[1] == y:
            return last[2]
        row = self._point_row(x, y)
        memo[0] = (x, y, row)  # one assignment: a reader on another thread sees all or none
        return row

    def _point_row(self, x: float, y: float) -> NDArray[np.bool_]:
        rows, cols = self.shape
        x, y, inv = float(x), float(y), 1.0 / self.resolution_m
        fx, fy = (x - self.origin_x) * inv, (y - self.origin_y) * inv
        if math.isfinite(fx) and math.isfinite(fy):
            # grid_cell's arithmetic on Python floats (the same IEEE operations, without
            # a numpy call per operation): this runs several times per frame.
            c = min(max(float(math.floor(fx)), 0.0), cols - 1.0)
            r = min(max(float(math.floor(fy)), 0.0), rows - 1.0)
            return self._cell_row(int(r * cols + c))
        flat, _ = grid_cell(x, y, self.origin_x, self.origin_y, inv, rows, cols)
        return self._cell_row(int(flat))

    def _cell_row(self, cell: int) -> NDArray[np.bool_]:
        cache = self._rows
        hit = cache.get(cell)
        if hit is None:
            # Compiled: with many people walking, most frames meet a cell not kept.
            hit = _unpack_row(self.bits[cell], self.n_objects)
            hit.flags.writeable = False
            if len(cache) >= ROW_CACHE:
                cache.pop(next(iter(cache)))
            cache[cell] = hit
        return hit

    @cached_property
    def _last_row(self) -> list[tuple[float, float, NDArray[np.bool_]] | None]:
        """The last point :meth:`row` answered and its row (the fit check and the
        narrator ask for the same estimate one after the other)."""
        return [None]

    @cached_property
    def _rows(self) -> dict[int, NDArray[np.bool_]]:
        return {}


def pack_bits(table: NDArray[np.bool_]) -> NDArray[np.uint64]:
    """Pack a boolean (cells, N) table into (cells, ceil(N / 64)) little-endian words."""
    cells, n = table.shape
    words = max((n + 63) // 64, 1)
    padded = np.zeros((cells, words * 64), dtype=bool)
    padded[:, :n] = table
    packed = np.packbits(padded.reshape(cells, words, 64), axis=2, bitorder="little")
    return packed.view("<u8").reshape(cells, words).astype(np.uint64)


@njit(cache=True, nogil=True)
def _unpack_row(words: NDArray[np.uint64], n: int) -> NDArray[np.bool_]:  # pragma: no cover
    """One cell's row of :func:`unpack_bits`: bit ``o % 64`` of word ``o // 64``."""
    out = np.empty(n, dtype=np.bool_)
    one = np.uint64(1)
    for o in range(n):
        out[o] = (words[o >> 6] >> np.uint64(o & 63)) & one
    return out


def unpack_bits(bits: NDArray[np.uint64], n: int) -> NDArray[np.bool_]:
    """The inverse of :func:`pack_bits`: (cells, words) words to a (cells, n) table."""
    words = np.ascontiguousarray(bits, dtype="<u8")
    flat = np.unpackbits(words.view(np.uint8), axis=-1, bitorder="little")
    return flat[..., :n].astype(bool)
