"""Compiled (numba) form of :func:`app.localization.sensor.log_likelihood_reference`.

Particles are taken in blocks of ``BLOCK`` so that everything a block touches stays
in the first-level cache. Per block: each particle's heading as a unit vector and its
visibility bits (one load per 64 objects) are read once; for each candidate object the
unit vector towards it in the particle's body frame is computed once (float32: the
bearing geometry needs no more) with an offset that pushes an invisible object out of
reach; every detection of the object's class keeps its best match (eq. 3, the cosine
of the bearing error is a dot product); then the class-weighted, score-tempered
log-likelihoods are summed (eq. 2). Inner loops run over particles and are branch-free
so that they vectorize. The result differs from the float64 reference by float32
rounding only, within the bound that
:func:`app.localization.tolerances.log_likelihood_tolerance` derives (a few 1e-3 in
log-likelihood where weights matter).

The evidence tracker scores poses over a window of recent frames
(:func:`window_log_likelihood`) and searches around them there: a pattern search
(:func:`window_pattern_search`) and a refinement among jittered copies
(:func:`window_jitter_search`). Each search runs whole, every round, in one compiled
call to :func:`_window_search`, with numpy's arithmetic to the bit: the searches'
numpy definitions are in :mod:`app.localization.evidence`. Compiled code is cached on
disk; :func:`app.localization.filter.warm_up` compiles it at start-up so no request
waits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.compass import CompassReading, compass_terms
from app.localization.config import FilterConfig
from app.localization.fastmath import FAST, grid_cell, sincos, softplus
from app.localization.sensor import SPREAD_MIN_NORM, SPREAD_MIN_R, Observation, object_spread_sq
from app.maps.geometry import wrap_scalar
from app.maps.model import SemanticMap
from app.maps.visibility import VisibilityGrid

#: Particles per block: the block's working set (unit vectors, best matches of up to
#: ~20 detections) stays within a 32 KB first-level cache.
BLOCK = 256
#: Best-match value meaning "no visible candidate"; anything below -1.5 reads so.
NO_MATCH = -2.0
#: Added to the match of an invisible object, so it can never beat NO_MATCH + 1.
HIDDEN = -4.0


@njit(cache=True, fastmath=FAST, nogil=True, error_model="numpy")
def _kernel(
    x, y, theta, use_vis, grid, vis_bits, cos_half_fov, check_fov, fov_cos, fov_sin, max_range_sq,
    obj_xy, obj_spread_sq, det_cos, det_sin, det_score, det_group,
    group_kappa, group_weight, group_log_floor, group_log_keep, member_start, members, out,
):  # fmt: skip  # pragma: no cover - compiled
    f32 = np.float32
    n = x.shape[0]
    k_total = det_cos.shape[0]
    # grid: origin x, origin y, 1 / resolution, rows, cols of the visibility grid.
    gx, gy, g_inv = grid[0], grid[1], grid[2]
    g_rows, g_cols = grid[3], grid[4]
    n_words = vis_bits.shape[1]
    check_range = max_range_sq < np.inf
    range_sq = f32(max_range_sq) if check_range else f32(0.0)
    half_fov = f32(cos_half_fov)
    # The field of view's centre direction in the body frame (cos, sin).
    fc = f32(fov_cos)
    fs = f32(fov_sin)
    xs = np.empty(BLOCK, dtype=f32)
    ys = np.empty(BLOCK, dtype=f32)
    ct = np.empty(BLOCK, dtype=f32)
    st = np.empty(BLOCK, dtype=f32)
    fx = np.empty(BLOCK, dtype=f32)
    fy = np.empty(BLOCK, dtype=f32)
    off = np.zeros(BLOCK, dtype=f32)
    # A movable object's match: its scale (fx, fy scaled in place) and its added part.
    spread_add = np.zeros(BLOCK, dtype=f32)
    cell = np.empty(BLOCK, dtype=np.int64)
    bits = np.empty((n_words, BLOCK), dtype=np.uint64)
    best = np.empty((k_total, BLOCK), dtype=f32)
    one = np.uint64(1)
    for start in range(0, n, BLOCK):
        m = min(BLOCK, n - start)
        # 1-D views only in the inner loops: the compiler vectorizes those.
        bx, by, bt = x[start : start + m], y[start : start + m], theta[start : start + m]
        o_out = out[start : start + m]
        for i in range(m):
            xs[i] = f32(bx[i])
            ys[i] = f32(by[i])
            s, c = sincos(bt[i])
            ct[i] = f32(c)
            st[i] = f32(s)
        if use_vis:
            for i in range(m):  # the particle's grid cell, clipped onto the grid
                cell[i] = int(grid_cell(bx[i], by[i], gx, gy, g_inv, g_rows, g_cols)[0])
            for w in range(n_words):
                b_bits = bits[w]
                for i in range(m):
                    b_bits[i] = vis_bits[cell[i], w]
        for k in range(k_total):
            row = best[k]
            for i in range(m):
                row[i] = f32(NO_MATCH)
        for g in range(group_kappa.shape[0]):
            for j in range(member_start[g], member_start[g + 1]):
                o = members[j]
                ox = f32(obj_xy[o, 0])
                oy = f32(obj_xy[o, 1])
                for i in range(m):
                    dx = ox - xs[i]
                    dy = oy - ys[i]
                    inv = f32(1.0) / np.sqrt(dx * dx + dy * dy + f32(1e-20))
                    fx[i] = (ct[i] * dx + st[i] * dy) * inv
                    fy[i] = (ct[i] * dy - st[i] * dx) * inv
                if use_vis:
                    b_bits = bits[o >> 6]
                    shift = np.uint64(o & 63)
                    for i in range(m):
                        off[i] = f32(HIDDEN) * f32(one - ((b_bits[i] >> shift) & one))
                    if check_fov:
                        for i in range(m):
                            inside = fx[i] * fc + fy[i] * fs >= half_fov
                            off[i] = off[i] if inside else f32(HIDDEN)
                    if check_range:
                        for i in range(m):
                            dx = ox - xs[i]
                            dy = oy - ys[i]
                            off[i] = off[i] if dx * dx + dy * dy <= range_sq else f32(HIDDEN)
                # An object whose drawn place is uncertain (std s): its match is the
                # cosine of a von Mises of concentration kappa * r, r = d^2 / (d^2 +
                # kappa s^2), taken back to the class's kappa with its normalisation:
                # 1 + r (cos - 1) + log(r) / (2 kappa) (sensor.spread_match).
                sq = obj_spread_sq[o]
                spread = sq > 0.0
                if spread:
                    ks = f32(group_kappa[g] * sq)
                    half_inv_k = f32(0.5 / group_kappa[g])
                    for i in range(m):
                        dx = ox - xs[i]
                        dy = oy - ys[i]
                        d2 = dx * dx + dy * dy
                        r = max(d2 / (d2 + ks), f32(SPREAD_MIN_R))
                        fx[i] = r * fx[i]
                        fy[i] = r * fy[i]
                        norm = max(half_inv_k * np.log(r), f32(SPREAD_MIN_NORM))
                        spread_add[i] = off[i] + (f32(1.0) - r) + norm
                for k in range(k_total):
                    if det_group[k] != g:
                        continue
                    ca = f32(det_cos[k])
                    sa = f32(det_sin[k])
                    row = best[k]
                    if spread:
                        for i in range(m):
                            row[i] = max(row[i], ca * fx[i] + sa * fy[i] + spread_add[i])
                    else:
                        for i in range(m):
                            row[i] = max(row[i], ca * fx[i] + sa * fy[i] + off[i])
        for i in range(m):
            o_out[i] = 0.0
        for k in range(k_total):
            g = det_group[k]
            kappa = group_kappa[g]
            log_keep = group_log_keep[g]
            log_floor = group_log_floor[g]
            scale = group_weight[g] * det_score[k]
            row = best[k]
            if log_floor == -np.inf:
                for i in range(m):
                    # No visible candidate: the likelihood is 0 (the paper's model).
                    lp = kappa * (row[i] - 1.0) + log_keep if row[i] > -1.5 else -np.inf
                    o_out[i] += scale * lp
            else:
                # log(floor + keep e^a) = log_floor + softplus(a + log_keep - log_floor).
                # "No candidate" gives a hugely negative z: only the clutter floor remains.
                shift_z = log_keep - log_floor
                for i in range(m):
                    z = kappa * (row[i] - 1.0) + shift_z
                    o_out[i] += scale * (log_floor + softplus(z))


#: The kernel's map, visibility and field-of-view arguments: use_vis, grid geometry,
#: visibility bits, cos(half FOV), check_fov, FOV centre (cos, sin), max range^2, objects,
#: and each object's squared position std (m^2; :func:`~app.localization.sensor.
#: object_spread_sq`).
SensorSetup = tuple[
    bool, NDArray[np.float64], NDArray[np.uint64], float, bool, float, float, float,
    NDArray[np.float64], NDArray[np.float64],
]  # fmt: skip


def _sensor_setup(
    semantic_map: SemanticMap, config: FilterConfig, grid: VisibilityGrid | None
) -> SensorSetup:
    """The kernel's map, visibility and field-of-view arguments (:data:`SensorSetup`):
    ``_kernel``'s 4th to 13th, ``use_vis`` to ``obj_spread_sq``, between the poses and
    the observation."""
    if config.visibility and grid is not None:
        vis_bits = grid.bits
        rows, cols = grid.shape
        geometry = np.array(
            [grid.origin_x, grid.origin_y, 1.0 / grid.resolution_m, rows, cols], dtype=np.float64
        )
    else:
        # No grid: field of view and range still apply (with visibility on), every
        # object is in line of sight from the one cell.
        words = max((semantic_map.object_count + 63) // 64, 1)
        vis_bits = np.full((1, words), ~np.uint64(0))
        geometry = np.array([0.0, 0.0, 1.0, 1.0, 1.0])
    check_fov = config.visibility and config.fov_deg < 360.0
    max_range = config.max_range_m if config.visibility else None
    max_range_sq = np.inf if max_range is None else max_range**2
    return (
        bool(config.visibility),
        geometry,
        vis_bits,
        float(np.cos(np.radians(config.fov_deg) / 2.0)),
        check_fov,
        float(np.cos(np.radians(config.fov_centre_deg))),
        float(np.sin(np.radians(config.fov_centre_deg))),
        float(max_range_sq),
        semantic_map.object_xy.reshape(-1, 2),
        object_spread_sq(semantic_map, config),
    )


def log_likelihood(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> NDArray[np.float64]:
    """Per-particle log P(Z | s, M), same numbers as the reference, shape (N,).

    Args:
        x, y, theta: particle poses, shape (N,), metres and radians.
        grid: the map's visibility grid (used when ``config.visibility`` is on).
    """
    return likelihood_with(_sensor_setup(semantic_map, config, grid), x, y, theta, obs)


def likelihood_with(
    setup: SensorSetup,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    obs: Observation,
) -> NDArray[np.float64]:
    """:func:`log_likelihood` with the map's part of the kernel's arguments made once
    (:func:`_sensor_setup`; a sensor model keeps it, app.localization.models)."""
    n = x.shape[0]
    out = np.zeros(n, dtype=np.float64)
    if obs.empty:
        return out
    _kernel(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        *setup,
        obs.det_cos,
        obs.det_sin,
        obs.det_score,
        obs.det_group,
        obs.group_kappa,
        obs.group_weight,
        obs.group_log_floor,
        obs.group_log_keep,
        obs.member_start,
        obs.members,
        out,
    )
    return out


# ------------------------------------------------------------------ windows
#: An :class:`ObservationWindow`'s arrays as one tuple (:attr:`ObservationWindow.arrays`).
WindowArrays = tuple[
    NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
    NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
    NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
]  # fmt: skip


@dataclass(frozen=True)
class ObservationWindow:
    """Several frames' observations, each seen from a pose fixed relative to the one
    scored (the odometry chained back), packed as flat arrays for one compiled call.

    Frame ``f`` was seen from ``pose ⊕ rel[f]``: ``rel`` holds (forward m, left m, turn
    rad) in the scored pose's body frame. Its detections are rows
    ``det_start[f]:det_start[f+1]`` of the ``det_*`` arrays (``det_group`` local to the
    frame), its classes rows ``group_start[f]:group_start[f+1]`` of the ``group_*``
    arrays, and their member slices start at ``member_start[start_of_frame[f] + g]``
    (offsets into the joined ``members``). ``compass`` rows are (heading, kappa,
    log_keep, log_floor) of :func:`~app.localization.compass.compass_terms`, heading NaN
    without a reading.
    """

    rel: NDArray[np.float64]
    det_start: NDArray[np.int64]
    group_start: NDArray[np.int64]
    start_of_frame: NDArray[np.int64]
    det_cos: NDArray[np.float64]
    det_sin: NDArray[np.float64]
    det_score: NDArray[np.float64]
    det_group: NDArray[np.int64]
    group_kappa: NDArray[np.float64]
    group_weight: NDArray[np.float64]
    group_log_floor: NDArray[np.float64]
    group_log_keep: NDArray[np.float64]
    member_start: NDArray[np.int64]
    members: NDArray[np.int64]
    compass: NDArray[np.float64]

    @property
    def frames(self) -> int:
        return int(self.rel.shape[0])

    def without(self, obj: int | Sequence[int]) -> ObservationWindow:
        """The same frames with the map's object ``obj`` (or each of several) explaining
        no detection (taken out of every class's candidates)."""
        drop = np.isin(self.members, obj)
        before = np.concatenate([[0], np.cumsum(drop)])
        return replace(
            self,
            members=self.members[~drop],
            member_start=self.member_start - before[self.member_start],
        )

    @property
    def arrays(self) -> WindowArrays:
        """The arrays in the order the compiled searches unpack them."""
        return (
            self.rel, self.det_start, self.group_start, self.start_of_frame, self.compass,
            self.det_cos, self.det_sin, self.det_score, self.det_group,
            self.group_kappa, self.group_weight, self.group_log_floor, self.group_log_keep,
            self.member_start, self.members,
        )  # fmt: skip


def pack_window(
    frames: Sequence[tuple[tuple[float, float, float], Observation, CompassReading | None]],
) -> ObservationWindow:
    """Join ``(rel, observation, compass)`` frames into one :class:`ObservationWindow`."""
    det_start, group_start, start_of_frame = [0], [0], []
    member_start: list[NDArray[np.int64]] = []
    members: list[NDArray[np.int64]] = []
    n_members = 0
    n_starts = 0
    compass = np.full((len(frames), 4), np.nan)
    for f, (_, obs, heading) in enumerate(frames):
        det_start.append(det_start[-1] + obs.det_cos.size)
        group_start.append(group_start[-1] + obs.group_kappa.size)
        start_of_frame.append(n_starts)
        starts = obs.member_start if obs.member_start.size else np.zeros(1, dtype=np.int64)
        member_start.append(starts.astype(np.int64) + n_members)
        n_starts += starts.size
        members.append(obs.members.astype(np.int64))
        n_members += obs.members.size
        if heading is not None:
            compass[f] = compass_terms(heading)

    def joined(name: str, dtype: type) -> NDArray[Any]:
        parts: list[NDArray[Any]] = [
            np.asarray(getattr(obs, name), dtype=dtype) for _, obs, _ in frames
        ]
        return np.concatenate(parts) if parts else np.empty(0, dtype=dtype)

    return ObservationWindow(
        rel=np.array([r for r, _, _ in frames], dtype=np.float64).reshape(-1, 3),
        det_start=np.array(det_start, dtype=np.int64),
        group_start=np.array(group_start, dtype=np.int64),
        start_of_frame=np.array(start_of_frame, dtype=np.int64),
        det_cos=joined("det_cos", np.float64),
        det_sin=joined("det_sin", np.float64),
        det_score=joined("det_score", np.float64),
        det_group=joined("det_group", np.int64),
        group_kappa=joined("group_kappa", np.float64),
        group_weight=joined("group_weight", np.float64),
        group_log_floor=joined("group_log_floor", np.float64),
        group_log_keep=joined("group_log_keep", np.float64),
        member_start=np.concatenate(member_start) if member_start else np.zeros(1, np.int64),
        members=np.concatenate(members) if members else np.empty(0, dtype=np.int64),
        compass=compass,
    )


@njit(cache=True, fastmath=FAST, nogil=True, error_model="numpy")
def _window_kernel(
    x, y, theta, rel, det_start, group_start, start_of_frame, compass,
    use_vis, grid, vis_bits, cos_half_fov, check_fov, fov_cos, fov_sin, max_range_sq, obj_xy,
    obj_spread_sq, det_cos, det_sin, det_score, det_group,
    group_kappa, group_weight, group_log_floor, group_log_keep, member_start, members, out,
):  # fmt: skip  # pragma: no cover - compiled
    n = x.shape[0]
    xs = np.empty(n)
    ys = np.empty(n)
    ts = np.empty(n)
    one = np.empty(n)
    for i in range(n):
        out[i] = 0.0
    for f in range(rel.shape[0]):
        a, b, c = rel[f, 0], rel[f, 1], rel[f, 2]
        for i in range(n):
            s, co = sincos(theta[i])
            xs[i] = x[i] + co * a - s * b
            ys[i] = y[i] + s * a + co * b
            ts[i] = theta[i] + c
        d0, d1 = det_start[f], det_start[f + 1]
        if d1 > d0:
            g0, g1 = group_start[f], group_start[f + 1]
            m0 = start_of_frame[f]
            _kernel(
                xs, ys, ts, use_vis, grid, vis_bits, cos_half_fov, check_fov, fov_cos, fov_sin,
                max_range_sq, obj_xy, obj_spread_sq, det_cos[d0:d1], det_sin[d0:d1],
                det_score[d0:d1],
                det_group[d0:d1], group_kappa[g0:g1], group_weight[g0:g1],
                group_log_floor[g0:g1], group_log_keep[g0:g1],
                member_start[m0 : m0 + (g1 - g0) + 1], members, one,
            )  # fmt: skip
            for i in range(n):
                out[i] += one[i]
        heading = compass[f, 0]
        if heading == heading:  # a reading (not NaN): the mixture of compass.py
            kappa, log_keep, log_floor = compass[f, 1], compass[f, 2], compass[f, 3]
            for i in range(n):
                vm = kappa * (np.cos(heading - ts[i]) - 1.0) + log_keep
                hi = max(vm, log_floor)
                out[i] += hi + np.log1p(np.exp(-abs(vm - log_floor)))


# ----------------------------------------------------------- local searches
@njit(cache=True, nogil=True, inline="always")
def _score(x, y, theta, window, setup, out):  # fmt: skip  # pragma: no cover - compiled
    """:func:`_window_kernel` with the window's arrays and the sensor setup as tuples
    (:attr:`ObservationWindow.arrays`, :func:`_sensor_setup`)."""
    rel, det_start, group_start, start_of_frame, compass = window[:5]
    det_cos, det_sin, det_score, det_group = window[5:9]
    group_kappa, group_weight, group_log_floor, group_log_keep = window[9:13]
    member_start, members = window[13], window[14]
    use_vis, grid, vis_bits, cos_half_fov, check_fov, fov_cos, fov_sin = setup[:7]
    max_range_sq, obj_xy, obj_spread_sq = setup[7], setup[8], setup[9]
    _window_kernel(
        x, y, theta, rel, det_start, group_start, start_of_frame, compass,
        use_vis, grid, vis_bits, cos_half_fov, check_fov, fov_cos, fov_sin, max_range_sq, obj_xy,
        obj_spread_sq, det_cos, det_sin, det_score, det_group,
        group_kappa, group_weight, group_log_floor, group_log_keep, member_start, members, out,
    )  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _move_to_best(
    x, y, theta, score, cx, cy, ct, keep_max, free, free_grid, window, setup, js,
):  # fmt: skip  # pragma: no cover - compiled
    """One round of a local search, in place: score the candidates ``cx, cy, ct`` (the
    same number for each pose, pose after pose) over the window, -inf outside the free
    space, and move each pose to its best candidate (the first of equals, or the first
    NaN, as ``np.argmax`` picks) if that beats the pose's score. The score becomes the
    best candidate's where it won, and with ``keep_max`` also where that is NaN (what
    ``np.maximum`` gives)."""
    if not cx.shape[0]:
        return  # no candidates (a round of no copies): every pose stays
    _score(cx, cy, ct, window, setup, js)
    ox, oy, inv_res, rows, cols = free_grid
    for i in range(cx.shape[0]):
        cell, inside = grid_cell(cx[i], cy[i], ox, oy, inv_res, rows, cols)
        if not (inside and free[int(cell)]):
            js[i] = -np.inf
    m = x.shape[0]
    k = cx.shape[0] // m
    for p in range(m):
        b = p * k
        for j in range(p * k + 1, p * k + k):
            if js[b] != js[b]:
                break
            if js[j] > js[b] or js[j] != js[j]:
                b = j
        best = js[b]
        better = best > score[p]
        if better:
            x[p], y[p], theta[p] = cx[b], cy[b], ct[b]
        if better or (keep_max and best != best):
            score[p] = best


@njit(cache=True, nogil=True, error_model="numpy")
def _window_search(
    x, y, theta, counts, jitter, pattern, step_m, step_rad, rounds, free, free_grid, window,
    setup, score,
):  # fmt: skip  # pragma: no cover - compiled
    """Window scores of the poses (x, y, theta moved in place, ``score`` written), then
    the jitter rounds (``counts`` copies per pose each, offsets in the columns of
    ``jitter``, shape (3, N * sum(counts))), then ``rounds`` rounds of the steps
    ``pattern`` (3, K) scaled by ``step_m``, ``step_rad``, halved each round.

    ``free`` is the free-space mask flattened, ``free_grid`` its grid; ``window`` and
    ``setup`` are :attr:`ObservationWindow.arrays` and :func:`_sensor_setup`'s tuple.
    Not fast-math: the candidates' sums and the wrap round as numpy's do (the scoring
    inside, :func:`_window_kernel`, keeps its own liberties and so its own numbers).
    """
    m = x.shape[0]
    _score(x, y, theta, window, setup, score)
    # Jitter rounds: round r adds columns start:start + m * counts[r] of ``jitter``.
    start = 0
    for r in range(counts.shape[0]):
        n = m * counts[r]
        cx, cy, ct, js = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        for i in range(n):
            p = i // counts[r]
            cx[i] = x[p] + jitter[0, start + i]
            cy[i] = y[p] + jitter[1, start + i]
            ct[i] = wrap_scalar(theta[p] + jitter[2, start + i])
        _move_to_best(x, y, theta, score, cx, cy, ct, False, free, free_grid, window, setup, js)
        start += n
    # Pattern rounds: every step of ``pattern`` around every pose, the steps halved.
    k = pattern.shape[1]
    cx, cy, ct, js = np.empty(m * k), np.empty(m * k), np.empty(m * k), np.empty(m * k)
    for _ in range(rounds):
        for p in range(m):
            for j in range(k):
                i = p * k + j
                cx[i] = x[p] + step_m * pattern[0, j]
                cy[i] = y[p] + step_m * pattern[1, j]
                ct[i] = wrap_scalar(theta[p] + step_rad * pattern[2, j])
        _move_to_best(x, y, theta, score, cx, cy, ct, True, free, free_grid, window, setup, js)
        step_m, step_rad = step_m / 2.0, step_rad / 2.0


#: The free space's arguments of the search kernels (:func:`_free_space_setup`).
FreeSetup = tuple[NDArray[np.bool_], tuple[float, float, float, float, float]]


def _free_space_setup(semantic_map: SemanticMap) -> FreeSetup:
    """The free-space mask flattened row-major, and its grid (origin x, origin y,
    1 / resolution, rows, cols) as floats, one compiled signature for every map: the
    numbers :meth:`~app.maps.freespace.FreeSpaceGrid.is_free` gives
    :func:`~app.maps.geometry.grid_cell` (which compares and multiplies the counts as
    floats anyway), so both put every point into the same cell."""
    fs = semantic_map.free_space
    rows, cols = fs.mask.shape
    grid = (float(fs.origin_x), float(fs.origin_y), 1.0 / fs.resolution_m, float(rows), float(cols))
    return fs.mask.reshape(-1), grid


#: No jitter rounds, or no pattern steps.
_NO_COUNTS = np.empty(0, dtype=np.int64)
_NO_STEPS = np.empty((3, 0))


def _searched(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    counts: NDArray[np.int64],
    jitter: NDArray[np.float64],
    pattern: NDArray[np.float64],
    step_m: float,
    step_rad: float,
    rounds: int,
    window: ObservationWindow,
    free: FreeSetup,
    setup: SensorSetup,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One call of :func:`_window_search` on copies of the poses: (x, y, theta, score);
    ``free`` and ``setup`` from :func:`_free_space_setup` and :func:`_sensor_setup`."""
    x, y, theta = (np.array(v, dtype=np.float64) for v in (x, y, theta))
    score = np.empty(x.shape[0])
    _window_search(
        x, y, theta, counts, jitter, np.ascontiguousarray(pattern, dtype=np.float64),
        float(step_m), float(step_rad), int(rounds), *free, window.arrays, setup, score,
    )  # fmt: skip
    return x, y, theta, score


def window_log_likelihood(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    window: ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> NDArray[np.float64]:
    """Sum over the window's frames of log P(Z_f | pose ⊕ rel_f, M) (and the compass's
    log-likelihood where a frame has one), one compiled call, shape (N,)."""
    return window_likelihood_with(_sensor_setup(semantic_map, config, grid), x, y, theta, window)


def window_likelihood_with(
    setup: SensorSetup,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    window: ObservationWindow,
) -> NDArray[np.float64]:
    """:func:`window_log_likelihood` with :func:`_sensor_setup` made once."""
    out = np.zeros(x.shape[0], dtype=np.float64)
    if not window.frames or not x.shape[0]:
        return out
    arrays = window.arrays  # the frames' poses and compass first, then the detections
    _window_kernel(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        *arrays[:5], *setup, *arrays[5:], out,
    )  # fmt: skip
    return out


def window_pattern_search(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    pattern: NDArray[np.float64],
    step_m: float,
    step_rad: float,
    rounds: int,
    window: ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Pattern search over the window, every round in one compiled call.

    Each round tries the steps ``pattern`` (shape (3, K): x, y, heading, in units of the
    round's steps) around every pose, wraps the headings, moves each pose to its best
    candidate in the free space if that beats its window score, keeps the larger
    score, and halves the steps (``step_m``, ``step_rad`` the first round's). The
    arithmetic is the numpy definition's,
    :func:`app.localization.search.pattern_search_reference`, to the bit. Returns the
    poses and their window scores, each shape (N,).
    """
    return pattern_search_with(
        _free_space_setup(semantic_map), _sensor_setup(semantic_map, config, grid),
        x, y, theta, pattern, step_m, step_rad, rounds, window,
    )  # fmt: skip


def pattern_search_with(
    free: FreeSetup,
    setup: SensorSetup,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    pattern: NDArray[np.float64],
    step_m: float,
    step_rad: float,
    rounds: int,
    window: ObservationWindow,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`window_pattern_search` with the map's setups made once."""
    return _searched(
        x, y, theta, _NO_COUNTS, _NO_STEPS, pattern, step_m, step_rad, rounds, window, free, setup
    )


def window_jitter_search(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    jitter: Sequence[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]],
    window: ObservationWindow,
    semantic_map: SemanticMap,
    config: FilterConfig,
    grid: VisibilityGrid | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Each pose moved to the best of its jittered copies, round after round, in one
    compiled call.

    ``jitter`` holds each round's offsets (x, y, heading), each shape (N, K) for K
    copies per pose: drawn beforehand, since they do not depend on the search. A copy
    replaces its pose when it lies in the free space and beats the pose's window score.
    The arithmetic is the numpy definition's,
    :func:`app.localization.search.jitter_search_reference`, to the bit. Returns the
    poses and their window scores, each shape (N,).
    """
    return jitter_search_with(
        _free_space_setup(semantic_map), _sensor_setup(semantic_map, config, grid),
        x, y, theta, jitter, window,
    )  # fmt: skip


def jitter_search_with(
    free: FreeSetup,
    setup: SensorSetup,
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    jitter: Sequence[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]],
    window: ObservationWindow,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`window_jitter_search` with the map's setups made once."""
    counts = np.array([ox.shape[1] for ox, _, _ in jitter], dtype=np.int64)
    offsets = np.empty((3, x.shape[0] * int(counts.sum())))
    start = 0
    for round_offsets in jitter:
        n = round_offsets[0].size
        for row, part in zip(offsets, round_offsets, strict=True):
            row[start : start + n] = part.reshape(-1)
        start += n
    return _searched(x, y, theta, counts, offsets, _NO_STEPS, 0.0, 0.0, 0, window, free, setup)
