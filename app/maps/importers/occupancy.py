"""Import a ROS map_server occupancy grid (YAML + PGM/PNG) as wall segments.

The YAML's fields are honoured as map_server reads them: ``image`` (relative to the
YAML file), ``resolution`` (metres per pixel), ``origin`` (x, y, yaw of the lower-left
pixel), ``negate``, ``occupied_thresh``, ``free_thresh`` and ``mode`` (trinary and
scale: a pixel's occupancy is ``(255 - v) / 255``, or ``v / 255`` when negated; raw:
``v / 100``). Image rows grow downward, map y grows upward: row 0 is the top of the map.

Vectorization (scikit-image, chosen over hand-written image code): the occupied pixels,
cleared of specks, are thinned to a one-pixel skeleton (``skeletonize``), so a wall of
any thickness becomes its centre line, as in hand-drawn maps; the skeleton is traced
into chains between junctions and ends, each chain simplified by Douglas-Peucker
(``approximate_polygon``), collinear segments meeting end to end are merged, and each
free end is extended by half the wall's thickness (the skeleton stops short of it).
Doorways are gaps between occupied pixels, so they stay open.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import yaml
from numpy.typing import NDArray

from app.maps.importers.common import MapImportError

N = TypeVar("N", int, float, str)

#: Occupied specks smaller than this many pixels are sensor noise, not walls.
MIN_BLOB_PX = 4
#: Douglas-Peucker tolerance, pixels.
SIMPLIFY_PX = 1.0
#: Segments meeting end to end within this angle (degrees) are merged.
COLLINEAR_DEG = 4.0
#: Largest image accepted, pixels.
MAX_PIXELS = 40_000_000


@dataclass(frozen=True)
class OccupancyMap:
    """A ROS map_server map: the occupied mask (image orientation) and its frame."""

    occupied: NDArray[np.bool_]  # (rows, cols), row 0 is the top of the image
    resolution: float
    origin: tuple[float, float, float]  # x, y (metres), yaw (radians)
    image_path: Path

    def to_map(self, rows: NDArray[np.float64], cols: NDArray[np.float64]) -> NDArray[np.float64]:
        """Map metres (x, y) of pixel-centre coordinates (row, col), shape (M, 2)."""
        h = self.occupied.shape[0]
        x = (np.asarray(cols) + 0.5) * self.resolution
        y = (h - np.asarray(rows) - 0.5) * self.resolution
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return np.column_stack([ox + c * x - s * y, oy + s * x + c * y])


def _field(meta: dict, key: str, source: Path, kind: type[N], default: N | None = None) -> N:
    if key not in meta:
        if default is None:
            raise MapImportError(f"{source}: {key}: missing (map_server requires it)")
        return default
    value = meta[key]
    try:
        if kind is float:
            out = float(value)
            if not math.isfinite(out):
                raise ValueError
            return kind(out)
        return kind(value)
    except (TypeError, ValueError):
        raise MapImportError(f"{source}: {key}: {value!r} is not a {kind.__name__}") from None


def read_occupancy(yaml_path: str | Path) -> OccupancyMap:
    """Read a map_server YAML and its image into an :class:`OccupancyMap`."""
    from PIL import Image, UnidentifiedImageError

    src = Path(yaml_path)
    try:
        meta = yaml.safe_load(src.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MapImportError(f"{src}: cannot read it ({exc})") from None
    except yaml.YAMLError as exc:
        raise MapImportError(f"{src}: not valid YAML ({exc})") from None
    if not isinstance(meta, dict):
        raise MapImportError(f"{src}: expected a YAML mapping with image, resolution, origin")
    image = Path(str(_field(meta, "image", src, str)))
    image = image if image.is_absolute() else src.parent / image
    res = float(_field(meta, "resolution", src, float))
    if not 0.001 <= res <= 10.0:
        raise MapImportError(f"{src}: resolution: {res} m per pixel is out of 0.001-10")
    origin = meta.get("origin")
    if (
        not isinstance(origin, list | tuple)
        or len(origin) != 3
        or not all(isinstance(v, int | float) and math.isfinite(v) for v in origin)
    ):
        raise MapImportError(f"{src}: origin: expected [x, y, yaw] numbers, got {origin!r}")
    negate = int(_field(meta, "negate", src, int, 0))
    occ_t = float(_field(meta, "occupied_thresh", src, float, 0.65))
    free_t = float(_field(meta, "free_thresh", src, float, 0.196))
    if not 0.0 <= free_t <= occ_t <= 1.0:
        raise MapImportError(
            f"{src}: free_thresh {free_t} and occupied_thresh {occ_t} must satisfy "
            "0 <= free_thresh <= occupied_thresh <= 1"
        )
    mode = str(meta.get("mode", "trinary"))
    if mode not in ("trinary", "scale", "raw"):
        raise MapImportError(f"{src}: mode: {mode!r} is not trinary, scale or raw")
    try:
        with Image.open(image) as img:
            if img.width * img.height > MAX_PIXELS:
                raise MapImportError(
                    f"{image}: {img.width} x {img.height} pixels; at most {MAX_PIXELS:,} accepted"
                )
            pixels = np.asarray(img.convert("RGBA" if img.mode in ("RGBA", "LA", "P") else "RGB"))
    except FileNotFoundError:
        raise MapImportError(f"{src}: image: {image} does not exist") from None
    except (UnidentifiedImageError, OSError) as exc:
        raise MapImportError(f"{src}: image: {image} is not a readable image ({exc})") from None
    value = pixels[..., :3].astype(np.float64).mean(axis=2)  # map_server averages channels
    if mode == "raw":
        p = value / 100.0
        occupied = (value <= 100) & (p > occ_t)
    else:
        p = value / 255.0 if negate else (255.0 - value) / 255.0
        occupied = p > occ_t
    if pixels.shape[2] == 4:
        occupied &= pixels[..., 3] > 0  # transparent pixels are unknown
    return OccupancyMap(
        occupied, res, (float(origin[0]), float(origin[1]), float(origin[2])), image
    )


# ------------------------------------------------------------------ vectorizing
_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def _trace_chains(skeleton: NDArray[np.bool_]) -> list[list[tuple[int, int]]]:
    """Chains of skeleton pixels between ends and junctions (and closed loops)."""
    pixels = set(zip(*np.nonzero(skeleton), strict=True))
    pixels = {(int(r), int(c)) for r, c in pixels}

    def neighbours(p: tuple[int, int]) -> list[tuple[int, int]]:
        return [
            (p[0] + dr, p[1] + dc) for dr, dc in _NEIGHBOURS if (p[0] + dr, p[1] + dc) in pixels
        ]

    degree = {p: len(neighbours(p)) for p in pixels}
    nodes = {p for p, d in degree.items() if d != 2}
    used: set[tuple[tuple[int, int], tuple[int, int]]] = set()
    chains = []
    for start in sorted(nodes):
        for nxt in neighbours(start):
            if (start, nxt) in used:
                continue
            chain = [start, nxt]
            used.add((start, nxt))
            used.add((nxt, start))
            prev, cur = start, nxt
            while cur not in nodes:
                step = [q for q in neighbours(cur) if q != prev and (cur, q) not in used]
                if not step:
                    break
                prev, cur = cur, step[0]
                used.add((prev, cur))
                used.add((cur, prev))
                chain.append(cur)
            chains.append(chain)
    seen = {p for chain in chains for p in chain}
    for p in sorted(pixels - seen):  # closed loops without any junction
        if p in seen:
            continue
        chain = [p]
        seen.add(p)
        cur = p
        while True:
            step = [q for q in neighbours(cur) if q not in seen]
            if not step:
                break
            cur = step[0]
            seen.add(cur)
            chain.append(cur)
        chain.append(p)
        chains.append(chain)
    return chains


def _merge_collinear(segments: list[list[float]], tol_deg: float) -> list[list[float]]:
    """Merge segments that meet end to end and point the same way, until none do."""
    segs = [list(s) for s in segments]
    cos_tol = math.cos(math.radians(tol_deg))
    changed = True
    while changed:
        changed = False
        ends: dict[tuple[float, float], list[int]] = {}
        for i, (x1, y1, x2, y2) in enumerate(segs):
            ends.setdefault((round(x1, 6), round(y1, 6)), []).append(i)
            ends.setdefault((round(x2, 6), round(y2, 6)), []).append(i)
        gone: set[int] = set()
        for key, members in ends.items():
            live = [i for i in members if i not in gone]
            for a_i in range(len(live)):
                for b_i in range(a_i + 1, len(live)):
                    i, j = live[a_i], live[b_i]
                    if i in gone or j in gone:
                        continue
                    far_i = _other_end(segs[i], key)
                    far_j = _other_end(segs[j], key)
                    u = (far_i[0] - key[0], far_i[1] - key[1])
                    v = (far_j[0] - key[0], far_j[1] - key[1])
                    nu, nv = math.hypot(*u), math.hypot(*v)
                    if nu == 0 or nv == 0:
                        continue
                    if (u[0] * v[0] + u[1] * v[1]) / (nu * nv) <= -cos_tol:
                        segs[i] = [far_i[0], far_i[1], far_j[0], far_j[1]]
                        gone.add(j)
                        changed = True
        segs = [s for k, s in enumerate(segs) if k not in gone]
    return segs


def _other_end(seg: list[float], key: tuple[float, float]) -> tuple[float, float]:
    if (round(seg[0], 6), round(seg[1], 6)) == key:
        return seg[2], seg[3]
    return seg[0], seg[1]


def vectorize(occ: OccupancyMap, *, min_blob_px: int = MIN_BLOB_PX) -> NDArray[np.float64]:
    """Wall segments (x1, y1, x2, y2) in map metres from the occupied pixels, shape (W, 4)."""
    from scipy import ndimage
    from skimage.measure import approximate_polygon
    from skimage.morphology import remove_small_objects, skeletonize

    mask = occ.occupied
    if min_blob_px > 1 and mask.any():
        mask = remove_small_objects(mask, max_size=min_blob_px - 1, connectivity=2)
    if not mask.any():
        return np.zeros((0, 4))
    skeleton = skeletonize(mask)
    half_width = ndimage.distance_transform_edt(mask)  # pixels to the nearest free pixel
    chains = _trace_chains(skeleton)
    segments: list[list[float]] = []
    for chain in chains:
        pts = np.array(chain, dtype=np.float64)
        if len(chain) == 1:
            continue
        simple = approximate_polygon(pts, tolerance=SIMPLIFY_PX)
        for a, b in itertools.pairwise(simple):
            if np.any(a != b):
                segments.append([a[0], a[1], b[0], b[1]])
    segments = _merge_collinear(segments, COLLINEAR_DEG)
    # Free ends stop half a wall short of the wall's end: extend them.
    counts: dict[tuple[float, float], int] = {}
    for r1, c1, r2, c2 in segments:
        for key in ((r1, c1), (r2, c2)):
            counts[key] = counts.get(key, 0) + 1
    out = []
    for r1, c1, r2, c2 in segments:
        p, q = np.array([r1, c1]), np.array([r2, c2])
        d = q - p
        length = float(np.hypot(*d))
        if length == 0:
            continue
        u = d / length
        if counts[(r1, c1)] == 1:
            p = p - u * max(float(half_width[int(r1), int(c1)]) - 0.5, 0.0)
        if counts[(r2, c2)] == 1:
            q = q + u * max(float(half_width[int(r2), int(c2)]) - 0.5, 0.0)
        out.append([p[0], p[1], q[0], q[1]])
    rc = np.array(out, dtype=np.float64).reshape(-1, 4)
    a = occ.to_map(rc[:, 0], rc[:, 1])
    b = occ.to_map(rc[:, 2], rc[:, 3])
    return np.column_stack([a, b])


def region_polygons(
    labels: NDArray[np.int64], occ: OccupancyMap, simplify_px: float = 1.5
) -> list[tuple[int, NDArray[np.float64]]]:
    """One polygon (map metres) per non-zero label of a room segmentation image.

    The outline of each label's largest connected part, simplified.
    """
    from skimage.measure import approximate_polygon, find_contours, label

    out = []
    for value in np.unique(labels):
        if value == 0:
            continue
        parts = label(labels == value, connectivity=1)
        if parts.max() == 0:
            continue
        sizes = np.bincount(parts.ravel())[1:]
        biggest = np.pad(parts == (int(np.argmax(sizes)) + 1), 1)
        contours = find_contours(biggest.astype(np.float64), 0.5)
        ring = max(contours, key=len)
        ring = approximate_polygon(ring, tolerance=simplify_px)[:-1] - 1.0  # undo the pad
        if len(ring) >= 3:
            out.append((int(value), occ.to_map(ring[:, 0], ring[:, 1])))
    return out


def read_region_image(path: str | Path, occ: OccupancyMap) -> NDArray[np.int64]:
    """A room segmentation image as integer labels, same size as the map.

    Each colour (or grey level) other than black and white is one room, named by its
    colour (`region #c81e1e`).
    """
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    try:
        with Image.open(p) as img:
            arr = np.asarray(img.convert("RGB")).astype(np.int64)
    except (FileNotFoundError, UnidentifiedImageError, OSError) as exc:
        raise MapImportError(f"{p}: not a readable image ({exc})") from None
    if arr.shape[:2] != occ.occupied.shape:
        raise MapImportError(
            f"{p}: {arr.shape[1]} x {arr.shape[0]} pixels; the occupancy image is "
            f"{occ.occupied.shape[1]} x {occ.occupied.shape[0]}"
        )
    packed = (arr[..., 0] << 16) | (arr[..., 1] << 8) | arr[..., 2]
    packed[packed == 0xFFFFFF] = 0  # black and white: no room
    return packed
