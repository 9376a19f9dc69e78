"""The annotated 2D floor map: file schema, validation, and array form for the filter.

A map file (see docs/API.md) holds walls, semantic objects (class, position, optional
label) and optional named regions. :func:`load_map` validates a file with pydantic and
refuses anything invalid with a message that names the field and the reason;
:class:`SemanticMap` is the validated map as numpy arrays plus the derived, cached
structures the filter needs (free space, line of sight).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, ValidationError, field_validator, model_validator

from app.maps.geometry import (
    grid_cells,
    point_segment_distance,
    points_in_polygon,
    segments_cross_walls,
)
from app.resources import bundled_maps_dir as bundled_maps_dir  # re-exported for old imports
from app.validation import Finite, StrictInput

#: An object class is a lower-case word: letters, digits, '_' or '-', starting with a letter.
CLASS_PATTERN = re.compile(r"^[a-z][a-z0-9_-]*$")
#: A map name is usable as a file name and in a URL.
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: Every point of the free space is at least this far from every wall, in metres.
WALL_CLEARANCE_M = 0.1
#: An object closer than this to a wall is mounted in it (doors, windows), in metres.
MOUNT_TOLERANCE_M = 0.05


class WallSpec(StrictInput):
    """A wall segment from (x1, y1) to (x2, y2), metres."""

    x1: Finite
    y1: Finite
    x2: Finite
    y2: Finite

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


class MapFile(StrictInput):
    """The JSON map file as docs/API.md describes it."""

    name: str
    description: str = ""
    walls: list[WallSpec] = Field(default_factory=list)
    objects: list[ObjectSpec] = Field(min_length=1)
    regions: list[RegionSpec] = Field(default_factory=list)

    @field_validator("name")
    @classmethod
    def _usable_name(cls, value: str) -> str:
        if not NAME_PATTERN.match(value):
            raise ValueError(
                f"name {value!r} may hold only letters, digits, '_', '-' and '.', "
                "and must start with a letter or digit"
            )
        return value


class MapError(ValueError):
    """A map file that cannot be used; the message says which field and why."""


def _format_validation_error(source: str, error: ValidationError) -> str:
    parts = []
    for item in error.errors():
        where = ".".join(str(p) for p in item["loc"]) or "(file)"
        parts.append(f"{where}: {item['msg']}")
    return f"{source}: " + "; ".join(parts)


def parse_map(
    data: object, *, source: str = "map", expected_name: str | None = None
) -> SemanticMap:
    """Validate already-decoded JSON and build a :class:`SemanticMap`.

    Raises:
        MapError: naming the offending field and the reason.
    """
    try:
        spec = MapFile.model_validate(data)
    except ValidationError as exc:
        raise MapError(_format_validation_error(source, exc)) from None
    if expected_name is not None and spec.name != expected_name:
        raise MapError(
            f"{source}: name: {spec.name!r} must equal the file name without .json "
            f"({expected_name!r})"
        )
    return SemanticMap(spec)


def load_map(path: str | Path) -> SemanticMap:
    """Load and validate one map file; its ``name`` must match the file name."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MapError(f"{p}: no such map file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MapError(f"{p}: not valid JSON ({exc})") from None
    return parse_map(data, source=str(p), expected_name=p.stem)


def load_map_dir(directory: str | Path) -> dict[str, SemanticMap]:
    """Load every ``*.json`` map in a directory, keyed by name (sorted)."""
    d = Path(directory)
    if not d.is_dir():
        raise MapError(f"{d}: not a directory of maps")
    return {m.name: m for m in (load_map(p) for p in sorted(d.glob("*.json")))}


