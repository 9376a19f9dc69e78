"""Map fixtures of the localization tests (the builders are in tests/helpers.py)."""

from __future__ import annotations

import pytest

from app.maps.model import SemanticMap
from tests import helpers
from tests.helpers import room


@pytest.fixture(scope="session")
def paper_office() -> SemanticMap:
    return helpers.paper_office()


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
