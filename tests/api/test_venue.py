"""A venue of three floors through the real service: maps, levels in results, a lift ride."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np

from app.main import create_app
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import VENUE_NAME, venue_legs, venue_map, venue_spec
from app.simulation.venue_walk import simulate_venue
from tests.helpers import free_port, make_settings, serving, venue_frame_json


def test_a_venue_is_served_and_a_lift_ride_is_followed_to_the_second_floor(
    tmp_path: Path,
) -> None:
    (tmp_path / f"{VENUE_NAME}.json").write_text(json.dumps(venue_spec()))
    app = create_app(make_settings(maps=[tmp_path], max_particles=10_000))
    with serving(app, free_port()) as host, httpx.Client(base_url=f"http://{host}") as http:
        listed = {m["name"]: m for m in http.get("/maps").json()}
        venue = listed[VENUE_NAME]
        assert [lv["id"] for lv in venue["levels"]] == ["L0", "L1", "L2"]
        assert venue["levels"][1] == {
            "id": "L1",
            "name": "First Floor",
            "ordinal": 1,
            "elevation_m": 4.5,
        }
        assert [c["kind"] for c in venue["connectors"]] == [
            "elevator",
            "stairs",
            "escalator",
            "escalator",
        ]
        assert venue["bounds"] == {"min_x": 0.0, "min_y": 0.0, "max_x": 24.0, "max_y": 14.0}
        assert listed["paper_office"]["levels"] == [] and listed["paper_office"]["connectors"] == []
        raw = http.get(f"/maps/{VENUE_NAME}").json()
        assert raw["levels"][0]["id"] == "L0" and raw["walls"][0]["level"] == "L0"

        # Refused: a level the map lacks, a level on a map without levels, a pose in a
        # wall of its level, an altitude that is no number.
        pose = {"x": 1.5, "y": 5.0, "theta_deg": 90}
        for body, words in (
            ({"map": VENUE_NAME, "initial_pose": {**pose, "level": "L9"}}, "'L9' is not a level"),
            ({"map": "paper_office", "initial_pose": {**pose, "level": "L0"}}, "has no levels"),
            (
                {
                    "map": VENUE_NAME,
                    "initial_pose": {"x": 3.0, "y": 1.0, "theta_deg": 0, "level": "L1"},
                },
                "not in the free space of map 'three_floor_venue' on level 'L1'",
            ),
        ):
            r = http.post("/sessions", json=body)
            assert r.status_code == 422 and words in r.json()["message"], r.text

        sid = http.post("/sessions", json={"map": VENUE_NAME, "particles": 8000, "seed": 4}).json()[
            "id"
        ]
        r = http.post(
            f"/sessions/{sid}/frames", json={"altitude": {"relative_m": "12"}, "detections": []}
        )
        assert r.status_code == 422

        m = venue_map()
        start, legs = venue_legs()
        cfg = SimulationConfig(path=((0.0, 0.0),), miss_prob=0.1)
        frames = simulate_venue(m, start, legs[:3], cfg, np.random.default_rng(4))
        said: list[str] = []
        results = []
        for vf in frames:
            res = http.post(f"/sessions/{sid}/frames", json=venue_frame_json(vf)).json()
            results.append((vf, res))
            said.append(res["feedback"]["text"])
        located = [(vf, res) for vf, res in results if res["converged"]]
        assert located
        for vf, res in located:
            assert res["pose"]["level"]["id"] == m.layout.levels[vf.level].id
            # Positions are in the file's frame, whatever the level.
            assert abs(res["pose"]["x"] - vf.file_pose.x) < 1.0
            assert abs(res["pose"]["y"] - vf.file_pose.y) < 1.0
            assert res["uncertainty"]["level_probability"] > 0.9
            assert res["hypotheses"][0]["level"]["id"] == res["pose"]["level"]["id"]
        last = results[-1][1]
        assert last["converged"] and last["pose"]["level"]["name"] == "Second Floor"
        text = " ".join(said)
        assert "You are on the Ground Floor." in text
        assert "You are on the Second Floor." in text
        assert "You are on the First Floor" not in text  # the lift passed it, never located there
        assert text.index("Ground Floor") < text.index("Second Floor")
