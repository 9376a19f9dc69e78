"""The sensor model of eqs. (2)-(3) and its additions."""

from __future__ import annotations

from dataclasses import replace

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
    scaled_bessel_i0,
    spread_match,
)
from app.localization.sensor_kernel import log_likelihood
from app.localization.tolerances import (
    U64,
    candidate_flip_mask,
    log_likelihood_tolerance,
)
from app.localization.types import Detection, Pose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared
from app.simulation.camera import CameraModel, visible_objects
from tests.helpers import room

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


def tol(m, cfg, x, y, th, dets, value) -> np.ndarray:
    """How far the kernel's ``value`` may be from the exact log-likelihood (derived)."""
    x, y, th = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (x, y, th))
    return log_likelihood_tolerance(x, y, th, prepare_observation(dets, m, cfg), m, cfg, value)


def agree(m, cfg, x, y, th, a_dets, b_dets, a, b) -> bool:
    """Two kernel results the exact arithmetic makes equal, each within its bound."""
    a_tol, b_tol = tol(m, cfg, x, y, th, a_dets, a), tol(m, cfg, x, y, th, b_dets, b)
    return bool((np.abs(a - b) <= a_tol + b_tol).all())


def bearing_tolerance(m: SemanticMap, x: float, y: float, obs, cfg: FilterConfig) -> float:
    """float64 residuals (compiled and numpy): two bearings' rounding, in class sigmas."""
    objs = m.object_xy[np.unique(obs.members)]
    distance = np.hypot(objs[:, 0] - x, objs[:, 1] - y).min()
    coordinate = np.hypot(x, y) + np.hypot(objs[:, 0], objs[:, 1]).max()
    # atan2 within an ulp or two, and the wrap of an angle up to 3 pi: 4 roundings of 2 pi.
    bearing = U64 * (coordinate + distance) / distance + 4 * U64 * 2 * np.pi
    return float(2 * bearing / min(cfg.bearing_std_rad(c) for c in obs.classes))


@pytest.mark.parametrize("cfg", [FilterConfig(), FilterConfig.paper()], ids=["bearings", "paper"])
def test_likelihood_peaks_at_the_true_pose(small_room: SemanticMap, cfg: FilterConfig) -> None:
    truth = (2.5, 1.5, 0.4)
    dets = observe(small_room, *truth)
    rng = np.random.default_rng(0)
    pts = small_room.free_space.sample(3000, rng)
    th = rng.uniform(-np.pi, np.pi, 3000)
    others = loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, dets)
    at_truth = loglik(small_room, cfg, *truth, dets)[0]
    truth_tol = tol(small_room, cfg, *truth, dets, at_truth)[0]
    # Exactly, nothing beats the truth; computed, within both results' rounding bounds.
    others_tol = tol(small_room, cfg, pts[:, 0], pts[:, 1], th, dets, others)
    assert (others - others_tol <= at_truth + truth_tol).all()
    # Small displacements are worse than the truth as well, by more than the rounding.
    for dx, dy, dth in [(0.2, 0, 0), (0, -0.2, 0), (0, 0, 0.05)]:
        moved = (truth[0] + dx, truth[1] + dy, truth[2] + dth)
        worse = loglik(small_room, cfg, *moved, dets)[0]
        assert worse + tol(small_room, cfg, *moved, dets, worse)[0] < at_truth - truth_tol


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
    # Exactly equal; each computed value within its own bound (float32 rounds positions
    # far from the origin more coarsely, so the bound follows the shift).
    a_tol, b_tol = tol(m1, cfg, px, py, pth, dets, a), tol(m2, cfg, qx, qy, pth + angle, dets, b)
    assert abs(a - b) <= a_tol[0] + b_tol[0]


def test_score_zero_detection_changes_nothing(small_room: SemanticMap) -> None:
    cfg = FilterConfig()
    rng = np.random.default_rng(1)
    pts = small_room.free_space.sample(500, rng)
    th = rng.uniform(-np.pi, np.pi, 500)
    base = [Detection("door", 0.5), Detection("window", -2.0)]
    with_zero = [*base, Detection("table", 1.0, 0.0), Detection("window", 0.1, 0.0)]
    a = loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, base)
    b = loglik(small_room, cfg, pts[:, 0], pts[:, 1], th, with_zero)
    assert agree(small_room, cfg, pts[:, 0], pts[:, 1], th, base, with_zero, a, b)


