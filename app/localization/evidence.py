"""Confidence from evidence: alternative places kept alive, and their evidence counted.

A particle filter's weight share says nothing about a mode that resampling has
already killed: in a symmetric or repetitive building the mirror mode dies by chance,
not by evidence. So besides the filter's own cloud (the *main* belief), this module
keeps a small set of **alternative hypotheses**, each a little particle cloud of its own
with the accumulated log-likelihood ratio ``llr`` of everything observed since it was
found, against the main belief:

* **Found** by a periodic global consistency search (every ``search_every`` frames while
  the main belief is a tight mode): candidate poses all over the free space with the
  heading that points one detection at an object of its class (as in sensor
  resetting), scored with the compiled sensor kernel on the current frame; the best
  are refined and scored again on the last ``window`` frames, chained back by the
  odometry. A candidate away from the main mode whose window evidence is within
  ``seed_llr`` of the main mode's (scored the same way) becomes an alternative, its
  ``llr`` starting at that difference. The window forgets what came before it; the
  earlier searches did not: once the main mode has been searched against, a place
  they did not find was at most ``seed_llr`` as likely as the main mode then, so a
  newcomer starts with that prior added (the first search of a mode adds none).
* **Tracked** every frame like the filter: moved with the same odometry and motion
  model, weighted by the same sensor kernel. Its frame evidence (the log of its
  prior-weighted mean likelihood, moves through walls included) minus the main
  belief's is added to ``llr``; so evidence for and against accumulates over the whole
  walk, at a few hundred particles per alternative. The main belief's frame evidence
  comes from an *anchor*: a cloud of the same size drawn from the filter's heaviest
  cluster and tracked the same way (redrawn whenever it leaves that cluster), so that
  both sides of the ratio carry the same small-sample bias (a log of a mean of a few
  hundred peaked likelihoods is biased low; against the filter's thousands of
  particles it drifted a true alternative down by about one unit a second).
* **Dropped** only when its evidence against falls below ``drop_llr``, or when the
  main belief has come to cover it.
* **Swapped** with the main belief when its evidence for exceeds ``switch_llr``: the
  filter's cloud is replaced by the alternative's, and the old main mode becomes an
  alternative carrying the opposite evidence.

The probability of the alternatives under the whole belief, ``e^llr / (1 + sum e^llr)``
summed (the main belief's prior counted equal to each alternative's), gates
``converged`` (see :class:`~app.localization.estimate.ConvergenceGate`) and enters the
protection radius.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.config import FilterConfig
from app.localization.geometry import wrap_angle
from app.localization.map import SemanticMap
from app.localization.motion import motion_log_penalty, sample_motion
from app.localization.recovery import sample_from_observation
from app.localization.resampling import systematic_resample
from app.localization.sensor import Observation
from app.localization.types import Hypothesis, Odometry
from app.localization.visibility import VisibilityGrid


@dataclass(frozen=True)
class EvidenceSettings:
    """Rates, sizes and thresholds of the alternative-hypothesis bookkeeping."""

    #: Frames between global searches (1 s at 5 frames/s).
    search_every: int = 5
    #: Frames of history a search scores, chained back by the odometry.
    window: int = 10
    #: Score every ``window_stride``-th frame of the window.
    window_stride: int = 2
    #: Candidate poses per square metre of free space, and the bounds of their count.
    candidates_per_m2: float = 25.0
    min_candidates: int = 1_000
    max_candidates: int = 6_000
    #: Best candidates refined and scored on the window.
    shortlist: int = 32
    #: Jittered copies per coarse refinement round of the shortlist: (count, position
    #: std m, heading std rad).
    refine: tuple[tuple[int, float, float], ...] = ((16, 0.2, float(np.radians(5.0))),)
    #: The best ``finalists`` (distinct places) are then refined finely, and so is the
    #: main mode: a newcomer placed 0.2 m off would start several units of evidence
    #: behind a main mode that the filter has had time to centre.
    finalists: int = 6
    refine_fine: tuple[tuple[int, float, float], ...] = (
        (48, 0.1, float(np.radians(2.5))),
        (48, 0.04, float(np.radians(1.0))),
        (48, 0.015, float(np.radians(0.4))),
    )
    #: Particles per alternative.
    particles: int = 150
    #: Spread of a new alternative's cloud (m, rad).
    seed_std_m: float = 0.1
    seed_std_rad: float = float(np.radians(2.0))
    max_alternatives: int = 8
    #: Frames an alternative is tracked, once settled, before it can take ``converged``
    #: away.
    probation: int = 5
    #: Frames a fresh cloud (alternative or anchor) settles before its evidence counts.
    settle: int = 5
    #: A candidate within this log-evidence of the main mode over the window is kept.
    seed_llr: float = -6.0
    #: An alternative whose evidence against falls below this is dropped.
    drop_llr: float = -20.0
    #: An alternative this much more likely than the main belief replaces it.
    switch_llr: float = float(np.log(20.0))
    #: Distinct from the main mode (and from each other) beyond these.
    distinct_m: float = 1.0
    distinct_rad: float = float(np.radians(45.0))


DEFAULT_EVIDENCE = EvidenceSettings()


def chain_back(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    odometry: Odometry,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The poses one frame earlier, undoing ``odometry`` (noise-free), shape (N,) each."""
    t0 = theta - odometry.turn_rad
    c, s = np.cos(t0), np.sin(t0)
    x0 = x - (c * odometry.forward_m - s * odometry.left_m)
    y0 = y - (s * odometry.forward_m + c * odometry.left_m)
    return x0, y0, wrap_angle(t0)


