"""Sessions on a venue of several floors: checkpoints carry the level, a known start's level."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.types import InitialPose
from app.service import checkpoint
from app.service.errors import InvalidSessionSpec
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.sharing import rebuild
from app.service.store import MemoryStore
from app.service.types import FrameInput, SessionSpec
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import VENUE_NAME, venue_legs, venue_map
from app.simulation.venue_walk import VenueFrame, simulate_venue
from tests.helpers import make_settings

VENUE = venue_map()
#: A walk of the venue suite's phone-vio-66 condition whose first lift ride ends
#: before the place on the new floor is found.
SEED_66 = 0


def manager() -> SessionManager:
    return SessionManager({VENUE_NAME: VENUE}, make_settings(), Metrics(), MemoryStore(shared=True))


def frames() -> list[VenueFrame]:
    start, legs = venue_legs()
    cfg = SimulationConfig(path=((0.0, 0.0),), miss_prob=0.1)
    return simulate_venue(VENUE, start, legs[:3], cfg, np.random.default_rng(7))


def inputs(vf: VenueFrame, timed: bool = False) -> FrameInput:
    """A frame of the venue walk as a session takes it (``timed``: see phone_inputs)."""
    f = vf.frame
    return FrameInput(
        timestamp=f.t if timed else None,
        odometry=f.odometry,
        detections=tuple(f.detections),
        altitude=vf.altitude,
    )


def phone_inputs(i: int, vf: VenueFrame, timed: bool = False) -> FrameInput:
    """Frame ``i`` of a phone's walk as a session takes it: the first without odometry,
    the detections' age when the phone gives it; ``timed``: with the frame's timestamp
    (without one, what the narrator says at most every few seconds goes by the wall
    clock)."""
    f = vf.frame
    return FrameInput(
        timestamp=f.t if timed else None,
        odometry=None if i == 0 else f.odometry,
        detections=tuple(f.detections),
        altitude=vf.altitude,
        detections_age_s=getattr(f, "detections_age_s", None) or 0.0,
    )


def test_a_restored_venue_session_keeps_its_level_and_barometer_and_goes_on_exactly() -> None:
    m = manager()
    spec = SessionSpec(map_name=VENUE_NAME, particles=2000, seed=5)  # kept whole
    a = m.build(spec)
    walk = frames()
    # Up to the middle of the lift ride: the barometer's anchor and the level matter.
    riding = next(i for i, vf in enumerate(walk) if vf.riding) + 40
    for vf in walk[:riding]:
        a.process_sync(inputs(vf, timed=True))
    assert a.filter.floors is not None and a.filter.floors.changes >= 1
    state = checkpoint.unpack(checkpoint.pack(a.capture()))
    assert state["filter"]["floors"]["anchor_m"] == a.filter.floors.anchor_m
    b = rebuild(m, state)
    for vf in walk[riding : riding + 60]:
        frame = inputs(vf, timed=True)  # the narrator's clock is the frames'
        out_a, out_b = a.process_sync(frame), b.process_sync(frame)
        assert out_a.estimate == out_b.estimate and out_a.level == out_b.level
        assert out_a.feedback == out_b.feedback
    assert out_a.level is not None and out_a.level.id == "L2"
    m.close()


def test_a_known_start_names_its_level_or_covers_every_level() -> None:
    m = manager()
    pose = InitialPose(6.0, 11.0, 0.0, 0.2, 0.1)
    on_l1 = m.build(
        SessionSpec(
            map_name=VENUE_NAME, particles=2000, seed=1, initial_pose=pose, initial_level="L1"
        )
    )
    levels = VENUE.layout.level_of_plane_x(on_l1.filter.x)
    assert (levels == 1).all()
    anywhere = m.build(SessionSpec(map_name=VENUE_NAME, particles=3000, seed=1, initial_pose=pose))
    counts = np.bincount(VENUE.layout.level_of_plane_x(anywhere.filter.x), minlength=3)
    assert (counts > 800).all()
    with pytest.raises(InvalidSessionSpec, match="'L7' is not a level"):
        m.build(SessionSpec(map_name=VENUE_NAME, initial_pose=pose, initial_level="L7"))
    m.close()


def test_through_a_narrow_camera_the_floor_is_said_after_a_ride_before_the_place_is_found() -> None:
    """A phone held in the hand sees little in a lift car and loses the place there;
    the barometer's count of storeys still says the floor on leaving it. The session
    says it then ("You are on the Second Floor.") while not yet converged, and never
    names a floor the person is not on."""
    from app.experiments.venue import CONDITIONS, _walk
    from app.service.types import SensorSpec

    _, walk, legs = _walk(SEED_66, CONDITIONS["phone-vio-66"])
    spec = SessionSpec(
        map_name=VENUE_NAME,
        particles=10_000,
        seed=SEED_66 + 1,
        sensor=SensorSpec(fov_deg=66.0),
        odometry_source="vio",
    )
    session = manager().build(spec)
    ride = next(k for k, leg in enumerate(legs) if hasattr(leg, "to_level"))
    end = max(i for i, vf in enumerate(walk) if vf.leg == ride)
    unlocated_floor = []
    for i, vf in enumerate(walk[: end + 50]):
        out = session.process_sync(phone_inputs(i, vf))
        for lv in VENUE.layout.levels:
            if f"You are on the {lv.name}." in out.feedback.text:
                assert lv.id == VENUE.layout.levels[vf.level].id, (i, out.feedback.text)
                if i > end - 25 and not out.estimate.converged:
                    unlocated_floor.append(i)
    assert unlocated_floor, "the floor was not said before the place was found"


def test_a_session_restored_after_a_ride_it_was_pinned_to_goes_on_exactly() -> None:
    """A narrow camera loses the place in the lift car; the ride's stop becomes the
    alternatives' known start, loosened by the distance walked since. A session captured
    a few metres after it and restored (a worker lost, the store kept) takes the very
    same steps: the walked distance rides in the checkpoint."""
    from app.experiments.venue import CONDITIONS, _walk
    from app.service.types import SensorSpec

    cond = CONDITIONS["phone-pdr-66"]
    _, walk, _ = _walk(6, cond)
    spec = SessionSpec(
        map_name=VENUE_NAME,
        particles=2000,  # kept whole by the checkpoint
        seed=7,
        sensor=SensorSpec(fov_deg=66.0),
        odometry_source="pdr",
    )
    m = manager()
    a = m.build(spec)

    cut = None
    for i, vf in enumerate(walk):
        a.process_sync(phone_inputs(i, vf, timed=True))
        ev = a.filter.evidence
        assert ev is not None
        if ev._prior_drift > 0.0 and ev._prior_walked_m > 3.0:
            cut = i + 1
            break
    assert cut is not None, "no ride the belief was pinned to"
    state = checkpoint.unpack(checkpoint.pack(a.capture()))
    b = rebuild(m, state)
    for i, vf in enumerate(walk[cut : cut + 300], start=cut):
        frame = phone_inputs(i, vf, timed=True)  # the narrator's clock is the frames'
        out_a, out_b = a.process_sync(frame), b.process_sync(frame)
        assert out_a.estimate == out_b.estimate and out_a.feedback == out_b.feedback, i
    m.close()
