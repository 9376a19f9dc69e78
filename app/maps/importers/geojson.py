"""Import a GeoJSON floor (a CAD or GIS export) as walls, objects and regions.

A FeatureCollection whose features are read by geometry and properties:

* LineString / MultiLineString: walls, one segment per consecutive pair of points.
* Polygon / MultiPolygon with a ``name`` property: a region (its exterior ring); without
  one: walls along every ring.
* Point with a ``class`` property: an object (``label`` optional).

Coordinates are metres in the map frame, or, with ``origin=(lat, lon)``, WGS84
longitude/latitude, projected with pyproj onto an azimuthal equidistant plane centred
at the origin (x east, y north, metres; distances from the origin are exact, and
within a building the distortion is far below a millimetre). Polygons are checked with
shapely: one whose ring crosses itself is refused with the reason and the feature.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from app.maps.importers.common import MapImportError, wgs84_projector

#: Largest GeoJSON file read, bytes.
MAX_GEOJSON_BYTES = 20_000_000


def read_geojson(
    path: str | Path, origin: tuple[float, float] | None = None
) -> tuple[np.ndarray, list[dict[str, object]], list[dict[str, object]]]:
    """Walls (W, 4), objects and regions of a GeoJSON floor, in map metres."""
    import shapely

    src = Path(path)
    try:
        if src.stat().st_size > MAX_GEOJSON_BYTES:
            raise MapImportError(f"{src}: larger than {MAX_GEOJSON_BYTES:,} bytes")
        data = json.loads(src.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MapImportError(f"{src}: cannot read it ({exc})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MapImportError(f"{src}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("type") != "FeatureCollection":
        raise MapImportError(f"{src}: expected a GeoJSON FeatureCollection")
    features = data.get("features")
    if not isinstance(features, list):
        raise MapImportError(f"{src}: features: expected a list")
    project = wgs84_projector(origin)
    walls: list[np.ndarray] = []
    objects: list[dict[str, object]] = []
    regions: list[dict[str, object]] = []
    for i, feat in enumerate(features):
        where = f"{src}: features[{i}]"
        if not isinstance(feat, dict) or not isinstance(feat.get("geometry"), dict):
            raise MapImportError(f"{where}: expected a Feature with a geometry")
        props = feat.get("properties") or {}
        if not isinstance(props, dict):
            raise MapImportError(f"{where}: properties: expected an object")
        try:
            geom = shapely.geometry.shape(feat["geometry"])
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            raise MapImportError(f"{where}: geometry: not valid GeoJSON ({exc})") from None
        kind = geom.geom_type
        try:
            if kind == "Point":
                if "class" not in props:
                    raise MapImportError(f"{where}: a Point needs a 'class' property (an object)")
                (x, y) = project([[geom.x, geom.y]])[0]
                obj: dict[str, object] = {
                    "class": str(props["class"]),
                    "x": float(x),
                    "y": float(y),
                }
                if props.get("label"):
                    obj["label"] = str(props["label"])
                objects.append(obj)
            elif kind in ("LineString", "MultiLineString"):
                for line in getattr(geom, "geoms", [geom]):
                    walls.append(_segments(project(line.coords)))
            elif kind in ("Polygon", "MultiPolygon"):
                for poly in getattr(geom, "geoms", [geom]):
                    if not poly.is_valid:
                        raise MapImportError(
                            f"{where}: polygon is not simple ({shapely.is_valid_reason(poly)})"
                        )
                    if "name" in props:
                        ring = project(poly.exterior.coords)[:-1]
                        regions.append(
                            {
                                "name": str(props["name"]),
                                "polygon": [[float(a), float(b)] for a, b in ring],
                            }
                        )
                    else:
                        for ring in (poly.exterior, *poly.interiors):
                            walls.append(_segments(project(ring.coords)))
            else:
                raise MapImportError(
                    f"{where}: {kind} is not used (LineString, Polygon or Point expected)"
                )
        except ValueError as exc:
            if isinstance(exc, MapImportError):
                raise
            raise MapImportError(f"{where}: coordinates: {exc}") from None
    all_walls = np.vstack(walls) if walls else np.zeros((0, 4))
    coords = np.concatenate(
        [all_walls.reshape(-1), np.array([[o["x"], o["y"]] for o in objects]).reshape(-1)]
    )
    if coords.size and not np.all(np.isfinite(coords)):
        raise MapImportError(f"{src}: coordinates are not all finite numbers")
    return all_walls, objects, regions


def _segments(points: np.ndarray) -> np.ndarray:
    """Consecutive pairs of a polyline as wall rows, zero-length ones dropped."""
    seg = np.column_stack([points[:-1], points[1:]])
    keep = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 1e-9
    return seg[keep]


def parse_origin(text: str) -> tuple[float, float]:
    """``"LAT,LON"`` in degrees."""
    try:
        lat_s, lon_s = text.split(",")
        lat, lon = float(lat_s), float(lon_s)
    except ValueError:
        raise MapImportError(f"--origin: {text!r} is not LAT,LON in degrees") from None
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise MapImportError(f"--origin: {text!r} is not LAT,LON in degrees")
    return lat, lon
