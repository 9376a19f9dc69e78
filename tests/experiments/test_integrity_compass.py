"""The integrity suite's compass scenarios: the symmetric room, and choosing scenarios."""

from __future__ import annotations

import numpy as np
import pytest

from app.experiments.hard_maps import hard_map
from app.experiments.integrity import CONDITIONS, Scenario, run_scenario, scenarios


def test_the_symmetric_room_is_the_same_after_a_half_turn() -> None:
    m = hard_map("symmetric_room").map
    assert "door" not in m.classes
    for cls, members in m.class_members.items():
        pts = m.object_xy[members]
        turned = np.array([12.0, 8.0]) - pts  # half turn about the centre (6, 4)
        key = lambda a: sorted(map(tuple, np.round(a, 9)))  # noqa: E731
        assert key(turned) == key(pts), cls


def test_compass_conditions_carry_a_compass() -> None:
    sim = Scenario("symmetric_room", "compass-60off-late-180").simulation()
    assert sim.compass_std_deg is not None and sim.fov_deg == 180.0
    assert [(b.start_s, b.end_s, b.bias_deg) for b in sim.compass_biases] == [(20.0, 40.0, 60.0)]
    assert Scenario("symmetric_room", "nominal-180").simulation().compass_std_deg is None


def test_scenarios_can_be_chosen() -> None:
    chosen = scenarios(select="symmetric_room/compass-180,*/nominal-90")
    assert [s.name for s in chosen] == [
        "paper_office / nominal-90",
        "rotation_room / nominal-90",
        "symmetric_room / compass-180",
    ]
    every = [s for s in scenarios() if s.map_name == "symmetric_room"]
    assert every and scenarios(select="symmetric_room") == every
    assert all(s.condition in CONDITIONS for s in scenarios())
    with pytest.raises(ValueError, match="unknown map 'nope'"):
        scenarios(select="nope")
    with pytest.raises(ValueError, match="unknown condition 'sideways'"):
        scenarios(select="*/sideways")


def test_only_a_compass_ends_the_half_turn_ambiguity() -> None:
    """Same walk, same seed: without a compass the filter rightly never claims a fix (the
    two ways round explain everything equally); with one it fixes, and never wrongly."""
    without = run_scenario(Scenario("symmetric_room", "nominal-360"), 0, 3000)
    with_compass = run_scenario(Scenario("symmetric_room", "compass-360"), 0, 3000)
    assert not np.any(without.converged & (without.err_m > 1.0))
    assert not np.any(with_compass.converged & (with_compass.err_m > 1.0))
    assert with_compass.converged.mean() > 0.8
    assert with_compass.converged.mean() > without.converged.mean() + 0.5
