"""Guidance across levels end to end, over a real server: a person on the ground floor
of Riverside Station (the bundled venue) is guided to the Bakery on the first floor,
walks to the up escalator as told, hears "Take the escalator up to the First Floor.",
rides it (the barometer rising with the ride), hears "You are on the First Floor." once
the service confirms the level, and is guided on to the Bakery; step-free, the way goes
by the lift, which the person rides likewise to the first floor's cash machine.

The simulated person's true pose is in the map's plane (app.maps.levels: the first
floor lies one level pitch east of the ground floor), where the map's arrays are; what
goes over the wire (the initial pose, the estimate) is in the file's frame with a
level. The phone's barometer reads the person's altitude (plus noise): the level's
elevation while walking, rising through a ride; the camera sees the level whose
elevation is nearest that altitude, as in app.simulation.venue_walk.
"""

from __future__ import annotations

import itertools
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
FRAME_S = 0.2
#: An escalator carries the person at this speed (m/s); a lift climbs at this rate
#: (m/s) between door waits of this long (s).
ESCALATOR_MPS = 0.5
LIFT_CLIMB_MPS = 1.0
LIFT_DOORS_S = 3.0
#: The level is to be confirmed within this long after leaving a ride (issue 28), s.
CONFIRM_S = 5.0


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


def _walk(http, sid, pose, rng, t0, stop_when, frames=400, odo=None):
    """Follow the guidance until ``stop_when(result)``; the results and the last pose.
    ``odo``: the first frame's odometry (None: a session's first frame)."""
    x, y, th = pose
    results = []
    for i in range(frames):
        frame = _frame(Pose(x, y, th), odo, t0 + FRAME_S * i, rng)
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


def _ride_track(
    start: tuple[float, float, float], a0: float, a1: float, path, lift: bool
) -> list[tuple[float, float, float, float]]:
    """(x, y, theta, altitude) per frame of a ride from ``start`` (file frame), the
    altitude going from ``a0`` to ``a1``. An escalator or stairs: along ``path`` at
    ``ESCALATOR_MPS``, the altitude rising with the distance covered. A lift: into the
    car along ``path`` at walking pace, the doors, the climb, the doors."""
    x, y, th = start
    track = [(x, y, th, a0)]
    legs = list(zip([(x, y), *path[:-1]], path, strict=True))
    length = sum(math.dist(a, b) for a, b in legs)
    done = 0.0
    step = STEP_M if lift else ESCALATOR_MPS * FRAME_S
    for (ax, ay), (bx, by) in legs:
        th = math.atan2(by - ay, bx - ax)
        n = max(1, math.ceil(math.dist((ax, ay), (bx, by)) / step))
        for k in range(1, n + 1):
            x, y = ax + (bx - ax) * k / n, ay + (by - ay) * k / n
            share = (done + math.dist((ax, ay), (x, y))) / length
            track.append((x, y, th, a0 if lift else a0 + (a1 - a0) * share))
        done += math.dist((ax, ay), (bx, by))
    if lift:
        doors = [(x, y, th, a0)] * round(LIFT_DOORS_S / FRAME_S)
        climb = math.ceil(abs(a1 - a0) / (LIFT_CLIMB_MPS * FRAME_S))
        rising = [(x, y, th, a0 + (a1 - a0) * k / climb) for k in range(1, climb + 1)]
        track += doors + rising + [(x, y, th, a1)] * round(LIFT_DOORS_S / FRAME_S)
    return track


def _ride(http, sid, pose, to_level, path, rng, t0, lift=False):
    """Take a connector from the level of plane pose ``pose`` to ``to_level`` (an index)
    by the track of :func:`_ride_track` (``path`` in the file's frame); odometry as the
    phone's tracking measures it, the barometer the altitude, the camera the level
    nearest it. The results, the plane pose at the end and the next frame's time."""
    level = int(LAYOUT.level_of_plane_x(pose[0]))
    elevation = np.array([lv.elevation_m for lv in LAYOUT.levels])
    start = (pose[0] - float(LAYOUT.offsets(level)), pose[1], pose[2])
    track = _ride_track(start, elevation[level], elevation[to_level], path, lift)
    results = []
    t = t0
    for (px, py, pth, _), (x, y, th, alt) in itertools.pairwise(track):
        on = int(np.argmin(np.abs(elevation - alt)))
        plane = Pose(x + float(LAYOUT.offsets(on)), y, th)
        odo = (math.dist((px, py), (x, y)), float(wrap_angle(th - pth)))
        r = http.post(f"/sessions/{sid}/frames", json=_frame(plane, odo, t, rng, alt))
        assert r.status_code == 200, r.text
        res = r.json()
        res["_altitude_m"] = alt  # the truth, for the test's eyes only
        results.append(res)
        t += FRAME_S
    x, y, th, _ = track[-1]
    return results, (x + float(LAYOUT.offsets(to_level)), y, th), t


def _located_between_floors(res: dict) -> bool:
    """Whether a ride's frame said "located" while the person was plainly between floors:
    more than 1.5 m (of a 4 m pitch) from every level's elevation. Near a floor a
    barometer reading 0.2 m of noise cannot yet tell a ride from a step: smoothed over
    five readings, a ride shows once it has risen a metre or so (measured: 1.3 m into an
    escalator climbing 0.57 m a second, 0.8 m into a lift's climb)."""
    gap = min(abs(res["_altitude_m"] - lv.elevation_m) for lv in LAYOUT.levels)
    return bool(res["converged"]) and gap > 1.5


