"""Where the time of one filter step goes, stage by stage (standard workload of issue 8).

Run: ``python benchmarks/breakdown.py`` (prints a markdown table). Each stage is timed
on its own, on the state a real step leaves, median over ``--repeats`` calls; the
stages are the ones :meth:`ParticleFilter.step` runs, in its order.
"""

from __future__ import annotations

import argparse
import timeit

import numpy as np

from app.bench import CLASSES, cpu_model, generated_map
from app.localization.config import FilterConfig
from app.localization.estimate import estimate_pose
from app.localization.filter import ParticleFilter, warm_up
from app.localization.resampling import effective_sample_size, systematic_resample
from app.localization.sensor import normalized_residuals, prepare_observation
from app.localization.types import Detection, Odometry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--particles", type=int, default=10_000)
    parser.add_argument("--detections", type=int, default=10)
    parser.add_argument("--objects", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args()
    warm_up()
    semantic_map = generated_map(args.objects)
    config = FilterConfig(particles=args.particles, adaptive=False)
    pf = ParticleFilter(semantic_map, config, rng=np.random.default_rng(0))
    det_rng = np.random.default_rng(1)
    frame = [
        Detection(CLASSES[k % 3], float(det_rng.uniform(-np.pi, np.pi)), 0.9)
        for k in range(args.detections)
    ]
    odo = Odometry(0.1, 0.0, np.radians(2.0))
    for _ in range(5):
        pf.step(odo, frame)
    obs = prepare_observation(frame, semantic_map, config)
    pf.last_observation = obs
    w = pf.weights
    raw = estimate_pose(pf.x, pf.y, pf.theta, w, rng=pf.rng)
    state = (pf.x.copy(), pf.y.copy(), pf.theta.copy(), pf.log_w.copy())
    # predict and the full step move the particles: each stage starts from this state.

    def restore() -> None:
        pf.x, pf.y, pf.theta, pf.log_w = (a.copy() for a in state)

    def resample() -> None:  # what _resample does when due, without injection
        idx = systematic_resample(w, pf.n, pf.rng)
        _ = pf.x[idx], pf.y[idx], pf.theta[idx], np.zeros(pf.n)

    grid = semantic_map.visibility
    row = grid.visible(raw.x, raw.y)[0]

    stages = [
        ("predict: noisy motion + free-space/wall test", lambda: pf.predict(odo)),
        ("group detections by class", lambda: prepare_observation(frame, semantic_map, config)),
        ("sensor kernel, eqs. (2)-(3) + visibility", lambda: pf.observation_log_likelihood(obs)),
        ("normalize weights + ESS", lambda: effective_sample_size(pf.weights)),
        ("estimate: clustering", lambda: estimate_pose(pf.x, pf.y, pf.theta, w, rng=pf.rng)),
        (
            "residual check of the estimate (when converged)",
            lambda: normalized_residuals(
                raw.x, raw.y, raw.theta_rad, obs, semantic_map, config, row
            ),
        ),
        ("resample when due (systematic)", resample),
    ]
    print(f"CPU: {cpu_model()}; {args.particles:,} particles, {args.detections} detections, "
          f"{args.objects} objects\n")  # fmt: skip
    print("| stage | median µs |")
    print("|---|---:|")
    for name, fn in stages:
        restore()
        fn()
        t = timeit.repeat(fn, number=1, repeat=args.repeats)
        print(f"| {name} | {np.median(t) * 1e6:.0f} |", flush=True)
    full = timeit.repeat(lambda: pf.step(odo, frame), number=1, repeat=args.repeats)
    print(f"| **full step** | **{np.median(full) * 1e6:.0f}** |")


if __name__ == "__main__":
    main()
