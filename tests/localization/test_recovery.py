"""Recovery: augmented MCL's w_slow / w_fast, and particles drawn from the observation."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.recovery import MAX_INJECTION, AugmentedMCL, sample_from_observation
from app.localization.sensor import prepare_observation
from app.localization.types import Detection, InitialPose, Odometry
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap


def test_first_evidence_starts_both_averages_and_injects_nothing() -> None:
    mcl = AugmentedMCL(alpha_slow=0.02, alpha_fast=0.3)
    assert mcl.update(-1.0) == 0.0
    assert mcl.w_slow == mcl.w_fast == pytest.approx(np.exp(-1.0))


def test_steady_evidence_never_injects() -> None:
    mcl = AugmentedMCL(alpha_slow=0.02, alpha_fast=0.3)
    shares = [mcl.update(-1.0 + 0.05 * np.sin(i)) for i in range(200)]
    assert max(shares) == 0.0  # jitter stays inside the dead band


def test_injects_once_w_fast_falls_below_the_dead_band_of_w_slow() -> None:
    mcl = AugmentedMCL(alpha_slow=0.02, alpha_fast=0.3)
    for _ in range(50):
        mcl.update(-1.0)
    shares = []
    for _ in range(10):  # the observations stop fitting: likelihood e^-4 instead of e^-1
        share = mcl.update(-4.0)
        shares.append(share)
        assert mcl.w_fast < mcl.w_slow
        expected = np.clip(1.0 - mcl.w_fast / (mcl.threshold * mcl.w_slow), 0.0, MAX_INJECTION)
        assert share == pytest.approx(expected)
    assert shares[0] == 0.0  # one bad frame is not yet below half of w_slow
    assert 0.0 < shares[-1] <= MAX_INJECTION
    assert shares == sorted(shares)  # the longer it lasts, the more is injected
    mcl.reset()
    assert mcl.w_slow == mcl.w_fast == 0.0


def test_frames_without_usable_detections_leave_recovery_untouched(
    small_room: SemanticMap,
) -> None:
    pf = ParticleFilter(small_room, FilterConfig(particles=500), rng=np.random.default_rng(0))
    pf.correct([Detection("door", 0.3)])
    before = (pf._recovery.w_slow, pf._recovery.w_fast)
    assert before[0] > 0.0
    # Nothing, an unknown class, and a score-0 detection: no evidence, no injection.
    for dets in ([], [Detection("sofa", 0.1)], [Detection("door", 0.1, 0.0)]):
        assert pf.correct(dets) == 0.0
        assert (pf._recovery.w_slow, pf._recovery.w_fast) == before


def test_sampled_poses_point_a_detection_at_an_object_of_its_class(
    small_room: SemanticMap,
) -> None:
    dets = [Detection("door", 0.7, 1.0), Detection("window", -1.2, 1.0)]
    obs = prepare_observation(dets, small_room, FilterConfig())
    x, y, th = sample_from_observation(2000, obs, small_room, np.random.default_rng(4), 0.0)
    assert small_room.free_space.is_free(x, y).all()
    # Exactly (no heading noise): some detection, turned by the heading, points at an
    # object of its class.
    explained = np.zeros(x.size, dtype=bool)
    for d in dets:
        objs = small_room.object_xy[small_room.class_members[d.cls]]
        towards = np.arctan2(objs[None, :, 1] - y[:, None], objs[None, :, 0] - x[:, None])
        err = np.abs(wrap_angle(towards - (th[:, None] + d.bearing_rad)))
        explained |= (err < 1e-9).any(axis=1)
    assert explained.all()
    # Both detections are used (drawn in proportion to their scores).
    door = small_room.object_xy[small_room.class_members["door"][0]]
    via_door = np.abs(wrap_angle(np.arctan2(door[1] - y, door[0] - x) - th - 0.7)) < 1e-9
    assert 0.4 < via_door.mean() < 0.6


def _blank_wall_walk(
    room_map: SemanticMap, seed: int
) -> tuple[ParticleFilter, list[float], list[bool]]:
    """A person at (1, 2) of ``small_room`` who sees the door, the table and a window
    through a 90-degree camera facing east, then turns to the bare west wall (nothing
    in view) and stands there for 10 s of a phone's false detections: errors (m) and
    ``converged`` of those frames."""
    config = FilterConfig(particles=2000, fov_deg=90.0, bearing_std_deg=2.0)
    rng = np.random.default_rng(seed)
    pf = ParticleFilter(
        room_map,
        config,
        rng=np.random.default_rng(seed + 1),
        initial_pose=InitialPose(1.0, 2.0, 0.0, 0.05, np.radians(1.0)),
    )
    x, y = 1.0, 2.0

    def seen(theta: float) -> list[Detection]:
        out = []
        for (ox, oy), k in zip(room_map.object_xy, room_map.object_class, strict=True):
            b = float(wrap_angle(np.arctan2(oy - y, ox - x) - theta))
            if abs(b) < np.radians(40.0):
                noisy = b + rng.normal(0.0, np.radians(2.0))
                out.append(Detection(room_map.classes[k], noisy, 0.9))
        return out

    for _ in range(15):  # facing east: located
        pf.step(Odometry(), seen(0.0))
    assert pf.estimate.converged
    theta = 0.0
    for _ in range(6):  # turning to the west wall, 30 degrees a frame
        theta += np.radians(30.0)
        pf.step(Odometry(turn_rad=np.radians(30.0)), seen(theta))
    errors, converged = [], []
    classes = ["door", "window", "table"]
    for _ in range(50):  # 10 s facing a bare wall; the detector's boxes are all false
        false = [
            Detection(str(rng.choice(classes)), float(rng.uniform(-0.7, 0.7)), 0.6)
            for _ in range(int(rng.integers(1, 3)))
        ]
        est = pf.step(Odometry(), false)
        errors.append(float(np.hypot(est.x - x, est.y - y)))
        converged.append(est.converged)
    return pf, errors, converged


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_false_detections_where_nothing_is_in_view_do_not_pull_a_held_fix_away(
    small_room: SemanticMap, seed: int
) -> None:
    """Facing a bare wall, every detection is clutter wherever the person stands: the
    recovery injects nothing for such frames, and the fix stays where it was."""
    pf, errors, converged = _blank_wall_walk(small_room, seed)
    assert max(errors) < 0.3
    assert all(converged)
    assert pf._sees_nothing
