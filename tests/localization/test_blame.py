"""A fix let go for sliding off the odometry blames the moved object that dragged it."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.filter import SLIDE_BLAME_SPAN_M, ParticleFilter
from app.localization.slide import MIN_FRAMES
from app.localization.types import Estimate, InitialPose, Odometry, Pose
from app.maps.model import SemanticMap
from app.service import checkpoint
from tests.helpers import seen_from
from tests.localization.test_separation import OBJECTS, PLANT, STEP_M, corridor

TABLE = 5
FRAMES = 25


def _world(obj: int, dx: float, dy: float) -> SemanticMap:
    """The corridor today: object ``obj`` moved by (dx, dy) since it was drawn."""
    objects = [dict(o) for o in OBJECTS]
    objects[obj]["x"] = float(objects[obj]["x"]) + dx
    objects[obj]["y"] = float(objects[obj]["y"]) + dy
    return corridor(objects)


def _let_go(world: SemanticMap, at: tuple[float, float, float]) -> tuple[ParticleFilter, Pose]:
    """A filter on the corridor as drawn, its cloud around ``at`` (where a slide let its
    fix go), that walked the corridor's middle 2.4 m seeing ``world`` (the evidence
    tracker's window) with its fixes told on the truth at first (the slide test's
    anchors: the odometry carries them to the truth); and the walk's last pose."""
    drawn = corridor(OBJECTS)
    x, y, t = at
    pf = ParticleFilter(
        drawn,
        FilterConfig(particles=2000),
        rng=np.random.default_rng(5),
        initial_pose=InitialPose(x, y, t, 0.05, 0.02),
    )
    assert pf.evidence is not None and pf.unseen is not None
    pose = Pose(3.0, 1.5, 0.0)
    for k in range(FRAMES):
        pose = Pose(3.0 + STEP_M * k, 1.5, 0.0)
        odometry = Odometry(STEP_M, 0.0, 0.0) if k else None
        seen = seen_from(world, pose)
        pf.evidence._history.append((odometry, pf.sensor.observe(seen), None))
        if odometry is not None:
            pf.odometry_check.moved(odometry)
        if k < FRAMES - MIN_FRAMES:  # anchors old enough to compare with
            pf.odometry_check.add(pose.x, pose.y, pose.theta_rad, True)
        else:
            pf.odometry_check.add(x, y, t, True)
    return pf, pose


def _raw(at: tuple[float, float, float]) -> Estimate:
    return Estimate(*at, 0.05, 0.05, 0.02, False)


def test_a_table_moved_along_the_corridor_is_blamed_and_half_the_cloud_goes_back() -> None:
    # The table moved 1.2 m along the corridor drags the fix 0.6 m back and sideways
    # (the place the window fits best with every object, found so): without the
    # table, the place is the truth again; without the plant, it is pulled farther off.
    dragged = (4.9, 1.1, 0.04)
    pf, truth = _let_go(_world(TABLE, 1.2, 0.0), dragged)
    before = (pf.x.copy(), pf.y.copy())
    pf._blame_the_slide(_raw(dragged))
    assert pf.unseen is not None
    assert np.flatnonzero(pf.unseen.moved).tolist() == [TABLE]
    assert TABLE in pf.sensor.excluded and PLANT not in pf.sensor.excluded
    # Half the cloud moved by one rigid motion onto the truth, the other half kept.
    assert np.array_equal(pf.x[1::2], before[0][1::2])
    moved = np.hypot(pf.x[::2] - truth.x, pf.y[::2] - truth.y)
    kept = np.hypot(before[0][::2] - truth.x, before[1][::2] - truth.y)
    assert np.median(moved) < 0.25 < 0.5 < np.median(kept)
    # Until the next fix the gain's search comes at its base interval, also in a worker
    # that takes the session up from the store.
    state = pf.checkpoint()
    assert state["search_at_base"]
    again = ParticleFilter(pf.map, pf.config, rng=np.random.default_rng(1))
    data = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": state})
    again.restore(checkpoint.unpack(data)["filter"])
    assert again._search_at_base and TABLE in again.sensor.excluded


@pytest.mark.parametrize(
    ("world", "at"),
    [
        # Nothing moved: every object's absence leaves the place where it is.
        (corridor(OBJECTS), (5.4, 1.5, 0.0)),
        # The plant moved across the corridor, 9 m ahead: it pulls the fix little, and
        # without the table (the one that moves the place most) the place goes off.
        (_world(PLANT, 0.0, 1.0), (5.5, 1.43, -0.03)),
        # A jump, not a drag: the place let go is far from where the odometry carried
        # the fix.
        (_world(TABLE, 1.2, 0.0), (5.4 - SLIDE_BLAME_SPAN_M - 1.0, 1.5, 0.0)),
    ],
)
def test_no_object_is_blamed_that_does_not_take_the_place_back(
    world: SemanticMap, at: tuple[float, float, float]
) -> None:
    pf, _ = _let_go(world, at)
    before = pf.x.copy()
    pf._blame_the_slide(_raw(at))
    assert pf.unseen is not None and not pf.unseen.moved.any()
    assert pf.sensor.excluded == () and np.array_equal(pf.x, before)
    assert not pf.checkpoint()["search_at_base"]


def test_a_fixture_is_never_taken_for_moved() -> None:
    pf, _ = _let_go(corridor(OBJECTS), (5.4, 1.5, 0.0))
    assert pf.unseen is not None
    door = int(np.flatnonzero(pf.map.fixed)[0])
    with pytest.raises(ValueError, match="fixture"):
        pf.unseen.take_moved(door)
    assert not pf.unseen.moved.any() and not pf.unseen.absent.any()


@pytest.mark.parametrize("older_key", ["after_ride", "after_blame"])
def test_a_checkpoint_of_the_last_releases_keeps_asking_for_the_search(older_key: str) -> None:
    # The flag was kept as after_ride (a ride) or after_blame (a blame) before the two
    # became one; a session stored then is taken up asking for the search all the same.
    pf, _ = _let_go(corridor(OBJECTS), (5.4, 1.5, 0.0))
    state = pf.checkpoint()
    del state["search_at_base"]
    for flag in (True, False):
        again = ParticleFilter(pf.map, pf.config, rng=np.random.default_rng(1))
        again.restore({**state, older_key: flag})
        assert again.checkpoint()["search_at_base"] is flag
