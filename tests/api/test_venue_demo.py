"""The demo on a venue: the bundled three-floor map, simulated walks with a ride."""

from __future__ import annotations

import json

import numpy as np
from fastapi.testclient import TestClient

from app.maps.model import parse_map
from app.maps.prepare import ensure_prepared
from app.resources import bundled_maps_dir
from app.simulation.venue import VENUE_NAME, venue_spec
from app.simulation.venue_demo import demo_legs
from app.simulation.venue_walk import Ride, Walk


def test_the_bundled_venue_is_the_one_the_suite_walks() -> None:
    on_disk = json.loads((bundled_maps_dir() / f"{VENUE_NAME}.json").read_text())
    assert on_disk == json.loads(json.dumps(venue_spec()))


def test_simulated_venue_frames_carry_the_barometer_and_a_session_follows_them(
    client: TestClient,
) -> None:
    r = client.post("/simulations", json={"map": VENUE_NAME, "seed": 3})
    assert r.status_code == 200, r.text
    frames = r.json()["frames"]
    assert all("altitude" in f and "truth" not in f for f in frames)
    heights = [f["altitude"]["relative_m"] for f in frames]
    assert max(heights) - min(heights) > 8.0  # the lift rises two floors
    sid = client.post("/sessions", json={"map": VENUE_NAME, "particles": 3000, "seed": 3}).json()[
        "id"
    ]
    levels = set()
    for f in frames[:800]:
        res = client.post(f"/sessions/{sid}/frames", json=f).json()
        if res["converged"]:
            levels.add(res["pose"]["level"]["id"])
    assert {"L0", "L2"} <= levels


def test_a_venue_without_a_known_walk_gets_one_planned_through_a_connector() -> None:
    spec = venue_spec("another_venue")
    m = ensure_prepared(parse_map(spec))
    start, legs = demo_legs(m, np.random.default_rng(0))
    assert start == "L0"
    first, ride, last = legs
    assert isinstance(first, Walk) and isinstance(ride, Ride) and isinstance(last, Walk)
    assert ride.kind == "elevator" and ride.to_level == "L1"
    # The walk ends in the lift car (file frame) and the next one starts there.
    assert 0.4 < first.points[-1][0] < 2.6 and 0.4 < first.points[-1][1] < 2.6
    assert all(0.0 < x < 24.0 and 0.0 < y < 14.0 for x, y in last.points)
