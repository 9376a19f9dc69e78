"""Words for directions and distances, as a person would say them.

Bearings are counter-clockwise positive (left is +90 deg) while a clock runs
clockwise, so the clock hour comes from the negated bearing: 12 is straight ahead,
3 to the right, 6 behind, 9 to the left.
"""

from __future__ import annotations

from typing import Literal

from app.maps.geometry import wrap_deg

Style = Literal["clock", "left_right", "degrees"]
Units = Literal["metric", "imperial"]

FEET_PER_METRE = 3.28084


def clock_from_bearing_deg(bearing_deg: float) -> int:
    """Clock hour 1..12 of a bearing (degrees, CCW positive, 0 straight ahead)."""
    hour = round(-wrap_deg(bearing_deg) / 30.0) % 12
    return 12 if hour == 0 else int(hour)


def clock_distance_hours(a: int, b: int) -> int:
    """How many hours apart two clock positions are (0..6)."""
    d = abs(a - b) % 12
    return min(d, 12 - d)


def direction_phrase(bearing_deg: float, style: Style = "clock") -> str:
    """Where something is relative to the person: 'at 2 o'clock', 'ahead to the left'..."""
    b = wrap_deg(bearing_deg)
    if style == "clock":
        return f"at {clock_from_bearing_deg(b)} o'clock"
    side = "left" if b > 0 else "right"
    mag = abs(b)
    if style == "degrees":
        if mag < 3:
            return "straight ahead"
        if mag > 177:
            return "straight behind you"
        return f"{mag:.0f} degrees to the {side}"
    if mag < 15:
        return "straight ahead"
    if mag < 60:
        return f"ahead to the {side}"
    if mag < 120:
        return f"to your {side}"
    if mag < 165:
        return f"behind you to the {side}"
    return "behind you"


def distance_phrase(distance_m: float, units: Units = "metric", *, certain: bool = True) -> str:
    """A distance rounded as people speak: 'less than a metre', 'about 3 metres'.

    ``certain=False`` hedges more ('roughly').
    """
    hedge = "about" if certain else "roughly"
    if units == "imperial":
        feet = distance_m * FEET_PER_METRE
        if feet < 3:
            return "less than 3 feet"
        n = round(feet) if feet < 10 else 5 * round(feet / 5)
        return f"{hedge} {n} feet"
    if distance_m < 1.0:
        return "less than a metre"
    if distance_m < 1.5:
        return "1 metre" if certain else "roughly 1 metre"
    n = round(distance_m) if distance_m < 10 else 5 * round(distance_m / 5)
    return f"{hedge} {n} metres"


def capitalize(text: str) -> str:
    return text[:1].upper() + text[1:]


def article(word: str) -> str:
    return ("an " if word[:1].lower() in "aeiou" else "a ") + word
