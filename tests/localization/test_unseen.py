"""The unseen-object check: its compiled frame count against the vectorized numpy form."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from app.bench import CLASSES, generated_map
from app.localization.config import FilterConfig
from app.localization.sensor import prepare_observation
from app.localization.types import Detection
from app.localization.unseen import DEFAULT_UNSEEN, UnseenObjects
from app.maps.geometry import wrap_angle


def _numpy_counts(
    unseen: UnseenObjects, x: float, y: float, theta: float, obs, row
) -> tuple[np.ndarray, np.ndarray, int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One frame counted as the vectorized numpy code did (before it was compiled)."""
    st, sm, cfg = unseen.settings, unseen.map, unseen.config
    index = {c: i for i, c in enumerate(sm.classes)}
    group_class = np.array([index[c] for c in obs.classes], dtype=np.int64)
    reported = unseen.reported.copy()
    reported[group_class] = True
    reach_m = unseen.reach_m.copy()
    dx, dy = sm.object_xy[:, 0] - x, sm.object_xy[:, 1] - y
    dist = np.hypot(dx, dy)
    bearing = wrap_angle(np.arctan2(dy, dx) - theta)
    cls = sm.object_class
    view = (dist <= st.near_m) & (dist >= st.min_m) & reported[cls]
    if row is not None and cfg.visibility:
        view &= row
    if cfg.fov_deg < 360.0:
        off_centre = np.abs(wrap_angle(bearing - np.radians(cfg.fov_centre_deg)))
        view &= off_centre <= np.radians(cfg.fov_deg) / 2.0 - st.margin_rad
    in_view = np.flatnonzero(view)
    same = cls[in_view][:, None] == group_class[obs.det_group][None, :]
    err = np.abs(wrap_angle(obs.det_bearing[None, :] - bearing[in_view][:, None]))
    within = st.cutoff_sigmas / np.sqrt(obs.group_kappa[obs.det_group])
    seen = np.zeros(sm.object_count, dtype=bool)
    seen[in_view] = (same & (err <= within[None, :])).any(axis=1)
    # A near miss: a detection of its class within near_miss_rad but outside the angle
    # the object's extent subtends, none seeing it.
    extent = np.arctan2(st.extent_m, dist[in_view])[:, None]
    close = np.zeros(sm.object_count, dtype=bool)
    close[in_view] = (same & (err <= st.near_miss_rad) & (err > extent)).any(axis=1)
    np.maximum.at(reach_m, cls[seen], dist[seen])
    reach = np.where(reach_m > 0.0, reach_m, reach_m.max())
    clear = view & (dist <= reach[cls])
    expected = st.decay * unseen.expected + clear
    seen_count = st.decay * unseen.seen + (clear & seen)
    near = st.decay * unseen.near + (clear & close & ~seen)
    missed = int(np.count_nonzero(clear & ~seen))
    # The hit rate's sums: the objects in clear view that the detector does report now
    # and then, one at a time (as the kernel adds them).
    # Per band of distance.
    band = np.minimum((dist / st.band_m).astype(np.int64), unseen.bands - 1)
    rate = unseen.rate_sums * st.rate_decay
    for i in np.flatnonzero(clear & (seen_count > st.max_seen_share * expected)):
        rate[band[i], 0] += 1.0
        rate[band[i], 1] += 1.0 if seen[i] else 0.0
    # The misses weighed by their band's miss rate, after this frame's sums.
    pooled = (rate[:, 1].sum() + st.rate_prior * st.rate_prior_frames) / (
        rate[:, 0].sum() + st.rate_prior_frames
    )
    hit = (rate[:, 1] + pooled * st.band_prior_frames) / (rate[:, 0] + st.band_prior_frames)
    miss_rate = np.clip(1.0 - hit, 1e-6, 1.0 - 1e-9)
    # (the C library's log, as the compiled code calls it: numpy's SIMD log may differ
    # in the last bit on some CPUs)
    weight = np.array([-math.log(m) for m in miss_rate[band]])
    miss = st.decay * unseen.miss_evidence + np.where(clear & ~seen, weight, 0.0)
    return expected, seen_count, int(np.count_nonzero(clear)), missed, reach_m, rate, near, miss


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize(
    ("fov_deg", "centre_deg", "with_row"),
    [(360.0, 0.0, True), (90.0, 20.0, True), (180.0, 0.0, False)],
)
def test_compiled_frame_count_matches_numpy_to_the_bit(
    fov_deg: float, centre_deg: float, with_row: bool
) -> None:
    sm = generated_map(40, seed=2)
    cfg = replace(FilterConfig(), fov_deg=fov_deg, fov_centre_deg=centre_deg)
    # Detections aimed at a few random objects a frame make a detector that misses most
    # of what is in view: a loose chance_miss lets such a walk meet both answers.
    unseen = UnseenObjects(sm, cfg, replace(DEFAULT_UNSEEN, chance_miss=0.5))
    rng = np.random.default_rng(7)
    x, y = 6.0, 5.0
    answers = set()
    near_misses = 0
    for frame in range(60):
        # A wandering pose (small steps, so the counts are not reset by a jump) and
        # detections: some aimed at objects (noisy), some of a class the map lacks.
        x = float(np.clip(x + rng.normal(0.0, 0.2), 0.5, 19.5))
        y = float(np.clip(y + rng.normal(0.0, 0.2), 0.5, 11.5))
        theta = float(rng.uniform(-4.0, 4.0))
        # From frame 40 on, one object only: the others in view go unreported.
        aims = rng.choice(sm.object_count, size=rng.integers(1, 8) if frame < 40 else 1)
        dets = [
            Detection(
                sm.class_of(int(i)),
                float(np.arctan2(*(sm.object_xy[i] - (x, y))[::-1]) - theta + rng.normal(0, 0.05)),
                float(rng.uniform(0.3, 1.0)),
            )
            for i in aims
        ] + [Detection(CLASSES[int(rng.integers(3))], float(rng.uniform(-np.pi, np.pi)), 0.5)]
        obs = prepare_observation(dets, sm, cfg)
        row = sm.visibility.row(x, y) if with_row else None
        want = _numpy_counts(unseen, x, y, theta, obs, row)
        unseen.update(x, y, theta, obs, row)
        got = (unseen.expected, unseen.seen, unseen.frame_expected, unseen.frame_missed)
        assert np.array_equal(_bits(got[0]), _bits(want[0]))
        assert np.array_equal(_bits(got[1]), _bits(want[1]))
        assert got[2:] == want[2:4]
        assert np.array_equal(_bits(unseen.reach_m), _bits(want[4]))
        assert np.array_equal(_bits(unseen.rate_sums), _bits(want[5]))
        assert np.array_equal(_bits(unseen.near), _bits(want[6]))
        assert np.array_equal(_bits(unseen.miss_evidence), _bits(want[7]))
        near_misses += int(np.count_nonzero(want[6]))
        # The kernel's answer to "contradicted" is the counts' (the property's formula).
        st = unseen.settings
        flagged = (
            (got[0] >= st.min_expected)
            & (got[1] <= st.max_seen_share * got[0])
            & (want[7] >= -math.log(st.chance_miss))
        )
        assert unseen.contradicted == bool(flagged.any())
        assert bool(unseen._flagged().any()) == bool(flagged.any())
        answers.add(unseen.contradicted)
    assert unseen.expected.max() > 1.0  # objects were in clear view, some frames running
    assert near_misses > 0  # the near-miss counts were compared where they count
    if fov_deg == 360.0:  # the full view meets both answers (a narrow one may not)
        assert answers == {True, False}, answers


