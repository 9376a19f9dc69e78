"""Confidence from evidence: alternative places kept alive, and their evidence counted.

A particle filter's weight share says nothing about a mode that resampling has already
killed: in a symmetric or repetitive building the mirror mode dies by chance, not by
evidence. So besides the filter's own cloud (the *main* belief), this module keeps a
small set of **alternative hypotheses**, each with the accumulated log-likelihood ratio
``llr`` of everything observed since it was found, against the main belief:

* **The anchor.** A cloud of ``particles`` poses drawn from the filter's heaviest
  cluster, tracked like a little filter (same motion model, same compiled sensor kernel,
  resampled every frame) and redrawn when it drifts off that cluster.
* **Alternatives are rigid motions of the anchor.** An alternative is the rigid motion
  (turn, shift) that carries the anchor onto another place. A rigid motion of the map
  commutes with body-frame odometry, so the carried cloud moves exactly as the anchor
  does; each frame its evidence is the log of the mean likelihood of the carried
  particles (moves through walls included), and ``llr`` gains the difference to the
  anchor's. Both sides of the ratio use the *same* particles: under an exact symmetry of
  the map the two are equal to rounding (independent small clouds drifted apart by units
  of evidence within seconds), and the cost is one kernel call over the anchor and its
  copies. Evidence counts while the main cluster is steady (tight and where it was);
  each copy's motion is re-fitted to its weighted mean every frame, and a young
  alternative's place is polished onto the recent frames every frame.
* **Counted twice.** ``seg`` counts the same ratio at every search on the frames since
  the last one, every place first polished onto the poses that explain the recent frames
  best: it cannot lose evidence to a copy a few decimetres off its place (at a turn the
  filter's cluster is corrected and the copies lag). :attr:`evidence` is the larger of
  the two: refuting a place takes both.
* **Found** by a periodic global consistency search (every ``search_every`` frames while
  the main mode is tight, once ``min_history`` frames are kept): candidate poses all
  over the free space with the heading that points one detection at an object of its
  class (as in sensor resetting), scored on the current frame; the best are refined and
  scored on the last ``window`` frames chained back by the odometry, then polished by a
  deterministic pattern search, as are the main mode and every tracked alternative (the
  motions are re-fitted, so a copy a few centimetres off does not lose evidence for
  nothing). A finalist away from the main mode whose window evidence is within
  ``seed_llr`` of the main mode's becomes an alternative, if the main mode's whole walk
  so far, carried onto it, stays in the free space (the odometry is the same for both: a
  shifted copy of a walk through a corridor's far end is no alternative). It starts at
  its window difference, never ahead (the best of thousands fits by selection), plus a
  prior: once the main mode has been searched against, a place earlier searches did not
  find was at most ``seed_llr`` as likely then. Places dropped earlier are remembered
  (as motions relative to the main mode) and not found again as newcomers.
* **Dropped** only when the evidence against falls below ``drop_llr`` (or every copy
  walks through a wall), or when the main belief has come to cover the place.
* **Swapped** with the main belief when both counts of the evidence for exceed
  ``switch_llr``: the filter's cloud is replaced by the alternative's, and the old main
  mode becomes an alternative carrying the opposite evidence. When the filter's heaviest
  cluster moves to another place by itself, the ratios are re-expressed against it (or
  the old place becomes an alternative at even odds), never silently re-referenced.

While the main belief does not explain the detections nothing is searched, weighed or
kept (converged could be neither gained nor held). The probability of the alternatives
under the whole belief, ``e^evidence / (1 + sum e^evidence)`` summed (the main belief's
prior counted equal to each alternative's), gates ``converged`` (see
:class:`~app.localization.convergence.ConvergenceGate`) and enters the protection radius.
"""

from __future__ import annotations

import math
from array import array
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.compass import CompassReading, compass_log_likelihood
from app.localization.config import FilterConfig
from app.localization.models import MotionModel, SensorModel
from app.localization.resampling import systematic_resample
from app.localization.sensor import Observation, observation_columns, observations_from_columns
from app.localization.types import Hypothesis, InitialPose, Odometry
from app.maps.geometry import wrap_angle, wrap_deg
from app.maps.model import SemanticMap
from app.maps.visibility import VisibilityGrid
from app.state import from_columns, from_plain


@dataclass(frozen=True)
class EvidenceSettings:
    """Rates, sizes and thresholds of the alternative-hypothesis bookkeeping."""

    #: Frames between global searches (1 s at 5 frames/s).
    search_every: int = 5
    #: With no alternative tracked, each search that finds none doubles the interval, up
    #: to this many frames (5 s): a converged walk through a building without look-alikes
    #: pays for a search every 5 s, not every second.
    max_search_every: int = 25
    #: Frames of history a search scores, chained back by the odometry.
    window: int = 10
    #: No search before this many frames: places fitted to a shorter history are often
    #: a metre off, and lose evidence for it before they are polished onto the spot.
    min_history: int = 6
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
    #: Pattern search that polishes a pose (the finalists, the main mode, every
    #: alternative): first steps (m, rad), halved this many times. Deterministic, so
    #: that the two sides of an exact symmetry land on exactly symmetric poses.
    polish_step_m: float = 0.25
    polish_step_rad: float = float(np.radians(4.0))
    polish_rounds: int = 8
    #: Particles of the anchor (each alternative carries a copy).
    particles: int = 150
    max_alternatives: int = 8
    #: Frames an alternative is tracked before it can take ``converged`` away.
    probation: int = 5
    #: Frames an alternative's place is polished every frame after it appears.
    young: int = 15
    #: A candidate within this log-evidence of the main mode over the window is kept.
    seed_llr: float = -6.0
    #: An alternative whose evidence against falls below this is dropped.
    drop_llr: float = -20.0
    #: An alternative this much more likely than the main belief replaces it.
    switch_llr: float = float(np.log(20.0))
    #: Frames of the main mode's walk kept to test a newcomer against (60 s).
    trail: int = 300
    #: Dropped alternatives remembered (while the main mode stays the same).
    max_graves: int = 32
    #: Distinct from the main mode (and from each other) beyond these.
    distinct_m: float = 1.0
    distinct_rad: float = float(np.radians(45.0))


DEFAULT_EVIDENCE = EvidenceSettings()


