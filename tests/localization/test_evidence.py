"""Confidence from evidence: mirror modes survive, clutter does not flap, the
protection radius holds the truth, kidnaps are noticed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.experiments.hard_maps import rotation_room
from app.localization.compass import CompassReading, compass_log_likelihood, compass_terms
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.sensor import log_likelihood_reference, prepare_observation
from app.localization.tolerances import U64, candidate_flip_mask, log_likelihood_tolerance
from app.localization.types import Odometry
from app.maps.model import SemanticMap
from app.simulation.scenarios import paper_config
from app.simulation.simulator import SimulationConfig, simulate


def walk(m: SemanticMap, sim: SimulationConfig, cfg: FilterConfig, seed: int):
    world, own = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 5]).spawn(2))
    frames = simulate(m, sim, world)
    pf = ParticleFilter(m, cfg, rng=own)
    out = []
    for f in frames:
        e = pf.step(f.odometry, f.detections)
        out.append((f, e, float(np.hypot(e.x - f.truth.x, e.y - f.truth.y))))
    return pf, out


def chain_back(x, y, theta, odometry: Odometry):
    """The poses one frame earlier, undoing ``odometry`` (noise-free): the reference."""
    t0 = theta - odometry.turn_rad
    c, s = np.cos(t0), np.sin(t0)
    return (
        x - (c * odometry.forward_m - s * odometry.left_m),
        y - (s * odometry.forward_m + c * odometry.left_m),
        t0,
    )


@pytest.mark.parametrize("fov", [360.0, 180.0])
def test_window_score_is_the_chained_sum_of_frames(paper_office: SemanticMap, fov: float) -> None:
    """One compiled call over the history window equals, per pose, the float64 reference
    log-likelihood of every scored frame at the pose chained back by the odometry, plus
    the compass terms, within the kernel's derived bound summed over the frames."""
    cfg = FilterConfig(fov_deg=fov, particles=200)
    sim = replace(paper_config("nominal", fov), duration_s=6.0, compass_std_deg=10.0)
    frames = simulate(paper_office, sim, np.random.default_rng(3))
    pf = ParticleFilter(paper_office, cfg, rng=np.random.default_rng(4))
    tracker = pf.evidence
    assert tracker is not None
    history = []
    for f in frames[:15]:
        heading = None if f.compass_rad is None else CompassReading(f.compass_rad, 0.2)
        obs = prepare_observation(f.detections, paper_office, cfg)
        tracker._history.append((f.odometry, obs, heading))
        history.append((f.odometry, obs, heading))
    history = history[-tracker.settings.window :]
    rng = np.random.default_rng(5)
    pts = paper_office.free_space.sample(300, rng)
    x, y, th = pts[:, 0], pts[:, 1], rng.uniform(-np.pi, np.pi, 300)
    got = tracker.window_score(x, y, th)
    want = np.zeros_like(x)
    bound = np.zeros_like(x)
    sure = np.ones(x.shape, dtype=bool)
    cx, cy, ct = x, y, th
    scored = 0
    for k in range(len(history) - 1, -1, -1):
        odo, obs, heading = history[k]
        if (len(history) - 1 - k) % tracker.settings.window_stride == 0:
            scored += 1
            if not obs.empty:
                rows = paper_office.visibility.visible(cx, cy)
                ref = log_likelihood_reference(cx, cy, ct, obs, paper_office, cfg, rows)
                want += ref
                # The kernel chains the pose in float64 with its own sine and cosine
                # before rounding it to float32, so its position may round one unit
                # away from the reference's: twice the per-frame bound covers that.
                tol = log_likelihood_tolerance(cx, cy, ct, obs, paper_office, cfg, ref)
                bound += 2.0 * np.where(np.isfinite(tol), tol, 0.0)
                sure &= ~candidate_flip_mask(cx, cy, ct, obs, paper_office, cfg)
            if heading is not None:
                _, kappa, _, _ = compass_terms(heading)
                want += compass_log_likelihood(ct, heading)
                # float64 angles of at most a few pi, rounded a few times.
                bound += kappa * 16 * np.pi * U64
        cx, cy, ct = chain_back(cx, cy, ct, odo)
    assert scored == 5
    assert np.count_nonzero(~sure) <= 3
    finite = np.isfinite(want) & sure
    assert np.array_equal(np.isfinite(got[sure]), np.isfinite(want[sure]))
    assert (np.abs(got[finite] - want[finite]) <= bound[finite]).all()
    assert np.ptp(want[finite]) > 10.0  # the poses really differ


