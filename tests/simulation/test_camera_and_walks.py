"""The virtual camera's geometry and the simulated walks."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from app.localization.types import Pose
from app.maps.geometry import wrap_angle
from app.maps.model import parse_map
from app.simulation import CameraModel, paper_config, simulate, visible_objects
from app.simulation.scenarios import PAPER_PATH
from app.simulation.simulator import CornerVisit, SimulationConfig
from app.simulation.walks import loop_path
from tests.helpers import paper_office

ROOM = parse_map(
    {
        "name": "room",
        "walls": [
            {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
            {"x1": 6, "y1": 0, "x2": 6, "y2": 4},
            {"x1": 6, "y1": 4, "x2": 0, "y2": 4},
            {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
            {"x1": 3, "y1": 0, "x2": 3, "y2": 2},
        ],
        "objects": [
            {"class": "door", "x": 6, "y": 1},  # in the east wall
            {"class": "table", "x": 1, "y": 1},  # behind the start, west
            {"class": "window", "x": 4.5, "y": 4},  # north wall, left-ahead
            {"class": "table", "x": 4.5, "y": 1},  # hidden from the west half by the inner wall
        ],
    }
)
OFFICE = paper_office()


def seen(pose: Pose, fov: float, max_range: float = 15.0) -> dict[int, float]:
    idx, bearing = visible_objects(ROOM, pose, CameraModel(fov, max_range))
    return {int(i): math.degrees(b) for i, b in zip(idx, bearing, strict=True)}


def test_bearings_are_counter_clockwise_positive() -> None:
    # Standing at (4.5, 2.5) facing east, the window at (4.5, 4) is straight to the left.
    s = seen(Pose(4.5, 2.5, 0.0), 360)
    assert s[2] == pytest.approx(90.0)
    assert s[3] == pytest.approx(-90.0)  # the table straight to the right


@pytest.mark.parametrize(("fov", "sees_behind"), [(180, False), (270, False), (360, True)])
def test_field_of_view_is_centred_on_the_heading(fov: float, sees_behind: bool) -> None:
    s = seen(Pose(2.0, 1.0, 0.0), fov)  # facing east; the west table is behind
    assert (1 in s) is sees_behind


def test_270_sees_to_the_side_but_180_does_not() -> None:
    # Facing east at (5, 3.5): the window at (4.5, 4) is at about 135 degrees.
    assert 2 in seen(Pose(5.0, 3.5, 0.0), 360)
    assert 2 in seen(Pose(5.0, 3.5, 0.0), 270)
    assert 2 not in seen(Pose(5.0, 3.5, 0.0), 180)


def test_walls_hide_and_mounted_objects_are_not_hidden_by_their_wall() -> None:
    s = seen(Pose(1.5, 1.0, 0.0), 360)
    assert 3 not in s  # the inner wall hides the east table
    assert 0 not in s  # ...and the door behind it
    s = seen(Pose(5.0, 2.0, 0.0), 360)
    assert 0 in s  # the door in the east wall is visible from inside
    assert 2 in s  # the window in the north wall too


def test_max_range() -> None:
    assert 1 in seen(Pose(2.0, 3.0, 0.0), 360, max_range=3.0)
    assert 2 not in seen(Pose(1.0, 1.0, 0.0), 360, max_range=3.0)


def clean(path: tuple[tuple[float, float], ...], **kw: object) -> SimulationConfig:
    return SimulationConfig(
        path=path, bearing_noise_deg=0.0, odometry_noise_m=0.0, odometry_noise_deg=0.0, **kw
    )


def test_noise_free_odometry_integrates_to_the_truth() -> None:
    frames = simulate(OFFICE, clean(PAPER_PATH), np.random.default_rng(0))
    assert frames[0].odometry is None
    x, y, th = frames[0].truth.x, frames[0].truth.y, frames[0].truth.theta_rad
    for f in frames[1:]:
        o = f.odometry
        x += math.cos(th) * o.forward_m - math.sin(th) * o.left_m
        y += math.sin(th) * o.forward_m + math.cos(th) * o.left_m
        th = float(wrap_angle(th + o.turn_rad))
    last = frames[-1].truth
    assert (x, y) == pytest.approx((last.x, last.y), abs=1e-9)
    assert th == pytest.approx(last.theta_rad, abs=1e-9)


def test_noise_free_bearings_point_at_the_objects() -> None:
    frames = simulate(OFFICE, clean(PAPER_PATH[:2]), np.random.default_rng(0))
    f = frames[10]
    for d in f.detections:
        members = OFFICE.object_xy[OFFICE.class_members[d.cls]]
        world = f.truth.theta_rad + d.bearing_rad
        dirs = np.arctan2(members[:, 1] - f.truth.y, members[:, 0] - f.truth.x)
        assert np.min(np.abs(wrap_angle(dirs - world))) < 1e-9


def test_paper_walk_timing_and_ends() -> None:
    frames = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(0))
    assert (frames[0].truth.x, frames[0].truth.y) == (1.5, 1.2)
    assert (frames[-1].truth.x, frames[-1].truth.y) == pytest.approx((5.0, 3.5))
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(PAPER_PATH))
    walking = sum(
        1
        for a, b in itertools.pairwise(frames)
        if math.dist((a.truth.x, a.truth.y), (b.truth.x, b.truth.y)) > 1e-9
    )
    assert walking * 0.2 * 0.5 == pytest.approx(length, abs=0.2)
    assert all(len(f.detections) == 11 for f in frames)  # 360 deg, nothing hidden


def test_same_seed_same_frames() -> None:
    cfg = paper_config("missing", 270)
    a = [f.to_contract() for f in simulate(OFFICE, cfg, np.random.default_rng(3))]
    b = [f.to_contract() for f in simulate(OFFICE, cfg, np.random.default_rng(3))]
    c = [f.to_contract() for f in simulate(OFFICE, cfg, np.random.default_rng(4))]
    assert a == b and a != c


def test_frame_json_is_the_contract_format() -> None:
    f = simulate(OFFICE, paper_config("nominal", 360), np.random.default_rng(0))[3].to_contract()
    assert set(f) == {"timestamp", "odometry", "detections", "describe", "truth"}
    assert set(f["odometry"]) == {"forward_m", "left_m", "turn_deg"}
    assert set(f["detections"][0]) == {"class", "bearing_deg", "score"}
    assert all(-180 < d["bearing_deg"] <= 180 for d in f["detections"])
    assert set(f["truth"]) == {"x", "y", "theta_deg"}


def test_miss_probability_rate() -> None:
    cfg = replace(paper_config("nominal", 360), miss_prob=0.3)
    frames = simulate(OFFICE, cfg, np.random.default_rng(1))
    rate = 1 - np.mean([len(f.detections) for f in frames]) / 11
    assert rate == pytest.approx(0.3, abs=0.03)


def test_random_loss_loses_a_random_share() -> None:
    frames = simulate(OFFICE, paper_config("missing", 360), np.random.default_rng(2))
    counts = np.array([len(f.detections) for f in frames])
    assert 0.35 < counts.mean() / 11 < 0.65  # half on average
    assert (counts == 0).any() and (counts >= 10).any()


def test_false_detections_rate_and_scores() -> None:
    cfg = replace(clean(PAPER_PATH), false_rate=1.0, fov_deg=360.0)
    frames = simulate(OFFICE, cfg, np.random.default_rng(5))
    false = [d for f in frames for d in f.detections if d.score < 1.0]
    assert len(false) / len(frames) == pytest.approx(1.0, abs=0.15)
    assert all(0.3 <= d.score <= 0.7 for d in false)


def test_occlusion_blocks_the_front_twice_for_ten_seconds() -> None:
    frames = simulate(OFFICE, paper_config("occlusion", 180), np.random.default_rng(0))
    blocked = [f.t for f in frames if f.blocked]
    starts = [t for i, t in enumerate(blocked) if i == 0 or t - blocked[i - 1] > 0.3]
    assert len(starts) == 2
    assert 10.0 <= starts[0] <= 12.0 and 35.0 <= starts[1] <= 38.0
    assert len(blocked) * 0.2 == pytest.approx(20.0, abs=0.5)
    for f in frames:
        if f.blocked:  # nothing in the front 180 degrees, and a 180 camera sees nothing
            assert f.detections == []


def test_corner_visit_faces_the_nearest_corner() -> None:
    cfg = clean(PAPER_PATH, corner_visits=(CornerVisit(2.0, 3.0),))
    frames = simulate(OFFICE, cfg, np.random.default_rng(0))
    f = next(f for f in frames if f.blocked)
    to_corner = math.atan2(0 - f.truth.y, 0 - f.truth.x)  # the south-west corner
    assert abs(float(wrap_angle(f.truth.theta_rad - to_corner))) < 1e-6


def test_kidnap_jumps_without_odometry() -> None:
    cfg = replace(clean(PAPER_PATH), kidnap_at_s=4.0, kidnap_pose=(8.0, 5.0, 90.0))
    frames = simulate(OFFICE, cfg, np.random.default_rng(0))
    i = next(i for i, f in enumerate(frames) if f.truth.x == 8.0 and f.truth.y == 5.0)
    assert frames[i].odometry is None
    assert frames[i].t == pytest.approx(4.0)
    assert math.dist((frames[i - 1].truth.x, frames[i - 1].truth.y), (8.0, 5.0)) > 2.0
    assert all(f.odometry is not None for f in frames[1:i])


def test_demo_loops_are_closed_and_walkable() -> None:
    rng = np.random.default_rng(0)
    office_loop = loop_path(OFFICE, rng)
    assert office_loop[0] == office_loop[-1] == PAPER_PATH[0]
    other = loop_path(ROOM, rng)
    assert other[0] == other[-1]
    assert all(ROOM.free_space.is_free([x], [y])[0] for x, y in other)


@pytest.mark.parametrize(
    ("pose", "index", "hour"),
    [
        (Pose(4.5, 2.5, 0.0), 2, 9),  # facing east, the window is to the left
        (Pose(4.5, 2.5, 0.0), 3, 3),  # ...and the table to the right
        (Pose(4.5, 2.5, math.pi / 2), 2, 12),  # facing north: the window is ahead
        (Pose(4.5, 2.5, -math.pi / 2), 2, 6),  # facing south: behind
    ],
)
def test_clock_of_a_known_bearing(pose: Pose, index: int, hour: int) -> None:
    from app.feedback import clock_from_bearing_deg

    assert clock_from_bearing_deg(seen(pose, 360)[index]) == hour
