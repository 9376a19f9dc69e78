"""Why the service says "not sure yet" where it is right: the gate's reasons, counted.

Availability (converged among the frames within half a metre of the person) is what a
person hears as "found"; the rest of those frames are a right estimate the service did
not tell. For a phone scenario (``map/condition`` of ``bearings experiments --suite
phone``) or a venue condition (``--suite venue``), every walking frame within
``RIGHT_M`` of the truth and not converged is counted under each reason the convergence
gate gave for it (``ConvergenceGate.not_gained_because``: the gain's tests it failed,
"let go: ..." on the frame a held fix was released, or the filter's reason for taking a
gain back, e.g. "wide radius"); a frame fails one test or several, so the shares add up
to more than 100 %. Frames the gate held but the filter did not tell (between floors)
count as "between floors".

    python tools/why_not_located.py phone door_corridor/pdr-missed30-pinhole66
    python tools/why_not_located.py venue phone-vio-66 --seeds 10
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from collections.abc import Sequence

from app.experiments import phone, venue
from app.experiments.integrity import RIGHT_M
from app.experiments.runner import map_jobs
from app.localization.filter import ParticleFilter
from app.localization.types import Estimate, Pose


def _count(pf: ParticleFilter, truth: Pose, est: Estimate, tally: Counter[str]) -> None:
    """One frame: counted when the estimate is right and not told."""
    tally["frames"] += 1
    if math.hypot(est.x - truth.x, est.y - truth.y) > RIGHT_M:
        return
    tally["near"] += 1
    if est.converged:
        tally["told"] += 1
        return
    gate = pf.gate
    for reason in ("between floors",) if gate.held else gate.not_gained_because:
        tally[reason] += 1


def _job(args: tuple[str, str, int]) -> Counter[str]:
    kind, row, seed = args
    tally: Counter[str] = Counter()
    if kind == "phone":
        map_name, condition = row.split("/")
        phone.run_scenario(
            phone.Scenario(map_name, condition),
            seed,
            10_000,
            on_frame=lambda session, f, out: _count(session.filter, f.truth, out.estimate, tally),
        )
    else:

        def step(pf: ParticleFilter, vf: venue.VenueFrame, est: Estimate) -> None:
            if not vf.riding:
                _count(pf, vf.frame.truth, est, tally)

        venue.run_condition(row, seed, 10_000, on_step=step)
    return tally


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=("phone", "venue"))
    parser.add_argument("row", help="map/condition (phone) or condition (venue)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds, from --first-seed")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    if args.kind == "phone":
        map_name, _, condition = args.row.partition("/")
        if condition not in phone.CONDITIONS:
            parser.error(f"no phone condition {condition!r}: {', '.join(phone.CONDITIONS)}")
        if not map_name:
            parser.error("a phone row is map/condition, e.g. door_corridor/vio-pinhole66")
    elif args.row not in venue.CONDITIONS:
        parser.error(f"no venue condition {args.row!r}: {', '.join(venue.CONDITIONS)}")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    total: Counter[str] = Counter()
    for tally in map_jobs(_job, [(args.kind, args.row, s) for s in seeds], args.workers):
        total.update(tally)
    near, told = total.pop("near", 0), total.pop("told", 0)
    frames = total.pop("frames", 0)
    untold = near - told
    print(
        f"{args.kind} {args.row}, seeds {seeds.start}-{seeds.stop - 1}: {frames} walking "
        f"frames, {near} within {RIGHT_M:g} m of the person, {told} of them told "
        f"(availability {told / max(near, 1):.3f}), {untold} not"
    )
    print("| reason | frames | share of those not told |")
    print("|---|---|---|")
    for reason, n in total.most_common():
        print(f"| {reason} | {n} | {n / max(untold, 1):.1%} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
