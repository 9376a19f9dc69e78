"""A known start given wrong: how often the service then tells a wrong place.

An app passes ``initial_pose`` from what it believes: the entrance the person said, the
door of the room they were in, the phone's heading. When that is wrong, the start is a
prior that the camera contradicts. For the phone suite's walks (the service's own
session, every effect of a real phone) this gives each session a start off by a
heading of 180 deg (``turned``), or placed ``2m`` or ``5m`` from where the walk begins
(in free space, in a random direction), or ``right``, with the tight spread an app
that trusts itself gives (5 cm, 1 deg) and with the contract's default (0.3 m,
10 deg), and counts per row the confidently-wrong frames (converged and more than 1 m
off), those beyond ``protection_m`` and availability (converged among the frames within
0.5 m), pooled over the seeds as the phone suite pools them (``phone.metrics``), and
when each seed's first right fix came.

    python tools/wrong_start.py                                  # every map, 5 seeds
    python tools/wrong_start.py --maps office_suite --conditions vio-360 --seeds 3

Compare versions on one machine (a walk's course depends on the CPU's floating point).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import defaultdict
from collections.abc import Callable, Sequence

import numpy as np

from app.experiments import phone
from app.experiments.integrity import RIGHT_M
from app.experiments.runner import map_jobs
from app.localization.types import InitialPose, Pose
from app.maps.model import SemanticMap

KINDS = ("turned", "2m", "5m", "right")
#: (std_xy_m, std_theta_deg) of the starts given: an app sure of itself, the default.
SPREADS = {"tight": (0.05, 1.0), "default": (0.3, 10.0)}


def given_start(
    kind: str, spread: str, seed: int
) -> Callable[[SemanticMap, Pose], InitialPose | None]:
    """The session's ``initial_pose`` of kind ``kind`` for a walk whose first true pose
    is ``truth`` (``phone.run_scenario``'s ``start``)."""
    std_xy, std_deg = SPREADS[spread]

    def start(semantic_map: SemanticMap, truth: Pose) -> InitialPose | None:
        x, y, theta = truth.x, truth.y, truth.theta_rad
        if kind == "turned":
            theta += math.pi
        elif kind != "right":
            off = float(kind.removesuffix("m"))
            rng = np.random.default_rng(seed + 1000)
            for _ in range(1000):
                a = rng.uniform(-math.pi, math.pi)
                cx, cy = x + off * math.cos(a), y + off * math.sin(a)
                if semantic_map.free_space.is_free(np.array([cx]), np.array([cy]))[0]:
                    x, y = cx, cy
                    break
            else:
                raise ValueError(f"no free place {kind} from the walk's start")
        return InitialPose(x, y, theta, std_xy, math.radians(std_deg))

    return start


def _job(args: tuple[str, str, str, str, int]) -> tuple[tuple[str, ...], phone.PhoneRun]:
    map_name, condition, kind, spread, seed = args
    run = phone.run_scenario(
        phone.Scenario(map_name, condition), seed, 10_000, start=given_start(kind, spread, seed)
    )
    return (map_name, condition, kind, spread), run


def first_right_s(run: phone.PhoneRun) -> float:
    """Seconds into the walk of its first converged frame within RIGHT_M (inf: never)."""
    right = np.flatnonzero(run.converged & (run.err_m <= RIGHT_M))
    return float(run.t[right[0]]) if right.size else math.inf


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", default=",".join(phone.MAPS))
    parser.add_argument("--conditions", default="vio-360,vio-pinhole66,pdr-pinhole66")
    parser.add_argument("--kinds", default=",".join(KINDS))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    maps, conditions = args.maps.split(","), args.conditions.split(",")
    kinds = args.kinds.split(",")
    for name in maps:
        if name not in phone.MAPS:
            parser.error(f"no map {name!r}: {', '.join(phone.MAPS)}")
    for c in conditions:
        if c not in phone.CONDITIONS:
            parser.error(f"no phone condition {c!r}: {', '.join(phone.CONDITIONS)}")
    for k in kinds:
        if k not in KINDS:
            parser.error(f"no kind {k!r}: {', '.join(KINDS)}")
    jobs = [
        (m, c, k, s, seed)
        for m in maps
        for c in conditions
        for k in kinds
        for s in SPREADS
        for seed in range(args.seeds)
    ]
    rows: dict[tuple[str, ...], list[phone.PhoneRun]] = defaultdict(list)
    for key, run in map_jobs(_job, jobs, args.workers):
        rows[key].append(run)
    print("| map | condition | start | spread | frames | confidently wrong | beyond protection "
          "| availability | first right fix (s, per seed) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    totals: dict[str, float] = defaultdict(float)
    for key, runs in rows.items():
        m = phone.metrics(runs)  # the phone suite's own figures, pooled over the seeds
        frames, wrong = int(m["frames"]), int(m["wrong_frames"])
        beyond = round(float(m["beyond_protection_share"]) * frames)
        firsts = ", ".join(
            "never" if math.isinf(f) else f"{f:.1f}" for f in map(first_right_s, runs)
        )
        print(f"| {' | '.join(key)} | {frames} | {wrong} | {beyond} | "
              f"{float(m['availability']):.2f} | {firsts} |")  # fmt: skip
        group = "right" if key[2] == "right" else "wrong"
        totals[f"{group} wrong"] += wrong
        totals[f"{group} beyond"] += beyond
    print(
        f"\nstarts given wrong: {totals['wrong wrong']:.0f} confidently-wrong frames, "
        f"{totals['wrong beyond']:.0f} beyond protection; given right: "
        f"{totals['right wrong']:.0f} and {totals['right beyond']:.0f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
