"""The recorded walk: a place is told only if the walk could have led there."""

from __future__ import annotations

import math

import pytest

from app.localization.types import Odometry
from app.localization.walked import (
    BASE_TOLERANCE_M,
    MAX_HEADING_OFF_DEG,
    MAX_WALK_M,
    WalkedPath,
)
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared

STEP = Odometry(0.25, 0.0, 0.0)


@pytest.fixture(scope="module")
def corridor() -> SemanticMap:
    """A 30 m x 2 m corridor along x."""
    walls = [
        {"x1": 0, "y1": 0, "x2": 30, "y2": 0},
        {"x1": 30, "y1": 0, "x2": 30, "y2": 2},
        {"x1": 30, "y1": 2, "x2": 0, "y2": 2},
        {"x1": 0, "y1": 2, "x2": 0, "y2": 0},
    ]
    objects = [{"class": "door", "x": 10, "y": 2}, {"class": "plant", "x": 20, "y": 0.3}]
    return ensure_prepared(parse_map({"name": "corridor", "walls": walls, "objects": objects}))


def _walked(metres: float, share: float = 0.03, scale_tolerance: float = 0.05) -> WalkedPath:
    path = WalkedPath(share, scale_tolerance)
    for _ in range(round(metres / STEP.forward_m)):
        path.moved(STEP)
    return path


def test_the_distance_to_the_free_space_is_zero_inside_and_grows_outside(
    corridor: SemanticMap,
) -> None:
    fs = corridor.free_space
    inside, wall, beyond = fs.distance_outside([15.0, 15.0, 15.0], [1.0, 0.0, -3.0])
    assert inside == 0.0
    assert 0.0 < wall < 0.25  # the wall's cell, a clearance away from the free space
    # Off the grid: the edge cell's distance plus the way to the grid.
    assert beyond == pytest.approx(3.0 + fs.distance_outside(15.0, fs.origin_y)[0], abs=1e-9)


def test_the_true_end_of_a_walk_fits_and_a_look_alike_further_back_does_not(
    corridor: SemanticMap,
) -> None:
    """Walked 10 m east from x = 2: at x = 12 the walk fits; the same view 6 m back
    (x = 6) would have begun 4 m beyond the corridor's west wall."""
    path = _walked(10.0)
    assert path.fits(corridor.free_space, 12.0, 1.0, 0.0)
    assert not path.fits(corridor.free_space, 6.0, 1.0, 0.0)
    # Turned round, the walk would have come from the east: from x = 2 facing west it
    # begins at x = 12, in the corridor.
    assert path.fits(corridor.free_space, 2.0, 1.0, math.pi)
    # Facing across the corridor the walk would have come through its south wall.
    assert not path.fits(corridor.free_space, 12.0, 1.0, math.pi / 2)


def test_the_heading_and_the_scale_may_be_off_within_their_tolerance(
    corridor: SemanticMap,
) -> None:
    """A pose whose heading is off by less than MAX_HEADING_OFF_DEG, or whose walk the
    odometry measured a few percent long, is not refused for it."""
    path = _walked(10.0)
    off = math.radians(MAX_HEADING_OFF_DEG - 2.0)
    assert path.fits(corridor.free_space, 12.0, 1.0, off)
    assert path.fits(corridor.free_space, 12.0, 1.0, -off)
    # Walked 20 m by the odometry, 18 m in fact, to x = 18: as measured the walk would
    # begin 2 m beyond the west wall (1.7 m turned by 10 degrees), more than the
    # 0.5 + 0.03 x 20 m its oldest point may lie off; 10 % shorter, it begins inside.
    assert _walked(20.0, share=0.03, scale_tolerance=0.1).fits(corridor.free_space, 18.0, 1.0, 0.0)
    assert not _walked(20.0, share=0.03, scale_tolerance=0.0).fits(
        corridor.free_space, 18.0, 1.0, 0.0
    )


