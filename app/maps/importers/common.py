"""What every importer shares: the objects CSV, snapping objects onto walls, the map dict."""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import numpy as np

from app.maps.geometry import point_segment_distance


class MapImportError(ValueError):
    """An input file that cannot be imported; the message names the file and the place."""


def wgs84_projector(
    origin: tuple[float, float] | None,
) -> Callable[[object], np.ndarray]:
    """A function from points (..., 2) to map metres (M, 2).

    Without an origin the points are taken as metres already. With ``origin=(lat, lon)``
    they are WGS84 longitude, latitude in degrees, projected with pyproj onto an
    azimuthal equidistant plane centred at the origin (x east, y north, metres;
    distances from the origin are exact, and within a building the distortion is far
    below a millimetre). A point that is not a longitude, latitude raises ValueError.
    """
    if origin is None:
        return lambda xy: np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    from pyproj import Transformer

    lat, lon = origin
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise MapImportError(f"origin: {lat}, {lon} is not a latitude, longitude in degrees")
    to_local = Transformer.from_crs(
        "EPSG:4326",
        f"+proj=aeqd +lat_0={lat} +lon_0={lon} +x_0=0 +y_0=0 +ellps=WGS84 +units=m",
        always_xy=True,
    )

    def project(xy: object) -> np.ndarray:
        arr = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if np.any(np.abs(arr[:, 1]) > 90.0) or np.any(np.abs(arr[:, 0]) > 180.0):
            raise ValueError("not longitude, latitude in degrees")
        x, y = to_local.transform(arr[:, 0], arr[:, 1])
        return np.column_stack([x, y])

    return project


def read_objects_csv(path: str | Path) -> list[dict[str, object]]:
    """Objects from ``class,x,y[,label]`` rows in map metres (a header row is optional)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise MapImportError(f"{p}: cannot read it ({exc})") from None
    objects: list[dict[str, object]] = []
    for line_no, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        if line_no == 1 and row[0].strip().lower() == "class":
            continue  # header
        if len(row) < 3:
            raise MapImportError(f"{p}: line {line_no}: expected class,x,y[,label], got {row!r}")
        try:
            x, y = float(row[1]), float(row[2])
        except ValueError:
            raise MapImportError(
                f"{p}: line {line_no}: x and y must be numbers (metres), got {row[1]!r}, {row[2]!r}"
            ) from None
        obj: dict[str, object] = {"class": row[0].strip(), "x": x, "y": y}
        label = ",".join(row[3:]).strip()
        if label:
            obj["label"] = label
        objects.append(obj)
    if not objects:
        raise MapImportError(f"{p}: no objects (expected rows class,x,y[,label])")
    return objects


def snap_objects(
    objects: list[dict[str, object]], walls: np.ndarray, within_m: float, onto_m: float = 0.01
) -> int:
    """Move objects lying within ``within_m`` of a wall onto it (in place); return how many.

    An object drawn on a thick wall's centre line, or a few pixels off its face, would
    otherwise sit behind the face it belongs to and be hidden by it. Snapped objects
    end ``onto_m`` from the face, so they count as mounted in it.
    """
    if not objects or walls.shape[0] == 0:
        return 0
    xy = np.array([[o["x"], o["y"]] for o in objects], dtype=np.float64)
    dist = point_segment_distance(xy, walls)
    nearest = dist.argmin(axis=1)
    moved = 0
    for i, w_i in enumerate(nearest):
        d = dist[i, w_i]
        if d <= onto_m or d > within_m:
            continue
        w = walls[w_i]
        seg = w[2:4] - w[0:2]
        t = float(np.clip(np.dot(xy[i] - w[0:2], seg) / max(float(seg @ seg), 1e-12), 0.0, 1.0))
        p = w[0:2] + t * seg
        objects[i]["x"], objects[i]["y"] = round(float(p[0]), 4), round(float(p[1]), 4)
        moved += 1
    return moved


def map_dict(
    name: str,
    walls: np.ndarray,
    objects: list[dict[str, object]],
    regions: list[dict[str, object]],
    description: str,
) -> dict[str, object]:
    """A map file's JSON (coordinates rounded to 0.1 mm)."""
    return {
        "name": name,
        "description": description,
        "walls": [
            {
                "x1": round(float(a), 4),
                "y1": round(float(b), 4),
                "x2": round(float(c), 4),
                "y2": round(float(d), 4),
            }
            for a, b, c, d in walls
        ],
        "objects": objects,
        "regions": regions,
    }
