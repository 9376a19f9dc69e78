"""The compass: a heavy-tailed heading measurement, and what it does to the filter."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from app.localization.compass import (
    MIN_STD_DEG,
    OUTLIER_SHARE,
    CompassReading,
    compass_log_likelihood,
)
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.sensor import scaled_bessel_i0
from app.maps.model import parse_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import CompassBias, simulate

OFFICE_JSON = json.loads((bundled_maps_dir() / "paper_office.json").read_text())
#: The paper office without its door: the same after a half turn about its centre.
SYMMETRIC = parse_map(
    {
        **OFFICE_JSON,
        "name": "symmetric_office",
        "objects": [o for o in OFFICE_JSON["objects"] if o["class"] != "door"],
    }
)
OFFICE = parse_map(OFFICE_JSON)


def test_the_likelihood_peaks_at_the_reading_and_has_a_floor() -> None:
    reading = CompassReading(math.radians(30.0), math.radians(20.0))
    theta = np.radians(np.arange(-180.0, 180.0, 1.0))
    ll = compass_log_likelihood(theta, reading)
    kappa = 1.0 / math.radians(20.0) ** 2
    uniform = OUTLIER_SHARE * scaled_bessel_i0(kappa)  # relative to the von Mises peak
    assert ll.max() == pytest.approx(math.log(1.0 - OUTLIER_SHARE + uniform), rel=1e-12)
    assert np.degrees(theta[np.argmax(ll)]) == pytest.approx(30.0)
    floor = math.log(uniform)
    assert ll.min() >= floor - 1e-12
    # Heavy tail: 90 degrees off and 180 degrees off cost about the same.
    off = {d: ll[np.argmin(np.abs(np.degrees(theta) - (30.0 + d)))] for d in (90.0, 150.0)}
    assert off[90.0] - off[150.0] < 0.1
    # A claimed std below MIN_STD_DEG is not believed.
    sharp = compass_log_likelihood(theta, CompassReading(0.0, math.radians(0.5)))
    floored = compass_log_likelihood(theta, CompassReading(0.0, math.radians(MIN_STD_DEG)))
    assert np.allclose(sharp, floored)


def test_the_compass_picks_the_right_one_of_two_mirror_modes() -> None:
    pf = ParticleFilter(SYMMETRIC, FilterConfig(particles=2000), rng=np.random.default_rng(0))
    n = pf.n
    # Half the particles at (3, 2) facing east, half at the mirror pose (7, 5) facing west.
    pf.x = np.r_[np.full(n // 2, 3.0), np.full(n - n // 2, 7.0)]
    pf.y = np.r_[np.full(n // 2, 2.0), np.full(n - n // 2, 5.0)]
    pf.theta = np.r_[np.zeros(n // 2), np.full(n - n // 2, math.pi)]
    pf.log_w = np.zeros(n)
    # No detections, only a compass reading 10 degrees off east.
    w = pf.weights.copy()
    ll = compass_log_likelihood(pf.theta, CompassReading(math.radians(10.0), math.radians(20.0)))
    pf.step(None, [], CompassReading(math.radians(10.0), math.radians(20.0)))
    east = np.cos(pf.theta) > 0
    # One reading: the east mode's share is the likelihood ratio (motion noise aside).
    expected = (w[: n // 2] * np.exp(ll[: n // 2])).sum() / (w * np.exp(ll)).sum()
    assert pf.weights[east].sum() == pytest.approx(expected, abs=0.02)
    assert expected > 0.9


def _walk(m, compass: bool, seed: int, biases=(), fov=360.0, particles=2000):
    sim = paper_config("nominal", fov)
    if compass:
        sim = replace(sim, compass_std_deg=15.0, compass_biases=biases)
    world, filt = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 1]).spawn(2))
    frames = simulate(m, sim, world)
    pf = ParticleFilter(m, FilterConfig(particles=particles, fov_deg=fov), rng=filt)
    out = []
    for f in frames:
        heading = None
        if f.compass_rad is not None:
            heading = CompassReading(f.compass_rad, math.radians(20.0))
        e = pf.step(f.odometry, f.detections, heading)
        out.append((f.t, e.converged, math.hypot(e.x - f.truth.x, e.y - f.truth.y)))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_with_a_compass_the_symmetric_room_is_never_confidently_wrong(seed: int) -> None:
    run = _walk(SYMMETRIC, True, seed)
    assert not any(conv and err > 1.0 for _, conv, err in run)
    assert sum(conv for _, conv, _ in run) > 0.8 * len(run)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("start", [0.0, 20.0])
def test_a_compass_60_degrees_off_for_20_s_does_not_make_it_confidently_wrong(
    seed: int, start: float
) -> None:
    bias = (CompassBias(start, start + 20.0, 60.0),)
    for m in (OFFICE, SYMMETRIC):
        run = _walk(m, True, seed, bias)
        assert not any(conv and err > 1.0 for _, conv, err in run), m.name
