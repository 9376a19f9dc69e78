"""The venue suite's walks with the barometer's reference jumping, and no ride.

A phone's barometer reads altitude relative to a reference of its own, and that reference
can jump: a door opening on a pressurized zone, a glitch of the sensor. This adds
``--jump`` metres to every reading from ``--at`` seconds into each walk of a venue-suite
condition (``app/experiments/venue.py``) and counts, over ``--seeds`` walks, the frames
``converged`` on a level other than the person's (confidently on a wrong floor), those on
the right level but more than 1 m off, and all converged frames (what the jump cost in
availability; compare with ``--jump 0``).

    PYTHONPATH=. python tools/barometer_jump.py --condition phone-vio-180 --jump 4.5 --at 200
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

from app.experiments import venue
from app.localization.filter import ParticleFilter


def run_walk(condition: str, seed: int, jump_m: float, at_s: float) -> dict[str, int]:
    """One walk of ``condition``; the counts described in the module docstring."""
    cond = venue.CONDITIONS[condition]
    if not cond.barometer:
        raise SystemExit(f"condition {condition!r} has no barometer")
    semantic_map, frames, _ = venue._walk(seed, cond)
    pf = ParticleFilter(
        semantic_map, venue.filter_config(cond, 10_000), rng=np.random.default_rng(seed + 1)
    )
    counts = {"wrong_floor": 0, "wrong_place": 0, "converged": 0, "frames": len(frames)}
    for i, vf in enumerate(frames):
        if vf.altitude is not None and vf.frame.t >= at_s:
            reading = dataclasses.replace(vf.altitude, relative_m=vf.altitude.relative_m + jump_m)
            vf = dataclasses.replace(vf, altitude=reading)
        est = venue.step(pf, vf, frames[i - 1].frame.t if i else None, barometer=True)
        if not est.converged:
            continue
        counts["converged"] += 1
        level = int(semantic_map.layout.level_of_plane_x(np.array(est.x)))
        truth = vf.frame.truth
        if level != vf.level:
            counts["wrong_floor"] += 1
        elif float(np.hypot(est.x - truth.x, est.y - truth.y)) > 1.0:
            counts["wrong_place"] += 1
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--condition", default="phone-vio-180", choices=sorted(venue.CONDITIONS))
    parser.add_argument("--jump", type=float, default=4.5, help="metres added to the readings")
    parser.add_argument("--at", type=float, default=100.0, help="seconds into each walk")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    args = parser.parse_args()
    total = {"wrong_floor": 0, "wrong_place": 0, "converged": 0, "frames": 0}
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        counts = run_walk(args.condition, seed, args.jump, args.at)
        print(json.dumps({"seed": seed, **counts}), flush=True)
        for key, value in counts.items():
            total[key] += value
    print(json.dumps({"condition": args.condition, "jump_m": args.jump, "at_s": args.at, **total}))


if __name__ == "__main__":
    main()
