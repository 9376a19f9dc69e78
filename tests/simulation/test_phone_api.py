"""A simulated phone's frames, as JSON, are frames the real service takes (uvicorn)."""

from __future__ import annotations

import httpx
import numpy as np

from app.api.schemas import Frame
from app.experiments.phone import pinhole_camera
from app.main import create_app
from app.simulation.phone import simulate_phone, vio_phone
from app.simulation.simulator import SimulationConfig
from tests.helpers import free_port, make_settings, paper_office, serving


def test_phone_frames_with_pixel_boxes_go_through_the_api() -> None:
    camera = pinhole_camera()
    walk = SimulationConfig(
        path=((1.5, 1.2), (8.5, 1.2), (8.5, 5.8)), camera=camera, duration_s=8.0
    )
    frames = simulate_phone(paper_office(), walk, vio_phone(), np.random.default_rng(4))
    assert any(f.dropped_before for f in frames)  # the walk has dropped frames in it
    ages_known = "detections_age_s" in Frame.model_fields
    port = free_port()
    with (
        serving(create_app(make_settings(port=port)), port) as url,
        httpx.Client(base_url=f"http://{url}", timeout=30.0) as client,
    ):
        created = client.post(
            "/sessions",
            json={
                "map": "paper_office", "particles": 1000, "seed": 1,
                "camera": {
                    "model": "pinhole", "width_px": int(camera.width_px),
                    "fx_px": camera.fx_px, "cx_px": camera.cx_px,
                },
            },
        )  # fmt: skip
        assert created.status_code == 201, created.text
        sid = created.json()["id"]
        boxes = 0
        for i, f in enumerate(frames, start=1):
            body = f.to_contract(camera)
            assert body.get("detections_age_s") == f.detections_age_s
            if not ages_known:  # a service before issue 27 refuses the extra key
                body.pop("detections_age_s", None)
            boxes += sum("box" in d for d in body["detections"])  # type: ignore[union-attr]
            answer = client.post(f"/sessions/{sid}/frames", json=body)
            assert answer.status_code == 200, answer.text
            assert answer.json()["seq"] == i
    assert boxes > len(frames)  # the pinhole saw objects, as pixel boxes
