"""tools/why_not_located.py: the frames right and not told, counted by the gate's reasons."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from app.bench import generated_map
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.types import Estimate, Pose
from tools.why_not_located import _count, main


def test_a_right_frame_not_told_counts_under_the_gates_reasons() -> None:
    pf = ParticleFilter(
        generated_map(10), FilterConfig(particles=500), rng=np.random.default_rng(1)
    )
    est = pf.step(None, [])  # a global start: no fix, and the gate says why
    assert not est.converged and pf.gate.not_gained_because
    tally: Counter[str] = Counter()
    near = Pose(est.x + 0.3, est.y, 0.0)
    far = Pose(est.x + 3.0, est.y, 0.0)
    _count(pf, near, est, tally)
    _count(pf, far, est, tally)
    assert tally["frames"] == 2 and tally["near"] == 1 and tally["told"] == 0
    for reason in pf.gate.not_gained_because:
        assert tally[reason] == 1
    told = Estimate(est.x, est.y, 0.0, 0.1, 0.1, 0.1, True, ())
    _count(pf, near, told, tally)
    assert tally["told"] == 1 and tally["near"] == 2


def test_an_unknown_row_is_refused_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["venue", "phone-vio-99"])
    assert "no venue condition 'phone-vio-99'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["phone", "door_corridor/vio-99"])
    assert "no phone condition 'vio-99'" in capsys.readouterr().err
