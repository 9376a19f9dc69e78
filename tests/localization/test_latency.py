"""Detections weighed at their capture pose (app/localization/latency.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.latency import LAG_MAX_S, CaptureClock, LatencyEstimate, fraction, inverse
from app.localization.motion import compose_odometry
from app.localization.types import Detection, InitialPose, Odometry
from app.maps.model import SemanticMap

motions = st.builds(Odometry, st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, 3))
#: float64 compositions of a few sines and cosines of angles up to 3 rad, and sums of
#: numbers up to a few metres: a few units in the last place of the largest.
TOL = 64 * np.finfo(np.float64).eps * 8.0


@settings(max_examples=200, deadline=None)
@given(motions)
def test_a_motion_and_its_inverse_compose_to_nothing(m: Odometry) -> None:
    for pair in ((m, inverse(m)), (inverse(m), m)):
        z = compose_odometry(*pair)
        assert z is not None
        assert abs(z.forward_m) < TOL and abs(z.left_m) < TOL and abs(z.turn_rad) < TOL


@settings(max_examples=200, deadline=None)
@given(motions)
def test_the_whole_of_a_motion_is_itself_and_halves_add_up_for_straight_moves(
    m: Odometry,
) -> None:
    whole = fraction(m, 1.0)
    assert math.isclose(whole.forward_m, m.forward_m, abs_tol=TOL)
    assert math.isclose(whole.left_m, m.left_m, abs_tol=TOL)
    straight = Odometry(m.forward_m, m.left_m, 0.0)
    halves = compose_odometry(fraction(straight, 0.5), fraction(straight, 0.5))
    assert halves is not None
    assert math.isclose(halves.forward_m, m.forward_m, abs_tol=TOL)
    assert math.isclose(halves.left_m, m.left_m, abs_tol=TOL)


def test_without_an_age_the_motion_passes_unchanged() -> None:
    clock = CaptureClock()
    for m in (Odometry(0.1, 0.02, 0.3), Odometry(-0.2, 0.0, -1.0)):
        assert clock.step(m, 0.1, 0.0) == m
    assert clock.step(None, 0.1, 0.2) is None


def test_an_age_longer_than_a_frame_reaches_back_over_several() -> None:
    clock = CaptureClock()
    for _ in range(5):
        clock.step(Odometry(0.1, 0.0, 0.0), 0.1, 0.25)
    # Walking straight at 1 m/s: the capture was 0.25 m behind the frame's end.
    assert math.isclose(clock.back.forward_m, 0.25, abs_tol=1e-12)
    assert clock.back.left_m == 0.0 and clock.back.turn_rad == 0.0


def spin_frames(
    m: SemanticMap, x: float, y: float, rate_rad_s: float, lag_s: float, frames: int, rng
) -> list[tuple[Odometry, list[Detection], float]]:
    """A person turning on the spot at ``rate_rad_s``, 10 frames/s, whose detections
    show every object in view as seen ``lag_s`` before each frame's end."""
    out = []
    for k in range(1, frames + 1):
        seen_at = rate_rad_s * (0.1 * k - lag_s)
        dets = []
        for i in range(m.object_count):
            ox, oy = m.object_xy[i]
            b = math.atan2(oy - y, ox - x) - seen_at
            dets.append(Detection(m.class_of(i), float(rng.normal(b, math.radians(2.0))), 0.9))
        out.append((Odometry(0.0, 0.0, rate_rad_s * 0.1), dets, 0.1 * k * rate_rad_s))
    return out


def test_telling_the_latency_keeps_a_turning_person_located(small_room: SemanticMap) -> None:
    """Turning at 90 deg/s with detections 0.2 s old: 18 degrees of bearing error if
    weighed at the frame's end. Told the age, the filter's heading stays on the truth."""
    rate, lag = math.radians(90.0), 0.2
    errors = {}
    for told in (0.0, lag):
        rng = np.random.default_rng(4)
        pf = ParticleFilter(
            small_room,
            FilterConfig(particles=3000),
            rng=np.random.default_rng(5),
            initial_pose=InitialPose(3.0, 1.5, 0.0, 0.1, math.radians(3.0)),
        )
        offs = []
        for odo, dets, heading in spin_frames(small_room, 3.0, 1.5, rate, lag, 30, rng):
            est = pf.step(odo, dets, detections_age_s=told, frame_s=0.1)
            offs.append(abs((est.theta_rad - heading + math.pi) % (2 * math.pi) - math.pi))
        # (the first two frames' detections were captured before the session began)
        errors[told] = max(offs[2:])
    assert errors[lag] < math.radians(5.0), errors
    assert errors[0.0] > math.radians(12.0), errors


