"""Confidence from evidence: mirror modes survive, clutter does not flap, the
protection radius holds the truth, kidnaps are noticed."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from app.experiments.hard_maps import rotation_room
from app.localization import sensor_kernel
from app.localization.alternatives import DEFAULT_EVIDENCE, moves_onto, near, near_pairs
from app.localization.compass import CompassReading, compass_log_likelihood, compass_terms
from app.localization.config import FilterConfig
from app.localization.evidence import EvidenceTracker
from app.localization.filter import ParticleFilter
from app.localization.models import BearingSensorModel, OdometryMotionModel
from app.localization.search import PATTERN, jitter_search_reference, pattern_search_reference
from app.localization.sensor import log_likelihood_reference, prepare_observation
from app.localization.tolerances import U64, candidate_flip_mask, log_likelihood_tolerance
from app.localization.types import Hypothesis, Odometry
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


def search_windows(m: SemanticMap) -> list[EvidenceTracker]:
    """Trackers holding a walk's history, each with its case: a full camera and a
    compass; a 90 deg camera with clutter and misses; visibility off (no grid); a
    compass alone (every position of a heading scores the same: ties); no frames."""
    cases = [
        ("360, compass", FilterConfig(), dict(compass_std_deg=10.0)),
        ("90, clutter", FilterConfig(fov_deg=90.0), dict(false_rate=1.0, miss_prob=0.2)),
        ("no visibility", FilterConfig(visibility=False), {}),
        ("compass only", FilterConfig(), dict(compass_std_deg=10.0)),
        ("no frames", FilterConfig(), {}),
    ]
    out = []
    for seed, (name, cfg, sim_changes) in enumerate(cases):
        sim = replace(paper_config("nominal", cfg.fov_deg), duration_s=4.0, **sim_changes)
        grid = m.visibility if cfg.visibility else None
        models = BearingSensorModel(m, cfg, grid), OdometryMotionModel(m, cfg)
        tracker = EvidenceTracker(*models, np.random.default_rng(seed))
        frames = [] if name == "no frames" else simulate(m, sim, np.random.default_rng(seed))
        for f in frames[:12]:
            heading = None if f.compass_rad is None else CompassReading(f.compass_rad, 0.2)
            detections = [] if name == "compass only" else f.detections
            tracker._history.append((f.odometry, prepare_observation(detections, m, cfg), heading))
        out.append(tracker)
    return out


def search_poses(m: SemanticMap, rng: np.random.Generator, n: int):
    """Poses to search from: most in the free space, some anywhere in and around the
    map (walls, outside, off the free-space grid), two repeated, one heading NaN (a
    NaN score: the first one wins, as np.argmax picks it)."""
    inside = m.free_space.sample(n - n // 4, rng)
    lo_x, lo_y, hi_x, hi_y = m.bounds
    x = np.concatenate([inside[:, 0], rng.uniform(lo_x - 2.0, hi_x + 2.0, n // 4)])
    y = np.concatenate([inside[:, 1], rng.uniform(lo_y - 2.0, hi_y + 2.0, n // 4)])
    t = rng.uniform(-np.pi, np.pi, n)
    x[1], y[1], t[1] = x[0], y[0], t[0]
    t[2] = np.nan
    return x, y, t


def assert_same_numbers(got, want) -> None:
    """Equal to the bit, NaN where NaN (a NaN's payload is not a number)."""
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape
        assert np.array_equal(np.isnan(g), np.isnan(w))
        ok = ~np.isnan(w)
        assert np.array_equal(g[ok].view(np.int64), w[ok].view(np.int64))


def test_compiled_pattern_search_is_the_reference(paper_office: SemanticMap) -> None:
    """The compiled pattern search does the numpy definition's arithmetic: the same
    candidates, wrap, free-space test, tie rule and updates give the same bits, for
    the polish's own steps and for coarse random ones (more candidates off the free
    space) over windows of every kind; and a step to a NaN heading (a NaN score, which
    wins as np.argmax picks it and stays as np.maximum keeps it) does what numpy does."""
    rng = np.random.default_rng(11)
    moved = off_free = 0
    for tracker in search_windows(paper_office):
        window = tracker.window()
        for trial in range(6):
            x, y, t = search_poses(paper_office, rng, int(rng.integers(3, 40)))
            if trial == 0:
                steps = (DEFAULT_EVIDENCE.polish_step_m, DEFAULT_EVIDENCE.polish_step_rad, 8)
            else:
                steps = (rng.uniform(0.05, 2.0), rng.uniform(0.01, 1.5), int(rng.integers(1, 9)))
            pattern = PATTERN if trial != 1 else np.insert(PATTERN, 13, [0, 0, np.nan], axis=1)
            args = (window, paper_office, tracker.config, tracker.grid)
            got = sensor_kernel.window_pattern_search(x, y, t, pattern, *steps, *args)
            want = pattern_search_reference(x, y, t, pattern, *steps, *args)
            assert_same_numbers(got, want)
            if trial == 0:  # the polish is this search
                assert_same_numbers(tracker.finder.polished(x, y, t, window), want)
            moved += int(np.count_nonzero((got[0] != x) | (got[1] != y)))
            off_free += int(np.count_nonzero(~paper_office.free_space.is_free(x, y)))
    assert moved > 100 and off_free > 50  # the searches really moved, from everywhere


def test_compiled_jitter_search_is_the_reference(paper_office: SemanticMap) -> None:
    """The compiled jitter search gives the numpy definition's bits for random rounds
    of copies (one copy's heading NaN: its NaN score wins the pose's round, as
    np.argmax picks it, and changes nothing); the refinement draws its jitter as the
    definition consumes it (per round x, y, heading), so it ends in the same poses and
    the same generator state."""
    rng = np.random.default_rng(12)
    for tracker in search_windows(paper_office):
        window = tracker.window()
        args = (window, paper_office, tracker.config, tracker.grid)
        for _ in range(6):
            x, y, t = search_poses(paper_office, rng, int(rng.integers(3, 40)))
            jitter = [
                tuple(rng.normal(0.0, std, (x.size, count)) for std in (0.5, 0.5, 0.3))
                for count in rng.integers(1, 20, int(rng.integers(1, 4)))
            ]
            jitter[0][2][0, -1] = np.nan
            got = sensor_kernel.window_jitter_search(x, y, t, jitter, *args)
            assert_same_numbers(got, jitter_search_reference(x, y, t, jitter, *args))
        rounds = ((16, 0.2, 0.1), (5, 0.05, 0.02))
        tracker.finder.rng = np.random.default_rng(13)
        got = tracker.finder.refined(x, y, t, rounds, window)
        drawn = np.random.default_rng(13)
        jitter = [
            tuple(drawn.normal(0.0, std, (x.size, count)) for std in (s_m, s_m, s_rad))
            for count, s_m, s_rad in rounds
        ]
        assert_same_numbers(got, jitter_search_reference(x, y, t, jitter, *args))
        assert tracker.finder.rng.bit_generator.state == drawn.bit_generator.state


def test_near_pairs_is_near_of_every_pose() -> None:
    """The search's finalists are told apart by one call for all pairs: row i is what
    _near says of every pose against pose i, also at the thresholds themselves."""
    st = DEFAULT_EVIDENCE
    rng = np.random.default_rng(14)
    x, y = rng.uniform(0.0, 3.0, 60), rng.uniform(0.0, 3.0, 60)
    t = rng.uniform(-np.pi, np.pi, 60)
    # Pairs exactly a threshold apart (and wrapped across +-pi).
    x[1], y[1], t[1] = x[0] + st.distinct_m, y[0], t[0]
    x[3], y[3], t[3] = x[2], y[2], t[2] + st.distinct_rad
    x[5], y[5], t[5] = x[4], y[4], np.pi - st.distinct_rad / 2
    t[4] = -np.pi + st.distinct_rad / 2
    pairs = near_pairs(x, y, t, st)
    for i in range(x.size):
        h = Hypothesis(float(x[i]), float(y[i]), float(t[i]), 0.0)
        assert np.array_equal(pairs[i], near(x, y, t, h, st))
    assert 60 < np.count_nonzero(pairs) < 60 * 60  # some pairs near, most not


@pytest.mark.parametrize("seed", [0, 1])
def test_mirror_mode_of_a_symmetric_room_survives(seed: int) -> None:
    """Rotation room, 180 deg camera, the only door behind: the pose and its image
    under the room's 180 deg rotation explain everything equally. The filter must
    never claim either, and must still name both (its own clusters or alternatives).
    How the weight splits between the two is chance: a cloud that happens to hold the
    image's side keeps most of it (measured on an AMD EPYC, seed 1: 0.98 and 0.02; 0.1
    or more each on another CPU), so naming is what is held, not the split."""
    hm = rotation_room()
    sim = SimulationConfig(path=hm.path, fov_deg=180.0, duration_s=8.0)
    _, out = walk(hm.map, sim, FilterConfig(fov_deg=180.0, particles=6000), seed)
    assert not any(e.converged for _, e, _ in out)
    f, e, _ = out[-1]
    image = (12.0 - f.truth.x, 8.0 - f.truth.y)
    named = list(e.hypotheses)

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


def test_the_trail_keeps_the_last_positions_in_order() -> None:
    from app.localization.alternatives import Trail

    trail = Trail(5)
    assert len(trail) == 0 and trail.points().shape == (0, 2)
    for k in range(23):  # past the point where the oldest are dropped
        trail.append(float(k), -float(k))
        want = [[float(i), -float(i)] for i in range(max(0, k - 4), k + 1)]
        assert trail.points().tolist() == want, k
        assert len(trail) == len(want)
    trail.clear()
    assert len(trail) == 0 and not trail


def test_a_long_tracked_look_alike_counts_at_half_its_evidence_for_a_gain(
    paper_office: SemanticMap,
) -> None:
    """Refuted by a few units only after ``rival_frames`` of tracking, a look-alike keeps
    a gain away that the same evidence against a newcomer would not."""
    cfg = FilterConfig(particles=200)
    models = (
        BearingSensorModel(paper_office, cfg, paper_office.visibility),
        OdometryMotionModel(paper_office, cfg),
    )
    tracker = EvidenceTracker(*models, np.random.default_rng(0))
    st = tracker.settings
    assert tracker.gain_share == 0.0  # nothing tracked
    tracker.moves = np.zeros((2, 3))
    tracker.llr = tracker.seg = np.array([-9.0, -30.0])
    tracker.age = np.array([st.rival_frames - 1, 0])
    # Young: the gain is held to the same share as everything else.
    assert tracker.gain_share == pytest.approx(tracker.alternative_share, rel=1e-12)
    tracker.age = np.array([st.rival_frames, st.rival_frames])
    w = cfg.evidence_weight
    want = [np.exp(st.rival_weight * w * -9.0), np.exp(st.rival_weight * w * -30.0)]
    assert tracker.gain_share == pytest.approx(sum(want) / (1.0 + sum(want)), rel=1e-12)
    assert tracker.alternative_share < 0.01 < tracker.gain_share


def test_a_gain_waiting_for_a_search_gets_it_at_the_base_interval(
    paper_office: SemanticMap,
) -> None:
    """A walk with no look-alike searches every 5 s once its searches keep finding none;
    told that a gain waits for a search (the filter does so after a ride), the tracker
    searches again within ``search_every`` frames."""
    sim = replace(paper_config("nominal", 360.0), duration_s=60.0)
    frames = simulate(paper_office, sim, np.random.default_rng(11))
    pf = ParticleFilter(paper_office, FilterConfig(), rng=np.random.default_rng(12))
    assert pf.evidence is not None
    quiet, base = pf.evidence.settings.max_search_every, pf.evidence.settings.search_every
    i = 0
    for i, f in enumerate(frames):
        est = pf.step(f.odometry, f.detections)
        if i > 50 and est.converged and pf.evidence.searched_ago == 0:
            break
    assert pf.evidence.search_interval == quiet  # the walk's searches found nothing

    def searched_within(gain_waits: bool) -> bool:
        tracker = copy.deepcopy(pf.evidence)
        assert tracker is not None
        main = pf.estimate.hypotheses[0]
        particles = (pf.x, pf.y, pf.theta, pf.weights)
        for f in frames[i + 1 : i + 1 + base]:
            obs = pf.sensor.observe(f.detections)
            tracker.update(f.odometry, obs, main, True, particles, None, True, gain_waits)
            if tracker.searched_ago == 0:
                return True
        return False

    assert searched_within(gain_waits=True)
    assert not searched_within(gain_waits=False)


def test_only_a_young_alternative_is_moved_onto_a_better_search_finalist(
    paper_office: SemanticMap,
) -> None:
    """A search finalist near a tracked alternative that fits the window better takes
    its place only while the alternative is young: an older one's place is what its
    evidence followed, and a few frames' best fit a metre off is often chance."""
    sim = replace(paper_config("nominal", 360.0), duration_s=8.0)
    frames = simulate(paper_office, sim, np.random.default_rng(21))
    pf = ParticleFilter(paper_office, FilterConfig(particles=2000), rng=np.random.default_rng(22))
    for f in frames:
        pf.step(f.odometry, f.detections)
    tracker = pf.evidence
    assert tracker is not None and tracker._anchor is not None
    truth = frames[-1].truth
    # An alternative 0.6 m off the person's place; the finalist on the place itself.
    off = (np.array([truth.x + 0.6]), np.array([truth.y]), np.array([truth.theta_rad]))
    there = (np.array([truth.x]), np.array([truth.y]), np.array([truth.theta_rad]))
    window = tracker.window()
    assert tracker.window_score(*there, window)[0] > tracker.window_score(*off, window)[0]

    def moved(age: int) -> bool:
        t = copy.deepcopy(tracker)
        t.moves = moves_onto(t._anchor_pose(), *off)
        t.llr = t.seg = np.array([-1.0])
        t.age = np.array([age])
        t._replace_places(*there, np.array([0.0]), window)
        return bool(abs(t._centres()[0][0] - truth.x) < 1e-6)

    assert moved(0) and moved(tracker.settings.young - 1)
    assert not moved(tracker.settings.young)
