"""Plane geometry on numpy arrays: angles, segment crossings, points and walls, polygons.

Everything here is vectorized and unit-agnostic except angles, which are radians;
:class:`PolygonCells` answers one point at a time from a grid built with arrays. The
compiled point-and-wall tests (:func:`crosses_wall`, :func:`nearest_walls`,
:func:`enclosed`) serve the map model, its checks and the grids prepared from it
(:mod:`app.maps.prepare`), which all stand on this module.
"""

from __future__ import annotations

import math
from array import array

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Tolerance of the segment tests (parallel lines, touching end points).
GEOMETRY_EPS = 1e-9


def wrap_angle(angle_rad: ArrayLike) -> FloatArray:
    """Wrap angles to the half-open interval (-pi, pi].

    Works element-wise on scalars and arrays of any shape. The arithmetic is numpy's
    ``np.mod(a + pi, 2 pi) - pi`` to the last bit (C's ``fmod``, then the divisor added
    to a negative remainder, both exact), compiled: the filter wraps small arrays
    several times a frame, where numpy's five calls per wrap cost more than the work.
    """
    a = np.asarray(angle_rad, dtype=np.float64)
    wrapped: FloatArray = _wrap_array(a.reshape(-1))
    return wrapped[0] if a.ndim == 0 else wrapped.reshape(a.shape)


def wrap_rad(angle: float) -> float:
    """:func:`wrap_angle` of one Python float, without numpy: the same IEEE operations
    (``math.fmod`` is C's ``fmod``, the additions exact), so the same bits, in a tenth
    of the time of a numpy call (the convergence gate wraps one angle every frame)."""
    if not math.isfinite(angle):
        return math.nan  # (math.fmod raises on infinities where C's gives NaN)
    two_pi = 2.0 * math.pi
    m = math.fmod(angle + math.pi, two_pi)
    if m < 0.0:
        m += two_pi
    elif m == 0.0:
        m = 0.0
    w = m - math.pi
    return math.pi if w <= -math.pi else w


@njit(cache=True, inline="always")
def wrap_scalar(angle: float) -> float:  # pragma: no cover - compiled
    """:func:`wrap_angle` of one angle, for compiled kernels (:func:`wrap_rad` is its
    Python twin: numba compiles no ``math.fmod``, so the two texts stay apart, and
    tests/maps/test_geometry.py holds them to the same bits)."""
    # np.mod's float remainder: fmod, moved into [0, 2 pi) when negative, +0.0 when zero.
    two_pi = 2.0 * np.pi
    m = np.fmod(angle + np.pi, two_pi)
    if m < 0.0:
        m += two_pi
    elif m == 0.0:
        m = 0.0
    w = m - np.pi
    # np.mod maps +pi to -pi; the contract's interval is closed at +pi.
    return np.pi if w <= -np.pi else w


@njit(cache=True)
def _wrap_array(flat: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    out = np.empty(flat.size)
    for i in range(flat.size):
        out[i] = wrap_scalar(flat[i])
    return out


def wrap_deg(angle_deg: float) -> float:
    """Wrap one angle in degrees to (-180, 180].

    Plain float arithmetic: it runs for every detection of every frame on the event loop,
    where numpy's per-call overhead on a scalar was a tenth of the loop's time under load.
    """
    angle = float(angle_deg)
    if -180.0 < angle <= 180.0:
        return angle  # already in range: returned exactly
    wrapped = (angle + 180.0) % 360.0 - 180.0  # Python's % is in [0, 360)
    return 180.0 if wrapped <= -180.0 else wrapped


def segments_cross_walls(
    start: ArrayLike, end: ArrayLike, walls: ArrayLike, *, ignore: ArrayLike | None = None
) -> NDArray[np.bool_]:
    """Whether each segment start->end properly crosses at least one wall.

    Args:
        start: segment start points, shape (M, 2).
        end: segment end points, shape (M, 2).
        walls: wall segments as rows (x1, y1, x2, y2), shape (W, 4).
        ignore: optional boolean mask, shape (M, W) or (W,): walls to skip per segment
            (e.g. the wall a door is mounted in).

    Returns:
        Boolean array, shape (M,). Touching a wall exactly at a segment end point
        counts as crossing only when the touch is strictly inside both segments.
    """
    p = np.atleast_2d(np.asarray(start, dtype=np.float64))
    q = np.atleast_2d(np.asarray(end, dtype=np.float64))
    w = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    if w.shape[0] == 0:
        return np.zeros(np.broadcast_shapes(p.shape, q.shape)[0], dtype=bool)
    r = (q - p)[:, None, :]  # (M, 1, 2)
    a = w[None, :, 0:2]  # (1, W, 2)
    s = (w[:, 2:4] - w[:, 0:2])[None, :, :]
    ap = a - p[:, None, :]
    denom = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]  # (M, W)
    t_num = ap[..., 0] * s[..., 1] - ap[..., 1] * s[..., 0]
    u_num = ap[..., 0] * r[..., 1] - ap[..., 1] * r[..., 0]
    parallel = np.abs(denom) < GEOMETRY_EPS
    safe = np.where(parallel, 1.0, denom)
    t = t_num / safe
    u = u_num / safe
    eps = GEOMETRY_EPS
    hit = (~parallel) & (t > eps) & (t < 1.0 - eps) & (u >= -eps) & (u <= 1.0 + eps)
    if ignore is not None:
        hit &= ~np.broadcast_to(np.asarray(ignore, dtype=bool), hit.shape)
    return np.asarray(hit.any(axis=1), dtype=np.bool_)