def _level_confirmed_s(ride: list[dict], after: list[dict], level_id: str) -> float:
    """Seconds from the ride's last frame to the first frame that says the person is on
    ``level_id`` ("You are on the First Floor.": 0 when a frame of the ride said it). It
    comes no later than the first frame converged there (the barometer's count of
    storeys may confirm the floor before the place on it is found), and no frame of the
    ride or after names another floor."""
    frames = [*ride, *after]
    names = {lv.id: lv.name for lv in LAYOUT.levels}
    said = [
        (i, lid)
        for i, res in enumerate(frames)
        for lid, name in names.items()
        if f"You are on the {name}." in res["feedback"]["text"]
    ]
    assert all(lid == level_id for _, lid in said), said
    fixed = [
        i
        for i, res in enumerate(frames)
        if res["converged"] and res["pose"]["level"]["id"] == level_id
    ]
    if not said:
        raise AssertionError(f"{level_id} was never confirmed")
    assert not fixed or said[0][0] <= fixed[0]
    return max(0.0, (said[0][0] - (len(ride) - 1)) * FRAME_S)


def _arrived(res: dict) -> bool:
    return bool((res["guidance"] or {}).get("arrived"))


def test_guided_up_the_escalator_and_on_to_a_room_on_the_next_floor(server_url: str) -> None:
    rng = np.random.default_rng(3)
    http = httpx.Client(base_url=f"http://{server_url}", timeout=60.0)
    sid = _session(http, START, seed=4)
    r = http.put(f"/sessions/{sid}/destination", json={"region": "Bakery"})
    assert r.status_code == 200, r.text
    assert r.json()["target"] == "Bakery" and r.json()["levels"] == []

    def at_escalator(res: dict) -> bool:
        return "Take the escalator" in res["feedback"]["text"]

    results, pose = _walk(http, sid, START, rng, 0.0, at_escalator)
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
    assert math.hypot(*(np.array(pose[:2]) - stop.polygon.mean(axis=0))) < 1.5

    # The ride: in at the escalator's open (south) end, carried north, up to the first floor.
    t = FRAME_S * len(results)
    top = (float(stop.polygon[:, 0].mean()), float(stop.polygon[:, 1].max()) - 1.5)
    ride, pose, t = _ride(http, sid, pose, 1, [top], rng, t)
    assert not any(map(_located_between_floors, ride)), "located between floors"
    after, _ = _walk(http, sid, pose, rng, t, _arrived, odo=(0.0, 0.0))
    assert _level_confirmed_s(ride, after, "L1") <= CONFIRM_S
    guided = [res for res in after if res["guidance"]]
    assert guided and all(res["guidance"]["connector"] is None for res in guided)
    assert all(res["pose"]["level"]["id"] == "L1" for res in after if res["converged"])
    assert "You have arrived at Bakery." in after[-1]["feedback"]["text"]
    end = after[-1]["pose"]
    (bakery,) = [r for r in VENUE.spec.regions if r.name == "Bakery"]
    xs = [p[0] for p in bakery.polygon]
    assert min(xs) - 1.5 < end["x"] < max(xs)  # in the file's frame, not the plane's
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

    def at_lift(res: dict) -> bool:
        return "Take the elevator" in res["feedback"]["text"]

    results, pose = _walk(http, sid, START, rng, 0.0, at_lift)
    guided = [res["guidance"] for res in results if res["guidance"]]
    assert guided, "never located"
    for g in guided:  # never an escalator nor the stairs
        c = g["connector"]
        assert (c["kind"], c["label"], c["direction"], c["to_level"]["id"]) == (
            "elevator",
            "Lift",
            "up",
            "L1",
        )
    said = " ".join(res["feedback"]["text"] for res in results)
    assert "The elevator up to the First Floor: go to" in said
    assert results[-1]["guidance"]["connector"]["at_stop"]
    assert results[-1]["feedback"]["text"].endswith("Take the elevator up to the First Floor.")

    # The ride: into the car, the doors, up one floor, the doors.
    car = LAYOUT.connector("elevator-1").stop_on(0)
    assert car is not None
    t = FRAME_S * len(results)
    (cx, cy), door_y = car.polygon.mean(axis=0), float(car.polygon[:, 1].min())
    # Through the door (its gap on the car's south side, around x = 0.5) to the middle.
    into = [(0.5, door_y - 0.5), (float(cx), float(cy))] if pose[1] < door_y else []
    ride, pose, t = _ride(http, sid, pose, 1, into or [(float(cx), float(cy))], rng, t, lift=True)
    assert not any(map(_located_between_floors, ride)), "located between floors"
    after, _ = _walk(http, sid, pose, rng, t, _arrived, odo=(0.0, 0.0))
    assert _level_confirmed_s(ride, after, "L1") <= CONFIRM_S
    assert all(res["pose"]["level"]["id"] == "L1" for res in after if res["converged"])
    assert all(res["guidance"]["connector"] is None for res in after if res["guidance"])
    assert after[-1]["pose"]["x"] < -18.0  # the cash machine's end, in the file's frame
    # A point on a venue needs its level; an unknown level is named.
    r = http.put(f"/sessions/{sid}/destination", json={"x": 1.0, "y": 2.0})
    assert r.status_code == 422 and "needs the level" in r.json()["message"]
    r = http.put(f"/sessions/{sid}/destination", json={"region": "Bakery", "level": "L9"})
    assert r.status_code == 422 and "'L9' is not a level" in r.json()["message"]
    http.close()
