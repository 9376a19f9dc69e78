"""Write a large synthetic IMDF venue, the size of a real station, to time the importer.

Each level is three bands of two rows of rooms facing a corridor, joined by a spine
corridor on the west side: 180 rooms, 3 corridors and the spine a level. Each room opens
onto its corridor, holds five pieces of furniture (fixtures drawn as octagons) and its
outline has a vertex every metre, as surveyed outlines do. On every level the same
places hold a lift, stairs and an escalator (the escalators joined to the level above
by directed relationships), corridors hold kiosks, and amenities stand along them.

    python tools/make_imdf_venue.py --levels 4 --out /tmp/big_venue.zip

With 4 levels: 736 units, 3,840 fixtures, 744 openings, 240 amenities, about 4 MB.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import uuid
import zipfile
from pathlib import Path

import numpy as np

LAT0, LON0 = 51.5308, -0.1238  # a station-sized place
M_PER_DEG = 111_195.0
ROOM_W_M, ROOM_D_M, CORRIDOR_M, SPINE_M = 8.0, 10.0, 5.0, 6.0
ROOMS_PER_ROW, BANDS = 30, 3


def _ll(x: float, y: float) -> list[float]:
    lon = LON0 + x / (M_PER_DEG * math.cos(math.radians(LAT0)))
    return [round(lon, 9), round(LAT0 + y / M_PER_DEG, 9)]


def _uid(key: str) -> str:
    return str(uuid.uuid5(uuid.NAMESPACE_URL, "synthetic-venue/" + key))


def _ring(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    """A rectangle with a vertex every metre along its edges, closed."""
    pts: list[tuple[float, float]] = []
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
    for (ax, ay), (bx, by) in itertools.pairwise(corners):
        n = max(int(math.hypot(bx - ax, by - ay)), 1)
        pts += [(ax + (bx - ax) * k / n, ay + (by - ay) * k / n) for k in range(n)]
    pts.append(pts[0])
    return [_ll(x, y) for x, y in pts]


def _feature(kind: str, key: str, geometry: object, props: dict[str, object]) -> dict[str, object]:
    return {
        "id": _uid(key),
        "type": "Feature",
        "feature_type": kind,
        "geometry": geometry,
        "properties": props,
    }


def venue(levels: int, rng: np.random.Generator) -> dict[str, list[dict[str, object]]]:
    """The venue's features by file name (without .geojson)."""
    out: dict[str, list[dict[str, object]]] = {
        k: [] for k in ("venue", "level", "unit", "opening", "fixture", "amenity", "relationship")
    }
    band_h = 2 * ROOM_D_M + CORRIDOR_M
    width = SPINE_M + ROOMS_PER_ROW * ROOM_W_M
    height = BANDS * band_h
    poly = {"type": "Polygon", "coordinates": [_ring(0, 0, width, height)]}
    out["venue"].append(
        _feature(
            "venue",
            "venue",
            poly,
            {
                "category": "transitstation",
                "name": {"en": "Synthetic Station"},
                "display_point": {"type": "Point", "coordinates": _ll(width / 2, height / 2)},
            },
        )
    )
    for lv in range(levels):
        lid = _uid(f"level{lv}")
        out["level"].append(
            _feature(
                "level",
                f"level{lv}",
                poly,
                {
                    "category": "unspecified",
                    "ordinal": lv,
                    "outdoor": False,
                    "name": {"en": f"Level {lv}"},
                    "short_name": {"en": str(lv)},
                },
            )
        )

        def unit(
            key: str,
            cat: str,
            rect: tuple[float, float, float, float],
            name: str | None,
            lv: int = lv,
            lid: str = lid,
        ) -> None:
            geom = {"type": "Polygon", "coordinates": [_ring(*rect)]}
            out["unit"].append(
                _feature(
                    "unit",
                    f"{lv}/{key}",
                    geom,
                    {"category": cat, "level_id": lid, "name": {"en": name} if name else None},
                )
            )

        unit("spine", "walkway", (0, 0, SPINE_M, height), "Spine")
        for b in range(BANDS):
            y0 = b * band_h
            cy0, cy1 = y0 + ROOM_D_M, y0 + ROOM_D_M + CORRIDOR_M
            unit(f"corr{b}", "walkway", (SPINE_M, cy0, width, cy1), f"Corridor {b + 1}")
            for k in range(0, ROOMS_PER_ROW * 2, 2):
                x = SPINE_M + (k // 2) * ROOM_W_M + rng.uniform(1, ROOM_W_M - 3)
                out["fixture"].append(
                    _octagon(
                        f"{lv}/kiosk{b}/{k}",
                        lid,
                        x,
                        cy0 + 2.5,
                        0.6,
                        "kiosk" if k % 6 == 0 else "furniture",
                    )
                )
                if k % 6 == 2:
                    out["amenity"].append(
                        _feature(
                            "amenity",
                            f"{lv}/am{b}/{k}",
                            {"type": "Point", "coordinates": _ll(x, cy1 - 0.3)},
                            {
                                "category": ["atm", "information", "vendingmachine"][(k // 6) % 3],
                                "unit_ids": [_uid(f"{lv}/corr{b}")],
                                "name": None,
                            },
                        )
                    )
            for side, (ry0, ry1, door_y) in enumerate(((y0, cy0, cy0), (cy1, cy1 + ROOM_D_M, cy1))):
                for r in range(ROOMS_PER_ROW):
                    x0 = SPINE_M + r * ROOM_W_M
                    key = f"room{b}/{side}/{r}"
                    cat, name = "room", f"Room {lv}.{b}{side}{r:02d}"
                    if side == 0 and r in (0, 15, 29):
                        cat, name = {
                            0: ("elevator", "Lift"),
                            15: ("stairs", None),
                            29: ("escalator", None),
                        }[r]
                    unit(key, cat, (x0, ry0, x0 + ROOM_W_M, ry1), name)
                    door = {
                        "type": "LineString",
                        "coordinates": [_ll(x0 + 3, door_y), _ll(x0 + 4.2, door_y)],
                    }
                    out["opening"].append(
                        _feature(
                            "opening",
                            f"{lv}/door/{key}",
                            door,
                            {"category": "pedestrian", "level_id": lid, "name": None},
                        )
                    )
                    if cat == "room":
                        for f in range(5):
                            out["fixture"].append(
                                _octagon(
                                    f"{lv}/{key}/f{f}",
                                    lid,
                                    x0 + rng.uniform(1.5, ROOM_W_M - 1.5),
                                    ry0 + rng.uniform(1.5, ROOM_D_M - 1.5),
                                    0.4,
                                    "furniture",
                                )
                            )
                    if cat == "escalator" and lv + 1 < levels:
                        out["relationship"].append(
                            _feature(
                                "relationship",
                                f"{lv}/esc{b}",
                                None,
                                {
                                    "category": "escalator",
                                    "direction": "directed",
                                    "origin": {"id": _uid(f"{lv}/{key}"), "feature_type": "unit"},
                                    "destination": {
                                        "id": _uid(f"{lv + 1}/{key}"),
                                        "feature_type": "unit",
                                    },
                                    "intermediary": None,
                                },
                            )
                        )
    return out


def _octagon(key: str, lid: str, x: float, y: float, r: float, cat: str) -> dict[str, object]:
    ring = [_ll(x + r * math.cos(a), y + r * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 9)]
    ring[-1] = ring[0]
    return _feature(
        "fixture",
        key,
        {"type": "Polygon", "coordinates": [ring]},
        {"category": cat, "level_id": lid, "name": None},
    )


def write(features: dict[str, list[dict[str, object]]], out: Path) -> None:
    """As a folder, or as a .zip when ``out`` ends in .zip."""
    files = {
        f"{k}.geojson": json.dumps({"type": "FeatureCollection", "features": v})
        for k, v in features.items()
    }
    files["manifest.json"] = json.dumps({"version": "1.0.0", "language": "en"})
    if out.suffix == ".zip":
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
            for name, text in files.items():
                zf.writestr(name, text)
        return
    out.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (out / name).write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True, help="a folder, or a .zip file")
    args = parser.parse_args()
    feats = venue(args.levels, np.random.default_rng(args.seed))
    write(feats, args.out)
    counts = ", ".join(f"{len(v)} {k}" for k, v in feats.items())
    print(f"wrote {args.out}: {counts}")


if __name__ == "__main__":
    main()
