"""The particle filter end to end on small simulated walks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from app.localization.config import FilterConfig
from app.localization.estimate import estimate_pose
from app.localization.filter import ParticleFilter
from app.localization.types import InitialPose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap
from app.simulation.scenarios import paper_config
from app.simulation.simulator import SimulationConfig, simulate


def run(m: SemanticMap, sim: SimulationConfig, cfg: FilterConfig, seed: int = 0, initial=None):
    frames = simulate(m, sim, np.random.default_rng(seed))
    pf = ParticleFilter(m, cfg, rng=np.random.default_rng(seed + 100), initial_pose=initial)
    out = []
    for f in frames:
        e = pf.step(f.odometry, f.detections)
        out.append((f, e, float(np.hypot(e.x - f.truth.x, e.y - f.truth.y))))
    return pf, out


def test_global_localization_converges_on_the_paper_office(paper_office: SemanticMap) -> None:
    sim = replace(paper_config("nominal", 360), duration_s=12.0)
    _, out = run(paper_office, sim, FilterConfig(particles=4000))
    first = next(i for i, (_, e, _) in enumerate(out) if e.converged)
    assert out[first][0].t <= 5.0
    late = [err for f, e, err in out if f.t >= 5.0]
    assert np.mean(late) < 0.15
    assert all(e.converged for f, e, _ in out if f.t >= 6.0)


def test_same_seed_same_result(small_room: SemanticMap) -> None:
    sim = SimulationConfig(path=((1, 1), (5, 1), (5, 3)), duration_s=4.0)
    _, a = run(small_room, sim, FilterConfig(particles=1000), seed=3)
    _, b = run(small_room, sim, FilterConfig(particles=1000), seed=3)
    assert [(e.x, e.y, e.theta_rad) for _, e, _ in a] == [(e.x, e.y, e.theta_rad) for _, e, _ in b]


def test_known_start_tracks(small_room: SemanticMap) -> None:
    sim = SimulationConfig(path=((1, 1), (5, 1), (5, 3)), duration_s=10.0)
    start = InitialPose(1.0, 1.0, 0.0, 0.2, 0.1)
    _, out = run(small_room, sim, FilterConfig(particles=1500), initial=start)
    assert max(err for _, _, err in out) < 0.3


def test_kidnapped_person_is_found_again(paper_office: SemanticMap) -> None:
    sim = replace(
        paper_config("nominal", 360),
        duration_s=24.0,
        kidnap_at_s=10.0,
        kidnap_pose=(8.0, 5.0, 90.0),
    )
    _, out = run(paper_office, sim, FilterConfig(particles=4000))
    before = [err for f, _, err in out if 5.0 <= f.t < 10.0]
    assert np.mean(before) < 0.15
    after = [(f.t, e, err) for f, e, err in out if f.t >= 10.0]
    recovered = next(t for t, e, err in after if e.converged and err < 0.2)
    assert recovered - 10.0 <= 6.0
    assert np.mean([err for t, _, err in after if t >= 18.0]) < 0.15
    # It never claims to be converged somewhere wrong after the kidnap.
    assert all(err < 0.5 for _, e, err in after if e.converged)


def test_particle_count_shrinks_once_localized_and_grows_when_lost(
    paper_office: SemanticMap,
) -> None:
    """KLD-sampling: every particle while lost, few once converged, all again after a kidnap."""
    sim = replace(
        paper_config("nominal", 360),
        duration_s=24.0,
        kidnap_at_s=10.0,
        kidnap_pose=(8.0, 5.0, 90.0),
    )
    cfg = FilterConfig(particles=6000, min_particles=600)
    _, out = run(paper_office, sim, cfg, seed=2)
    counts = {round(f.t, 1): e.n_particles for f, e, _ in out}
    assert counts[0.0] == 6000
    settled = [e.n_particles for f, e, _ in out if 6.0 <= f.t < 10.0]
    assert all(600 <= n <= 2000 for n in settled), settled
    assert max(e.n_particles for f, e, _ in out if 10.0 <= f.t < 14.0) == 6000
    late = [e.n_particles for f, e, _ in out if f.t >= 20.0]
    assert np.median(late) <= 2000
    fixed = replace(cfg, adaptive=False)
    _, out_fixed = run(paper_office, sim, fixed, seed=2)
    assert {e.n_particles for _, e, _ in out_fixed} == {6000}


def test_paper_model_has_no_recovery(paper_office: SemanticMap) -> None:
    sim = replace(
        paper_config("nominal", 360),
        duration_s=24.0,
        kidnap_at_s=10.0,
        kidnap_pose=(8.0, 5.0, 90.0),
    )
    _, ours = run(paper_office, sim, FilterConfig(particles=3000), seed=4)
    _, paper = run(paper_office, sim, FilterConfig.paper(particles=3000), seed=4)
    late = lambda out: np.mean([err for f, _, err in out if f.t >= 18.0])  # noqa: E731
    assert late(ours) < late(paper)


def test_frames_without_detections_do_not_inject(paper_office: SemanticMap) -> None:
    """Facing a corner with the view blocked is no evidence: the track survives."""
    sim = replace(paper_config("nominal", 180), duration_s=8.0)
    pf, out = run(paper_office, sim, FilterConfig(particles=3000, fov_deg=180))
    assert out[-1][1].converged
    before = (pf.x.copy(), pf.y.copy())
    slow, fast = pf._recovery.w_slow, pf._recovery.w_fast
    for _ in range(50):  # ten seconds of nothing
        e = pf.step(None, [])
    assert (pf._recovery.w_slow, pf._recovery.w_fast) == (slow, fast)
    truth = out[-1][0].truth
    assert np.hypot(e.x - truth.x, e.y - truth.y) < 0.8
    assert np.mean(np.hypot(pf.x - before[0].mean(), pf.y - before[1].mean())) < 2.0


def test_mirror_modes_are_never_converged() -> None:
    rng = np.random.default_rng(0)
    n = 4000
    x = np.concatenate([rng.normal(2.0, 0.05, n), rng.normal(8.0, 0.05, n)])
    y = np.concatenate([rng.normal(2.0, 0.05, n), rng.normal(5.0, 0.05, n)])
    th = np.concatenate([rng.normal(0.0, 0.02, n), rng.normal(np.pi, 0.02, n)])
    w = np.full(2 * n, 1.0 / (2 * n))
    e = estimate_pose(x, y, wrap_angle(th), w)
    assert not e.converged
    assert len(e.hypotheses) == 2
    assert np.isclose(e.hypotheses[0].weight, 0.5, atol=0.01)
    # The pose reported is one of the modes, not the point between them.
    assert min(np.hypot(e.x - 2, e.y - 2), np.hypot(e.x - 8, e.y - 5)) < 0.1
    # One heavy tight mode is converged.
    w2 = np.concatenate([np.full(n, 0.95 / n), np.full(n, 0.05 / n)])
    assert estimate_pose(x, y, wrap_angle(th), w2).converged


def test_estimate_summarizes_each_mode_by_its_weighted_moments() -> None:
    """Three separated modes (one across the +-pi seam), zero-weight outliers ignored."""
    rng = np.random.default_rng(2)
    centres = [(1.0, 1.0, np.pi - 0.01, 0.5), (6.0, 1.0, 0.5, 0.3), (1.0, 6.0, -1.0, 0.2)]
    xs, ys, ths, ws = [], [], [], []
    for cx, cy, ct, mass in centres:
        n = 3000
        xs.append(rng.normal(cx, 0.05, n))
        ys.append(rng.normal(cy, 0.08, n))
        ths.append(rng.normal(ct, 0.05, n))
        ws.append(np.full(n, mass / n))
    xs.append(np.full(50, 20.0))  # far away but weightless: never a hypothesis
    ys.append(np.full(50, 20.0))
    ths.append(np.zeros(50))
    ws.append(np.zeros(50))
    x, y, th, w = (np.concatenate(v) for v in (xs, ys, ths, ws))
    e = estimate_pose(x, y, wrap_angle(th), w)
    assert [round(h.weight, 3) for h in e.hypotheses] == [0.5, 0.3, 0.2]
    for h, (cx, cy, ct, _) in zip(e.hypotheses, centres, strict=True):
        assert np.hypot(h.x - cx, h.y - cy) < 0.01
        assert abs(wrap_angle(h.theta_rad - ct)) < 0.01
        assert abs(h.std_xy_m - np.hypot(0.05, 0.08)) < 0.01
    assert (e.x, e.y) == (e.hypotheses[0].x, e.hypotheses[0].y)
    assert abs(e.std_x_m - 0.05) < 0.005 and abs(e.std_y_m - 0.08) < 0.005
    assert abs(e.std_theta_rad - 0.05) < 0.005
    assert not e.converged  # half the mass is elsewhere


def test_weights_stay_finite_when_nothing_fits(small_room: SemanticMap) -> None:
    from app.localization.types import Detection

    pf = ParticleFilter(small_room, FilterConfig.paper(particles=500), rng=np.random.default_rng(0))
    for _ in range(5):
        e = pf.step(None, [Detection("door", 0.0), Detection("door", np.pi)])
    assert np.isfinite(pf.weights).all() and np.isclose(pf.weights.sum(), 1.0)
    assert np.isfinite(e.x) and np.isfinite(e.y)


def test_a_belief_with_no_possible_particle_starts_again(paper_office: SemanticMap) -> None:
    """A known start outside the building: every particle is impossible, so the filter
    starts again from no knowledge (never NaN, never stuck) and finds the person."""
    sim = replace(paper_config("nominal", 360), duration_s=10.0)
    outside = InitialPose(12.0, 3.5, 0.0, 0.2, 0.1)
    for cfg in (FilterConfig.paper(particles=4000), FilterConfig(particles=4000)):
        pf, out = run(paper_office, sim, cfg, initial=outside)
        assert pf.restarts == 1
        assert np.isfinite(pf.weights).all()
        assert np.mean([err for f, _, err in out if f.t >= 6.0]) < 0.15
