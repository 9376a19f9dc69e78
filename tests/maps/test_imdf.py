"""The IMDF importer, on a small venue written by hand from the IMDF specification.

``tests/maps/data/riverside_imdf`` is "Riverside Station": three levels of 40 m x 24 m
(layout in metres, south-west corner at 47.37690 N, 8.54170 E; the venue's display
point, the map's origin, is the building's middle, layout (20, 12)). On each level a
corridor runs east-west between a row of rooms to the south and one to the north; the
ground floor's corridor opens onto the entrance hall. Stairs (8-13 m), two escalators
(13-16 m up, 16-19 m down, joined by directed relationships) and a lift (19-22 m)
stand on the corridor's north side; the stairs and the lift are on every level and
are joined by their overlapping footprints. A kiosk and a column are fixtures that
block the way; a bench and a planter are not. Two units are named by their occupants.
"""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.maps.check import check_data, load_map
from app.maps.geometry import segments_cross_walls
from app.maps.importers.common import MapImportError
from app.maps.importers.imdf import import_imdf
from app.resources import bundled_maps_dir
from tools.make_imdf_venue import venue, write

VENUE = Path(__file__).parent / "data" / "riverside_imdf"


def at(x: float, y: float) -> np.ndarray:
    """Map metres of a point of the layout (origin at the building's middle)."""
    return np.array([x - 20.0, y - 12.0])


@pytest.fixture(scope="module")
def riverside() -> dict:
    data, _ = import_imdf(VENUE, "riverside")
    return data


def walls_of(data: dict, level: str) -> np.ndarray:
    return np.array(
        [[w["x1"], w["y1"], w["x2"], w["y2"]] for w in data["walls"] if w["level"] == level]
    )


def crosses(data: dict, level: str, a: tuple[float, float], b: tuple[float, float]) -> bool:
    return bool(segments_cross_walls(at(*a)[None], at(*b)[None], walls_of(data, level))[0])


def objects_of(data: dict, level: str, cls: str) -> list[dict]:
    return [o for o in data["objects"] if o["level"] == level and o["class"] == cls]


def test_levels_one_per_ordinal_named_and_stacked(riverside: dict) -> None:
    assert riverside["levels"] == [
        {"id": "L0", "name": "Ground Floor", "ordinal": 0, "elevation_m": 0.0},
        {"id": "L1", "name": "First Floor", "ordinal": 1, "elevation_m": 4.0},
        {"id": "L2", "name": "Second Floor", "ordinal": 2, "elevation_m": 8.0},
    ]
    for key in ("walls", "objects", "regions"):
        assert {item["level"] for item in riverside[key]} == {"L0", "L1", "L2"}


def test_levels_of_two_buildings_on_one_ordinal_make_one_map_level(tmp_path: Path) -> None:
    """A venue of several buildings has one IMDF level per building and floor, sharing
    the ordinal: one map level, and the summary says it gathered two."""

    def second_building(data: dict) -> None:
        ground = next(f for f in data["features"] if f["properties"]["ordinal"] == 0)
        annex = json.loads(json.dumps(ground))
        annex["id"] = "7d3c7f0e-2b9a-4c1e-9a51-000000000001"
        data["features"].append(annex)

    data, summary = import_imdf(_broken(tmp_path, "level.geojson", second_building), "x")
    assert [lv["id"] for lv in data["levels"]] == ["L0", "L1", "L2"]
    first = summary.lines()[0]
    assert "3 levels from 4 IMDF levels" in first and "L0 'Ground Floor' from 2," in first


def test_projection_puts_the_building_in_metres_around_its_middle(riverside: dict) -> None:
    xy = np.concatenate([walls_of(riverside, "L0")[:, 0:2], walls_of(riverside, "L0")[:, 2:4]])
    # The layout's 40 m x 24 m; the hand-made file used a spherical metre per degree,
    # pyproj the ellipsoid: a few centimetres apart over 40 m.
    assert np.allclose(xy.min(axis=0), [-20, -12], atol=0.1)
    assert np.allclose(xy.max(axis=0), [20, 12], atol=0.1)


