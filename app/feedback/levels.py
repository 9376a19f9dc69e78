"""What is said of the floor a person is on: "You are on the First Floor."

Said once the filter confirms a level (its first fix on a map with levels, and every
confirmed change after a ride), never while the person is between floors.
"""

from __future__ import annotations

#: Words that make a level's name read as a common noun ("the First Floor",
#: "the Mezzanine"); other names are said bare ("Level 2", "B1").
_COMMON = ("floor", "basement", "mezzanine", "concourse", "ground", "lobby", "platform")


def level_sentence(name: str) -> str:
    """The sentence announcing level ``name``."""
    words = name.lower().split()
    article = "the " if words and words[-1] in _COMMON else ""
    return f"You are on {article}{name}."
