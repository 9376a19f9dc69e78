"""The odometry's scale and heading drift, estimated from the converged walk."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from app.bench import generated_map
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.odometry_bias import (
    BIAS_PRIORS,
    CLAMP_STDS,
    NARROW_POSITION_STD_M,
    NARROW_SHORTFALL,
    SEGMENT_S,
    OdometryBias,
)
from app.localization.types import Odometry

DT = 0.2  # 5 frames a second


def _walk(n: int, rng: np.random.Generator) -> np.ndarray:
    """A person's true poses (n, 3): walking at 0.5 m/s, turning now and then."""
    poses = np.zeros((n, 3))
    for i in range(1, n):
        turn = rng.normal(0.0, 0.05) + (0.3 if i % 60 == 0 else 0.0)
        x, y, t = poses[i - 1]
        poses[i] = (x + 0.1 * math.cos(t), y + 0.1 * math.sin(t), t + turn)
    return poses


def _increments(poses: np.ndarray) -> list[Odometry]:
    """The exact body-frame motion between consecutive poses."""
    out = []
    for (x0, y0, t0), (x1, y1, t1) in itertools.pairwise(poses):
        c, s = math.cos(t0), math.sin(t0)
        dx, dy = x1 - x0, y1 - y0
        out.append(Odometry(c * dx + s * dy, -s * dx + c * dy, t1 - t0))
    return out


def _biased(motion: list[Odometry], scale: float, drift_rad_s: float) -> list[Odometry]:
    """What an odometry with this scale and drift reports for ``motion``."""
    return [
        Odometry(m.forward_m * scale, m.left_m * scale, m.turn_rad + drift_rad_s * DT)
        for m in motion
    ]


def _feed(
    bias: OdometryBias,
    poses: np.ndarray,
    raw: list[Odometry],
    rng: np.random.Generator,
    converged: bool = True,
    pos_noise: float = 0.05,
    heading_noise: float = math.radians(1.0),
) -> None:
    """Each frame's raw odometry and a converged estimate a little off the truth."""
    for pose, odo in zip(poses[1:], raw, strict=True):
        est = (
            pose[0] + rng.normal(0.0, pos_noise),
            pose[1] + rng.normal(0.0, pos_noise),
            pose[2] + rng.normal(0.0, heading_noise),
        )
        bias.observe(odo, DT, est, converged, 0.1, math.radians(2.0))


def test_learns_a_pdr_scale_and_drift_from_the_converged_walk() -> None:
    rng = np.random.default_rng(3)
    poses = _walk(1500, rng)  # 5 minutes
    drift = math.radians(8.0) / 60.0
    raw = _biased(_increments(poses), 1.08, drift)
    bias = OdometryBias(BIAS_PRIORS["pdr"])
    _feed(bias, poses, raw, rng)
    assert bias.updates > 50
    # The odometry reads 8 % long: its distances are to be shrunk by 1 / 1.08.
    assert bias.scale == pytest.approx(1.0 / 1.08, abs=0.01)
    assert math.degrees(bias.drift_rad_s) * 60.0 == pytest.approx(8.0, abs=1.5)
    # The corrected motion is closer to the true one than the raw.
    truth = _increments(poses)
    fixed = [bias.correct(o, DT) for o in raw]
    raw_err = sum(abs(o.forward_m - t.forward_m) for o, t in zip(raw, truth, strict=True))
    fix_err = sum(abs(o.forward_m - t.forward_m) for o, t in zip(fixed, truth, strict=True))  # type: ignore[union-attr]
    assert fix_err < 0.2 * raw_err


def test_exact_odometry_stays_exact() -> None:
    rng = np.random.default_rng(4)
    poses = _walk(1500, rng)
    bias = OdometryBias(BIAS_PRIORS["pdr"])
    _feed(bias, poses, _increments(poses), rng)
    assert bias.scale == pytest.approx(1.0, abs=0.01)
    assert abs(math.degrees(bias.drift_rad_s) * 60.0) < 1.0


