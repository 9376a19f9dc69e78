"""Compiled (numba) form of :func:`app.localization.sensor.log_likelihood_reference`.

One pass per particle: the unit vectors towards the frame's candidate objects are
computed once, then every detection takes its best match among its class (eq. 3),
and the class-weighted, score-tempered log-likelihoods are summed (eq. 2). Compiled
code is cached on disk; :func:`warm_up` compiles it at start-up so no request waits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import FilterConfig
from app.localization.map import SemanticMap
from app.localization.sensor import Observation


@njit(cache=True, fastmath=False, nogil=True)
def _kernel(
    x, y, theta, cells, vis_table, use_vis, cos_half_fov, check_fov, max_range_sq,
    obj_x, obj_y, det_cos, det_sin, det_score, det_group,
    group_kappa, group_weight, group_log_floor, group_log_keep, member_start, members, out,
):  # fmt: skip
    n = x.shape[0]
    m_total = members.shape[0]
    k_total = det_cos.shape[0]
    bx = np.empty(m_total)
    by = np.empty(m_total)
    ok = np.empty(m_total, dtype=np.bool_)
    for i in range(n):
        ct = math.cos(theta[i])
        st = math.sin(theta[i])
        cell = cells[i]
        for j in range(m_total):
            o = members[j]
            dx = obj_x[o] - x[i]
            dy = obj_y[o] - y[i]
            d2 = dx * dx + dy * dy
            inv = 1.0 / math.sqrt(d2 + 1e-24)
            fx = (ct * dx + st * dy) * inv
            bx[j] = fx
            by[j] = (ct * dy - st * dx) * inv
            good = True
            if use_vis:
                good = vis_table[cell, o]
                if good and check_fov and fx < cos_half_fov:
                    good = False
                if good and d2 > max_range_sq:
                    good = False
            ok[j] = good
        total = 0.0
        for k in range(k_total):
            g = det_group[k]
            best = -2.0
            found = False
            for j in range(member_start[g], member_start[g + 1]):
                if ok[j]:
                    c = det_cos[k] * bx[j] + det_sin[k] * by[j]
                    if c > best:
                        best = c
                    found = True
            log_floor = group_log_floor[g]
            if found:
                a = group_kappa[g] * (best - 1.0) + group_log_keep[g]
                if log_floor > -math.inf:
                    hi = max(a, log_floor)
                    lp = hi + math.log(math.exp(a - hi) + math.exp(log_floor - hi))
                else:
                    lp = a
            else:
                lp = log_floor
            total += group_weight[g] * det_score[k] * lp
        out[i] = total


def log_likelihood(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    cells: NDArray[np.int64] | None = None,
    vis_table: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Per-particle log P(Z | s, M), same numbers as the reference, shape (N,).

    Args:
        cells: each particle's visibility-grid cell, shape (N,) (with ``visibility``).
        vis_table: the grid's table, shape (cells, objects) (with ``visibility``).
    """
    n = x.shape[0]
    out = np.zeros(n, dtype=np.float64)
    if obs.empty:
        return out
    use_vis = bool(config.visibility and vis_table is not None and cells is not None)
    if not use_vis:
        cells = np.zeros(n, dtype=np.int64)
        vis_table = np.ones((1, max(semantic_map.object_count, 1)), dtype=np.bool_)
    check_fov = config.fov_deg < 360.0
    max_range_sq = np.inf if config.max_range_m is None else config.max_range_m**2
    with np.errstate(divide="ignore"):
        log_floor = np.log(obs.group_floor)
        log_keep = np.log(obs.group_keep)
    _kernel(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(theta, dtype=np.float64),
        cells,
        vis_table,
        use_vis,
        float(np.cos(np.radians(config.fov_deg) / 2.0)),
        check_fov,
        float(max_range_sq),
        semantic_map.object_xy[:, 0].copy(),
        semantic_map.object_xy[:, 1].copy(),
        obs.det_cos,
        obs.det_sin,
        obs.det_score,
        obs.det_group,
        obs.group_kappa,
        obs.group_weight,
        log_floor,
        log_keep,
        obs.member_start,
        obs.members,
        out,
    )
    return out
