"""What a person may ask to be guided to, resolved against the map.

A destination is an object's label ("main entrance"), an object class ("door": the
nearest door by walking distance), a region ("Kitchen": the nearest point of it) or a
point in map metres. Names are matched without regard to case; an unknown name is
refused with the closest names the map does have.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from app.maps.model import SemanticMap

Kind = Literal["label", "class", "region", "point"]


class UnknownDestination(LookupError):
    """The map has nothing by that name (or the point is outside it); says what it has."""


@dataclass(frozen=True)
class DestinationSpec:
    """What was asked for: one of label, class, region, or a point (x, y)."""

    kind: Kind
    name: str = ""
    x: float = 0.0
    y: float = 0.0

    @property
    def key(self) -> tuple[object, ...]:
        """A hashable identity (case-folded names) for caching plans."""
        if self.kind == "point":
            return ("point", round(self.x, 3), round(self.y, 3))
        return (self.kind, self.name.casefold())


@dataclass(frozen=True)
class Target:
    """A resolved destination.

    Attributes:
        name: how to speak it ("main entrance", "door", "Kitchen", "the point 3.0, 4.5").
        kind: what was asked for.
        points: candidate end points (metres), shape (K, 2): the objects of a class, the
            one labelled object (or several sharing the label), the point; empty for a
            region, whose end is wherever the path enters it.
        objects: the map object index of each point (-1 for a plain point), shape (K,).
        region: the region's index for a region destination, else -1.
    """

    name: str
    kind: Kind
    points: NDArray[np.float64]
    objects: NDArray[np.int64]
    region: int = -1


def _suggest(word: str, names: list[str]) -> str:
    lowered = {n.casefold(): n for n in names}
    close = difflib.get_close_matches(word.casefold(), list(lowered), n=3, cutoff=0.5)
    if close:
        return "did you mean " + ", ".join(repr(lowered[c]) for c in close) + "?"
    shown = sorted(names)[:12]
    more = "" if len(names) <= 12 else f" (and {len(names) - 12} more)"
    return ("known: " + ", ".join(repr(n) for n in shown) + more) if names else "it has none"


def resolve(semantic_map: SemanticMap, spec: DestinationSpec) -> Target:
    """The map's objects, region or point that ``spec`` names.

    Raises:
        UnknownDestination: nothing by that name; the message lists close names.
    """
    m = semantic_map
    where = f"map {m.name!r}"
    if spec.kind == "label":
        labels = [lb for lb in m.object_labels if lb]
        idx = [
            i
            for i, lb in enumerate(m.object_labels)
            if lb and lb.casefold() == spec.name.casefold()
        ]
        if not idx:
            raise UnknownDestination(
                f"label: no object labelled {spec.name!r} on {where}; {_suggest(spec.name, labels)}"
            )
        found = np.array(idx, dtype=np.int64)
        return Target(m.object_labels[idx[0]] or spec.name, "label", m.object_xy[found], found)
    if spec.kind == "class":
        cls = spec.name.casefold()
        if cls not in m.class_members:
            raise UnknownDestination(
                f"class: no object of class {spec.name!r} on {where}; "
                f"{_suggest(spec.name, list(m.classes))}"
            )
        found = m.class_members[cls]
        return Target(cls, "class", m.object_xy[found], found)
    if spec.kind == "region":
        names = list(m.region_names)
        for i, n in enumerate(names):
            if n.casefold() == spec.name.casefold():
                return Target(n, "region", np.zeros((0, 2)), np.zeros(0, dtype=np.int64), i)
        raise UnknownDestination(
            f"region: no region named {spec.name!r} on {where}; {_suggest(spec.name, names)}"
        )
    min_x, min_y, max_x, max_y = m.bounds
    if not (min_x <= spec.x <= max_x and min_y <= spec.y <= max_y):
        raise UnknownDestination(
            f"x, y: the point ({spec.x:g}, {spec.y:g}) is outside {where} "
            f"(x {min_x:g} to {max_x:g}, y {min_y:g} to {max_y:g})"
        )
    return Target(
        f"the point {spec.x:.1f}, {spec.y:.1f}",
        "point",
        np.array([[spec.x, spec.y]], dtype=np.float64),
        np.array([-1], dtype=np.int64),
    )