def _log_mean_exp_rows(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """log of the mean of exp over each row, shape (A,); -inf for an all -inf row."""
    m = a.max(axis=1)
    safe = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return safe + np.log(np.exp(a - safe[:, None]).mean(axis=1))


class _Trail:
    """The main mode's last ``size`` positions (x, y), oldest first, kept as flat doubles:
    a checkpoint (once a second) copies them as one buffer instead of walking 300
    pairs (43 us)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._xy = array("d")

    def append(self, x: float, y: float) -> None:
        xy = self._xy
        xy.append(x)
        xy.append(y)
        if len(xy) > 4 * self.size:  # drop the oldest now and then, not at every frame
            del xy[: len(xy) - 2 * self.size]

    def clear(self) -> None:
        del self._xy[:]

    def __len__(self) -> int:
        return min(len(self._xy) // 2, self.size)

    def points(self) -> NDArray[np.float64]:
        """The positions, shape (len, 2) (a copy)."""
        xy = self._xy
        kept = xy[-2 * self.size :] if len(xy) > 2 * self.size else xy
        return np.array(kept, dtype=np.float64).reshape(-1, 2)


class EvidenceTracker:
    """Alternative hypotheses of one filter, with their accumulated evidence."""

    def __init__(
        self,
        sensor: SensorModel,
        motion: MotionModel,
        rng: np.random.Generator,
        settings: EvidenceSettings = DEFAULT_EVIDENCE,
    ) -> None:
        #: The filter's own models (:mod:`~app.localization.models`): the anchor and the
        #: alternatives move and are weighed exactly as its particles are.
        self.sensor = sensor
        self.motion = motion
        self.map = sensor.semantic_map
        self.config = sensor.config
        self.grid = sensor.grid
        self.rng = rng
        self.settings = settings
        #: Whether a place (x, y) may hold an alternative at all (set by the filter on
        #: a map with levels, app.localization.floors); None: anywhere.
        self.place_allowed: Callable[[float, float], bool] | None = None
        self.reset()

    def reset(self) -> None:
        """Forget every alternative and the history (a new start)."""
        #: Per alternative, the rigid motion (turn, shift x, shift y) that carries the
        #: anchor onto it, shape (A, 3).
        self.moves = np.empty((0, 3))
        self.llr = np.empty(0)
        #: Per alternative, the same ratio counted the search's way (see ``evidence``).
        self.seg = np.empty(0)
        #: Frames each alternative has been tracked.
        self.age = np.empty(0, dtype=np.int64)
        #: Rigid motions of alternatives dropped by the evidence while the main mode
        #: stayed the same: found again, they are known dead, not newcomers.
        self._graves = np.empty((0, 3))
        #: The main mode's positions since it formed (the walk so far, as it believes).
        self._trail = _Trail(self.settings.trail)
        #: The anchor cloud of the main belief, rows x, y, theta; None until drawn.
        self._anchor = None
        self._history: deque[tuple[Odometry | None, Observation, CompassReading | None]] = deque(
            maxlen=self.settings.window
        )
        self._since_search = self.settings.search_every
        #: Searches in a row of this main mode that found nothing (the interval's doubling).
        self._quiet = 0
        #: Frames since the last global search (None before the first one).
        self.searched_ago: int | None = None
        self.searches = 0
        self.swaps = 0
        #: Searches run against the current main mode while it stayed tight.
        self.mode_searches = 0
        self._last_main: Hypothesis | None = None
        #: A known start (:meth:`set_prior`), and the main mode's pose at the start under
        #: it (carried along when another place becomes the main mode); None without one.
        self._prior: InitialPose | None = None
        self._start: tuple[float, float, float] | None = None

    def set_prior(self, prior: InitialPose | None) -> None:
        """A known start: places it excludes are no alternatives (docs/API.md,
        ``initial_pose``). An alternative is a rigid motion of the main mode, so where
        it started is that motion applied to where the main mode started: its prior
        odds against the main mode are the ratio of the start's prior densities there,
        and they enter its evidence when it is found."""
        self._prior = prior
        self._start = None if prior is None else (prior.x, prior.y, prior.theta_rad)

    @property
    def prior_confines(self) -> bool:
        """Whether the known start leaves no room for another place: its 3-std spread is
        within what counts as the same place (no search needed to rule others out)."""
        p = self._prior
        return (
            p is not None
            and 3.0 * p.std_xy_m < self.settings.distinct_m
            and 3.0 * p.std_theta_rad < self.settings.distinct_rad
        )

    def _prior_log_ratio(self, moves: NDArray[np.float64]) -> NDArray[np.float64]:
        """Log prior odds of the places ``moves`` (A, 3) carry the main mode onto, against
        the main mode: each start's squared Mahalanobis distance to the known start,
        halved, relative to the main mode's own. Zeros without a known start."""
        p, start = self._prior, self._start
        if p is None or start is None or not moves.shape[0]:
            return np.zeros(moves.shape[0])
        sx, sy, st = (np.array([v]) for v in start)
        cx, cy, ct = _carry(moves, sx, sy, st)

        def d2(x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64]) -> Any:
            turn = wrap_angle(t - p.theta_rad)
            return ((x - p.x) ** 2 + (y - p.y) ** 2) / p.std_xy_m**2 + (turn / p.std_theta_rad) ** 2

        return -0.5 * (d2(cx[:, 0], cy[:, 0], ct[:, 0]) - d2(sx, sy, st))

    def _carry_start(self, move: NDArray[np.float64]) -> None:
        """The main mode became the place ``move`` (3,) carries it onto: so did its start."""
        if self._start is not None:
            cx, cy, ct = _carry(move[None], *(np.array([v]) for v in self._start))
            self._start = (float(cx[0, 0]), float(cy[0, 0]), float(ct[0, 0]))

    # ---------------------------------------------------------- checkpoints
    def checkpoint(self) -> dict[str, Any]:
        """The anchor, the alternatives (motions, evidence, ages), the dropped ones, the
        main mode's trail and the recent frames (:meth:`_history_columns`), as plain
        data, arrays and frozen values; the random generator is the filter's."""
        return {
            "moves": self.moves,
            "llr": self.llr,
            "seg": self.seg,
            "age": self.age,
            "graves": self._graves,
            "trail": self._trail.points(),
            "anchor": self._anchor,
            "history": self._history_columns(),
            "since_search": self._since_search,
            "quiet": self._quiet,
            "searched_ago": self.searched_ago,
            "searches": self.searches,
            "swaps": self.swaps,
            "mode_searches": self.mode_searches,
            "last_main": self._last_main,
            "prior": self._prior,
            "start": self._start,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a :meth:`checkpoint` of a tracker with the same map and config."""
        self.moves = np.array(state["moves"], dtype=np.float64).reshape(-1, 3)
        self.llr = np.array(state["llr"], dtype=np.float64)
        self.seg = np.array(state.get("seg", state["llr"]), dtype=np.float64)
        self.age = np.array(state["age"], dtype=np.int64)
        self._graves = np.array(state["graves"], dtype=np.float64).reshape(-1, 3)
        self._trail.clear()
        for x, y in np.asarray(state["trail"], dtype=np.float64).reshape(-1, 2).tolist():
            self._trail.append(x, y)
        anchor = state["anchor"]
        self._anchor = None if anchor is None else np.array(anchor, dtype=np.float64)
        self._history.clear()
        self._history.extend(self._history_from(state["history"]))
        self._since_search = int(state["since_search"])
        self._quiet = int(state.get("quiet", 0))
        self.searched_ago = state["searched_ago"]
        self.searches = int(state["searches"])
        self.swaps = int(state["swaps"])
        self.mode_searches = int(state["mode_searches"])
        self._last_main = from_plain(Hypothesis | None, state["last_main"])
        # (checkpoints before known starts were priors hold neither)
        self._prior = from_plain(InitialPose | None, state.get("prior"))
        start = state.get("start")
        self._start = None if start is None else tuple(float(v) for v in start)  # type: ignore[assignment]

    def _history_columns(self) -> dict[str, Any]:
        """The window of recent frames as a few arrays: the odometry as rows (forward,
        left, turn; ``moved`` False where a frame had none), the observations as
        :func:`~app.localization.sensor.observation_columns`, the compass readings as
        they are (mostly None)."""
        history = self._history
        moved = np.array([odo is not None for odo, _, _ in history], dtype=bool)
        motion = np.array(
            [
                (0.0, 0.0, 0.0) if o is None else (o.forward_m, o.left_m, o.turn_rad)
                for o, _, _ in history
            ],
            dtype=np.float64,
        ).reshape(-1, 3)
        return {
            "motion": motion,
            "moved": moved,
            "observations": observation_columns([obs for _, obs, _ in history]),
            "compass": [compass for _, _, compass in history],
        }

    def _history_from(
        self, history: Any
    ) -> list[tuple[Odometry | None, Observation, CompassReading | None]]:
        """The window :meth:`_history_columns` wrote, or the forms of earlier checkpoint
        formats: 3 kept the odometry as records and every field of the observations
        (:func:`~app.state.to_columns`), 1 one (odometry, observation, compass) record
        a frame."""
        if isinstance(history, Mapping) and "motion" in history:  # format 4
            rows = np.asarray(history["motion"], dtype=np.float64).reshape(-1, 3).tolist()
            moved = np.asarray(history["moved"], dtype=bool).tolist()
            odometry = [Odometry(*row) if m else None for row, m in zip(rows, moved, strict=True)]
            observations = observations_from_columns(history["observations"], self.map, self.config)
            plain_compass = history["compass"]
        elif isinstance(history, Mapping):  # formats 2 and 3
            odometry = [from_plain(Odometry | None, odo) for odo in history["odometry"]]
            observations = from_columns(Observation, history["observations"])
            plain_compass = history["compass"]
        else:  # format 1
            records = zip(*history, strict=True) if history else ((), (), ())
            plain_odometry, plain_observations, plain_compass = records
            odometry = [from_plain(Odometry | None, odo) for odo in plain_odometry]
            observations = [from_plain(Observation, obs) for obs in plain_observations]
        compass = [from_plain(CompassReading | None, c) for c in plain_compass]
        return list(zip(odometry, observations, compass, strict=True))

    @property
    def _anchor(self) -> NDArray[np.float64] | None:
        """The anchor cloud, rows x, y, theta (its mean pose cached until it changes)."""
        return self._cloud

    @_anchor.setter
    def _anchor(self, cloud: NDArray[np.float64] | None) -> None:
        self._cloud = cloud
        self._pose: tuple[float, float, float] | None = None

    @property
    def search_interval(self) -> int:
        """Frames between searches now: ``search_every`` while alternatives are tracked,
        doubled by each search in a row that found none, up to ``max_search_every``."""
        st = self.settings
        if self.count:
            return st.search_every
        return min(st.max_search_every, st.search_every << min(self._quiet, 8))

    # ------------------------------------------------------------ read-outs
    @property
    def count(self) -> int:
        return int(self.llr.size)

    @property
    def evidence(self) -> NDArray[np.float64]:
        """Each alternative's log-ratio against the main belief, shape (A,): the larger of
        the two ways of counting it.

        ``llr`` is counted every frame on the anchor's carried copies: fine-grained, but
        a copy a little off its place loses evidence for nothing until it is re-fitted
        (at a turn that makes a sideways error visible, a copy can lose several units
        in a few frames). ``seg`` is counted at each search on the frames since the
        last one, with the main mode and every alternative first polished onto the
        poses that explain the recent frames best: no such loss, at a coarser pace. An
        alternative counts as refuted only when both agree, and the main belief is
        replaced only when both do.
        """
        return np.maximum(self.llr, self.seg)

    @property
    def _agreed(self) -> NDArray[np.float64]:
        """The evidence both counts agree on, shape (A,): what a swap takes."""
        return np.minimum(self.llr, self.seg)

    def probabilities(self) -> NDArray[np.float64]:
        """Each alternative's probability under the whole belief, shape (A,)."""
        if not self.count:
            return np.empty(0)
        # Tempered: a real detector's errors repeat from frame to frame (a box's bias, a
        # stale object), so a log-ratio summed over frames overstates the evidence
        # (FilterConfig.evidence_temper).
        ev = self.config.evidence_temper * self.evidence
        top = max(0.0, float(ev.max()))
        e = np.exp(ev - top)
        return e / (np.exp(-top) + e.sum())

    @property
    def alternative_share(self) -> float:
        """Probability that the person is at one of the alternatives, not the main mode."""
        return float(self.probabilities().sum()) if self.count else 0.0

    @property
    def confirmed_share(self) -> float:
        """:attr:`alternative_share` of the alternatives tracked for ``probation`` frames.

        The best of thousands of candidates fits a short window better than a typical
        look-alike would, by selection alone; one that then keeps its evidence for a
        second of tracking is a real competitor.
        """
        if not self.count:
            return 0.0  # (what the empty sum gives, without numpy's calls each frame)
        p = self.probabilities()
        return float(p[self.age >= self.settings.probation].sum())

    def clouds(self) -> tuple[NDArray[np.float64], ...]:
        """The alternatives' clouds (the anchor carried onto each), each shape (A, P)."""
        assert self._anchor is not None
        return _carry(self.moves, *self._anchor)

    def hypotheses(self) -> list[Hypothesis]:
        """One :class:`Hypothesis` per alternative, weight = its probability."""
        if not self.count or self._anchor is None:
            return []
        cx, cy, ct = self._centres()
        spread = float(np.hypot(self._anchor[0].std(), self._anchor[1].std()))
        return [
            Hypothesis(float(cx[i]), float(cy[i]), float(ct[i]), float(p), spread)
            for i, p in enumerate(self.probabilities())
        ]

    def farthest_m(self, x: float, y: float) -> float:
        """Distance from (x, y) that holds every alternative's particles."""
        if not self.count or self._anchor is None:
            return 0.0
        ax, ay, _ = self.clouds()
        return float(np.hypot(ax - x, ay - y).max())

    # ------------------------------------------------------------ one frame
    def update(
        self,
        odometry: Odometry | None,
        obs: Observation,
        main: Hypothesis | None,
        main_tight: bool,
        particles: tuple[NDArray[np.float64], ...],
        heading: CompassReading | None = None,
        search_ok: bool = True,
    ) -> bool:
        """Move and weigh the alternatives, search when due; True if a swap is due.

        Args:
            odometry: this frame's odometry (as given to the filter).
            obs: this frame's observation (may be empty: no evidence).
            main: the main belief's heaviest mode, None when it has none.
            main_tight: whether the main mode is tight enough to search against.
            particles: the filter's x, y, theta and normalized weights (to draw the
                anchor from).
            heading: this frame's compass reading, weighed like the filter does.
            search_ok: whether a global search may run now (the filter says no while
                its estimate does not explain the detections: converged could not be
                gained or held anyway, and the search would be wasted).
        """
        # Frames without detections are kept too: their odometry chains the window.
        self._history.append((odometry, obs, heading))
        if self.searched_ago is not None:
            self.searched_ago += 1
        # Evidence counts while the main belief is one tight cluster that stayed put: in
        # between (a turn with little in view, a cluster that jumps) the anchor is drawn
        # from a cloud that does not know where it is, and so are the copies' ratios.
        steady = (
            main is not None
            and main_tight
            and self._last_main is not None
            and _same_place(main.x, main.y, main.theta_rad, self._last_main, self.settings)
        )
        if self._anchor is not None:
            # While the main belief does not explain the detections, converged can be
            # neither gained nor held: the places are only carried along.
            self._track(odometry, obs, heading, steady, weigh=search_ok)
        if main is not None:
            self._follow_main(main, particles, search_ok)
            self._forget_covered(main)
        # The window is packed at most once a frame (the polish and the search share it).
        window = None
        if (
            main is not None
            and search_ok
            and self._anchor is not None
            and not obs.empty
            and self.count
            and (self.age < self.settings.young).any()
        ):
            window = self.window()
            self._refit_young(main, window)
        self._last_main = main
        if not steady or odometry is None:
            # A new main mode (or none): its searches, its dead and its walk start again.
            self.mode_searches = 0
            self._quiet = 0
            self._graves = np.empty((0, 3))
            self._trail.clear()
        if main is not None:
            self._trail.append(main.x, main.y)
        self._since_search += 1
        if (
            main is not None
            and main_tight
            and search_ok
            and self._anchor is not None
            and not obs.empty
            and self._since_search >= self.search_interval
            and len(self._history) >= self.settings.min_history
        ):
            if not self.count:
                # Moved by the odometry alone meanwhile (see _track): take the
                # filter's own cloud of the main mode again, tight and weighed.
                self._draw_anchor(main, particles)
            self._search(main, self.window() if window is None else window)
            self._quiet = 0 if self.count else self._quiet + 1
        return bool(self.count and self._agreed.max() >= self.settings.switch_llr)

    def _track(
        self,
        odometry: Odometry | None,
        obs: Observation,
        heading: CompassReading | None,
        count: bool = True,
        weigh: bool = True,
    ) -> None:
        """Move the anchor by the odometry; weigh it and its carried copies (their
        ratios gain this frame's evidence only if ``count``; nothing is weighed unless
        ``weigh``)."""
        assert self._anchor is not None
        x0, y0, t0 = self._anchor
        a, p = self.count, x0.size
        rows = a + 1 if a and weigh else 1
        # Row 0 the moved anchor, rows 1.. its copies: x, y, theta, each (rows, P).
        poses = np.empty((3, rows, p))
        nx, ny, nt = self.motion.sample(x0, y0, t0, odometry, self.rng, out=poses[:, 0])
        if rows == 1:
            # Nothing to weigh (no alternative, or no evidence worth counting): the
            # anchor only has to follow the main mode (it is redrawn from the filter's
            # cluster when it drifts, and re-centred by every search), so the odometry
            # alone moves it, and the copies with it.
            self._anchor = poses[:, 0]
            return
        # The copies move with the same body-frame motion: a rigid motion of the map
        # commutes with it, so the carried cloud is the moved cloud carried. The starts
        # (x, y only: the penalty's) are carried the same way, by :func:`_carry`'s
        # arithmetic written into the stacked rows.
        starts = np.empty((2, rows, p))
        starts[0, 0], starts[1, 0] = x0, y0
        turn, shift_x, shift_y = self.moves[:, 0:1], self.moves[:, 1:2], self.moves[:, 2:3]
        c, s = np.cos(turn), np.sin(turn)
        for x, y, (cx, cy) in ((x0, y0, starts), (nx, ny, poses[:2])):
            np.subtract(c * x, s * y, out=cx[1:])
            cx[1:] += shift_x
            np.add(s * x, c * y, out=cy[1:])
            cy[1:] += shift_y
        poses[2, 1:] = wrap_angle(nt + turn)
        fx, fy, ft = (v.reshape(-1) for v in poses)
        log_w, _ = self.motion.weigh_moves(
            starts[0].reshape(-1), starts[1].reshape(-1), fx, fy, np.zeros(fx.shape[0])
        )
        if not obs.empty:
            log_w += self.sensor.log_likelihood(fx, fy, ft, obs)
        if heading is not None:
            log_w += compass_log_likelihood(ft, heading)
        log_w = log_w.reshape(rows, p)
        ev = _log_mean_exp_rows(log_w)
        if not np.isfinite(ev[0]):
            self._anchor = None  # the anchor walked through a wall: draw it again
            return
        if count:
            self.llr = self.llr + (ev[1:] - ev[0])
        self.age = self.age + 1
        self._refit(log_w, *poses)
        keep = np.isfinite(ev[1:]) & (self.evidence >= self.settings.drop_llr)
        if not keep.all():
            graves = np.vstack([self._graves, self.moves[~keep]])
            self._graves = graves[-self.settings.max_graves :]
            self._keep(keep)
        w = np.exp(log_w[0] - log_w[0].max())
        idx = systematic_resample(w / w.sum(), p, self.rng)
        self._anchor = poses[:, 0].take(idx, axis=1)

    def _refit(
        self,
        log_w: NDArray[np.float64],
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
    ) -> None:
        """Re-fit each copy's rigid motion to what this frame says, shape (A + 1, P) each
        (row 0 the anchor).

        The motion becomes the one carrying the anchor's weighted mean pose onto the
        copy's: a copy placed a little off its place (the best pose of a short window
        rarely is exact) slides onto it as a filter's cloud would, instead of losing
        evidence for nothing until the next search. Under an exact symmetry the copy's
        weights are the anchor's carried, and the motion stays what it was.
        """
        top = log_w.max(axis=1, keepdims=True)
        ok = np.isfinite(top[:, 0])
        if not ok[0]:
            return
        fit: slice | NDArray[np.intp] = slice(None)  # the re-fitted copies' rows of moves
        if not ok.all():  # leave the copies with no weight out (else nothing is copied)
            rows = np.flatnonzero(ok)
            log_w, top, x, y, t = log_w[rows], top[rows], x[rows], y[rows], t[rows]
            fit = rows[1:] - 1
        w = np.exp(log_w - top)
        total = w.sum(axis=1)
        mx = (w * x).sum(axis=1) / total
        my = (w * y).sum(axis=1) / total
        mt = np.arctan2((w * np.sin(t)).sum(axis=1), (w * np.cos(t)).sum(axis=1))
        fitted = _moves_onto((float(mx[0]), float(my[0]), float(mt[0])), mx[1:], my[1:], mt[1:])
        self.moves[fit] = fitted

    def _keep(self, keep: NDArray[np.bool_]) -> None:
        self.moves, self.llr, self.age = self.moves[keep], self.llr[keep], self.age[keep]
        self.seg = self.seg[keep]

    def _anchor_pose(self) -> tuple[float, float, float]:
        if self._pose is None:
            assert self._anchor is not None
            # The means as ndarray.mean computes them (the same sums, divided by the
            # count), without its per-call overhead.
            x, y, t = self._anchor
            n, add = x.shape[0], np.add.reduce
            self._pose = (
                float(add(x)) / n,
                float(add(y)) / n,
                float(np.arctan2(float(add(np.sin(t))) / n, float(add(np.cos(t))) / n)),
            )
        return self._pose

    def _centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Each alternative's centre pose (x, y, theta), each shape (A,)."""
        ax, ay, at = self._anchor_pose()
        cx, cy, ct = _carry(self.moves, np.array([ax]), np.array([ay]), np.array([at]))
        return cx[:, 0], cy[:, 0], ct[:, 0]

    def _set_anchor(self, cloud: NDArray[np.float64]) -> None:
        """Replace the anchor, leaving every alternative's place where it was."""
        old = self._anchor
        places = self._centres() if old is not None and self.count else None
        self._anchor = cloud
        if places is not None:
            self.moves = _moves_onto(self._anchor_pose(), *places)

    def _draw_anchor(self, main: Hypothesis, particles: tuple[NDArray[np.float64], ...]) -> bool:
        """Draw the anchor from the filter's particles of the main mode; False if none."""
        x, y, t, w = particles
        w = np.where(_near(x, y, t, main, self.settings), w, 0.0)
        total = w.sum()
        if total <= 0.0:
            return False
        idx = systematic_resample(w / total, self.settings.particles, self.rng)
        self._set_anchor(np.vstack([x[idx], y[idx], t[idx]]))
        return True

    def _follow_main(
        self, main: Hypothesis, particles: tuple[NDArray[np.float64], ...], fitted: bool = True
    ) -> None:
        """Keep the anchor on the filter's heaviest cluster, and the ratios meaningful.

        The anchor is redrawn from the cluster when it has drifted from it (same place).
        When the filter's heaviest cluster moves to another place, the evidence is not
        re-referenced silently: if that place is an alternative, the two swap roles and
        every ratio is re-expressed against it; otherwise the old anchor's place becomes
        an alternative with even odds, and evidence decides between them from now on,
        if it explained the detections (``fitted``): a place that did not is no
        alternative worth tracking.
        """
        st = self.settings
        if self._anchor is None:
            self._draw_anchor(main, particles)
            return
        ax, ay, at = self._anchor_pose()
        anchor = Hypothesis(ax, ay, at, 0.0)
        if _same_place(main.x, main.y, main.theta_rad, anchor, st):
            close = (
                np.hypot(ax - main.x, ay - main.y) < st.distinct_m / 2
                and abs(_wrap(at - main.theta_rad)) < st.distinct_rad / 2
            )
            if not close:
                self._draw_anchor(main, particles)
            return
        hit = np.flatnonzero(_near(*self._centres(), main, st)) if self.count else np.empty(0)
        if hit.size:
            self._make_main(int(hit[np.argmax(self.evidence[hit])]))
            return
        if self._draw_anchor(main, particles):
            # The old anchor's place, now an alternative, carried from the new anchor; with
            # a known start, at the odds the prior gives it against the new place.
            nx, ny, nt = self._anchor_pose()
            ahead = _moves_onto((ax, ay, at), np.array([nx]), np.array([ny]), np.array([nt]))[0]
            odds = -float(self._prior_log_ratio(ahead[None])[0])
            self._carry_start(ahead)
            if fitted:
                back = _moves_onto((nx, ny, nt), np.array([ax]), np.array([ay]), np.array([at]))
                self._append(back[0], odds)

    def _make_main(self, i: int) -> None:
        """Alternative ``i`` becomes the main mode; the old main an alternative."""
        self._carry_start(self.moves[i])
        ax, ay, at = self._anchor_pose()
        shift, seg_shift = float(self.llr[i]), float(self.seg[i])
        assert self._anchor is not None
        cx, cy, ct = _carry(self.moves[i : i + 1], *self._anchor)
        places = self._centres()
        self._anchor = np.vstack([cx[0], cy[0], ct[0]])
        px, py, pt = (v.copy() for v in places)
        px[i], py[i], pt[i] = ax, ay, at
        self.moves = _moves_onto(self._anchor_pose(), px, py, pt)
        self.llr = self.llr - shift
        self.llr[i] = -shift
        self.seg = self.seg - seg_shift
        self.seg[i] = -seg_shift
        self.age[i] = 0
        self.mode_searches = 0
        self._graves = np.empty((0, 3))

    def _near_any(self, h: Hypothesis) -> bool:
        """Whether ``h`` is a tracked alternative's place, or a dropped one's."""
        if self.count and _near(*self._centres(), h, self.settings).any():
            return True
        if not self._graves.shape[0]:
            return False
        ax, ay, at = (np.array([v]) for v in self._anchor_pose())
        gx, gy, gt = _carry(self._graves, ax, ay, at)
        return bool(_near(gx[:, 0], gy[:, 0], gt[:, 0], h, self.settings).any())

    def _forget_covered(self, main: Hypothesis) -> None:
        """Drop alternatives the main mode has come to cover (the filter holds them)."""
        if self.count and self._anchor is not None:
            self._keep(~_near(*self._centres(), main, self.settings))

    # --------------------------------------------------------------- search
    def window(
        self, newest: int | None = None, stride: int | None = None
    ) -> sensor_kernel.ObservationWindow:
        """The history window's scored frames (every ``window_stride``-th, newest first,
        back to the last break in the odometry), each with its pose relative to the
        newest frame's (the odometry chained back, noise-free); or every ``stride``-th
        of the ``newest`` frames only."""
        frames = list(self._history)
        if newest is not None:
            frames = frames[-newest:]
        stride = self.settings.window_stride if stride is None else stride
        rel = (0.0, 0.0, 0.0)
        packed = []
        for k in range(len(frames) - 1, -1, -1):
            odo, obs, heading = frames[k]
            if (len(frames) - 1 - k) % stride == 0:
                packed.append((rel, obs, heading))
            if odo is None or k == 0:
                break
            # pose_{k-1} = pose_k ⊕ inverse(odo_k); rel_{k-1} = rel_k ⊕ inverse(odo_k).
            c, s = np.cos(odo.turn_rad), np.sin(odo.turn_rad)
            bf = -(c * odo.forward_m + s * odo.left_m)
            bl = -(-s * odo.forward_m + c * odo.left_m)
            a, b, t = rel
            ca, sa = np.cos(t), np.sin(t)
            rel = (a + ca * bf - sa * bl, b + sa * bf + ca * bl, t - odo.turn_rad)
        return sensor_kernel.pack_window(packed)

    def window_score(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        theta: NDArray[np.float64],
        window: sensor_kernel.ObservationWindow | None = None,
    ) -> NDArray[np.float64]:
        """Sum of log-likelihoods over the history window, poses chained back, shape (N,)."""
        w = self.window() if window is None else window
        return self.sensor.window_log_likelihood(x, y, theta, w)

    def _refined(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        rounds: tuple[tuple[int, float, float], ...],
        window: sensor_kernel.ObservationWindow,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Each pose moved to the best of its jittered copies over the window (``rounds``
        of random jitter), with its window score. The jitter is drawn first, round by
        round (x, y, heading), then every round runs in one compiled call."""
        m = x.shape[0]
        jitter = [
            (
                self.rng.normal(0.0, std_m, (m, count)),
                self.rng.normal(0.0, std_m, (m, count)),
                self.rng.normal(0.0, std_rad, (m, count)),
            )
            for count, std_m, std_rad in rounds
        ]
        return self.sensor.jitter_search(x, y, t, jitter, window)

    def _polished(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        window: sensor_kernel.ObservationWindow,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Pattern search over the window: each round tries the 27 steps of -1, 0, +1 in
        x, y and heading around each pose, moves to the best, and halves the steps.
        Every pose of a search and every round go through one compiled call."""
        st = self.settings
        return self.sensor.pattern_search(
            x, y, t, PATTERN, st.polish_step_m, st.polish_step_rad, st.polish_rounds, window
        )

    def _search(self, main: Hypothesis, window: sensor_kernel.ObservationWindow) -> None:
        """One global consistency search (module docstring) over ``window`` (this frame's
        :meth:`window`); may add alternatives. The main mode, every tracked alternative
        and the finalists are polished together."""
        st = self.settings
        # The frames since the last search of this mode (all of the history at its first),
        # packed below only if an alternative is tracked to be weighed on them.
        segment_frames = self._since_search if self.mode_searches else len(self._history)
        self._since_search = 0
        self.searched_ago = 0
        self.searches += 1
        prior = st.seed_llr if self.mode_searches else 0.0
        self.mode_searches += 1
        obs = self._history[-1][1]
        fs = self.map.free_space
        area = fs.free_cells.size * fs.resolution_m**2
        n = int(min(max(st.candidates_per_m2 * area, st.min_candidates), st.max_candidates))
        cx, cy, ct = self.sensor.sample_poses(n, obs, self.rng)
        away = ~_near(cx, cy, ct, main, st)
        cx, cy, ct = cx[away], cy[away], ct[away]
        picked: list[int] = []
        rx = ry = rt = np.empty(0)
        if cx.size:
            score = self.sensor.log_likelihood(cx, cy, ct, obs)
            k = min(st.shortlist, cx.size)
            top = np.argpartition(-score, k - 1)[:k]
            rx, ry, rt, rs = self._refined(cx[top], cy[top], ct[top], st.refine, window)
            # The best distinct places, in plain Python over precomputed flags (a numpy
            # call on one element per candidate cost more than the comparisons).
            close = _near_pairs(rx, ry, rt, st)
            finite = np.isfinite(rs).tolist()
            for i in np.argsort(-rs).tolist():
                if not finite[i] or len(picked) >= st.finalists:
                    break
                row = close[i]
                if any(row[j] for j in picked):
                    continue
                picked.append(i)
        # One polish: the main mode, the tracked alternatives, the finalists.
        ax, ay, at = self._centres() if self.count else (np.empty(0),) * 3
        a = ax.size
        main_pose, main_score, (qx, qy, qt, qs) = self._polish_with_main(
            main,
            np.concatenate([ax, rx[picked]]),
            np.concatenate([ay, ry[picked]]),
            np.concatenate([at, rt[picked]]),
            window,
        )
        mx, my, mt = main_pose
        if a:
            # Each place where the recent frames put it: the segment's evidence.
            on_segment = self.window_score(
                np.concatenate([[mx], qx[:a]]),
                np.concatenate([[my], qy[:a]]),
                np.concatenate([[mt], qt[:a]]),
                self.window(newest=segment_frames, stride=1),
            )
            self.seg = self.seg + (on_segment[1:] - on_segment[0])
        self._recentre(main_pose, (qx[:a], qy[:a], qt[:a]))
        main_h = Hypothesis(mx, my, mt, 0.0)
        fx, fy, ft, fsc = qx[a:], qy[a:], qt[a:], qs[a:]
        self._replace_places(fx, fy, ft, fsc, window)
        for i in np.argsort(-fsc):
            gain = float(fsc[i] - main_score)
            if gain + prior < st.seed_llr or not np.isfinite(gain):
                break
            h = Hypothesis(float(fx[i]), float(fy[i]), float(ft[i]), 0.0)
            if _same_place(h.x, h.y, h.theta_rad, main_h, st):
                continue
            move = _moves_onto(
                self._anchor_pose(), np.array([h.x]), np.array([h.y]), np.array([h.theta_rad])
            )[0]
            if self._near_any(h) or not self._walk_fits(move):
                continue
            if self.place_allowed is not None and not self.place_allowed(h.x, h.y):
                continue
            # A known start that makes the place unlikely by itself excludes it.
            odds = float(self._prior_log_ratio(move[None])[0])
            if odds < st.seed_llr:
                continue
            # The best of thousands of candidates fits the window better than the main
            # mode by selection alone: a newcomer never starts ahead; tracked evidence
            # will show whether it is.
            self._append(move, min(gain, 0.0) + prior + odds)

    def _replace_places(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        score: NDArray[np.float64],
        window: sensor_kernel.ObservationWindow,
    ) -> None:
        """Move a tracked alternative onto a search finalist at its place that explains
        the window better (its evidence kept): the global search starts from thousands
        of poses, the local polish from one, which a short early window may have put
        a metre or more off."""
        if not self.count or not x.size:
            return
        cx, cy, ct = (v.copy() for v in self._centres())
        current = self.window_score(cx, cy, ct, window)
        moved = False
        for i in np.argsort(-score):
            h = Hypothesis(float(x[i]), float(y[i]), float(t[i]), 0.0)
            near = np.flatnonzero(_near(cx, cy, ct, h, self.settings))
            if near.size != 1 or not score[i] > current[near[0]]:
                continue
            j = int(near[0])
            cx[j], cy[j], ct[j], current[j] = h.x, h.y, h.theta_rad, score[i]
            moved = True
        if moved:
            self.moves = _moves_onto(self._anchor_pose(), cx, cy, ct)

    def _refit_young(self, main: Hypothesis, window: sensor_kernel.ObservationWindow) -> None:
        """Polish every young alternative's place over the window, each frame.

        A place found by a search, or left behind by the main cluster, is often some
        decimetres off: a copy there loses evidence faster than the weighted-mean
        re-fit of :meth:`_refit` (which moves it within the anchor's spread) can bring
        it back. For its first ``young`` frames it is polished like the searches do,
        against the same recent frames as the main mode (whose place is polished
        alongside, so the two stay comparable): ``window``, this frame's :meth:`window`.
        """
        young = np.flatnonzero(self.age < self.settings.young)
        cx, cy, ct = (v.copy() for v in self._centres())
        main_pose, _, (qx, qy, qt, _) = self._polish_with_main(
            main, cx[young], cy[young], ct[young], window
        )
        cx[young], cy[young], ct[young] = qx, qy, qt
        self._recentre(main_pose, (cx, cy, ct))

    def _polish_with_main(
        self,
        main: Hypothesis,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        window: sensor_kernel.ObservationWindow,
    ) -> tuple[
        tuple[float, float, float],
        float,
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ]:
        """Polish the main mode and the places (x, y, t) together, in one call.

        The main mode is polished from two starts, the filter's cluster and the anchor,
        and the better kept (a pattern search from one start can stop in a poorer local
        optimum). Returns the main mode's pose and window score, and the places' polished
        poses and scores.
        """
        ax, ay, at = self._anchor_pose()
        px, py, pt, ps = self._polished(
            np.concatenate([[main.x, ax], x]),
            np.concatenate([[main.y, ay], y]),
            np.concatenate([[main.theta_rad, at], t]),
            window,
        )
        b = int(np.argmax(ps[:2]))
        pose = (float(px[b]), float(py[b]), float(pt[b]))
        return pose, float(ps[b]), (px[2:], py[2:], pt[2:], ps[2:])

    def _walk_fits(self, move: NDArray[np.float64]) -> bool:
        """Whether the main mode's walk so far, carried by ``move``, stays in the free
        space: a place is only an alternative if the whole walk could have led there
        (the odometry is the same for both; the window alone forgets the rest)."""
        if not self._trail:
            return True
        tx, ty = self._trail.points().T.copy()
        cx, cy, _ = _carry(move[None], tx, ty, np.zeros_like(tx))
        return bool(self.map.free_space.is_free(cx[0], cy[0]).all())

    def _recentre(
        self,
        main: tuple[float, float, float],
        places: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ) -> None:
        """Move the anchor onto the main mode's refined pose, and every alternative onto
        its own refined place: a little cloud off by a few centimetres would otherwise
        lose evidence for nothing until it had drifted back."""
        assert self._anchor is not None
        x, y, theta = main
        move = _moves_onto(self._anchor_pose(), np.array([x]), np.array([y]), np.array([theta]))
        cx, cy, ct = _carry(move, *self._anchor)
        self._anchor = np.vstack([cx[0], cy[0], ct[0]])
        if self.count:
            self.moves = _moves_onto(self._anchor_pose(), *places)
            self._merge_duplicates()

    def _merge_duplicates(self) -> None:
        """Of alternatives that refinement has brought onto one place, keep the one with
        the most evidence: two copies of one place would count it twice."""
        cx, cy, ct = self._centres()
        keep = np.ones(self.count, dtype=bool)
        for i in np.argsort(-self.evidence):
            if not keep[i]:
                continue
            h = Hypothesis(float(cx[i]), float(cy[i]), float(ct[i]), 0.0)
            same = _near(cx, cy, ct, h, self.settings) & keep
            same[i] = False
            keep &= ~same
        self._keep(keep)

    def _append(self, move: NDArray[np.float64], llr: float) -> None:
        """Add one alternative (dropping the weakest when full)."""
        st = self.settings
        if self.count >= st.max_alternatives:
            worst = int(np.argmin(self.evidence))
            if self.evidence[worst] >= llr:
                return
            self._keep(np.arange(self.count) != worst)
        self.moves = np.vstack([self.moves, move[None]])
        self.llr = np.append(self.llr, llr)
        self.seg = np.append(self.seg, llr)
        self.age = np.append(self.age, 0)

    # ----------------------------------------------------------------- swap
    def swap(self, n: int) -> tuple[NDArray[np.float64], ...]:
        """Make the strongest alternative the main belief; return its cloud (n particles).

        The old main belief becomes an alternative with the opposite evidence; the
        others are re-expressed against the new main belief.
        """
        best = int(np.argmax(self._agreed))
        self._make_main(best)
        self.swaps += 1
        assert self._anchor is not None
        pick = self.rng.integers(0, self._anchor.shape[1], n)
        jitter = 0.02
        nx = self._anchor[0, pick] + self.rng.normal(0.0, jitter, n)
        ny = self._anchor[1, pick] + self.rng.normal(0.0, jitter, n)
        nt = wrap_angle(self._anchor[2, pick] + self.rng.normal(0.0, jitter, n))
        return nx, ny, nt


#: The pattern search's 27 steps (x, y, heading; each -1, 0 or +1), shape (3, 27), in
#: the order of ``np.meshgrid``'s grid flattened: the search takes the first of equal
#: candidates, so the order is part of its result.
PATTERN = np.array(np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0])).reshape(3, -1)


