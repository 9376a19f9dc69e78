"""A fix held in a lift car whose view is blind weighs no detection (the blind hold)."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.floors import AltitudeReading
from app.localization.types import Detection, InitialPose, Odometry, Pose
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel, visible_objects
from app.simulation.venue import venue_map
from tests.localization.test_recovery import _blank_wall_walk

VENUE = venue_map()
CAMERA = CameraModel(180.0, 15.0)
#: The phone's barometer, steady: nobody rides yet (without altitude a lift car's
#: floor is unknown, and nobody in it is located).
STILL = AltitudeReading(12.0)
#: Facing the back of the Ground Floor's lift car: in front of its doors, then inside.
HALL = Pose(1.5, 4.0, -np.pi / 2)
CAR = Pose(1.5, 1.5, -np.pi / 2)


def seen_from(pose: Pose, rng: np.random.Generator) -> list[Detection]:
    """What a 180-degree camera sees from ``pose``, bearings 2 degrees off at most."""
    idx, bearing = visible_objects(VENUE, pose, CAMERA)
    return [
        Detection(VENUE.class_of(int(j)), float(b + rng.uniform(-0.035, 0.035)), 0.9)
        for j, b in zip(idx, bearing, strict=True)
    ]


def false_boxes(rng: np.random.Generator) -> list[Detection]:
    """One to three boxes of the map's classes at any bearing in view: all false."""
    return [
        Detection(str(rng.choice(VENUE.classes)), float(rng.uniform(-1.5, 1.5)), 0.6)
        for _ in range(int(rng.integers(1, 4)))
    ]


def into_the_car(
    seed: int, weighed: list[int], *, split: bool = False
) -> tuple[ParticleFilter, list[float]]:
    """Located in front of the lift, a person walks into the car and stands there for 8 s
    of false boxes (``split``: the filter goes on from its checkpoint halfway, as on
    another worker). ``weighed`` collects the steps whose detections weighed the
    particles; returns the filter and the errors (m) of the frames in the car."""
    config = FilterConfig(particles=2000, fov_deg=CAMERA.fov_deg)
    rng = np.random.default_rng(seed)
    start = InitialPose(HALL.x, HALL.y, HALL.theta_rad, 0.05, np.radians(1.0))
    pf = ParticleFilter(VENUE, config, rng=np.random.default_rng(seed + 1), initial_pose=start)
    count(pf, weighed)
    for _ in range(15):
        pf.step(Odometry(), seen_from(HALL, rng), altitude=STILL)
    assert pf.estimate.converged
    y = HALL.y
    while y > CAR.y + 1e-9:  # 0.1 m a frame into the car
        y -= 0.1
        pf.step(
            Odometry(forward_m=0.1), seen_from(Pose(CAR.x, y, CAR.theta_rad), rng), altitude=STILL
        )
    errors = []
    for k in range(40):
        if split and k == 20:
            state = pf.checkpoint()
            pf = ParticleFilter(VENUE, config, rng=np.random.default_rng(seed + 2), state=state)
            count(pf, weighed)
        est = pf.step(Odometry(), false_boxes(rng), altitude=STILL)
        errors.append(float(np.hypot(est.x - CAR.x, est.y - CAR.y)))
    return pf, errors


def count(pf: ParticleFilter, weighed: list[int]) -> None:
    """Append ``pf``'s step count to ``weighed`` whenever it weighs its particles."""
    weigh = pf.observation_log_likelihood

    def counted(obs):  # type: ignore[no-untyped-def]
        weighed.append(pf.steps)
        return weigh(obs)

    pf.observation_log_likelihood = counted  # type: ignore[method-assign]


def test_the_car_sees_nothing_and_its_false_boxes_weigh_nothing() -> None:
    weighed: list[int] = []
    pf, errors = into_the_car(0, weighed)
    in_car = pf.steps - 40
    assert pf._blind_hold
    assert len([s for s in weighed if s >= in_car]) <= 2  # before the hold began
    assert max(errors) < 0.3
    assert pf.estimate.converged


