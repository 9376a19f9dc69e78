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
log-likelihood where weights matter). Compiled code is cached on disk;
:func:`warm_up` compiles it at start-up so no request waits.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import FilterConfig
from app.localization.fastmath import FAST, grid_cell, sincos, softplus
from app.localization.sensor import Observation
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
    obj_xy, det_cos, det_sin, det_score, det_group,
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
                for k in range(k_total):
                    if det_group[k] != g:
                        continue
                    ca = f32(det_cos[k])
                    sa = f32(det_sin[k])
                    row = best[k]
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
    n = x.shape[0]
    out = np.zeros(n, dtype=np.float64)
    if obs.empty:
        return out
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
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
    _kernel(
        x,
        y,
        np.ascontiguousarray(theta, dtype=np.float64),
        bool(config.visibility),
        geometry,
        vis_bits,
        float(np.cos(np.radians(config.fov_deg) / 2.0)),
        check_fov,
        float(np.cos(np.radians(config.fov_centre_deg))),
        float(np.sin(np.radians(config.fov_centre_deg))),
        float(max_range_sq),
        semantic_map.object_xy.reshape(-1, 2),
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
