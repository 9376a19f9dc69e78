"""Venues with several floors: levels, connectors, and the plane the filter works in.

A map file may list ``levels`` (docs/API.md, "Map file"); then every wall, object and
region names its level, and ``connectors`` (elevators, stairs, escalators, ramps) say
where a person can change level: each has one stop (a polygon) per level it serves.
All levels share the file's x/y frame. A file without ``levels`` is one level, exactly
as before.

The filter, the visibility and free-space grids and everything built on them work in
one 2D *plane*: level k (in ordinal order) is laid out at ``x + offset_x[k]``, side by
side with a gap of :data:`LEVEL_GAP_M` between the levels' extents, and a *fence* wall
in the middle of each gap (so no line of sight runs from one level into another
through an open doorway). Objects, walls and visibility are then per level with no
change to any kernel, and a pose on a wrong level is tens of metres from the truth.
For a file without levels the plane is the file's frame. :class:`LevelLayout` maps
between the two.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, field_validator, model_validator

from app.maps.freespace import MapError
from app.validation import Finite, Integer, StrictInput

#: A level or connector id: letters, digits, '_', '-' or '.', starting with a letter or digit.
ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: Free space between two levels laid side by side in the plane, metres.
LEVEL_GAP_M = 20.0
#: A fence reaches this far beyond the levels' extent in y (a line of sight from one
#: level to another stays within their common extent), metres.
FENCE_MARGIN_M = 0.5
#: The elevation of a level that gives none: its ordinal times this, metres.
STOREY_HEIGHT_M = 4.0
#: The kinds of connector and the directions one can be taken in.
ConnectorKind = Literal["elevator", "stairs", "escalator", "ramp"]
Direction = Literal["both", "up", "down"]


def _id_word(value: str) -> str:
    if not ID_PATTERN.match(value):
        raise ValueError(
            f"id {value!r} may hold only letters, digits, '_', '-' and '.', "
            "and must start with a letter or digit"
        )
    return value


class LevelSpec(StrictInput):
    """One floor: its id (what elements name), its spoken name, its ordinal (0 the
    ground floor, negative below) and its elevation (default ordinal x 4 m)."""

    id: str = Field(min_length=1, max_length=64)
    name: str = Field(min_length=1, max_length=200)
    ordinal: Integer = Field(ge=-50, le=200)
    elevation_m: Finite | None = None

    @field_validator("id")
    @classmethod
    def _id_word(cls, value: str) -> str:
        return _id_word(value)


class StopSpec(StrictInput):
    """Where a connector is entered and left on one level (the car, the stairs' landing)."""

    level: str
    polygon: list[tuple[Finite, Finite]] = Field(min_length=3, max_length=200)


class ConnectorSpec(StrictInput):
    """A way between levels: one stop per level it serves."""

    id: str = Field(min_length=1, max_length=64)
    kind: ConnectorKind
    label: str | None = Field(default=None, max_length=200)
    direction: Direction = "both"
    stops: list[StopSpec] = Field(min_length=2, max_length=200)

    @field_validator("id")
    @classmethod
    def _id_word(cls, value: str) -> str:
        return _id_word(value)

    @model_validator(mode="after")
    def _escalator_runs_one_way(self) -> ConnectorSpec:
        if self.kind == "escalator" and self.direction == "both":
            raise ValueError('an escalator runs one way: its direction must be "up" or "down"')
        if self.kind == "escalator" and len(self.stops) != 2:
            raise ValueError(f"an escalator has exactly 2 stops, not {len(self.stops)}")
        return self


# ------------------------------------------------------------------ references
class _OnLevel(Protocol):
    """A wall, object or region of a map file (:mod:`app.maps.model`)."""

    @property
    def level(self) -> str | None: ...


class _Point(Protocol):
    @property
    def x(self) -> float: ...

    @property
    def y(self) -> float: ...


class _Wall(_OnLevel, Protocol):
    @property
    def x1(self) -> float: ...

    @property
    def y1(self) -> float: ...

    @property
    def x2(self) -> float: ...

    @property
    def y2(self) -> float: ...


class _Object(_OnLevel, _Point, Protocol): ...


class MapSpec(Protocol):
    """What this module reads of a map file (:class:`app.maps.model.MapFile`; the model
    imports this module, so it is named by what it holds)."""

    @property
    def name(self) -> str: ...

    @property
    def walls(self) -> Sequence[_Wall]: ...

    @property
    def objects(self) -> Sequence[_Object]: ...

    @property
    def regions(self) -> Sequence[_OnLevel]: ...

    @property
    def levels(self) -> Sequence[LevelSpec] | None: ...

    @property
    def connectors(self) -> Sequence[ConnectorSpec]: ...


def reference_problems(spec: MapSpec) -> list[tuple[str, str]]:
    """Every (field, reason) where levels and the elements naming them disagree.

    With ``levels``: ids and ordinals unique, every wall, object and region on a listed
    level, every connector's id unique, its stops on listed and distinct levels, an
    escalator's two stops on adjacent levels. Without: no element names a level and
    there are no connectors.
    """
    out: list[tuple[str, str]] = []
    elements: tuple[tuple[str, Sequence[_OnLevel]], ...] = (
        ("walls", spec.walls),
        ("objects", spec.objects),
        ("regions", spec.regions),
    )
    if spec.levels is None:
        for key, items in elements:
            for i, item in enumerate(items):
                if item.level is not None and len(out) < 20:
                    out.append((f"{key}[{i}].level", "the map has no levels: remove it"))
        if spec.connectors:
            out.append(("connectors", "the map has no levels: connectors need levels"))
        return out
    if not spec.levels:
        return [("levels", "must list at least one level (or be left out)")]
    ids: dict[str, int] = {}
    ordinals: dict[int, str] = {}
    for i, level in enumerate(spec.levels):
        if level.id in ids:
            out.append((f"levels[{i}].id", f"{level.id!r} is also levels[{ids[level.id]}]'s id"))
        ids.setdefault(level.id, i)
        if level.ordinal in ordinals:
            out.append(
                (
                    f"levels[{i}].ordinal",
                    f"{level.ordinal} is also level {ordinals[level.ordinal]!r}'s ordinal",
                )
            )
        ordinals.setdefault(level.ordinal, level.id)
    known = ", ".join(repr(k) for k in ids)
    for key, items in elements:
        for i, item in enumerate(items):
            if len(out) >= 20:
                break
            if item.level is None:
                out.append((f"{key}[{i}].level", f"missing: the map has levels ({known})"))
            elif item.level not in ids:
                out.append((f"{key}[{i}].level", f"{item.level!r} is not a level ({known})"))
    order = sorted(ordinals)
    rank = {ordinals[o]: r for r, o in enumerate(order)}
    seen: dict[str, int] = {}
    for c, conn in enumerate(spec.connectors):
        where = f"connectors[{c}]"
        if conn.id in seen:
            out.append((f"{where}.id", f"{conn.id!r} is also connectors[{seen[conn.id]}]'s id"))
        seen.setdefault(conn.id, c)
        served: set[str] = set()
        for s, stop in enumerate(conn.stops):
            if stop.level not in ids:
                out.append(
                    (f"{where}.stops[{s}].level", f"{stop.level!r} is not a level ({known})")
                )
            elif stop.level in served:
                out.append((f"{where}.stops[{s}].level", f"a second stop on level {stop.level!r}"))
            served.add(stop.level)
        if conn.kind == "escalator" and served <= set(ids) and len(served) == 2:
            a, b = (rank[s.level] for s in conn.stops)
            if abs(a - b) != 1:
                out.append(
                    (
                        f"{where}.stops",
                        f"escalator {conn.id!r} joins levels {conn.stops[0].level!r} and "
                        f"{conn.stops[1].level!r}, which are not adjacent",
                    )
                )
    return out


# ------------------------------------------------------------------ the layout
@dataclass(frozen=True)
class Level:
    """One level as the map holds it: ``index`` in ordinal order, ``offset_x`` its shift
    in the plane (metres)."""

    index: int
    id: str
    name: str
    ordinal: int
    elevation_m: float
    offset_x: float


@dataclass(frozen=True)
class Stop:
    """A connector's stop: its level's index and its polygon in the file's frame and
    in the plane, shape (V, 2) each."""

    level: int
    polygon: NDArray[np.float64]
    plane_polygon: NDArray[np.float64]


@dataclass(frozen=True)
class Connector:
    """A connector with its stops in ordinal order of their levels."""

    id: str
    kind: str
    label: str | None
    direction: str
    stops: tuple[Stop, ...]

    @property
    def levels(self) -> tuple[int, ...]:
        return tuple(s.level for s in self.stops)

    def stop_on(self, level: int) -> Stop | None:
        for stop in self.stops:
            if stop.level == level:
                return stop
        return None

    def reachable(self, level: int) -> tuple[int, ...]:
        """The levels a person at this connector's stop on ``level`` can ride to: an
        elevator or a ramp any other stop, stairs and escalators the neighbouring stop
        (an escalator only in its direction); none when it does not stop there."""
        pos = [s.level for s in self.stops]
        if level not in pos:
            return ()
        k = pos.index(level)
        if self.kind in ("elevator", "ramp"):
            out = [p for p in pos if p != level]
        else:
            out = [pos[j] for j in (k - 1, k + 1) if 0 <= j < len(pos)]
        if self.direction == "up":
            out = [p for p in out if p > level]
        elif self.direction == "down":
            out = [p for p in out if p < level]
        return tuple(out)


class LevelLayout:
    """The levels of one map file and where each lies in the plane.

    Attributes:
        levels: in ordinal order (empty for a file without levels).
        connectors: every connector, stops in ordinal order.
        wall_level, object_level, region_level: each element's level index (0 for a
            file without levels), shapes (W,), (N,), (R,) in file order.
        fences: the walls added between levels in the plane, rows (x1, y1, x2, y2).
        pitch_m: the plane distance from one level to the next (0 with one level).
    """

    def __init__(self, spec: MapSpec) -> None:
        problems = reference_problems(spec)
        if problems:
            raise MapError(f"{spec.name}: " + "; ".join(f"{f}: {m}" for f, m in problems), problems)
        self.wall_level: NDArray[np.int64]
        self.object_level: NDArray[np.int64]
        self.region_level: NDArray[np.int64]
        if spec.levels is None:
            self.levels: tuple[Level, ...] = ()
            self.connectors: tuple[Connector, ...] = ()
            self.wall_level = np.zeros(len(spec.walls), dtype=np.int64)
            self.object_level = np.zeros(len(spec.objects), dtype=np.int64)
            self.region_level = np.zeros(len(spec.regions), dtype=np.int64)
            self.fences = np.zeros((0, 4), dtype=np.float64)
            self.pitch_m = 0.0
            self.file_bounds = (0.0, 0.0, 0.0, 0.0)
            return
        ordered = sorted(spec.levels, key=lambda lv: lv.ordinal)
        index = {lv.id: k for k, lv in enumerate(ordered)}
        self.wall_level = np.array([index[w.level or ""] for w in spec.walls], dtype=np.int64)
        self.object_level = np.array([index[o.level or ""] for o in spec.objects], dtype=np.int64)
        self.region_level = np.array([index[r.level or ""] for r in spec.regions], dtype=np.int64)
        xs: list[float] = []
        ys: list[float] = []
        for w in spec.walls:
            xs += (w.x1, w.x2)
            ys += (w.y1, w.y2)
        for o in spec.objects:
            xs.append(o.x)
            ys.append(o.y)
        for conn in spec.connectors:
            for stop in conn.stops:
                xs += [p[0] for p in stop.polygon]
                ys += [p[1] for p in stop.polygon]
        x0, x1 = min(xs), max(xs)
        y0, y1 = min(ys), max(ys)
        self.file_bounds = (x0, y0, x1, y1)
        self.pitch_m = (x1 - x0) + LEVEL_GAP_M if len(ordered) > 1 else 0.0
        self.levels = tuple(
            Level(
                k,
                lv.id,
                lv.name,
                int(lv.ordinal),
                lv.ordinal * STOREY_HEIGHT_M if lv.elevation_m is None else float(lv.elevation_m),
                k * self.pitch_m,
            )
            for k, lv in enumerate(ordered)
        )
        fences = []
        for k in range(len(ordered) - 1):
            fx = x1 + LEVEL_GAP_M / 2 + k * self.pitch_m
            fences.append((fx, y0 - FENCE_MARGIN_M, fx, y1 + FENCE_MARGIN_M))
        self.fences = np.array(fences, dtype=np.float64).reshape(-1, 4)
        conns = []
        for conn in spec.connectors:
            stops = sorted(
                (
                    Stop(
                        index[s.level],
                        np.array(s.polygon, dtype=np.float64),
                        self.to_plane(s.polygon, index[s.level]),
                    )
                    for s in conn.stops
                ),
                key=lambda s: s.level,
            )
            conns.append(Connector(conn.id, conn.kind, conn.label, conn.direction, tuple(stops)))
        self.connectors = tuple(conns)

    # ---------------------------------------------------------------- questions
    @property
    def has_levels(self) -> bool:
        """Whether the file lists levels (even one)."""
        return bool(self.levels)

    @property
    def count(self) -> int:
        """How many levels (1 for a file without levels)."""
        return max(len(self.levels), 1)

    def level_index(self, level_id: str) -> int:
        """The index of the level with this id.

        Raises:
            KeyError: naming the id and the map's levels.
        """
        for lv in self.levels:
            if lv.id == level_id:
                return lv.index
        known = ", ".join(repr(lv.id) for lv in self.levels) or "none"
        raise KeyError(f"{level_id!r} is not a level of this map (levels: {known})")

    def connector(self, connector_id: str) -> Connector:
        for conn in self.connectors:
            if conn.id == connector_id:
                return conn
        raise KeyError(f"{connector_id!r} is not a connector of this map")

    # ---------------------------------------------------------------- the plane
    def offsets(self, level: ArrayLike) -> NDArray[np.float64]:
        """The plane x offset of each level index (0 without levels)."""
        lv = np.asarray(level, dtype=np.int64)
        return lv.astype(np.float64) * self.pitch_m

    def to_plane(self, xy: ArrayLike, level: ArrayLike) -> NDArray[np.float64]:
        """File-frame points (shape (M, 2)) on the given levels, in the plane."""
        pts = np.array(xy, dtype=np.float64).reshape(-1, 2)
        pts[:, 0] += self.offsets(np.broadcast_to(np.asarray(level), pts.shape[:1]))
        return pts

    def level_of(self, x: float) -> int:
        """:meth:`level_of_plane_x` of one plane x."""
        return int(self.level_of_plane_x(np.array(x)))

    def level_of_plane_x(self, x: ArrayLike) -> NDArray[np.int64]:
        """The level index a plane x lies on (the nearest level's extent), shape of x."""
        xa = np.asarray(x, dtype=np.float64)
        if self.pitch_m <= 0.0:
            return np.zeros(xa.shape, dtype=np.int64)
        x0 = self.file_bounds[0]
        k = np.floor((xa - x0 + LEVEL_GAP_M / 2) / self.pitch_m).astype(np.int64)
        return np.clip(k, 0, len(self.levels) - 1)

    def from_plane(self, xy: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Plane points (shape (M, 2)) as file-frame points and level indices."""
        pts = np.array(xy, dtype=np.float64).reshape(-1, 2)
        level = self.level_of_plane_x(pts[:, 0])
        pts[:, 0] -= self.offsets(level)
        return pts, level

    def plane_walls(self, walls: NDArray[np.float64]) -> NDArray[np.float64]:
        """The file's walls (rows x1, y1, x2, y2) shifted to their levels, then the fences."""
        if not self.levels:
            return walls
        shifted = walls.copy()
        off = self.offsets(self.wall_level)
        shifted[:, 0] += off
        shifted[:, 2] += off
        return np.vstack([shifted, self.fences])

    def plane_points(
        self, xy: NDArray[np.float64], level: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Points (M, 2) shifted to their levels (the same array without levels)."""
        if not self.levels:
            return xy
        return self.to_plane(xy, level)

    def plane_polygons(
        self, polygons: Sequence[NDArray[np.float64]], level: NDArray[np.int64]
    ) -> list[NDArray[np.float64]]:
        if not self.levels:
            return list(polygons)
        return [self.to_plane(p, k) for p, k in zip(polygons, level, strict=True)]
