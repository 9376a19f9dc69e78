"""GET /maps, /maps/{name}, /healthz, /metrics, /docs."""

from __future__ import annotations

import json
from pathlib import Path

from fastapi.testclient import TestClient

from app.main import create_app
from app.resources import bundled_maps_dir
from tests.helpers import make_settings


def test_health(client: TestClient) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}


def test_list_maps_has_summaries(client: TestClient) -> None:
    maps = {m["name"]: m for m in client.get("/maps").json()}
    office = maps["paper_office"]
    assert office["classes"] == ["door", "table", "window"]
    assert office["object_count"] == 11
    assert office["bounds"] == {"min_x": 0.0, "min_y": 0.0, "max_x": 10.0, "max_y": 7.0}


def test_get_map_returns_the_file(client: TestClient) -> None:
    body = client.get("/maps/paper_office").json()
    on_disk = json.loads((bundled_maps_dir() / "paper_office.json").read_text())
    assert body["name"] == on_disk["name"]
    assert body["objects"][-1] == on_disk["objects"][-1]
    assert body["objects"][0]["class"] == "window"


def test_unknown_map_is_404_with_message(client: TestClient) -> None:
    r = client.get("/maps/atlantis")
    assert r.status_code == 404
    assert "atlantis" in r.json()["message"] and "paper_office" in r.json()["message"]


def test_extra_map_directory_is_served(tmp_path: Path) -> None:
    extra = {
        "name": "kiosk",
        "objects": [{"class": "door", "x": 0, "y": 0}, {"class": "sign", "x": 2, "y": 1}],
    }
    (tmp_path / "kiosk.json").write_text(json.dumps(extra))
    with TestClient(create_app(make_settings(maps=[tmp_path]))) as c:
        names = [m["name"] for m in c.get("/maps").json()]
        assert "kiosk" in names and "paper_office" in names


def test_metrics_count_frames_and_sessions(client: TestClient, session_id: str) -> None:
    client.post(f"/sessions/{session_id}/frames", json={"detections": []})
    text = client.get("/metrics").text
    assert "bearings_frames_total 1.0" in text
    assert "bearings_active_sessions 1.0" in text
    assert "bearings_step_seconds_bucket" in text


def test_openapi_documents_units(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    det = spec["components"]["schemas"]["DetectionIn"]["properties"]["bearing_deg"]
    assert "counter-clockwise" in det["description"]
    assert client.get("/docs").status_code == 200


def test_demo_page_is_served(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and 'aria-live="polite"' in r.text