def _log_mean_exp_rows(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """log of the mean of exp over each row, shape (A,); -inf for an all -inf row."""
    m = np.max(a, axis=1)
    safe = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return safe + np.log(np.mean(np.exp(a - safe[:, None]), axis=1))


class EvidenceTracker:
    """Alternative hypotheses of one filter, with their accumulated evidence."""

    def __init__(
        self,
        semantic_map: SemanticMap,
        config: FilterConfig,
        grid: VisibilityGrid | None,
        rng: np.random.Generator,
        settings: EvidenceSettings = DEFAULT_EVIDENCE,
    ) -> None:
        self.map = semantic_map
        self.config = config
        self.grid = grid
        self.rng = rng
        self.settings = settings
        self.reset()

    def reset(self) -> None:
        """Forget every alternative and the history (a new start)."""
        p = self.settings.particles
        self.x = np.empty((0, p))
        self.y = np.empty((0, p))
        self.theta = np.empty((0, p))
        self.llr = np.empty(0)
        #: Frames each alternative has been tracked.
        self.age = np.empty(0, dtype=np.int64)
        #: The anchor cloud of the main belief, rows x, y, theta; None until drawn.
        self._anchor: NDArray[np.float64] | None = None
        self._anchor_age = 0
        self._history: deque[tuple[Odometry | None, Observation]] = deque(
            maxlen=self.settings.window
        )
        self._since_search = self.settings.search_every
        #: Frames since the last global search (None before the first one).
        self.searched_ago: int | None = None
        self.searches = 0
        self.swaps = 0
        #: Searches run against the current main mode while it stayed tight.
        self.mode_searches = 0
        self._last_main: Hypothesis | None = None

    # ------------------------------------------------------------ read-outs
    @property
    def count(self) -> int:
        return int(self.llr.size)

    def probabilities(self) -> NDArray[np.float64]:
        """Each alternative's probability under the whole belief, shape (A,)."""
        if not self.count:
            return np.empty(0)
        top = max(0.0, float(self.llr.max()))
        e = np.exp(self.llr - top)
        return e / (np.exp(-top) + e.sum())

    @property
    def alternative_share(self) -> float:
        """Probability that the person is at one of the alternatives, not the main mode."""
        return float(self.probabilities().sum())

    @property
    def confirmed_share(self) -> float:
        """:attr:`alternative_share` of the alternatives tracked for ``probation`` frames.

        The best of thousands of candidates fits a short window better than a typical
        look-alike would, by selection alone; one that then keeps its evidence for a
        second of tracking is a real competitor.
        """
        p = self.probabilities()
        st = self.settings
        return float(p[self.age >= st.settle + st.probation].sum())

    def hypotheses(self) -> list[Hypothesis]:
        """One :class:`Hypothesis` per alternative, weight = its probability."""
        out = []
        for a, p in enumerate(self.probabilities()):
            c, s = np.cos(self.theta[a]).mean(), np.sin(self.theta[a]).mean()
            spread = float(np.hypot(self.x[a].std(), self.y[a].std()))
            out.append(
                Hypothesis(
                    float(self.x[a].mean()),
                    float(self.y[a].mean()),
                    float(np.arctan2(s, c)),
                    float(p),
                    spread,
                )
            )
        return out

    def farthest_m(self, x: float, y: float) -> float:
        """Distance from (x, y) that holds every alternative's particles."""
        if not self.count:
            return 0.0
        return float(np.max(np.hypot(self.x - x, self.y - y)))

    # ------------------------------------------------------------ one frame
    def update(
        self,
        odometry: Odometry | None,
        obs: Observation,
        main_log_evidence: float,
        main: Hypothesis | None,
        main_tight: bool,
        particles: tuple[NDArray[np.float64], ...],
    ) -> bool:
        """Move and weigh the alternatives, search when due; True if a swap is due.

        Args:
            odometry: this frame's odometry (as given to the filter).
            obs: this frame's observation (may be empty: no evidence).
            main_log_evidence: the main belief's log evidence for this frame (its
                prior-weighted mean likelihood, moves through walls included).
            main: the main belief's heaviest mode, None when it has none.
            main_tight: whether the main mode is tight enough to search against.
            particles: the filter's x, y, theta and normalized weights (to draw the
                anchor from).
        """
        # Frames without detections are kept too: their odometry chains the window.
        self._history.append((odometry, obs))
        if self.searched_ago is not None:
            self.searched_ago += 1
        if self.count or self._anchor is not None:
            self._track(odometry, obs, main_log_evidence)
        if main is not None:
            self._follow_main(main, particles)
            self._forget_covered(main)
        last, self._last_main = self._last_main, main
        if (
            not main_tight
            or main is None
            or last is None
            or odometry is None
            or not self._near(
                np.array([main.x]), np.array([main.y]), np.array([main.theta_rad]), last
            )[0]
        ):
            # A new main mode (or none): its searches start again.
            self.mode_searches = 0
        self._since_search += 1
        if (
            main is not None
            and main_tight
            and not obs.empty
            and self._since_search >= self.settings.search_every
        ):
            self._search(main)
        return bool(self.count and self.llr.max() >= self.settings.switch_llr)

    def _follow_main(self, main: Hypothesis, particles: tuple[NDArray[np.float64], ...]) -> None:
        """Keep the anchor on the filter's heaviest cluster, and the ratios meaningful.

        The anchor is redrawn from the cluster when it has drifted from it (same place).
        When the filter's heaviest cluster moves to another place, the evidence must not
        be re-referenced silently: if that place is an alternative, the two swap roles
        and every ratio is re-expressed against it; otherwise the old anchor becomes an
        alternative with even odds, and evidence decides between them from now on.
        """
        st = self.settings
        if self._anchor is not None:
            c = self._anchor
            mean_t = np.arctan2(np.sin(c[2]).mean(), np.cos(c[2]).mean())
            centre = Hypothesis(float(c[0].mean()), float(c[1].mean()), float(mean_t), 0.0)
            same = self._near(
                np.array([main.x]), np.array([main.y]), np.array([main.theta_rad]), centre
            )[0]
            if same:
                if (
                    np.hypot(centre.x - main.x, centre.y - main.y) < st.distinct_m / 2
                    and abs(float(wrap_angle(centre.theta_rad - main.theta_rad)))
                    < st.distinct_rad / 2
                ):
                    return
            else:
                hit = np.flatnonzero(self._near(*self._centres(), main)) if self.count else []
                if len(hit):
                    i = int(hit[np.argmax(self.llr[hit])])
                    shift = float(self.llr[i])
                    old = self._anchor
                    self._anchor = np.vstack([self.x[i], self.y[i], self.theta[i]])
                    self._anchor_age = int(self.age[i])
                    self.x[i], self.y[i], self.theta[i] = old
                    self.llr = self.llr - shift
                    self.llr[i] = -shift
                    self.age[i] = 0
                    return
                self._add_cloud(c[0], c[1], c[2], 0.0)
        x, y, t, w = particles
        near = self._near(x, y, t, main)
        w = np.where(near, w, 0.0)
        if w.sum() <= 0.0:
            self._anchor = None
            return
        idx = systematic_resample(w / w.sum(), st.particles, self.rng)
        self._anchor = np.vstack([x[idx], y[idx], t[idx]])
        self._anchor_age = 0

    def _track(self, odometry: Odometry | None, obs: Observation, main_ev: float) -> None:
        anchored = self._anchor is not None
        st = self.settings
        rows = [self.x, self.y, self.theta]
        if self._anchor is not None:
            rows = [np.vstack([self._anchor[k][None], rows[k]]) for k in range(3)]
        a, p = rows[0].shape
        fx, fy, ft = (v.reshape(-1) for v in rows)
        nx, ny, nt = sample_motion(fx, fy, ft, odometry, self.config, self.rng)
        log_w = motion_log_penalty(fx, fy, nx, ny, self.map)
        if not obs.empty:
            log_w = log_w + sensor_kernel.log_likelihood(
                nx, ny, nt, obs, self.map, self.config, self.grid
            )
        log_w = log_w.reshape(a, p)
        ev = _log_mean_exp_rows(log_w)
        if anchored and np.isfinite(ev[0]):
            main_ev = float(ev[0])
        first = 1 if anchored else 0
        # A fresh cloud (either side) first settles: a few hundred particles drawn
        # tight but 0.1 m off would swing the ratio by units of evidence in the first
        # frames, by chance, not by what was seen (its search already scored them).
        counts = (self.age >= st.settle) & (self._anchor_age >= st.settle)
        self.llr = self.llr + np.where(counts, ev[first:] - main_ev, 0.0)
        self.age = self.age + 1
        self._anchor_age += 1
        alive = np.isfinite(ev)
        alive[first:] &= self.llr >= self.settings.drop_llr
        # Resample each alternative's cloud on its own (systematic, equal weights after).
        nx, ny, nt = (v.reshape(a, p) for v in (nx, ny, nt))
        for i in np.flatnonzero(alive):
            w = np.exp(log_w[i] - ev[i]) / p
            idx = systematic_resample(w / w.sum(), p, self.rng)
            nx[i], ny[i], nt[i] = nx[i, idx], ny[i, idx], nt[i, idx]
        if anchored:
            self._anchor = np.vstack([nx[0], ny[0], nt[0]]) if alive[0] else None
        keep = alive[first:]
        self.x, self.y, self.theta = nx[first:][keep], ny[first:][keep], nt[first:][keep]
        self.llr = self.llr[keep]
        self.age = self.age[keep]

    def _centres(self) -> tuple[NDArray[np.float64], ...]:
        c = np.cos(self.theta).mean(axis=1)
        s = np.sin(self.theta).mean(axis=1)
        return self.x.mean(axis=1), self.y.mean(axis=1), np.arctan2(s, c)

    def _near(
        self, x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64], h: Hypothesis
    ) -> NDArray[np.bool_]:
        st = self.settings
        return (np.hypot(x - h.x, y - h.y) < st.distinct_m) & (
            np.abs(wrap_angle(t - h.theta_rad)) < st.distinct_rad
        )

    def _forget_covered(self, main: Hypothesis) -> None:
        """Drop alternatives the main mode has come to cover (the filter holds them)."""
        if not self.count:
            return
        keep = ~self._near(*self._centres(), main)
        self.x, self.y, self.theta, self.llr, self.age = (
            self.x[keep], self.y[keep], self.theta[keep], self.llr[keep], self.age[keep]
        )  # fmt: skip

    # --------------------------------------------------------------- search
    def window_score(
        self, x: NDArray[np.float64], y: NDArray[np.float64], theta: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Sum of log-likelihoods over the history window, poses chained back, shape (N,)."""
        total = np.zeros(x.shape[0])
        stride = self.settings.window_stride
        frames = list(self._history)
        for k in range(len(frames) - 1, -1, -1):
            odo, obs = frames[k]
            if (len(frames) - 1 - k) % stride == 0:
                total += sensor_kernel.log_likelihood(
                    x, y, theta, obs, self.map, self.config, self.grid
                )
            if odo is None or k == 0:
                break
            x, y, theta = chain_back(x, y, theta, odo)
        return total

    def _refined(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        rounds: tuple[tuple[int, float, float], ...],
    ) -> tuple[NDArray[np.float64], ...]:
        """Each pose moved to the best of its jittered copies over the window."""
        score = self.window_score(x, y, t)
        m = x.shape[0]
        for count, std_m, std_rad in rounds:
            jx = x[:, None] + self.rng.normal(0.0, std_m, (m, count))
            jy = y[:, None] + self.rng.normal(0.0, std_m, (m, count))
            jt = wrap_angle(t[:, None] + self.rng.normal(0.0, std_rad, (m, count)))
            js = self.window_score(jx.reshape(-1), jy.reshape(-1), jt.reshape(-1)).reshape(m, count)
            js = np.where(self.map.free_space.is_free(jx, jy), js, -np.inf)
            best = np.argmax(js, axis=1)
            better = js[np.arange(m), best] > score
            rows = np.flatnonzero(better)
            x, y, t = x.copy(), y.copy(), t.copy()
            x[rows], y[rows], t[rows] = (
                jx[rows, best[rows]],
                jy[rows, best[rows]],
                jt[rows, best[rows]],
            )
            score = np.where(better, js[np.arange(m), best], score)
        return x, y, t, score

    def _search(self, main: Hypothesis) -> None:
        """One global consistency search (module docstring); may add alternatives."""
        st = self.settings
        self._since_search = 0
        self.searched_ago = 0
        self.searches += 1
        prior = st.seed_llr if self.mode_searches else 0.0
        self.mode_searches += 1
        obs = self._history[-1][1]
        mx, my, mt, ms = self._refined(
            np.array([main.x]), np.array([main.y]), np.array([main.theta_rad]), st.refine_fine
        )
        self._recentre(mx[0], my[0], mt[0])
        fs = self.map.free_space
        area = fs.free_cells.size * fs.resolution_m**2
        n = int(np.clip(st.candidates_per_m2 * area, st.min_candidates, st.max_candidates))
        cx, cy, ct = sample_from_observation(
            n, obs, self.map, self.rng, self.config.bearing_std_rad("")
        )
        away = ~self._near(cx, cy, ct, main)
        cx, cy, ct = cx[away], cy[away], ct[away]
        if not cx.size:
            return
        score = sensor_kernel.log_likelihood(cx, cy, ct, obs, self.map, self.config, self.grid)
        k = min(st.shortlist, cx.size)
        top = np.argpartition(-score, k - 1)[:k]
        rx, ry, rt, rs = self._refined(cx[top], cy[top], ct[top], st.refine)
        picked: list[int] = []
        for i in np.argsort(-rs):
            h = Hypothesis(float(rx[i]), float(ry[i]), float(rt[i]), 0.0)
            if not np.isfinite(rs[i]) or len(picked) >= st.finalists:
                break
            if picked and self._near(rx[picked], ry[picked], rt[picked], h).any():
                continue
            picked.append(int(i))
        if not picked:
            return
        rx, ry, rt, rs = self._refined(rx[picked], ry[picked], rt[picked], st.refine_fine)
        main_score = float(ms[0])
        order = np.argsort(-rs)
        ex, ey, et = self._centres() if self.count else (np.empty(0),) * 3
        for i in order:
            gain = float(rs[i] - main_score)
            if gain + prior < st.seed_llr or not np.isfinite(gain):
                break
            h = Hypothesis(float(rx[i]), float(ry[i]), float(rt[i]), 0.0)
            if self._near(np.array([mx[0]]), np.array([my[0]]), np.array([mt[0]]), h)[0]:
                continue
            if ex.size and self._near(ex, ey, et, h).any():
                continue
            # The best of thousands of candidates fits the window better than the main
            # mode by selection alone: a newcomer never starts ahead; tracked evidence
            # will show whether it is.
            self._add(h, min(gain, 0.0) + prior)
            ex, ey, et = self._centres()

    def _recentre(self, x: float, y: float, theta: float) -> None:
        """Move the anchor onto the main mode's refined pose, and every alternative onto
        its own (refined the same way), rigidly: a small cloud that started a little off
        recovers slowly by itself, and would lose evidence meanwhile for nothing."""
        if self._anchor is not None:
            self._anchor = np.vstack(_moved(*self._anchor, x, y, theta))
        if not self.count:
            return
        cx, cy, ct = self._centres()
        rx, ry, rt, _ = self._refined(cx, cy, ct, self.settings.refine_fine)
        for i in range(self.count):
            self.x[i], self.y[i], self.theta[i] = _moved(
                self.x[i], self.y[i], self.theta[i], rx[i], ry[i], rt[i]
            )

    def _add(self, h: Hypothesis, llr: float) -> None:
        st = self.settings
        p = st.particles
        if self._anchor is not None:
            # The anchor's cloud moved rigidly onto the candidate: both sides of the
            # ratio then start with the same spread (no Occam penalty for a newcomer).
            x, y, t = _moved(*self._anchor, h.x, h.y, h.theta_rad)
        else:
            x = h.x + self.rng.normal(0.0, st.seed_std_m, p)
            y = h.y + self.rng.normal(0.0, st.seed_std_m, p)
            t = wrap_angle(h.theta_rad + self.rng.normal(0.0, st.seed_std_rad, p))
        self._add_cloud(x, y, t, llr)

    def _add_cloud(
        self, x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64], llr: float
    ) -> None:
        """Append one alternative's cloud (dropping the weakest when full)."""
        st = self.settings
        if self.count >= st.max_alternatives:
            worst = int(np.argmin(self.llr))
            if self.llr[worst] >= llr:
                return
            keep = np.arange(self.count) != worst
            self.x, self.y, self.theta, self.llr, self.age = (
                self.x[keep], self.y[keep], self.theta[keep], self.llr[keep], self.age[keep]
            )  # fmt: skip
        self.x = np.vstack([self.x, x[None]])
        self.y = np.vstack([self.y, y[None]])
        self.theta = np.vstack([self.theta, t[None]])
        self.llr = np.append(self.llr, llr)
        self.age = np.append(self.age, 0)

    # ----------------------------------------------------------------- swap
    def swap(
        self,
        main_x: NDArray[np.float64],
        main_y: NDArray[np.float64],
        main_theta: NDArray[np.float64],
        main_w: NDArray[np.float64],
        n: int,
    ) -> tuple[NDArray[np.float64], ...]:
        """Replace the main belief by the strongest alternative; return its cloud (n).

        The old main belief (particles and normalized weights given) becomes an
        alternative with the opposite evidence; the others are re-expressed against
        the new main belief.
        """
        st = self.settings
        best = int(np.argmax(self.llr))
        shift = float(self.llr[best])
        pick = self.rng.integers(0, st.particles, n)
        jitter = 0.02
        nx = self.x[best, pick] + self.rng.normal(0.0, jitter, n)
        ny = self.y[best, pick] + self.rng.normal(0.0, jitter, n)
        nt = wrap_angle(self.theta[best, pick] + self.rng.normal(0.0, jitter, n))
        new_anchor = np.vstack([self.x[best], self.y[best], self.theta[best]])
        if self._anchor is not None:
            self.x[best], self.y[best], self.theta[best] = self._anchor
        else:
            idx = systematic_resample(main_w, st.particles, self.rng)
            self.x[best], self.y[best], self.theta[best] = main_x[idx], main_y[idx], main_theta[idx]
        self._anchor = new_anchor
        self._anchor_age = int(self.age[best])
        self.llr = self.llr - shift
        self.llr[best] = -shift
        self.swaps += 1
        self.mode_searches = 0
        return nx, ny, nt


def _moved(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
    to_x: float,
    to_y: float,
    to_theta: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A cloud turned about its centre and moved so its centre is the given pose."""
    mx, my = float(x.mean()), float(y.mean())
    turn = to_theta - float(np.arctan2(np.sin(t).mean(), np.cos(t).mean()))
    c, s = np.cos(turn), np.sin(turn)
    nx = to_x + c * (x - mx) - s * (y - my)
    ny = to_y + s * (x - mx) + c * (y - my)
    return nx, ny, wrap_angle(t + turn)


def main_mode(hypotheses: Sequence[Hypothesis]) -> Hypothesis | None:
    """The heaviest hypothesis of the filter's own clusters, if any."""
    return hypotheses[0] if hypotheses else None