POSE = (10.0, 9.0)  # 15 objects within 7.5 m in line of sight on generated_map(40, 2)


def _bearings(sm) -> np.ndarray:
    offsets = sm.object_xy - POSE
    return np.arctan2(offsets[:, 1], offsets[:, 0])


def _loneliest_in_view(sm, cfg, among: np.ndarray | None = None) -> tuple[int, float]:
    """The object in clear view at POSE (of those ``among`` marks, when given) farthest
    in bearing from any other of its class (a detection of a same-class neighbour in its
    direction would see it), and that angle."""
    probe = UnseenObjects(sm, cfg)
    _walk_past(probe, sm, 1.0, -1, 3, seed=0)
    in_clear = np.flatnonzero((probe.expected > 0) & (True if among is None else among))
    assert in_clear.size >= 4
    bearing = _bearings(sm)

    def alone(i: int) -> float:
        mates = [
            j for j in range(sm.object_count) if j != i and sm.object_class[j] == sm.object_class[i]
        ]
        return float(np.min(np.abs(wrap_angle(bearing[mates] - bearing[i]))))

    best = max(in_clear.tolist(), key=alone)
    return best, alone(best)


def _walk_past(unseen: UnseenObjects, sm, hit_prob: float, absent: int, frames: int, seed: int):
    """Frames at one pose seeing every object in clear view with ``hit_prob`` each, but
    never the object ``absent``; per frame, whether the estimate was contradicted."""
    rng = np.random.default_rng(seed)
    (x, y), theta = POSE, 0.0
    flags = []
    for _ in range(frames):
        dets = [
            Detection(sm.class_of(int(i)), float(np.arctan2(dy, dx)) - theta, 0.9)
            for i, (dx, dy) in enumerate(sm.object_xy - (x, y))
            if i != absent and rng.random() < hit_prob
        ]
        obs = prepare_observation(dets, sm, unseen.config)
        unseen.update(x, y, theta, obs, sm.visibility.row(x, y))
        flags.append(unseen.contradicted)
    return flags