def test_unknown_class_is_ignored(small_room: SemanticMap) -> None:
    cfg = FilterConfig()
    obs = prepare_observation([Detection("sofa", 0.3), Detection("door", 0.1)], small_room, cfg)
    assert obs.ignored == ("sofa",)
    assert obs.classes == ("door",)
    door, with_sofa = [Detection("door", 0.1)], [Detection("door", 0.1), Detection("sofa", 2)]
    a = loglik(small_room, cfg, [2, 3], [2, 1], [0, 1], door)
    b = loglik(small_room, cfg, [2, 3], [2, 1], [0, 1], with_sofa)
    assert agree(small_room, cfg, [2, 3], [2, 1], [0, 1], door, with_sofa, a, b)


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
    w1, w2, d = Detection("window", -0.9), Detection("window", -2.4), Detection("door", 0.2)

    def ll(dets: list[Detection]) -> tuple[np.ndarray, np.ndarray]:
        value = loglik(m, cfg, x, y, th, dets)
        return value, tol(m, cfg, x, y, th, dets, value)

    (one, t_one), (two, t_two) = ll([w1]), ll([w1, w1])
    assert (np.abs(one - two) <= t_one + t_two).all()
    # Numerically: with two different windows, the class term is the mean of the two.
    (a, t_a), (b, t_b), (both, t_both) = ll([w1]), ll([w2]), ll([w1, w2])
    assert (np.abs(both - (a + b) / 2) <= t_both + (t_a + t_b) / 2).all()
    # Classes multiply (logs add), eq. (2).
    (door, t_door), (mixed, t_mixed) = ll([d]), ll([w1, d])
    assert (np.abs(mixed - (a + door)) <= t_mixed + t_a + t_door).all()
    assert np.abs(mixed - a).min() > 1.0  # the door really adds something


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
    # The paper's model ignores walls and matches it perfectly: 0 up to float32 rounding.
    assert paper[0] >= -tol(m, FilterConfig.paper(), 4.5, 2.0, towards_door, dets, paper)[0]


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
        FilterConfig(object_spread_m=0.3),
        FilterConfig(object_spread_m=0.5, fov_deg=66.0, likelihood_bias_deg=3.0),
        FilterConfig(object_spread_m=0.3, clutter=False, bearing_std_deg=20.0),
    ],
)
def test_compiled_kernel_matches_the_numpy_reference(paper_office: SemanticMap, cfg) -> None:
    rng = np.random.default_rng(5)
    pts = paper_office.free_space.sample(400, rng)
    th = rng.uniform(-np.pi, np.pi, 400)
    dets = observe(paper_office, 3.0, 2.0, 0.7, 270)
    dets += [Detection("table", 2.0, 0.4), Detection("door", -1.0, 0.6)]
    assert_kernel_matches_reference(paper_office, cfg, pts[:, 0], pts[:, 1], th, dets)


