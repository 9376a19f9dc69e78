"""The odometry motion model and the wall / free-space penalty."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.random import default_rng

from app.localization.config import FilterConfig
from app.localization.fastmath import fill_normal
from app.localization.motion import (
    MAX_SPEED_M_S,
    MIN_JUMP_M,
    NO_ODOMETRY_STD_M,
    implausible,
    penalized,
    sample_motion,
)
from app.localization.tolerances import U64, motion_position_tolerance
from app.localization.types import Odometry
from app.maps.geometry import segments_cross_walls
from tests.helpers import room

EXACT = FilterConfig(
    trans_noise_frac=0, rot_noise_frac=0, trans_noise_floor_m=0, rot_noise_floor_deg=0
)


def test_noise_free_motion_is_exact_in_the_body_frame() -> None:
    x, y, th = np.array([1.0, 2.0]), np.array([1.0, 1.0]), np.array([0.0, np.pi / 2])
    nx, ny, nth = sample_motion(
        x, y, th, Odometry(0.5, 0.2, np.pi / 2), EXACT, np.random.default_rng(0)
    )
    # Facing east: forward is +x, left is +y. Facing north: forward is +y, left is -x.
    # Exact up to the polynomial sine and cosine (and float64 rounding).
    within = motion_position_tolerance(step_m=0.7, coordinate_m=2.0)
    assert np.abs(nx - [1.5, 1.8]).max() <= within and np.abs(ny - [1.2, 1.5]).max() <= within
    assert np.abs(nth - [np.pi / 2, np.pi]).max() <= 4 * U64 * np.pi
    assert x.tolist() == [1.0, 2.0]  # inputs untouched


def test_noise_grows_with_motion_and_has_a_floor() -> None:
    n = 20_000
    zeros = np.zeros(n)
    cfg = FilterConfig()
    rng = np.random.default_rng(1)
    still_x, _, still_t = sample_motion(zeros, zeros, zeros, Odometry(0, 0, 0), cfg, rng)
    assert still_x.std() == pytest.approx(cfg.trans_noise_floor_m, rel=0.05)
    assert still_t.std() == pytest.approx(np.radians(cfg.rot_noise_floor_deg), rel=0.05)
    walk_x, _, _ = sample_motion(zeros, zeros, zeros, Odometry(1.0, 0, 0), cfg, rng)
    assert walk_x.mean() == pytest.approx(1.0, abs=0.01)
    expected = cfg.trans_noise_frac * 1.0 + cfg.trans_noise_floor_m
    assert walk_x.std() == pytest.approx(expected, rel=0.05)
    lost_x, _, _ = sample_motion(zeros, zeros, zeros, None, cfg, rng)
    assert lost_x.std() == pytest.approx(NO_ODOMETRY_STD_M, rel=0.05)


def test_motion_noise_is_the_tabulated_normal_of_the_filters_generator() -> None:
    """Particle i's forward, left and turn noise are draws i, N + i and 2N + i of
    fill_normal from the same generator (standing still, facing +x, each new
    coordinate is just its scaled draw, with one rounding either way)."""
    n, cfg = 1000, FilterConfig()
    zeros = np.zeros(n)
    nx, ny, nt = sample_motion(zeros, zeros, zeros, Odometry(0, 0, 0), cfg, default_rng(5))
    z = fill_normal(default_rng(5), 3 * n).astype(np.float64)
    std_t, std_r = cfg.trans_noise_floor_m, float(np.radians(cfg.rot_noise_floor_deg))
    assert np.array_equal(nx, std_t * z[:n])
    assert np.array_equal(ny, std_t * z[n : 2 * n])
    assert np.array_equal(nt, std_r * z[2 * n :])


def test_heading_stays_wrapped() -> None:
    th = np.full(1000, 3.1)
    _, _, nth = sample_motion(
        np.zeros(1000),
        np.zeros(1000),
        th,
        Odometry(0, 0, 0.5),
        FilterConfig(),
        np.random.default_rng(2),
    )
    assert (nth > -np.pi).all() and (nth <= np.pi).all()


def test_moves_through_walls_or_off_the_map_are_impossible() -> None:
    m = room([{"class": "door", "x": 6, "y": 2}], walls=[{"x1": 3, "y1": 0, "x2": 3, "y2": 4}])
    x0 = np.array([2.5, 2.5, 1.0, 2.0])
    y0 = np.array([2.0, 2.0, 1.0, 2.0])
    x1 = np.array([3.5, 2.8, 1.2, 7.0])  # through the wall, short step, step, off the map
    y1 = np.array([2.0, 2.0, 1.0, 2.0])
    penalty, _ = penalized(x0, y0, x1, y1, m, np.zeros(x0.size))
    assert penalty.tolist() == [-np.inf, 0.0, 0.0, -np.inf]


def test_penalized_weights_are_the_weights_plus_the_penalty() -> None:
    """The filter's one pass: log-weights plus the move's penalty, and whether any is
    left finite (none once every move is impossible)."""
    m = room([{"class": "door", "x": 6, "y": 2}], walls=[{"x1": 3, "y1": 0, "x2": 3, "y2": 4}])
    x0 = np.array([2.5, 2.5, 1.0, 2.0])
    y0 = np.array([2.0, 2.0, 1.0, 2.0])
    x1 = np.array([3.5, 2.8, 1.2, 7.0])
    y1 = np.array([2.0, 2.0, 1.0, 2.0])
    log_w = np.array([-1.5, -0.25, -np.inf, 3.0])
    got, possible = penalized(x0, y0, x1, y1, m, log_w)
    assert got.tolist() == (log_w + penalized(x0, y0, x1, y1, m, np.zeros(4))[0]).tolist()
    assert got.tolist() == [-np.inf, -0.25, -np.inf, -np.inf] and possible
    assert not penalized(x0[[0, 3]], y0[[0, 3]], x1[[0, 3]], y1[[0, 3]], m, log_w[:2])[1]


def test_wall_test_of_long_moves_agrees_with_the_geometry_module() -> None:
    """The compiled crossing test gives the same answer as segments_cross_walls."""
    walls = [
        {"x1": 3, "y1": 0, "x2": 3, "y2": 1.5},
        {"x1": 3, "y1": 2.5, "x2": 3, "y2": 4},
        {"x1": 0, "y1": 2, "x2": 2, "y2": 2},
    ]
    m = room([{"class": "door", "x": 6, "y": 2}], walls=walls)
    rng = np.random.default_rng(5)
    start = m.free_space.sample(5000, rng)
    end = start + rng.normal(0.0, 1.0, start.shape)  # many long moves, some through walls
    zeros = np.zeros(len(start))
    penalty, _ = penalized(start[:, 0], start[:, 1], end[:, 0], end[:, 1], m, zeros)
    expected = m.free_space.is_free(end[:, 0], end[:, 1]) & ~segments_cross_walls(
        start, end, m.walls
    )
    assert np.array_equal(penalty == 0.0, expected)
    assert 100 < np.count_nonzero(~expected) < 4900  # both outcomes are exercised


def test_an_odometry_adding_up_frames_adds_up_their_noise_floors() -> None:
    """Standing still, one step standing for four frames spreads the particles twice as
    far as one frame's (the floors are each frame's own, independent: sqrt(4))."""
    cfg = FilterConfig()
    n = 200_000
    zero = np.zeros(n)
    spread = {}
    for steps in (1, 4):
        x, _, theta = sample_motion(
            zero, zero, zero, Odometry(0.0, 0.0, 0.0), cfg, default_rng(3), steps=steps
        )
        spread[steps] = (float(np.std(x)), float(np.std(theta)))
    assert spread[1][0] == pytest.approx(cfg.trans_noise_floor_m, rel=0.02)
    assert spread[4][0] == pytest.approx(2.0 * spread[1][0], rel=0.02)
    assert spread[4][1] == pytest.approx(2.0 * spread[1][1], rel=0.02)


def test_a_frame_is_implausible_only_faster_than_a_person_on_foot() -> None:
    step = Odometry(0.2, 0.0, 0.3)
    assert not implausible(step, 0.2)
    assert not implausible(None, 0.2)
    jump = Odometry(0.9, 0.2, 0.0)  # 0.92 m in 0.2 s: 4.6 m/s
    assert implausible(jump, 0.2)
    assert not implausible(jump, None)  # no duration: no speed to judge by
    assert not implausible(jump, 0.0)
    # Three frames dropped: 0.8 s lets that much more through; a short frame is held to
    # MIN_JUMP_M.
    reach = MAX_SPEED_M_S * 0.8
    assert not implausible(Odometry(reach - 0.05, 0.0, 0.0), 0.8)
    assert implausible(Odometry(reach + 0.05, 0.0, 0.0), 0.8)
    assert not implausible(Odometry(MIN_JUMP_M - 0.01, 0.0, 0.0), 0.05)
    assert implausible(Odometry(0.0, -(MIN_JUMP_M + 0.01), 0.0), 0.05)
