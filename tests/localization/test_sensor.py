"""The sensor model of eqs. (2)-(3) and its additions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.bench import generated_map
from app.localization.config import FilterConfig
from app.localization.sensor import (
    candidate_mask,
    log_likelihood_reference,
    normalized_residuals,
    prepare_observation,
)
from app.localization.sensor_kernel import log_likelihood
from app.localization.types import Detection, Pose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap, parse_map
from app.simulation.camera import CameraModel, visible_objects
from tests.localization.conftest import room

#: Detections that match nothing in particular (false or far-off ones), one per class.
CLASS_BEARINGS = [("door", 0.5), ("window", -2.5), ("table", 3.0)]


def observe(
    m: SemanticMap, x: float, y: float, theta: float, fov: float = 360.0
) -> list[Detection]:
    idx, bearing = visible_objects(m, Pose(x, y, theta), CameraModel(fov))
    return [Detection(m.class_of(int(i)), float(b)) for i, b in zip(idx, bearing, strict=True)]


def loglik(m, cfg, x, y, th, dets, *, kernel: bool = True) -> np.ndarray:
    x, y, th = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (x, y, th))
    obs = prepare_observation(dets, m, cfg)
    if kernel:
        grid = m.visibility if cfg.visibility else None
        return log_likelihood(x, y, th, obs, m, cfg, grid)
    rows = m.visibility.visible(x, y) if cfg.visibility else None
    return log_likelihood_reference(x, y, th, obs, m, cfg, rows)


@pytest.mark.parametrize("cfg", [FilterConfig(), FilterConfig.paper()], ids=["bearings", "paper"])
def test_likelihood_peaks_at_the_true_pose(small_room: SemanticMap, cfg: FilterConfig) -> None:
    truth = (2.5, 1.5, 0.4)
    dets = observe(small_room, *truth)
    rng = np.random.default_rng(0)
    pts = small_room.free_space.sample(3000, rng)
    th = rng.uniform(-np.pi, np.pi, 3000)
    others = loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, dets)
    at_truth = loglik(small_room, cfg, *truth, dets)[0]
    assert at_truth >= others.max() - 1e-9
    # Small displacements are worse than the truth as well.
    for dx, dy, dth in [(0.2, 0, 0), (0, -0.2, 0), (0, 0, 0.05)]:
        assert (
            loglik(small_room, cfg, truth[0] + dx, truth[1] + dy, truth[2] + dth, dets)[0]
            < at_truth
        )


@settings(max_examples=25, deadline=None)
@given(
    angle=st.floats(-np.pi, np.pi),
    shift=st.tuples(st.floats(-20, 20), st.floats(-20, 20)),
    px=st.floats(0.5, 5.5),
    py=st.floats(0.5, 3.5),
    pth=st.floats(-np.pi, np.pi),
)
def test_moving_world_and_person_together_changes_nothing(angle, shift, px, py, pth) -> None:
    """Rigidly transform map and particle alike: the likelihood is unchanged."""
    objects = [(6, 3, "door"), (1.5, 0, "window"), (4.5, 0, "window"), (2, 2.5, "table")]
    c, s = np.cos(angle), np.sin(angle)

    def tf(x: float, y: float) -> tuple[float, float]:
        return c * x - s * y + shift[0], s * x + c * y + shift[1]

    dets = [
        Detection("door", 0.3),
        Detection("window", -1.0),
        Detection("window", 2.0),
        Detection("table", 1.2, 0.7),
    ]
    cfg = FilterConfig.paper()
    m1 = parse_map({"name": "a", "objects": [{"class": k, "x": x, "y": y} for x, y, k in objects]})
    m2 = parse_map(
        {
            "name": "b",
            "objects": [{"class": k, "x": tf(x, y)[0], "y": tf(x, y)[1]} for x, y, k in objects],
        }
    )
    a = loglik(m1, cfg, px, py, pth, dets)[0]
    qx, qy = tf(px, py)
    b = loglik(m2, cfg, qx, qy, pth + angle, dets)[0]
    assert np.isclose(a, b, rtol=1e-6, atol=1e-6)


def test_score_zero_detection_changes_nothing(small_room: SemanticMap) -> None:
    cfg = FilterConfig()
    rng = np.random.default_rng(1)
    pts = small_room.free_space.sample(500, rng)
    th = rng.uniform(-np.pi, np.pi, 500)
    base = [Detection("door", 0.5), Detection("window", -2.0)]
    with_zero = [*base, Detection("table", 1.0, 0.0), Detection("window", 0.1, 0.0)]
    assert np.allclose(
        loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, base),
        loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, with_zero),
    )


def test_unknown_class_is_ignored(small_room: SemanticMap) -> None:
    cfg = FilterConfig()
    obs = prepare_observation([Detection("sofa", 0.3), Detection("door", 0.1)], small_room, cfg)
    assert obs.ignored == ("sofa",)
    assert obs.classes == ("door",)
    a = loglik(small_room, cfg, [2, 3], [2, 1], [0, 1], [Detection("door", 0.1)])
    b = loglik(
        small_room, cfg, [2, 3], [2, 1], [0, 1], [Detection("door", 0.1), Detection("sofa", 2)]
    )
    assert np.allclose(a, b)


def test_each_class_is_weighted_by_one_over_its_count() -> None:
    """Eq. (2): doubling a class's detections leaves its total weight unchanged."""
    m = room(
        [
            {"class": "window", "x": 1, "y": 0},
            {"class": "window", "x": 5, "y": 0},
            {"class": "door", "x": 6, "y": 2},
        ]
    )
    cfg = FilterConfig.paper()
    x, y, th = np.array([3.0, 2.0]), np.array([2.0, 1.0]), np.array([0.3, -0.5])
    one = loglik(m, cfg, x, y, th, [Detection("window", -0.9)])
    two = loglik(m, cfg, x, y, th, [Detection("window", -0.9), Detection("window", -0.9)])
    assert np.allclose(one, two)
    # Numerically: with two different windows, the class term is the mean of the two.
    a = loglik(m, cfg, x, y, th, [Detection("window", -0.9)])
    b = loglik(m, cfg, x, y, th, [Detection("window", -2.4)])
    both = loglik(m, cfg, x, y, th, [Detection("window", -0.9), Detection("window", -2.4)])
    assert np.allclose(both, (a + b) / 2)
    # Classes multiply (logs add), eq. (2).
    door = loglik(m, cfg, x, y, th, [Detection("door", 0.2)])
    mixed = loglik(m, cfg, x, y, th, [Detection("window", -0.9), Detection("door", 0.2)])
    assert np.allclose(mixed, a + door)


