"""Objects the estimate says are in plain view, that the camera keeps not reporting.

The sensor model of the paper (eqs. 2-3) only weighs what the detector reports: an
object the pose should see but that is never reported costs nothing. In a room that a
rotation maps onto itself except for one door, the mirror-image pose then explains
every detection as well as the true pose, and a false detection that happens to
point at the mirror's door tips the evidence its way. Yet from the mirror pose that
door is a few metres straight ahead, frame after frame, and no detection ever points
at it.

This module keeps that negative evidence for the gate of ``converged`` only (it never
moves a particle): per object, a decaying count of frames in which the estimate had it
*clearly in view* (line of sight on the visibility grid, within ``near_m``, at least
``margin_rad`` inside the field of view, of a class the detector has reported at least
once in this session, and no farther than the detector has been seen to report objects
of that class, or of any class while that one has not been seen yet: a detector that
only reports small objects up close is not held to more) and of those in which a
detection of its class pointed at it (within ``cutoff_sigmas`` of its bearing). An
object in clear view for ``min_expected`` frames' worth of count yet seen in at most
``max_seen_share`` of them marks the estimate as *contradicted*: converged is not
gained, and is given up.

Only frames with detections count (a blocked camera reports nothing at all, which says
nothing about any one object). When the estimate jumps by more than ``jump_m`` the
counts start again: they were about another place.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.localization.config import FilterConfig
from app.localization.sensor import Observation
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap


@dataclass(frozen=True)
class UnseenSettings:
    """What "clearly in view" means, and how much not seeing it takes."""

    near_m: float = 8.0
    #: Closer than this the bearing to an object's reference point is ill-defined.
    min_m: float = 0.7
    margin_rad: float = float(np.radians(10.0))
    #: A detection within this many of its class's stds of the object's bearing sees it.
    cutoff_sigmas: float = 4.0
    #: Per-frame decay of the counts (about 7 frames of memory).
    decay: float = 0.85
    min_expected: float = 4.0
    max_seen_share: float = 0.15
    jump_m: float = 1.0


DEFAULT_UNSEEN = UnseenSettings()


class UnseenObjects:
    """Decaying per-object counts of frames in clear view and frames seen."""

    def __init__(
        self,
        semantic_map: SemanticMap,
        config: FilterConfig,
        settings: UnseenSettings = DEFAULT_UNSEEN,
    ) -> None:
        self.map = semantic_map
        self.config = config
        self.settings = settings
        self.reported = np.zeros(len(semantic_map.classes), dtype=bool)
        #: Per class, the farthest an object of it was seen from the estimate (m; 0 while
        #: none was): how far this detector reports such objects.
        self.reach_m = np.zeros(len(semantic_map.classes))
        self._class_index = {c: i for i, c in enumerate(semantic_map.classes)}
        self.reset()

    def reset(self) -> None:
        """Forget the counts (not the classes the detector has reported)."""
        n = self.map.object_count
        self.expected = np.zeros(n)
        self.seen = np.zeros(n)
        self._at: tuple[float, float] | None = None
        #: The last frame's objects in clear view, and how many of them went unreported.
        self.frame_expected = 0
        self.frame_missed = 0

    @property
    def contradicted(self) -> bool:
        """Whether an object in clear view has gone unreported (module docstring)."""
        st = self.settings
        flagged = (self.expected >= st.min_expected) & (
            self.seen <= st.max_seen_share * self.expected
        )
        return bool(flagged.any())

    def update(
        self,
        x: float,
        y: float,
        theta: float,
        obs: Observation,
        visible_row: NDArray[np.bool_] | None,
    ) -> None:
        """Count one frame at the estimate (x, y, theta); frames without detections skip."""
        if obs.empty:
            return
        st = self.settings
        if self._at is not None and np.hypot(x - self._at[0], y - self._at[1]) > st.jump_m:
            self.reset()
        self._at = (x, y)
        # The observation's class groups as the map's class indices.
        group_class = np.array([self._class_index[c] for c in obs.classes], dtype=np.int64)
        self.reported[group_class] = True
        dx = self.map.object_xy[:, 0] - x
        dy = self.map.object_xy[:, 1] - y
        dist = np.hypot(dx, dy)
        bearing = wrap_angle(np.arctan2(dy, dx) - theta)
        cls = self.map.object_class
        view = (dist <= st.near_m) & (dist >= st.min_m) & self.reported[cls]
        if visible_row is not None and self.config.visibility:
            view &= visible_row
        if self.config.fov_deg < 360.0:
            off_centre = np.abs(wrap_angle(bearing - np.radians(self.config.fov_centre_deg)))
            view &= off_centre <= np.radians(self.config.fov_deg) / 2.0 - st.margin_rad
        in_view = np.flatnonzero(view)
        # Each object in view against every detection of its class at once.
        same = cls[in_view][:, None] == group_class[obs.det_group][None, :]
        err = np.abs(wrap_angle(obs.det_bearing[None, :] - bearing[in_view][:, None]))
        within = st.cutoff_sigmas / np.sqrt(obs.group_kappa[obs.det_group])
        seen = np.zeros(self.map.object_count, dtype=bool)
        seen[in_view] = (same & (err <= within[None, :])).any(axis=1)
        # How far this detector reports each class, learnt from what it reported; a class
        # never seen yet is expected as far as any class was.
        np.maximum.at(self.reach_m, cls[seen], dist[seen])
        reach = np.where(self.reach_m > 0.0, self.reach_m, self.reach_m.max())
        clear = view & (dist <= reach[cls])
        self.expected = st.decay * self.expected + clear
        self.seen = st.decay * self.seen + (clear & seen)
        self.frame_expected = int(np.count_nonzero(clear))
        self.frame_missed = int(np.count_nonzero(clear & ~seen))

    @property
    def frame_contradicts(self) -> bool:
        """Whether the last frame left at least half of the objects in clear view
        unreported (or had none in clear view to judge by)."""
        return self.frame_expected == 0 or 2 * self.frame_missed >= self.frame_expected

    def checkpoint(self) -> dict[str, Any]:
        return {
            "expected": self.expected,
            "seen": self.seen,
            "reported": self.reported,
            "reach": self.reach_m,
            "at": None if self._at is None else list(self._at),
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        self.expected = np.array(state["expected"], dtype=np.float64)
        self.seen = np.array(state["seen"], dtype=np.float64)
        self.reported = np.array(state["reported"], dtype=bool)
        self.reach_m = np.array(state.get("reach", np.zeros(self.reported.size)), dtype=float)
        at = state["at"]
        self._at = None if at is None else (float(at[0]), float(at[1]))
