"""The venue suite's walks with the phone's tracker losing track: a gap in the odometry.

A visual-inertial tracker stops now and then ("limited tracking": a blank wall, a quick
turn, a lift car's closed box) and the app sends frames without ``odometry`` while the
person goes on. ``tools/unmodelled.py`` tries that on one-level maps; this tool tries it
on the venue suite's three floors (``bearings experiments --suite venue``), where the
gaps also fall on stairs, escalators and lifts (``app.experiments.venue.run_condition``'s
``alter``):

* ``periodic``: frames without odometry for 3 s of every 20 s;
* ``rides``: frames without odometry for every ride (stairs, escalator, lift) and the
  second after it.

Prints per condition and effect: frames, confidently wrong (converged and more than 1 m
off, or on a wrong level), converged on a wrong level, and availability (converged among
the walking frames within 0.5 m of the person on the person's level).

    python tools/venue_gaps.py --conditions phone-vio,barometer,no-barometer
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from dataclasses import replace

from app.experiments import venue
from app.experiments.runner import map_jobs
from app.simulation.venue_walk import VenueFrame

#: Seconds between the starts of two gaps (``periodic``), and a gap's length.
PERIOD_S = 20.0
GAP_S = 3.0
#: How long after a ride the tracker is still lost (``rides``).
AFTER_RIDE_S = 1.0
EFFECTS = ("none", "periodic", "rides")


def lose_tracking(frames: list[VenueFrame], effect: str) -> list[VenueFrame]:
    """``frames`` with odometry taken out where ``effect`` loses track (the first frame
    has none anyway)."""
    out: list[VenueFrame] = []
    ride_end = -float("inf")
    for vf in frames:
        t = vf.frame.t
        if vf.riding:
            ride_end = t
        lost = (effect == "periodic" and t >= PERIOD_S and t % PERIOD_S < GAP_S) or (
            effect == "rides" and (vf.riding or t - ride_end <= AFTER_RIDE_S)
        )
        out.append(replace(vf, frame=replace(vf.frame, odometry=None)) if lost else vf)
    return out


def _job(args: tuple[str, str, int]) -> tuple[str, str, venue.VenueRun]:
    condition, effect, seed = args
    run = venue.run_condition(
        condition, seed, 10_000, alter=lambda frames: lose_tracking(frames, effect)
    )
    return condition, effect, run


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--conditions", default="phone-vio,barometer,no-barometer")
    parser.add_argument("--effects", default="periodic,rides")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    conditions = [c for c in args.conditions.split(",") if c]
    effects = [e for e in args.effects.split(",") if e]
    for c in conditions:
        if c not in venue.CONDITIONS:
            parser.error(f"unknown condition {c!r}; known: {', '.join(venue.CONDITIONS)}")
    for e in effects:
        if e not in EFFECTS:
            parser.error(f"unknown effect {e!r}; known: {', '.join(EFFECTS)}")
    started = time.perf_counter()
    jobs = [(c, e, s) for c in conditions for e in effects for s in range(args.seeds)]
    runs: dict[tuple[str, str], list[venue.VenueRun]] = {}
    for condition, effect, run in map_jobs(_job, jobs, args.workers):
        runs.setdefault((condition, effect), []).append(run)
    print(f"seeds 0-{args.seeds - 1}, {time.perf_counter() - started:.0f} s")
    print("| condition | effect | frames | confidently wrong | on a wrong level | availability |")
    print("|---|---|---|---|---|---|")
    for (condition, effect), walks in runs.items():
        frames = wrong = wrong_level = told = near = 0
        for r in walks:
            off_level = r.level != r.est_level
            frames += r.converged.size
            wrong += int((r.converged & ((r.err_m > 1.0) | off_level)).sum())
            wrong_level += int((r.converged & off_level).sum())
            right = ~r.riding & (r.err_m <= 0.5) & ~off_level
            told += int((right & r.converged).sum())
            near += int(right.sum())
        share = told / near if near else float("nan")
        print(f"| {condition} | {effect} | {frames} | {wrong} | {wrong_level} | {share:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
