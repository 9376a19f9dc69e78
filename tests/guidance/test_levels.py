"""Guidance across levels, on the bundled Riverside Station (made by the IMDF importer
from tests/maps/data/riverside_imdf; the layout is described in tests/maps/test_imdf.py).

Map frame: the building's middle is (0, 0); the corridor of every level runs along
y = -4 .. 4; the stairs (x -12 .. -7), the up escalator (-7 .. -4), the down escalator
(-4 .. -1) and the lift (-1 .. 2, y 4 .. 7) stand north of it; the up escalator and the
down one join the ground and first floors only, the stairs and the lift all three.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from app.feedback.guidance import GuidanceSpeaker, directions
from app.guidance import DestinationSpec, UnknownDestination, Unreachable, guide, plan_for
from app.guidance.levels import ride_cost_m
from app.maps.check import load_map
from app.maps.model import SemanticMap, parse_map
from app.resources import bundled_maps_dir

VENUE = load_map(bundled_maps_dir() / "riverside_station.json")
ENTRANCE_HALL = (-14.0, -8.0)  # ground floor, by the main entrance
UP, DOWN, STAIRS, LIFT = "escalator-1", "escalator-2", "stairs-1", "elevator-1"


def _without(connector_ids: set[str]) -> SemanticMap:
    data = copy.deepcopy(VENUE.to_json())
    data["connectors"] = [c for c in data["connectors"] if c["id"] not in connector_ids]
    return parse_map(data)


def _stop_middle(m: SemanticMap, connector_id: str, level: str) -> np.ndarray:
    conn = m.layout.connector(connector_id)
    stop = conn.stop_on(m.layout.level_index(level))
    assert stop is not None
    return stop.polygon.mean(axis=0)


def test_the_bundled_venue_is_what_the_tests_expect() -> None:
    layout = VENUE.layout
    assert [lv.id for lv in layout.levels] == ["L0", "L1", "L2"]
    kinds = {c.id: (c.kind, c.direction, c.levels) for c in layout.connectors}
    assert kinds == {
        UP: ("escalator", "up", (0, 1)),
        DOWN: ("escalator", "down", (0, 1)),
        LIFT: ("elevator", "both", (0, 1, 2)),
        STAIRS: ("stairs", "both", (0, 1, 2)),
    }


def test_up_a_level_by_the_escalator_then_on_to_the_target() -> None:
    plan = plan_for(VENUE, DestinationSpec("region", "Bakery"))
    g = guide(plan, *ENTRANCE_HALL, 0.0, "L0")
    assert g.connector is not None and not g.arrived
    c = g.connector
    assert (c.id, c.kind, c.direction, c.to_level.id) == (UP, "escalator", "up", "L1")
    assert not c.at_stop
    # The directions lead to the escalator's stop, in the ground floor's part of the plane.
    end = VENUE.layout.from_plane(g.path[-1:])[0][0]
    assert np.allclose(end, _stop_middle(VENUE, UP, "L0"), atol=0.3)
    assert g.path_m == pytest.approx(float(np.hypot(*np.diff(g.path, axis=0).T).sum()), abs=0.01)
    # At the stop: time to take it.
    at = guide(plan, *_stop_middle(VENUE, UP, "L0"), 0.0, "L0")
    assert at.connector is not None and at.connector.at_stop
    assert directions(at) == "Take the escalator up to the First Floor."
    # Off the escalator on the first floor: no level change left, on to the bakery.
    off = guide(plan, *_stop_middle(VENUE, UP, "L1"), 0.0, "L1")
    assert off.connector is None and off.path_m > 5.0
    assert VENUE.layout.from_plane(off.path[-1:])[1][0] == 1
    assert not off.arrived


def test_escalators_only_their_way() -> None:
    plan = plan_for(VENUE, DestinationSpec("region", "Entrance Hall"))
    # Standing by the up escalator's top on the first floor: down is by the down one.
    g = guide(plan, *_stop_middle(VENUE, UP, "L1"), 0.0, "L1")
    assert g.connector is not None
    assert (g.connector.id, g.connector.direction, g.connector.to_level.id) == (DOWN, "down", "L0")
    # Without the down escalator the stairs, never the up escalator, nearer as it is.
    no_down = _without({DOWN})
    g = guide(plan_for(no_down, DestinationSpec("region", "Entrance Hall")),
              *_stop_middle(VENUE, UP, "L1"), 0.0, "L1")  # fmt: skip
    assert g.connector is not None and g.connector.id == STAIRS
    # With neither the down escalator, the stairs nor the lift, there is no way down.
    cut_off = _without({DOWN, STAIRS, LIFT})
    with pytest.raises(Unreachable):
        guide(plan_for(cut_off, DestinationSpec("region", "Entrance Hall")), 0.0, 0.0, 0.0, "L1")


def test_step_free_takes_the_lift() -> None:
    plan = plan_for(VENUE, DestinationSpec("region", "Bakery", step_free=True))
    assert plan.target.step_free
    g = guide(plan, *ENTRANCE_HALL, 0.0, "L0")
    assert g.connector is not None
    assert (g.connector.id, g.connector.kind, g.connector.to_level.id) == (LIFT, "elevator", "L1")
    assert directions(g).startswith("The elevator up to the First Floor: go ")
    # A plan without step_free is another plan (cached apart).
    assert plan is not plan_for(VENUE, DestinationSpec("region", "Bakery"))
    # Without the lift nothing step-free leads up, and the speaker says so.
    assert GuidanceSpeaker().no_way("Bakery", 0.0, step_free=True) == (
        "I cannot find a step-free way from here to Bakery."
    )
    with pytest.raises(Unreachable, match=r"no step-free path \(lifts and ramps only\)"):
        no_lift = _without({LIFT})
        guide(plan_for(no_lift, DestinationSpec("region", "Bakery", step_free=True)),
              *ENTRANCE_HALL, 0.0, "L0")  # fmt: skip


def test_two_flights_of_stairs_are_one_ride_to_the_last_level() -> None:
    stairs_only = _without({UP, DOWN, LIFT})
    plan = plan_for(stairs_only, DestinationSpec("region", "Library"))
    g = guide(plan, *ENTRANCE_HALL, 0.0, "L0")
    assert g.connector is not None
    assert (g.connector.id, g.connector.direction, g.connector.to_level.id) == (STAIRS, "up", "L2")
    assert directions(g).startswith("The stairs up to the Second Floor: go ")


def test_a_class_goes_to_the_nearest_by_walking_and_a_level_narrows_it() -> None:
    # Three restrooms, one a floor; from the second floor's gallery the Gents are nearest.
    plan = plan_for(VENUE, DestinationSpec("class", "restroom"))
    g = guide(plan, 10.0, 0.0, 0.0, "L2")
    assert g.connector is None and g.target == "restroom (Gents)"
    only_l0 = plan_for(VENUE, DestinationSpec("class", "restroom", level="L0"))
    g = guide(only_l0, 10.0, 0.0, 0.0, "L2")
    assert g.connector is not None and g.connector.direction == "down"
    with pytest.raises(UnknownDestination, match="level 'L2'"):
        plan_for(VENUE, DestinationSpec("class", "escalator", level="L2"))
    with pytest.raises(UnknownDestination, match="'L7' is not a level"):
        plan_for(VENUE, DestinationSpec("class", "door", level="L7"))


def test_a_point_needs_its_level() -> None:
    with pytest.raises(UnknownDestination, match="needs the level it is on"):
        plan_for(VENUE, DestinationSpec("point", x=10.0, y=0.0))
    plan = plan_for(VENUE, DestinationSpec("point", x=10.0, y=0.0, level="L2"))
    assert plan.target.name == "the point 10.0, 0.0 on Second Floor"
    g = guide(plan, 10.0, 0.0, 0.0, "L0")
    assert g.connector is not None and g.connector.direction == "up"
    here = guide(plan, 10.0, 0.0, 0.0, "L2")
    assert here.connector is None and here.arrived


def test_ride_costs_weigh_height_by_kind() -> None:
    assert ride_cost_m("stairs", 4.0) > ride_cost_m("escalator", 4.0)
    assert ride_cost_m("ramp", 1.0) == 12.0
    assert ride_cost_m("elevator", 8.0) == ride_cost_m("elevator", -8.0) == 28.0


def test_the_speaker_says_the_connector_when_it_applies() -> None:
    plan = plan_for(VENUE, DestinationSpec("region", "Bakery"))
    speaker = GuidanceSpeaker()
    far = guide(plan, *ENTRANCE_HALL, 0.0, "L0")
    first = speaker.update(far, True, 0.0, *ENTRANCE_HALL)
    assert first.startswith("The escalator up to the First Floor: go ")
    stop = _stop_middle(VENUE, UP, "L0")
    at = guide(plan, *stop, 0.0, "L0")
    assert speaker.update(at, True, 1.0, *stop) == ""  # within 2 s of the last words
    assert speaker.update(at, True, 2.5, *stop) == "Take the escalator up to the First Floor."
    assert speaker.update(at, True, 5.0, *stop) == ""  # said once
    top = _stop_middle(VENUE, UP, "L1")
    off = guide(plan, *top, 0.0, "L1")
    assert speaker.update(off, True, 9.0, *top).startswith("Bakery: go ")


def test_one_level_maps_route_as_before() -> None:
    suite = load_map(bundled_maps_dir() / "office_suite.json")
    plan = plan_for(suite, DestinationSpec("label", "main entrance"))
    assert plan.stops == []
    a = guide(plan, 3.0, 8.0, 0.0)
    b = guide(plan, 3.0, 8.0, 0.0, 0)  # level index 0 of a map without levels
    assert a.connector is None and np.array_equal(a.path, b.path)
