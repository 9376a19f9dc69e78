"""Sessions on a venue of several floors: checkpoints carry the level, a known start's level."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.types import InitialPose
from app.service import checkpoint
from app.service.errors import InvalidSessionSpec
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.store import MemoryStore
from app.service.types import FrameInput, SessionSpec
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import VENUE_NAME, venue_legs, venue_map
from app.simulation.venue_walk import VenueFrame, simulate_venue
from tests.helpers import make_settings

VENUE = venue_map()


def manager() -> SessionManager:
    return SessionManager({VENUE_NAME: VENUE}, make_settings(), Metrics(), MemoryStore(shared=True))


def frames() -> list[VenueFrame]:
    start, legs = venue_legs()
    cfg = SimulationConfig(path=((0.0, 0.0),), miss_prob=0.1)
    return simulate_venue(VENUE, start, legs[:3], cfg, np.random.default_rng(7))


def inputs(vf: VenueFrame) -> FrameInput:
    f = vf.frame
    return FrameInput(odometry=f.odometry, detections=tuple(f.detections), altitude=vf.altitude)


def test_a_restored_venue_session_keeps_its_level_and_barometer_and_goes_on_exactly() -> None:
    m = manager()
    spec = SessionSpec(map_name=VENUE_NAME, particles=2000, seed=5)  # kept whole
    a = m.build(spec)
    walk = frames()
    # Up to the middle of the lift ride: the barometer's anchor and the level matter.
    riding = next(i for i, vf in enumerate(walk) if vf.riding) + 40
    for vf in walk[:riding]:
        a.process_sync(inputs(vf))
    assert a.filter.floors is not None and a.filter.floors.changes >= 1
    state = checkpoint.unpack(checkpoint.pack(a.capture()))
    assert state["filter"]["floors"]["anchor_m"] == a.filter.floors.anchor_m
    b = m.build(
        checkpoint.spec_of(state),
        session_id=state["id"],
        created_at=checkpoint.created_at_of(state),
        filter_state=state["filter"],
    )
    b.restore(state)
    for vf in walk[riding : riding + 60]:
        out_a, out_b = a.process_sync(inputs(vf)), b.process_sync(inputs(vf))
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
