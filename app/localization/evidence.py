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

The module keeps the tracker; the places themselves (rigid motions, how two poses are
told apart, the settings) are :mod:`~app.localization.alternatives`', and the search
that finds them is :mod:`~app.localization.search`'s.

While the main belief does not explain the detections nothing is searched, weighed or
kept (converged could be neither gained nor held). The probability of the alternatives
under the whole belief, ``e^evidence / (1 + sum e^evidence)`` summed (the main belief's
prior counted equal to each alternative's), gates ``converged`` (see
:class:`~app.localization.convergence.ConvergenceGate`) and enters the protection radius.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.alternatives import (
    DEFAULT_EVIDENCE,
    EvidenceSettings,
    Trail,
    carry,
    log_mean_exp_rows,
    moves_onto,
    near,
    same_place,
)
from app.localization.compass import CompassReading, compass_log_likelihood
from app.localization.fastmath import hypot
from app.localization.models import MotionModel, SensorModel
from app.localization.resampling import systematic_resample
from app.localization.search import PlaceSearch, Separation, explaining
from app.localization.sensor import Observation, observation_columns
from app.localization.types import Hypothesis, InitialPose, Odometry
from app.maps.geometry import wrap_angle, wrap_rad
from app.state import from_columns, from_plain


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
        #: The global consistency search (:mod:`~app.localization.search`).
        self.finder = PlaceSearch(sensor, settings, rng)
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
        self._trail = Trail(self.settings.trail)
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
        #: The share of the distance walked since the prior was set that the odometry
        #: may be off by (0: the walk since is taken as exact), and that distance (m).
        self._prior_drift = 0.0
        self._prior_walked_m = 0.0

    def set_prior(
        self,
        prior: InitialPose | None,
        start: tuple[float, float, float] | None = None,
        drift: float = 0.0,
    ) -> None:
        """A known start: places it excludes are no alternatives (docs/API.md,
        ``initial_pose``). An alternative is a rigid motion of the main mode, so where
        it started is that motion applied to where the main mode started (``start``,
        the prior's own pose when not given): its prior odds against the main mode are
        the ratio of the start's prior densities there, and they enter its evidence
        when it is found. With ``drift``, the start's position std grows by that share
        of the distance walked since: the walk is no rigid motion when the odometry
        drifts, and a small turn of a long trail moves its start by metres."""
        self._prior, self._prior_drift, self._prior_walked_m = prior, drift, 0.0
        if prior is None:
            self._start = None
        else:
            self._start = start if start is not None else (prior.x, prior.y, prior.theta_rad)

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
        cx, cy, ct = carry(moves, sx, sy, st)

        var_xy = p.std_xy_m**2 + (self._prior_drift * self._prior_walked_m) ** 2

        def d2(x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64]) -> Any:
            turn = wrap_angle(t - p.theta_rad)
            return ((x - p.x) ** 2 + (y - p.y) ** 2) / var_xy + (turn / p.std_theta_rad) ** 2

        return -0.5 * (d2(cx[:, 0], cy[:, 0], ct[:, 0]) - d2(sx, sy, st))

    def _carry_start(self, move: NDArray[np.float64]) -> None:
        """The main mode became the place ``move`` (3,) carries it onto: so did its start."""
        if self._start is not None:
            cx, cy, ct = carry(move[None], *(np.array([v]) for v in self._start))
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
            "prior_drift": self._prior_drift,
            "prior_walked_m": self._prior_walked_m,
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
        # (and before a prior could drift, none did)
        self._prior_drift = float(state.get("prior_drift", 0.0))
        self._prior_walked_m = float(state.get("prior_walked_m", 0.0))

    def reobserve(self) -> None:
        """Make the window's observations again, as the sensor model would make them now
        (after :meth:`~app.localization.models.SensorModel.exclude`): the same as a
        checkpoint's round trip, so a restored tracker scores as this one does."""
        frames = self._history_from(self._history_columns())
        self._history.clear()
        self._history.extend(frames)

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
            observations = self.sensor.observations_from_columns(history["observations"])
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

    def probabilities(self, weights: NDArray[np.float64] | float = 1.0) -> NDArray[np.float64]:
        """Each alternative's probability under the whole belief, shape (A,); with
        ``weights`` (per alternative, or one for all), each evidence counted at that
        share of itself besides the temper."""
        if not self.count:
            return np.empty(0)
        # Tempered: a real detector's errors repeat from frame to frame (a box's bias, a
        # stale object), so a log-ratio summed over frames overstates the evidence
        # (FilterConfig.evidence_temper, FilterConfig.evidence_weight).
        ev = self.config.evidence_weight * weights * self.evidence
        top = max(0.0, float(ev.max()))
        e = np.exp(ev - top)
        return e / (np.exp(-top) + e.sum())

    @property
    def alternative_share(self) -> float:
        """Probability that the person is at one of the alternatives, not the main mode."""
        return float(self.probabilities().sum()) if self.count else 0.0

    @property
    def gain_share(self) -> float:
        """:attr:`alternative_share` with the evidence against each alternative tracked
        for ``rival_frames`` or more counted at ``rival_weight`` of itself: what gaining
        ``converged`` is held to (EvidenceSettings.rival_frames)."""
        if not self.count:
            return 0.0
        st = self.settings
        rival = np.where(self.age >= st.rival_frames, st.rival_weight, 1.0)
        return float(self.probabilities(rival).sum())

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
        return carry(self.moves, *self._anchor)

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

    def separation_m(self, x: float, y: float, theta: float, rings: bool = True) -> Separation:
        """The solution separation of the pose (x, y, theta) over the history window
        (:meth:`~app.localization.search.PlaceSearch.separation`): how far the place
        that best explains the window moves when one movable object (not
        :attr:`~app.maps.model.SemanticMap.fixed`) that explains a detection there
        (:func:`~app.localization.search.explaining`) is left out; ``rings``: seek
        its places from around the pose too (``Separation.far_m``)."""
        window = self.window()
        movable = self._movable_explaining((x, y, theta), window)
        left_out: list[int | tuple[int, ...]] = [int(k) for k in movable]
        # Furniture is rearranged a class at a time as often as a piece at a time (the
        # plants carried to the other wall): every movable object of one class together.
        cls = self.map.object_class[movable]
        for c in np.unique(cls):
            group = movable[cls == c]
            if group.size > 1:
                left_out.append(tuple(int(k) for k in group))
        return self.finder.separation((x, y, theta), window, left_out, rings)

    def places_without(
        self, x: float, y: float, theta: float
    ) -> tuple[tuple[float, float, float], list[tuple[int, tuple[float, float, float]]]]:
        """The place that best explains the history window, searched from the pose (x,
        y, theta), and for each movable object that explains a detection there (as in
        :meth:`separation_m`) the place it slides to without that object
        (:meth:`~app.localization.search.PlaceSearch.places_without`)."""
        window = self.window()
        movable = [int(k) for k in self._movable_explaining((x, y, theta), window)]
        full, slid = self.finder.places_without((x, y, theta), window, movable)
        return full, list(zip(movable, slid, strict=True))

    def _movable_explaining(
        self, pose: tuple[float, float, float], window: sensor_kernel.ObservationWindow
    ) -> NDArray[np.int64]:
        """The movable objects (not fixtures) that explain a detection of ``window``
        seen from ``pose`` (:func:`~app.localization.search.explaining`)."""
        seen = explaining(pose, window, self.map.object_xy.reshape(-1, 2))
        return seen[~self.map.fixed[seen]]

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
        gain_waits: bool = False,
        steps: int = 1,
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
            gain_waits: whether a gain of ``converged`` waits for a search (the gate
                gains only after one during its run of steady frames): searches then
                come every ``search_every`` frames, not at the lengthened interval.
            steps: frames ``odometry`` adds up (the motion noise's floors add up).
        """
        # Frames without detections are kept too: their odometry chains the window.
        self._history.append((odometry, obs, heading))
        if odometry is not None and self._prior is not None:
            self._prior_walked_m += hypot(odometry.forward_m, odometry.left_m)
        if self.searched_ago is not None:
            self.searched_ago += 1
        # Evidence counts while the main belief is one tight cluster that stayed put: in
        # between (a turn with little in view, a cluster that jumps) the anchor is drawn
        # from a cloud that does not know where it is, and so are the copies' ratios.
        steady = (
            main is not None
            and main_tight
            and self._last_main is not None
            and same_place(main.x, main.y, main.theta_rad, self._last_main, self.settings)
        )
        if self._anchor is not None:
            # While the main belief does not explain the detections, converged can be
            # neither gained nor held: the places are only carried along.
            self._track(odometry, obs, heading, steady, weigh=search_ok, steps=steps)
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
            and self._since_search
            >= (self.settings.search_every if gain_waits else self.search_interval)
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
        steps: int = 1,
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
        nx, ny, nt = self.motion.sample(
            x0, y0, t0, odometry, self.rng, out=poses[:, 0], steps=steps
        )
        if rows == 1:
            # Nothing to weigh (no alternative, or no evidence worth counting): the
            # anchor only has to follow the main mode (it is redrawn from the filter's
            # cluster when it drifts, and re-centred by every search), so the odometry
            # alone moves it, and the copies with it.
            self._anchor = poses[:, 0]
            return
        # The copies move with the same body-frame motion: a rigid motion of the map
        # commutes with it, so the carried cloud is the moved cloud carried. The starts
        # (x, y only: the penalty's) are carried the same way, by :func:`carry`'s
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
        ev = log_mean_exp_rows(log_w)
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
        fitted = moves_onto((float(mx[0]), float(my[0]), float(mt[0])), mx[1:], my[1:], mt[1:])
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
        cx, cy, ct = carry(self.moves, np.array([ax]), np.array([ay]), np.array([at]))
        return cx[:, 0], cy[:, 0], ct[:, 0]

    def _set_anchor(self, cloud: NDArray[np.float64]) -> None:
        """Replace the anchor, leaving every alternative's place where it was."""
        old = self._anchor
        places = self._centres() if old is not None and self.count else None
        self._anchor = cloud
        if places is not None:
            self.moves = moves_onto(self._anchor_pose(), *places)

    def _draw_anchor(self, main: Hypothesis, particles: tuple[NDArray[np.float64], ...]) -> bool:
        """Draw the anchor from the filter's particles of the main mode; False if none."""
        x, y, t, w = particles
        w = np.where(near(x, y, t, main, self.settings), w, 0.0)
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
        if same_place(main.x, main.y, main.theta_rad, anchor, st):
            close = (
                hypot(ax - main.x, ay - main.y) < st.distinct_m / 2
                and abs(wrap_rad(at - main.theta_rad)) < st.distinct_rad / 2
            )
            if not close:
                self._draw_anchor(main, particles)
            return
        hit = np.flatnonzero(near(*self._centres(), main, st)) if self.count else np.empty(0)
        if hit.size:
            self._make_main(int(hit[np.argmax(self.evidence[hit])]))
            return
        if self._draw_anchor(main, particles):
            # The old anchor's place, now an alternative, carried from the new anchor; with
            # a known start, at the odds the prior gives it against the new place.
            nx, ny, nt = self._anchor_pose()
            ahead = moves_onto((ax, ay, at), np.array([nx]), np.array([ny]), np.array([nt]))[0]
            odds = -float(self._prior_log_ratio(ahead[None])[0])
            self._carry_start(ahead)
            if fitted:
                back = moves_onto((nx, ny, nt), np.array([ax]), np.array([ay]), np.array([at]))
                self._append(back[0], odds)

    def _make_main(self, i: int) -> None:
        """Alternative ``i`` becomes the main mode; the old main an alternative."""
        self._carry_start(self.moves[i])
        ax, ay, at = self._anchor_pose()
        shift, seg_shift = float(self.llr[i]), float(self.seg[i])
        assert self._anchor is not None
        cx, cy, ct = carry(self.moves[i : i + 1], *self._anchor)
        places = self._centres()
        self._anchor = np.vstack([cx[0], cy[0], ct[0]])
        px, py, pt = (v.copy() for v in places)
        px[i], py[i], pt[i] = ax, ay, at
        self.moves = moves_onto(self._anchor_pose(), px, py, pt)
        self.llr = self.llr - shift
        self.llr[i] = -shift
        self.seg = self.seg - seg_shift
        self.seg[i] = -seg_shift
        self.age[i] = 0
        self.mode_searches = 0
        self._graves = np.empty((0, 3))

    def _near_any(self, h: Hypothesis) -> bool:
        """Whether ``h`` is a tracked alternative's place, or a dropped one's."""
        if self.count and near(*self._centres(), h, self.settings).any():
            return True
        if not self._graves.shape[0]:
            return False
        ax, ay, at = (np.array([v]) for v in self._anchor_pose())
        gx, gy, gt = carry(self._graves, ax, ay, at)
        return bool(near(gx[:, 0], gy[:, 0], gt[:, 0], h, self.settings).any())

    def _forget_covered(self, main: Hypothesis) -> None:
        """Drop alternatives the main mode has come to cover (the filter holds them)."""
        if self.count and self._anchor is not None:
            self._keep(~near(*self._centres(), main, self.settings))

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
        new_x, new_y, new_t = self.finder.finalists(obs, main, window)
        # One polish: the main mode, the tracked alternatives, the finalists.
        ax, ay, at = self._centres() if self.count else (np.empty(0),) * 3
        a = ax.size
        main_pose, main_score, (qx, qy, qt, qs) = self.finder.polish_with_main(
            main,
            self._anchor_pose(),
            np.concatenate([ax, new_x]),
            np.concatenate([ay, new_y]),
            np.concatenate([at, new_t]),
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
            if same_place(h.x, h.y, h.theta_rad, main_h, st):
                continue
            move = moves_onto(
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
        """Move a young alternative onto a search finalist at its place that explains
        the window better (its evidence kept): the global search starts from thousands
        of poses, the local polish from one, which a short early window may have put
        a metre or more off. Only a young one (``settings.young`` frames): the place of
        an alternative tracked longer is what its copies' evidence has followed, and on
        a window of a few frames with few detections a pose a metre off can fit best by
        chance (measured: the true place, tracked 18 s as an alternative between two
        identical offices, moved 1 m off that way, was refuted within 5 frames and the
        wrong office told 12 m off; integrity suite 19 -> 3 confidently-wrong frames)."""
        if not self.count or not x.size:
            return
        cx, cy, ct = (v.copy() for v in self._centres())
        current = self.window_score(cx, cy, ct, window)
        moved = False
        young = self.age < self.settings.young
        for i in np.argsort(-score):
            h = Hypothesis(float(x[i]), float(y[i]), float(t[i]), 0.0)
            same = np.flatnonzero(near(cx, cy, ct, h, self.settings))
            if same.size != 1 or not young[same[0]] or not score[i] > current[same[0]]:
                continue
            j = int(same[0])
            cx[j], cy[j], ct[j], current[j] = h.x, h.y, h.theta_rad, score[i]
            moved = True
        if moved:
            self.moves = moves_onto(self._anchor_pose(), cx, cy, ct)

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
        main_pose, _, (qx, qy, qt, _) = self.finder.polish_with_main(
            main, self._anchor_pose(), cx[young], cy[young], ct[young], window
        )
        cx[young], cy[young], ct[young] = qx, qy, qt
        self._recentre(main_pose, (cx, cy, ct))

    def _walk_fits(self, move: NDArray[np.float64]) -> bool:
        """Whether the main mode's walk so far, carried by ``move``, stays in the free
        space: a place is only an alternative if the whole walk could have led there
        (the odometry is the same for both; the window alone forgets the rest)."""
        if not self._trail:
            return True
        tx, ty = self._trail.points().T.copy()
        cx, cy, _ = carry(move[None], tx, ty, np.zeros_like(tx))
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
        move = moves_onto(self._anchor_pose(), np.array([x]), np.array([y]), np.array([theta]))
        cx, cy, ct = carry(move, *self._anchor)
        self._anchor = np.vstack([cx[0], cy[0], ct[0]])
        if self.count:
            self.moves = moves_onto(self._anchor_pose(), *places)
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
            same = near(cx, cy, ct, h, self.settings) & keep
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
    def strongest(self) -> tuple[float, float, int]:
        """The alternative a swap would take: its centre (x, y) and the frames it has
        been tracked."""
        best = int(np.argmax(self._agreed))
        cx, cy, _ = self._centres()
        return float(cx[best]), float(cy[best]), int(self.age[best])

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
