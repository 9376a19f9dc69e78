"""The virtual spherical camera: which map objects a person sees, and at which bearing.

An object is seen when its centre lies inside the field of view (centred on the
heading, or turned by ``fov_centre_deg`` for a yawed or off-centre phone camera),
within the maximum range, and in line of sight (walls block; a door or
window is not hidden by the wall it is mounted in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.localization.types import Pose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap


@dataclass(frozen=True)
class CameraModel:
    """Field of view (degrees), maximum range (metres), and the field's centre direction
    relative to the heading (degrees, CCW positive)."""

    fov_deg: float = 360.0
    max_range_m: float = 15.0
    fov_centre_deg: float = 0.0


def visible_objects(
    semantic_map: SemanticMap, pose: Pose, camera: CameraModel
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Objects the camera sees from ``pose`` and their exact bearings.

    Returns:
        (indices shape (K,), bearings in radians relative to the heading, CCW positive,
        shape (K,)).
    """
    d = semantic_map.object_xy - np.array([pose.x, pose.y])
    bearing = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose.theta_rad)
    off_centre = wrap_angle(bearing - np.radians(camera.fov_centre_deg))
    in_fov = np.abs(off_centre) <= np.radians(camera.fov_deg) / 2.0 + 1e-12
    in_range = np.hypot(d[:, 0], d[:, 1]) <= camera.max_range_m
    seen = in_fov & in_range
    idx = np.flatnonzero(seen)
    if idx.size:
        los = semantic_map.line_of_sight([[pose.x, pose.y]], idx)[0]
        idx = idx[los]
    return idx, bearing[idx]
