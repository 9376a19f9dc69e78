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
rides between levels. :meth:`WalkedPath.fits` carries it onto a pose, turned by every
heading error up to ``MAX_HEADING_OFF_DEG`` and stretched or shrunk by the odometry's
scale tolerance (both move the whole path, so they are searched), and asks whether for
one of them every point lies within ``BASE_TOLERANCE_M`` plus ``share`` of the distance
walked since it (the heading's wander along the way, :data:`WANDER_SHARE`) of the free
space (:meth:`~app.maps.freespace.FreeSpaceGrid.distance_outside`). Points, not the
segments between them: a walk through a thin wall is not caught, one through the outside
of the building or through rooms a few metres deep is.
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.localization.motion import compose_odometry
from app.localization.types import Odometry
from app.maps.freespace import FreeSpaceGrid

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
                self._xyw = array("d", self._recent().ravel().tolist())

    def _recent(self) -> NDArray[np.float64]:
        """The kept points of the last ``MAX_WALK_M`` walked: x, y, distance walked (N, 3)."""
        pts = np.frombuffer(self._xyw, dtype=np.float64).reshape(-1, 3)
        return pts[pts[:, 2] >= self._walked - MAX_WALK_M]

    @property
    def walked_m(self) -> float:
        """Metres walked since the reset."""
        return self._walked

    def fits(self, free_space: FreeSpaceGrid, x: float, y: float, theta: float) -> bool:
        """Whether the path, carried so that its end is the pose (x, y, theta), keeps
        within its tolerance of ``free_space`` at every point."""
        if not self._xyw:
            return True
        pts = self._recent()
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
        far = free_space.distance_outside(px, py)
        return bool((far <= allowed).all(axis=1).any())

    def checkpoint(self) -> dict[str, Any]:
        """The dead reckoning and the points :meth:`fits` reads (the last
        ``MAX_WALK_M``), as one float32 array: millimetres over a 60 m walk."""
        pts = self._recent()
        return {"pose": list(self._pose), "walked": self._walked, "points": pts.astype(np.float32)}

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it existed: the path
        starts again)."""
        self.reset()
        if state is None:
            return
        px, py, pt = (float(v) for v in state["pose"])
        self._pose = (px, py, pt)
        self._walked = float(state["walked"])
        points = np.asarray(state["points"], dtype=np.float64).reshape(-1)
        self._xyw = array("d", points.tolist())
