"""A TestClient on a fresh app (no viser, small limits so they are easy to hit)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.main import create_app


def make_settings(**overrides: object) -> Settings:
    base = {
        "viser": False,
        "max_sessions": 5,
        "max_particles": 20_000,
        "default_particles": 1000,
        "max_detections": 20,
        "max_message_bytes": 8192,
    }
    return Settings(**{**base, **overrides})


@pytest.fixture
def client() -> Iterator[TestClient]:
    with TestClient(create_app(make_settings())) as c:
        yield c


@pytest.fixture
def session_id(client: TestClient) -> str:
    r = client.post("/sessions", json={"map": "paper_office", "particles": 1000, "seed": 1})
    assert r.status_code == 201, r.text
    return r.json()["id"]
