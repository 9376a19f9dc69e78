"""A new fix facing otherwise than the last told one, carried by the odometry, waits."""

from __future__ import annotations

import math

import numpy as np

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.odometry_bias import BIAS_PRIORS
from app.localization.told_heading import (
    BASE_DEG,
    MIN_SINCE_S,
    TURNED_GAIN_FRAMES,
    ToldHeading,
)
from app.localization.types import Odometry, Pose
from tests.helpers import paper_office, seen_from

OFFICE = paper_office()
POSE = Pose(3.0, 2.0, math.pi / 2)


def test_the_told_heading_turns_with_the_odometry() -> None:
    told = ToldHeading(BIAS_PRIORS["vio"])
    assert not told.disagrees(1.0)  # nothing told yet: nothing to disagree with
    told.told(0.5)
    told.moved(Odometry(0.4, 0.0, math.radians(90.0)), 0.2)
    assert told.heading_rad is not None
    assert math.isclose(told.heading_rad, 0.5 + math.radians(90.0))
    # Within MIN_SINCE_S of the told frame nothing disagrees: a fix taken up again so
    # soon continues the one let go.
    assert not told.disagrees(0.5 + math.radians(90.0 + 3.0 * BASE_DEG))
    told.moved(Odometry(0.0, 0.0, 0.0), MIN_SINCE_S)
    assert not told.disagrees(0.5 + math.radians(90.0 + 0.9 * BASE_DEG))
    assert told.disagrees(0.5 + math.radians(90.0 + 1.5 * BASE_DEG))
    assert told.disagrees(0.5 - math.radians(1.5 * BASE_DEG) + math.radians(90.0))


def test_the_allowance_grows_with_the_sources_drift() -> None:
    """From BASE_DEG when told, faster for step counting's gyro than for VIO's."""
    vio, pdr = ToldHeading(BIAS_PRIORS["vio"]), ToldHeading(BIAS_PRIORS["pdr"])
    for told in (vio, pdr):
        told.told(0.0)
        assert math.isclose(told.allowance_rad(), math.radians(BASE_DEG))
    before = vio.allowance_rad()
    for _ in range(300):  # a minute at 5 frames/s
        for told in (vio, pdr):
            told.moved(Odometry(0.1, 0.0, 0.0), 0.2)
    assert before < vio.allowance_rad() < pdr.allowance_rad()
    # A minute of VIO: within a few degrees of the base; of PDR: tens of degrees more.
    assert math.degrees(vio.allowance_rad()) < BASE_DEG + 15.0
    assert math.degrees(pdr.allowance_rad()) > BASE_DEG + 25.0


def test_a_break_in_the_odometry_forgets_the_heading_and_a_checkpoint_keeps_it() -> None:
    told = ToldHeading(BIAS_PRIORS["pdr"])
    told.told(1.0)
    told.moved(Odometry(0.3, 0.0, 0.1), 0.5)
    again = ToldHeading(BIAS_PRIORS["pdr"])
    again.restore(told.checkpoint())
    assert (again.heading_rad, again.since_s) == (told.heading_rad, told.since_s)
    told.moved(None, 0.2)
    assert told.heading_rad is None and told.checkpoint() is None
    again.restore(None)  # a checkpoint from before the heading was kept
    assert again.heading_rad is None


def _first_fix(told_offset_deg: float | None) -> tuple[int, int, tuple[str, ...]]:
    """Standing still at POSE from a global start through a VIO phone's odometry, with a
    fix facing ``told_offset_deg`` off POSE's heading told MIN_SINCE_S before (None:
    none): the
    frame of the first fix, the gate's streak then, and the reasons given on the frame
    before it."""
    config = FilterConfig(particles=3000, odometry_source="vio")
    pf = ParticleFilter(OFFICE, config, rng=np.random.default_rng(1))
    if told_offset_deg is not None:
        pf.told_heading.told(POSE.theta_rad + math.radians(told_offset_deg))
        pf.told_heading.moved(Odometry(0.0, 0.0, 0.0), MIN_SINCE_S)  # told a while ago
    seen = seen_from(OFFICE, POSE)
    why: tuple[str, ...] = ()
    for k in range(120):
        if pf.step(Odometry(0.0, 0.0, 0.0), seen, frame_s=0.2).converged:
            return k, pf.gate.streak, why
        why = pf.gate.not_gained_because
    raise AssertionError("never converged")


def test_a_fix_turned_from_the_last_one_is_told_only_after_a_longer_steady_run() -> None:
    plain, plain_streak, _ = _first_fix(None)
    assert plain_streak < TURNED_GAIN_FRAMES  # told well before the longer run
    agreeing, _, _ = _first_fix(0.5 * BASE_DEG)
    assert agreeing == plain
    turned, streak, why = _first_fix(3.0 * BASE_DEG)
    assert turned > plain
    assert streak >= TURNED_GAIN_FRAMES
    assert why == ("turned from the last fix",)


def test_the_told_heading_is_the_told_frames_median_not_the_last_ones() -> None:
    """A span of told frames ends for a reason: its last frame may face 20 degrees off
    (a fix let go while turning, its latency unsaid), and a right fix after it must not
    wait on that frame."""
    told = ToldHeading(BIAS_PRIORS["vio"])
    for _ in range(6):
        told.told(0.0)
        told.moved(Odometry(0.1, 0.0, 0.0), 0.2)
    told.told(math.radians(20.0))
    told.moved(Odometry(0.0, 0.0, 0.0), MIN_SINCE_S)
    assert told.heading_rad is not None and abs(told.heading_rad) < 1e-12
    assert not told.disagrees(0.0)
    assert told.disagrees(math.radians(20.0 + BASE_DEG))


def test_a_run_held_back_for_its_heading_stays_held_back_across_a_checkpoint() -> None:
    """A session restored mid-run (a restart of the service) keeps the told heading and
    the run's flag: the fix still waits for the longer steady run."""
    config = FilterConfig(particles=3000, odometry_source="vio")
    pf = ParticleFilter(OFFICE, config, rng=np.random.default_rng(1))
    pf.told_heading.told(POSE.theta_rad + math.radians(3.0 * BASE_DEG))
    pf.told_heading.moved(Odometry(0.0, 0.0, 0.0), MIN_SINCE_S)
    seen = seen_from(OFFICE, POSE)
    for _ in range(120):
        assert not pf.step(Odometry(0.0, 0.0, 0.0), seen, frame_s=0.2).converged
        if pf.gate.not_gained_because == ("turned from the last fix",):
            break
    else:
        raise AssertionError("never held back for its heading")
    again = ParticleFilter(pf.map, pf.config, rng=np.random.default_rng(9), state=pf.checkpoint())
    assert again.told_heading.heading_rad == pf.told_heading.heading_rad
    for _ in range(120):
        if again.step(Odometry(0.0, 0.0, 0.0), seen, frame_s=0.2).converged:
            assert again.gate.streak >= TURNED_GAIN_FRAMES
            return
    raise AssertionError("never converged after the restore")