def test_walls_part_rooms_but_not_open_floor(riverside: dict) -> None:
    # Entrance hall (lobby) to the concourse (walkway): one open floor, no wall.
    assert not crosses(riverside, "L0", (6, 4), (6, 12))
    # Concourse to the stairs and the escalators: open.
    assert not crosses(riverside, "L0", (10, 12), (10, 20))
    assert not crosses(riverside, "L0", (14.5, 12), (14.5, 20))
    # Between the stairs and the escalator, and between the two escalators: walls.
    assert crosses(riverside, "L0", (11, 20), (14.5, 20))
    assert crosses(riverside, "L0", (14.5, 20), (17.5, 20))
    # The ticket office: through its door (15-16 m) no wall, beside it a wall.
    assert not crosses(riverside, "L0", (15.5, 12), (15.5, 4))
    assert crosses(riverside, "L0", (18, 12), (18, 4))
    # The lobby and the ticket office share a wall with no opening.
    assert crosses(riverside, "L0", (10, 4), (14, 4))
    # The lift: in through its door only.
    assert not crosses(riverside, "L1", (20.5, 12), (20.5, 17.5))
    assert crosses(riverside, "L1", (21.5, 12), (21.5, 17.5))
    # The outer wall stays whole at the main entrance (the door is mounted in it).
    assert crosses(riverside, "L0", (6, 1), (6, -1))


def test_fixtures_that_block_become_walls_and_the_rest_do_not(riverside: dict) -> None:
    assert crosses(riverside, "L0", (29, 11.75), (34, 11.75))  # the newsstand kiosk
    assert crosses(riverside, "L1", (23, 11.8), (25, 11.8))  # the column
    assert not crosses(riverside, "L0", (18, 10), (18, 12.5))  # the bench
    assert not crosses(riverside, "L1", (5, 11.5), (8, 11.5))  # the planter


def test_objects_doors_lifts_restrooms_and_amenities(riverside: dict) -> None:
    doors = objects_of(riverside, "L0", "door")
    labels = {d.get("label") for d in doors}
    assert {"Main Entrance", "door to Ticket Office", "door to Riverside Cafe"} <= labels
    ticket = next(d for d in doors if d.get("label") == "door to Ticket Office")
    assert np.allclose([ticket["x"], ticket["y"]], at(15.5, 8), atol=0.05)
    for level in ("L0", "L1", "L2"):
        (lift,) = objects_of(riverside, level, "elevator")  # at its door, not a door
        assert np.allclose([lift["x"], lift["y"]], at(20.5, 16), atol=0.05)
        assert lift["label"] == "Lift"
        assert len(objects_of(riverside, level, "restroom")) == 1
        assert len(objects_of(riverside, level, "stairs")) == 1
    assert [o.get("label") for o in objects_of(riverside, "L1", "restroom")] == ["Ladies"]
    assert len(objects_of(riverside, "L0", "escalator")) == 2
    assert objects_of(riverside, "L2", "escalator") == []
    assert [o["label"] for o in objects_of(riverside, "L0", "ticketing")] == ["Ticket machines"]
    assert len(objects_of(riverside, "L1", "atm")) == 1
    assert objects_of(riverside, "L2", "fireextinguisher")
    assert not any(o["class"] == "unspecified" for o in riverside["objects"])


def test_regions_from_named_units_and_occupants(riverside: dict) -> None:
    regions = {(r["name"], r["level"]) for r in riverside["regions"]}
    assert {("Concourse", "L0"), ("Riverside Cafe", "L0"), ("Pharmacy", "L1")} <= regions
    assert ("Gallery", "L2") in regions
    cafe = next(r for r in riverside["regions"] if r["name"] == "Riverside Cafe")
    assert np.allclose(np.min(cafe["polygon"], axis=0), at(0, 16), atol=0.1)