def test_an_unsaid_latency_is_learnt_from_the_lag_in_turns() -> None:
    """Bearings seen 0.2 s late while turning at w are off by 0.2 w: the estimate finds
    0.2 s once turns have said enough, whatever age was applied meanwhile, and ignores
    frames walking straight, lone detections and residuals of another object."""
    est = LatencyEstimate()
    rng = np.random.default_rng(0)
    applied = 0.0
    while est.age_s is None:
        w = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.4, 1.5))
        lag = (0.2 - applied) * w  # what is left after the age applied
        est.update([lag + float(rng.normal(0.0, 0.01)) for _ in range(3)], w, applied)
        est.update([0.3, 0.3, 0.3], 0.1, applied)  # walking straight: no evidence
        est.update([lag], w, applied)  # one detection: no evidence
        est.update([lag, 1.0, -1.0], w, applied)  # two far residuals: no evidence
        applied = 0.1
    assert est.age_s == pytest.approx(0.2, abs=0.02)
    back = LatencyEstimate()
    back.restore(est.checkpoint())
    assert back.age_s == est.age_s
    back.restore(None)
    assert back.age_s is None


def test_a_learnt_latency_stays_in_its_bounds() -> None:
    est = LatencyEstimate()
    for _ in range(10):
        est.update([-0.2, -0.2], 1.0, 0.0)  # bearings ahead of the turn: no negative age
    assert est.turn_sq >= 2.0 and est.age_s is None
    small = LatencyEstimate()
    for _ in range(10):
        small.update([0.01, 0.01], 1.0, 0.0)  # 0.01 s: as a walk without latency learns
    assert small.age_s is None
    for _ in range(40):
        est.update([0.25, 0.25], 0.4, 0.0)  # 0.6 s
    assert est.age_s is not None and est.age_s <= LAG_MAX_S


def _late_phone_walk(timed: bool) -> ParticleFilter:
    """The office suite's walk through a phone in the hand (its sway turns it all the
    time) whose detections are 0.2 s old and that does not say so, at 5 frames/s, fed
    from a known start with or without the frames' durations: the filter after it."""
    from app.experiments import phone
    from app.simulation.phone import PhoneEffects, simulate_phone

    scenario = phone.Scenario("office_suite", "ideal-360")
    sm, _ = phone.suite_map(scenario.map_name)
    walk = phone.walk_of(scenario)
    effects = PhoneEffects(latency_s=(0.2, 0.2), latency_known=False, sway_deg=8.0)
    frames = simulate_phone(sm, walk, effects, np.random.default_rng(1))
    assert frames[1].t - frames[0].t == pytest.approx(0.2)
    start = frames[0].truth
    pf = ParticleFilter(
        sm,
        FilterConfig(particles=3000),
        rng=np.random.default_rng(2),
        initial_pose=InitialPose(start.x, start.y, start.theta_rad, 0.05, math.radians(1.0)),
    )
    last = None
    for f in frames:
        assert f.detections_age_s is None  # the app does not say it
        frame_s = None if last is None or not timed else f.t - last
        pf.step(f.odometry, f.detections, frame_s=frame_s)
        last = f.t
    return pf


def test_the_filter_learns_a_phones_unsaid_latency_on_a_walk() -> None:
    """By the walk's end the filter weighs the detections back by most of their age,
    never more (0.14-0.16 s on seeds 1-3; the filter's own heading follows late bearings
    part of the way, and a walk turning only at its corners learns far less)."""
    learnt = _late_phone_walk(timed=True).latency.age_s
    assert learnt is not None and 0.08 < learnt <= 0.2


def test_the_filter_learns_an_untimed_phones_latency_in_frames() -> None:
    """The same walk sent without timestamps (and so without frame durations): the lag is
    learnt in frames, each taken for latency.DEFAULT_FRAME_S. The walk's 5 frames/s put
    0.2 s one frame back: most of a frame is learnt (0.69-0.84 of it on seeds 1-3), never
    more, and the timed learner learns nothing."""
    from app.localization.latency import DEFAULT_FRAME_S

    pf = _late_phone_walk(timed=False)
    learnt = pf.latency_untimed.age_s
    assert learnt is not None and 0.4 * DEFAULT_FRAME_S < learnt <= DEFAULT_FRAME_S
    assert pf.latency.age_s is None