def test_a_detector_that_misses_a_third_must_miss_an_object_longer() -> None:
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    absent, apart = _loneliest_in_view(sm, cfg)
    assert apart > np.radians(10.0)
    # A reliable detector: the object never reported is flagged within a second.
    reliable = _walk_past(UnseenObjects(sm, cfg), sm, 0.98, absent, 60, seed=1)
    assert any(reliable[:8])
    # One missing 30 % at random, every object present: its unlucky runs flag nothing
    # (they did at the counts alone: a run of about four misses was enough) ...
    flaky = UnseenObjects(sm, cfg)
    assert not any(_walk_past(flaky, sm, 0.7, -1, 600, seed=2))
    rate = flaky.rate_sums[:, 1].sum() / flaky.rate_sums[:, 0].sum()
    assert 0.6 < rate < 0.85  # (a neighbour of the same class seen counts too)
    # ... and an object it never reports is still flagged, later.
    assert any(_walk_past(UnseenObjects(sm, cfg), sm, 0.7, absent, 60, seed=3))


def test_an_object_reported_here_before_is_told_from_one_never_reported() -> None:
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    obj, _ = _loneliest_in_view(sm, cfg)
    never = UnseenObjects(sm, cfg)
    flags = _walk_past(never, sm, 1.0, obj, 20, seed=1)
    assert flags[-1] and never.never_reported
    # Reported on the first frames at this place, then missed as long.
    before = UnseenObjects(sm, cfg)
    assert not any(_walk_past(before, sm, 1.0, -1, 3, seed=1))
    flags = _walk_past(before, sm, 1.0, obj, 20, seed=1)
    assert flags[-1] and not before.never_reported
    assert not UnseenObjects(sm, cfg).never_reported  # (nothing flagged)


def test_an_object_taken_away_or_moved_is_forgiven_and_a_moved_one_is_told_apart() -> None:
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    gone, apart = _loneliest_in_view(sm, cfg)
    assert apart > np.radians(30.0)
    # Taken away: never reported, no detection of its class anywhere near it.
    taken = UnseenObjects(sm, cfg)
    flags = _walk_past(taken, sm, 1.0, gone, 20, seed=1)
    assert flags[-1] and taken.forgive() == 1
    assert not taken.contradicted and taken.absent[gone] and not taken.moved.any()
    assert not any(_walk_past(taken, sm, 1.0, gone, 20, seed=2))  # it flags no more
    # Moved: its class keeps being reported 15 degrees off its drawn place.
    assert not sm.fixed[gone]  # (a table)
    moved = _reported_off(sm, cfg, gone, np.radians(15.0))
    assert moved.contradicted and moved.forgive() == 1
    assert not moved.contradicted and moved.absent[gone] and moved.moved[gone]
    assert moved.moved.sum() == 1


