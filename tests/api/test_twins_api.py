"""A map that a half turn carries onto itself, through the real service: the person's
place and its twin are both listed, nothing is told, and the feedback says a compass
heading is what would tell them apart instead of suggesting a turn or a walk."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import httpx
import numpy as np

from app.experiments.hard_maps import hard_map
from app.experiments.integrity import Scenario
from app.main import create_app
from app.simulation.simulator import simulate
from tests.helpers import free_port, make_settings, serving


def test_twin_places_are_listed_and_the_feedback_asks_for_a_compass(tmp_path: Path) -> None:
    room = hard_map("symmetric_room").map
    (tmp_path / "turned_room.json").write_text(
        json.dumps({**room.to_json(), "name": "turned_room"})
    )
    world = np.random.default_rng(5)
    frames = simulate(room, Scenario("symmetric_room", "nominal-360").simulation(), world)[:80]
    app = create_app(make_settings(maps=[tmp_path], max_particles=5000))
    with serving(app, free_port()) as host, httpx.Client(base_url=f"http://{host}") as http:
        sid = http.post("/sessions", json={"map": "turned_room", "seed": 2}).json()["id"]
        results = []
        for f in frames:
            body = f.to_contract()
            body.pop("truth")
            r = http.post(f"/sessions/{sid}/frames", json=body)
            assert r.status_code == 200, r.text
            results.append(r.json())
    assert not any(res["converged"] for res in results)
    last = results[-1]
    assert last["feedback"]["suggestion"] is None
    said = [k for k, res in enumerate(results) if "compass" in res["feedback"]["text"]]
    assert said and all(b - a >= 50 for a, b in itertools.pairwise(said))  # 10 s at 5 frames/s
    assert not any("Turn slowly" in res["feedback"]["text"] for res in results[said[0] :])
    truth = frames[-1].truth
    twin = (12.0 - truth.x, 8.0 - truth.y)  # turned half round about (6, 4)
    top = last["hypotheses"][:2]
    assert abs(top[0]["weight"] - top[1]["weight"]) < 1e-6
    for x, y in ((truth.x, truth.y), twin):
        assert min(np.hypot(h["x"] - x, h["y"] - y) for h in top) < 0.5
