"""Small maps shared by the localization tests."""

from __future__ import annotations

import pytest

from app.maps.model import SemanticMap, load_map, parse_map
from app.resources import bundled_maps_dir


def room(objects: list[dict], walls: list[dict] | None = None, name: str = "room") -> SemanticMap:
    """A 6 m x 4 m walled room with the given objects (and extra walls)."""
    outline = [
        {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
        {"x1": 6, "y1": 0, "x2": 6, "y2": 4},
        {"x1": 6, "y1": 4, "x2": 0, "y2": 4},
        {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
    ]
    return parse_map({"name": name, "walls": outline + (walls or []), "objects": objects})


@pytest.fixture(scope="session")
def paper_office() -> SemanticMap:
    return load_map(bundled_maps_dir() / "paper_office.json")


@pytest.fixture(scope="session")
def small_room() -> SemanticMap:
    """Asymmetric: one door, two windows, a table."""
    return room(
        [
            {"class": "door", "x": 6, "y": 3},
            {"class": "window", "x": 1.5, "y": 0},
            {"class": "window", "x": 4.5, "y": 0},
            {"class": "table", "x": 2, "y": 2.5},
        ]
    )