def test_a_lapsed_contradiction_is_resolved_only_by_reports_of_its_objects() -> None:
    """An object flagged, then reported again in most frames (the estimate that missed
    it has come to where it is seen), resolves the contradiction, once; one reported now
    and then (a far object, or one moved near its drawn place) does not, nor one flagged
    on a single frame, nor one forgiven (the gate's wait is then a stale map's margin)."""
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    obj, _ = _loneliest_in_view(sm, cfg)

    def lapse(hit_prob: float, seed: int) -> tuple[UnseenObjects, list[bool], list[bool]]:
        unseen = UnseenObjects(sm, cfg)
        assert _walk_past(unseen, sm, 1.0, obj, 20, seed=1)[-1]
        assert unseen.lately[obj] and unseen.lately.sum() == 1
        rng = np.random.default_rng(seed)
        flags, resolved = [], []
        for _ in range(30):
            gone = -1 if rng.random() < hit_prob else obj
            flags += _walk_past(unseen, sm, 1.0, gone, 1, seed=int(rng.integers(1 << 30)))
            resolved.append(unseen.resolved)
        return unseen, flags, resolved

    back, flags, resolved = lapse(1.0, seed=3)
    first = flags.index(False)
    assert sum(resolved) == 1 and resolved.index(True) >= first
    assert not back.lately.any() and not any(flags[first:])
    # Reported in about a third of the frames: the flag lapses, the contradiction stays.
    now_and_then, flags, resolved = lapse(0.3, seed=4)
    assert not all(flags) and not any(resolved) and now_and_then.lately[obj]
    # Flagged on one frame only, then reported: not resolved (a drag's sweep).
    once = UnseenObjects(sm, cfg)
    flags = _walk_past(once, sm, 1.0, obj, 20, seed=1)
    start = flags.index(True)
    once = UnseenObjects(sm, cfg)
    assert _walk_past(once, sm, 1.0, obj, start + 1, seed=1)[-1] and once.flag_frames == 1
    _walk_past(once, sm, 1.0, -1, 30, seed=6)
    assert not once.resolved and once.lately[obj]
    # Forgiven: no report resolves it.
    forgiven = UnseenObjects(sm, cfg)
    assert _walk_past(forgiven, sm, 1.0, obj, 20, seed=1)[-1] and forgiven.forgive() == 1
    _walk_past(forgiven, sm, 1.0, -1, 30, seed=5)
    assert not forgiven.resolved and forgiven.lately[obj]
    # The objects flagged survive a checkpoint.
    copy = UnseenObjects(sm, cfg)
    copy.restore(now_and_then.checkpoint())
    assert np.array_equal(copy.lately, now_and_then.lately)
    assert copy.flag_frames == now_and_then.flag_frames > 1


def _reported_off(sm, cfg, obj: int, off_rad: float) -> UnseenObjects:
    """The counts of 20 frames at POSE reporting every object but ``obj`` (98 % each),
    and ``obj``'s class ``off_rad`` off its drawn bearing."""
    (x, y), bearing = POSE, _bearings(sm)
    unseen = UnseenObjects(sm, cfg)
    rng = np.random.default_rng(4)
    for _ in range(20):
        dets = [
            Detection(sm.class_of(int(i)), float(bearing[i]), 0.9)
            for i in range(sm.object_count)
            if i != obj and rng.random() < 0.98
        ] + [Detection(sm.class_of(obj), float(bearing[obj] + off_rad), 0.9)]
        obs = prepare_observation(dets, sm, cfg)
        unseen.update(x, y, 0.0, obs, sm.visibility.row(x, y))
    return unseen


