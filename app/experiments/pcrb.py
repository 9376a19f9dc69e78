"""The posterior Cramér-Rao bound (PCRB) of the filtering problem.

The accuracy limit of *any* estimator of the pose at frame k from the detections and
odometry up to k, in the simulator's model: the pose moves by the measured odometry
(forward, left, turn in the previous body frame, each with Gaussian noise), and each
frame brings the bearings to the visible objects with Gaussian noise. Tichavský,
Muravchik and Nehorai (IEEE Trans. Signal Processing 46(5), 1998) give the Fisher
information J_k of the pose recursively; for additive Gaussian process noise w_k ~
N(0, Q_k) and x_{k+1} = f(x_k) + w_k it reads

    J_{k+1} = Q_k^-1 + H_{k+1}^T R^-1 H_{k+1} - Q_k^-1 F_k (J_k + F_k^T Q_k^-1 F_k)^-1 F_k^T Q_k^-1

with F_k the Jacobian of the motion, H_{k+1} the Jacobian of the bearings, R the
bearing noise covariance. Along a known true path the expectations reduce to these
matrices evaluated at the truth. The bound on the position error is the square root
of the trace of the (x, y) block of J_k^-1. The walk starts with no prior (global
start): J_0 is the first frame's information alone.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from app.localization.types import Pose
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel, visible_objects

#: Added to the first frame's information so that it can be inverted even when that
#: frame alone does not fix the pose (fewer than three bearings).
REGULARIZER = 1e-9


def pcrb_step(
    info: NDArray[np.float64],
    motion_jacobian: NDArray[np.float64],
    process_cov: NDArray[np.float64],
    bearing_jacobian: NDArray[np.float64],
    bearing_var: float,
) -> NDArray[np.float64]:
    """One step of the recursion: J_k -> J_{k+1} (all 3 x 3; ``bearing_jacobian`` M x 3)."""
    q_inv = np.linalg.inv(process_cov)
    f = motion_jacobian
    d11 = f.T @ q_inv @ f
    d12 = -f.T @ q_inv
    d22 = q_inv + bearing_jacobian.T @ bearing_jacobian / bearing_var
    return d22 - d12.T @ np.linalg.solve(info + d11, d12)


def bearing_jacobian(
    semantic_map: SemanticMap, pose: Pose, camera: CameraModel
) -> NDArray[np.float64]:
    """Rows d(bearing)/d(x, y, theta) for each object the camera sees, shape (M, 3)."""
    idx, _ = visible_objects(semantic_map, pose, camera)
    d = semantic_map.object_xy[idx] - np.array([pose.x, pose.y])
    r2 = np.sum(d * d, axis=1)
    return np.column_stack([d[:, 1] / r2, -d[:, 0] / r2, -np.ones(idx.size)])


def pcrb_position_m(
    semantic_map: SemanticMap,
    truth: Sequence[Pose],
    fov_deg: float,
    bearing_noise_deg: float,
    odometry_noise_m: float,
    odometry_noise_deg: float,
    max_range_m: float = 15.0,
) -> NDArray[np.float64]:
    """The PCRB on the position error (m) at every frame of a walk, shape (T,)."""
    camera = CameraModel(fov_deg, max_range_m)
    var = float(np.radians(bearing_noise_deg)) ** 2
    noise = np.diag([odometry_noise_m**2, odometry_noise_m**2, np.radians(odometry_noise_deg) ** 2])
    h0 = bearing_jacobian(semantic_map, truth[0], camera)
    info = h0.T @ h0 / var + REGULARIZER * np.eye(3)
    out = np.empty(len(truth))
    out[0] = _position_bound(info)
    for k in range(1, len(truth)):
        prev, cur = truth[k - 1], truth[k]
        c, s = np.cos(prev.theta_rad), np.sin(prev.theta_rad)
        dx, dy = cur.x - prev.x, cur.y - prev.y
        fwd, left = c * dx + s * dy, -s * dx + c * dy
        f = np.eye(3)
        f[0, 2] = -s * fwd - c * left
        f[1, 2] = c * fwd - s * left
        g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        h = bearing_jacobian(semantic_map, cur, camera)
        info = pcrb_step(info, f, g @ noise @ g.T, h, var)
        out[k] = _position_bound(info)
    return out


def _position_bound(info: NDArray[np.float64]) -> float:
    cov = np.linalg.inv(info)
    return float(np.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))
