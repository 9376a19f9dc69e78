"""Hostile map files, one per way a venue's export can go wrong (shared by the tests)."""

from __future__ import annotations

import json
from pathlib import Path


def box(name: str, *, walls: list[dict] | None = None, objects: list[dict] | None = None,
        regions: list[dict] | None = None) -> dict:  # fmt: skip
    """A 6 m x 4 m walled room with a door, plus whatever is given."""
    outline = [
        {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
        {"x1": 6, "y1": 0, "x2": 6, "y2": 4},
        {"x1": 6, "y1": 4, "x2": 0, "y2": 4},
        {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
    ]
    data = {
        "name": name,
        "walls": outline + (walls or []),
        "objects": [{"class": "door", "x": 6, "y": 2}, {"class": "table", "x": 2, "y": 2}]
        + (objects or []),
    }
    if regions:
        data["regions"] = regions
    return data


def hostile_maps() -> dict[str, dict]:
    """name -> decoded JSON of each hostile case."""
    many = [{"x1": 0.001 * i, "y1": 0, "x2": 0.001 * i, "y2": 1} for i in range(100_000)]
    return {
        "many_walls": box("many_walls", walls=many),
        "no_free_space": {
            "name": "no_free_space",
            # four walls 10 cm apart: nothing is 0.1 m clear of them
            "walls": [
                {"x1": 0, "y1": 0, "x2": 0.1, "y2": 0},
                {"x1": 0.1, "y1": 0, "x2": 0.1, "y2": 0.1},
                {"x1": 0.1, "y1": 0.1, "x2": 0, "y2": 0.1},
                {"x1": 0, "y1": 0.1, "x2": 0, "y2": 0},
            ],
            "objects": [{"class": "door", "x": 0.05, "y": 0}],
        },
        "huge_coordinates": box(
            "huge_coordinates", objects=[{"class": "sign", "x": 1e300, "y": 2}]
        ),
        "zero_length_wall": box("zero_length_wall", walls=[{"x1": 3, "y1": 1, "x2": 3, "y2": 1}]),
        "outside_object": box(
            "outside_object",
            objects=[
                {"class": "window", "x": 6.08, "y": 1},  # 8 cm outside the east wall: snapped
                {"class": "bench", "x": 9, "y": 2},  # 3 m outside: a warning, kept
            ],
        ),
        "self_intersecting": box(
            "self_intersecting",
            walls=[
                {"x1": 3, "y1": 0, "x2": 3, "y2": 2},
                {"x1": 3, "y1": 1, "x2": 3, "y2": 1.5},  # lies on the wall above
            ],
            regions=[{"name": "bowtie", "polygon": [[0, 0], [6, 4], [6, 0], [0, 4]]}],
        ),
    }


def write_hostile_dir(directory: Path) -> None:
    """Every hostile case as a file, plus a broken symlink and an oversized file."""
    for name, data in hostile_maps().items():
        (directory / f"{name}.json").write_text(json.dumps(data))
    (directory / "broken_link.json").symlink_to(directory / "gone" / "nowhere.json")
