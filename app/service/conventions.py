"""Whether a client's bearings and turns follow one sign convention (docs/API.md).

``bearing_deg`` and the odometry's ``turn_deg`` are both counter-clockwise positive
(left of forward is +90). A client that sends one of them clockwise (an image's x axis
taken for the bearing, a compass's sense taken for the turn) gets no error: the session
never finds a place that explains what it is sent, and says "not sure" for ever. This
check needs no map. When the person turns by ``T``, what is in view turns by ``-T``: each
object's bearing moves the other way. Over the last ``WINDOW`` frames with odometry, once
they turned by at least ``MIN_TURN_RAD`` (a corner: the sway of a hand-held phone and a
detector's late frames average out over it), the frame's detections are laid on the
window's first frame's, turned by ``-T`` and by ``+T``: whichever puts more of them within
``MATCH_RAD`` of a detection of their class there casts the window's vote. Once
``MIN_VOTES`` votes are in and at most ``AGREE_SHARE`` of them are for ``-T``, the session
warns, once. On the phone suite's walks (45, nine scenarios, 360 deg to 66 deg cameras,
VIO and PDR, a stale map) the correct walks gave ``-T`` at least 0.64 of their votes, and
the same walks with their bearings mirrored at most 0.36.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

from app.localization.types import Detection, Odometry

#: Frames a vote spans, and the least turn over them that votes (rad).
WINDOW = 5
MIN_TURN_RAD = math.radians(30.0)
#: How near a turned bearing must come to one of its class to match (rad): the walk's
#: parallax over the window and the detector's noise.
MATCH_RAD = math.radians(8.0)
#: Votes before the check says anything, and the share for ``-T`` at or below which it
#: warns.
MIN_VOTES = 15
AGREE_SHARE = 0.25

#: What the client hears, once, when its bearings and turns disagree.
MIRRORED_WARNING = (
    "bearings and odometry turns disagree in sign: as the odometry turns left, the "
    "objects' bearings move left too. Both bearing_deg and turn_deg are counter-clockwise "
    "positive (left of forward is +90); one of them is sent clockwise"
)


class TurnSignCheck:
    """Votes on whether bearings move against the odometry's turns (module docstring)."""

    def __init__(self) -> None:
        self.agree = 0
        self.disagree = 0
        self.warned = False
        self._turned = 0.0  # the odometry's turns added up (rad)
        self._window: deque[tuple[float, list[tuple[str, float]]]] = deque(maxlen=WINDOW)

    def update(self, odometry: Odometry | None, detections: Sequence[Detection]) -> str | None:
        """One frame: the warning on the frame the check decides the signs disagree."""
        if self.warned:
            return None
        if odometry is None:  # the turn since the window's frames is not known
            self._window.clear()
            return None
        self._turned += odometry.turn_rad
        seen = [(d.cls, d.bearing_rad) for d in detections]
        said = None
        if len(self._window) == WINDOW and seen:
            start, before = self._window[0]
            turn = self._turned - start
            if abs(turn) >= MIN_TURN_RAD and before:
                against = _matches(seen, before, -turn)
                along = _matches(seen, before, turn)
                self.agree += against > along
                self.disagree += along > against
                votes = self.agree + self.disagree
                if votes >= MIN_VOTES and self.agree <= AGREE_SHARE * votes:
                    self.warned = True
                    said = MIRRORED_WARNING
        self._window.append((self._turned, seen))
        return said

    def checkpoint(self) -> dict[str, Any]:
        return {
            "agree": self.agree,
            "disagree": self.disagree,
            "warned": self.warned,
            "turned": self._turned,
            "window": [[t, [[c, b] for c, b in seen]] for t, seen in self._window],
        }

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before the check)."""
        state = state or {}
        self.agree = int(state.get("agree", 0))
        self.disagree = int(state.get("disagree", 0))
        self.warned = bool(state.get("warned", False))
        self._turned = float(state.get("turned", 0.0))
        self._window.clear()
        for t, seen in state.get("window", []):
            self._window.append((float(t), [(str(c), float(b)) for c, b in seen]))


def _matches(seen: list[tuple[str, float]], before: list[tuple[str, float]], shift: float) -> int:
    """How many of ``seen`` lie within MATCH_RAD of a detection of their class in
    ``before`` moved by ``shift``."""
    # (math.remainder wraps to [-pi, pi] in plain Python: a compiled function's call
    # costs more than the arithmetic here.)
    tau = 2.0 * math.pi
    return sum(
        any(c == pc and abs(math.remainder(b - pb - shift, tau)) < MATCH_RAD for pc, pb in before)
        for c, b in seen
    )
