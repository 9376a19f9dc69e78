"""The geometry bound on systematic bearing errors (app/localization/dilution.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.dilution import (
    PAIRWISE_BLOCK,
    Q99_2D,
    BearingGeometry,
    _frame_sums,
    _frame_sums_reference,
)
from app.localization.sensor import prepare_observation
from app.localization.types import Detection
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared


def room(objects: list[dict]) -> SemanticMap:
    """A 20 m x 20 m walled room with the given objects, prepared."""
    corners = [(0, 0), (20, 0), (20, 20), (0, 20)]
    walls = [
        {"x1": a[0], "y1": a[1], "x2": b[0], "y2": b[1]}
        for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
    ]
    return ensure_prepared(parse_map({"name": "big", "walls": walls, "objects": objects}))


def seen_from(m, x: float, y: float, theta: float, bias_rad: float = 0.0) -> list[Detection]:
    out = []
    for i in range(m.object_count):
        ox, oy = m.object_xy[i]
        out.append(Detection(m.class_of(i), math.atan2(oy - y, ox - x) - theta + bias_rad, 1.0))
    return out


def radius(objects: list[dict], x: float, y: float, frames: int = 5) -> float:
    m = room(objects)
    cfg = FilterConfig(visibility=False)
    geo = BearingGeometry(m, cfg)
    for _ in range(frames):
        obs = prepare_observation(seen_from(m, x, y, 0.0), m, cfg)
        geo.add(x, y, 0.0, obs, None)
    return geo.radius_m(x, y, 0.0)


def test_objects_all_around_pin_the_fix_and_a_narrow_far_cone_does_not() -> None:
    around = [
        {"class": "door", "x": 12.0, "y": 10.0},
        {"class": "window", "x": 10.0, "y": 12.0},
        {"class": "table", "x": 8.0, "y": 10.0},
        {"class": "plant", "x": 10.0, "y": 8.0},
    ]
    cone = [
        {"class": "door", "x": 18.0, "y": 9.0},
        {"class": "window", "x": 18.0, "y": 10.0},
        {"class": "table", "x": 18.0, "y": 11.0},
    ]
    near, far = radius(around, 10.0, 10.0), radius(cone, 10.0, 10.0)
    assert near < 0.3, near
    assert far > 5 * near, (near, far)
    # One object fixes no position.
    assert radius(around[:1], 10.0, 10.0) == math.inf


def test_the_bound_covers_a_real_bias_and_does_not_shrink_with_repetition() -> None:
    """A bias of the assumed size on one object moves the least-squares fix by less than
    the radius; seeing the same thing 20 times gives the same radius as 5 times. (Three
    bearings and three unknowns: 3 degrees on one object moves the fix by metres.)"""
    cone = [
        {"class": "door", "x": 16.0, "y": 8.0},
        {"class": "window", "x": 17.0, "y": 10.0},
        {"class": "table", "x": 15.0, "y": 12.5},
    ]
    r5, r20 = radius(cone, 10.0, 10.0, 5), radius(cone, 10.0, 10.0, 20)
    # Equal but for rounding: the bound's closed form subtracts nearly equal sums (three
    # bearings in a narrow cone make the matrix nearly singular, condition about 1e5),
    # so 20 summands against 5 differ by float64's eps times that, and some.
    assert math.isclose(r5, r20, rel_tol=1e5 * 64 * np.finfo(np.float64).eps)
    # Brute force: the pose best explaining bearings with one object 3 deg off.
    m = room(cone)
    truth = seen_from(m, 10.0, 10.0, 0.0)
    worst = 0.0
    for k in range(3):
        biased = [
            Detection(d.cls, d.bearing_rad + (math.radians(3.0) if i == k else 0.0), 1.0)
            for i, d in enumerate(truth)
        ]
        xs, ys, ts = np.meshgrid(
            np.linspace(0, 20, 201), np.linspace(0, 20, 201), np.radians(np.linspace(-20, 20, 81))
        )
        cost = np.zeros_like(xs)
        for i, d in enumerate(biased):
            ox, oy = m.object_xy[i]
            off = np.arctan2(oy - ys, ox - xs) - ts - d.bearing_rad
            cost += ((off + np.pi) % (2 * np.pi) - np.pi) ** 2
        j = np.unravel_index(np.argmin(cost), cost.shape)
        worst = max(worst, math.hypot(xs[j] - 10.0, ys[j] - 10.0))
    assert worst > 1.0  # the bias does move the fix ...
    assert worst < r5 / Q99_2D * 1.5  # ... by about one std of the bound, not more


def cone_geometry(
    objects: tuple[tuple[float, float], ...], poses: list[tuple[float, float, float]]
) -> tuple[SemanticMap, BearingGeometry]:
    """A room with a door, a window and a table at ``objects``, and the geometry of a
    66-degree camera's views of them from ``poses``."""
    m = room(
        [
            {"class": c, "x": x, "y": y}
            for c, (x, y) in zip(("door", "window", "table"), objects, strict=True)
        ]
    )
    cfg = FilterConfig(visibility=False, fov_deg=66.0)
    geo = BearingGeometry(m, cfg)
    for x, y, t in poses:
        geo.add(x, y, t, prepare_observation(seen_from(m, x, y, t), m, cfg), None)
    return m, geo