def test_connectors_from_relationships_and_overlap(riverside: dict) -> None:
    by_kind: dict[str, list[dict]] = {}
    for c in riverside["connectors"]:
        by_kind.setdefault(c["kind"], []).append(c)
    assert sorted(by_kind) == ["elevator", "escalator", "stairs"]
    escalators = sorted(by_kind["escalator"], key=lambda c: c["stops"][0]["polygon"][0][0])
    assert [c["direction"] for c in escalators] == ["up", "down"]
    for c in escalators:
        assert [s["level"] for s in c["stops"]] == ["L0", "L1"]
    (lift,) = by_kind["elevator"]
    assert lift["label"] == "Lift" and lift["direction"] == "both"
    assert [s["level"] for s in lift["stops"]] == ["L0", "L1", "L2"]
    poly = np.array(lift["stops"][0]["polygon"])
    assert np.allclose(poly.min(axis=0), at(19, 16), atol=0.1)
    assert np.allclose(poly.max(axis=0), at(22, 19), atol=0.1)
    (stairs,) = by_kind["stairs"]
    assert [s["level"] for s in stairs["stops"]] == ["L0", "L1", "L2"]
    assert len({c["id"] for c in riverside["connectors"]}) == 4


def test_summary_says_what_was_made_of_what() -> None:
    _, summary = import_imdf(VENUE, "riverside")
    text = "\n".join(summary.lines())
    assert "3 levels from 3 IMDF levels" in text
    assert "units: 35 ->" in text and "24 regions" in text
    assert "openings: 25 -> 22 doors (1 in the outer wall, kept mounted in it), 3 an " in text
    assert "not used: unspecified 1" in text
    assert "as walls: kiosk 1, obstruction 1; not used: furniture 1, vegetation 1" in text
    assert "(2 from 3 relationships, 2 by overlapping units)" in text
    assert "relationship traversal 1" in text
    # The venue's other files are named as not read (the import has no use for them).
    assert text.endswith("files not read: address.geojson, building.geojson, footprint.geojson")


def test_a_zip_reads_like_the_folder(tmp_path: Path, riverside: dict) -> None:
    flat = tmp_path / "flat.zip"
    nested = tmp_path / "nested.zip"
    with zipfile.ZipFile(flat, "w") as a, zipfile.ZipFile(nested, "w") as b:
        for f in sorted(VENUE.iterdir()):
            a.write(f, f.name)
            b.write(f, f"export/riverside/{f.name}")
    for archive in (flat, nested):
        data, summary = import_imdf(archive, "riverside")
        data["description"] = riverside["description"]
        assert data == riverside
        assert summary.not_read == ["address.geojson", "building.geojson", "footprint.geojson"]


def _broken(tmp_path: Path, name: str, edit) -> Path:
    d = tmp_path / "venue"
    shutil.copytree(VENUE, d)
    path = d / name
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    return d


def test_refusals_name_the_file_the_feature_and_the_reason(tmp_path: Path) -> None:
    with pytest.raises(MapImportError, match=r"no such folder or \.zip"):
        import_imdf(tmp_path / "missing", "x")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(MapImportError, match=r"no level\.geojson"):
        import_imdf(empty, "x")
    not_zip = tmp_path / "v.zip"
    not_zip.write_text("hello")
    with pytest.raises(MapImportError, match=r"not a folder or a readable \.zip"):
        import_imdf(not_zip, "x")

    def bad_ordinal(d: dict) -> None:
        d["features"][1]["properties"]["ordinal"] = "first"

    with pytest.raises(MapImportError, match=r"level.geojson: features\[1\].*ordinal"):
        import_imdf(_broken(tmp_path / "a", "level.geojson", bad_ordinal), "x")

    def lost_level(d: dict) -> None:
        d["features"][3]["properties"]["level_id"] = "nowhere"

    with pytest.raises(MapImportError, match=r"unit.geojson: features\[3\].*'nowhere'"):
        import_imdf(_broken(tmp_path / "b", "unit.geojson", lost_level), "x")

    def point_opening(d: dict) -> None:
        d["features"][0]["geometry"] = {"type": "Point", "coordinates": [8.5418, 47.3769]}

    with pytest.raises(MapImportError, match=r"opening.geojson: features\[0\].*LineString"):
        import_imdf(_broken(tmp_path / "c", "opening.geojson", point_opening), "x")

    def wrong_type(d: dict) -> None:
        d["features"][0]["feature_type"] = "opening"

    with pytest.raises(MapImportError, match=r"feature_type 'opening' in the unit file"):
        import_imdf(_broken(tmp_path / "d", "unit.geojson", wrong_type), "x")

    def far_away(d: dict) -> None:
        d["features"][0]["geometry"]["coordinates"][0][1] = [8.5, 147.0]

    with pytest.raises(MapImportError, match=r"unit.geojson: coordinates"):
        import_imdf(_broken(tmp_path / "e", "unit.geojson", far_away), "x")
    with pytest.raises(MapImportError, match="storey"):
        import_imdf(VENUE, "x", storey_m=0.0)