def test_a_door_reported_off_its_place_is_forgiven_as_gone_never_as_moved() -> None:
    """A door or a window is part of the building: reported a little off its drawn
    place, it has not moved (the estimate is off, or the door is not what the detector
    calls one). Forgiven, it stays in the sensor model: taken for moved, it left it, and
    a place along a corridor of doors that did not see them lost nothing by it, the
    true place what told it apart."""
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    doors = sm.object_class == sm.classes.index("door")
    door, apart = _loneliest_in_view(sm, cfg, among=doors)
    # 15 degrees off and 4 stds of 2 degrees wide, the report reaches no other door.
    assert sm.fixed[door] and apart > np.radians(15.0 + 4 * 2.0)
    unseen = _reported_off(sm, cfg, door, np.radians(15.0))
    assert unseen.contradicted and unseen.near[door] > 0.0  # a near miss, as a moved one has
    assert unseen.forgive() == 1
    assert not unseen.contradicted and unseen.absent[door] and not unseen.moved.any()


def _glance(unseen: UnseenObjects, sm, target: int, pattern: str, seed: int) -> bool:
    """Through a 66-degree camera at POSE: a warm-up turning round and round (each
    object nearer than 6 m reported 98 % of its frames in view, each farther one 25 %),
    the counts then forgotten (not the hit rates), and ``target`` glanced at for
    ``len(pattern)`` frames, reported where ``pattern`` has "H"; whether it was
    flagged at the end."""
    rng = np.random.default_rng(seed)
    bearing = _bearings(sm)
    dist = np.hypot(*(sm.object_xy - POSE).T)
    half = np.radians(33.0)

    def frame(theta: float, forced: dict[int, bool]) -> None:
        rel = wrap_angle(bearing - theta)
        p = np.where(dist < 6.0, 0.98, 0.25)
        hit = (np.abs(rel) <= half) & (rng.random(sm.object_count) < p)
        for i, h in forced.items():
            hit[i] = h
        dets = [Detection(sm.class_of(int(i)), float(rel[i]), 0.9) for i in np.flatnonzero(hit)]
        dets.append(Detection(sm.class_of(target), float(rel[target] + 1.0), 0.9))  # (a frame
        # is counted only with detections; this one aims at nothing in view)
        unseen.update(*POSE, theta, prepare_observation(dets, sm, unseen.config), None)

    for k in range(400):
        frame(0.25 * k, {})
    unseen.reset()
    for c in pattern:
        frame(float(bearing[target]), {target: c == "H"})
    return unseen.contradicted


def test_far_objects_are_held_to_the_hit_rate_at_their_distance() -> None:
    """A detector that reports near objects nearly always and far ones a quarter of
    the time (small in the image): a far object glanced at for six frames and reported
    in one of them is no contradiction, as it was at one rate over all distances (most
    of what is in view is near); a near object missed so is one. (The rate learnt far
    away is well above a quarter: a near object of the same class in line with a far
    one sees it, and only objects reported now and then count.)"""
    sm = generated_map(40, seed=2)
    cfg = replace(FilterConfig(), fov_deg=66.0)
    dist = np.hypot(*(sm.object_xy - POSE).T)
    bearing = _bearings(sm)

    def lonely(among: np.ndarray) -> int:
        """Of ``among``, the object farthest in bearing from any other of its class in
        view (a detection of that one would see it)."""
        near = dist <= DEFAULT_UNSEEN.near_m + 1.0
        gap = [
            np.min(
                np.abs(
                    wrap_angle(
                        bearing[near & (sm.object_class == sm.object_class[i])
                                & (np.arange(sm.object_count) != i)] - bearing[i]
                    )
                )
            )
            for i in np.flatnonzero(among)
        ]  # fmt: skip
        assert max(gap) > np.radians(15.0)
        return int(np.flatnonzero(among)[int(np.argmax(gap))])

    far = lonely((dist >= 6.0) & (dist <= 7.5))
    near = lonely((dist >= 1.5) & (dist <= 4.0))
    glance = "MHMMMM"
    banded = UnseenObjects(sm, cfg)
    assert not _glance(banded, sm, far, glance, seed=1)
    rates = 1.0 - banded.miss_rates()
    assert rates[1] > 0.9 and rates[-1] < rates[1] - 0.05  # learnt: far reported less
    # One band over every distance (the rate before) flags it.
    one_band = replace(DEFAULT_UNSEEN, band_m=DEFAULT_UNSEEN.near_m)
    assert _glance(UnseenObjects(sm, cfg, one_band), sm, far, glance, seed=1)
    # A near object missed so is flagged.
    assert _glance(UnseenObjects(sm, cfg), sm, near, glance, seed=1)


