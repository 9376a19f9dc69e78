"""The evidence tracker's global consistency search: places the recent frames fit.

Candidate poses are drawn all over the free space, each pointing one detection of the
newest frame at an object of its class (as in sensor resetting), and scored on that
frame; the best are refined by random jitter over a window of recent frames chained
back by the odometry (:meth:`PlaceSearch.refined`), and the best distinct ones become
the finalists (:meth:`PlaceSearch.finalists`). The tracker (:mod:`~app.localization.evidence`)
then polishes them with a deterministic pattern search (:meth:`PlaceSearch.polished`),
together with the main mode and every alternative it keeps, and decides which become
alternatives. Both searches run compiled (the sensor model's); the numpy definitions they
are held to are :func:`pattern_search_reference` and :func:`jitter_search_reference`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from app.localization import sensor_kernel
from app.localization.alternatives import EvidenceSettings, near, near_pairs
from app.localization.config import FilterConfig
from app.localization.models import SensorModel
from app.localization.sensor import Observation
from app.localization.sensor_kernel import ObservationWindow
from app.localization.types import Hypothesis
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap
from app.maps.visibility import VisibilityGrid


class PlaceSearch:
    """The search of one evidence tracker: its sensor model, settings and generator."""

    def __init__(
        self, sensor: SensorModel, settings: EvidenceSettings, rng: np.random.Generator
    ) -> None:
        self.sensor = sensor
        self.settings = settings
        self.rng = rng
        self.map = sensor.semantic_map

    def finalists(
        self, obs: Observation, main: Hypothesis, window: ObservationWindow
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The search's distinct best places away from ``main``, best first: candidates
        all over the free space, each pointing one of ``obs``'s detections at an object
        of its class, scored on that frame; the ``shortlist`` best refined over
        ``window`` and, of those, up to ``finalists`` distinct places kept."""
        st = self.settings
        fs = self.map.free_space
        area = fs.free_cells.size * fs.resolution_m**2
        n = int(min(max(st.candidates_per_m2 * area, st.min_candidates), st.max_candidates))
        cx, cy, ct = self.sensor.sample_poses(n, obs, self.rng)
        away = ~near(cx, cy, ct, main, st)
        cx, cy, ct = cx[away], cy[away], ct[away]
        picked: list[int] = []
        rx = ry = rt = np.empty(0)
        if cx.size:
            score = self.sensor.log_likelihood(cx, cy, ct, obs)
            k = min(st.shortlist, cx.size)
            top = np.argpartition(-score, k - 1)[:k]
            rx, ry, rt, rs = self.refined(cx[top], cy[top], ct[top], st.refine, window)
            # The best distinct places, in plain Python over precomputed flags (a numpy
            # call on one element per candidate cost more than the comparisons).
            close = near_pairs(rx, ry, rt, st)
            finite = np.isfinite(rs).tolist()
            for i in np.argsort(-rs).tolist():
                if not finite[i] or len(picked) >= st.finalists:
                    break
                row = close[i]
                if any(row[j] for j in picked):
                    continue
                picked.append(i)
        return rx[picked], ry[picked], rt[picked]

    def refined(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        rounds: tuple[tuple[int, float, float], ...],
        window: ObservationWindow,
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

    def polished(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        window: ObservationWindow,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Pattern search over the window: each round tries the 27 steps of -1, 0, +1 in
        x, y and heading around each pose, moves to the best, and halves the steps.
        Every pose of a search and every round go through one compiled call."""
        st = self.settings
        return self.sensor.pattern_search(
            x, y, t, PATTERN, st.polish_step_m, st.polish_step_rad, st.polish_rounds, window
        )

    def polish_with_main(
        self,
        main: Hypothesis,
        anchor: tuple[float, float, float],
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        t: NDArray[np.float64],
        window: ObservationWindow,
    ) -> tuple[
        tuple[float, float, float],
        float,
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ]:
        """Polish the main mode and the places (x, y, t) together, in one call.

        The main mode is polished from two starts, the filter's cluster and ``anchor``
        (the anchor cloud's pose),
        and the better kept (a pattern search from one start can stop in a poorer local
        optimum). Returns the main mode's pose and window score, and the places' polished
        poses and scores.
        """
        ax, ay, at = anchor
        px, py, pt, ps = self.polished(
            np.concatenate([[main.x, ax], x]),
            np.concatenate([[main.y, ay], y]),
            np.concatenate([[main.theta_rad, at], t]),
            window,
        )
        b = int(np.argmax(ps[:2]))
        pose = (float(px[b]), float(py[b]), float(pt[b]))
        return pose, float(ps[b]), (px[2:], py[2:], pt[2:], ps[2:])

    def separation(
        self,
        pose: tuple[float, float, float],
        window: ObservationWindow,
        objects: Sequence[int | tuple[int, ...]],
        rings: bool = True,
    ) -> Separation:
        """How far the place that best explains ``window`` moves when one of ``objects``
        explains nothing, the most over them: solution separation, as GNSS integrity
        monitoring tests a fix against one faulty satellite (each satellite left out in
        turn), here against one object moved since the map was drawn. An entry of
        ``objects`` may be a tuple of objects left out together (``obj`` then names the
        first).

        The full place is a pattern search over the window from ``pose``. With an object
        left out, the place is sought twice: by a search from the full place (``near_m``:
        where the fix slides when the object goes), and as the best of that and of
        searches started on :data:`SEPARATION_RINGS_M` around it in free space
        (``far_m``: one search from the full place can stop in its own local optimum
        while a place a metre away explains the rest of the window better). Without
        ``rings``, ``far_m`` is ``near_m``."""
        if not objects:
            return Separation(0.0, 0.0, -1)
        pattern_search = self.sensor.pattern_search
        steps = _SEPARATION_STEPS
        bx, by, bt = self._full_place(pose, window)
        sx, sy = bx, by
        if rings:
            sx = np.concatenate([bx, bx[0] + _RING_DX])
            sy = np.concatenate([by, by[0] + _RING_DY])
            keep = self.map.free_space.is_free(sx, sy)
            keep[0] = True  # the full place's own search (the first) always runs
            sx, sy = sx[keep], sy[keep]
        st = np.full(sx.shape, bt[0])
        near_m, far_m, which = 0.0, 0.0, -1
        for obj in objects:
            qx, qy, _, qs = pattern_search(sx, sy, st, PATTERN, *steps, window.without(obj))
            moved = np.hypot(qx - bx[0], qy - by[0])
            best = int(np.argmax(qs))
            if moved[0] > near_m:
                near_m, which = float(moved[0]), int(obj if isinstance(obj, int) else obj[0])
            far_m = max(far_m, float(moved[best]))
        return Separation(near_m, far_m, which)

    def places_without(
        self,
        pose: tuple[float, float, float],
        window: ObservationWindow,
        objects: Sequence[int],
    ) -> tuple[tuple[float, float, float], list[tuple[float, float, float]]]:
        """The place that best explains ``window`` (a pattern search from ``pose``), and
        for each of ``objects`` the place it slides to when that object explains nothing
        (a search from the full place, as :meth:`separation`'s ``near_m``)."""
        bx, by, bt = self._full_place(pose, window)
        slid = []
        for obj in objects:
            qx, qy, qt, _ = self.sensor.pattern_search(
                bx, by, bt, PATTERN, *_SEPARATION_STEPS, window.without(obj)
            )
            slid.append((float(qx[0]), float(qy[0]), float(qt[0])))
        return (float(bx[0]), float(by[0]), float(bt[0])), slid

    def _full_place(
        self, pose: tuple[float, float, float], window: ObservationWindow
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The place that best explains ``window``, a pattern search from ``pose`` (the
        separation's steps), as one-element arrays."""
        x, y, t = (np.array([v]) for v in pose)
        bx, by, bt, _ = self.sensor.pattern_search(x, y, t, PATTERN, *_SEPARATION_STEPS, window)
        return bx, by, bt


class Separation(NamedTuple):
    """:meth:`PlaceSearch.separation`'s answer (metres; ``obj`` -1 when none)."""

    #: The most the fix slides, searched from the full place, when one object goes.
    near_m: float
    #: The most the best place found, from the rings too, lies from the full place.
    far_m: float
    #: The object whose absence slides the fix farthest (``near_m``).
    obj: int


def explaining(
    pose: tuple[float, float, float], window: ObservationWindow, object_xy: NDArray[np.float64]
) -> NDArray[np.int64]:
    """The objects that explain a detection of ``window`` seen from ``pose``: for each
    detection, the candidate of its class whose bearing is nearest, if within the
    class's crossover to clutter (where keeping the match is likelier than clutter;
    every match without a clutter floor). Visibility is not checked: an object out of
    sight explains nothing in the kernel, and leaving it out moves nothing."""
    x, y, t = pose
    cos_t, sin_t = np.cos(t), np.sin(t)
    # Per class, how far from its bearing (1 - cos of the error) a match still beats the
    # clutter floor: kappa (cos - 1) + log_keep = log_floor at the crossover.
    reach = (window.group_log_keep - window.group_log_floor) / window.group_kappa
    found: set[int] = set()
    for f in range(window.frames):
        a, b, c = window.rel[f]
        fx, fy, ft = x + cos_t * a - sin_t * b, y + sin_t * a + cos_t * b, t + c
        g0 = int(window.group_start[f])
        starts = window.member_start[int(window.start_of_frame[f]) :]
        for k in range(int(window.det_start[f]), int(window.det_start[f + 1])):
            g = int(window.det_group[k])
            cand = window.members[starts[g] : starts[g + 1]]
            if not cand.size:
                continue
            dx, dy = object_xy[cand, 0] - fx, object_xy[cand, 1] - fy
            bearing = np.arctan2(dy, dx) - ft
            cos_err = np.cos(bearing) * window.det_cos[k] + np.sin(bearing) * window.det_sin[k]
            best = int(np.argmax(cos_err))
            if 1.0 - cos_err[best] <= reach[g0 + g]:
                found.add(int(cand[best]))
    return np.array(sorted(found), dtype=np.int64)


#: The solution separation's pattern search (:meth:`PlaceSearch.separation`): first
#: steps of 0.5 m and 6 deg halved over 10 rounds reach about a metre from the start,
#: as far as one moved object was measured to drag a fix.
SEPARATION_STEP_M = 0.5
SEPARATION_STEP_RAD = float(np.radians(6.0))
SEPARATION_ROUNDS = 10
#: ... started also from rings of these radii (m) around the full place, eight starts
#: each (``Separation.far_m``): a moved object pulls a fix 1-1.5 m, and a search reaches
#: about a metre from where it starts (app.localization.filter.SEPARATION_RINGS_FOV_DEG).
SEPARATION_RINGS_M = (0.75, 1.5)
_RING_ANGLES = np.arange(8) * (np.pi / 4.0)
_RING_DX = np.concatenate([r * np.cos(_RING_ANGLES) for r in SEPARATION_RINGS_M])
_RING_DY = np.concatenate([r * np.sin(_RING_ANGLES) for r in SEPARATION_RINGS_M])
#: The separation's steps, as the pattern search takes them.
_SEPARATION_STEPS = (SEPARATION_STEP_M, SEPARATION_STEP_RAD, SEPARATION_ROUNDS)


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
    window: ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The pattern search of :meth:`PlaceSearch.polished` in numpy, the definition
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
    window: ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The jitter search of :meth:`PlaceSearch.refined` in numpy, the definition
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
_Scoring = tuple[ObservationWindow, SemanticMap, FilterConfig, VisibilityGrid | None]


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
