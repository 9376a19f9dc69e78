"""What a person may ask to be guided to, resolved against the map.

A destination is an object's label ("main entrance"), an object class ("door": the
nearest door by walking distance), a region ("Kitchen": the nearest point of it) or a
point in map metres. Names are matched without regard to case; an unknown name is
refused with the closest names the map does have.

On a venue with several levels a destination may name its level: a point needs one
(its x, y are in that level's frame), a label, class or region is then looked for on
that level only (else on all of them, the nearest by walking distance winning). A
``step_free`` destination is reached through lifts and ramps only. Resolved points
are in the map's plane (:mod:`app.maps.levels`), like every array of the map.
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
    """What was asked for: one of label, class, region, or a point (x, y); on which
    level (an id, or None: any, or the only one), and whether the way must be step-free."""

    kind: Kind
    name: str = ""
    x: float = 0.0
    y: float = 0.0
    level: str | None = None
    step_free: bool = False

    @property
    def key(self) -> tuple[object, ...]:
        """A hashable identity (case-folded names) for caching plans."""
        if self.kind == "point":
            return ("point", round(self.x, 3), round(self.y, 3), self.level, self.step_free)
        return (self.kind, self.name.casefold(), self.level, self.step_free)


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
        step_free: reached through lifts and ramps only.
    """

    name: str
    kind: Kind
    points: NDArray[np.float64]
    objects: NDArray[np.int64]
    region: int = -1
    step_free: bool = False


def _suggest(word: str, names: list[str]) -> str:
    lowered = {n.casefold(): n for n in names}
    close = difflib.get_close_matches(word.casefold(), list(lowered), n=3, cutoff=0.5)
    if close:
        return "did you mean " + ", ".join(repr(lowered[c]) for c in close) + "?"
    shown = sorted(names)[:12]
    more = "" if len(names) <= 12 else f" (and {len(names) - 12} more)"
    return ("known: " + ", ".join(repr(n) for n in shown) + more) if names else "it has none"


def _level(m: SemanticMap, spec: DestinationSpec) -> int | None:
    """The index of the level asked for (None: any)."""
    if spec.level is None:
        return None
    layout = m.layout
    if not layout.has_levels:
        raise UnknownDestination(f"level: map {m.name!r} has no levels; leave level out")
    try:
        return layout.level_index(spec.level)
    except KeyError as exc:
        raise UnknownDestination(f"level: {exc.args[0]}") from None


def resolve(semantic_map: SemanticMap, spec: DestinationSpec) -> Target:
    """The map's objects, region or point that ``spec`` names.

    Raises:
        UnknownDestination: nothing by that name (on the level asked for); the message
            lists close names.
    """
    m = semantic_map
    where = f"map {m.name!r}"
    level = _level(m, spec)
    layout = m.layout
    on_level = (
        np.ones(m.object_count, dtype=bool) if level is None else layout.object_level == level
    )
    if level is not None:
        where += f", level {layout.levels[level].id!r}"
    free = spec.step_free
    if spec.kind == "label":
        labels = [lb for lb, ok in zip(m.object_labels, on_level, strict=True) if lb and ok]
        idx = [
            i
            for i, lb in enumerate(m.object_labels)
            if lb and lb.casefold() == spec.name.casefold() and on_level[i]
        ]
        if not idx:
            raise UnknownDestination(
                f"label: no object labelled {spec.name!r} on {where}; {_suggest(spec.name, labels)}"
            )
        found = np.array(idx, dtype=np.int64)
        name = m.object_labels[idx[0]] or spec.name
        return Target(name, "label", m.object_xy[found], found, step_free=free)
    if spec.kind == "class":
        cls = spec.name.casefold()
        members = m.class_members.get(cls, np.zeros(0, dtype=np.int64))
        found = members[on_level[members]]
        if not found.size:
            present = sorted({m.class_of(int(i)) for i in np.flatnonzero(on_level)})
            raise UnknownDestination(
                f"class: no object of class {spec.name!r} on {where}; "
                f"{_suggest(spec.name, present)}"
            )
        return Target(cls, "class", m.object_xy[found], found, step_free=free)
    if spec.kind == "region":
        names = [
            n
            for i, n in enumerate(m.region_names)
            if level is None or layout.region_level[i] == level
        ]
        for i, n in enumerate(m.region_names):
            if level is not None and layout.region_level[i] != level:
                continue
            if n.casefold() == spec.name.casefold():
                empty = np.zeros((0, 2))
                return Target(n, "region", empty, np.zeros(0, dtype=np.int64), i, step_free=free)
        raise UnknownDestination(
            f"region: no region named {spec.name!r} on {where}; {_suggest(spec.name, names)}"
        )
    if layout.has_levels:
        if level is None:
            known = ", ".join(repr(lv.id) for lv in layout.levels)
            raise UnknownDestination(
                f"level: a point on {where} needs the level it is on (one of {known})"
            )
        min_x, min_y, max_x, max_y = layout.file_bounds
    else:
        min_x, min_y, max_x, max_y = m.bounds
    if not (min_x <= spec.x <= max_x and min_y <= spec.y <= max_y):
        raise UnknownDestination(
            f"x, y: the point ({spec.x:g}, {spec.y:g}) is outside {where} "
            f"(x {min_x:g} to {max_x:g}, y {min_y:g} to {max_y:g})"
        )
    name = f"the point {spec.x:.1f}, {spec.y:.1f}"
    point = np.array([[spec.x, spec.y]], dtype=np.float64)
    if level is not None:
        name += f" on {layout.levels[level].name}"
        point = layout.to_plane(point, level)
    return Target(name, "point", point, np.array([-1], dtype=np.int64), step_free=free)