def test_the_bound_reaches_as_far_back_along_a_narrow_cone_as_the_bearings_allow() -> None:
    """Stepping back from a few objects in a narrow cone ahead changes their bearings
    far less than stepping towards them: the linearization at the estimate is symmetric
    and too short behind it (paper_office seed 3, a 66-degree camera: 0.48 m where a
    fix 1.03 m off kept the bearings within the bias). The bound reaches at least as
    far back as a walk moved rigidly there keeps every bearing within the bias."""
    poses = [(10.0 + 0.1 * k, 10.0, 0.0) for k in range(10)]
    m, geo = cone_geometry(((15.0, 9.0), (15.0, 11.0), (17.0, 10.0)), poses)
    x, y, _ = poses[-1]
    r = geo.reach_m(x, y, geo.radius_m(x, y, 0.0))

    def mean_square(back_m: float) -> float:
        """The mean over frames of the squared bearing changes with the walk moved back
        by ``back_m`` and turned about the last pose by the best of a fine grid."""
        turn = np.radians(np.arange(-10.0, 10.0, 0.01))  # every turn of the grid at once
        c, s = np.cos(turn), np.sin(turn)
        total = np.zeros_like(turn)
        for px, py, _ in poses:
            qx = x + c * (px - x) - s * (py - y) - back_m
            qy = y + s * (px - x) + c * (py - y)
            for ox, oy in m.object_xy:
                change = np.arctan2(oy - qy, ox - qx) - turn - math.atan2(oy - py, ox - px)
                total += change * change
        return float(total.min()) / len(poses)

    limit = (Q99_2D * geo.bias_rad) ** 2
    linear = Q99_2D * geo.bias_rad / math.sqrt(_weakest(geo, x, y))
    reach = 0.0
    while mean_square(reach + 0.1) <= limit:
        reach += 0.1
    assert reach > 1.2 * linear, (linear, reach)
    assert r >= 0.95 * reach, (r, reach)  # the search halves the last step 5 times


def _weakest(geo: BearingGeometry, x: float, y: float) -> float:
    """The linearized information along the weakest direction (the Schur complement's
    smaller eigenvalue), from the frames' rows."""
    info = np.zeros((3, 3))
    for fx, fy, rows in geo._frames:
        a, b, w = rows[:, 0], rows[:, 1], rows[:, 2]
        c = -1.0 - a * (fy - y) + b * (fx - x)
        j = np.stack([a, b, c], axis=1)
        info += (j * w[:, None]).T @ j
    info /= len(geo._frames)
    schur = info[:2, :2] - np.outer(info[:2, 2], info[2, :2]) / info[2, 2]
    return float(np.linalg.eigvalsh(schur)[0])


def test_the_compiled_ridge_search_is_its_numpy_reference() -> None:
    """The compiled search (:func:`dilution._ridge`) takes the reference's steps: the
    same reach along every ray, to float64 rounding; and a 360-degree camera, with
    objects on every side, is not searched at all."""
    poses = [(10.0 + 0.1 * k, 10.0 + 0.02 * k, 0.05) for k in range(12)]
    m, geo = cone_geometry(((15.0, 9.0), (15.0, 11.5), (18.0, 10.5)), poses)
    x, y, _ = poses[-1]
    points = geo._points()
    linear = 0.5
    for angle in np.radians(np.arange(0.0, 180.0, 22.5)):
        ux, uy = math.cos(angle), math.sin(angle)
        want = geo._ridge_reference(x, y, ux, uy, linear)
        got = geo._ridge_m(points, x, y, ux, uy, linear)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), (angle, got, want)
    wide = BearingGeometry(m, FilterConfig(visibility=False))
    assert wide.reach_m(x, y, 0.3) == 0.3


def test_the_compiled_frame_sums_are_numpys_to_the_last_bit() -> None:
    """A frame's sums (:func:`dilution._frame_sums`, compiled up to numpy's pairwise
    block, numpy's beyond it) are the numpy reference's bits: rows from none to past
    the block, magnitudes over eight decades, signed zeros, read-only rows too."""
    rng = np.random.default_rng(7)
    for k in range(3000):
        n = int(rng.integers(0, PAIRWISE_BLOCK + 20)) if k % 10 == 0 else int(rng.integers(0, 40))
        rows = rng.standard_normal((n, 3)) * 10.0 ** rng.uniform(-4.0, 4.0, (n, 3))
        if n and k % 5 == 0:
            rows[rng.integers(0, n), rng.integers(0, 3)] = -0.0
        if k % 3 == 0:
            rows.flags.writeable = False
        fx, fy = float(rng.normal(0.0, 30.0)), float(rng.normal(0.0, 30.0))
        got = np.array(_frame_sums(fx, fy, rows))
        want = np.array(_frame_sums_reference(fx, fy, rows))
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), (n, got, want)


def test_the_kept_means_are_the_frames_sums_averaged_until_a_frame_comes_or_goes() -> None:
    _, geo = cone_geometry(
        ((15.0, 9.0), (15.0, 11.5), (18.0, 10.5)),
        [(10.0 + 0.1 * k, 10.0 + 0.02 * k, 0.05) for k in range(25)],
    )
    frames = len(geo._sums)
    assert frames == geo._frames.maxlen  # the window is full: frames have gone too
    want = tuple(sum(column) / frames for column in zip(*geo._sums, strict=True))
    assert geo._means() == want
    geo.shift_x(3.0)
    shifted = tuple(sum(column) / frames for column in zip(*geo._sums, strict=True))
    assert shifted != want and geo._means() == shifted
    geo.clear_frames()
    assert geo._sum_means is None