def test_the_blind_hold_is_kept_in_a_checkpoint() -> None:
    weighed: list[int] = []
    pf, errors = into_the_car(1, weighed, split=True)
    assert pf._blind_hold
    assert not [s for s in weighed if s >= pf.steps - 20]  # none after the restart
    assert max(errors) < 0.3


def test_walking_out_of_the_car_ends_the_hold() -> None:
    weighed: list[int] = []
    pf, _ = into_the_car(2, weighed)
    rng = np.random.default_rng(9)
    y = CAR.y
    # turn round, 45 degrees a frame, then walk out of the car towards the hall
    for _ in range(4):
        pf.step(Odometry(turn_rad=np.pi / 4), [], altitude=STILL)
    for _ in range(15):
        y += 0.1
        pf.step(Odometry(forward_m=0.1), seen_from(Pose(CAR.x, y, np.pi / 2), rng), altitude=STILL)
    assert not pf._blind_hold
    assert weighed[-1] == pf.steps - 1  # the last frame's detections were weighed
    est = pf.estimate
    assert np.hypot(est.x - CAR.x, est.y - y) < 0.5


def test_a_frame_without_odometry_ends_the_hold() -> None:
    """The app lost its odometry (paused in the lift, opened again elsewhere): the person
    may be anywhere, and what the camera now sees is weighed again."""
    weighed: list[int] = []
    pf, _ = into_the_car(3, weighed)
    assert pf._blind_hold
    rng = np.random.default_rng(5)
    elsewhere = Pose(8.0, 6.0, 0.0)
    pf.step(None, seen_from(elsewhere, rng), altitude=STILL)
    assert not pf._blind_hold
    assert weighed[-1] == pf.steps - 1
    assert not pf.estimate.converged


def test_a_one_level_map_never_holds_blind(small_room: SemanticMap) -> None:
    """Only a connector's stop (a lift car) holds blind: elsewhere what the estimate does
    not explain may be what corrects a drifting odometry."""
    pf, _, _ = _blank_wall_walk(small_room, 0)
    assert pf._sees_nothing and not pf._blind_hold


@pytest.mark.parametrize("through_a_checkpoint", [False, True])
def test_a_fix_held_into_a_lift_rides_with_the_barometer_and_is_told_on_arrival(
    through_a_checkpoint: bool,
) -> None:
    """Located as the ride began, a person rides one storey in a car that shows nothing
    but false boxes (at the lift's 1 m/s), for longer than the hold's frames without
    evidence allow: the fix rides along and is told again as soon as the barometer has
    them on the First Floor, in the car there; the level is right
    (``through_a_checkpoint``: by a filter restored mid-ride from a checkpoint, as a
    worker taking the session over after a store outage would)."""
    pf, _ = into_the_car(4, [])
    assert pf.estimate.converged
    rng = np.random.default_rng(11)
    storey_m = 4.5
    told_riding = False
    altitude = STILL.relative_m
    # 4.5 m at 0.2 m a frame (1 m/s at 5 frames/s), then the door wait: with the 40
    # frames in the car before, more frames without evidence than a hold allows.
    frames = int(storey_m / 0.2) + 20
    assert 40 + frames > pf.gate.hold_without_evidence
    for k in range(frames):
        if through_a_checkpoint and k == 10:
            pf = ParticleFilter(
                VENUE, pf.config, rng=np.random.default_rng(12), state=pf.checkpoint()
            )
        altitude = min(altitude + 0.2, STILL.relative_m + storey_m)
        est = pf.step(Odometry(), false_boxes(rng), altitude=AltitudeReading(altitude))
        if pf.floors is not None and pf.floors.in_transit:
            told_riding = told_riding or est.converged
    assert not told_riding  # nobody is located between floors
    layout = VENUE.layout
    assert est.converged, pf.gate.lost_because
    assert layout.level_of(est.x) == 1
    on_first = float(est.x - layout.offsets(1))
    assert np.hypot(on_first - CAR.x, est.y - CAR.y) < 0.5
