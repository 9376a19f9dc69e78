"""Scaling table of one full filter step (issue 8): particles, map objects, detections.

Run: ``python benchmarks/step.py`` (prints a markdown table; one row per setting,
each the median over ``--steps`` timed steps on this machine's one core).
"""

from __future__ import annotations

import argparse

from app.bench import bench_step, cpu_model
from app.localization.filter import warm_up

ROWS = [
    (1_000, 30, 10),
    (10_000, 30, 10),
    (100_000, 30, 10),
    (10_000, 10, 10),
    (10_000, 100, 10),
    (10_000, 300, 10),
    (10_000, 30, 1),
    (10_000, 30, 50),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    warm_up()
    print(f"CPU: {cpu_model()}\n")
    print("| particles | objects | detections | median ms/step | p90 ms/step |")
    print("|---:|---:|---:|---:|---:|")
    for particles, objects, detections in ROWS:
        steps = max(10, args.steps // 10) if particles >= 100_000 else args.steps
        r = bench_step(particles, detections, objects, steps)
        print(
            f"| {particles:,} | {objects} | {detections} | {r['median_ms_per_step']:.2f} "
            f"| {r['p90_ms_per_step']:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
