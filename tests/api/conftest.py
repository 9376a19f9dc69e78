"""A TestClient on a fresh app (no viser, small limits so they are easy to hit)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.helpers import make_settings


@pytest.fixture
def client() -> Iterator[TestClient]:
    with TestClient(create_app(make_settings())) as c:
        yield c


@pytest.fixture
def session_id(client: TestClient) -> str:
    r = client.post("/sessions", json={"map": "paper_office", "particles": 1000, "seed": 1})
    assert r.status_code == 201, r.text
    return r.json()["id"]