def test_learns_nothing_while_not_converged() -> None:
    rng = np.random.default_rng(5)
    poses = _walk(600, rng)
    bias = OdometryBias(BIAS_PRIORS["pdr"])
    _feed(bias, poses, _biased(_increments(poses), 1.1, 0.002), rng, converged=False)
    assert bias.updates == 0
    assert (bias.scale, bias.drift_rad_s) == (1.0, 0.0)


def test_a_jumping_estimate_is_left_out_and_the_result_stays_near_the_prior() -> None:
    """Estimates teleporting between two places a few metres apart say nothing of the
    odometry; and however the measurements go, the scale stays within the prior's reach."""
    rng = np.random.default_rng(6)
    poses = _walk(900, rng)
    jumpy = poses.copy()
    jumpy[::40, 0] += 6.0  # a frame now and then at another place
    bias = OdometryBias(BIAS_PRIORS["vio"])
    _feed(bias, jumpy, _increments(poses), rng)
    prior = BIAS_PRIORS["vio"]
    assert abs(bias.scale - 1.0) <= CLAMP_STDS * prior.scale_std + 1e-12
    assert abs(bias.scale - 1.0) < 0.01  # the jumps were left out, not averaged in


def test_a_vio_prior_is_tighter_than_a_pdr_one() -> None:
    """The same few noisy measurements move a VIO estimate less than a PDR one."""
    rng = np.random.default_rng(7)
    poses = _walk(int(3 * SEGMENT_S / DT), rng)
    raw = _biased(_increments(poses), 1.05, 0.0)
    moved = {}
    for source in ("vio", "pdr"):
        bias = OdometryBias(BIAS_PRIORS[source])
        _feed(bias, poses, raw, np.random.default_rng(8), pos_noise=0.15)
        moved[source] = abs(bias.scale - 1.0)
    assert moved["vio"] < moved["pdr"]


def test_checkpoint_round_trip_continues_identically() -> None:
    rng = np.random.default_rng(9)
    poses = _walk(400, rng)
    raw = _biased(_increments(poses), 0.93, -0.001)
    a = OdometryBias(BIAS_PRIORS["pdr"])
    _feed(a, poses[:201], raw[:200], np.random.default_rng(10))
    b = OdometryBias(BIAS_PRIORS["pdr"])
    b.restore(a.checkpoint())
    for bias in (a, b):
        _feed(bias, poses[200:], raw[200:], np.random.default_rng(11))
    assert a.checkpoint() == b.checkpoint()
    assert a.updates > 0


def test_filter_corrects_odometry_and_checkpoints_the_estimate() -> None:
    semantic_map = generated_map(10)
    config = FilterConfig(particles=500, odometry_source="pdr")
    pf = ParticleFilter(semantic_map, config, rng=np.random.default_rng(1))
    assert pf.odometry_bias is not None
    pf.odometry_bias.scale = 0.9
    state = pf.checkpoint()
    assert state["odometry_bias"]["scale"][0] == 0.9
    # An older checkpoint (none kept) resumes with the prior.
    del state["odometry_bias"]
    again = ParticleFilter(semantic_map, config, rng=np.random.default_rng(1), state=state)
    assert again.odometry_bias is not None and again.odometry_bias.scale == 1.0
    # Off unless asked for (the paper's and the simulator's suites).
    assert (
        ParticleFilter(
            semantic_map, FilterConfig(particles=500), rng=np.random.default_rng(1)
        ).odometry_bias
        is None
    )


