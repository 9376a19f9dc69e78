"""Venues with several floors: the map file's levels and connectors, their checks, the plane."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from app.maps.check import check_data, check_file
from app.maps.levels import LEVEL_GAP_M
from app.maps.model import MapError, parse_map
from app.maps.prepare import ensure_prepared
from app.resources import bundled_maps_dir
from app.simulation.venue import venue_spec

VENUE = venue_spec()


def problems_of(data: dict[str, object]) -> list[str]:
    return [f"{p.field}: {p.message}" for p in check_data(data, source="v.json").problems]


def edited(edit: object) -> dict[str, object]:
    data = copy.deepcopy(VENUE)
    edit(data)  # type: ignore[operator]
    return data


def test_the_venue_passes_every_check_and_lists_its_levels_and_connectors() -> None:
    result = check_data(VENUE, source="v.json")
    assert result.problems == []
    m = result.map
    assert m is not None
    layout = m.layout
    assert [lv.id for lv in layout.levels] == ["L0", "L1", "L2"]
    assert [lv.name for lv in layout.levels] == ["Ground Floor", "First Floor", "Second Floor"]
    assert [c.id for c in layout.connectors] == ["lift-a", "stairs", "esc-up", "esc-down"]
    assert layout.object_level.tolist() == [
        layout.level_index(str(o["level"]))
        for o in VENUE["objects"]  # type: ignore[attr-defined]
    ]
    assert len(layout.wall_level) == len(VENUE["walls"])  # type: ignore[arg-type]
    assert set(layout.region_level.tolist()) == {0, 1, 2}


def test_levels_lie_side_by_side_in_the_plane_and_come_back() -> None:
    m = ensure_prepared(parse_map(VENUE))
    layout = m.layout
    assert layout.pitch_m == pytest.approx(24.0 + LEVEL_GAP_M)
    # An object on the First Floor lies one pitch east of its file position.
    first = int(np.flatnonzero(layout.object_level == 1)[0])
    spec_obj = VENUE["objects"][first]  # type: ignore[index]
    assert m.object_xy[first].tolist() == [spec_obj["x"] + layout.pitch_m, spec_obj["y"]]
    pts = np.array([[1.0, 2.0], [23.0, 13.0], [5.0, 5.0]])
    plane = layout.to_plane(pts, [0, 1, 2])
    back, level = layout.from_plane(plane)
    np.testing.assert_allclose(back, pts)
    assert level.tolist() == [0, 1, 2]
    # The file's JSON comes back unshifted.
    assert m.to_json()["objects"][first]["x"] == spec_obj["x"]  # type: ignore[index]
    # Each level has free space of its own; the gaps between them have none.
    fs = ensure_prepared(m).free_space
    assert fs.is_free([5.0, 5.0 + layout.pitch_m, 5.0 + 2 * layout.pitch_m], [5.0] * 3).all()
    assert not fs.is_free([24.0 + LEVEL_GAP_M / 2], [5.0]).any()


def test_no_line_of_sight_runs_from_one_level_into_another() -> None:
    data = edited(lambda d: d["walls"].pop(3))  # the west wall of the Ground Floor: open
    m = parse_map(data)
    pitch = m.layout.pitch_m
    # Through the gap east of the Ground Floor a point there would see the First Floor.
    sees = m.line_of_sight([[23.0, 7.0]], np.flatnonzero(m.layout.object_level == 1))
    assert not sees.any()
    assert pitch > 0


def test_a_file_without_levels_is_unchanged() -> None:
    path = bundled_maps_dir() / "paper_office.json"
    data = json.loads(path.read_text())
    m = parse_map(data)
    assert m.layout.levels == () and m.layout.connectors == ()
    out = m.to_json()
    assert "levels" not in out and "connectors" not in out
    assert all("level" not in w for w in out["walls"])  # type: ignore[attr-defined]
    assert all("level" not in o for o in out["objects"])  # type: ignore[attr-defined]
    rows = [[w["x1"], w["y1"], w["x2"], w["y2"]] for w in data["walls"]]
    np.testing.assert_array_equal(m.walls, rows)


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda d: d["walls"][0].pop("level"), "walls[0].level: missing: the map has levels"),
        (lambda d: d["objects"][2].update(level="L9"), "objects[2].level: 'L9' is not a level"),
        (lambda d: d["levels"][1].update(id="L0"), "levels[1].id: 'L0' is also levels[0]'s id"),
        (lambda d: d["levels"][2].update(ordinal=0), "levels[2].ordinal: 0 is also level 'L0'"),
        (lambda d: d.update(levels=[]), "levels: must list at least one level"),
        (
            lambda d: d["connectors"][0]["stops"][1].update(level="L7"),
            "connectors[0].stops[1].level: 'L7' is not a level",
        ),
        (
            lambda d: d["connectors"][1]["stops"][1].update(level="L0"),
            "connectors[1].stops[1].level: a second stop on level 'L0'",
        ),
        (
            lambda d: d["connectors"][2].update(direction="both"),
            'direction must be "up" or "down"',
        ),
        (
            lambda d: d["connectors"][2]["stops"][1].update(level="L2"),
            "escalator 'esc-up' joins levels 'L0' and 'L2', which are not adjacent",
        ),
        (lambda d: d["connectors"][3].update(id="lift-a"), "'lift-a' is also connectors[0]'s id"),
        (
            lambda d: d["connectors"][0].update(kind="teleporter"),
            "connectors.0.kind: Input should be 'elevator', 'stairs', 'escalator' or 'ramp'",
        ),
        (
            lambda d: d["connectors"][1]["stops"][0].update(polygon=[[30, 1], [31, 1], [31, 2]]),
            "connectors[1].stops[0].polygon: stairs 'stairs' (Stairs): its stop on level 'L0' "
            "holds no free space",
        ),
        (
            lambda d: d["connectors"][0]["stops"][0].update(
                polygon=[[3.05, 1], [3.1, 1], [3.1, 2]]
            ),
            "its stop on level 'L0' holds no free space",
        ),
    ],
)
def test_bad_levels_and_connectors_are_refused_with_their_field(
    edit: object, expected: str
) -> None:
    found = problems_of(edited(edit))
    assert any(expected in p for p in found), found
    assert check_data(edited(edit), source="v.json").map is None


def test_levels_without_levels_are_refused() -> None:
    data = json.loads((bundled_maps_dir() / "paper_office.json").read_text())
    data["objects"][0]["level"] = "L0"
    data["connectors"] = VENUE["connectors"]
    found = problems_of(data)
    assert "objects[0].level: the map has no levels: remove it" in found
    assert "connectors: the map has no levels: connectors need levels" in found
    with pytest.raises(MapError, match=r"objects\[0\]\.level"):
        parse_map(data)


def test_a_level_with_no_free_space_is_named() -> None:
    def no_room_on_l2(d: dict[str, object]) -> None:
        d["walls"] = [w for w in d["walls"] if w["level"] != "L2" or w["x1"] == 3.0]  # type: ignore[attr-defined,index]
        for c in d["connectors"]:  # type: ignore[attr-defined]
            c["stops"] = [s for s in c["stops"] if s["level"] != "L2"]

    found = problems_of(edited(no_room_on_l2))
    assert any(p.startswith("walls: the map has no free space on level 'L2'") for p in found), found


def test_map_check_reads_a_venue_file(tmp_path: Path) -> None:
    path = tmp_path / f"{VENUE['name']}.json"
    path.write_text(json.dumps(VENUE))
    result = check_file(path)
    assert result.ok, [str(p) for p in result.problems]
    assert result.map is not None and len(result.map.layout.levels) == 3
