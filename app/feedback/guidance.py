"""Speaking the way to a destination, in the narrator's style.

"Main entrance: go to 1 o'clock, 3 metres, then to 3 o'clock." names the target, the
direction and distance of the next turn of the path (or of the target itself when the
way is straight), and the turn to take there (relative to the direction walked until
then). It is spoken when guidance starts, again whenever the direction to walk changes
by an hour on the clock (at most every ``MIN_GAP_S`` seconds), and every ``REPEAT_S``
seconds while the person walks; once on
arrival ("You have arrived at main entrance."). While the filter has not converged no
direction is given, since it would rest on a position that is not known: the person
hears "Finding where you are before guiding you." instead.

When the way changes level next, the directions lead to the connector and name it,
"The escalator up to the First Floor: go to 1 o'clock, 5 metres.", and once the person
stands at it: "Take the escalator up to the First Floor." Each is said as soon as it
applies (a new connector, or arriving at one), at most every ``MIN_GAP_S`` seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.feedback.phrasing import (
    FEET_PER_METRE,
    Style,
    Units,
    capitalize,
    clock_distance_hours,
    clock_from_bearing_deg,
    direction_phrase,
)
from app.guidance import ConnectorStep, Guidance

#: Repeat the directions this often while the person walks (seconds).
REPEAT_S = 10.0
#: A change of direction is spoken at most this often (seconds): turning on the spot
#: sweeps the clock an hour at a time, and speech must keep up.
MIN_GAP_S = 2.0
#: Moving at least this far since the last directions counts as walking (metres).
WALKING_M = 1.0
#: Repeat "Finding where you are..." at most this often (seconds).
FINDING_REPEAT_S = 30.0
#: After arriving, the arrival is announced again only once the person is this far away.
LEAVE_M = 2.5

FINDING = "Finding where you are before guiding you."


def _distance(distance_m: float, units: Units) -> str:
    """A short distance for directions: '3 metres', '1 metre', '10 feet'."""
    if units == "imperial":
        feet = distance_m * FEET_PER_METRE
        return "less than 3 feet" if feet < 3 else f"{round(feet)} feet"
    if distance_m < 1.0:
        return "less than a metre"
    n = round(distance_m)
    return "1 metre" if n == 1 else f"{n} metres"


def _towards(bearing_deg: float, style: Style) -> str:
    if style == "clock":
        return f"to {clock_from_bearing_deg(bearing_deg)} o'clock"
    return direction_phrase(bearing_deg, style)


def level_phrase(name: str) -> str:
    """'the First Floor', but 'Level 2' and '2nd floor'... as they are."""
    words = name.split()
    bare = name[:1].isdigit() or (words and words[0].casefold() in ("level", "floor", "the"))
    return name if bare else f"the {name}"


def connector_phrase(step: ConnectorStep) -> str:
    """'the escalator up to the First Floor'."""
    return f"the {step.kind} {step.direction} to {level_phrase(step.to_level.name)}"


def directions(g: Guidance, style: Style = "clock", units: Units = "metric") -> str:
    """The sentence for one set of directions (see the module docstring)."""
    if g.arrived:
        return f"You have arrived at {g.target}."
    where = g.target
    if g.connector is not None:
        if g.connector.at_stop:
            return f"Take {connector_phrase(g.connector)}."
        where = connector_phrase(g.connector)
    if g.next is None:
        return (
            f"{capitalize(where)}: go {_towards(g.bearing_deg, style)}, "
            f"{_distance(g.distance_m, units)}."
        )
    return (
        f"{capitalize(where)}: go {_towards(g.next.bearing_deg, style)}, "
        f"{_distance(g.next.distance_m, units)}, then {_towards(g.next.then_deg, style)}."
    )


def _step_key(g: Guidance) -> tuple[str, int, bool] | None:
    """What must be said anew when it changes: the connector ahead and being at it."""
    c = g.connector
    return None if c is None else (c.id, c.to_level.index, c.at_stop)


@dataclass
class GuidanceSpeaker:
    """Per-session memory of what was said about the way, so it is not repeated."""

    style: Style = "clock"
    units: Units = "metric"
    _said_at: float | None = None
    _clock: int | None = None
    _where: tuple[float, float] | None = None
    _finding_at: float | None = None
    _arrived: bool = False
    _step: tuple[str, int, bool] | None = None

    def reset(self) -> None:
        """A new destination (or none): start afresh."""
        self._said_at = self._clock = self._where = self._finding_at = None
        self._arrived = False
        self._step = None

    def no_way(self, target: str, now: float, step_free: bool = False) -> str:
        """Located, but no walkable way (no step-free one, with ``step_free``) leads from
        here to ``target`` (said now and then)."""
        self._said_at = self._clock = self._where = None
        if self._finding_at is None or not 0 <= now - self._finding_at < FINDING_REPEAT_S:
            self._finding_at = now
            way = "a step-free way" if step_free else "a way"
            return f"I cannot find {way} from here to {target}."
        return ""

    def update(
        self, guidance: Guidance | None, converged: bool, now: float, x: float, y: float
    ) -> str:
        """What to say about the way this frame (often nothing)."""
        if not converged or guidance is None:
            self._said_at = self._clock = self._where = None
            if self._finding_at is None or not 0 <= now - self._finding_at < FINDING_REPEAT_S:
                self._finding_at = now
                return FINDING
            return ""
        self._finding_at = None
        if guidance.arrived:
            if self._arrived:
                return ""
            self._arrived = True
            self._said_at, self._where = now, (x, y)
            return directions(guidance, self.style, self.units)
        if self._arrived:
            if guidance.path_m < LEAVE_M:
                return ""  # still at the target, a step or two away: nothing new
            self._arrived = False
            self._said_at = self._clock = None  # walked away: guide afresh
        aim = guidance.next.bearing_deg if guidance.next is not None else guidance.bearing_deg
        clock = clock_from_bearing_deg(aim)
        walked = (
            self._where is not None
            and ((x - self._where[0]) ** 2 + (y - self._where[1]) ** 2) ** 0.5 >= WALKING_M
        )
        since = None if self._said_at is None else now - self._said_at
        step = _step_key(guidance)
        due = (
            since is None
            or self._clock is None
            or (
                not 0 <= since < MIN_GAP_S  # (a clock going backwards counts as due)
                and (
                    step != self._step
                    or clock_distance_hours(self._clock, clock) >= 1
                    or (walked and since >= REPEAT_S)
                )
            )
        )
        if not due:
            return ""
        self._said_at, self._clock, self._where = now, clock, (x, y)
        self._step = step
        return directions(guidance, self.style, self.units)