def test_door_behind_a_wall_cannot_be_matched() -> None:
    # An inner wall at x = 3 hides the west door from the east half of the room.
    m = room(
        [{"class": "door", "x": 0, "y": 2}, {"class": "window", "x": 4.5, "y": 0}],
        walls=[{"x1": 3, "y1": 0, "x2": 3, "y2": 4}],
    )
    towards_door = np.pi  # facing west, the door would be straight ahead
    dets = [Detection("door", 0.0)]
    vis = loglik(m, FilterConfig(clutter=False), 4.5, 2.0, towards_door, dets)
    assert vis[0] == -np.inf
    floor = loglik(m, FilterConfig(), 4.5, 2.0, towards_door, dets)
    assert np.isfinite(floor[0]) and floor[0] < -3  # only the clutter floor explains it
    paper = loglik(m, FilterConfig.paper(), 4.5, 2.0, towards_door, dets)
    assert paper[0] > -1e-6  # the paper's model ignores walls and matches it perfectly


def test_field_of_view_limits_candidates(small_room: SemanticMap) -> None:
    # Facing +x at (2, 1.5): the window at (1.5, 0) is behind-right, outside a 180 deg view.
    dets = [Detection("window", np.radians(-108.4))]
    wide = loglik(small_room, FilterConfig(fov_deg=360, clutter=False), 2.0, 1.5, 0.0, dets)
    narrow = loglik(small_room, FilterConfig(fov_deg=180, clutter=False), 2.0, 1.5, 0.0, dets)
    assert wide[0] > -1.0
    assert narrow[0] < wide[0]


@pytest.mark.parametrize(
    "cfg",
    [
        FilterConfig(),
        FilterConfig.paper(),
        FilterConfig(fov_deg=180),
        FilterConfig(clutter=False),
        FilterConfig(max_range_m=3.0, bearing_std_deg=5.0),
    ],
)
def test_compiled_kernel_matches_the_numpy_reference(paper_office: SemanticMap, cfg) -> None:
    rng = np.random.default_rng(5)
    pts = paper_office.free_space.sample(400, rng)
    th = rng.uniform(-np.pi, np.pi, 400)
    dets = observe(paper_office, 3.0, 2.0, 0.7, 270)
    dets += [Detection("table", 2.0, 0.4), Detection("door", -1.0, 0.6)]
    fast = loglik(paper_office, cfg, pts[:, 0], pts[:, 1], th, dets)
    ref = loglik(paper_office, cfg, pts[:, 0], pts[:, 1], th, dets, kernel=False)
    finite = np.isfinite(ref)
    assert np.array_equal(finite, np.isfinite(fast))
    # The kernel works in float32 (with polynomial sine, cosine and softplus): its
    # log-likelihoods match the float64 reference within 1e-3 (weights within 0.1 %).
    assert np.abs(fast[finite] - ref[finite]).max() < 1e-3


