"""The filter and the evidence tracker work through the models they are given."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.models import BearingSensorModel, OdometryMotionModel
from app.localization.types import InitialPose, Odometry
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate

OFFICE = load_map(bundled_maps_dir() / "paper_office.json")


class Counting:
    """Hands every call on to ``inner`` and counts it by method name."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.calls: Counter[str] = Counter()

    def __getattr__(self, name: str) -> Any:
        value = getattr(self.inner, name)
        if not callable(value):
            return value

        def counted(*args: Any, **kwargs: Any) -> Any:
            self.calls[name] += 1
            return value(*args, **kwargs)

        return counted


def _walk(pf: ParticleFilter, frames: list) -> list[tuple[float, ...]]:
    out = []
    for f in frames:
        est = pf.step(f.odometry, f.detections)
        out.append((est.x, est.y, est.theta_rad, float(est.converged)))
    return out


def test_given_models_are_the_only_ones_used_and_change_nothing() -> None:
    cfg = FilterConfig(particles=2_000)
    frames = simulate(OFFICE, paper_config("nominal", 360.0), np.random.default_rng(3))[:60]
    plain = _walk(ParticleFilter(OFFICE, cfg, rng=np.random.default_rng(5)), frames)
    sensor = Counting(BearingSensorModel(OFFICE, cfg, OFFICE.visibility))
    motion = Counting(OdometryMotionModel(OFFICE, cfg))
    pf = ParticleFilter(
        OFFICE, cfg, rng=np.random.default_rng(5), sensor_model=sensor, motion_model=motion
    )
    assert pf.evidence is not None and pf.evidence.sensor is sensor
    assert _walk(pf, frames) == plain
    # Every frame weighed and moved through them; the tracker searched through them too.
    assert sensor.calls["observe"] == len(frames)
    assert motion.calls["sample"] >= len(frames)
    assert motion.calls["weigh_moves"] >= len(frames)
    assert sensor.calls["log_likelihood"] > len(frames)
    assert sensor.calls["pattern_search"] > 0 and sensor.calls["jitter_search"] > 0


class StandingStill(OdometryMotionModel):
    """A motion model for which nobody ever moves (whatever the odometry says)."""

    def sample(self, x, y, theta, odometry, rng, out=None):  # type: ignore[no-untyped-def]
        return super().sample(x, y, theta, Odometry(0.0, 0.0, 0.0), rng, out)


def test_another_motion_model_moves_the_particles_its_way() -> None:
    cfg = FilterConfig(particles=500, evidence=False, recovery=False)
    start = InitialPose(3.0, 3.0, 0.0, 0.05, 0.02)
    walked = ParticleFilter(OFFICE, cfg, rng=np.random.default_rng(1), initial_pose=start)
    still = ParticleFilter(
        OFFICE,
        cfg,
        rng=np.random.default_rng(1),
        initial_pose=start,
        motion_model=StandingStill(OFFICE, cfg),
    )
    for _ in range(5):
        walked.predict(Odometry(0.2, 0.0, 0.0))
        still.predict(Odometry(0.2, 0.0, 0.0))
    assert abs(float(np.average(walked.x, weights=walked.weights)) - 4.0) < 0.1
    assert abs(float(np.average(still.x, weights=still.weights)) - 3.0) < 0.1
