"""The annotated 2D floor map: file schema, validation, and array form for the filter.

A map file (see docs/API.md) holds walls, semantic objects (class, position, optional
label) and optional named regions. :func:`load_map` validates a file with pydantic and
refuses anything invalid with a message that names the field and the reason;
:class:`SemanticMap` is the validated map as numpy arrays, plus the free-space and
visibility grids the filter needs once the map is prepared. Preparing is a step of its
own (:mod:`app.maps.prepare`, which stands on this module): the loaders do it
(:func:`app.maps.check.load_map`, :func:`~app.maps.check.load_map_dirs`), and code that
needs the grids of a map it built itself calls :func:`app.maps.prepare.ensure_prepared`.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable
from functools import cached_property
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, ValidationError, field_validator, model_validator

from app.maps.freespace import WALL_CLEARANCE_M as WALL_CLEARANCE_M  # re-exported
from app.maps.freespace import FreeSpaceGrid as FreeSpaceGrid  # re-exported
from app.maps.freespace import MapError as MapError  # re-exported
from app.maps.geometry import (
    PolygonCells,
    first_polygon,
    nearest_walls,
    polygon_edges,
    segments_cross_walls,
)
from app.maps.levels import ConnectorSpec, LevelLayout, LevelSpec, reference_problems
from app.maps.visibility import VisibilityGrid
from app.validation import Finite, StrictInput, problem_text

#: An object class is a lower-case word: letters, digits, '_' or '-', starting with a letter.
CLASS_PATTERN = re.compile(r"^[a-z][a-z0-9_-]*$")
#: A map name is usable as a file name and in a URL.
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: An object closer than this to a wall is mounted in it (doors, windows), in metres.
MOUNT_TOLERANCE_M = 0.05
#: Classes that are part of the building: they stay where the plan puts them (a door
#: drawn in a gap between two walls is no farther than its frame from where it is).
#: Furniture, plants and machines move; these do not (:attr:`SemanticMap.fixed`).
FIXTURE_CLASSES = frozenset(
    {"door", "window", "exit", "entrance", "elevator", "lift", "stairs", "escalator"}
)
#: Values kept per map in :attr:`SemanticMap.derived` (per set of detected classes: a
#: few dozen in a real walk).
DERIVED_LIMIT = 1024

T = TypeVar("T")


class MapNotPrepared(RuntimeError):
    """A map's grids were asked for before the map was prepared (a programming error:
    prepare it first, see :mod:`app.maps.prepare`)."""


class WallSpec(StrictInput):
    """A wall segment from (x1, y1) to (x2, y2), metres."""

    x1: Finite
    y1: Finite
    x2: Finite
    y2: Finite
    level: str | None = None

    @model_validator(mode="after")
    def _has_length(self) -> WallSpec:
        if self.x1 == self.x2 and self.y1 == self.y2:
            raise ValueError("a wall must have two distinct end points")
        return self


class ObjectSpec(StrictInput):
    """A semantic landmark: its class, its position (metres) and an optional label."""

    cls: str = Field(alias="class", description="lower-case class word, e.g. door")
    x: Finite
    y: Finite
    label: str | None = Field(default=None, max_length=200)
    level: str | None = None

    @field_validator("cls")
    @classmethod
    def _class_word(cls, value: str) -> str:
        if not CLASS_PATTERN.match(value):
            raise ValueError(
                f"class {value!r} must be one lower-case word (letters, digits, '_' or '-')"
            )
        return value


class RegionSpec(StrictInput):
    """A named polygon (room, corridor) used for spoken feedback."""

    name: str = Field(min_length=1, max_length=200)
    polygon: list[tuple[Finite, Finite]] = Field(min_length=3)
    level: str | None = None


class MapFile(StrictInput):
    """The JSON map file as docs/API.md describes it."""

    name: str
    description: str = ""
    walls: list[WallSpec] = Field(default_factory=list)
    objects: list[ObjectSpec] = Field(min_length=1)
    regions: list[RegionSpec] = Field(default_factory=list)
    #: Venues with several floors (:mod:`app.maps.levels`); None: one level, as before.
    levels: list[LevelSpec] | None = None
    connectors: list[ConnectorSpec] = Field(default_factory=list)

    @field_validator("name")
    @classmethod
    def _usable_name(cls, value: str) -> str:
        if not NAME_PATTERN.match(value):
            raise ValueError(
                f"name {value!r} may hold only letters, digits, '_', '-' and '.', "
                "and must start with a letter or digit"
            )
        return value


def _validation_error(source: str, error: ValidationError) -> MapError:
    fields = []
    for item in error.errors():
        where = ".".join(str(p) for p in item["loc"]) or "(file)"
        fields.append((where, problem_text(item)))
    return MapError(f"{source}: " + "; ".join(f"{f}: {m}" for f, m in fields), fields)


def validate_spec(
    data: object, *, source: str = "map", expected_name: str | None = None
) -> MapFile:
    """Validate already-decoded JSON against the file schema.

    Raises:
        MapError: naming the offending field and the reason.
    """
    try:
        spec = MapFile.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(source, exc) from None
    problems = reference_problems(spec)
    if problems:
        raise MapError(f"{source}: " + "; ".join(f"{f}: {m}" for f, m in problems), problems)
    if expected_name is not None and spec.name != expected_name:
        reason = f"{spec.name!r} must equal the file name without .json ({expected_name!r})"
        raise MapError(f"{source}: name: {reason}", [("name", reason)])
    return spec


def parse_map(
    data: object, *, source: str = "map", expected_name: str | None = None
) -> SemanticMap:
    """Validate already-decoded JSON and build a :class:`SemanticMap`.

    Raises:
        MapError: naming the offending field and the reason.
    """
    return SemanticMap(validate_spec(data, source=source, expected_name=expected_name))


class SemanticMap:
    """A validated map as arrays.

    Attributes:
        spec: the validated file.
        walls: rows (x1, y1, x2, y2), shape (W, 4), metres.
        object_xy: object centres, shape (N, 2), metres.
        object_class: index into ``classes`` per object, shape (N,).
        classes: the sorted distinct class words.
        class_members: per class, the indices of its objects.
        mounted_walls: whether object n lies on wall w (doors, windows), shape (N, W).
    """

    def __init__(self, spec: MapFile, *, grid_resolution_m: float | None = None) -> None:
        self.spec = spec
        #: Values other modules derive from the map and keep with it (keyed by a tuple
        #: whose first item names the user), so they go when the map goes.
        self.derived: dict[tuple[object, ...], Any] = {}
        self.name = spec.name
        self.description = spec.description
        #: The levels and connectors, each element's level, and the plane every array
        #: below is in (the file's frame for a map without levels; see app.maps.levels).
        self.layout = layout = LevelLayout(spec)
        self.walls = layout.plane_walls(
            np.array([[w.x1, w.y1, w.x2, w.y2] for w in spec.walls], dtype=np.float64).reshape(
                -1, 4
            )
        )
        self.object_xy = layout.plane_points(
            np.array([[o.x, o.y] for o in spec.objects], dtype=np.float64), layout.object_level
        )
        self.classes: tuple[str, ...] = tuple(sorted({o.cls for o in spec.objects}))
        index = {c: i for i, c in enumerate(self.classes)}
        self.object_class = np.array([index[o.cls] for o in spec.objects], dtype=np.int64)
        self.object_labels: tuple[str | None, ...] = tuple(o.label for o in spec.objects)
        self.class_members: dict[str, NDArray[np.int64]] = {
            c: np.flatnonzero(self.object_class == i) for i, c in enumerate(self.classes)
        }
        self.region_names: tuple[str, ...] = tuple(r.name for r in spec.regions)
        self.region_polygons = layout.plane_polygons(
            [np.array(r.polygon, dtype=np.float64) for r in spec.regions], layout.region_level
        )
        #: Object n is mounted in wall w: within MOUNT_TOLERANCE_M of it.
        self.mounted_walls = nearest_walls(self.object_xy, self.walls, MOUNT_TOLERANCE_M)[2]
        self._grid_resolution_m = grid_resolution_m
        self._free_space: FreeSpaceGrid | None = None
        self._visibility: VisibilityGrid | None = None

    def __repr__(self) -> str:
        return (
            f"SemanticMap({self.name!r}, walls={len(self.walls)}, "
            f"objects={len(self.object_xy)}, classes={list(self.classes)})"
        )

    @property
    def object_count(self) -> int:
        return int(self.object_xy.shape[0])

    def derived_value(self, key: tuple[object, ...], make: Callable[[], T]) -> T:
        """The value kept under ``key`` in :attr:`derived`, made (and kept) if absent;
        the oldest goes when :data:`DERIVED_LIMIT` values are kept."""
        derived = self.derived
        found = derived.get(key)
        if found is None:
            found = make()
            if len(derived) >= DERIVED_LIMIT:
                # Another thread (the view, a planner) may be changing the dict too: then
                # some other value goes, or none; a value made twice is the same value.
                with contextlib.suppress(StopIteration, RuntimeError, KeyError):
                    derived.pop(next(iter(derived)))
            derived[key] = found
        return found

    def class_indexes(self, classes: tuple[str, ...]) -> NDArray[np.int64]:
        """The index in :attr:`classes` of each of ``classes`` (kept per tuple: the
        filter asks for the same few sets of detected classes frame after frame)."""
        return self.derived_value(
            ("class_indexes", classes),
            lambda: np.array([self.classes.index(c) for c in classes], dtype=np.int64),
        )

    def class_of(self, index: int) -> str:
        return self.classes[int(self.object_class[index])]

    @cached_property
    def fixed(self) -> NDArray[np.bool_]:
        """Per object, whether it is part of the building and cannot have been moved
        since the map was drawn: of a :data:`FIXTURE_CLASSES` class or mounted in a
        wall, shape (N,)."""
        fixture = np.array([c in FIXTURE_CLASSES for c in self.classes], dtype=bool)
        return fixture[self.object_class] | self.mounted_walls.any(axis=1)

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) over walls and objects, metres."""
        pts = [self.object_xy]
        if self.walls.shape[0]:
            pts += [self.walls[:, 0:2], self.walls[:, 2:4]]
        allp = np.vstack(pts)
        lo = allp.min(axis=0)
        hi = allp.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def line_of_sight(
        self, points: ArrayLike, objects: ArrayLike | None = None
    ) -> NDArray[np.bool_]:
        """Whether each object is visible from each point (no wall in between).

        An object mounted in a wall is not hidden by that wall.

        Args:
            points: viewpoints, shape (M, 2).
            objects: object indices, shape (K,); all objects when None.

        Returns:
            Boolean array, shape (M, K).
        """
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        idx = np.arange(self.object_count) if objects is None else np.asarray(objects).reshape(-1)
        out = np.ones((pts.shape[0], idx.size), dtype=bool)
        if self.walls.shape[0] == 0:
            return out
        for k, n in enumerate(idx):
            target = np.broadcast_to(self.object_xy[n], pts.shape)
            blocked = segments_cross_walls(pts, target, self.walls, ignore=self.mounted_walls[n])
            out[:, k] = ~blocked
        return out

    @cached_property
    def _region_edges(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Every region polygon's edges at once (:func:`polygon_edges`)."""
        return polygon_edges(self.region_polygons)

    @cached_property
    def _region_cells(self) -> PolygonCells:
        """The regions on a grid, for :meth:`region_at` (built on first use)."""
        return PolygonCells(*self._region_edges)

    def region_index(self, points: ArrayLike) -> NDArray[np.int64]:
        """Index of the first region containing each point, or -1, shape (M,)."""
        return first_polygon(points, *self._region_edges)

    def region_at(self, x: float, y: float) -> str | None:
        """The name of the region containing (x, y), or None; the same answer as
        :meth:`region_index`, mostly from a grid (called per hypothesis every frame)."""
        i = self._region_cells.first(x, y)
        return self.region_names[i] if i >= 0 else None

    @property
    def grid_resolution_m(self) -> float | None:
        """The free-space grid's cell side asked for, or None for the automatic one."""
        return self._grid_resolution_m

    @property
    def prepared(self) -> bool:
        """Whether the map holds its grids (:mod:`app.maps.prepare`)."""
        return self._visibility is not None

    def attach(self, free_space: FreeSpaceGrid, visibility: VisibilityGrid) -> None:
        """Hold the grids built (or read from the cache) for this map."""
        if visibility.n_objects != self.object_count:
            raise ValueError(
                f"map {self.name!r}: a visibility grid of {visibility.n_objects} objects "
                f"does not fit a map of {self.object_count}"
            )
        free_space.distance_outside(0.0, 0.0)  # its distance field, now rather than mid-walk
        self._free_space = free_space
        self._visibility = visibility

    def _not_prepared(self, grid: str) -> MapNotPrepared:
        return MapNotPrepared(
            f"map {self.name!r} has no {grid} grid: prepare it first "
            "(app.maps.prepare.ensure_prepared, or load it with app.maps.check.load_map)"
        )

    @property
    def free_space(self) -> FreeSpaceGrid:
        """Where a person can stand (:func:`app.maps.prepare.build_free_space`).

        Raises:
            MapNotPrepared: the map was never prepared.
        """
        if self._free_space is None:
            raise self._not_prepared("free-space")
        return self._free_space

    @property
    def visibility(self) -> VisibilityGrid:
        """Which objects each cell sees (:func:`app.maps.prepare.build_visibility`).

        Raises:
            MapNotPrepared: the map was never prepared.
        """
        if self._visibility is None:
            raise self._not_prepared("visibility")
        return self._visibility

    def to_json(self) -> dict[str, object]:
        """The map file's JSON (with ``class`` spelled as in the file); a file without
        levels has no ``levels``, ``connectors`` or ``level`` keys, as before them."""
        data = self.spec.model_dump(by_alias=True, exclude_none=False)
        if self.spec.levels is None:
            del data["levels"], data["connectors"]
            for key in ("walls", "objects", "regions"):
                for item in data[key]:
                    del item["level"]
        return data
