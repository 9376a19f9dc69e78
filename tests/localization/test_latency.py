"""Detections weighed at their capture pose (app/localization/latency.py)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.latency import CaptureClock, fraction, inverse
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