@pytest.mark.parametrize("seed", [0, 1])
def test_mirror_mode_of_a_symmetric_room_survives(seed: int) -> None:
    """Rotation room, 180 deg camera, the only door behind: the pose and its image
    under the room's 180 deg rotation explain everything equally. The filter must
    never claim either, and must still name both (its own clusters or alternatives)."""
    hm = rotation_room()
    sim = SimulationConfig(path=hm.path, fov_deg=180.0, duration_s=8.0)
    _, out = walk(hm.map, sim, FilterConfig(fov_deg=180.0, particles=6000), seed)
    assert not any(e.converged for _, e, _ in out)
    f, e, _ = out[-1]
    image = (12.0 - f.truth.x, 8.0 - f.truth.y)
    named = [h for h in e.hypotheses if h.weight >= 0.1]

    def near(h, p):
        return np.hypot(h.x - p[0], h.y - p[1]) < 1.0

    assert any(near(h, (f.truth.x, f.truth.y)) for h in named)
    assert any(near(h, image) for h in named)


def test_clutter_does_not_flap(paper_office: SemanticMap) -> None:
    """One false detection per frame (Poisson), 180 deg: once found, the position is
    held while it stays right; no 'Location found' / 'no longer sure' alternation."""
    sim = replace(paper_config("nominal", 180.0), false_rate=1.0)
    held = []
    for seed in (1, 2, 3):
        _, out = walk(paper_office, sim, FilterConfig(fov_deg=180.0, particles=5000), seed)
        conv = np.array([e.converged for _, e, _ in out])
        err = np.array([x for _, _, x in out])
        assert conv.any()
        lost_while_right = np.flatnonzero(conv[:-1] & ~conv[1:] & (err[1:] <= 0.3))
        assert lost_while_right.size <= 1  # at most one flip in this 53 s walk
        assert not np.any(conv & (err > 1.0))
        held.append(conv[int(np.argmax(conv)) :])
    assert np.concatenate(held).mean() >= 0.85


def test_protection_radius_holds_the_truth(paper_office: SemanticMap) -> None:
    """Calibration on a small run: the truth within protection_m on converged frames."""
    covered, total = 0, 0
    for seed, sim in enumerate(
        (paper_config("nominal", 360.0), replace(paper_config("nominal", 180.0), false_rate=1.0))
    ):
        _, out = walk(paper_office, sim, FilterConfig(fov_deg=sim.fov_deg, particles=4000), seed)
        for _, e, err in out:
            assert (e.protection_m is None) == (not e.converged)
            if e.converged:
                total += 1
                covered += err <= e.protection_m
    assert total > 300
    assert covered / total >= 0.99


def test_kidnap_is_noticed_at_once(paper_office: SemanticMap) -> None:
    sim = replace(
        paper_config("nominal", 360.0),
        duration_s=20.0,
        kidnap_at_s=10.0,
        kidnap_pose=(8.0, 5.0, 90.0),
    )
    _, out = walk(paper_office, sim, FilterConfig(particles=4000), 0)
    assert any(e.converged for f, e, _ in out if f.t < 10.0)
    assert not any(e.converged and err > 1.0 for _, e, err in out)
    assert any(e.converged and err < 0.2 for f, e, err in out if f.t > 14.0)


def test_paper_model_has_no_evidence_tracker(paper_office: SemanticMap) -> None:
    pf = ParticleFilter(
        paper_office, FilterConfig.paper(particles=100), rng=np.random.default_rng(0)
    )
    assert pf.evidence is None