def test_the_command_writes_a_map_that_passes_its_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "riverside.json"
    assert main(["map", "import", "--imdf", str(VENUE), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "3 levels from 3 IMDF levels" in printed and f"wrote {out}" in printed
    assert main(["map", "check", str(out)]) == 0
    assert "3 levels, 4 connectors" in capsys.readouterr().out
    m = load_map(out)
    assert [lv.name for lv in m.layout.levels] == ["Ground Floor", "First Floor", "Second Floor"]
    for extra in (["--objects", "x.csv"], ["--origin", "47,8"]):
        assert main(["map", "import", "--imdf", str(VENUE), *extra, "--out", str(out)]) == 1
        assert "does not go with --imdf" in capsys.readouterr().out
    assert main(["map", "import", "--imdf", str(tmp_path), "--out", str(out)]) == 1
    assert "no level.geojson" in capsys.readouterr().out


def test_the_bundled_example_is_the_importer_s_output() -> None:
    bundled = json.loads((bundled_maps_dir() / "riverside_station.json").read_text())
    data, _ = import_imdf(VENUE, "riverside_station")
    data["description"] = bundled["description"]
    result = check_data(data, source="riverside_station", expected_name="riverside_station")
    assert result.problems == [] and result.map is not None
    assert json.loads(json.dumps(result.map.to_json())) == bundled


def test_a_station_sized_venue_imports_and_passes_its_check(tmp_path: Path) -> None:
    """The synthetic venue of tools/make_imdf_venue.py on two levels (timed on four by
    benchmarks/imdf_import.py)."""
    features = venue(2, np.random.default_rng(0))
    write(features, tmp_path / "venue.zip")
    data, summary = import_imdf(tmp_path / "venue.zip", "station")
    assert summary.units == 368 and summary.fixtures == 1890
    kinds: dict[str, int] = {}
    for c in data["connectors"]:
        kinds[c["kind"]] = kinds.get(c["kind"], 0) + 1
    # Per band a lift and stairs joined by overlap and an escalator by its relationship.
    assert kinds == {"elevator": 3, "stairs": 3, "escalator": 3}
    result = check_data(data, source="station", expected_name="station")
    assert result.map is not None, result.problems
    assert len(result.map.layout.levels) == 2


def test_an_escalator_without_its_way_is_no_connector(tmp_path: Path) -> None:
    def undirected(d: dict) -> None:
        d["features"][0]["properties"]["direction"] = "undirected"

    data, summary = import_imdf(_broken(tmp_path, "relationship.geojson", undirected), "x")
    kinds = sorted(c["kind"] for c in data["connectors"])
    # The up escalator's relationship lost its way, and its units (found by overlap
    # then) have none either: only the down escalator is left of the two.
    assert kinds == ["elevator", "escalator", "stairs"]
    assert [c["direction"] for c in data["connectors"] if c["kind"] == "escalator"] == ["down"]
    text = "\n".join(summary.lines())
    assert "escalator relationship without a direction between two levels 1" in text
    assert "escalator units with no directed relationship (way unknown) 1" in text
    # The escalators are still seen: objects of their kind.
    assert sum(o["class"] == "escalator" for o in data["objects"]) == 4
    assert check_data(data, source="x", expected_name="x").map is not None


def _unit_ids(category: str) -> list[str]:
    """The ids of the venue's units of ``category``, in the file's order (L0 up)."""
    units = json.loads((VENUE / "unit.geojson").read_text())["features"]
    return [f["id"] for f in units if f["properties"]["category"] == category]


def test_an_id_used_twice_keeps_the_unit_a_connector_stands_on(tmp_path: Path) -> None:
    """A real export gave an amenity the id of a stairs unit (IMDF ids are unique): the
    stairs keep every floor, and the summary names the two features."""
    stairs_l1 = _unit_ids("stairs")[1]

    def reuse(d: dict) -> None:
        d["features"][0]["id"] = stairs_l1

    data, summary = import_imdf(_broken(tmp_path, "amenity.geojson", reuse), "x")
    (stairs,) = [c for c in data["connectors"] if c["kind"] == "stairs"]
    assert [s["level"] for s in stairs["stops"]] == ["L0", "L1", "L2"]
    text = "\n".join(summary.lines())
    assert (
        f"ids used twice (IMDF ids are unique; the feature read first keeps it, the other "
        f"is no connector's stop): amenity.geojson: features[0] has the id of "
        f"unit.geojson: features[18] ({stairs_l1})"
    ) in text
    # The amenity is still an object (only its place as a stop went).
    assert len(objects_of(data, "L0", "information")) == 1
    assert "check:" not in text


def test_stairs_that_pass_a_level_without_a_stop_are_pointed_out(tmp_path: Path) -> None:
    """Stairs units on the ground and second floors only (the first floor's unit is no
    stairs): one flight from L0 to L2, which the summary asks to check."""
    stairs_l1 = _unit_ids("stairs")[1]

    def not_stairs(d: dict) -> None:
        for f in d["features"]:
            if f["id"] == stairs_l1:
                f["properties"]["category"] = "unspecified"

    data, summary = import_imdf(_broken(tmp_path, "unit.geojson", not_stairs), "x")
    (stairs,) = [c for c in data["connectors"] if c["kind"] == "stairs"]
    assert [s["level"] for s in stairs["stops"]] == ["L0", "L2"]
    text = "\n".join(summary.lines())
    assert "  check: stairs-1 goes from L0 to L2, with no stop on L1" in text
    assert "ids used twice" not in text


def test_names_in_the_manifest_s_language_and_no_venue_file(tmp_path: Path) -> None:
    def french(d: dict) -> None:
        d["features"][0]["properties"]["name"] = {"en": "Ground Floor", "fr": "Rez-de-chaussée"}

    venue_dir = _broken(tmp_path, "level.geojson", french)
    (venue_dir / "manifest.json").write_text(json.dumps({"version": "1.0.0", "language": "fr"}))
    (venue_dir / "venue.geojson").unlink()
    data, _ = import_imdf(venue_dir, "x")
    # French where there is French, else English.
    assert [lv["name"] for lv in data["levels"]] == [
        "Rez-de-chaussée",
        "First Floor",
        "Second Floor",
    ]
    # Without the venue's display point the plane is centred on the levels' extent:
    # the same building's middle here.
    xy = np.array([[w["x1"], w["y1"]] for w in data["walls"]])
    assert np.allclose(xy.min(axis=0), [-20, -12], atol=0.1)


def test_storey_height_is_a_choice_of_the_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "tall.json"
    assert (
        main(["map", "import", "--imdf", str(VENUE), "--storey-m", "5.5", "--out", str(out)]) == 0
    )
    levels = json.loads(out.read_text())["levels"]
    assert [lv["elevation_m"] for lv in levels] == [0.0, 5.5, 11.0]
    capsys.readouterr()
    geojson = tmp_path / "floor.geojson"
    geojson.write_text(json.dumps({"type": "FeatureCollection", "features": []}))
    args = ["map", "import", "--geojson", str(geojson), "--storey-m", "5", "--out", str(out)]
    assert main(args) == 1
    assert "--storey-m goes with --imdf only" in capsys.readouterr().out