@dataclass(frozen=True)
class FreeSpaceGrid:
    """Cells where a person can stand: enclosed by walls and clear of them.

    ``mask[row, col]`` covers the square with lower-left corner
    ``(origin_x + col * resolution_m, origin_y + row * resolution_m)``.
    """

    origin_x: float
    origin_y: float
    resolution_m: float
    mask: NDArray[np.bool_]  # shape (rows, cols)
    free_cells: NDArray[np.int64] = field(repr=False)  # flat indices of free cells

    def cell_index(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Row-major flat cell index for each point and whether it is on the grid.

        Points off the grid get the nearest edge cell (see :func:`grid_cells`).
        """
        return grid_cells(x, y, self.origin_x, self.origin_y, self.resolution_m, self.mask.shape)

    def is_free(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.bool_]:
        """Whether each point lies in a free cell (False off the grid)."""
        flat, inside = self.cell_index(x, y)
        return inside & self.mask.reshape(-1)[flat]

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` points uniform over the free space, shape (n, 2)."""
        if self.free_cells.size == 0:
            raise MapError("the map has no free space inside its walls")
        cols = self.mask.shape[1]
        pick = self.free_cells[rng.integers(0, self.free_cells.size, size=n)]
        r, c = np.divmod(pick, cols)
        jitter = rng.random((n, 2))
        x = self.origin_x + (c + jitter[:, 0]) * self.resolution_m
        y = self.origin_y + (r + jitter[:, 1]) * self.resolution_m
        return np.column_stack([x, y])


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
        self.name = spec.name
        self.description = spec.description
        self.walls = np.array(
            [[w.x1, w.y1, w.x2, w.y2] for w in spec.walls], dtype=np.float64
        ).reshape(-1, 4)
        self.object_xy = np.array([[o.x, o.y] for o in spec.objects], dtype=np.float64)
        self.classes: tuple[str, ...] = tuple(sorted({o.cls for o in spec.objects}))
        index = {c: i for i, c in enumerate(self.classes)}
        self.object_class = np.array([index[o.cls] for o in spec.objects], dtype=np.int64)
        self.object_labels: tuple[str | None, ...] = tuple(o.label for o in spec.objects)
        self.class_members: dict[str, NDArray[np.int64]] = {
            c: np.flatnonzero(self.object_class == i) for i, c in enumerate(self.classes)
        }
        self.region_names: tuple[str, ...] = tuple(r.name for r in spec.regions)
        self.region_polygons = [np.array(r.polygon, dtype=np.float64) for r in spec.regions]
        if self.walls.shape[0]:
            self.mounted_walls = (
                point_segment_distance(self.object_xy, self.walls) < MOUNT_TOLERANCE_M
            )
        else:
            self.mounted_walls = np.zeros((len(spec.objects), 0), dtype=bool)
        self._grid_resolution_m = grid_resolution_m

    def __repr__(self) -> str:
        return (
            f"SemanticMap({self.name!r}, walls={len(self.walls)}, "
            f"objects={len(self.object_xy)}, classes={list(self.classes)})"
        )

    @property
    def object_count(self) -> int:
        return int(self.object_xy.shape[0])

    def class_of(self, index: int) -> str:
        return self.classes[int(self.object_class[index])]

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

    def region_index(self, points: ArrayLike) -> NDArray[np.int64]:
        """Index of the first region containing each point, or -1, shape (M,)."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        out = np.full(pts.shape[0], -1, dtype=np.int64)
        for i in range(len(self.region_polygons) - 1, -1, -1):
            out[points_in_polygon(pts, self.region_polygons[i])] = i
        return out

    def region_at(self, x: float, y: float) -> str | None:
        """The name of the region containing (x, y), or None."""
        i = int(self.region_index([[x, y]])[0])
        return self.region_names[i] if i >= 0 else None

    @cached_property
    def free_space(self) -> FreeSpaceGrid:
        """Cells enclosed by walls in all four axis directions, wholly >= 0.1 m from walls.

        Every point of a free cell is at least ``WALL_CLEARANCE_M`` from every wall (the
        cell centre is tested with the half-diagonal added), which the motion model
        relies on to skip ray tests for short moves.

        A map without walls is free everywhere within its bounds plus one metre.
        Computed once per map and cached.
        """
        min_x, min_y, max_x, max_y = self.bounds
        margin = 1.0 if self.walls.shape[0] == 0 else 0.0
        min_x, min_y, max_x, max_y = min_x - margin, min_y - margin, max_x + margin, max_y + margin
        area = max((max_x - min_x) * (max_y - min_y), 1e-6)
        res = self._grid_resolution_m or max(0.05, float(np.sqrt(area / 200_000.0)))
        cols = max(1, int(np.ceil((max_x - min_x) / res)))
        rows = max(1, int(np.ceil((max_y - min_y) / res)))
        cx = min_x + (np.arange(cols) + 0.5) * res
        cy = min_y + (np.arange(rows) + 0.5) * res
        gx, gy = np.meshgrid(cx, cy)
        centres = np.column_stack([gx.ravel(), gy.ravel()])
        if self.walls.shape[0] == 0:
            mask = np.ones(centres.shape[0], dtype=bool)
        else:
            mask = np.ones(centres.shape[0], dtype=bool)
            reach = 2.0 * (max_x - min_x + max_y - min_y) + 1.0
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                far = centres + reach * np.array([dx, dy], dtype=np.float64)
                mask &= _chunked_cross(centres, far, self.walls)
            clear = np.ones_like(mask)
            for start in range(0, centres.shape[0], 20_000):
                part = centres[start : start + 20_000]
                clear[start : start + 20_000] = point_segment_distance(part, self.walls).min(
                    axis=1
                ) >= WALL_CLEARANCE_M + res * np.sqrt(0.5)
            mask &= clear
        mask2d = mask.reshape(rows, cols)
        return FreeSpaceGrid(min_x, min_y, res, mask2d, np.flatnonzero(mask))

    def to_json(self) -> dict[str, object]:
        """The map file's JSON (with ``class`` spelled as in the file)."""
        return self.spec.model_dump(by_alias=True, exclude_none=False)


def _chunked_cross(
    start: NDArray[np.float64], end: NDArray[np.float64], walls: NDArray[np.float64]
) -> NDArray[np.bool_]:
    out = np.empty(start.shape[0], dtype=bool)
    step = max(1, 2_000_000 // max(1, walls.shape[0]))
    for i in range(0, start.shape[0], step):
        out[i : i + step] = segments_cross_walls(start[i : i + step], end[i : i + step], walls)
    return out
