"""End to end over a real server and a real WebSocket: a phone client streams pixel
boxes from a 360-degree camera, odometry and a compass heading, walks wherever the
guidance says, and is led around a wall to a door it could not walk to straight."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator

import httpx
import numpy as np
import pytest
from websockets.sync.client import connect

from app.guidance import ARRIVED_M
from app.localization.camera import Camera
from app.localization.types import Pose
from app.main import create_app
from app.maps.check import load_map
from app.maps.geometry import segments_cross_walls, wrap_angle
from app.resources import bundled_maps_dir
from app.simulation.camera import CameraModel, visible_objects
from tests.helpers import free_port, make_settings, serving

SUITE = load_map(bundled_maps_dir() / "office_suite.json")
CAMERA = Camera("equirectangular", 3840, yaw_offset_deg=0.0)
START = (3.0, 8.0, 0.0)  # in Office 1, facing east
STEP_M = 0.1  # 0.5 m/s at 5 frames/s
MAX_TURN = math.radians(45.0)  # per frame


@pytest.fixture(scope="module")
def server_url() -> Iterator[str]:
    port = free_port()
    with serving(create_app(make_settings(port=port)), port) as url:
        yield url


def _frame(pose: Pose, odo: tuple[float, float, float] | None, t: float, rng) -> dict:
    """What the phone sends: boxes of what its camera sees, odometry, compass."""
    idx, bearing = visible_objects(SUITE, pose, CameraModel(360.0, 15.0))
    dets = []
    for j, b in zip(idx, bearing, strict=True):
        noisy = math.degrees(b) + rng.normal(0.0, 2.0)
        dist = float(np.hypot(*(SUITE.object_xy[j] - (pose.x, pose.y))))
        box = CAMERA.box_of(noisy, math.degrees(2 * math.atan2(0.45, max(dist, 0.3))))
        assert box is not None
        dets.append(
            {"class": SUITE.class_of(int(j)), "box": {"u_min_px": box[0], "u_max_px": box[1]}}
        )
    frame: dict = {
        "timestamp": round(t, 3),
        "detections": dets,
        "heading": {
            "heading_deg": math.degrees(pose.theta_rad) + rng.normal(0.0, 10.0),
            "std_deg": 15.0,
        },
    }
    if odo is not None:
        frame["odometry"] = {
            "forward_m": odo[0] + rng.normal(0.0, 0.01),
            "left_m": odo[1],
            "turn_deg": math.degrees(odo[2]) + rng.normal(0.0, 0.5),
        }
    return frame


def test_guided_around_a_wall_to_the_main_entrance(server_url: str) -> None:
    rng = np.random.default_rng(5)
    http = httpx.Client(base_url=f"http://{server_url}", timeout=60.0)  # slow when loaded
    x, y, th = START
    r = http.post(
        "/sessions",
        json={
            "map": "office_suite",
            "particles": 2000,
            "seed": 2,
            "camera": {"model": "equirectangular", "width_px": 3840},
            "initial_pose": {"x": x, "y": y, "theta_deg": 0.0, "std_xy_m": 0.5},
        },
    )
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    r = http.put(f"/sessions/{sid}/destination", json={"label": "main entrance"})
    assert r.status_code == 200, r.text
    door = np.array(r.json()["points"][0])
    # The straight line is walled off: the corridor wall is between.
    assert segments_cross_walls([[x, y]], [door], SUITE.walls)[0]

    trail = [(x, y)]
    spoken: list[str] = []
    odo = None
    arrived = None
    with connect(f"ws://{server_url}/sessions/{sid}/stream") as ws:
        for i in range(400):
            ws.send(json.dumps(_frame(Pose(x, y, th), odo, 0.2 * i, rng)))
            res = json.loads(ws.recv())
            assert "error" not in res, res
            spoken.append(res["feedback"]["text"])
            g = res["guidance"]
            if g is None:
                assert not res["converged"]
                odo = (0.0, 0.0, 0.0)  # stand and wait to be located
                continue
            if g["arrived"]:
                arrived = res
                break
            # Follow the directions: turn towards the next turn (or the target), walk.
            aim = (g["next"] or g)["bearing_deg"]
            turn = float(np.clip(math.radians(aim), -MAX_TURN, MAX_TURN))
            th = float(wrap_angle(th + turn))
            walk = STEP_M if abs(math.radians(aim) - turn) < math.radians(20) else 0.0
            nx, ny = x + walk * math.cos(th), y + walk * math.sin(th)
            # Every step taken on the guidance's word stays in the free space.
            assert SUITE.free_space.is_free(nx, ny), (i, (x, y), (nx, ny), g)
            assert not segments_cross_walls([[x, y]], [[nx, ny]], SUITE.walls)[0]
            x, y = nx, ny
            trail.append((x, y))
            odo = (walk, 0.0, turn)
    http.close()
    assert arrived is not None, f"never arrived; last at {(x, y)}, said {spoken[-5:]}"
    assert "You have arrived at main entrance." in arrived["feedback"]["text"]
    # Within 1 m of the door by the estimate; the estimate is within a few cm of truth.
    err = math.hypot(arrived["pose"]["x"] - x, arrived["pose"]["y"] - y)
    assert err < 0.3
    assert float(np.hypot(*(door - (x, y)))) <= ARRIVED_M + err
    # The walk went round: through the office door in the corridor wall (y = 3).
    path = np.array(trail)
    below = np.flatnonzero(path[:, 1] < 3.0)
    assert below.size and 2.5 < path[below[0], 0] < 3.5
    text = " ".join(spoken)
    assert "Main entrance: go to" in text and ", then to" in text
