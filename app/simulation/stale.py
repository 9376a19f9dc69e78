"""A stale map: the world as it is now, against the map drawn some time ago.

Furniture moves, things are taken away and new things appear; doors and windows stay
in their walls. :func:`stale_world` makes the present world from the map the filter
holds: objects moved by ``move_m`` in a random direction (to free space), removed, or
added at random free places. The simulator draws detections from this world while the
filter weighs them against the old map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.maps.model import FIXTURE_CLASSES, SemanticMap, parse_map


@dataclass(frozen=True)
class StaleMap:
    """How much changed since the map was drawn (shares of the map's objects, each at
    least one object when above zero)."""

    moved_share: float = 0.1
    move_m: tuple[float, float] = (1.0, 1.5)
    removed_share: float = 0.05
    added_share: float = 0.05

    def __post_init__(self) -> None:
        for name in ("moved_share", "removed_share", "added_share"):
            share = getattr(self, name)
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"StaleMap.{name} must be in [0, 1], got {share}")
        lo, hi = self.move_m
        if not 0.0 < lo <= hi:
            raise ValueError(f"StaleMap.move_m must be 0 < low <= high, got {self.move_m}")


def _count(share: float, n: int) -> int:
    return 0 if share <= 0.0 else max(1, round(share * n))


def stale_world(
    semantic_map: SemanticMap, stale: StaleMap, rng: np.random.Generator
) -> SemanticMap:
    """The world today: ``semantic_map`` with objects moved, removed and added."""
    spec = semantic_map.to_json()
    objects = [dict(o) for o in spec["objects"]]  # type: ignore[attr-defined]
    n = len(objects)
    free = semantic_map.free_space
    # Fixtures are never moved (a moved door is a different building).
    movable = [i for i in range(n) if not semantic_map.fixed[i]]
    n_move = min(_count(stale.moved_share, n), len(movable))
    for i in rng.permutation(movable)[:n_move]:
        x0, y0 = float(objects[i]["x"]), float(objects[i]["y"])
        for _ in range(50):
            angle = rng.uniform(0.0, 2.0 * np.pi)
            dist = rng.uniform(*stale.move_m)
            x, y = x0 + dist * np.cos(angle), y0 + dist * np.sin(angle)
            if bool(free.is_free(x, y)):
                objects[i]["x"], objects[i]["y"] = round(float(x), 3), round(float(y), 3)
                break
    n_remove = min(_count(stale.removed_share, n), n - 1)
    removed = set(int(i) for i in rng.permutation(n)[:n_remove])
    kept = [o for i, o in enumerate(objects) if i not in removed]
    loose = sorted({o["class"] for o in objects if o["class"] not in FIXTURE_CLASSES})
    classes = loose or sorted({o["class"] for o in objects})
    for _ in range(_count(stale.added_share, n)):
        x, y = free.sample(1, rng)[0]
        cls = classes[int(rng.integers(len(classes)))]
        kept.append({"class": cls, "x": round(float(x), 3), "y": round(float(y), 3)})
    spec["objects"] = kept
    return parse_map(spec, source=f"stale copy of {semantic_map.name}")