def test_a_checkpoint_from_before_the_bands_restores_its_counts_and_flags() -> None:
    sm = generated_map(40, seed=2)
    cfg = FilterConfig()
    absent, _ = _loneliest_in_view(sm, cfg)
    unseen = UnseenObjects(sm, cfg)
    _walk_past(unseen, sm, 0.9, absent, 12, seed=1)
    state = unseen.checkpoint()
    # The pooled sums are stored where an older version reads them, the bands beside.
    assert np.array_equal(state["rate"], unseen.rate_sums.sum(axis=0))
    again = UnseenObjects(sm, cfg)
    again.restore(state)
    assert np.array_equal(again.rate_sums, unseen.rate_sums)
    assert np.array_equal(again.miss_evidence, unseen.miss_evidence)
    # What an older version stored: one pair of hit-rate sums, no weighed misses.
    old = {k: v for k, v in state.items() if k not in ("miss", "rate_bands")}
    restored = UnseenObjects(sm, cfg)
    restored.restore(old)
    assert restored.rate_sums.shape == (restored.bands, 2)
    assert np.allclose(restored.rate_sums.sum(axis=0), old["rate"])
    # Its flags are the old formula's: decayed misses against the needed count.
    st = restored.settings
    hit = (old["rate"][1] + st.rate_prior * st.rate_prior_frames) / (
        old["rate"][0] + st.rate_prior_frames
    )
    needed = math.log(st.chance_miss) / math.log(1.0 - hit)
    want = (
        (restored.expected >= st.min_expected)
        & (restored.seen <= st.max_seen_share * restored.expected)
        & (restored.expected - restored.seen >= needed - 1e-9)
    )
    assert want.any() and np.array_equal(restored._flagged(), want)


def test_a_box_off_a_wide_object_s_centre_up_close_is_no_near_miss() -> None:
    """Up close a box's centre is not the object's reference point: a table 1 m away
    reported 15 deg off its centre is neither seen nor a near miss (within the angle
    ``extent_m`` subtends: no sign it was moved), one 6 m away reported 15 deg off is a
    near miss; without the extent both were near misses."""
    from app.maps.model import parse_map

    far = (6.0 * math.cos(math.radians(-60.0)), 6.0 * math.sin(math.radians(-60.0)))
    sm = parse_map(
        {
            "name": "tables",
            "objects": [
                {"class": "table", "x": 1.0, "y": 0.0},
                {"class": "table", "x": far[0], "y": far[1]},
                {"class": "door", "x": 0.0, "y": 7.0},
                # Reported where it stands: tables are reported this far away.
                {"class": "table", "x": -6.5, "y": 0.0},
            ],
        }
    )
    cfg = FilterConfig()
    dets = [
        Detection("table", math.radians(15.0), 0.9),
        Detection("table", math.radians(-45.0), 0.9),
        Detection("door", math.radians(90.0), 0.9),
        Detection("table", math.radians(180.0), 0.9),
    ]
    obs = prepare_observation(dets, sm, cfg)
    for settings, near_miss in (
        (DEFAULT_UNSEEN, False),
        (replace(DEFAULT_UNSEEN, extent_m=0.0), True),
    ):
        unseen = UnseenObjects(sm, cfg, settings)
        for _ in range(5):
            unseen.update(0.0, 0.0, 0.0, obs, None)
        assert unseen.seen[0] == 0.0 and unseen.expected[0] > 0.0
        assert bool(unseen.near[0] > 0.0) == near_miss
        assert unseen.seen[1] == 0.0 and unseen.near[1] > 0.0
        assert unseen.seen[2] > 0.0 and unseen.seen[3] > 0.0