def assert_kernel_matches_reference(m, cfg, x, y, th, dets) -> None:
    """The float32 kernel within its derived bound of the float64 reference, per particle.

    Particles with an object within rounding of the field-of-view or range edge may
    see a different candidate set; they are left out, and must be rare.
    """
    fast = loglik(m, cfg, x, y, th, dets)
    ref = loglik(m, cfg, x, y, th, dets, kernel=False)
    obs = prepare_observation(dets, m, cfg)
    sure = ~candidate_flip_mask(x, y, th, obs, m, cfg)
    assert np.count_nonzero(~sure) <= max(1, x.size // 100)
    finite = np.isfinite(ref)
    assert np.array_equal(finite[sure], np.isfinite(fast[sure]))
    ok = sure & finite
    bound = log_likelihood_tolerance(x[ok], y[ok], th[ok], obs, m, cfg, ref[ok])
    assert (np.abs(fast[ok] - ref[ok]) <= bound).all()
    # The bound is tight enough to mean something: where weights matter (within 20 of
    # the best log-likelihood) it keeps them within 5 % (1 % for a typical particle;
    # more only right next to an object, where float32 directions really are coarse).
    near_best = ref[ok] > ref[ok].max() - 20.0
    assert bound[near_best].max() < 0.05 and np.median(bound[near_best]) < 0.01
    assert np.ptp(ref[finite]) > 1.0  # the particles really differ


@pytest.mark.parametrize(
    "cfg",
    [
        FilterConfig(),
        FilterConfig(fov_deg=200.0, max_range_m=6.0),
        FilterConfig.paper(),
        FilterConfig(object_spread_m=0.3),
    ],
    ids=["bearings", "fov-range", "paper", "spread"],
)
def test_compiled_kernel_matches_the_reference_on_a_map_of_many_objects(cfg) -> None:
    """150 objects: visibility bits span three 64-bit words; particles span many blocks."""
    m = generated_map(150, seed=3)
    rng = np.random.default_rng(6)
    pts = m.free_space.sample(1000, rng)
    th = rng.uniform(-np.pi, np.pi, 1000)
    dets = observe(m, 7.3, 4.1, -2.0) + [Detection(c, b, 0.7) for c, b in CLASS_BEARINGS]
    assert_kernel_matches_reference(m, cfg, pts[:, 0], pts[:, 1], th, dets)


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
        within = bearing_tolerance(small_room, x, y, obs, cfg)
        for k in range(len(dets)):  # in the observation's (grouped) order
            cls, bearing = obs.classes[obs.det_group[k]], obs.det_bearing[k]
            objs = small_room.class_members[cls]
            ok = candidate_mask(
                np.array([x]), np.array([y]), np.array([th]), objs, small_room, cfg, row[None]
            )[0]
            rel = small_room.object_xy[objs[ok]] - [x, y]
            err = np.abs(wrap_angle(bearing - (np.arctan2(rel[:, 1], rel[:, 0]) - th)))
            want = err.min() / cfg.bearing_std_rad(cls) if ok.any() else np.inf
            assert got[k] == pytest.approx(want, rel=0, abs=within)


def test_residuals_are_zero_at_the_true_pose_and_three_for_a_three_sigma_error(
    small_room: SemanticMap,
) -> None:
    cfg = FilterConfig()
    truth = (2.5, 1.5, 0.4)
    dets = observe(small_room, *truth)
    obs = prepare_observation(dets, small_room, cfg)
    within = bearing_tolerance(small_room, *truth[:2], obs, cfg)
    assert np.abs(normalized_residuals(*truth, obs, small_room, cfg)).max() <= within
    off = [Detection(d.cls, d.bearing_rad + 3 * cfg.bearing_std_rad(d.cls)) for d in dets[:1]]
    r = normalized_residuals(*truth, prepare_observation(off, small_room, cfg), small_room, cfg)
    assert r[0] == pytest.approx(3.0, rel=0, abs=within)


def test_a_likelihood_bias_counts_a_share_of_each_class_log_likelihood(
    small_room: SemanticMap,
) -> None:
    dets = observe(small_room, 2.5, 1.5, 0.4)
    per_class = {"table": 4.0}
    narrow = FilterConfig(class_bearing_std_deg=per_class, fov_deg=120.0)
    bare = prepare_observation(dets, small_room, narrow)
    cfg = replace(narrow, likelihood_bias_deg=3.0)
    part = prepare_observation(dets, small_room, cfg)
    # A wide camera's objects lie on every side: the bare noise weighs them.
    wide = prepare_observation(dets, small_room, replace(cfg, fov_deg=180.0))
    assert np.array_equal(wide.group_weight, bare.group_weight)
    assert bare.classes == part.classes and len(part.classes) >= 2
    # What counts as explained stays where the noise puts it.
    assert np.array_equal(bare.group_kappa, part.group_kappa)
    assert np.array_equal(bare.group_log_floor, part.group_log_floor)
    for g, cls in enumerate(part.classes):
        std = per_class.get(cls, 2.0)
        share = std**2 / (std**2 + 9.0)
        assert part.group_weight[g] == pytest.approx(bare.group_weight[g] * share, rel=4 * U64)


def test_a_likelihood_bias_shrinks_the_gap_between_nearby_poses_by_the_std_ratio(
    small_room: SemanticMap,
) -> None:
    """A pose a steady bias favours no longer buries the truth: the gap between two
    poses' log-likelihoods shrinks by std^2 / (std^2 + bias^2), 4 / 13 for 2 and 3
    degrees, as a Gaussian widened by the bias would weigh it."""
    truth, near = (2.5, 1.5, 0.4), (2.9, 1.3, 0.45)
    dets = observe(small_room, *truth, fov=120.0)
    bare = FilterConfig(fov_deg=120.0)
    part = replace(bare, likelihood_bias_deg=3.0)
    gaps = []
    slack = 0.0
    for cfg in (bare, part):
        a, b = loglik(small_room, cfg, *truth, dets), loglik(small_room, cfg, *near, dets)
        gaps.append(float(a[0] - b[0]))
        slack += float(
            tol(small_room, cfg, *truth, dets, a)[0] + tol(small_room, cfg, *near, dets, b)[0]
        )
    assert gaps[0] > 10 * slack  # the bare model tells the two apart
    assert gaps[1] == pytest.approx(gaps[0] * 4.0 / 13.0, rel=0, abs=slack)


@pytest.mark.parametrize("std_deg", [2.0, 5.0])
def test_a_spread_match_is_a_wider_von_mises_relative_to_the_class_peak(std_deg: float) -> None:
    """kappa (match - 1) is the log-density of a von Mises of concentration kappa r, r =
    d^2 / (d^2 + kappa s^2), relative to the class's own peak: exact but for the Bessel
    function's ratio, taken as r^-1/2 (its error about 1 / (8 kappa r) for kappa r of 10
    and more: bounded by twice that)."""
    kappa = 1.0 / np.radians(std_deg) ** 2
    err = np.radians(np.linspace(-40.0, 40.0, 81))
    for d, s in [(1.0, 0.3), (3.0, 0.3), (8.0, 0.5), (2.0, 0.0)]:
        match = spread_match(np.cos(err), np.array(d * d), np.array(kappa), np.array(s * s))
        r = d * d / (d * d + kappa * s * s)
        exact = kappa * r * (np.cos(err) - 1.0) + np.log(
            scaled_bessel_i0(kappa) / scaled_bessel_i0(kappa * r)
        )
        assert kappa * r >= 10.0
        assert np.abs(kappa * (match - 1.0) - exact).max() <= 1.0 / (4.0 * kappa * r)
        if s == 0.0:
            assert np.array_equal(match, np.cos(err))  # a fixed object: the cosine itself


def test_a_moved_table_seen_close_pulls_the_pose_less_with_a_spread() -> None:
    """A table 0.7 m along from where it was drawn, 1 m from the person, and three fixed
    objects 5-7 m off: at the bare noise the best pose along the walk follows the table
    most of the way; with movable objects' places uncertain (0.3 m) it stays near the
    truth, and a fixed object (a door) is weighed as before."""
    drawn = [(8.0, 4.0, "door"), (8.0, -2.0, "window"), (-3.0, 4.0, "window"), (3.0, 1.0, "table")]
    m = ensure_prepared(
        parse_map({"name": "moved", "objects": [{"class": k, "x": x, "y": y} for x, y, k in drawn]})
    )
    truth = (3.0, 0.0, 0.0)
    seen = [*drawn[:3], (3.7, 1.0, "table")]
    dets = [Detection(k, float(np.arctan2(y - truth[1], x - truth[0]))) for x, y, k in seen]
    xs = np.linspace(1.5, 4.5, 301)
    zeros = np.zeros_like(xs)
    best = {}
    for spread in (0.0, 0.3):
        cfg = FilterConfig(object_spread_m=spread)
        ll = loglik(m, cfg, xs, zeros, zeros, dets)
        best[spread] = abs(float(xs[np.argmax(ll)]) - truth[0])
    assert best[0.0] > 0.5
    assert best[0.3] < 0.5 * best[0.0]
    doors = [Detection("door", float(np.arctan2(4.0, 5.0)))]
    plain = loglik(m, FilterConfig(), xs, zeros, zeros, doors)
    spread_cfg = FilterConfig(object_spread_m=0.3)
    assert np.array_equal(plain, loglik(m, spread_cfg, xs, zeros, zeros, doors))