def test_the_first_stretch_of_a_converged_run_teaches_nothing() -> None:
    """A fix's first seconds are its least sure (it forms where it first fits, then
    settles): the first stretch of each converged run is not measured. An estimate that
    lags a fifth behind the odometry while it settles leaves the scale alone, and the
    next stretch measures it."""
    rng = np.random.default_rng(9)
    poses = _walk(int(2.5 * SEGMENT_S / DT), rng)
    first = int(SEGMENT_S / DT) + 1
    settling = poses.copy()
    # Over the first stretch the estimate covers only 80 % of the walk, then keeps pace.
    settling[:first, :2] = poses[0, :2] + 0.8 * (poses[:first, :2] - poses[0, :2])
    settling[first:, :2] = poses[first:, :2] - (poses[first - 1, :2] - settling[first - 1, :2])
    bias = OdometryBias(BIAS_PRIORS["pdr"])
    raw = _increments(poses)
    _feed(bias, settling[: first + 1], raw[:first], rng, pos_noise=0.0)
    assert bias.scale == 1.0
    _feed(bias, settling[first:], raw[first:], rng, pos_noise=0.0)
    assert bias.scale != 1.0 and bias.scale == pytest.approx(1.0, abs=0.02)


def test_a_heading_off_by_a_steady_angle_teaches_no_scale() -> None:
    """A converged estimate whose heading is a steady 12 degrees off (its position right)
    turns the odometry's account of every stretch by that angle: the stretch's length is
    still the walk's, so exact odometry keeps a scale of 1 (the stretch's projection on the
    estimate's displacement was short by cos 12 deg, and taught a scale of 0.98)."""
    rng = np.random.default_rng(12)
    poses = _walk(1500, rng)  # 5 minutes
    turned = poses.copy()
    turned[:, 2] += math.radians(12.0)
    bias = OdometryBias(BIAS_PRIORS["pdr"])
    _feed(bias, turned, _increments(poses), rng)
    assert bias.updates > 50
    assert bias.scale == pytest.approx(1.0, abs=0.01)


def test_a_narrow_cameras_fix_teaches_the_scale_more_cautiously() -> None:
    """Through a camera narrower than 180 deg a fix's place along the walk is known only
    to a few decimetres whatever its cloud says, so the same stretches move the scale
    less and leave it less sure than a 360 deg camera's; the filter hands its camera's
    field of view to the estimate."""
    rng = np.random.default_rng(13)
    poses = _walk(int(4 * SEGMENT_S / DT), rng)
    raw = _biased(_increments(poses), 1.08, 0.0)
    learnt = {}
    for fov in (66.0, 360.0):
        bias = OdometryBias(BIAS_PRIORS["pdr"], fov)
        _feed(bias, poses, raw, np.random.default_rng(14))
        learnt[fov] = bias
    assert learnt[66.0].updates == learnt[360.0].updates > 0
    assert learnt[66.0].scale_var > 2.0 * learnt[360.0].scale_var
    # Both head for 1 / 1.08, the narrow one less far.
    assert 1.0 > learnt[66.0].scale > learnt[360.0].scale > 1.0 / 1.08 - 0.02
    narrow = ParticleFilter(
        generated_map(10),
        FilterConfig(particles=500, odometry_source="pdr", fov_deg=66.0),
        rng=np.random.default_rng(1),
    )
    assert narrow.odometry_bias is not None
    assert narrow.odometry_bias.min_position_std_m == NARROW_POSITION_STD_M


def test_a_narrow_cameras_shortfall_is_made_up() -> None:
    """Through a narrow camera the fix's displacement falls short of the person's by
    about ``NARROW_SHORTFALL`` (measured, module docstring): exact odometry and a fix
    whose every displacement is that much short leave the narrow camera's scale at 1,
    while a 360 deg camera's fix, which does not fall short, would be taken at its word."""
    rng = np.random.default_rng(21)
    poses = _walk(1500, rng)
    short = poses.copy()
    short[:, :2] *= 1.0 - NARROW_SHORTFALL  # every displacement that share short
    learnt = {}
    for fov in (66.0, 360.0):
        bias = OdometryBias(BIAS_PRIORS["pdr"], fov)
        _feed(bias, short, _increments(poses), np.random.default_rng(22), pos_noise=0.02)
        learnt[fov] = bias.scale
    assert learnt[66.0] == pytest.approx(1.0, abs=0.004)
    assert learnt[360.0] == pytest.approx(1.0 - NARROW_SHORTFALL, abs=0.004)