def test_the_tolerance_grows_with_the_distance_walked_since_a_point(
    corridor: SemanticMap,
) -> None:
    """The oldest point may lie BASE_TOLERANCE_M plus share x distance beyond the free
    space: a 20 m walk that would have begun 1 m beyond the west wall (1.15 m from the
    free space) fits with a 10 % share (2.5 m), not with 1 % (0.7 m); a recent point
    only within BASE_TOLERANCE_M."""
    assert _walked(20.0, share=0.1, scale_tolerance=0.0).fits(corridor.free_space, 19.0, 1.0, 0.0)
    assert not _walked(20.0, share=0.01, scale_tolerance=0.0).fits(
        corridor.free_space, 19.0, 1.0, 0.0
    )
    # 1 m walked, ending 1 m beyond the east wall: off by more than BASE_TOLERANCE_M.
    assert BASE_TOLERANCE_M < 1.0
    assert not _walked(1.0, share=0.1).fits(corridor.free_space, 31.0, 1.0, 0.0)
    assert _walked(1.0, share=0.1).fits(corridor.free_space, 29.0, 1.0, 0.0)


def test_a_reset_forgets_the_walk_and_old_points_are_let_go(corridor: SemanticMap) -> None:
    path = _walked(10.0)
    path.reset()
    assert path.fits(corridor.free_space, 6.0, 1.0, 0.0)
    assert path.walked_m == 0.0
    # A walk far longer than MAX_WALK_M back and forth: only its last MAX_WALK_M count.
    path = WalkedPath(0.03, 0.05)
    for _ in range(4):
        for _ in range(round(20.0 / STEP.forward_m)):
            path.moved(STEP)
        path.moved(Odometry(0.0, 0.0, math.pi))
    assert path.walked_m == pytest.approx(80.0)
    assert len(path._xyw) // 3 <= 2 * MAX_WALK_M / STEP.forward_m + 1


def test_only_the_last_metres_of_the_walk_are_tested(corridor: SemanticMap) -> None:
    """20 m north, then three 20 m legs east, west and east: the last MAX_WALK_M (60 m)
    are the three legs, which keep to the corridor from x = 5 to 25; the first leg,
    placed there, would come from 19 m south of it."""
    assert pytest.approx(60.0) == MAX_WALK_M  # (the walk below is laid out for it)
    path = WalkedPath(0.03, 0.05)
    path.moved(Odometry(0.0, 0.0, math.pi / 2))
    for turn in (-math.pi / 2, math.pi, math.pi, None):
        for _ in range(round(20.0 / STEP.forward_m)):
            path.moved(STEP)
        if turn is not None:
            path.moved(Odometry(0.0, 0.0, turn))
    assert path.fits(corridor.free_space, 25.0, 1.0, 0.0)
    # Walked 10 m less, the first leg's last 10 m are within the 60 m: refused.
    shorter = WalkedPath(0.03, 0.05)
    shorter.moved(Odometry(0.0, 0.0, math.pi / 2))
    for metres, turn in ((20.0, -math.pi / 2), (20.0, math.pi), (20.0, math.pi), (10.0, None)):
        for _ in range(round(metres / STEP.forward_m)):
            shorter.moved(STEP)
        if turn is not None:
            shorter.moved(Odometry(0.0, 0.0, turn))
    assert not shorter.fits(corridor.free_space, 15.0, 1.0, 0.0)


def test_checkpoint_round_trip_keeps_the_walk(corridor: SemanticMap) -> None:
    path = _walked(10.0)
    copy = WalkedPath(0.03, 0.05)
    copy.restore(path.checkpoint())
    assert copy.walked_m == path.walked_m
    for pose in ((12.0, 1.0, 0.0), (6.0, 1.0, 0.0)):
        assert copy.fits(corridor.free_space, *pose) == path.fits(corridor.free_space, *pose)
    copy.restore(None)  # a checkpoint from before the walk was kept: starts again
    assert copy.walked_m == 0.0
