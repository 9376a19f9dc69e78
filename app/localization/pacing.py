"""How often the filter weighs what is seen: at most about 5 times a second.

A phone sending 10 frames a second shows the same view twice 0.1 s apart: weighed as two
views, the evidence piled up twice as fast as the gate's frame counts, the evidence
tracker's windows and the bearings' noise were set for (measured on the phone suite at
10 frames/s: corridors flipping 1.2-1.7 times a minute, a tail p95 of 6-9 m at 180 deg).
A frame with odometry that ends less than :data:`WEIGH_PERIOD_S`, less half its own
length, after the last one weighed is answered by dead reckoning from that one's answer
(:meth:`~app.localization.filter.ParticleFilter.step`); :class:`Pacing` keeps what such
frames bring for the next frame weighed: their motion (composed), their seconds, and
their compass and barometer readings. At 10 frames/s every other frame is weighed, at 5
(or anything slower than about 6.7) every one, and a faster stream is paced to about 5
a second.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from app.localization.compass import CompassReading
from app.localization.floors import AltitudeReading
from app.localization.motion import compose_odometry
from app.localization.types import Odometry
from app.state import from_plain

#: The filter weighs what is seen at most this often (s).
WEIGH_PERIOD_S = 0.2


@dataclass(frozen=True)
class Weighed:
    """What the next step weighs: the frame's own inputs, with those of the frames
    answered before it added (``steps``: how many frames its odometry adds up)."""

    odometry: Odometry | None
    frame_s: float | None
    heading: CompassReading | None
    altitude: AltitudeReading | None
    steps: int


class Pacing:
    """The frames answered since the last step, waiting to be weighed with the next."""

    def __init__(self) -> None:
        self._clear()

    def _clear(self) -> None:
        self.frames = 0
        self.motion = Odometry(0.0, 0.0, 0.0)
        self.seconds = 0.0
        self.heading: CompassReading | None = None
        self.altitude: AltitudeReading | None = None

    def waits(self, odometry: Odometry | None, frame_s: float | None) -> bool:
        """Whether a frame with this odometry, ``frame_s`` long, ends too soon after the
        last one weighed to be weighed itself (its odometry and length known)."""
        return (
            odometry is not None
            and frame_s is not None
            and frame_s > 0.0
            and self.seconds + frame_s < WEIGH_PERIOD_S - frame_s / 2.0
        )

    def hold(
        self,
        odometry: Odometry,
        frame_s: float,
        heading: CompassReading | None,
        altitude: AltitudeReading | None,
    ) -> Odometry:
        """Keep a frame answered between steps; the motion since the last step."""
        motion = compose_odometry(self.motion, odometry)
        assert motion is not None
        self.frames += 1
        self.motion = motion
        self.seconds += frame_s
        # A reading kept waits with the turns that follow it.
        self.heading = heading or _turned(self.heading, odometry.turn_rad)
        self.altitude = altitude or self.altitude
        return motion

    def release(
        self,
        odometry: Odometry | None,
        frame_s: float | None,
        heading: CompassReading | None,
        altitude: AltitudeReading | None,
    ) -> Weighed:
        """A frame to weigh, with what the frames held before it brought (its own
        readings first); nothing is held after."""
        if not self.frames:
            return Weighed(odometry, frame_s, heading, altitude, 1)
        if heading is None and odometry is not None:
            heading = _turned(self.heading, odometry.turn_rad)
        out = Weighed(
            compose_odometry(self.motion, odometry),
            None if frame_s is None else frame_s + self.seconds,
            heading,
            altitude or self.altitude,
            1 + self.frames,
        )
        self._clear()
        return out

    def checkpoint(self) -> dict[str, Any]:
        m = self.motion
        return {
            "paced": [self.frames, m.forward_m, m.left_m, m.turn_rad, self.seconds],
            "paced_readings": [self.heading, self.altitude],
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """From :meth:`checkpoint`'s keys in ``state`` (an older checkpoint held none)."""
        paced = state.get("paced") or [0, 0.0, 0.0, 0.0, 0.0]
        self.frames = int(paced[0])
        self.motion = Odometry(float(paced[1]), float(paced[2]), float(paced[3]))
        self.seconds = float(paced[4])
        heading, altitude = state.get("paced_readings") or (None, None)
        self.heading = from_plain(CompassReading | None, heading)
        self.altitude = from_plain(AltitudeReading | None, altitude)


def _turned(reading: CompassReading | None, turn_rad: float) -> CompassReading | None:
    """A compass reading carried through a turn of the body (None stays None)."""
    if reading is None:
        return None
    return CompassReading(reading.heading_rad + turn_rad, reading.std_rad)