def point_segment_distance(points: ArrayLike, walls: ArrayLike) -> FloatArray:
    """Distance from each point to each segment.

    Args:
        points: shape (M, 2).
        walls: rows (x1, y1, x2, y2), shape (W, 4).

    Returns:
        Distances in map units, shape (M, W).
    """
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))[:, None, :]
    w = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    a = w[None, :, 0:2]
    d = (w[:, 2:4] - w[:, 0:2])[None, :, :]
    length_sq = np.maximum(np.sum(d * d, axis=-1), GEOMETRY_EPS)
    t = np.clip(np.sum((p - a) * d, axis=-1) / length_sq, 0.0, 1.0)
    closest = a + t[..., None] * d
    return np.linalg.norm(p - closest, axis=-1)


# ------------------------------------------------ compiled point and wall tests
@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def crosses_wall(px, py, qx, qy, ax, ay, bx, by, eps):  # fmt: skip  # pragma: no cover
    """Whether segment p->q properly crosses wall a->b (one pair of
    :func:`segments_cross_walls`, same tolerances)."""
    rx = qx - px
    ry = qy - py
    sx = bx - ax
    sy = by - ay
    denom = rx * sy - ry * sx
    if abs(denom) < eps:
        return False
    apx = ax - px
    apy = ay - py
    t = (apx * sy - apy * sx) / denom
    u = (apx * ry - apy * rx) / denom
    return eps < t < 1.0 - eps and -eps <= u <= 1.0 + eps


@njit(cache=True, nogil=True, error_model="numpy")
def _enclosed_points(px, py, walls, eps):  # fmt: skip  # pragma: no cover - compiled
    """Whether a wall crosses each point's horizontal and vertical lines on both sides."""
    out = np.zeros(px.shape[0], dtype=np.bool_)
    for i in range(px.shape[0]):
        x, y = px[i], py[i]
        left = right = down = up = False
        for w in range(walls.shape[0]):
            x1, y1, x2, y2 = walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
            if abs(y2 - y1) > eps and min(y1, y2) <= y <= max(y1, y2):
                cx = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
                left = left or cx < x
                right = right or cx > x
            if abs(x2 - x1) > eps and min(x1, x2) <= x <= max(x1, x2):
                cy = y1 + (x - x1) * (y2 - y1) / (x2 - x1)
                down = down or cy < y
                up = up or cy > y
            if left and right and down and up:
                out[i] = True
                break
    return out


