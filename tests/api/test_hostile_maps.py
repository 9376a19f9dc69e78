"""Hostile map files in --maps: each refused or warned at load; the rest served; no 500."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.helpers import make_settings
from tests.maps.hostile import box, write_hostile_dir

REFUSED = ("many_walls", "no_free_space", "huge_coordinates", "zero_length_wall", "broken_link")
SERVED = ("good", "outside_object", "self_intersecting")


def test_hostile_maps_are_skipped_and_the_others_served(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    write_hostile_dir(tmp_path)
    (tmp_path / "good.json").write_text(json.dumps(box("good")))
    caplog.set_level(logging.WARNING, logger="bearings.maps")
    with TestClient(create_app(make_settings(maps=[tmp_path]))) as c:
        names = {m["name"] for m in c.get("/maps").json()}
        assert {"paper_office", *SERVED} <= names
        assert not names & set(REFUSED)
        for name in REFUSED:
            r = c.post("/sessions", json={"map": name, "particles": 1000})
            assert r.status_code == 404, r.text
            assert name in r.json()["message"]
        for name in SERVED:
            r = c.post("/sessions", json={"map": name, "particles": 1000, "seed": 1})
            assert r.status_code == 201, r.text
            sid = r.json()["id"]
            frame = {"detections": [{"class": "door", "bearing_deg": 10.0}]}
            r = c.post(f"/sessions/{sid}/frames", json=frame)
            assert r.status_code == 200, r.text
    logged = caplog.text
    for name in REFUSED:
        assert f"{name}.json" in logged  # each refusal is logged with its file
    assert "walls: 100,004 entries" in logged
    assert "no free space" in logged and "too far from the origin" in logged
    assert "broken symbolic link" in logged and "overlaps walls[4]" in logged
