"""What of a session's state to draw: a weight-sampled subset of particles and overlays."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from app.service.session import SessionSnapshot

MAX_DRAWN = 5_000
HEADING_TICK_M = 0.15
RAY_LENGTH_M = 3.0


def sample_particles(
    snap: SessionSnapshot, rng: np.random.Generator, max_drawn: int = MAX_DRAWN
) -> tuple[NDArray[np.float32], NDArray[np.uint8], NDArray[np.float32]]:
    """At most ``max_drawn`` particles drawn by weight.

    Returns:
        points shape (M, 3); colours shape (M, 3) uint8 (dark blue = light weight,
        yellow = heavy); heading ticks as segments, shape (M, 2, 3).
    """
    n = snap.x.size
    w = snap.weights
    idx = rng.choice(n, size=max_drawn, replace=True, p=w) if n > max_drawn else np.arange(n)
    x, y, th, wi = snap.x[idx], snap.y[idx], snap.theta[idx], w[idx]
    pts = np.zeros((idx.size, 3), dtype=np.float32)
    pts[:, 0], pts[:, 1], pts[:, 2] = x, y, 0.02
    rel = wi / max(float(wi.max()), 1e-300)
    colours = np.empty((idx.size, 3), dtype=np.uint8)
    colours[:, 0] = (40 + 215 * rel).astype(np.uint8)
    colours[:, 1] = (60 + 160 * rel).astype(np.uint8)
    colours[:, 2] = (160 - 130 * rel).astype(np.uint8)
    ticks = np.zeros((idx.size, 2, 3), dtype=np.float32)
    ticks[:, 0, :2] = pts[:, :2]
    ticks[:, 1, 0] = x + HEADING_TICK_M * np.cos(th)
    ticks[:, 1, 1] = y + HEADING_TICK_M * np.sin(th)
    ticks[:, :, 2] = 0.02
    return pts, colours, ticks


def pose_arrow(x: float, y: float, theta: float, length: float = 0.6) -> NDArray[np.float32]:
    """One arrow from (x, y) along theta, shape (1, 2, 3)."""
    return np.array(
        [[[x, y, 0.08], [x + length * np.cos(theta), y + length * np.sin(theta), 0.08]]],
        dtype=np.float32,
    )


def detection_rays(snap: SessionSnapshot) -> NDArray[np.float32]:
    """Segments from the estimate along each detection's bearing, shape (K, 2, 3)."""
    est = snap.estimate
    if est is None or not snap.detections:
        return np.zeros((0, 2, 3), dtype=np.float32)
    ang = est.theta_rad + np.array([d.bearing_rad for d in snap.detections])
    rays = np.zeros((ang.size, 2, 3), dtype=np.float32)
    rays[:, 0, 0], rays[:, 0, 1] = est.x, est.y
    rays[:, 1, 0] = est.x + RAY_LENGTH_M * np.cos(ang)
    rays[:, 1, 1] = est.y + RAY_LENGTH_M * np.sin(ang)
    rays[:, :, 2] = 0.05
    return rays
