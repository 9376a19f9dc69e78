"""Additions for the demo page: simulated frames to stream, and where the view lives."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Request
from pydantic import Field, StrictBool

from app.api.convert import camera_of
from app.api.deps import ManagerDep
from app.api.errors import error_responses
from app.api.schemas import CameraIn
from app.maps.model import SemanticMap
from app.service.errors import UnknownMap
from app.simulation.simulator import SimulationConfig, simulate
from app.simulation.venue_demo import demo_legs
from app.simulation.venue_walk import simulate_venue
from app.simulation.walks import demo_config
from app.validation import Finite, Integer, StrictInput

router = APIRouter(tags=["demo"])


class SimulationRequest(StrictInput):
    map: str = Field("paper_office", description="map to walk on")
    fov_deg: Finite = Field(360.0, gt=0, le=360, description="camera field of view, degrees")
    occlusion: StrictBool = Field(False, description="face a corner with the front 180 deg blocked")
    missing: StrictBool = Field(False, description="each frame loses a random share of detections")
    false_rate: Finite = Field(0.0, ge=0, le=5, description="false detections per frame (mean)")
    bearing_noise_deg: Finite = Field(2.0, ge=0, le=45, description="bearing noise std, degrees")
    seed: Integer = Field(0, ge=0, le=2**32 - 1, description="random seed")
    camera: CameraIn | None = Field(
        None, description="give detections as this camera's pixel boxes (its field of view)"
    )
    compass_std_deg: (
        Annotated[float, Field(gt=0, le=90, allow_inf_nan=False, strict=True)] | None
    ) = Field(None, description="give each frame a compass heading with this noise")


@router.post(
    "/simulations",
    summary="Simulated frames of a looping walk (with ground truth)",
    responses=error_responses(400, 404, 413, 422),
)
async def simulations(body: SimulationRequest, manager: ManagerDep) -> dict[str, object]:
    """Frames in the ``Frame`` format (plus ``truth``) for a client to stream to a session;
    on a map with levels, a walk with a ride between levels, with ``altitude`` (and
    without ``truth``)."""
    if body.map not in manager.maps:
        raise UnknownMap(body.map, sorted(manager.maps))
    semantic_map = manager.maps[body.map]

    def make() -> list[dict[str, object]]:
        rng = np.random.default_rng(body.seed)
        if semantic_map.layout.has_levels:
            return venue_frames(semantic_map, body, rng)
        cfg = demo_config(
            semantic_map,
            rng,
            fov_deg=body.fov_deg,
            occlusion=body.occlusion,
            missing=body.missing,
            false_rate=body.false_rate,
            bearing_noise_deg=body.bearing_noise_deg,
        )
        camera = camera_of(body.camera)
        cfg = replace(cfg, camera=camera, compass_std_deg=body.compass_std_deg)
        return [f.to_contract(camera) for f in simulate(semantic_map, cfg, rng)]

    frames = await asyncio.to_thread(make)
    return {"map": body.map, "rate_hz": 5.0, "frames": frames}


def venue_frames(
    semantic_map: SemanticMap, body: SimulationRequest, rng: np.random.Generator
) -> list[dict[str, object]]:
    """A walk through a venue with a ride between levels (app.simulation.venue_demo),
    its frames carrying the barometer's altitude. Without ``truth``: the simulator's
    truth is in the filter's plane, not the file's frame."""
    start, legs = demo_legs(semantic_map, rng)
    cfg = SimulationConfig(
        path=((0.0, 0.0),),
        fov_deg=body.fov_deg,
        random_loss=body.missing,
        false_rate=body.false_rate,
        bearing_noise_deg=body.bearing_noise_deg,
    )
    camera = camera_of(body.camera)
    out = []
    for vf in simulate_venue(semantic_map, start, legs, cfg, rng):
        frame = vf.frame.to_contract(camera)
        del frame["truth"]
        if vf.altitude is not None:
            frame["altitude"] = {
                "relative_m": round(vf.altitude.relative_m, 3),
                "std_m": vf.altitude.std_m,
            }
        out.append(frame)
    return out


@router.get("/view", summary="Where the live viser view is served")
async def view(request: Request) -> dict[str, object]:
    settings = request.app.state.settings
    live = request.app.state.view
    port = live.port if live is not None else settings.viser_port
    return {"enabled": live is not None, "port": port}
