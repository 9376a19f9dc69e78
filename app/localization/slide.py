"""Whether the estimate keeps to the odometry: a cloud dragged off by a stale map.

An object moved since the map was drawn (a table 1.3 m from where the map has it) is
detected every frame where the map says nothing is. At the true pose each of its
detections costs the clutter floor; a pose a metre off explains it, at the price of
a few degrees on the objects that did not move. Frame after frame the second is about
as likely as the first, and the cloud, whose motion noise lets it slip a few
centimetres a frame, slides towards it: measured on the phone suite's stale maps, the
estimate fell 0.6-0.9 m behind the odometry over 5 s of walking while the cloud stayed
a few centimetres wide, every detection looked explained, and the gate said
"converged" a metre off (docs/results/phone.md). The fit at one frame cannot tell:
from the dragged pose the moved object fits and the others are a little off.

The odometry can tell. Over a few seconds it is good to centimetres at VIO grade and
to a tenth of the distance at PDR grade, and it does not know the map. So the check
keeps the converged estimates of the last ``SLIDE_FRAMES`` frames with the odometry's
dead reckoning at each, and measures how far the estimate now lies from the oldest of
them (at least ``MIN_FRAMES`` old) carried forward by the odometry since: the *slide*. A
converged estimate that slid more than the gate allows (:class:`~app.localization.
convergence.ConvergenceGate`, ``hold_slide_m``) is not one to tell a person: either
it, or the one before, was wrong by about that much.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from app.localization.types import Odometry

#: Frames between the estimate compared and the one it is compared with (5 s at 5 Hz:
#: long enough for a drag of a few centimetres a frame to add up, short enough for the
#: odometry's drift to stay small).
SLIDE_FRAMES = 25
#: The youngest estimate compared with (2 s at 5 Hz): a cloud that converged a metre
#: off and is being dragged further shows within seconds of converging.
MIN_FRAMES = 10

Pose = tuple[float, float, float]


def _compose(a: Pose, forward: float, left: float, turn: float) -> Pose:
    """Pose ``a`` moved by ``forward``, ``left`` (in its own frame) and turned by ``turn``."""
    x, y, t = a
    c, s = math.cos(t), math.sin(t)
    return (x + c * forward - s * left, y + s * forward + c * left, t + turn)


class OdometryCheck:
    """The recent converged estimates with the dead reckoning at each (module docstring)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the history (odometry lost, the belief started over or moved elsewhere)."""
        #: Dead reckoning: the odometry composed since the last reset.
        self._reckoned: Pose = (0.0, 0.0, 0.0)
        #: Per frame: the dead reckoning then, and the converged estimate (None if not).
        self._past: deque[tuple[Pose, Pose | None]] = deque(maxlen=SLIDE_FRAMES)

    def moved(self, odometry: Odometry) -> None:
        """The person moved by ``odometry``."""
        self._reckoned = _compose(
            self._reckoned, odometry.forward_m, odometry.left_m, odometry.turn_rad
        )

    def slide_m(self, x: float, y: float) -> float:
        """How far (x, y) lies from the oldest converged estimate of the last
        ``SLIDE_FRAMES`` frames, at least ``MIN_FRAMES`` old, carried forward by the
        odometry since (m); 0 without such an estimate."""
        old_enough = len(self._past) - MIN_FRAMES + 1
        anchors = (i for i in range(old_enough) if self._past[i][1] is not None)
        first = next(anchors, None)
        if first is None:
            return 0.0
        reckoned_then, estimate_then = self._past[first]
        assert estimate_then is not None
        # The dead reckoning's motion since then, in its pose then, applied to the estimate then.
        rx, ry, rt = reckoned_then
        dx, dy = self._reckoned[0] - rx, self._reckoned[1] - ry
        c, s = math.cos(rt), math.sin(rt)
        forward, left = c * dx + s * dy, -s * dx + c * dy
        px, py, _ = _compose(estimate_then, forward, left, 0.0)
        return math.hypot(x - px, y - py)

    def add(self, x: float, y: float, theta: float, converged: bool) -> None:
        """Record this frame's estimate (kept as an anchor only when converged)."""
        self._past.append((self._reckoned, (x, y, theta) if converged else None))

    def checkpoint(self) -> dict[str, Any]:
        return {"reckoned": self._reckoned, "past": list(self._past)}

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it existed)."""
        self.reset()
        if state is None:
            return
        self._reckoned = _pose(state["reckoned"])
        for reckoned, estimate in state["past"]:
            self._past.append((_pose(reckoned), None if estimate is None else _pose(estimate)))


def _pose(value: Any) -> Pose:
    return (float(value[0]), float(value[1]), float(value[2]))
