"""Walks through a venue of several floors: lift, stairs and escalator rides, a barometer.

A walk is a list of legs. :class:`Walk` goes through waypoints on one level;
:class:`Ride` takes a connector to another level: through waypoints inside the
connector's stops (none for a lift: the person stands), at its own pace, the true
altitude moving from the level's elevation to the other's over the ride (a lift
after a door wait, and a door wait at the end). The true level is the one whose
elevation is nearest the altitude. The frames are what a phone sends: odometry in the
body frame (the
ride's horizontal motion, as visual-inertial tracking measures it; nothing while the
lift moves), detections of what is in view on the true level (none while a lift moves:
its doors are shut; false detections still come), and the barometer's
altitude: the truth plus a drift (a random offset, a random rate and a random walk)
plus noise.

Poses are kept in the map file's frame with a level and given to the camera in the
plane (:mod:`app.maps.levels`), so the odometry never sees a level's offset.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from app.localization.floors import AltitudeReading
from app.localization.types import Pose
from app.maps.geometry import segments_cross_walls, wrap_angle
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel
from app.simulation.phone import PhoneEffects, add_sway, phone_frames, phone_streams
from app.simulation.simulator import SimFrame, SimulationConfig, _detections, _odometry
from app.simulation.stale import stale_world


@dataclass(frozen=True)
class Walk:
    """Walk through ``points`` (file frame, metres) on the current level."""

    points: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Ride:
    """Take connector ``kind`` to level ``to_level`` (an id), through ``points`` at
    ``speed_mps`` (none for a lift: standing), rising or falling at ``climb_mps``."""

    kind: str
    to_level: str
    points: tuple[tuple[float, float], ...] = ()
    speed_mps: float = 0.4
    climb_mps: float = 1.0
    #: Standing before and after (a lift's doors), seconds.
    wait_s: float = 0.0


Leg = Walk | Ride


@dataclass(frozen=True)
class Barometer:
    """Barometric altitude noise and drift, metres and seconds."""

    noise_m: float = 0.25
    #: Drift: a constant rate drawn from +-``drift_rate_mps``, and a random walk.
    drift_rate_mps: float = 0.01
    walk_m_per_sqrt_s: float = 0.03
    #: The std the phone reports with each reading.
    reported_std_m: float = 0.5


@dataclass(frozen=True)
class VenueFrame:
    """A simulated frame with its level and altitudes."""

    frame: SimFrame
    #: The true pose in the file's frame and the true level's index.
    file_pose: Pose
    level: int
    true_altitude_m: float
    altitude: AltitudeReading | None
    #: Which leg the frame belongs to, and whether that leg is a ride.
    leg: int
    riding: bool


def _truth(
    semantic_map: SemanticMap, start_level: str, legs: list[Leg], cfg: SimulationConfig
) -> list[tuple[float, float, float, int, float, int, bool, bool]]:
    """(x, y, theta, level, altitude, leg, riding, shut) per frame, file frame; ``shut``:
    in a lift car between its door waits, the doors closed (nothing of any floor in view)."""
    layout = semantic_map.layout
    dt = 1.0 / cfg.rate_hz
    step_turn = np.radians(cfg.turn_rate_deg_s) * dt
    level = layout.level_index(start_level)
    first = next(leg for leg in legs if leg.points)
    pos = np.array(first.points[0], dtype=np.float64)
    heading = 0.0
    alt = layout.levels[level].elevation_m
    elevations = np.array([lv.elevation_m for lv in layout.levels])
    out: list[tuple[float, float, float, int, float, int, bool, bool]] = []

    def emit(k: int, riding: bool, shut: bool = False) -> None:
        out.append((float(pos[0]), float(pos[1]), heading, level, alt, k, riding, shut))

    def go(points: tuple[tuple[float, float], ...], speed: float, k: int, riding: bool) -> None:
        nonlocal pos, heading
        for p in points:
            goal_pt = np.array(p, dtype=np.float64)
            while True:
                goal = goal_pt - pos
                dist = float(np.hypot(*goal))
                if dist < 1e-9:
                    break
                want = float(np.arctan2(goal[1], goal[0]))
                diff = float(wrap_angle(want - heading))
                if abs(diff) > step_turn:
                    heading = float(wrap_angle(heading + np.sign(diff) * step_turn))
                else:
                    heading = want
                    pos = pos + goal / dist * min(speed * dt, dist)
                step(k, riding)

    ride_state: dict[str, float] = {}

    def step(k: int, riding: bool, shut: bool = False) -> None:
        nonlocal alt, level
        if riding and ride_state:
            alt = float(
                np.clip(
                    alt + ride_state["rate"] * dt,
                    min(ride_state["a0"], ride_state["a1"]),
                    max(ride_state["a0"], ride_state["a1"]),
                )
            )
            # The true level: the one whose elevation is nearest the altitude.
            level = int(np.argmin(np.abs(elevations - alt)))
        emit(k, riding, shut)

    emit(0, False)
    for k, leg in enumerate(legs):
        if isinstance(leg, Walk):
            _check_clear(semantic_map, level, (float(pos[0]), float(pos[1])), leg.points, k)
            ride_state.clear()
            go(leg.points, cfg.speed_mps, k, False)
            continue
        to = layout.level_index(leg.to_level)
        a0, a1 = alt, layout.levels[to].elevation_m
        for _ in range(round(leg.wait_s * cfg.rate_hz)):
            emit(k, True)
        if leg.points:
            length = sum(
                float(np.hypot(b[0] - a[0], b[1] - a[1]))
                for a, b in zip(((pos[0], pos[1]), *leg.points[:-1]), leg.points, strict=True)
            )
            rate = (a1 - a0) * leg.speed_mps / max(length, 1e-6)
        else:
            rate = float(np.sign(a1 - a0)) * leg.climb_mps
        ride_state.update(a0=a0, a1=a1, rate=rate, to=float(to))
        if leg.points:
            go(leg.points, leg.speed_mps, k, True)
        while abs(alt - a1) > 1e-9:
            # A lift moves with its doors closed: the car's walls and doors are all
            # its rider sees (until this, the simulated car showed each floor it passed
            # through its doorway).
            step(k, True, shut=not leg.points)
        level = to
        ride_state.clear()
        for _ in range(round(leg.wait_s * cfg.rate_hz)):
            emit(k, True)
    return out


def _check_clear(
    semantic_map: SemanticMap,
    level: int,
    at: tuple[float, float],
    points: tuple[tuple[float, float], ...],
    leg: int,
) -> None:
    """Refuse a walking leg (from ``at`` through ``points``, file frame) that crosses a
    wall of its level: the simulated person would pass where nobody can, and a filter
    that keeps its particles out of walls would rightly fall behind them (a walk drawn
    by hand into a lift car through its side wall looked like the filter's fault)."""
    path = np.array([at, *points], dtype=np.float64)
    if path.shape[0] < 2 or semantic_map.walls.shape[0] == 0:
        return
    path[:, 0] += float(semantic_map.layout.offsets(level))
    crossed = segments_cross_walls(path[:-1], path[1:], semantic_map.walls)
    if crossed.any():
        i = int(np.flatnonzero(crossed)[0])
        a, b = ((round(float(x), 3), round(float(y), 3)) for x, y in ((at, *points)[i], points[i]))
        lv = semantic_map.layout.levels[level].id
        raise ValueError(
            f"walk leg {leg}: the stretch from {a} to {b} crosses a wall of level {lv}"
        )


def _barometer(
    altitudes: list[float], barometer: Barometer | None, rng: np.random.Generator, dt: float
) -> list[AltitudeReading | None]:
    """The barometer's reading per tick of the true ``altitudes`` (None without one)."""
    if barometer is None:
        return [None] * len(altitudes)
    offset = float(rng.uniform(-50.0, 50.0))
    rate = float(rng.uniform(-1.0, 1.0) * barometer.drift_rate_mps)
    drift = 0.0
    out: list[AltitudeReading | None] = []
    for i, alt in enumerate(altitudes):
        if i:
            step_m = barometer.walk_m_per_sqrt_s * dt**0.5
            drift += rate * dt + float(rng.normal(0.0, step_m))
        value = alt + offset + drift + float(rng.normal(0.0, barometer.noise_m))
        out.append(AltitudeReading(value, barometer.reported_std_m))
    return out


def _doors_shut(config: SimulationConfig) -> SimulationConfig:
    """``config`` with its blocked view (the frames ``shut`` in a lift car between its
    door waits) blocking the whole field: only false detections come then."""
    return replace(config, blocked_sector_deg=360.0)


def simulate_venue(
    semantic_map: SemanticMap,
    start_level: str,
    legs: list[Leg],
    config: SimulationConfig,
    rng: np.random.Generator,
    barometer: Barometer | None = Barometer(),
) -> list[VenueFrame]:
    """Frames of one walk through the venue (``config.path`` is not used: the legs are)."""
    layout = semantic_map.layout
    camera = CameraModel(config.fov_deg, config.max_range_m)
    truth = _truth(semantic_map, start_level, legs, config)
    baro_rng = rng.spawn(1)[0]
    dt = 1.0 / config.rate_hz
    readings = _barometer([row[4] for row in truth], barometer, baro_rng, dt)
    shut_view = _doors_shut(config)
    frames: list[VenueFrame] = []
    prev: Pose | None = None
    for i, (x, y, th, level, alt, k, riding, shut) in enumerate(truth):
        t = i * dt
        file_pose = Pose(x, y, th)
        px = x + float(layout.offsets(level))
        plane_pose = Pose(px, y, th)
        odo = None if prev is None else _odometry(prev, file_pose, config, rng)
        prev = file_pose
        dets, widths = _detections(
            semantic_map, plane_pose, shut, shut_view if shut else config, camera, rng
        )
        frame = SimFrame(round(t, 6), plane_pose, odo, dets, shut, tuple(widths))
        frames.append(VenueFrame(frame, file_pose, level, alt, readings[i], k, riding))
    return frames


def simulate_venue_phone(
    semantic_map: SemanticMap,
    start_level: str,
    legs: list[Leg],
    config: SimulationConfig,
    effects: PhoneEffects,
    rng: np.random.Generator,
    barometer: Barometer | None = Barometer(),
) -> list[VenueFrame]:
    """The walk of :func:`simulate_venue` as a real phone sends it: the effects of
    :mod:`app.simulation.phone` (latency, duplicates, class confusion, detection falling
    with distance, box-centre bias, dropped frames, the odometry's grade, the hand's sway,
    false detections) on the same true walk, with the barometer of :func:`simulate_venue`.

    Each frame is a :class:`~app.simulation.phone.PhoneFrame` (its ``detections_age_s``
    too); a dropped frame is missing (the next one carries its motion). The sway turns the
    camera while the person walks or climbs stairs, not while standing in a lift or on an
    escalator. ``config`` gives the rate, speed, field of view, range, bearing noise and
    independent misses (``miss_prob``); ``effects.false_rate`` the false detections.
    """
    layout = semantic_map.layout
    truth = _truth(semantic_map, start_level, legs, config)
    baro_rng = rng.spawn(1)[0]
    streams = phone_streams(rng)
    world = semantic_map
    if effects.stale is not None:
        world = stale_world(semantic_map, effects.stale, streams["stale"])
    xyz = np.array([row[:3] for row in truth], dtype=np.float64)
    level = np.array([row[3] for row in truth], dtype=np.int64)
    striding = np.array(
        [not riding or getattr(legs[k], "kind", "") == "stairs" for *_, k, riding, _ in truth]
    )
    add_sway(xyz, config.rate_hz, effects, streams["sway"], striding)
    shut = np.array([row[7] for row in truth], dtype=bool)
    none = np.zeros(len(truth), dtype=bool)
    phone = phone_frames(
        world,
        xyz,
        shut,
        none,
        _doors_shut(config),
        effects,
        streams,
        plane_x=layout.offsets(level),
    )
    readings = _barometer([row[4] for row in truth], barometer, baro_rng, 1.0 / config.rate_hz)
    frames: list[VenueFrame] = []
    for f in phone:
        i = round(f.t * config.rate_hz)
        x, y, th = (float(v) for v in xyz[i])
        _, _, _, lv, alt, k, riding, _ = truth[i]
        frames.append(VenueFrame(f, Pose(x, y, th), lv, alt, readings[i], k, riding))
    return frames
