"""Solution separation: a first fix is not told while one movable object pulls it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import app.localization.evidence as evidence_module
from app.localization import sensor_kernel
from app.localization.config import FilterConfig
from app.localization.convergence import GAIN_PROTECTION_M
from app.localization.evidence import EvidenceTracker
from app.localization.filter import (
    GAIN_SEPARATION_M,
    GAIN_SEPARATION_MAX_M,
    SEPARATION_RINGS_FOV_DEG,
    ParticleFilter,
    separation_allows_gain,
)
from app.localization.models import BearingSensorModel, OdometryMotionModel
from app.localization.search import Separation, explaining
from app.localization.types import Odometry, Pose
from app.maps.model import SemanticMap, parse_map
from app.simulation.camera import CameraModel, visible_objects
from tests.helpers import ensure_prepared, paper_office, seen_from

#: A corridor 20 m x 3 m: three doors in one wall, a window at its end, and two pieces
#: of furniture (index 4, the plant, is the one a test moves).
OBJECTS = [
    {"class": "door", "x": 2.0, "y": 3.0},
    {"class": "door", "x": 10.0, "y": 3.0},
    {"class": "door", "x": 18.0, "y": 3.0},
    {"class": "window", "x": 20.0, "y": 1.5},
    {"class": "plant", "x": 14.0, "y": 0.3},
    {"class": "table", "x": 6.0, "y": 0.5},
]
PLANT = 4
STEP_M = 0.1


def corridor(objects: list[dict]) -> SemanticMap:
    outline = [
        {"x1": 0, "y1": 0, "x2": 20, "y2": 0},
        {"x1": 20, "y1": 0, "x2": 20, "y2": 3},
        {"x1": 20, "y1": 3, "x2": 0, "y2": 3},
        {"x1": 0, "y1": 3, "x2": 0, "y2": 0},
    ]
    return ensure_prepared(parse_map({"name": "corridor", "walls": outline, "objects": objects}))


def _tracker(
    drawn: SemanticMap, world: SemanticMap, frames: int = 25
) -> tuple[EvidenceTracker, Pose]:
    """A tracker on the map ``drawn`` whose history is a walk along the corridor's
    middle seen, noise-free, in ``world``; and the walk's last pose."""
    cfg = FilterConfig()
    sensor = BearingSensorModel(drawn, cfg, drawn.visibility)
    tracker = EvidenceTracker(sensor, OdometryMotionModel(drawn, cfg), np.random.default_rng(0))
    pose = Pose(3.0, 1.5, 0.0)
    for k in range(frames):
        pose = Pose(3.0 + STEP_M * k, 1.5, 0.0)
        odometry = Odometry(STEP_M, 0.0, 0.0) if k else None
        tracker._history.append((odometry, sensor.observe(seen_from(world, pose)), None))
    return tracker, pose


def _moved(dy: float) -> SemanticMap:
    """The corridor today: the plant moved ``dy`` across it."""
    objects = [dict(o) for o in OBJECTS]
    objects[PLANT]["y"] = float(objects[PLANT]["y"]) + dy
    return corridor(objects)


def test_leaving_an_object_out_is_excluding_it_from_the_sensor_model() -> None:
    m = corridor(OBJECTS)
    tracker, pose = _tracker(m, m)
    window = tracker.window()
    assert window.members.size
    cfg = FilterConfig()
    for obj in range(m.object_count):
        excluded = BearingSensorModel(m, cfg, m.visibility)
        excluded.exclude([obj])
        again = sensor_kernel.pack_window(
            [(rel, excluded.observe(seen_from(m, pose)), None) for rel in window.rel[:1]]
        )
        mine = window.without(obj)
        # The newest frame's classes: the same candidates, in the same order.
        n = again.member_start.size
        assert np.array_equal(mine.member_start[:n], again.member_start)
        assert np.array_equal(mine.members[: again.members.size], again.members)
        assert obj not in mine.members
        # Every other object keeps all of its places among the candidates.
        kept = window.members[window.members != obj]
        assert np.array_equal(mine.members, kept)


def test_the_objects_that_explain_a_noise_free_view_are_the_ones_in_it() -> None:
    m = corridor(OBJECTS)
    tracker, pose = _tracker(m, m, frames=1)
    seen = explaining(
        (pose.x, pose.y, pose.theta_rad), tracker.window(), m.object_xy.reshape(-1, 2)
    )
    in_view, _ = visible_objects(m, pose, CameraModel(360.0, 15.0))  # (seen_from's camera)
    assert 0 < len(in_view) < m.object_count
    assert seen.tolist() == sorted(int(j) for j in in_view)
    # From a pose turned half round, no detection points at any object of its class.
    turned = explaining((pose.x, pose.y, math.pi), tracker.window(), m.object_xy.reshape(-1, 2))
    assert turned.size < m.object_count


def test_a_moved_object_pulls_the_fix_by_more_than_the_gain_allows() -> None:
    drawn = corridor(OBJECTS)
    tracker, pose = _tracker(drawn, drawn)
    still = tracker.separation_m(pose.x, pose.y, pose.theta_rad)
    assert max(still.near_m, still.far_m) < 0.2 * GAIN_SEPARATION_M
    tracker, pose = _tracker(drawn, _moved(1.0))
    pulled = tracker.separation_m(pose.x, pose.y, pose.theta_rad)
    assert pulled.near_m > GAIN_SEPARATION_M
    assert pulled.obj >= 0  # the object whose absence moves the fix that far is named


