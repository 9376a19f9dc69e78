"""Map checks: each hostile case gives a clear message naming the file and the field."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.maps import check
from app.maps.check import check_data, check_file, load_map, load_map_dirs
from app.maps.model import MapError
from app.resources import bundled_maps_dir
from tests.maps.hostile import box, hostile_maps, write_hostile_dir

CASES = hostile_maps()


def messages(name: str) -> list[str]:
    return [str(p) for p in check_data(CASES[name], source=f"{name}.json").problems]


def test_bundled_maps_have_no_problems() -> None:
    for path in sorted(bundled_maps_dir().glob("*.json")):
        result = check_file(path)
        assert result.ok, [str(p) for p in result.problems]


def test_too_many_walls_is_refused_before_anything_is_built() -> None:
    result = check_data(CASES["many_walls"], source="many_walls.json")
    assert result.map is None
    assert messages("many_walls") == [
        f"many_walls.json: walls: 100,004 entries; at most {check.MAX_WALLS:,} are accepted"
    ]


def test_no_free_space_is_refused() -> None:
    result = check_data(CASES["no_free_space"], source="no_free_space.json")
    assert result.map is None
    (msg,) = messages("no_free_space")
    assert msg.startswith("no_free_space.json: walls: the map has no free space")


def test_huge_coordinates_are_refused_with_the_field() -> None:
    (msg,) = messages("huge_coordinates")
    assert msg.startswith("huge_coordinates.json: objects[2].x: 1e+300 m is too far")
    assert check_data(CASES["huge_coordinates"]).map is None


def test_too_wide_a_map_is_refused() -> None:
    data = box("wide", objects=[{"class": "sign", "x": 5000, "y": 2}])
    (problem,) = check_data(data, source="wide.json").problems
    assert problem.field == "(extent)" and "metres" in problem.message


def test_non_finite_and_zero_length_are_field_errors() -> None:
    (msg,) = messages("zero_length_wall")
    assert (
        msg
        == "zero_length_wall.json: walls.4: Value error, a wall must have two distinct end points"
    )
    data = box("nan", walls=[{"x1": float("nan"), "y1": 0, "x2": 1, "y2": 1}])
    (problem,) = check_data(data, source="nan.json").problems
    assert problem.field == "walls.4.x1" and "finite" in problem.message


def test_objects_outside_walls_are_snapped_or_reported() -> None:
    result = check_data(CASES["outside_object"], source="outside_object.json")
    assert result.map is not None  # warnings only
    window, bench = result.problems
    assert window.severity == bench.severity == "warning"
    assert window.field == "objects[2]" and "moved onto it at (6.00, 1.00)" in window.message
    assert bench.field == "objects[3]" and "outside the walls" in bench.message
    m = result.map
    assert m.object_xy[2].tolist() == [6.0, 1.0]
    assert m.mounted_walls[2].any()  # the snapped window now sits in the east wall
    assert m.object_xy[3].tolist() == [9.0, 2.0]


def test_overlapping_walls_and_bowtie_regions_are_reported() -> None:
    result = check_data(CASES["self_intersecting"], source="self_intersecting.json")
    assert result.map is not None
    fields = {p.field: p.message for p in result.problems}
    assert fields["walls[5]"] == "overlaps walls[4] along 0.50 m (a duplicated wall?)"
    assert fields["regions[0].polygon"] == (
        "region 'bowtie' is not a simple polygon: its edge from point 0 crosses its edge "
        "from point 2"
    )
    # A square and a concave (L-shaped) room are simple.
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    ell = np.array([[0, 0], [3, 0], [3, 1], [1, 1], [1, 3], [0, 3]], dtype=float)
    assert check._first_self_crossing(square) is None
    assert check._first_self_crossing(ell) is None


def test_files_broken_links_and_sizes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    link = tmp_path / "a.json"
    link.symlink_to(tmp_path / "missing.json")
    (problem,) = check_file(link).problems
    assert problem.field == "(file)" and "broken symbolic link" in problem.message
    big = tmp_path / "big.json"
    big.write_text(json.dumps(box("big")))
    monkeypatch.setattr(check, "MAX_FILE_BYTES", 100)
    (problem,) = check_file(big).problems
    assert "bytes; map files of at most 100 bytes" in problem.message
    bad = tmp_path / "bad.json"
    bad.write_text('{"name": "bad", "walls": [], "objects": [{"class": "door", "x": NaN, "y": 0}]}')
    assert "not valid JSON" in check_file(bad).problems[0].message


def test_load_map_raises_with_every_error() -> None:
    with pytest.raises(MapError) as info:
        load_map(Path("/nonexistent/x.json"))
    assert "no such map file" in str(info.value)


def test_a_bad_file_is_skipped_and_the_others_are_served(tmp_path: Path) -> None:
    write_hostile_dir(tmp_path)
    (tmp_path / "good.json").write_text(json.dumps(box("good")))
    maps, problems = load_map_dirs([bundled_maps_dir(), tmp_path, tmp_path / "nope"])
    assert {"paper_office", "good", "outside_object", "self_intersecting"} <= set(maps)
    for refused in ("many_walls", "no_free_space", "huge_coordinates", "zero_length_wall"):
        assert refused not in maps
        assert any(p.source.endswith(f"{refused}.json") for p in problems)
    assert any("broken symbolic link" in p.message for p in problems)
    assert any(p.field == "(directory)" for p in problems)
    assert maps["good"].prepared  # prepared at load
    assert np.count_nonzero(maps["good"].free_space.mask) > 0


def test_map_check_cli_prints_problems_and_exit_code(tmp_path: Path) -> None:
    write_hostile_dir(tmp_path)
    files = [str(tmp_path / f"{n}.json") for n in ("zero_length_wall", "huge_coordinates")]
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "app.cli",
            "map",
            "check",
            *files,
            str(tmp_path / "broken_link.json"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 1
    assert "zero_length_wall.json: walls.4:" in bad.stdout
    assert "huge_coordinates.json: objects[2].x:" in bad.stdout
    assert "broken_link.json: (file): broken symbolic link" in bad.stdout
    good = subprocess.run(
        [
            sys.executable,
            "-m",
            "app.cli",
            "map",
            "check",
            str(bundled_maps_dir() / "paper_office.json"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert good.returncode == 0 and "no problems" in good.stdout


def test_a_map_that_turns_onto_itself_is_usable_with_a_warning_that_says_why() -> None:
    """A floor a half turn carries onto itself loads, with a warning naming the turn and
    what would tell its twin places apart; the same floor with one door does not warn."""
    from app.experiments.hard_maps import hard_map

    result = check_data(hard_map("symmetric_room").map.to_json(), source="hall")
    assert result.map is not None and not result.errors
    (warning,) = result.problems
    assert warning.severity == "warning" and warning.field == "objects"
    assert "rotation of 180 deg about (6.00, 4.00)" in warning.message
    assert "compass" in warning.message
    assert check_data(hard_map("rotation_room").map.to_json(), source="room").problems == []
    # A square hall with a window in each wall turns onto itself three ways: one warning.
    hall = {
        "name": "hall",
        "walls": [
            {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
            {"x1": 6, "y1": 0, "x2": 6, "y2": 6},
            {"x1": 6, "y1": 6, "x2": 0, "y2": 6},
            {"x1": 0, "y1": 6, "x2": 0, "y2": 0},
        ],
        "objects": [
            {"class": "window", "x": x, "y": y} for x, y in ((3, 0), (6, 3), (3, 6), (0, 3))
        ],
    }
    (warning,) = check_data(hall, source="hall").problems
    assert "rotation of 90, 180 and 270 deg about (3.00, 3.00)" in warning.message