@pytest.mark.parametrize(
    "cfg",
    [FilterConfig(), FilterConfig(fov_deg=200.0, max_range_m=6.0), FilterConfig.paper()],
    ids=["bearings", "fov-range", "paper"],
)
def test_compiled_kernel_matches_the_reference_on_a_map_of_many_objects(cfg) -> None:
    """150 objects: visibility bits span three 64-bit words; particles span many blocks."""
    m = generated_map(150, seed=3)
    rng = np.random.default_rng(6)
    pts = m.free_space.sample(1000, rng)
    th = rng.uniform(-np.pi, np.pi, 1000)
    dets = observe(m, 7.3, 4.1, -2.0) + [Detection(c, b, 0.7) for c, b in CLASS_BEARINGS]
    fast = loglik(m, cfg, pts[:, 0], pts[:, 1], th, dets)
    ref = loglik(m, cfg, pts[:, 0], pts[:, 1], th, dets, kernel=False)
    finite = np.isfinite(ref)
    assert np.array_equal(finite, np.isfinite(fast))
    # Within 1e-3 where weights matter; float32 cosines leave a relative error of about
    # 1e-6 on hopeless particles (log-likelihood -900: weight e^-900 either way).
    err = np.abs(fast[finite] - ref[finite])
    assert (err <= 1e-3 + 1e-5 * np.abs(ref[finite])).all()
    assert err[ref[finite] > ref[finite].max() - 20.0].max() < 1e-3
    assert np.ptp(ref[finite]) > 1.0  # the particles really differ


@pytest.mark.parametrize(
    "cfg",
    [FilterConfig(), FilterConfig(fov_deg=180.0, max_range_m=3.0), FilterConfig.paper()],
    ids=["bearings", "fov-range", "paper"],
)
def test_residuals_are_bearing_errors_to_the_best_visible_object(
    small_room: SemanticMap, cfg: FilterConfig
) -> None:
    """Against a brute force over the candidates of candidate_mask, at many poses."""
    rng = np.random.default_rng(4)
    dets = [
        Detection("door", 0.4),
        Detection("window", -2.0),
        Detection("window", 2.9),
        Detection("table", -0.2),
    ]
    obs = prepare_observation(dets, small_room, cfg)
    grid = small_room.visibility
    pts = small_room.free_space.sample(200, rng)
    for (x, y), th in zip(pts, rng.uniform(-np.pi, np.pi, 200), strict=True):
        row = grid.visible(x, y)[0]
        got = normalized_residuals(x, y, th, obs, small_room, cfg, row)
        for k in range(len(dets)):  # in the observation's (grouped) order
            cls, bearing = obs.classes[obs.det_group[k]], obs.det_bearing[k]
            objs = small_room.class_members[cls]
            ok = candidate_mask(
                np.array([x]), np.array([y]), np.array([th]), objs, small_room, cfg, row[None]
            )[0]
            rel = small_room.object_xy[objs[ok]] - [x, y]
            err = np.abs(wrap_angle(bearing - (np.arctan2(rel[:, 1], rel[:, 0]) - th)))
            want = err.min() / cfg.bearing_std_rad(cls) if ok.any() else np.inf
            assert got[k] == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_residuals_are_zero_at_the_true_pose_and_three_for_a_three_sigma_error(
    small_room: SemanticMap,
) -> None:
    cfg = FilterConfig()
    truth = (2.5, 1.5, 0.4)
    dets = observe(small_room, *truth)
    obs = prepare_observation(dets, small_room, cfg)
    assert np.allclose(normalized_residuals(*truth, obs, small_room, cfg), 0.0, atol=1e-9)
    off = [Detection(d.cls, d.bearing_rad + 3 * cfg.bearing_std_rad(d.cls)) for d in dets[:1]]
    r = normalized_residuals(*truth, prepare_observation(off, small_room, cfg), small_room, cfg)
    assert r[0] == pytest.approx(3.0, abs=1e-6)
