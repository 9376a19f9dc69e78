"""Simulated walks streamed into live sessions, for `bearings demo` and the view's controls.

A :class:`DemoWalk` creates a session and feeds it frames from the simulator in real
time (5 frames/s), looping its path for ever, exactly as a phone app would through
the public API. "Kidnap" carries the simulated person to a random place without
telling the filter.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from app.localization.compass import CompassReading
from app.localization.floors import AltitudeReading
from app.localization.types import Odometry
from app.maps.geometry import wrap_angle
from app.service.errors import LimitReached, SessionNotFound
from app.service.sessions import SessionManager
from app.service.types import FrameInput, SensorSpec, SessionSpec
from app.simulation.simulator import SimFrame, SimulationConfig, simulate
from app.simulation.venue_demo import demo_legs
from app.simulation.venue_walk import simulate_venue
from app.simulation.walks import demo_config

log = logging.getLogger("bearings.demo")


@dataclass(frozen=True)
class DemoSettings:
    map_name: str = "paper_office"
    fov_deg: float = 360.0
    occlusion: bool = False
    missing: bool = False
    particles: int = 10_000
    seed: int = 0
    speed: float = 1.0  # playback speed; 1.0 is real time
    share_view: bool = False  # list the walk's session in the live view
    max_duration_s: float | None = None  # end the walk (and its session) after this long


def frame_input_of(frame: SimFrame, altitude: AltitudeReading | None = None) -> FrameInput:
    """A simulated frame as the service takes it (the ground truth rides along for the
    view), with a venue walk's barometer reading."""
    return FrameInput(
        altitude=altitude,
        timestamp=frame.t,
        odometry=frame.odometry,
        detections=tuple(frame.detections),
        truth=frame.truth,
        heading=None
        if frame.compass_rad is None
        else CompassReading(frame.compass_rad, math.radians(frame.compass_std_deg or 20.0)),
    )


def new_walk(manager: SessionManager, **settings: Any) -> DemoWalk:
    """A walk with the given :class:`DemoSettings` fields, started on the running loop.

    What the live view's demo button calls (as ``functools.partial(new_walk, manager)``).
    """
    walk = DemoWalk(manager, DemoSettings(**settings))
    walk.start()
    return walk


class DemoWalk:
    """One simulated person walking in a loop, streaming into one session."""

    def __init__(self, manager: SessionManager, settings: DemoSettings) -> None:
        self.manager = manager
        self.settings = settings
        self.session_id: str | None = None
        self._kidnap = False
        self._rng = np.random.default_rng(settings.seed)
        self._task: asyncio.Task[None] | None = None
        self.finished = False
        #: A venue walk's barometer readings, frame by frame (empty on one level).
        self._altitudes: list[AltitudeReading | None] = []

    def kidnap(self) -> None:
        """Carry the person elsewhere at the next frame (no odometry for that frame)."""
        self._kidnap = True

    def start(self) -> asyncio.Task[None]:
        self._task = asyncio.get_running_loop().create_task(self.run())
        return self._task

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self.session_id is not None:
            with contextlib.suppress(SessionNotFound):
                await self.manager.delete(self.session_id)

    def _frames(self) -> list[SimFrame]:
        s = self.settings
        semantic_map = self.manager.maps[s.map_name]
        if semantic_map.layout.has_levels:  # a walk with a ride (app.simulation.venue_demo)
            start, legs = demo_legs(semantic_map, self._rng)
            cfg = SimulationConfig(path=((0.0, 0.0),), fov_deg=s.fov_deg, random_loss=s.missing)
            walk = simulate_venue(semantic_map, start, legs, cfg, self._rng)
            self._altitudes = [vf.altitude for vf in walk]
            return [vf.frame for vf in walk]
        self._altitudes = []
        cfg = demo_config(
            semantic_map, self._rng, fov_deg=s.fov_deg, occlusion=s.occlusion, missing=s.missing
        )
        return simulate(semantic_map, cfg, self._rng)

    def _kidnapped_frames(self) -> list[SimFrame]:
        frames = self._frames()
        start = int(self._rng.integers(len(frames) // 3, len(frames)))
        rest = frames[start:]
        self._altitudes = self._altitudes[start:]
        return [replace(rest[0], odometry=None), *rest[1:]]

    async def run(self) -> None:
        s = self.settings
        session = await self.manager.create(
            SessionSpec(
                map_name=s.map_name,
                particles=s.particles,
                seed=s.seed,
                sensor=SensorSpec(fov_deg=s.fov_deg),
                share_view=s.share_view,
            )
        )
        self.session_id = session.id
        try:
            if s.max_duration_s is None:
                await self._walk(session.id)
            else:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._walk(session.id), s.max_duration_s)
                log.info("demo walk reached its time limit and ends")
                with contextlib.suppress(SessionNotFound):
                    await self.manager.delete(session.id)
        finally:
            self.finished = True

    async def _walk(self, session_id: str) -> None:
        s = self.settings
        period = 1.0 / 5.0 / max(s.speed, 1e-3)
        frames = self._frames()
        i = 0
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            if self._kidnap:
                self._kidnap = False
                frames, i = self._kidnapped_frames(), 0
            if i >= len(frames):  # the loop closes where it began: carry on from there
                last = frames[-1].truth
                frames, i = self._frames(), 0
                turn = float(wrap_angle(frames[0].truth.theta_rad - last.theta_rad))
                frames[0] = replace(frames[0], odometry=Odometry(0.0, 0.0, turn))
            try:
                altitude = self._altitudes[i] if i < len(self._altitudes) else None
                await self.manager.process(session_id, frame_input_of(frames[i], altitude))
            except (SessionNotFound, LimitReached):
                log.info("demo session ended (or the service is restarting); demo walk stops")
                return
            i += 1
            next_at += period
            await asyncio.sleep(max(0.0, next_at - loop.time()))


async def run_demo_walk(manager: SessionManager, **settings: Any) -> None:
    """The walk `bearings demo` starts: the paper office, 360 degree camera, real time."""
    walk = DemoWalk(manager, DemoSettings(**settings))
    await walk.run()
