"""Frames without odometry: a short timed gap is walked through, a long or untimed one
lets the fix go (app.localization.gap)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.gap import GAP_HOLD_S, OdometryGap
from app.localization.motion import NO_ODOMETRY_STD_M, GuessedMotion, sample_motion
from app.localization.types import Odometry
from app.maps.model import SemanticMap
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate


def test_a_short_gap_is_walked_at_the_recent_velocity() -> None:
    gap = OdometryGap(360.0)
    for _ in range(30):
        motion, broke = gap.frame(Odometry(0.1, 0.02, 0.05), 0.2)
        assert not broke
    assert gap.velocity == pytest.approx((0.5, 0.1), rel=1e-3)
    motion, broke = gap.frame(None, 0.4)
    assert isinstance(motion, GuessedMotion) and not broke
    moved = (motion.forward_m, motion.left_m, motion.turn_rad)
    assert moved == pytest.approx((0.2, 0.04, 0.0), rel=1e-3)


def test_a_gap_longer_than_the_hold_breaks_off_once() -> None:
    gap = OdometryGap(360.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    # (Frames of 0.25 s: sums of them are exact in binary floating point.)
    frames = int(GAP_HOLD_S / 0.25) + 5
    out = [gap.frame(None, 0.25) for _ in range(frames)]
    broke = [k for k, (_, b) in enumerate(out) if b]
    assert len(broke) == 1
    assert GAP_HOLD_S < 0.25 * (broke[0] + 1) <= GAP_HOLD_S + 0.25
    assert all(m is None for m, _ in out[broke[0] :])
    assert all(isinstance(m, GuessedMotion) for m, _ in out[: broke[0]])


def test_a_frame_of_unknown_duration_breaks_off_at_once_and_moves_by_nothing() -> None:
    gap = OdometryGap(360.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    assert gap.frame(None, None) == (None, True)
    # ... and the gap stays unbounded until odometry comes back.
    assert gap.frame(None, 0.2) == (None, False)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    motion, broke = gap.frame(None, 0.2)
    assert isinstance(motion, GuessedMotion) and not broke


def test_a_camera_that_does_not_see_all_around_walks_no_gap_through() -> None:
    gap = OdometryGap(180.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    assert gap.frame(None, 0.2) == (None, True)
    assert gap.frame(None, 0.2) == (None, False)


def test_the_gap_survives_a_checkpoint() -> None:
    gap = OdometryGap(360.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    gap.frame(None, 0.2)
    again = OdometryGap(360.0)
    again.restore(gap.checkpoint(), had_odometry=False)
    assert again.checkpoint() == gap.checkpoint()
    older = OdometryGap(360.0)
    older.restore(None, had_odometry=True)
    assert older.frame(None, None) == (None, True)


def test_a_guessed_motion_moves_the_cloud_by_its_mean_with_more_than_unknown_noise() -> None:
    n = 20_000
    cfg = FilterConfig()
    zeros = np.zeros(n)
    x, y, _ = sample_motion(
        zeros, zeros, zeros, GuessedMotion(0.4, 0.0, 0.0), cfg, np.random.default_rng(0)
    )
    # The mean within four standard errors of the guess; the spread beyond the unknown
    # motion's own (float64 sums of 20,000 draws: far below these margins).
    se = float(np.std(x)) / np.sqrt(n)
    assert abs(float(np.mean(x)) - 0.4) < 4 * se
    assert abs(float(np.mean(y))) < 4 * se
    assert float(np.std(x)) > NO_ODOMETRY_STD_M * 1.05


def _walk_with_a_gap(
    m: SemanticMap, gap_s: float, timed: bool
) -> list[tuple[float, bool, float, str]]:
    """The paper office's nominal walk at 360 deg whose odometry stops for ``gap_s``
    seconds from t = 8 s (a tracker's "limited tracking"): per frame the time,
    converged, the error and why the fix was last let go."""
    sim = replace(paper_config("nominal", 360), duration_s=8.0 + gap_s + 4.0)
    frames = simulate(m, sim, np.random.default_rng(4))
    pf = ParticleFilter(m, FilterConfig(particles=4000), rng=np.random.default_rng(104))
    out = []
    last_t: float | None = None
    for f in frames:
        odo = None if 8.0 <= f.t < 8.0 + gap_s else f.odometry
        frame_s: float | None = None if last_t is None or not timed else f.t - last_t
        e = pf.step(odo, f.detections, frame_s=frame_s)
        err = float(np.hypot(e.x - f.truth.x, e.y - f.truth.y))
        out.append((f.t, e.converged, err, ",".join(pf._gate.lost_because)))
        last_t = f.t
    return out


def test_a_fix_is_kept_through_a_short_gap_in_the_odometry(paper_office: SemanticMap) -> None:
    """Three seconds without odometry, timed: the fix is held and right all along (before,
    the first frame of the gap let it go: "odometry lost")."""
    out = _walk_with_a_gap(paper_office, 3.0, timed=True)
    assert all(conv for t, conv, _, _ in out if 7.0 <= t <= 15.0)
    assert max(err for t, _, err, _ in out if 7.0 <= t <= 15.0) < 0.5


def test_an_untimed_or_long_gap_lets_the_fix_go(paper_office: SemanticMap) -> None:
    """Without the frames' durations nothing bounds how far the person went: the gap's
    first frame lets the fix go; timed, a gap longer than GAP_HOLD_S lets it go once the
    hold is over."""
    untimed = _walk_with_a_gap(paper_office, 3.0, timed=False)
    first = next(k for k, (t, *_) in enumerate(untimed) if t >= 8.0)
    assert untimed[first - 1][1] and not untimed[first][1]
    assert "odometry lost" in untimed[first][3]
    long = _walk_with_a_gap(paper_office, GAP_HOLD_S + 1.0, timed=True)
    released = [
        (t, why)
        for (t, conv, _, why), (_, before, _, _) in zip(long[1:], long[:-1], strict=True)
        if before and not conv
    ]
    # (At the frame whose gap, its frames' durations summed, first passes the hold: the
    # walk's frames are 0.2 s apart, the sum's last bit decides between two of them.)
    hold_ends = 8.0 + GAP_HOLD_S
    assert [why for t, why in released if hold_ends - 0.25 < t <= hold_ends + 0.25] == [
        "odometry lost"
    ], released
    assert all(conv for t, conv, _, _ in long if 7.0 <= t < hold_ends - 0.25)


def test_a_gap_broken_off_guesses_no_more_until_odometry_comes_back() -> None:
    gap = OdometryGap(360.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    gap.frame(None, 0.2)
    assert gap.guessed
    assert gap.break_off()
    assert not gap.guessed
    assert gap.frame(None, 0.2) == (None, False)
    motion, _ = gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    assert not gap.guessed and motion == Odometry(0.1, 0.0, 0.0)
    motion, broke = gap.frame(None, 0.2)
    assert gap.guessed and isinstance(motion, GuessedMotion) and not broke


def test_no_gap_is_walked_through_where_the_person_may_be_riding() -> None:
    gap = OdometryGap(360.0)
    gap.frame(Odometry(0.1, 0.0, 0.0), 0.2)
    assert gap.frame(None, 0.2, may_guess=False) == (None, True)
    # ... nor later in the same gap, once the ride is over.
    assert gap.frame(None, 0.2) == (None, False)


@pytest.mark.parametrize("barometer", [True, False])
def test_a_venue_walks_a_gap_through_only_with_a_barometer_and_away_from_its_connectors(
    barometer: bool,
) -> None:
    """On a map with levels, stairs, an escalator or a lift car move a person otherwise
    than the walk before them (measured, the venue suite's stairs with the tracker lost
    for the climb: fixes 1.0-1.4 m off, 24 frames in 10 walks, when walked through); and
    without a barometer nothing says a ride began. Standing in the middle of the ground
    floor's hall, far from every stop, with a barometer: walked through."""
    from app.localization.floors import AltitudeReading
    from app.simulation.venue import venue_map

    venue = venue_map()
    pf = ParticleFilter(venue, FilterConfig(particles=500), rng=np.random.default_rng(0))
    floors = pf.floors
    assert floors is not None
    here = next(
        (x, y)
        for x in np.linspace(*venue.bounds[0::2], 40)
        for y in np.linspace(*venue.bounds[1::2], 40)
        if bool(venue.free_space.is_free(x, y)) and not floors.in_stop(x, y)
    )
    altitude = AltitudeReading(0.0) if barometer else None
    for k in range(4):
        pf.step(Odometry(0.1, 0.0, 0.0), [], altitude=altitude, frame_s=None if k == 0 else 0.2)
    pf.estimate = replace(pf.estimate, x=float(here[0]), y=float(here[1]))
    pf.step(None, [], altitude=altitude, frame_s=0.2)
    assert pf.gap.guessed == barometer


def test_a_filter_restored_mid_gap_goes_on_as_the_one_that_was_not(
    paper_office: SemanticMap,
) -> None:
    """A session handed to another worker in the middle of a gap (its checkpoint through
    the store) walks the rest of it through as it would have: same guesses, same
    answers (the gap's run and the walk's velocity are in the checkpoint)."""
    sim = replace(paper_config("nominal", 360), duration_s=12.0)
    frames = simulate(paper_office, sim, np.random.default_rng(4))
    cfg = FilterConfig(particles=2000)
    pf = ParticleFilter(paper_office, cfg, rng=np.random.default_rng(104))
    twin: ParticleFilter | None = None
    last_t: float | None = None
    for f in frames:
        odo = None if 8.0 <= f.t < 10.0 else f.odometry
        frame_s = None if last_t is None else f.t - last_t
        if twin is None and f.t >= 9.0:
            assert pf.gap.guessed and pf.estimate.converged
            state = pf.checkpoint()
            twin = ParticleFilter(paper_office, cfg, rng=np.random.default_rng(7), state=state)
        a = pf.step(odo, f.detections, frame_s=frame_s)
        if twin is not None:
            b = twin.step(odo, f.detections, frame_s=frame_s)
            assert (b.x, b.y, b.theta_rad, b.converged) == (a.x, a.y, a.theta_rad, a.converged)
            assert twin.gap.checkpoint() == pf.gap.checkpoint()
        last_t = f.t
    assert twin is not None
