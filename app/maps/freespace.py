"""Where a person can stand: the free-space grid, and the error every map problem raises.

Apart from :mod:`app.maps.model` so that the map preparation (:mod:`app.maps.prepare`),
which builds these grids, and the model, which asks for them, need not import each
other.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from app.maps.geometry import grid_cells

#: Every point of the free space is at least this far from every wall, in metres.
WALL_CLEARANCE_M = 0.1


class MapError(ValueError):
    """A map file that cannot be used; the message says which field and why.

    ``fields`` holds each (field, reason) pair when there are several.
    """

    def __init__(self, message: str, fields: list[tuple[str, str]] | None = None) -> None:
        super().__init__(message)
        self.fields = fields or [("(file)", message)]


@dataclass(frozen=True)
class FreeSpaceGrid:
    """Cells where a person can stand: enclosed by walls and clear of them.

    ``mask[row, col]`` covers the square with lower-left corner
    ``(origin_x + col * resolution_m, origin_y + row * resolution_m)``.
    """

    origin_x: float
    origin_y: float
    resolution_m: float
    mask: NDArray[np.bool_]  # shape (rows, cols)
    free_cells: NDArray[np.int64] = field(repr=False)  # flat indices of free cells

    def cell_index(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Row-major flat cell index for each point and whether it is on the grid.

        Points off the grid get the nearest edge cell (see :func:`grid_cells`).
        """
        return grid_cells(x, y, self.origin_x, self.origin_y, self.resolution_m, self.mask.shape)

    def is_free(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.bool_]:
        """Whether each point lies in a free cell (False off the grid)."""
        flat, inside = self.cell_index(x, y)
        return inside & self.mask.reshape(-1)[flat]

    def distance_outside(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """How far (m) each point lies from the free space: 0 in a free cell, else from
        its cell's centre to the nearest free cell's; off the grid, the nearest edge
        cell's distance plus the way to the grid."""
        flat, inside = self.cell_index(x, y)
        far = self._outside_m.reshape(-1)[flat]
        if inside.all():
            return far
        rows, cols = self.mask.shape
        px, py = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        ex = np.clip(px, self.origin_x, self.origin_x + cols * self.resolution_m)
        ey = np.clip(py, self.origin_y, self.origin_y + rows * self.resolution_m)
        return np.where(inside, far, far + np.hypot(px - ex, py - ey))

    @functools.cached_property
    def _outside_m(self) -> NDArray[np.float64]:
        """Per cell, :meth:`distance_outside` at its centre (scipy's Euclidean distance
        transform of the cells outside the free space); built when a map's grids are
        attached (:meth:`~app.maps.model.SemanticMap.attach`), not on a first use."""
        far = np.asarray(ndimage.distance_transform_edt(~self.mask), dtype=np.float64)
        return far * self.resolution_m

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` points uniform over the free space, shape (n, 2)."""
        if self.free_cells.size == 0:
            raise MapError("the map has no free space inside its walls")
        cols = self.mask.shape[1]
        pick = self.free_cells[rng.integers(0, self.free_cells.size, size=n)]
        r, c = np.divmod(pick, cols)
        jitter = rng.random((n, 2))
        x = self.origin_x + (c + jitter[:, 0]) * self.resolution_m
        y = self.origin_y + (r + jitter[:, 1]) * self.resolution_m
        return np.column_stack([x, y])
