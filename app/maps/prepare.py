"""Prepare a map for the filter: its free-space and visibility grids, built once at load.

Both grids used to be built inside the first request that needed them; on a floor of a
few hundred walls that took a minute. Here they are built when a map is loaded
(service start or reload), by compiled kernels that touch only what each wall can
reach, and stored on disk keyed by the map's content hash, so a restart reads them back
instead of building them again.

* **Free space** (:class:`~app.maps.freespace.FreeSpaceGrid`): cells enclosed by walls in
  all four axis directions and wholly at least ``WALL_CLEARANCE_M`` from every wall.
  For each grid row the kernel keeps the leftmost and rightmost crossing of the row's
  centre line by any wall (and likewise per column): a cell is enclosed when a wall
  crosses its row on both sides and its column on both sides. Clearance is exact:
  each wall marks only the cells within reach of its bounding box.
* **Visibility** (:class:`~app.maps.visibility.VisibilityGrid`): per cell holding free
  space, which objects the cell centre sees. Each (cell, object) ray is tested only
  against the walls that span its direction as seen from the object (angular bins per
  object), the wall that blocked the neighbouring cell's ray first (neighbouring rays
  are mostly blocked by the same wall), so a blocked ray usually costs one test and a
  clear one a handful.

The cache lives in ``BEARINGS_CACHE_DIR`` (default ``~/.cache/bearings``); a file there
is named by the SHA-256 of the map's canonical JSON and of this module's
``PREPARE_VERSION``, so an edited map or a changed builder never reads a stale grid.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from app.maps.freespace import WALL_CLEARANCE_M, FreeSpaceGrid
from app.maps.geometry import GEOMETRY_EPS, crosses_wall
from app.maps.model import SemanticMap
from app.maps.visibility import VisibilityGrid, pack_bits

log = logging.getLogger("bearings.maps")

#: Bump when the grids built here change meaning, so old cache files are not read.
#: 2: a map with levels gets the free-space cells of one floor per level.
PREPARE_VERSION = 2
#: The free-space grid aims at about this many cells per level (never finer than 5 cm).
#: A map's levels lie side by side in one plane (app.maps.levels), so one budget for
#: the plane made each floor's cells coarser the more floors a venue had: measured on a
#: real university building's six floors (imported from its IMDF files, not in this
#: repository), 0.42 m cells, whose 0.1 m clearance from every wall closed its lift
#: cars' doorways to the particles (a point 0.42 m from the nearest wall not free): a
#: phone's dead-reckoned fix was held at the car's door while the person stepped in,
#: 1.0-1.35 m behind. With the cells of one floor per level (0.17 m there), its walks
#: at PDR grade through a 66 deg camera went from 6 confidently-wrong frames of 4,210 to
#: 0 and from 0.30 to 0.68 of the frames within 0.5 m told, at VIO grade through a
#: 180 deg camera from 0.72 to 0.95 (6 walks each, 10,000 particles).
FREE_SPACE_CELLS = 200_000
MIN_RESOLUTION_M = 0.05
#: Upper bound on visibility cells x objects (bytes of the boolean table).
MAX_TABLE_BYTES = 24_000_000
#: Upper bound on the estimated ray-wall tests of the visibility grid (cells x objects
#: x walls per angular bin); beyond it the grid is coarsened so preparation stays bounded.
MAX_VISIBILITY_WORK = 3_000_000_000


@dataclass(frozen=True)
class PreparedMap:
    """The grids of one map and how they were obtained."""

    free_space: FreeSpaceGrid
    visibility: VisibilityGrid
    seconds: float
    from_cache: bool


# ----------------------------------------------------------------------- kernels
@njit(cache=True, nogil=True, error_model="numpy")
def _free_mask(walls, ox, oy, res, rows, cols, clearance, eps):  # fmt: skip  # pragma: no cover
    """The free-space mask (rows, cols): enclosed on four sides and clear of walls."""
    row_lo = np.full(rows, np.inf)
    row_hi = np.full(rows, -np.inf)
    col_lo = np.full(cols, np.inf)
    col_hi = np.full(cols, -np.inf)
    for w in range(walls.shape[0]):
        x1, y1, x2, y2 = walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
        if abs(y2 - y1) > eps:  # crosses row centre lines (horizontal walls are parallel)
            lo, hi = min(y1, y2), max(y1, y2)
            r0 = max(int(np.ceil((lo - oy) / res - 0.5)), 0)
            r1 = min(int(np.floor((hi - oy) / res - 0.5)), rows - 1)
            for r in range(r0, r1 + 1):
                cy = oy + (r + 0.5) * res
                x = x1 + (cy - y1) * (x2 - x1) / (y2 - y1)
                row_lo[r] = min(row_lo[r], x)
                row_hi[r] = max(row_hi[r], x)
        if abs(x2 - x1) > eps:
            lo, hi = min(x1, x2), max(x1, x2)
            c0 = max(int(np.ceil((lo - ox) / res - 0.5)), 0)
            c1 = min(int(np.floor((hi - ox) / res - 0.5)), cols - 1)
            for c in range(c0, c1 + 1):
                cx = ox + (c + 0.5) * res
                y = y1 + (cx - x1) * (y2 - y1) / (x2 - x1)
                col_lo[c] = min(col_lo[c], y)
                col_hi[c] = max(col_hi[c], y)
    mask = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(rows):
        cy = oy + (r + 0.5) * res
        for c in range(cols):
            cx = ox + (c + 0.5) * res
            mask[r, c] = row_lo[r] < cx < row_hi[r] and col_lo[c] < cy < col_hi[c]
    # Clearance: a cell is free only if its centre is at least reach from every wall.
    reach = clearance + res * np.sqrt(0.5)
    for w in range(walls.shape[0]):
        x1, y1, x2, y2 = walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
        dx = x2 - x1
        dy = y2 - y1
        length_sq = max(dx * dx + dy * dy, eps)
        c0 = max(int(np.floor((min(x1, x2) - reach - ox) / res)), 0)
        c1 = min(int(np.floor((max(x1, x2) + reach - ox) / res)), cols - 1)
        r0 = max(int(np.floor((min(y1, y2) - reach - oy) / res)), 0)
        r1 = min(int(np.floor((max(y1, y2) + reach - oy) / res)), rows - 1)
        for r in range(r0, r1 + 1):
            cy = oy + (r + 0.5) * res
            for c in range(c0, c1 + 1):
                if not mask[r, c]:
                    continue
                cx = ox + (c + 0.5) * res
                t = min(max(((cx - x1) * dx + (cy - y1) * dy) / length_sq, 0.0), 1.0)
                ex = cx - (x1 + t * dx)
                ey = cy - (y1 + t * dy)
                if np.sqrt(ex * ex + ey * ey) < reach:
                    mask[r, c] = False
    return mask


#: Angular bins per object when culling walls for the visibility rays.
ANGLE_BINS = 1024


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _pseudo_angle(dx, dy):  # fmt: skip  # pragma: no cover - compiled
    """A number in [0, 4) increasing with atan2(dy, dx) over [0, 2 pi), without atan2."""
    s = abs(dx) + abs(dy)
    if s == 0.0:
        return 0.0
    if dy >= 0.0:
        return dy / s if dx >= 0.0 else 1.0 - dx / s
    return 2.0 - dy / s if dx < 0.0 else 3.0 + dx / s


@njit(cache=True, nogil=True, error_model="numpy")
def _visibility_rows(cx, cy, obj_xy, walls, mounted, first, last, eps, table):  # pragma: no cover
    """In place: table[k, n] = object n (first <= n < last) visible from centre k.

    Per object, each wall is entered in the angular bins it spans as seen from the
    object (one bin of margin either side against rounding); a ray from a cell centre
    to the object can only cross walls of its own bin. The wall that blocked the
    previous cell is tried first.
    """
    n_walls = walls.shape[0]
    n_bins = ANGLE_BINS
    scale = n_bins / 4.0
    counts = np.zeros(n_bins + 1, dtype=np.int64)
    lo = np.empty(n_walls, dtype=np.int64)
    hi = np.empty(n_walls, dtype=np.int64)
    for n in range(first, last):
        qx = obj_xy[n, 0]
        qy = obj_xy[n, 1]
        counts[:] = 0
        for w in range(n_walls):
            lo[w] = 0
            hi[w] = -1
            if mounted[n, w]:
                continue
            ax = walls[w, 0] - qx
            ay = walls[w, 1] - qy
            bx = walls[w, 2] - qx
            by = walls[w, 3] - qy
            pa = _pseudo_angle(ax, ay)
            pb = _pseudo_angle(bx, by)
            if ax * by - ay * bx < 0.0:  # clockwise from a to b: span runs from b to a
                pa, pb = pb, pa
            b0 = int(np.floor(pa * scale)) - 1
            b1 = int(np.floor(pb * scale)) + 1
            if b1 < b0 + 2:  # the span wraps through angle 0
                b1 += n_bins
            if b1 - b0 >= n_bins:
                b0, b1 = 0, n_bins - 1
            lo[w] = b0
            hi[w] = b1
            for b in range(b0, b1 + 1):
                counts[b % n_bins + 1] += 1
        for b in range(n_bins):
            counts[b + 1] += counts[b]
        members = np.empty(counts[n_bins], dtype=np.int64)
        fill = counts[:n_bins].copy()
        for w in range(n_walls):
            for b in range(lo[w], hi[w] + 1):
                members[fill[b % n_bins]] = w
                fill[b % n_bins] += 1
        hint = -1
        for k in range(cx.shape[0]):
            px = cx[k]
            py = cy[k]
            blocked = False
            if hint >= 0 and crosses_wall(
                px, py, qx, qy, walls[hint, 0], walls[hint, 1], walls[hint, 2], walls[hint, 3], eps
            ):
                blocked = True
            else:
                b = min(int(_pseudo_angle(px - qx, py - qy) * scale), n_bins - 1)
                for m in range(counts[b], counts[b + 1]):
                    w = members[m]
                    if w == hint:
                        continue
                    if crosses_wall(
                        px, py, qx, qy, walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3], eps
                    ):
                        blocked = True
                        hint = w
                        break
            table[k, n] = not blocked


# ----------------------------------------------------------------------- builders
def grid_frame(
    bounds: tuple[float, float, float, float],
    has_walls: bool,
    resolution_m: float | None,
    levels: int = 1,
) -> tuple[float, float, float, int, int]:
    """(origin x, origin y, resolution, rows, cols) of a map's free-space grid.

    The grid covers the map's bounds (plus one metre when there are no walls) with
    about ``FREE_SPACE_CELLS`` cells per level, never finer than ``MIN_RESOLUTION_M``.
    """
    min_x, min_y, max_x, max_y = bounds
    margin = 0.0 if has_walls else 1.0
    min_x, min_y, max_x, max_y = min_x - margin, min_y - margin, max_x + margin, max_y + margin
    area = max((max_x - min_x) * (max_y - min_y), 1e-6)
    cells = FREE_SPACE_CELLS * max(levels, 1)
    res = resolution_m or max(MIN_RESOLUTION_M, float(np.sqrt(area / cells)))
    cols = max(1, int(np.ceil((max_x - min_x) / res)))
    rows = max(1, int(np.ceil((max_y - min_y) / res)))
    return min_x, min_y, res, rows, cols


def build_free_space(semantic_map: SemanticMap, resolution_m: float | None = None) -> FreeSpaceGrid:
    """Cells enclosed by walls in all four axis directions, wholly >= 0.1 m from walls.

    Every point of a free cell is at least ``WALL_CLEARANCE_M`` from every wall (the
    cell centre is tested with the half-diagonal added), which the motion model relies
    on to skip ray tests for short moves. A map without walls is free everywhere
    within its bounds plus one metre.
    """
    walls = np.ascontiguousarray(semantic_map.walls, dtype=np.float64).reshape(-1, 4)
    ox, oy, res, rows, cols = grid_frame(
        semantic_map.bounds, walls.shape[0] > 0, resolution_m, len(semantic_map.layout.levels)
    )
    if walls.shape[0] == 0:
        mask = np.ones((rows, cols), dtype=bool)
    else:
        mask = _free_mask(walls, ox, oy, res, rows, cols, WALL_CLEARANCE_M, GEOMETRY_EPS)
    return FreeSpaceGrid(ox, oy, res, mask, np.flatnonzero(mask.reshape(-1)))


def visibility_factor(rows: int, cols: int, n_objects: int, n_free: int, n_walls: int) -> int:
    """How many free-space cells (per side) one visibility cell spans.

    The smallest factor whose table fits ``MAX_TABLE_BYTES`` and whose estimated
    ray-wall work fits ``MAX_VISIBILITY_WORK`` (a ray meets the walls of one angular
    bin: each wall spans a few of the ``ANGLE_BINS`` as seen from an object).
    """
    n_obj = max(n_objects, 1)
    per_ray = 3.0 * n_walls / ANGLE_BINS + 4.0
    factor = 1
    while (rows // factor + 1) * (cols // factor + 1) * n_obj > MAX_TABLE_BYTES:
        factor += 1
    while n_free / factor**2 * n_obj * per_ray > MAX_VISIBILITY_WORK:
        factor += 1
    return factor


def build_visibility(
    semantic_map: SemanticMap, free_space: FreeSpaceGrid, *, threads: int | None = None
) -> VisibilityGrid:
    """Ray-test each free visibility cell's centre against every object."""
    fs = free_space
    n_obj = semantic_map.object_count
    walls = np.ascontiguousarray(semantic_map.walls, dtype=np.float64).reshape(-1, 4)
    fs_rows, fs_cols = fs.mask.shape
    factor = visibility_factor(fs_rows, fs_cols, n_obj, fs.free_cells.size, walls.shape[0])
    res = fs.resolution_m * factor
    rows = int(np.ceil(fs.mask.shape[0] / factor))
    cols = int(np.ceil(fs.mask.shape[1] / factor))
    table = np.zeros((rows * cols, n_obj), dtype=bool)
    # Only cells that contain free space matter; the rest stay False.
    coarse_free = np.zeros(rows * cols, dtype=bool)
    fr, fc = np.divmod(fs.free_cells, fs.mask.shape[1])
    coarse_free[(fr // factor) * cols + (fc // factor)] = True
    idx = np.flatnonzero(coarse_free)
    r, c = np.divmod(idx, cols)
    cx = fs.origin_x + (c + 0.5) * res
    cy = fs.origin_y + (r + 0.5) * res
    if walls.shape[0] and idx.size and n_obj:
        part = np.zeros((idx.size, n_obj), dtype=np.bool_)
        mounted = np.ascontiguousarray(semantic_map.mounted_walls, dtype=np.bool_)
        obj = np.ascontiguousarray(semantic_map.object_xy, dtype=np.float64)
        workers = max(1, min(threads or (os.cpu_count() or 1), n_obj))
        bounds = np.linspace(0, n_obj, workers + 1).astype(int)
        # The kernel releases the GIL: objects are split over the cores.
        with ThreadPoolExecutor(max_workers=workers) as pool:
            jobs = [
                pool.submit(
                    _visibility_rows,
                    cx,
                    cy,
                    obj,
                    walls,
                    mounted,
                    int(bounds[i]),
                    int(bounds[i + 1]),
                    GEOMETRY_EPS,
                    part,
                )
                for i in range(workers)
            ]
            for job in jobs:
                job.result()
        table[idx] = part
    elif idx.size:
        table[idx] = True
    return VisibilityGrid(fs.origin_x, fs.origin_y, res, (rows, cols), pack_bits(table), n_obj)


# ----------------------------------------------------------------------- cache
def content_key(semantic_map: SemanticMap) -> str:
    """SHA-256 of the map's canonical JSON, the grid resolution and ``PREPARE_VERSION``."""
    canonical = json.dumps(
        semantic_map.to_json(), sort_keys=True, separators=(",", ":"), allow_nan=False
    )
    extra = f"|v{PREPARE_VERSION}|res={semantic_map.grid_resolution_m}"
    return hashlib.sha256((canonical + extra).encode("utf-8")).hexdigest()


def _cache_file(cache_dir: Path, semantic_map: SemanticMap) -> Path:
    return cache_dir / f"{semantic_map.name}-{content_key(semantic_map)[:32]}.npz"


def _save(path: Path, fs: FreeSpaceGrid, vis: VisibilityGrid) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(
                f,
                free_frame=np.array([fs.origin_x, fs.origin_y, fs.resolution_m]),
                free_mask=np.packbits(fs.mask.reshape(-1)),
                free_shape=np.array(fs.mask.shape),
                vis_frame=np.array([vis.origin_x, vis.origin_y, vis.resolution_m]),
                vis_shape=np.array([*vis.shape, vis.n_objects]),
                vis_bits=vis.bits,
            )
        os.replace(tmp, path)  # atomic: a reader never sees half a file
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _load(path: Path) -> tuple[FreeSpaceGrid, VisibilityGrid]:
    with np.load(path, allow_pickle=False) as data:
        ox, oy, res = (float(v) for v in data["free_frame"])
        rows, cols = (int(v) for v in data["free_shape"])
        mask = np.unpackbits(data["free_mask"], count=rows * cols).astype(bool).reshape(rows, cols)
        vx, vy, vres = (float(v) for v in data["vis_frame"])
        vrows, vcols, n_obj = (int(v) for v in data["vis_shape"])
        bits = np.ascontiguousarray(data["vis_bits"], dtype=np.uint64)
    if bits.shape != (vrows * vcols, max((n_obj + 63) // 64, 1)):
        raise ValueError(f"visibility bits of shape {bits.shape} do not match the grid")
    fs = FreeSpaceGrid(ox, oy, res, mask, np.flatnonzero(mask.reshape(-1)))
    return fs, VisibilityGrid(vx, vy, vres, (vrows, vcols), bits, n_obj)


def build(semantic_map: SemanticMap) -> PreparedMap:
    """Build both grids (no cache)."""
    started = time.perf_counter()
    fs = build_free_space(semantic_map, semantic_map.grid_resolution_m)
    vis = build_visibility(semantic_map, fs)
    return PreparedMap(fs, vis, time.perf_counter() - started, from_cache=False)


def prepare(semantic_map: SemanticMap, cache_dir: Path | None = None) -> PreparedMap:
    """Give the map its grids: from the cache when there, else built (and cached).

    With ``cache_dir`` None nothing is read or written. A cache file that cannot be
    read is rebuilt; a cache that cannot be written is logged and skipped.
    """
    started = time.perf_counter()
    prepared: PreparedMap | None = None
    path = _cache_file(cache_dir, semantic_map) if cache_dir is not None else None
    if path is not None and path.is_file():
        try:
            fs, vis = _load(path)
            if vis.n_objects != semantic_map.object_count:
                raise ValueError("object count differs")
            prepared = PreparedMap(fs, vis, time.perf_counter() - started, from_cache=True)
        except (OSError, ValueError, KeyError) as exc:
            log.warning(
                "map %s: cache file %s unreadable (%s); rebuilding", semantic_map.name, path, exc
            )
    if prepared is None:
        prepared = build(semantic_map)
        if path is not None:
            try:
                _save(path, prepared.free_space, prepared.visibility)
            except OSError as exc:
                log.warning("map %s: cannot write cache %s (%s)", semantic_map.name, path, exc)
    semantic_map.attach(prepared.free_space, prepared.visibility)
    return prepared


_build_lock = threading.Lock()


def ensure_prepared(semantic_map: SemanticMap) -> SemanticMap:
    """The map, with its grids built now (once, thread-safe, no cache) if it was never
    prepared.

    The loaders prepare the maps they load (:func:`app.maps.check.load_map`,
    :func:`~app.maps.check.load_map_dirs`); this is for maps made in code (tests, the
    simulator's and the experiments' maps, benchmarks), and for the consumers that need
    the grids to say so where they take a map (the filter, the narrator, the planner).
    """
    if not semantic_map.prepared:
        with _build_lock:
            if not semantic_map.prepared:
                got = build(semantic_map)
                semantic_map.attach(got.free_space, got.visibility)
    return semantic_map