def enclosed(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Whether each point (M, 2) has a wall on all four axis sides (the free space's
    enclosure, without the clearance), shape (M,)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    w = np.ascontiguousarray(walls, dtype=np.float64).reshape(-1, 4)
    if w.shape[0] == 0:
        return np.ones(pts.shape[0], dtype=bool)
    return _enclosed_points(pts[:, 0].copy(), pts[:, 1].copy(), w, GEOMETRY_EPS)


@njit(cache=True, nogil=True, error_model="numpy")
def _nearest_walls(px, py, walls, eps, tolerance, near):  # fmt: skip  # pragma: no cover
    """Distance to and index of each point's nearest wall; near[i, w] = within tolerance."""
    n = px.shape[0]
    dist = np.full(n, np.inf)
    index = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        for w in range(walls.shape[0]):
            x1, y1 = walls[w, 0], walls[w, 1]
            dx = walls[w, 2] - x1
            dy = walls[w, 3] - y1
            t = ((px[i] - x1) * dx + (py[i] - y1) * dy) / max(dx * dx + dy * dy, eps)
            t = min(max(t, 0.0), 1.0)
            ex = px[i] - (x1 + t * dx)
            ey = py[i] - (y1 + t * dy)
            d = np.sqrt(ex * ex + ey * ey)
            near[i, w] = d < tolerance
            if d < dist[i]:
                dist[i] = d
                index[i] = w
    return dist, index


def nearest_walls(
    points: np.ndarray, walls: np.ndarray, tolerance: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point (M, 2): distance to the nearest wall, its index (-1 without walls), and
    which walls lie closer than ``tolerance`` (M, W); compiled, no (M, W, 2) temporaries."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    w = np.ascontiguousarray(walls, dtype=np.float64).reshape(-1, 4)
    near = np.zeros((pts.shape[0], w.shape[0]), dtype=np.bool_)
    dist, index = _nearest_walls(
        pts[:, 0].copy(), pts[:, 1].copy(), w, GEOMETRY_EPS, float(tolerance), near
    )
    return dist, index, near


def polygon_edges(polygons: list[NDArray[np.float64]]) -> tuple[FloatArray, NDArray[np.int64]]:
    """The polygons' edges (x1, y1, x2, y2) joined, shape (E, 4), and where each
    polygon's edges start, shape (P,). Each polygon: vertices in order, not closed."""
    edges = [
        np.column_stack([poly, np.roll(poly, -1, axis=0)])
        for poly in (np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons)
    ]
    lengths = np.array([e.shape[0] for e in edges], dtype=np.int64)
    starts = np.cumsum(lengths) - lengths
    return (np.concatenate(edges) if edges else np.empty((0, 4))), starts


def points_in_polygons(
    points: ArrayLike, edges: FloatArray, starts: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """Even-odd rule: whether each point is inside each polygon, shape (M, P).

    ``edges`` and ``starts`` as :func:`polygon_edges` gives them (every polygon at once).
    """
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    if not starts.size:
        return np.zeros((pts.shape[0], 0), dtype=bool)
    x, y = pts[:, 0:1], pts[:, 1:2]
    x1, y1, x2, y2 = (edges[None, :, i] for i in range(4))
    straddles = (y1 > y) != (y2 > y)
    dy = np.where(y2 == y1, 1.0, y2 - y1)
    crossings = straddles & (x < x1 + (y - y1) * (x2 - x1) / dy)
    # Crossings per polygon from running sums (a polygon without edges counts none).
    running = np.concatenate(
        [np.zeros((pts.shape[0], 1), dtype=np.int64), np.cumsum(crossings, axis=1)], axis=1
    )
    ends = np.append(starts[1:], edges.shape[0])
    return (running[:, ends] - running[:, starts]) % 2 == 1


def first_polygon(
    points: ArrayLike, edges: FloatArray, starts: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Index of the first polygon containing each point (:func:`points_in_polygons`), or
    -1, shape (M,)."""
    inside = points_in_polygons(points, edges, starts)
    if not inside.shape[1]:
        return np.full(inside.shape[0], -1, dtype=np.int64)
    return np.where(inside.any(axis=1), np.argmax(inside, axis=1), -1)


#: Cell side of a :class:`PolygonCells` grid (units of the map) ...
POLYGON_CELL = 0.1
#: ... unless the polygons span more than this many cells: then larger cells.
POLYGON_CELLS_MAX = 512
#: Most (edge, grid row) pairs, and most (point, edge) tests, a grid may cost to build;
#: polygons that need more are always tested exactly.
POLYGON_GRID_WORK = 500_000
#: The cell code of a cell an edge passes near (its points take the exact test).
_NEAR_EDGE = -2


class PolygonCells:
    """:func:`first_polygon` for one point at a time, mostly from a grid.

    In a cell that no edge comes near, every point lies in the same polygons, so the
    cell keeps the exact test's answer for its centre; neighbouring such cells share
    it, so the grid is built with one exact test per patch of them. A point in a cell
    near an edge takes the exact test, as does every point when the grid would cost
    too much to build; a finite point off the grid, a cell or more outside all the
    polygons' bounding box, is in none. "Near" is within the cell's half diagonal of
    its centre plus a margin orders of magnitude above the exact test's rounding, so
    the answer is always the exact test's.
    """

    def __init__(self, edges: FloatArray, starts: NDArray[np.int64]) -> None:
        self.edges = edges
        self.starts = starts
        self.x0 = self.y0 = 0.0
        self.inv = 1.0
        self.cols = self.rows = 0
        self.codes = array("i")
        #: False when every point takes the exact test.
        self.gridded = True
        if edges.shape[0]:
            self.gridded = self._build()

    def first(self, x: float, y: float) -> int:
        """:func:`first_polygon` of the point (x, y)."""
        fx = (x - self.x0) * self.inv
        fy = (y - self.y0) * self.inv
        if 0.0 <= fx < self.cols and 0.0 <= fy < self.rows:
            code = self.codes[int(fy) * self.cols + int(fx)]
            if code != _NEAR_EDGE:
                return code
        elif self.gridded and math.isfinite(fx) and math.isfinite(fy):
            return -1
        return int(first_polygon([[x, y]], self.edges, self.starts)[0])

    def _build(self) -> bool:
        """Lay the grid and fill in its codes; False when that would cost too much."""
        e = self.edges
        lo_x, hi_x = float(e[:, 0::2].min()), float(e[:, 0::2].max())
        lo_y, hi_y = float(e[:, 1::2].min()), float(e[:, 1::2].max())
        margin = 1e-9 * (1.0 + max(abs(lo_x), abs(hi_x), abs(lo_y), abs(hi_y)))
        span = max(hi_x - lo_x, hi_y - lo_y)
        side = max(POLYGON_CELL, span / (POLYGON_CELLS_MAX - 2))
        if not side > 4.0 * margin:
            return False  # coordinates so large that rounding is not small against a cell
        # One cell of padding all round: off the grid is a cell away from every polygon.
        x0, y0 = lo_x - side, lo_y - side
        cols = int((hi_x - lo_x) / side) + 3
        rows = int((hi_y - lo_y) / side) + 3
        near = _cells_near_edges(e, x0, y0, side, rows, cols, 0.75 * side + 2.0 * margin)
        if near is None:
            return False
        # Runs of cells along a row with no edge near any of them share one answer, and so
        # does a run whose first cell has such a cell above it (with that cell's run).
        clear = ~near
        run_starts = clear.copy()
        run_starts[:, 1:] &= near[:, :-1]
        first_cells = np.flatnonzero(run_starts)
        run_of = np.cumsum(run_starts.ravel()) - 1
        above = first_cells - cols
        joined = above >= 0
        joined[joined] = clear.ravel()[above[joined]]
        parent = np.arange(first_cells.size)
        parent[joined] = run_of[above[joined]]
        while not np.array_equal(parent[parent], parent):  # each run to the top of its chain
            parent = parent[parent]
        tops = np.flatnonzero(parent == np.arange(parent.size))
        if tops.size * e.shape[0] > POLYGON_GRID_WORK:
            return False
        r, c = np.divmod(first_cells[tops], cols)
        centres = np.column_stack([x0 + (c + 0.5) * side, y0 + (r + 0.5) * side])
        answer = np.zeros(first_cells.size, dtype=np.int64)
        chunk = max(1, 100_000 // e.shape[0])
        for i in range(0, tops.size, chunk):
            answer[tops[i : i + chunk]] = first_polygon(centres[i : i + chunk], e, self.starts)
        codes = np.full(rows * cols, _NEAR_EDGE, dtype=np.int32)
        inside = clear.ravel()
        codes[inside] = answer[parent[run_of[inside]]]
        self.x0, self.y0, self.inv = x0, y0, 1.0 / side
        self.cols, self.rows = cols, rows
        self.codes = array("i", codes.tobytes())
        return True


def _cells_near_edges(
    edges: FloatArray, x0: float, y0: float, side: float, rows: int, cols: int, reach: float
) -> NDArray[np.bool_] | None:
    """Cells whose centre may lie within ``reach`` of an edge, shape (rows, cols).

    Generous: it may name a few cells more, never one fewer. Per edge and grid row, the
    part of the edge within ``reach`` of the row's centre line, widened by ``reach``.
    None when there are more than :data:`POLYGON_GRID_WORK` (edge, row) pairs.
    """
    x1, y1, x2, y2 = (edges[:, i] for i in range(4))
    low, high = np.minimum(y1, y2), np.maximum(y1, y2)
    first = np.clip(np.ceil((low - reach - y0) / side - 0.5), 0, rows - 1).astype(np.int64)
    last = np.clip(np.floor((high + reach - y0) / side - 0.5), -1, rows - 1).astype(np.int64)
    count = np.maximum(last - first + 1, 0)
    total = int(count.sum())
    if total > POLYGON_GRID_WORK:
        return None
    k = np.repeat(np.arange(edges.shape[0]), count)
    row = first[k] + np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    centre_y = y0 + (row + 0.5) * side
    band_lo = np.clip(centre_y - reach, low[k], high[k])
    band_hi = np.clip(centre_y + reach, low[k], high[k])
    # Where along the edge (0..1) the band starts and ends (a level edge: all of it).
    dy = y2[k] - y1[k]
    level = dy == 0.0
    along = np.where(level, 1.0, dy)
    t_lo = np.where(level, 0.0, np.clip((band_lo - y1[k]) / along, 0.0, 1.0))
    t_hi = np.where(level, 1.0, np.clip((band_hi - y1[k]) / along, 0.0, 1.0))
    at_lo = x1[k] + (x2[k] - x1[k]) * t_lo
    at_hi = x1[k] + (x2[k] - x1[k]) * t_hi
    left, right = np.minimum(at_lo, at_hi), np.maximum(at_lo, at_hi)
    c_first = np.clip(np.ceil((left - reach - x0) / side - 0.5), 0, cols).astype(np.int64)
    c_last = np.clip(np.floor((right + reach - x0) / side - 0.5), -1, cols - 1).astype(np.int64)
    keep = c_first <= c_last
    # Mark each row's column span: +1 where it starts, -1 after it ends, then sum along.
    marks = np.zeros((rows, cols + 1), dtype=np.int64)
    np.add.at(marks, (row[keep], c_first[keep]), 1)
    np.add.at(marks, (row[keep], c_last[keep] + 1), -1)
    return np.asarray(np.cumsum(marks, axis=1)[:, :cols] > 0)


def points_in_polygon(points: ArrayLike, polygon: ArrayLike) -> NDArray[np.bool_]:
    """Even-odd rule point-in-polygon test.

    Args:
        points: shape (M, 2).
        polygon: vertices in order, shape (V, 2), not closed (first != last needed).

    Returns:
        Boolean array, shape (M,).
    """
    return points_in_polygons(points, *polygon_edges([np.asarray(polygon)]))[:, 0]


def grid_cell(x, y, origin_x, origin_y, inv_res, rows, cols):  # fmt: skip
    """(row-major flat index of the cell holding (x, y) as a float, on the grid?).

    The one grid-cell lookup. Points off the grid get the nearest edge cell (the flag
    says they are off it); a point on a cell boundary belongs to the cell above and to
    the right. Plain numpy arithmetic that works on scalars and arrays alike, so the
    compiled kernels compile this very function
    (:data:`app.localization.fastmath.grid_cell`) and every caller puts a point into
    the same cell; :func:`grid_cells` is the array form.
    """
    fc = np.floor((x - origin_x) * inv_res)
    fr = np.floor((y - origin_y) * inv_res)
    inside = (fc >= 0.0) & (fc < cols) & (fr >= 0.0) & (fr < rows)
    c = np.minimum(np.maximum(fc, 0.0), cols - 1.0)
    r = np.minimum(np.maximum(fr, 0.0), rows - 1.0)
    return r * cols + c, inside


def grid_cells(
    x: ArrayLike,
    y: ArrayLike,
    origin_x: float,
    origin_y: float,
    resolution_m: float,
    shape: tuple[int, int],
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`grid_cell` for arrays of points: (flat cell index, on the grid?).

    Both outputs have the broadcast shape of ``x`` and ``y`` (shape (1,) for scalars).
    """
    if isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.shape == y.shape and x.ndim:
        # The common case (particles' coordinates), without broadcasting's Python calls.
        xs, ys = x.astype(np.float64, copy=False), y.astype(np.float64, copy=False)
    else:
        shape_out = np.broadcast_shapes(np.shape(x), np.shape(y)) or (1,)
        xs = np.broadcast_to(np.asarray(x, dtype=np.float64), shape_out)
        ys = np.broadcast_to(np.asarray(y, dtype=np.float64), shape_out)
    rows, cols = shape
    flat, inside = grid_cell(xs, ys, origin_x, origin_y, 1.0 / resolution_m, rows, cols)
    return flat.astype(np.int64), inside
