"""The phone model: each effect does what it says, and switched off changes nothing it
controls (nor anything another effect controls)."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from app.experiments.hard_maps import hard_map
from app.maps.geometry import wrap_angle
from app.simulation.phone import (
    PDR,
    VIO,
    OdometryGrade,
    PhoneEffects,
    PhoneFrame,
    detect_probability,
    pdr_phone,
    simulate_phone,
    vio_phone,
)
from app.simulation.simulator import SimulationConfig
from app.simulation.stale import StaleMap, stale_world

MAP = hard_map("paper_office").map
WALK = SimulationConfig(path=hard_map("paper_office").path, fov_deg=360.0)


def frames(effects: PhoneEffects, seed: int = 3, walk: SimulationConfig = WALK) -> list[PhoneFrame]:
    return simulate_phone(MAP, walk, effects, np.random.default_rng(seed))


def odometry(fs: list[PhoneFrame]) -> list[object]:
    return [f.odometry for f in fs]


def test_no_effect_is_the_ideal_walk() -> None:
    fs = frames(PhoneEffects())
    assert all(f.detections_age_s is None and f.true_age_s == 0.0 for f in fs)
    assert all(f.dropped_before == 0 for f in fs)
    assert all(s >= 0 for f in fs for s in f.sources)  # no false detection
    # Every detection has the class of the object it came from, near its bearing.
    for f in fs:
        for d, s in zip(f.detections, f.sources, strict=True):
            assert d.cls == MAP.class_of(s)
            dx, dy = MAP.object_xy[s] - (f.truth.x, f.truth.y)
            true = wrap_angle(np.arctan2(dy, dx) - f.truth.theta_rad)
            assert abs(float(wrap_angle(d.bearing_rad - true))) < np.radians(10.0)


def test_same_seed_same_frames_and_detection_effects_leave_odometry_alone() -> None:
    all_on = vio_phone()
    assert frames(all_on) == frames(all_on)
    # Effects on the detections only: the odometry is the same, draw for draw.
    detection_only = replace(
        all_on, duplicate_prob=0.0, class_confusion=0.0, range_falloff=False,
        box_bias_share=0.0, false_rate=0.0, latency_s=None,
    )  # fmt: skip
    assert odometry(frames(all_on)) == odometry(frames(detection_only))


def test_duplicates_confusion_and_false_detections_only_when_on() -> None:
    base = frames(PhoneEffects())
    dup = frames(PhoneEffects(duplicate_prob=0.5))
    shared = sum(len(f.sources) - len(set(f.sources)) for f in dup)
    assert shared > 0.3 * sum(len(f.sources) for f in base)
    assert all(len(f.sources) == len(set(f.sources)) for f in base)
    conf = frames(PhoneEffects(class_confusion=0.2))
    wrong = [
        d.cls != MAP.class_of(s) for f in conf for d, s in zip(f.detections, f.sources, strict=True)
    ]
    assert 0.1 < np.mean(wrong) < 0.3
    false = frames(PhoneEffects(false_rate=1.0))
    per_frame = np.mean([sum(s < 0 for s in f.sources) for f in false])
    assert 0.8 < per_frame < 1.2
    # The bearings of true detections are the same draws with and without falses.
    assert [
        sorted(d.bearing_rad for d, s in zip(f.detections, f.sources, strict=True) if s >= 0)
        for f in false
    ] == [sorted(d.bearing_rad for d in f.detections) for f in base]


def test_latency_sees_the_past_and_says_so_only_when_known() -> None:
    known = frames(PhoneEffects(latency_s=(0.1, 0.3)))
    unknown = frames(PhoneEffects(latency_s=(0.1, 0.3), latency_known=False))
    ages = [f.detections_age_s for f in known]
    assert all(a is not None and 0.1 <= a <= 0.3 for a in ages)
    assert all(f.detections_age_s is None for f in unknown)
    assert [f.true_age_s for f in unknown] == [f.true_age_s for f in known]
    assert "detections_age_s" in known[10].to_contract()
    assert "detections_age_s" not in unknown[10].to_contract()
    # Walking straight at 0.5 m/s, a 0.2 s old detection is 0.1 m behind: the bearing of
    # the object seen is the one from the earlier position, not the frame's end.
    f = known[10]
    for d, s in zip(f.detections, f.sources, strict=True):
        dx, dy = MAP.object_xy[s] - (f.truth.x, f.truth.y)
        now = wrap_angle(np.arctan2(dy, dx) - f.truth.theta_rad)
        back = f.truth.x - 0.5 * f.true_age_s  # first leg walks +x
        then = wrap_angle(np.arctan2(dy + f.truth.y - f.truth.y, MAP.object_xy[s][0] - back) - 0.0)
        assert abs(float(wrap_angle(d.bearing_rad - then))) <= abs(
            float(wrap_angle(d.bearing_rad - now))
        ) + np.radians(8.0)


def test_dropped_frames_carry_their_motion() -> None:
    all_frames = frames(PhoneEffects(odometry=VIO))
    dropped = frames(PhoneEffects(odometry=VIO, drop_prob=0.3))
    assert 0.6 * len(all_frames) < len(dropped) < 0.8 * len(all_frames)
    assert sum(f.dropped_before for f in dropped) + len(dropped) == len(all_frames)

    # The odometry over the whole walk adds up to the same motion either way.
    def path_length(fs: list[PhoneFrame]) -> float:
        return sum(f.odometry.forward_m for f in fs if f.odometry is not None)

    assert path_length(dropped) == pytest.approx(path_length(all_frames), rel=0.02)


def test_odometry_grades_bias_scale_and_heading() -> None:
    true_length = sum(np.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(WALK.path))
    for grade, bound in ((VIO, 0.02), (PDR, 0.10)):
        errors = []
        for seed in range(8):
            fs = frames(PhoneEffects(odometry=grade), seed)
            moved = sum(f.odometry.forward_m for f in fs if f.odometry)  # noise averages out
            errors.append(moved / true_length - 1.0)
        # per-frame noise: std of the sum about noise_m * sqrt(frames) = 2 % of the walk
        assert max(abs(e) for e in errors) < bound + 0.04
        assert np.std(errors) > bound / 10  # a bias per walk, not zero
    # Standing still 60 s without noise: the summed turn is the drift, within the bound,
    # and no motion is measured.
    quiet = OdometryGrade("quiet", 0.1, 10.0, 0.0, 0.0)
    stand = SimulationConfig(path=((5.0, 3.5),), duration_s=60.0)
    drift = []
    for seed in range(6):
        fs = frames(PhoneEffects(odometry=quiet), seed, stand)
        drift.append(np.degrees(sum(f.odometry.turn_rad for f in fs if f.odometry)))
        assert all(f.odometry.forward_m == 0.0 for f in fs if f.odometry)
    assert max(abs(d) for d in drift) <= 10.0 + 1e-6
    assert max(abs(d) for d in drift) > 2.0


def test_sway_turns_the_camera_while_walking_only() -> None:
    still = frames(PhoneEffects())
    sway = frames(PhoneEffects(sway_deg=8.0))
    diff = np.degrees(
        [
            float(wrap_angle(a.truth.theta_rad - b.truth.theta_rad))
            for a, b in zip(sway, still, strict=True)
        ]
    )
    assert 6.0 < np.max(np.abs(diff)) <= 8.0 + 1e-9
    stand = SimulationConfig(path=((5.0, 3.5),), duration_s=5.0)
    assert {f.truth.theta_rad for f in frames(PhoneEffects(sway_deg=8.0), 1, stand)} == {0.0}


def test_far_objects_are_missed_more_and_scored_lower() -> None:
    p = detect_probability(np.array([1.0, 9.0, 15.0]), 9.0)
    assert p[0] > 0.9 and p[1] == pytest.approx(0.475) and p[2] < 0.2
    fs = frames(PhoneEffects(range_falloff=True), walk=replace(WALK, max_range_m=30.0))
    near, far = [], []
    for f in fs:
        for d, s in zip(f.detections, f.sources, strict=True):
            dist = np.hypot(*(MAP.object_xy[s] - (f.truth.x, f.truth.y)))
            (near if dist < 3.0 else far if dist > 7.0 else []).append(d.score)
    assert np.mean(near) > np.mean(far) + 0.15


def test_stale_world_moves_removes_and_adds() -> None:
    rng = np.random.default_rng(0)
    world = stale_world(MAP, StaleMap(moved_share=0.2, removed_share=0.1, added_share=0.1), rng)
    assert world.object_count == MAP.object_count  # one removed, one added (11 objects)
    old = {tuple(p) for p in MAP.object_xy.round(3)}
    changed = [tuple(p) for p in world.object_xy.round(3) if tuple(p) not in old]
    assert len(changed) >= 2
    with pytest.raises(ValueError, match="moved_share"):
        StaleMap(moved_share=1.5)
    with pytest.raises(ValueError, match="needs duration_s"):
        frames(PhoneEffects(), walk=SimulationConfig(path=((5.0, 3.5),)))


def test_presets() -> None:
    assert vio_phone().odometry is VIO and pdr_phone().odometry is PDR
    assert pdr_phone(stale=StaleMap()).stale is not None
