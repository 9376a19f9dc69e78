"""The filter and the evidence tracker work through the models they are given."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.models import BearingSensorModel, OdometryMotionModel
from app.localization.sensor import observation_columns
from app.localization.types import Detection, InitialPose, Odometry
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

    def sample(self, x, y, theta, odometry, rng, out=None, steps=1):  # type: ignore[no-untyped-def]
        return super().sample(x, y, theta, Odometry(0.0, 0.0, 0.0), rng, out, steps)


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


def test_an_excluded_object_explains_no_detection() -> None:
    """An object the filter took for moved or gone (a stale map) leaves the sensor model:
    a detection pointing at it is weighed as one pointing at nothing, in new frames and
    in frames kept as columns; the other objects of its class still explain theirs."""
    cfg = FilterConfig(particles=100)
    model = BearingSensorModel(OFFICE, cfg, OFFICE.visibility)
    x, y = np.array([6.0]), np.array([3.5])
    theta = np.zeros(1)
    windows = OFFICE.class_members["window"]
    assert windows.size >= 2
    first, second = (int(i) for i in windows[:2])
    at = [
        float(np.arctan2(OFFICE.object_xy[i, 1] - y[0], OFFICE.object_xy[i, 0] - x[0]))
        for i in (first, second)
    ]
    # A bearing as far from every window as can be: no window explains it.
    to_windows = np.arctan2(
        OFFICE.object_xy[windows, 1] - y[0], OFFICE.object_xy[windows, 0] - x[0]
    )
    scan = np.linspace(-np.pi, np.pi, 721)
    apart = np.abs(np.angle(np.exp(1j * (scan[:, None] - to_windows[None, :])))).min(axis=1)
    nothing = float(scan[np.argmax(apart)])
    assert apart.max() > np.radians(30.0)
    before = model.log_likelihood(x, y, theta, model.observe([Detection("window", at[0])]))
    alone = model.log_likelihood(x, y, theta, model.observe([Detection("window", nothing)]))
    assert before[0] > alone[0] + 1.0
    model.exclude([first])
    obs = model.observe([Detection("window", at[0])])
    assert first not in obs.members.tolist() and second in obs.members.tolist()
    after = model.log_likelihood(x, y, theta, obs)
    assert after[0] == pytest.approx(alone[0], abs=1e-6)
    # The other window still explains its detection; kept frames are made again alike.
    other = model.observe([Detection("window", at[1])])
    assert model.log_likelihood(x, y, theta, other)[0] > alone[0] + 1.0
    again = model.observations_from_columns(observation_columns([obs]))[0]
    assert np.array_equal(again.members, obs.members)


def test_a_class_with_every_object_excluded_seeds_no_pose_from_its_detections() -> None:
    """Sensor resetting draws poses from the detections of classes that still have an
    object; a frame of only excluded ones gives positions with any heading."""
    cfg = FilterConfig(particles=100)
    model = BearingSensorModel(OFFICE, cfg, OFFICE.visibility)
    door = [int(i) for i in OFFICE.class_members["door"]]
    model.exclude(door)
    only_doors = model.observe([Detection("door", 0.3), Detection("door", -1.0)])
    assert only_doors.members.size == 0
    x, y, theta = model.sample_poses(500, only_doors, np.random.default_rng(0))
    assert x.shape == y.shape == theta.shape == (500,)
    assert np.all(np.abs(theta) <= np.pi)
    mixed = model.observe([Detection("door", 0.3), Detection("window", 1.0)])
    x, y, theta = model.sample_poses(500, mixed, np.random.default_rng(0))
    # Every pose points its window detection at a window.
    win = OFFICE.object_xy[OFFICE.class_members["window"]]
    towards = np.arctan2(win[None, :, 1] - y[:, None], win[None, :, 0] - x[:, None])
    off = np.abs(np.angle(np.exp(1j * (towards - (theta[:, None] + 1.0)))))
    assert np.all(off.min(axis=1) < np.radians(15.0))
