"""Walk the bundled IMDF venue (riverside_station) with the venue filter and a barometer.

The walk (file frame, metres): from the entrance hall to the up escalator, up to the
First Floor, into the Bakery and back, the lift up to the Second Floor, the stairs down
to the First Floor, the down escalator to the Ground Floor, along the concourse. The
frames come from the venue simulator (app/simulation/venue_walk.py: 10 % of objects
missed, 0.2 false detections a frame, a drifting barometer); the filter runs as the
service runs it, from a global start.

    PYTHONPATH=. python tools/imdf_venue_walk.py --seeds 10 --particles 3000

Prints per seed the converged frames, the share of them on the true level, the
confidently-wrong frames (converged and more than 1 m off or on another level) and,
per ride, the time from leaving the connector to the first converged frame on the new
level within 1 m (0 when that came before the person left).
"""

from __future__ import annotations

import argparse

import numpy as np

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.simulation.simulator import SimulationConfig
from app.simulation.venue_walk import Barometer, Leg, Ride, Walk, simulate_venue

WRONG_M = 1.0
LEGS: list[Leg] = [
    Walk(((-14, -8), (-10, 0), (-5.5, 0), (-5.5, 5))),
    Ride("escalator", "L1", ((-5.5, 11.0),), speed_mps=0.5),
    Walk(
        (
            (-5.5, 11),
            (-5.5, 1),
            (10, 1),
            (10.5, 3.5),
            (10.5, 6),
            (10.5, 1),
            (1, 1),
            (0.5, 3),
            (0.5, 5.5),
        )
    ),
    Ride("elevator", "L2", climb_mps=1.0, wait_s=3.0),
    Walk(((0.5, 5.5), (0.5, 0), (-10, 0), (-9.5, 5))),
    Ride("stairs", "L1", ((-9.5, 11.0),), speed_mps=0.35),
    Walk(((-9.5, 11), (-9.5, 0), (-2.5, 0), (-2.5, 5))),
    Ride("escalator", "L0", ((-2.5, 11.0),), speed_mps=0.5),
    Walk(((-2.5, 11), (-2.5, 1.5), (15, 1.5))),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--particles", type=int, default=3000)
    args = parser.parse_args()
    m = load_map(bundled_maps_dir() / "riverside_station.json")
    layout = m.layout
    cfg = SimulationConfig(path=((0.0, 0.0),), miss_prob=0.1, false_rate=0.2)
    for seed in range(args.seeds):
        frames = simulate_venue(m, "L0", LEGS, cfg, np.random.default_rng(seed), Barometer())
        pf = ParticleFilter(
            m, FilterConfig(particles=args.particles), rng=np.random.default_rng(seed + 1)
        )
        n = len(frames)
        conv, err, est_level = np.zeros(n, bool), np.zeros(n), np.zeros(n, np.int64)
        for i, vf in enumerate(frames):
            f = vf.frame
            est = pf.step(f.odometry, f.detections, None, vf.altitude)
            est_level[i] = int(layout.level_of_plane_x(np.array(est.x)))
            err[i] = float(np.hypot(est.x - f.truth.x, est.y - f.truth.y))
            conv[i] = est.converged
        level = np.array([vf.level for vf in frames])
        leg = np.array([vf.leg for vf in frames])
        right = conv & (est_level == level) & (err <= WRONG_M)
        wrong = conv & ((est_level != level) | (err > WRONG_M))
        rides = []
        for k, spec in enumerate(LEGS):
            if isinstance(spec, Ride):
                end = int(np.flatnonzero(leg == k)[-1])
                to = layout.level_index(spec.to_level)
                ok = np.flatnonzero(right[end:] & (level[end:] == to))
                t = frames[end + ok[0]].frame.t - frames[end].frame.t if ok.size else np.inf
                rides.append(f"{spec.kind} to {spec.to_level} {t:.1f} s")
        share = float(np.mean(est_level[conv] == level[conv])) if conv.any() else float("nan")
        print(
            f"seed {seed}: {n} frames, {int(conv.sum())} converged, {share:.4f} of them on the "
            f"true level, {int(wrong.sum())} confidently wrong; rides: {', '.join(rides)}"
        )


if __name__ == "__main__":
    main()
