"""The map file schema, its refusals, and the derived arrays the filter uses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.maps.check import load_map, load_map_dir
from app.maps.model import MapError, parse_map
from app.maps.prepare import ensure_prepared
from app.resources import bundled_maps_dir
from tests.helpers import paper_office

ROOM = {
    "name": "room",
    "walls": [
        {"x1": 0, "y1": 0, "x2": 4, "y2": 0},
        {"x1": 4, "y1": 0, "x2": 4, "y2": 3},
        {"x1": 4, "y1": 3, "x2": 0, "y2": 3},
        {"x1": 0, "y1": 3, "x2": 0, "y2": 0},
        # an inner wall from the south wall up to y = 2 at x = 2
        {"x1": 2, "y1": 0, "x2": 2, "y2": 2},
    ],
    "objects": [
        {"class": "door", "x": 4, "y": 1.5, "label": "exit"},
        {"class": "table", "x": 1, "y": 1},
        {"class": "table", "x": 3, "y": 1},
    ],
    "regions": [{"name": "West", "polygon": [[0, 0], [2, 0], [2, 3], [0, 3]]}],
}


def test_bundled_paper_office_matches_the_protocol() -> None:
    m = paper_office()
    assert m.bounds == (0.0, 0.0, 10.0, 7.0)
    assert m.classes == ("door", "table", "window")
    assert len(m.class_members["window"]) == 6
    assert len(m.class_members["table"]) == 4
    assert m.object_labels[m.class_members["door"][0]] == "main entrance"
    assert m.region_at(5, 3.5) == "Office"


def test_every_bundled_map_loads() -> None:
    maps = load_map_dir(bundled_maps_dir())
    assert "paper_office" in maps
    for name, m in maps.items():
        assert m.name == name
        assert m.free_space.free_cells.size > 0


@pytest.mark.parametrize(
    ("patch", "field", "reason"),
    [
        ({"objects": [{"class": "Door", "x": 0, "y": 0}]}, "objects.0.class", "lower-case"),
        ({"objects": [{"class": "door", "x": "left", "y": 0}]}, "objects.0.x", "number"),
        ({"objects": [{"class": "door", "x": float("nan"), "y": 0}]}, "objects.0.x", "finite"),
        ({"objects": []}, "objects", "at least 1"),
        ({"walls": [{"x1": 1, "y1": 1, "x2": 1, "y2": 1}]}, "walls.0", "distinct"),
        ({"regions": [{"name": "R", "polygon": [[0, 0], [1, 1]]}]}, "regions.0.polygon", "3"),
        ({"colour": "red"}, "colour", "Extra inputs"),
        ({"name": "../etc"}, "name", "letters"),
    ],
)
def test_bad_maps_name_the_field_and_reason(patch: dict, field: str, reason: str) -> None:
    data = {**ROOM, **patch}
    with pytest.raises(MapError) as info:
        parse_map(data, source="bad.json")
    message = str(info.value)
    assert field in message
    assert reason in message


def test_name_must_match_file_name(tmp_path: Path) -> None:
    path = tmp_path / "other.json"
    path.write_text(json.dumps(ROOM))
    with pytest.raises(MapError, match="must equal the file name"):
        load_map(path)


def test_invalid_json_is_refused_with_the_path(tmp_path: Path) -> None:
    path = tmp_path / "room.json"
    path.write_text("{not json")
    with pytest.raises(MapError, match="not valid JSON"):
        load_map(path)


def test_line_of_sight_blocks_through_walls_but_not_own_wall() -> None:
    m = parse_map(ROOM)
    vis = m.line_of_sight([[1.0, 1.0], [3.0, 2.5], [1.0, 2.5]])
    door, west_table, east_table = 0, 1, 2
    # From the west table's side, the inner wall hides the east table and the door...
    assert not vis[0, east_table]
    assert not vis[0, door]
    # ...but from above the inner wall's end the door is visible, the low table is not.
    assert vis[2, door]
    assert not vis[2, east_table]
    # The door sits in the east wall; that wall does not hide it.
    assert vis[1, door]
    assert vis[0, west_table]


def test_free_space_is_inside_walls_and_clear_of_them() -> None:
    m = ensure_prepared(parse_map(ROOM))
    fs = m.free_space
    assert fs.is_free([1.0, 3.0], [1.5, 2.5]).all()
    assert not fs.is_free([-0.5, 5.0, 2.0, 0.05], [1.0, 1.0, 1.0, 1.5]).any()
    pts = fs.sample(2000, np.random.default_rng(1))
    assert fs.is_free(pts[:, 0], pts[:, 1]).all()
    assert (pts[:, 0] > 0).all() and (pts[:, 0] < 4).all()


def test_regions_and_json_round_trip() -> None:
    m = parse_map(ROOM)
    assert m.region_at(1.0, 1.0) == "West"
    assert m.region_at(3.0, 1.0) is None
    again = parse_map(json.loads(json.dumps(m.to_json())))
    assert again.to_json() == m.to_json()
    assert m.to_json()["objects"][0]["class"] == "door"


def test_derived_values_are_made_once_and_the_oldest_go_first(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import app.maps.model as model

    m = paper_office()
    classes = ("window", "door")
    assert m.class_indexes(classes).tolist() == [m.classes.index(c) for c in classes]
    assert m.class_indexes(classes) is m.class_indexes(classes)  # kept
    monkeypatch.setattr(model, "DERIVED_LIMIT", 3)
    m.derived.clear()
    made: list[int] = []

    def value(k: int) -> int:
        def make() -> int:
            made.append(k)
            return k

        return m.derived_value(("test", k), make)

    assert [value(k) for k in (1, 2, 1, 3, 4, 1)] == [1, 2, 1, 3, 4, 1]
    assert made == [1, 2, 3, 4, 1]  # 1 made again: the oldest, it went when 4 came
    assert len(m.derived) == 3


def test_fixtures_are_doors_windows_and_what_is_mounted_in_a_wall() -> None:
    """A door drawn in a gap between two walls is no farther than its frame from a wall
    it is not within reach of; it is a fixture by its class. A sign on a wall is one by
    being mounted in it; a table and a plant are neither."""
    sm = parse_map(
        {
            "name": "fixtures",
            "walls": [
                {"x1": 0, "y1": 0, "x2": 2.5, "y2": 0},
                {"x1": 3.5, "y1": 0, "x2": 8, "y2": 0},
                {"x1": 8, "y1": 0, "x2": 8, "y2": 6},
            ],
            "objects": [
                {"class": "door", "x": 3.0, "y": 0.0},
                {"class": "sign", "x": 8.0, "y": 3.0},
                {"class": "table", "x": 4.0, "y": 3.0},
                {"class": "plant", "x": 1.0, "y": 0.5},
                {"class": "window", "x": 6.0, "y": 0.0},
            ],
        }
    )
    assert not sm.mounted_walls[0].any()  # (the door sits in the gap)
    assert sm.fixed.tolist() == [True, True, False, False, True]