def pattern_search_reference(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
    pattern: NDArray[np.float64],
    step_m: float,
    step_rad: float,
    rounds: int,
    window: sensor_kernel.ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The pattern search of :meth:`EvidenceTracker._polished` in numpy, the definition
    :func:`~app.localization.sensor_kernel.window_pattern_search` computes: each round
    scores every step of ``pattern`` (3, K) around every pose over the window, -inf
    outside the free space, moves each pose to its best step (the first of equals) if
    that beats its score, keeps the larger score, and halves the steps."""
    dx, dy, dt = pattern
    scoring = (window, semantic_map, config, grid)
    score = sensor_kernel.window_log_likelihood(x, y, t, window, semantic_map, config, grid)
    for _ in range(rounds):
        jx = x[:, None] + step_m * dx[None, :]
        jy = y[:, None] + step_m * dy[None, :]
        jt = wrap_angle(t[:, None] + step_rad * dt[None, :])
        x, y, t, score = _best_candidates(x, y, t, score, jx, jy, jt, True, scoring)
        step_m, step_rad = step_m / 2.0, step_rad / 2.0
    return x, y, t, score


def jitter_search_reference(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
    jitter: Sequence[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]],
    window: sensor_kernel.ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The jitter search of :meth:`EvidenceTracker._refined` in numpy, the definition
    :func:`~app.localization.sensor_kernel.window_jitter_search` computes: each round
    adds its offsets (x, y, heading; each (N, K)) to the poses, scores the copies over
    the window, -inf outside the free space, and moves each pose to its best copy (the
    first of equals) if that beats its score."""
    scoring = (window, semantic_map, config, grid)
    score = sensor_kernel.window_log_likelihood(x, y, t, window, semantic_map, config, grid)
    for ox, oy, ot in jitter:
        jx = x[:, None] + ox
        jy = y[:, None] + oy
        jt = wrap_angle(t[:, None] + ot)
        x, y, t, score = _best_candidates(x, y, t, score, jx, jy, jt, False, scoring)
    return x, y, t, score


#: What scores a pose over a window: the window, the map, the configuration, the grid.
_Scoring = tuple[sensor_kernel.ObservationWindow, SemanticMap, FilterConfig, VisibilityGrid | None]


def _best_candidates(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
    score: NDArray[np.float64],
    jx: NDArray[np.float64],
    jy: NDArray[np.float64],
    jt: NDArray[np.float64],
    keep_max: bool,
    scoring: _Scoring,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One round of the references above: each pose's candidates (row i of ``jx, jy,
    jt``, shape (N, K)) scored over the window, -inf outside the free space; the pose
    moves to its best (the first of equals) where that beats its score, which becomes
    the best's there (and everywhere the larger of the two with ``keep_max``)."""
    window, semantic_map, config, grid = scoring
    m, k = jx.shape
    rows = np.arange(m)
    js = sensor_kernel.window_log_likelihood(
        jx.reshape(-1), jy.reshape(-1), jt.reshape(-1), window, semantic_map, config, grid
    )
    js = np.where(semantic_map.free_space.is_free(jx, jy), js.reshape(m, k), -np.inf)
    best = np.argmax(js, axis=1)
    better = js[rows, best] > score
    x = np.where(better, jx[rows, best], x)
    y = np.where(better, jy[rows, best], y)
    t = np.where(better, jt[rows, best], t)
    top = js[rows, best]
    return x, y, t, (np.maximum(score, top) if keep_max else np.where(better, top, score))


def _same_place(x: float, y: float, t: float, h: Hypothesis, st: EvidenceSettings) -> bool:
    """:func:`_near` for one pose, in plain float arithmetic (it runs several times a
    frame, where numpy's overhead on scalars was most of its cost)."""
    turn = abs(wrap_deg(math.degrees(t - h.theta_rad)))
    return math.hypot(x - h.x, y - h.y) < st.distinct_m and math.radians(turn) < st.distinct_rad


def _wrap(angle: float) -> float:
    """:func:`~app.maps.geometry.wrap_angle` of one angle in plain float arithmetic (the
    same operations: Python's float ``%`` rounds as numpy's ``mod`` does, both C's
    ``fmod`` corrected to the divisor's sign), without numpy's overhead on a scalar."""
    wrapped = (angle + math.pi) % (2.0 * math.pi) - math.pi
    return math.pi if wrapped <= -math.pi else wrapped


def _near(
    x: NDArray[np.float64] | float,
    y: NDArray[np.float64] | float,
    t: NDArray[np.float64] | float,
    h: Hypothesis,
    st: EvidenceSettings,
) -> NDArray[np.bool_]:
    """Whether poses are the same place as ``h`` (within ``distinct_m`` and ``_rad``)."""
    return (np.hypot(np.asarray(x) - h.x, np.asarray(y) - h.y) < st.distinct_m) & (
        np.abs(wrap_angle(np.asarray(t) - h.theta_rad)) < st.distinct_rad
    )


def _near_pairs(
    x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64], st: EvidenceSettings
) -> NDArray[np.bool_]:
    """:func:`_near` of every pose against every pose, shape (N, N): row ``i`` is
    ``_near(x, y, t, pose i)``, with the same arithmetic (one call instead of one a
    pose)."""
    return (np.hypot(x[None, :] - x[:, None], y[None, :] - y[:, None]) < st.distinct_m) & (
        np.abs(wrap_angle(t[None, :] - t[:, None])) < st.distinct_rad
    )


def _carry(
    moves: NDArray[np.float64],
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Poses carried by each rigid motion (turn, shift x, shift y), each shape (A, N)."""
    turn, sx, sy = moves[:, 0:1], moves[:, 1:2], moves[:, 2:3]
    c, s = np.cos(turn), np.sin(turn)
    return c * x - s * y + sx, s * x + c * y + sy, wrap_angle(t + turn)


def _moves_onto(
    source: tuple[float, float, float],
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The rigid motions carrying the pose ``source`` onto each pose (x, y, t), (A, 3)."""
    sx, sy, st = source
    turn = wrap_angle(np.asarray(t) - st)
    c, s = np.cos(turn), np.sin(turn)
    return np.column_stack([turn, x - (c * sx - s * sy), y - (s * sx + c * sy)])


def main_mode(hypotheses: Sequence[Hypothesis]) -> Hypothesis | None:
    """The heaviest hypothesis of the filter's own clusters, if any."""
    return hypotheses[0] if hypotheses else None
