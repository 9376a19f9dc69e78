"""How well the filter learns a phone's odometry scale and heading drift from a walk.

The suites count confidently-wrong frames: a rare event that moves from one walk to
another with any change to the filter, so ten seeds tell two versions of
:mod:`app.localization.odometry_bias` apart poorly. The scale the filter has learnt by
the second half of each walk, against the walk's own, is a steadier figure. For each
pedestrian-dead-reckoning scenario of the phone suite and condition of the venue suite
named here, every frame goes through the suite's own run (the service's session, the
venue's filter), and the filter's scale is compared, frame by frame over the walk's
second half, with the correction the walk asks for: the sum of the true forward steps
(each in the previous true pose's frame) over the sum of the odometry's, over the
frames walked (rides between floors left out).

    python tools/odometry_scale.py                   # seeds 0-5, venue seeds 0-9
    python tools/odometry_scale.py --seeds 3 --venue-seeds 3

Prints, per row, the mean absolute error of the learnt scale, its mean signed error
(negative: the filter takes the odometry's distances for longer than they are, and
lags behind the person), and the error of not learning at all (a scale of 1); then the
same for the heading drift in degrees a minute, the drift a walk asks for being the
odometry's turn beyond the true turn over the seconds walked. Compare versions on one
machine: a walk's course depends on the CPU's floating point.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from app.experiments import phone, venue
from app.experiments.runner import map_jobs
from app.localization.filter import ParticleFilter
from app.localization.types import Estimate, Odometry, Pose
from app.maps.geometry import wrap_rad
from app.service.session import Session
from app.service.types import FrameOutcome
from app.simulation.phone import PhoneFrame
from app.simulation.venue_walk import VenueFrame

PHONE_ROWS = (
    "office_suite/pdr-180",
    "office_suite/pdr-pinhole66",
    "office_suite/pdr-missed30-pinhole66",
    "door_corridor/pdr-pinhole66",
    "two_wing_office/pdr-pinhole66",
)
VENUE_ROWS = ("phone-pdr-180", "phone-pdr-66")


@dataclass
class OdometryTrace:
    """One walk: the true and odometry forward sums and turns, and the scale and heading
    drift learnt per frame."""

    true_forward_m: float = 0.0
    odometry_forward_m: float = 0.0
    #: The odometry's turn beyond the true turn (rad) over the seconds walked.
    excess_turn_rad: float = 0.0
    walked_s: float = 0.0
    learnt: list[float] = field(default_factory=list)
    learnt_drift: list[float] = field(default_factory=list)
    _last: Pose | None = None
    _last_t: float = 0.0

    def frame(
        self,
        t: float,
        truth: Pose,
        odometry: Odometry | None,
        walked: bool,
        learnt: tuple[float, float],
    ) -> None:
        """One frame: its time (s), its true pose, its odometry, whether it was walked (a
        step to sum), and the filter's scale and drift (rad/s) after it."""
        last, self._last = self._last, truth
        last_t, self._last_t = self._last_t, t
        self.learnt.append(learnt[0])
        self.learnt_drift.append(learnt[1])
        if last is None or odometry is None or not walked:
            return
        c, s = math.cos(last.theta_rad), math.sin(last.theta_rad)
        self.true_forward_m += c * (truth.x - last.x) + s * (truth.y - last.y)
        self.odometry_forward_m += odometry.forward_m
        self.excess_turn_rad += odometry.turn_rad - wrap_rad(truth.theta_rad - last.theta_rad)
        self.walked_s += t - last_t

    def errors(self) -> Errors:
        """The scale's :func:`_errors` (against a scale of 1)."""
        return _errors(self.learnt, self.true_forward_m / self.odometry_forward_m, 1.0)

    def drift_errors(self) -> Errors:
        """The heading drift's :func:`_errors`, in degrees a minute (against no drift)."""
        per_min = math.degrees(1.0) * 60.0
        wanted = self.excess_turn_rad / self.walked_s
        return _errors([v * per_min for v in self.learnt_drift], wanted * per_min, 0.0)


#: Mean |learnt - wanted| and mean (learnt - wanted) over a walk's second half, and
#: |uncorrected - wanted|.
Errors = tuple[float, float, float]


def _errors(learnt: list[float], wanted: float, uncorrected: float) -> Errors:
    half = np.array(learnt[len(learnt) // 2 :]) - wanted
    return float(np.mean(np.abs(half))), float(np.mean(half)), abs(uncorrected - wanted)


def _learnt(pf: ParticleFilter) -> tuple[float, float]:
    """The filter's odometry scale and heading drift (rad/s)."""
    assert pf.odometry_bias is not None, "the row's session does not estimate its odometry"
    return pf.odometry_bias.scale, pf.odometry_bias.drift_rad_s


def _job(args: tuple[str, str, int]) -> tuple[str, Errors, Errors]:
    kind, name, seed = args
    trace = OdometryTrace()
    if kind == "phone":

        def on_frame(session: Session, frame: PhoneFrame, _outcome: FrameOutcome) -> None:
            trace.frame(frame.t, frame.truth, frame.odometry, True, _learnt(session.filter))

        scenario = phone.scenarios(select=name)[0]
        phone.run_scenario(scenario, seed, 10_000, on_frame=on_frame)
    else:
        last_leg: list[int] = []  # the previous frame's leg (none before the first)

        def on_step(pf: ParticleFilter, vf: VenueFrame, _est: Estimate) -> None:
            walked = last_leg == [vf.leg] and not vf.riding
            last_leg[:] = [vf.leg]
            trace.frame(vf.frame.t, vf.file_pose, vf.frame.odometry, walked, _learnt(pf))

        venue.run_condition(name, seed, 10_000, on_step=on_step)
    return f"{kind}: {name}", trace.errors(), trace.drift_errors()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=6, help="phone suite seeds (from 0)")
    parser.add_argument("--venue-seeds", type=int, default=10, help="venue seeds (from 0)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    jobs = [("phone", row, s) for row in PHONE_ROWS for s in range(args.seeds)]
    jobs += [("venue", row, s) for row in VENUE_ROWS for s in range(args.venue_seeds)]
    results = map_jobs(_job, jobs, args.workers)
    for title, unit, pick in (
        ("scale", "", 1),
        ("heading drift", " (deg/min)", 2),
    ):
        print(
            f"| row | walks | learnt {title}, mean abs error{unit} | mean signed error "
            f"| no correction's error |"
        )
        print("|---|---|---|---|---|")
        every = []
        for row in dict.fromkeys(r[0] for r in results):
            mine = np.array([r[pick] for r in results if r[0] == row])
            every.append(mine)
            abs_err, signed, unlearnt = mine.mean(axis=0)
            print(f"| {row} | {len(mine)} | {abs_err:.4f} | {signed:+.4f} | {unlearnt:.4f} |")
        walks = sum(len(m) for m in every)
        abs_err, signed, unlearnt = np.concatenate(every).mean(axis=0)
        print(f"| all | {walks} | {abs_err:.4f} | {signed:+.4f} | {unlearnt:.4f} |")
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
