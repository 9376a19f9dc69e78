"""The WebSocket stream through the TestClient: order, errors, the connection survives."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect


def frame(i: int) -> str:
    return json.dumps({"timestamp": i * 0.2, "detections": [{"class": "door", "bearing_deg": 10}]})


def test_one_result_per_frame_in_order(client: TestClient, session_id: str) -> None:
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        seqs = []
        for i in range(5):
            ws.send_text(frame(i))
            seqs.append(json.loads(ws.receive_text())["seq"])
    assert seqs == [1, 2, 3, 4, 5]


def test_a_burst_gets_one_answer_per_frame_merged_ones_say_so(
    client: TestClient, session_id: str
) -> None:
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        for i in range(20):
            ws.send_text(frame(i))
        answers = [json.loads(ws.receive_text()) for _ in range(20)]
    seqs = [a["seq"] for a in answers]
    assert seqs == sorted(seqs) and seqs[0] == 1
    for a in answers:  # a step that stands for several frames says how many
        n = seqs.count(a["seq"])
        assert (n > 1) == any(f"{n} frames arrived" in w for w in a["warnings"])


@pytest.mark.parametrize(
    ("message", "code"),
    [
        ("{not json", "invalid_json"),
        (
            json.dumps({"detections": [{"class": "door", "bearing_deg": 1, "score": 3}]}),
            "invalid_frame",
        ),
        (json.dumps({"detections": [{"class": "door", "bearing_deg": "north"}]}), "invalid_frame"),
        (json.dumps([1, 2, 3]), "invalid_frame"),
        (
            json.dumps({"detections": [{"class": "door", "bearing_deg": i} for i in range(30)]}),
            "too_many_detections",
        ),
        ("x" * 9000, "message_too_large"),
    ],
)
def test_bad_message_gets_error_and_connection_stays_open(
    client: TestClient, session_id: str, message: str, code: str
) -> None:
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        ws.send_text(message)
        err = json.loads(ws.receive_text())
        assert err["error"]["code"] == code and err["error"]["message"]
        ws.send_text(json.dumps({"detections": []}))
        assert json.loads(ws.receive_text())["seq"] == 1  # nothing accepted was lost


def test_unknown_session_is_closed_with_reason(client: TestClient) -> None:
    with (
        client.websocket_connect("/sessions/nope/stream") as ws,
        pytest.raises(WebSocketDisconnect) as info,
    ):
        ws.receive_text()
    assert info.value.code == 1008
    assert "no session" in info.value.reason


def test_disconnect_does_not_end_the_session(client: TestClient, session_id: str) -> None:
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        ws.send_text(json.dumps({}))
        ws.receive_text()
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        ws.send_text(json.dumps({}))
        assert json.loads(ws.receive_text())["seq"] == 2
    assert client.get(f"/sessions/{session_id}").json()["frames"] == 2


def test_rest_and_websocket_share_one_order(client: TestClient, session_id: str) -> None:
    client.post(f"/sessions/{session_id}/frames", json={})
    with client.websocket_connect(f"/sessions/{session_id}/stream") as ws:
        ws.send_text("{}")
        assert json.loads(ws.receive_text())["seq"] == 2
