"""Plane geometry on numpy arrays: angles, segment crossings, polygons.

Everything here is vectorized and unit-agnostic except angles, which are radians.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Tolerance of the segment tests (parallel lines, touching end points).
GEOMETRY_EPS = 1e-9


def wrap_angle(angle_rad: ArrayLike) -> FloatArray:
    """Wrap angles to the half-open interval (-pi, pi].

    Works element-wise on scalars and arrays of any shape.
    """
    a = np.asarray(angle_rad, dtype=np.float64)
    wrapped = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    # np.mod maps +pi to -pi; the contract's interval is closed at +pi.
    return np.where(wrapped <= -np.pi, np.pi, wrapped)


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
    shape_out = np.broadcast_shapes(np.shape(x), np.shape(y)) or (1,)
    xs = np.broadcast_to(np.asarray(x, dtype=np.float64), shape_out)
    ys = np.broadcast_to(np.asarray(y, dtype=np.float64), shape_out)
    rows, cols = shape
    flat, inside = grid_cell(xs, ys, origin_x, origin_y, 1.0 / resolution_m, rows, cols)
    return flat.astype(np.int64), inside