def test_the_rings_find_a_better_place_the_search_from_the_fix_stops_short_of() -> None:
    """The plant moved 2 m across the corridor: with it left out, the search from the fix
    stays in the fix's local optimum, and only a search started a metre or more away
    finds where the rest of the window is better explained."""
    tracker, pose = _tracker(corridor(OBJECTS), _moved(2.0))
    found = tracker.separation_m(pose.x, pose.y, pose.theta_rad)
    assert found.near_m < 0.2 * GAIN_SEPARATION_M
    assert found.far_m > 2 * GAIN_SEPARATION_M
    alone = tracker.separation_m(pose.x, pose.y, pose.theta_rad, rings=False)
    assert alone.far_m == alone.near_m == found.near_m


def _left_out(
    monkeypatch: pytest.MonkeyPatch, m: SemanticMap
) -> tuple[list[list[int | tuple[int, ...]]], np.ndarray]:
    """What the separation of a noise-free walk on ``m`` leaves out (each call's list of
    objects and groups), and the objects that explain its detections."""
    tracker, pose = _tracker(m, m)
    tested: list[list[int | tuple[int, ...]]] = []

    def record(pose_: object, window: object, objects: list, *args: object) -> Separation:
        tested.append(list(objects))
        return Separation(0.0, 0.0, -1)

    monkeypatch.setattr(tracker.finder, "separation", record)
    tracker.separation_m(pose.x, pose.y, pose.theta_rad)
    seen = explaining(
        (pose.x, pose.y, pose.theta_rad), tracker.window(), m.object_xy.reshape(-1, 2)
    )
    return tested, seen


def test_only_movable_objects_are_left_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """The separation tests the movable objects that explain a detection, never a door or
    a window (SemanticMap.fixed): those are part of the building."""
    m = corridor(OBJECTS)
    tested, seen = _left_out(monkeypatch, m)
    assert m.fixed[seen].any() and not m.fixed[seen].all()  # both kinds explain detections
    assert tested == [[int(o) for o in seen if not m.fixed[o]]]


@pytest.mark.parametrize(
    ("near_m", "far_m", "fov_deg", "told"),
    [
        (0.0, 0.0, 360.0, True),
        (GAIN_PROTECTION_M + 0.1, 0.0, 360.0, False),
        # A better place found only from the rings keeps a wide camera's fix untold ...
        (0.0, GAIN_PROTECTION_M + 0.1, 360.0, False),
        # ... and is not sought through a narrower one (SEPARATION_RINGS_FOV_DEG).
        (0.0, GAIN_PROTECTION_M + 0.1, 180.0, True),
    ],
)
def test_a_first_fix_waits_while_one_object_pulls_it_beyond_its_radius(
    monkeypatch: pytest.MonkeyPatch, near_m: float, far_m: float, fov_deg: float, told: bool
) -> None:
    office = paper_office()
    pose = Pose(3.0, 2.0, math.pi / 2)
    asked: list[bool] = []

    def separation(self: object, x: float, y: float, t: float, rings: bool) -> Separation:
        asked.append(rings)
        return Separation(near_m, far_m if rings else near_m, 6)

    monkeypatch.setattr(evidence_module.EvidenceTracker, "separation_m", separation)
    pull_m = max(near_m, far_m if fov_deg >= SEPARATION_RINGS_FOV_DEG else near_m)

    def first_fix() -> int | None:
        config = FilterConfig(particles=3000, fov_deg=fov_deg)
        pf = ParticleFilter(office, config, rng=np.random.default_rng(1))
        seen = seen_from(office, pose)
        for k in range(60):
            est = pf.step(Odometry(0.0, 0.0, 0.0), seen)
            if est.converged:
                assert est.protection_m is not None
                # Told only where the pull is within its radius (or half a metre).
                assert separation_allows_gain(pull_m, est.protection_m)
                return k
        return None

    first = first_fix()
    assert asked and set(asked) == {fov_deg >= SEPARATION_RINGS_FOV_DEG}
    if told:
        assert first is not None
    else:
        # A first fix's radius is at most GAIN_PROTECTION_M, under the pull: never told.
        assert first is None


@pytest.mark.parametrize(
    ("pull_m", "radius_m", "told"),
    [
        (0.45, 0.2, True),  # within half a metre, whatever the radius
        (0.6, 0.55, False),  # beyond both
        (0.9, 1.32, True),  # within the radius and a metre
        # The traced gain: a moved plant pulled a fix 1.09 m, within its 1.32 m radius;
        # told, it was 1.19 m off.
        (1.09, 1.32, False),
        (GAIN_SEPARATION_MAX_M + 0.01, GAIN_PROTECTION_M, False),
    ],
)
def test_a_pull_over_a_metre_keeps_a_first_fix_untold_whatever_its_radius(
    pull_m: float, radius_m: float, told: bool
) -> None:
    assert GAIN_SEPARATION_M < GAIN_SEPARATION_MAX_M < GAIN_PROTECTION_M
    assert separation_allows_gain(pull_m, radius_m) is told


def test_several_objects_left_out_together_are_each_left_out() -> None:
    m = corridor(OBJECTS)
    tracker, _ = _tracker(m, m)
    window = tracker.window()
    both = window.without((PLANT, 5))
    one_by_one = window.without(PLANT).without(5)
    assert np.array_equal(both.members, one_by_one.members)
    assert np.array_equal(both.member_start, one_by_one.member_start)
    assert both.members.size < window.members.size


def test_every_movable_object_of_a_class_is_also_left_out_together(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Furniture is rearranged a class at a time (the plants carried to the other wall):
    besides each movable object alone, the movable objects of one class that explain
    detections are left out together; a class with one such object adds nothing."""
    m = corridor([*OBJECTS, {"class": "plant", "x": 11.0, "y": 2.7}])
    tested, seen = _left_out(monkeypatch, m)
    movable = [int(o) for o in seen if not m.fixed[o]]
    assert {PLANT, 6} <= set(movable)  # both plants explain detections, and the table
    assert tested == [[*movable, (PLANT, 6)]]
