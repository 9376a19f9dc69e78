"""A global start on a map with several levels: the first frame with detections weighs
(levels x particles) candidates and keeps ``particles`` of them."""

from __future__ import annotations

import numpy as np
import pytest

from app.experiments.venue import single_level_map
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.types import Detection, InitialPose, Odometry, Pose
from app.maps.model import SemanticMap
from app.simulation.venue import venue_map
from tests import helpers

VENUE = venue_map()


def seen_from(pose: Pose) -> list[Detection]:
    """What a 360-degree camera sees from plane pose ``pose``, exact bearings."""
    return helpers.seen_from(VENUE, pose)


def weight_near(pf: ParticleFilter, pose: Pose, radius_m: float = 1.0) -> float:
    near = np.hypot(pf.x - pose.x, pf.y - pose.y) < radius_m
    return float(pf.weights[near].sum())


def count_weighings(pf: ParticleFilter) -> list[int]:
    """A list the number of poses of each of the filter's sensor weighings is added to."""
    sizes: list[int] = []
    weigh = pf.sensor.log_likelihood

    def counted(x, y, theta, obs):  # type: ignore[no-untyped-def]
        sizes.append(int(np.size(x)))
        return weigh(x, y, theta, obs)

    pf.sensor.log_likelihood = counted  # type: ignore[method-assign]
    return sizes


def test_the_first_frame_weighs_a_candidate_per_particle_and_level() -> None:
    pf = ParticleFilter(VENUE, FilterConfig(particles=500), rng=np.random.default_rng(0))
    sizes = count_weighings(pf)
    pf.step(None, [])  # no detections: nothing to weigh, the start waits
    assert sizes == [] and pf.n == 500
    seen = seen_from(Pose(6.0, 11.0, 0.0))
    pf.step(Odometry(), seen)
    pf.step(Odometry(), seen)
    levels = len(VENUE.layout.levels)
    assert sizes[0] == levels * 500  # the first frame with detections: every level's share
    assert sizes[1:] == [pf.n] and pf.n <= 500  # then the steady filter


def test_the_first_frame_finds_the_person_more_often_than_a_third_of_the_particles_did() -> None:
    # 300 particles, 20 seeds, two places on the Ground Floor: the weight within 1 m of
    # the truth after the first frame. Drawn over the three floors at a third of a
    # one-level map's density it was 0.20 and 0.05 on average; weighed as (levels x
    # particles) candidates, 0.46 and 0.30 (the one-level map: 0.64 and 0.55).
    held = []
    for pose in (Pose(6.0, 11.0, 0.0), Pose(12.0, 4.0, 1.0)):
        seen = seen_from(pose)
        for seed in range(20):
            pf = ParticleFilter(VENUE, FilterConfig(particles=300), rng=np.random.default_rng(seed))
            pf.step(None, seen)
            held.append(weight_near(pf, pose))
    assert np.mean(held) > 0.3


def test_a_lone_detection_on_every_floor_keeps_every_floor() -> None:
    # One bench seen (there is one on each floor): the candidates' weights stay flat
    # across the floors, and so does the resampled cloud; nothing collapses onto one.
    for seed in range(5):
        pf = ParticleFilter(VENUE, FilterConfig(particles=3000), rng=np.random.default_rng(seed))
        pf.step(None, [Detection("bench", 0.5, 1.0)])
        shares = np.bincount(VENUE.layout.level_of_plane_x(pf.x), minlength=3) / pf.n
        assert shares.min() > 0.2, shares
        assert not pf.estimate.converged


def test_a_checkpoint_before_any_detection_keeps_the_wide_start() -> None:
    pf = ParticleFilter(VENUE, FilterConfig(particles=400), rng=np.random.default_rng(1))
    pf.step(None, [])
    again = ParticleFilter(
        VENUE, FilterConfig(particles=400), rng=np.random.default_rng(1), state=pf.checkpoint()
    )
    for f in (pf, again):
        f.step(Odometry(), seen_from(Pose(6.0, 11.0, 0.0)))
    np.testing.assert_array_equal(pf.x, again.x)
    assert again.checkpoint()["wide_first"] is False


@pytest.mark.parametrize("level_map", [False, True])
def test_a_known_start_or_a_one_level_map_draws_no_wide_start(level_map: bool) -> None:
    semantic_map: SemanticMap = single_level_map("L0") if level_map else VENUE
    start = None if level_map else InitialPose(6.0, 11.0, 0.0, 0.3, 0.1)
    pf = ParticleFilter(
        semantic_map, FilterConfig(particles=300), rng=np.random.default_rng(0), initial_pose=start
    )
    sizes = count_weighings(pf)
    pf.step(None, seen_from(Pose(6.0, 11.0, 0.0)))
    assert sizes == [300]
    if level_map:  # one-level checkpoints as they were
        assert "wide_first" not in pf.checkpoint()
