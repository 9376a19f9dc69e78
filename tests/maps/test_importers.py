"""Importers: an occupancy grid made here, GeoJSON in metres and in WGS84."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from app.cli import main
from app.maps.check import load_map
from app.maps.geometry import point_segment_distance, segments_cross_walls
from app.maps.importers.common import MapImportError
from app.maps.importers.geojson import read_geojson
from app.maps.importers.occupancy import read_occupancy, vectorize

RES = 0.05
ORIGIN = (-0.5, -0.5)
W_M, H_M = 5.0, 4.0  # the image covers x in [-0.5, 4.5], y in [-0.5, 3.5]
COLS, ROWS = round(W_M / RES), round(H_M / RES)


def px(x: float, y: float) -> tuple[int, int]:
    """(row, col) of the pixel holding map point (x, y); rows grow downward."""
    return ROWS - 1 - int((y - ORIGIN[1]) / RES), int((x - ORIGIN[0]) / RES)


def room_image() -> np.ndarray:
    """A 4 m x 3 m room (walls 3 px thick on x = 0, 4 and y = 0, 3) and a wall at x = 2
    from the south wall up to y = 1.8 only, leaving a 1.2 m doorway in the north."""
    occ = np.zeros((ROWS, COLS), dtype=bool)

    def line(x0: float, y0: float, x1: float, y1: float) -> None:
        for t in np.linspace(0, 1, 400):
            r, c = px(x0 + t * (x1 - x0), y0 + t * (y1 - y0))
            occ[r - 1 : r + 2, c - 1 : c + 2] = True

    line(0, 0, 4, 0)
    line(4, 0, 4, 3)
    line(4, 3, 0, 3)
    line(0, 3, 0, 0)
    line(2, 0, 2, 1.8)
    return occ


def write_ros(tmp: Path, occ: np.ndarray, *, negate: int = 0, suffix: str = "pgm") -> Path:
    grey = np.where(occ, 0, 254).astype(np.uint8)
    if negate:
        grey = 255 - grey
    Image.fromarray(grey, mode="L").save(tmp / f"room.{suffix}")
    yaml_path = tmp / "room.yaml"
    yaml_path.write_text(
        f"image: room.{suffix}\nresolution: {RES}\norigin: [{ORIGIN[0]}, {ORIGIN[1]}, 0.0]\n"
        f"negate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return yaml_path


def test_walls_lie_where_the_pixels_are(tmp_path: Path) -> None:
    occ = room_image()
    walls = vectorize(read_occupancy(write_ros(tmp_path, occ)))
    assert 5 <= walls.shape[0] <= 12  # a few segments, not one per pixel
    # Every wall runs over occupied pixels (sampled along it)...
    for x1, y1, x2, y2 in walls:
        for t in np.linspace(0.05, 0.95, 20):
            r, c = px(x1 + t * (x2 - x1), y1 + t * (y2 - y1))
            assert occ[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2].any()
    # ...and every occupied pixel is near a wall (within its half thickness + a pixel).
    rr, cc = np.nonzero(occ)
    centres = np.column_stack([ORIGIN[0] + (cc + 0.5) * RES, ORIGIN[1] + (ROWS - rr - 0.5) * RES])
    assert point_segment_distance(centres, walls).min(axis=1).max() <= 2.5 * RES


def test_origin_resolution_and_y_axis_are_honoured(tmp_path: Path) -> None:
    walls = vectorize(read_occupancy(write_ros(tmp_path, room_image())))
    xs, ys = walls[:, [0, 2]], walls[:, [1, 3]]
    assert xs.min() == pytest.approx(0.0, abs=RES) and xs.max() == pytest.approx(4.0, abs=RES)
    assert ys.min() == pytest.approx(0.0, abs=RES) and ys.max() == pytest.approx(3.0, abs=RES)
    # The inner wall stands in the south half (y up), not the north.
    inner = walls[np.abs(walls[:, [0, 2]] - 2.0).max(axis=1) < RES]
    assert inner.shape[0] == 1
    assert sorted(inner[0, [1, 3]]) == pytest.approx([0.0, 1.8], abs=2 * RES)


def test_doorways_stay_open(tmp_path: Path) -> None:
    walls = vectorize(read_occupancy(write_ros(tmp_path, room_image())))
    through_doorway = segments_cross_walls([[1.5, 2.4]], [[2.5, 2.4]], walls)
    through_wall = segments_cross_walls([[1.5, 1.0]], [[2.5, 1.0]], walls)
    assert not through_doorway[0] and through_wall[0]


def test_negate_and_png_give_the_same_walls(tmp_path: Path) -> None:
    a = vectorize(read_occupancy(write_ros(tmp_path, room_image())))
    other = tmp_path / "neg"
    other.mkdir()
    b = vectorize(read_occupancy(write_ros(other, room_image(), negate=1, suffix="png")))
    assert np.array_equal(a, b)


def test_import_cli_writes_a_valid_map(tmp_path: Path) -> None:
    yaml_path = write_ros(tmp_path, room_image())
    (tmp_path / "objects.csv").write_text(
        "class,x,y,label\ndoor,2.0,2.4,north doorway\nwindow,4.08,1.5,\ntable,1.0,1.0,\n"
        "table,3.0,1.0,\n"
    )
    regions = np.zeros((ROWS, COLS, 3), dtype=np.uint8)
    west_r0, west_c0 = px(0.1, 2.9)
    west_r1, west_c1 = px(1.9, 0.1)
    regions[west_r0:west_r1, west_c0:west_c1] = (200, 30, 30)
    Image.fromarray(regions).save(tmp_path / "rooms.png")
    out = tmp_path / "small_room.json"
    code = main(
        ["map", "import", "--occupancy", str(yaml_path), "--objects", str(tmp_path / "objects.csv"),
         "--regions", str(tmp_path / "rooms.png"), "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    m = load_map(out)
    assert m.name == "small_room" and m.object_count == 4
    window = m.class_members["window"][0]
    assert m.object_xy[window, 0] == pytest.approx(4.0, abs=RES)  # snapped onto the wall
    assert m.mounted_walls[window].any()
    assert m.region_names == ("region #c81e1e",)
    assert m.region_at(1.0, 1.5) == "region #c81e1e" and m.region_at(3.0, 1.5) is None
    assert m.free_space.is_free([1.0], [2.0])[0]


def geojson(features: list[dict]) -> dict:
    return {"type": "FeatureCollection", "features": features}


def feature(geometry: dict, **props: object) -> dict:
    return {"type": "Feature", "properties": props, "geometry": geometry}


FLOOR_M = [
    feature({"type": "Polygon", "coordinates": [[[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]]}),
    feature({"type": "LineString", "coordinates": [[3, 0], [3, 2.5]]}),
    feature({"type": "Point", "coordinates": [6, 2]}, **{"class": "door", "label": "exit"}),
    feature({"type": "Point", "coordinates": [1, 1]}, **{"class": "table"}),
    feature(
        {"type": "Polygon", "coordinates": [[[0, 0], [3, 0], [3, 4], [0, 4], [0, 0]]]},
        name="West",
    ),
]


def test_geojson_in_metres(tmp_path: Path) -> None:
    path = tmp_path / "floor.geojson"
    path.write_text(json.dumps(geojson(FLOOR_M)))
    walls, objects, regions = read_geojson(path)
    assert walls.shape == (5, 4)
    assert [0.0, 0.0, 6.0, 0.0] in walls.tolist() and [3.0, 0.0, 3.0, 2.5] in walls.tolist()
    assert objects == [
        {"class": "door", "x": 6.0, "y": 2.0, "label": "exit"},
        {"class": "table", "x": 1.0, "y": 1.0},
    ]
    assert regions == [{"name": "West", "polygon": [[0, 0], [3, 0], [3, 4], [0, 4]]}]
    out = tmp_path / "floor.json"
    assert main(["map", "import", "--geojson", str(path), "--out", str(out)]) == 0
    m = load_map(out)
    assert m.region_at(1, 1) == "West" and m.object_labels[0] == "exit"


def test_geojson_in_wgs84_is_projected_to_metres(tmp_path: Path) -> None:
    lat0, lon0 = 48.1374, 11.5755
    # Metres to degrees on a sphere of the mean Earth radius (independent of pyproj).
    radius = 6_371_008.8

    def lonlat(x: float, y: float) -> list[float]:
        return [
            lon0 + np.degrees(x / (radius * np.cos(np.radians(lat0)))),
            lat0 + np.degrees(y / radius),
        ]

    def convert(coords: object) -> object:
        if isinstance(coords[0], int | float):  # type: ignore[index]
            return lonlat(*coords)  # type: ignore[misc]
        return [convert(c) for c in coords]  # type: ignore[union-attr]

    features = [
        {**f, "geometry": {**f["geometry"], "coordinates": convert(f["geometry"]["coordinates"])}}
        for f in FLOOR_M
    ]
    path = tmp_path / "wgs.geojson"
    path.write_text(json.dumps(geojson(features)))
    walls, objects, regions = read_geojson(path, origin=(lat0, lon0))
    metres = tmp_path / "metres.geojson"
    metres.write_text(json.dumps(geojson(FLOOR_M)))
    metric, _, _ = read_geojson(metres)
    # The sphere differs from the ellipsoid by well under 1 % over a few metres.
    assert np.allclose(np.sort(walls, axis=0), np.sort(metric, axis=0), atol=0.03)
    assert objects[0]["x"] == pytest.approx(6.0, abs=0.03)
    assert objects[0]["y"] == pytest.approx(2.0, abs=0.03)
    assert np.allclose(regions[0]["polygon"], [[0, 0], [3, 0], [3, 4], [0, 4]], atol=0.03)
    out = tmp_path / "wgs_floor.json"
    args = [
        "map",
        "import",
        "--geojson",
        str(path),
        "--origin",
        f"{lat0},{lon0}",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert load_map(out).region_at(1, 1) == "West"


def test_geojson_refusals_name_the_feature(tmp_path: Path) -> None:
    bowtie = feature({"type": "Polygon", "coordinates": [[[0, 0], [4, 4], [4, 0], [0, 4], [0, 0]]]})
    path = tmp_path / "bad.geojson"
    path.write_text(json.dumps(geojson([FLOOR_M[0], bowtie])))
    with pytest.raises(
        MapImportError, match=r"features\[1\]: polygon is not simple \(Self-intersection"
    ):
        read_geojson(path)
    path.write_text(json.dumps(geojson([feature({"type": "Point", "coordinates": [1, 1]})])))
    with pytest.raises(MapImportError, match=r"features\[0\]: a Point needs a 'class'"):
        read_geojson(path)
    far = feature({"type": "Point", "coordinates": [500, 2]}, **{"class": "door"})
    path.write_text(json.dumps(geojson([far])))  # metres, read as if they were degrees
    with pytest.raises(MapImportError, match=r"features\[0\]: coordinates: not longitude"):
        read_geojson(path, origin=(48.0, 11.0))


def test_occupancy_refusals_name_the_field(tmp_path: Path) -> None:
    (tmp_path / "m.yaml").write_text("image: m.pgm\norigin: [0, 0, 0]\n")
    with pytest.raises(MapImportError, match="resolution: missing"):
        read_occupancy(tmp_path / "m.yaml")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n")
    with pytest.raises(MapImportError, match=r"origin: expected \[x, y, yaw\]"):
        read_occupancy(tmp_path / "m.yaml")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapImportError, match="does not exist"):
        read_occupancy(tmp_path / "m.yaml")
