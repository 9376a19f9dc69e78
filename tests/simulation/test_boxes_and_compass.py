"""Simulated frames as a phone sends them: pixel boxes of a camera model, a compass."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from app.api.convert import frame_input
from app.api.schemas import Frame
from app.localization.camera import Camera
from app.maps.check import load_map
from app.maps.geometry import wrap_deg
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import CompassBias, simulate

OFFICE = load_map(bundled_maps_dir() / "paper_office.json")
CAMERAS = [
    Camera("equirectangular", 3840),
    Camera("equirectangular", 2000, yaw_offset_deg=120.0),
    Camera("pinhole", 1920, fx_px=1000.0, cx_px=900.0, yaw_offset_deg=-40.0),
]


@pytest.mark.parametrize("camera", CAMERAS, ids=lambda c: f"{c.model}-{c.yaw_offset_deg:g}")
def test_boxes_through_the_api_give_the_simulated_bearings(camera: Camera) -> None:
    cfg = replace(paper_config("nominal"), camera=camera, duration_s=6.0)
    frames = simulate(OFFICE, cfg, np.random.default_rng(4))
    half = camera.fov_deg / 2.0
    checked = 0
    for f in frames:
        wire = f.to_contract(camera)
        assert all("box" in d and "bearing_deg" not in d for d in wire["detections"])
        got = frame_input(Frame.model_validate(wire), camera).detections
        boxes = [b for b in f.boxes(camera) if b is not None]
        assert len(got) == len(boxes)
        sim = [d for d, b in zip(f.detections, f.boxes(camera), strict=True) if b is not None]
        for d_sim, d_api, box in zip(sim, got, boxes, strict=True):
            b = math.degrees(d_sim.bearing_rad)
            # Every detection lies in the camera's field of view.
            assert abs(wrap_deg(b - camera.fov_centre_deg)) <= half + 1e-6
            if camera.model == "pinhole" and (box[0] == 0.0 or box[1] == camera.width_px):
                continue  # cut at the image edge: its centre moved, as a detector's would
            # Columns are rounded to 0.1 pixel; at most 0.05 pixel off, in degrees:
            # (a pinhole column spans at most 1/fx radians, at the image centre).
            pinhole = camera.model == "pinhole"
            per_px = math.degrees(1.0 / camera.fx_px) if pinhole else 360.0 / camera.width_px
            assert abs(wrap_deg(math.degrees(d_api.bearing_rad) - b)) <= 0.05 * per_px + 1e-9
            checked += 1
    assert checked > 50


def test_a_pinhole_camera_sees_only_its_field() -> None:
    cam = Camera("pinhole", 1920, fx_px=1480.0, cx_px=960.0)  # about 66 degrees
    frames = simulate(
        OFFICE, replace(paper_config("nominal"), camera=cam), np.random.default_rng(1)
    )
    wide = simulate(OFFICE, paper_config("nominal"), np.random.default_rng(1))
    assert sum(len(f.detections) for f in frames) < 0.4 * sum(len(f.detections) for f in wide)


def test_the_compass_reads_the_heading_with_noise_and_bias() -> None:
    cfg = replace(
        paper_config("nominal"),
        compass_std_deg=5.0,
        compass_biases=(CompassBias(10.0, 20.0, 60.0),),
    )
    frames = simulate(OFFICE, cfg, np.random.default_rng(2))
    err = np.array([wrap_deg(math.degrees(f.compass_rad - f.truth.theta_rad)) for f in frames])
    t = np.array([f.t for f in frames])
    biased = (t >= 10.0) & (t < 20.0)
    assert abs(np.mean(err[~biased])) < 1.0 and 4.0 < np.std(err[~biased]) < 6.0
    assert np.mean(err[biased]) == pytest.approx(60.0, abs=2.0)
    wire = frames[0].to_contract()
    assert wire["heading"] == {
        "heading_deg": pytest.approx(math.degrees(frames[0].compass_rad), abs=1e-3),
        "std_deg": 5.0,
    }
    assert (
        "heading"
        not in simulate(OFFICE, paper_config("nominal"), np.random.default_rng(2))[0].to_contract()
    )
