"""Whether the walk the odometry recorded could have led to a place.

A particle filter forgets how it got anywhere: a cloud that the recovery injects at a
look-alike place (a corridor's next bay, a stale map's moved furniture making the
wrong bay fit better) carries no history, and within seconds it can explain the
detections as well as the truth. The odometry still has the history. Chained back from
a candidate pose, the last tens of metres walked must lie in the free space, give or take
what the odometry's errors and the pose's heading can do over that distance; a place
whose walk would have come through the outside of the building or through solid rooms is
no place the person is. (The evidence tracker tests its alternatives the same way, with
the main mode's own trail: :meth:`~app.localization.evidence.EvidenceTracker._walk_fits`.)

Measured on the phone suite's stale office map: a look-alike place 6.3 m along the
corridor, where a moved plant and a removed table made the detections fit better than at
the truth, was told as a fix after the person had been lost for a minute; its walk,
chained back, began 5 m outside the building.

:class:`WalkedPath` keeps the dead-reckoned path (a point every ``POINT_SPACING_M`` walked,
the last ``MAX_WALK_M``), started again whenever the odometry breaks off or the person
rides between levels. :meth:`WalkedPath.fits` carries it onto a pose and checks every
point's distance to the free space against ``BASE_TOLERANCE_M`` plus ``share`` of the
distance walked since that point (the heading's error swings the path sideways, the
scale's stretches it, both in proportion to the distance).
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from app.localization.motion import compose_odometry
from app.localization.types import Odometry
from app.maps.model import SemanticMap

#: A point of the path is kept every this many metres walked.
POINT_SPACING_M = 0.25
#: The path kept: the last this many metres walked.
MAX_WALK_M = 60.0
#: How far a point of the path may lie from the free space however recent (m): the free
#: space keeps clear of the walls by a few decimetres, and a pose a few decimetres off.
BASE_TOLERANCE_M = 0.5
#: The pose's heading may be off by up to this much (degrees), tried in steps of
#: ``HEADING_STEP_DEG``: a heading error turns the whole path, so it is searched, not
#: added to every point's tolerance.
MAX_HEADING_OFF_DEG = 10.0
HEADING_STEP_DEG = 1.0
#: What the heading's wander along the path adds (a share of the distance walked since
#: a point), by odometry source: VIO's gyro drifts about 2 degrees a minute, step
#: counting's heading about 10 (BIAS_PRIORS); a source not said is taken for the latter.
WANDER_SHARE = {"vio": 0.03, "pdr": 0.08, "unknown": 0.08}


def outside_distance(semantic_map: SemanticMap) -> NDArray[np.float64]:
    """Per cell of the map's free-space grid, the distance (m) from its centre to the
    nearest free cell's (0 in the free space), kept with the map."""

    def make() -> NDArray[np.float64]:
        fs = semantic_map.free_space
        far = np.asarray(ndimage.distance_transform_edt(~fs.mask), dtype=np.float64)
        return far * fs.resolution_m

    return semantic_map.derived_value(("outside_distance",), make)


class WalkedPath:
    """The dead-reckoned path of the last ``MAX_WALK_M`` walked (module docstring).

    ``share``: how much of the distance walked since a point it may lie beyond the free
    space on top of ``BASE_TOLERANCE_M`` (the heading's wander, :data:`WANDER_SHARE`);
    ``scale_tolerance``: how far off the odometry's scale may be (a share): the path is
    tried stretched and shrunk by it, as it is turned by the heading's error.
    """

    def __init__(self, share: float, scale_tolerance: float) -> None:
        self.share = share
        self.scale_tolerance = scale_tolerance
        self.reset()

    def reset(self) -> None:
        """Forget the path (a new session, the odometry broke off, a ride)."""
        #: Dead reckoning: the odometry composed since the reset.
        self._pose = (0.0, 0.0, 0.0)
        self._walked = 0.0
        #: Kept points: x, y in the dead reckoning's frame and the distance walked there.
        self._xyw = array("d")

    def moved(self, odometry: Odometry) -> None:
        """The person moved by ``odometry``."""
        pose = compose_odometry(Odometry(*self._pose), odometry)
        assert pose is not None  # (both motions known)
        self._pose = (pose.forward_m, pose.left_m, pose.turn_rad)
        self._walked += math.hypot(odometry.forward_m, odometry.left_m)
        xyw = self._xyw
        if not xyw or self._walked - xyw[-1] >= POINT_SPACING_M:
            xyw.extend((pose.forward_m, pose.left_m, self._walked))
            # Drop the oldest now and then, not at every point.
            if xyw[2] < self._walked - 2.0 * MAX_WALK_M:
                keep = np.frombuffer(xyw, dtype=np.float64).reshape(-1, 3)
                keep = keep[keep[:, 2] >= self._walked - MAX_WALK_M]
                self._xyw = array("d", keep.ravel().tolist())

    @property
    def walked_m(self) -> float:
        """Metres walked since the reset."""
        return self._walked

    def fits(self, semantic_map: SemanticMap, x: float, y: float, theta: float) -> bool:
        """Whether the path, carried so that its end is the pose (x, y, theta), keeps
        within its tolerance of the map's free space at every point."""
        if not self._xyw:
            return True
        pts = np.frombuffer(self._xyw, dtype=np.float64).reshape(-1, 3)
        pts = pts[pts[:, 2] >= self._walked - MAX_WALK_M]
        allowed = BASE_TOLERANCE_M + self.share * (self._walked - pts[:, 2])
        # Each point in the dead reckoning's frame at its end ...
        rx, ry, rt = self._pose
        dx, dy = pts[:, 0] - rx, pts[:, 1] - ry
        cr, sr = math.cos(rt), math.sin(rt)
        fx, fy = cr * dx + sr * dy, -sr * dx + cr * dy
        # ... then on the pose, for every heading error and scale tried: (K, N).
        most = MAX_HEADING_OFF_DEG + 1e-9
        off = np.radians(np.arange(-MAX_HEADING_OFF_DEG, most, HEADING_STEP_DEG))
        tol = self.scale_tolerance
        scale = np.repeat(np.array([1.0 - tol, 1.0, 1.0 + tol]), off.size)[:, None]
        angle = theta + np.tile(off, 3)[:, None]
        c, s = np.cos(angle), np.sin(angle)
        px, py = x + scale * (c * fx - s * fy), y + scale * (s * fx + c * fy)
        fs = semantic_map.free_space
        flat, inside = fs.cell_index(px, py)
        far = outside_distance(semantic_map).reshape(-1)[flat]
        # Off the grid: the edge cell's distance, plus the way to the edge.
        rows, cols = fs.mask.shape
        ex = np.clip(px, fs.origin_x, fs.origin_x + cols * fs.resolution_m)
        ey = np.clip(py, fs.origin_y, fs.origin_y + rows * fs.resolution_m)
        far = np.where(inside, far, far + np.hypot(px - ex, py - ey))
        return bool((far <= allowed).all(axis=1).any())

    def checkpoint(self) -> dict[str, Any]:
        return {"pose": list(self._pose), "walked": self._walked, "points": list(self._xyw)}

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it existed: the path
        starts again)."""
        self.reset()
        if state is None:
            return
        px, py, pt = (float(v) for v in state["pose"])
        self._pose = (px, py, pt)
        self._walked = float(state["walked"])
        self._xyw = array("d", [float(v) for v in state["points"]])
