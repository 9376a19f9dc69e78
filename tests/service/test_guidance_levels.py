"""Guidance across levels end to end, over a real server: a person on the ground floor
of Riverside Station (the bundled venue) is guided to the Bakery on the first floor,
walks to the up escalator as told and hears "Take the escalator up to the First
Floor."; from the escalator's top the way leads on to the Bakery; step-free, the way
goes by the lift. (Confirming the level after a ride is the filter's, tested with it:
tests/localization/test_floors.py and the venue suite.)

The simulated person's true pose is in the map's plane (app.maps.levels: the first
floor lies one level pitch east of the ground floor), where the map's arrays are; what
goes over the wire (the initial pose, the estimate) is in the file's frame with a
level. The phone's barometer reads the level's elevation (plus noise): the filter
confirms a level from it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import httpx
import numpy as np
import pytest

from app.localization.types import Pose
from app.main import create_app
from app.maps.check import load_map
from app.maps.geometry import segments_cross_walls, wrap_angle
from app.resources import bundled_maps_dir
from app.simulation.camera import CameraModel, visible_objects
from tests.helpers import free_port, make_settings, serving

VENUE = load_map(bundled_maps_dir() / "riverside_station.json")
LAYOUT = VENUE.layout
START = (-14.0, -8.0, math.pi / 2)  # the entrance hall, facing north
STEP_M = 0.15
MAX_TURN = math.radians(45.0)


@pytest.fixture(scope="module")
def server_url() -> Iterator[str]:
    port = free_port()
    with serving(create_app(make_settings(port=port)), port) as url:
        yield url


def _frame(
    pose: Pose, odo: tuple[float, float] | None, t: float, rng, altitude_m: float | None = None
) -> dict:
    """Bearings of what a 360-degree camera sees from ``pose`` (in the plane), odometry,
    a compass and the barometer (the level's elevation unless ``altitude_m``)."""
    level = int(LAYOUT.level_of_plane_x(pose.x))
    if altitude_m is None:
        altitude_m = LAYOUT.levels[level].elevation_m
    idx, bearing = visible_objects(VENUE, pose, CameraModel(360.0, 15.0))
    frame: dict = {
        "timestamp": round(t, 3),
        "detections": [
            {"class": VENUE.class_of(int(j)), "bearing_deg": math.degrees(b) + rng.normal(0, 2)}
            for j, b in zip(idx, bearing, strict=True)
        ],
        "heading": {
            "heading_deg": math.degrees(pose.theta_rad) + rng.normal(0.0, 5.0),
            "std_deg": 10.0,
        },
        "altitude": {
            "relative_m": altitude_m + rng.normal(0.0, 0.2),
            "std_m": 0.3,
        },
    }
    if odo is not None:
        frame["odometry"] = {
            "forward_m": odo[0] + rng.normal(0.0, 0.01),
            "left_m": 0.0,
            "turn_deg": math.degrees(odo[1]) + rng.normal(0.0, 0.5),
        }
    return frame


def _session(http: httpx.Client, pose: tuple[float, float, float], seed: int) -> str:
    r = http.post(
        "/sessions",
        json={
            "map": "riverside_station",
            "particles": 2000,
            "seed": seed,
            "initial_pose": {
                "x": pose[0],  # the ground floor: its frame is the plane's
                "y": pose[1],
                "theta_deg": math.degrees(pose[2]),
                "std_xy_m": 0.5,
                "level": "L0",
            },
        },
    )
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _walk(http, sid, pose, rng, t0, stop_when, frames=400):
    """Follow the guidance until ``stop_when(result)``; the results and the last pose."""
    x, y, th = pose
    odo = None
    results = []
    for i in range(frames):
        frame = _frame(Pose(x, y, th), odo, t0 + 0.2 * i, rng)
        r = http.post(f"/sessions/{sid}/frames", json=frame)
        assert r.status_code == 200, r.text
        res = r.json()
        results.append(res)
        if stop_when(res):
            return results, (x, y, th)
        g = res["guidance"]
        if g is None:
            odo = (0.0, 0.0)
            continue
        if g["connector"] and g["connector"]["at_stop"]:
            odo = (0.0, 0.0)  # at the connector: wait to be told to take it
            continue
        aim = (g["next"] or g)["bearing_deg"]
        turn = float(np.clip(math.radians(aim), -MAX_TURN, MAX_TURN))
        th = float(wrap_angle(th + turn))
        walk = STEP_M if abs(math.radians(aim) - turn) < math.radians(20) else 0.0
        nx, ny = x + walk * math.cos(th), y + walk * math.sin(th)
        # The directions come from the estimate, not the truth: a step that would go
        # through a wall is not taken (the person bumps into it and stands).
        if segments_cross_walls([[x, y]], [[nx, ny]], VENUE.walls)[0]:
            walk, nx, ny = 0.0, x, y
        x, y = nx, ny
        odo = (walk, turn)
    raise AssertionError(f"never stopped; last {results[-1]['guidance']}, at {(x, y)}")


def test_guided_up_the_escalator_to_a_room_on_the_next_floor(server_url: str) -> None:
    rng = np.random.default_rng(3)
    http = httpx.Client(base_url=f"http://{server_url}", timeout=60.0)
    sid = _session(http, START, seed=4)
    r = http.put(f"/sessions/{sid}/destination", json={"region": "Bakery"})
    assert r.status_code == 200, r.text
    assert r.json()["target"] == "Bakery" and r.json()["levels"] == []

    def at_escalator(res: dict) -> bool:
        return "Take the escalator" in res["feedback"]["text"]

    results, (x, y, _) = _walk(http, sid, START, rng, 0.0, at_escalator)
    guided = [res["guidance"] for res in results if res["guidance"]]
    assert guided, "never located"
    for g in guided:  # all the way, the way leads up the escalator to the first floor
        c = g["connector"]
        assert c["kind"] == "escalator" and c["direction"] == "up" and not g["arrived"]
        assert c["to_level"] == {"id": "L1", "name": "First Floor", "ordinal": 1}
    said = " ".join(res["feedback"]["text"] for res in results)
    assert "The escalator up to the First Floor: go to" in said
    assert results[-1]["guidance"]["connector"]["at_stop"]
    assert results[-1]["feedback"]["text"].endswith("Take the escalator up to the First Floor.")
    up = LAYOUT.connector("escalator-1")
    stop = up.stop_on(0)
    assert stop is not None
    assert math.hypot(*(np.array([x, y]) - stop.polygon.mean(axis=0))) < 1.5

    http.close()


def test_off_the_escalator_on_to_the_room(server_url: str) -> None:
    """The second half: a session that starts at the escalator's top on the first floor
    (initial pose in that level's frame) is guided on to the Bakery, on that floor."""
    rng = np.random.default_rng(5)
    http = httpx.Client(base_url=f"http://{server_url}", timeout=60.0)
    up = LAYOUT.connector("escalator-1")
    stop = up.stop_on(1)
    assert stop is not None
    top = stop.polygon.mean(axis=0)  # the first floor's frame
    r = http.post(
        "/sessions",
        json={
            "map": "riverside_station",
            "particles": 2000,
            "seed": 6,
            "initial_pose": {
                "x": float(top[0]),
                "y": float(top[1]),
                "theta_deg": -90.0,
                "std_xy_m": 0.5,
                "level": "L1",
            },
        },
    )
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    assert http.put(f"/sessions/{sid}/destination", json={"region": "Bakery"}).status_code == 200
    start = LAYOUT.to_plane(top, 1)[0]  # where the simulated person stands, in the plane
    arrived, _ = _walk(
        http,
        sid,
        (start[0], start[1], -math.pi / 2),
        rng,
        0.0,
        lambda res: bool((res["guidance"] or {}).get("arrived")),
    )
    guided = [res for res in arrived if res["guidance"]]
    assert guided and all(res["guidance"]["connector"] is None for res in guided)
    assert all(res["pose"]["level"]["id"] == "L1" for res in guided)
    assert "You have arrived at Bakery." in arrived[-1]["feedback"]["text"]
    pose = arrived[-1]["pose"]
    (bakery,) = [r for r in VENUE.spec.regions if r.name == "Bakery"]
    xs = [p[0] for p in bakery.polygon]
    assert min(xs) - 1.5 < pose["x"] < max(xs)  # in the file's frame, not the plane's
    http.close()


def test_step_free_goes_by_the_lift(server_url: str) -> None:
    rng = np.random.default_rng(8)
    http = httpx.Client(base_url=f"http://{server_url}", timeout=60.0)
    sid = _session(http, START, seed=9)
    r = http.put(
        f"/sessions/{sid}/destination", json={"class": "atm", "level": "L1", "step_free": True}
    )
    assert r.status_code == 200, r.text
    body = r.json()
    # The first floor's cash machine, in the first floor's own frame (as in the file).
    assert body["levels"] == ["L1"] and body["step_free"] is True
    assert np.allclose(body["points"], [[-19.8, 0.0]], atol=0.1)
    results, _ = _walk(http, sid, START, rng, 0.0, lambda res: res["guidance"] is not None)
    c = results[-1]["guidance"]["connector"]
    assert (c["kind"], c["label"], c["direction"], c["to_level"]["id"]) == (
        "elevator",
        "Lift",
        "up",
        "L1",
    )
    assert "The elevator up to the First Floor: go to" in results[-1]["feedback"]["text"]
    # A point on a venue needs its level; an unknown level is named.
    r = http.put(f"/sessions/{sid}/destination", json={"x": 1.0, "y": 2.0})
    assert r.status_code == 422 and "needs the level" in r.json()["message"]
    r = http.put(f"/sessions/{sid}/destination", json={"region": "Bakery", "level": "L9"})
    assert r.status_code == 422 and "'L9' is not a level" in r.json()["message"]
    http.close()
