"""Print what a person would hear on the paper's walk: `python -m app.experiments.walkthrough`.

Runs the simulator, the filter and the narrator together (global start, 360 degree
camera) and prints every non-empty feedback text with its time, plus a "Where am I?"
at the end.
"""

from __future__ import annotations

import argparse

import numpy as np

from app.feedback import FeedbackOptions, Narrator
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--fov", type=float, default=360.0)
    parser.add_argument("--style", default="clock", choices=["clock", "left_right", "degrees"])
    parser.add_argument("--until", type=float, default=30.0, help="seconds of the walk to narrate")
    args = parser.parse_args()
    office = load_map(bundled_maps_dir() / "paper_office.json")
    frames = simulate(office, paper_config("nominal", args.fov), np.random.default_rng(args.seed))
    pf = ParticleFilter(
        office, FilterConfig(fov_deg=args.fov), rng=np.random.default_rng(args.seed)
    )
    narrator = Narrator(office, FeedbackOptions(style=args.style))
    for f in frames:
        if f.t > args.until:
            break
        est = pf.step(f.odometry, f.detections)
        fb = narrator.update(est, f.detections, timestamp_s=f.t, fov_deg=args.fov)
        if fb.text:
            print(f"{f.t:5.1f} s  {fb.text}")
    fb = narrator.update(est, f.detections, timestamp_s=f.t, describe=True, fov_deg=args.fov)
    print(f"{f.t:5.1f} s  [Where am I?] {fb.text}")


if __name__ == "__main__":
    main()
