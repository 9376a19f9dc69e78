"""tools/odometry_scale.py: the scale a walk asks for, and the suites' per-frame hooks it
reads the filter's scale through."""

from __future__ import annotations

import math

import pytest

from app.experiments import venue
from app.experiments.phone import Scenario, run_scenario
from app.localization.types import Odometry, Pose
from tools.odometry_scale import OdometryTrace


def test_the_wanted_scale_and_drift_are_the_walks() -> None:
    """A walk turning as it goes, its odometry reading 10 % long and turning 0.01 rad a
    second too far: the filter should learn 1 / 1.1 and 0.01 rad/s; one that learnt 0.95
    and 0.008 rad/s on the second half is off by 0.95 - 1 / 1.1 and -0.002 rad/s."""
    trace = OdometryTrace()
    x = y = theta = 0.0
    dt, drift = 0.2, 0.01
    for i in range(40):
        if i:
            # (carried on an escalator at frame 20: moved and turned, no step counted)
            fwd = 0.1 * 1.1 if i != 20 else 0.0
            step = Odometry(fwd, 0.0, 0.05 + drift * dt if i != 20 else 0.0)
            x, y = x + 0.1 * math.cos(theta), y + 0.1 * math.sin(theta)
            theta += 0.05
        else:
            step = None
        # An unwalked frame (a ride): its motion is not summed.
        learnt = (1.0, 0.0) if i < 20 else (0.95, 0.008)
        trace.frame(i * dt, Pose(x, y, theta), step, i != 20, learnt)
    abs_err, signed, unlearnt = trace.errors()
    wanted = 1.0 / 1.1
    assert signed == pytest.approx(0.95 - wanted, rel=1e-9)
    assert abs_err == pytest.approx(abs(0.95 - wanted), rel=1e-9)
    assert unlearnt == pytest.approx(1.0 - wanted, rel=1e-9)
    per_min = math.degrees(1.0) * 60.0
    abs_d, signed_d, unlearnt_d = trace.drift_errors()
    assert signed_d == pytest.approx(-0.002 * per_min, rel=1e-6)
    assert abs_d == pytest.approx(0.002 * per_min, rel=1e-6)
    assert unlearnt_d == pytest.approx(drift * per_min, rel=1e-6)


def test_the_phone_suite_calls_back_after_every_frame_with_its_session() -> None:
    seen = []
    run = run_scenario(
        Scenario("office_suite", "pdr-180"), 0, 500, max_s=3.0,
        on_frame=lambda session, frame, out: seen.append(
            (session.filter.odometry_bias is not None, frame.t, out.estimate.x)
        ),
    )  # fmt: skip
    assert [t for _, t, _ in seen] == run.t.tolist()
    assert all(has_bias for has_bias, _, _ in seen)  # a PDR phone's session estimates it


def test_the_venue_suite_calls_back_after_every_frame_of_the_venues_filter() -> None:
    seen = []
    run = venue.run_condition(
        "phone-pdr-180", 0, 300, on_step=lambda pf, vf, est: seen.append((vf.frame.t, est.x))
    )
    assert [t for t, _ in seen] == run.t.tolist()
