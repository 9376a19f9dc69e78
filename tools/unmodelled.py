"""The filter against what a phone does that the simulator was not built with.

The phone suite (``bearings experiments --suite phone``) simulates the effects issue 27
lists, and the filter was tuned on them. This tool asks what happens with effects that
were not designed for, each applied to the phone suite's own simulated frames of a
scenario (``app.experiments.phone.run_scenario``'s ``alter``):

* ``tracking-jump-0.8m`` / ``-1.5m``: every 20 s one frame's odometry is that much longer
  forward than the step (a visual-inertial tracker relocalizing: ARKit and ARCore move
  their world frame when they recognise a place again; a step counter counting a
  stride twice);
* ``heading-jump-20deg``: every 20 s one frame's turn is 20 degrees more than the turn
  (a compass-fused heading pulled by steel in a wall);
* ``noisier-detector``: every bearing off by a further 4.5 degrees std (the session says
  2; a cheaper detector, a blurred image);
* ``camera-yaw-6deg``: every bearing 6 degrees off (a phone in a chest mount turned a
  little);
* ``occlusion-bursts``: for 5 s of every 20 s, 80 % of the detections lost (a crowd);
* ``paused-8s``: no frame for 8 s from t = 25 s, then one without odometry (the app
  sent to the background and back);
* ``tracking-lost-3s``: frames go on, but for 3 s of every 20 s without odometry (a
  visual-inertial tracker's "limited tracking": a blank wall, a fast turn);
  ``tracking-lost-4.5s`` the same for 4.5 s (near the longest gap a fix is kept
  through, ``app.localization.gap.GAP_HOLD_S``);
* ``pace-change``: the odometry's lengths 12 % longer in the walk's second half (a step
  length learnt while walking slowly, then walking briskly);
* ``no-timestamps``: the app sends its detections' age but no timestamps (the field is
  optional);
* ``timestamps-in-ms``: the app's clock counts milliseconds (JavaScript's Date.now());
* ``bearings-clockwise`` / ``turns-clockwise``: the app sends its bearings, or its
  odometry's turns and sideways steps, clockwise positive (an image's x axis, a
  compass's sense); the contract has both counter-clockwise.

Prints per scenario and effect: frames, confidently wrong (converged and more than 1 m
off), beyond protection (converged and farther off than ``protection_m``), and
availability (converged among the frames within 0.5 m), as the phone suite counts them.

    python tools/unmodelled.py                                  # default rows, seeds 0-9
    python tools/unmodelled.py --out docs/results/unmodelled.md  # also as a results file
    python tools/unmodelled.py --rows office_suite/vio-360 --effects tracking-jump-1.5m
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from app.experiments import phone
from app.experiments.report import tool_results_head
from app.experiments.runner import map_jobs
from app.localization.types import Detection, Odometry
from app.simulation.phone import PhoneFrame

Frames = list[PhoneFrame]
#: An effect: the frames and a generator of its own, to the frames as sent.
Effect = Callable[[Frames, np.random.Generator], Frames]

#: The effects that come in bursts recur this often (s).
PERIOD_S = 20.0


def _every_period(frames: Frames, change: Callable[[Odometry], Odometry]) -> Frames:
    """``change`` applied to the odometry of the first frame of each period but the
    first (a frame without odometry is left as it is)."""
    out = []
    for i, f in enumerate(frames):
        odo = f.odometry
        starts = i > 0 and int(f.t // PERIOD_S) != int(frames[i - 1].t // PERIOD_S)
        if starts and odo is not None:
            f = replace(f, odometry=change(odo))
        out.append(f)
    return out


def _forward_jump(metres: float) -> Effect:
    def effect(frames: Frames, _rng: np.random.Generator) -> Frames:
        return _every_period(frames, lambda o: Odometry(o.forward_m + metres, o.left_m, o.turn_rad))

    return effect


def _heading_jump(frames: Frames, _rng: np.random.Generator) -> Frames:
    turn = math.radians(20.0)
    return _every_period(frames, lambda o: Odometry(o.forward_m, o.left_m, o.turn_rad + turn))


def _bearings(f: PhoneFrame, offsets: Sequence[float]) -> PhoneFrame:
    dets = [
        Detection(d.cls, d.bearing_rad + float(off), d.score)
        for d, off in zip(f.detections, offsets, strict=True)
    ]
    return replace(f, detections=dets)


def _noisier(frames: Frames, rng: np.random.Generator) -> Frames:
    std = math.radians(4.5)
    return [_bearings(f, rng.normal(0.0, std, len(f.detections))) for f in frames]


def _yaw(frames: Frames, _rng: np.random.Generator) -> Frames:
    off = math.radians(6.0)
    return [_bearings(f, [off] * len(f.detections)) for f in frames]


def _occlusion(frames: Frames, rng: np.random.Generator) -> Frames:
    out = []
    for f in frames:
        if f.t % PERIOD_S < 5.0:
            keep = rng.random(len(f.detections)) >= 0.8
            f = replace(
                f,
                detections=[d for d, k in zip(f.detections, keep, strict=True) if k],
                widths_deg=(),
                sources=(),
            )
        out.append(f)
    return out


def _paused(frames: Frames, _rng: np.random.Generator) -> Frames:
    start, end = 25.0, 33.0
    out: Frames = []
    gap = False
    for f in frames:
        if start <= f.t < end:
            gap = True
            continue
        if gap:
            f = replace(f, odometry=None)
            gap = False
        out.append(f)
    return out


def _tracking_lost(seconds: float) -> Effect:
    def effect(frames: Frames, _rng: np.random.Generator) -> Frames:
        return [
            replace(f, odometry=None) if f.t >= PERIOD_S and f.t % PERIOD_S < seconds else f
            for f in frames
        ]

    return effect


def _pace(frames: Frames, _rng: np.random.Generator) -> Frames:
    half = frames[-1].t / 2.0
    return [
        replace(
            f,
            odometry=Odometry(
                f.odometry.forward_m * 1.12, f.odometry.left_m * 1.12, f.odometry.turn_rad
            ),
        )
        if f.odometry is not None and f.t > half
        else f
        for f in frames
    ]


def _nothing(frames: Frames, _rng: np.random.Generator) -> Frames:
    return frames


def _milliseconds(frames: Frames, _rng: np.random.Generator) -> Frames:
    return [replace(f, t=f.t * 1000.0) for f in frames]


def _mirrored(frames: Frames, _rng: np.random.Generator) -> Frames:
    return [
        replace(f, detections=[Detection(d.cls, -d.bearing_rad, d.score) for d in f.detections])
        for f in frames
    ]


def _turns_mirrored(frames: Frames, _rng: np.random.Generator) -> Frames:
    return [
        f
        if f.odometry is None
        else replace(
            f, odometry=Odometry(f.odometry.forward_m, -f.odometry.left_m, -f.odometry.turn_rad)
        )
        for f in frames
    ]


EFFECTS: dict[str, Effect] = {
    "none": _nothing,
    "tracking-jump-0.8m": _forward_jump(0.8),
    "tracking-jump-1.5m": _forward_jump(1.5),
    "heading-jump-20deg": _heading_jump,
    "noisier-detector": _noisier,
    "camera-yaw-6deg": _yaw,
    "occlusion-bursts": _occlusion,
    "paused-8s": _paused,
    "tracking-lost-3s": _tracking_lost(3.0),
    "tracking-lost-4.5s": _tracking_lost(4.5),
    "pace-change": _pace,
    "no-timestamps": _nothing,
    "timestamps-in-ms": _milliseconds,
    "bearings-clockwise": _mirrored,
    "turns-clockwise": _turns_mirrored,
}
#: The effects whose frames go without timestamps.
UNTIMED = frozenset({"no-timestamps"})
ROWS = (
    "office_suite/vio-360",
    "office_suite/vio-180",
    "office_suite/pdr-pinhole66",
    "office_suite/vio-stale-360",
)


def _job(args: tuple[str, str, int]) -> tuple[str, str, phone.PhoneRun]:
    """One walk of ``row`` with effect ``name``, seed ``seed``."""
    row, name, seed = args
    scenario = phone.Scenario(*row.split("/"))
    rng = np.random.default_rng([seed, 1027])
    run = phone.run_scenario(
        scenario,
        seed,
        10_000,
        alter=lambda frames: EFFECTS[name](frames, rng),
        timestamps=name not in UNTIMED,
    )
    return row, name, run


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    phone.add_tool_arguments(parser, ROWS)
    parser.add_argument("--effects", default=",".join(EFFECTS), help="comma-separated")
    args = parser.parse_args(argv)
    try:
        rows = [f"{s.map_name}/{s.condition}" for s in phone.parse_rows(args.rows)]
    except ValueError as exc:
        parser.error(str(exc))
    effects = [e for e in args.effects.split(",") if e]
    for name in effects:
        if name not in EFFECTS:
            parser.error(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    started = time.perf_counter()
    jobs = [(r, e, s) for r in rows for e in effects for s in seeds]
    runs: dict[tuple[str, str], list[phone.PhoneRun]] = {}
    for row, name, run in map_jobs(_job, jobs, args.workers):
        runs.setdefault((row, name), []).append(run)
    lines = [
        "| scenario | effect | frames | confidently wrong | beyond protection | availability |",
        "|---|---|---|---|---|---|",
    ]
    for (row, name), walks in runs.items():
        m = phone.metrics(walks)  # the phone suite's own figures
        n = int(m["frames"])
        beyond = round(float(m["beyond_protection_share"]) * n)
        lines.append(
            f"| {row} | {name} | {n} | {m['wrong_frames']} | {beyond} | {m['availability']:.3f} |"
        )
    print(f"seeds {seeds.start}-{seeds.stop - 1}")
    print("\n".join(lines))
    if args.out:
        doc = (__doc__ or "").split("\n\n")
        head = tool_results_head(
            "Effects the simulator was not built with",
            f"python tools/unmodelled.py {' '.join(argv or sys.argv[1:])}",
            time.perf_counter() - started,
            f"seeds {seeds.start}-{seeds.stop - 1} of each phone-suite scenario, 10000 particles.",
            "\n\n".join(doc[1:3]),
        )
        with open(args.out, "w", encoding="utf-8") as out:
            out.write("\n".join([*head, *lines]) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
