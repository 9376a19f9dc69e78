"""Check map files before they are served: limits, coordinates, walls, objects, free space.

Every problem is a :class:`Problem` naming the file and the field (``walls[3].x2``,
``objects[12]``) and saying what is wrong. Errors make a file unusable; warnings leave
it usable (and say what was done about them, e.g. an object snapped onto a wall). The
service skips a file with errors and serves the others (:func:`load_map_dirs`);
``bearings map check`` prints the same messages.

Limits keep loading bounded in time and memory whatever a file holds: its size, the
number of walls, objects, regions and polygon vertices, the magnitude of every
coordinate and the map's extent.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from app.maps.freespace import WALL_CLEARANCE_M, FreeSpaceGrid
from app.maps.geometry import enclosed, nearest_walls, segments_cross_walls
from app.maps.model import (
    MOUNT_TOLERANCE_M,
    MapError,
    MapFile,
    SemanticMap,
    parse_map,
    validate_spec,
)
from app.maps.prepare import PreparedMap, build_free_space, prepare
from app.maps.symmetry import alike_levels, rotational_symmetries

log = logging.getLogger("bearings.maps")

#: Largest map file read, bytes (a floor of 250 walls and 130 objects is ~40 kB).
MAX_FILE_BYTES = 8_000_000
MAX_WALLS = 10_000
MAX_OBJECTS = 2_000
MAX_REGIONS = 1_000
MAX_REGION_VERTICES = 5_000
MAX_LEVELS = 100
MAX_CONNECTORS = 2_000
#: Largest absolute coordinate, metres.
MAX_COORDINATE_M = 100_000.0
#: Largest side of the map's bounding box, metres.
MAX_EXTENT_M = 2_000.0
#: An object outside the walls but this close to one is moved onto it (mounted).
SNAP_M = 0.1
#: Collinear walls sharing more than this length are reported as overlapping.
OVERLAP_M = 0.01

#: New positions of snapped objects, by object index.
Fixes = dict[int, tuple[float, float]]


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a map file."""

    source: str
    field: str
    message: str
    severity: Literal["error", "warning"] = "error"

    def __str__(self) -> str:
        tag = "" if self.severity == "error" else " (warning)"
        return f"{self.source}: {self.field}: {self.message}{tag}"


@dataclass
class CheckResult:
    """A checked file: the usable map (None if any error) and every problem found."""

    source: str
    map: SemanticMap | None
    problems: list[Problem]
    #: The map's grids and how they were obtained, when the check prepared them.
    prepared: PreparedMap | None = None

    @property
    def errors(self) -> list[Problem]:
        return [p for p in self.problems if p.severity == "error"]

    @property
    def ok(self) -> bool:
        return self.map is not None and not self.problems


# --------------------------------------------------------------------- raw JSON
def _count_problems(source: str, data: object) -> list[Problem]:
    """Limits on the decoded JSON, before anything is built from it."""
    if not isinstance(data, dict):
        return [Problem(source, "(file)", "must be a JSON object with walls and objects")]
    out = []
    for key, limit in (
        ("walls", MAX_WALLS),
        ("objects", MAX_OBJECTS),
        ("regions", MAX_REGIONS),
        ("levels", MAX_LEVELS),
        ("connectors", MAX_CONNECTORS),
    ):
        items = data.get(key)
        if isinstance(items, list) and len(items) > limit:
            out.append(
                Problem(source, key, f"{len(items):,} entries; at most {limit:,} are accepted")
            )
    regions = data.get("regions")
    if isinstance(regions, list) and len(regions) <= MAX_REGIONS:
        for i, r in enumerate(regions):
            poly = r.get("polygon") if isinstance(r, dict) else None
            if isinstance(poly, list) and len(poly) > MAX_REGION_VERTICES:
                out.append(
                    Problem(
                        source,
                        f"regions[{i}].polygon",
                        f"{len(poly):,} vertices; at most {MAX_REGION_VERTICES:,} are accepted",
                    )
                )
    return out


def _coordinate_problems(source: str, spec: MapFile) -> list[Problem]:
    """Coordinates beyond ``MAX_COORDINATE_M`` (reported per field, first few)."""
    out: list[Problem] = []
    limit = MAX_COORDINATE_M

    def far(values: Iterable[tuple[str, float]]) -> None:
        for where, v in values:
            if abs(v) > limit and len(out) < 20:
                out.append(
                    Problem(
                        source,
                        where,
                        f"{v:g} m is too far from the origin (at most {limit:,.0f} m either way)",
                    )
                )

    for i, w in enumerate(spec.walls):
        far((f"walls[{i}].{k}", getattr(w, k)) for k in ("x1", "y1", "x2", "y2"))
    for i, o in enumerate(spec.objects):
        far((f"objects[{i}].{k}", getattr(o, k)) for k in ("x", "y"))
    for i, r in enumerate(spec.regions):
        for j, (x, y) in enumerate(r.polygon):
            far(((f"regions[{i}].polygon[{j}]", x), (f"regions[{i}].polygon[{j}]", y)))
    for i, c in enumerate(spec.connectors):
        for s, stop in enumerate(c.stops):
            where = f"connectors[{i}].stops[{s}].polygon"
            far((where, v) for point in stop.polygon for v in point)
    return out


def _extent_problems(source: str, m: SemanticMap) -> list[Problem]:
    """A bounding box wider than ``MAX_EXTENT_M`` (a grid over it would be useless)."""
    out = []
    # Several levels lie side by side in the plane (app.maps.levels): the file's extent.
    x0, y0, x1, y1 = m.layout.file_bounds if m.layout.has_levels else m.bounds
    if max(x1 - x0, y1 - y0) > MAX_EXTENT_M:
        out.append(
            Problem(
                source,
                "(extent)",
                f"the map spans {x1 - x0:,.1f} m x {y1 - y0:,.1f} m; at most {MAX_EXTENT_M:,.0f} m "
                "a side is accepted (are the coordinates in metres?)",
            )
        )
    return out


# --------------------------------------------------------------------- geometry
def _overlapping_walls(source: str, walls: np.ndarray) -> list[Problem]:
    """Pairs of collinear walls that share a stretch (duplicated or overlapping walls)."""
    out: list[Problem] = []
    n = walls.shape[0]
    if n < 2:
        return out
    a = walls[:, 0:2]
    d = walls[:, 2:4] - a
    length = np.hypot(d[:, 0], d[:, 1])
    u = d / np.maximum(length, 1e-12)[:, None]
    # Group by direction (folded to [0, pi)) and offset of the supporting line.
    ang = np.mod(np.arctan2(u[:, 1], u[:, 0]), np.pi)
    normal = np.column_stack([-np.sin(ang), np.cos(ang)])
    offset = np.sum(a * normal, axis=1)
    key_a = np.round(ang / 1e-3).astype(np.int64)
    key_o = np.round(offset / 1e-3).astype(np.int64)
    order = np.lexsort((key_o, key_a))
    groups: dict[tuple[int, int], list[int]] = {}
    for i in order:
        groups.setdefault((int(key_a[i]), int(key_o[i])), []).append(int(i))
    for members in groups.values():
        if len(members) < 2:
            continue
        direction = np.array([np.cos(ang[members[0]]), np.sin(ang[members[0]])])
        spans = []
        for i in members:
            s = sorted((float(a[i] @ direction), float(walls[i, 2:4] @ direction)))
            spans.append((s[0], s[1], i))
        spans.sort()
        reach_end, reach_i = spans[0][1], spans[0][2]
        for lo, hi, i in spans[1:]:
            shared = min(hi, reach_end) - lo
            if shared > OVERLAP_M and len(out) < 20:
                j, k = sorted((reach_i, i))
                out.append(
                    Problem(
                        source,
                        f"walls[{k}]",
                        f"overlaps walls[{j}] along {shared:.2f} m (a duplicated wall?)",
                        "warning",
                    )
                )
            if hi > reach_end:
                reach_end, reach_i = hi, i
    return out


def _first_self_crossing(poly: np.ndarray) -> tuple[int, int] | None:
    """The first pair of non-adjacent edges of a closed polygon that cross, or None.

    Edge k runs from vertex k to vertex k + 1 (the last one back to vertex 0). A plain
    pairwise segment test (no polygon library to import at start-up); at most
    ``MAX_REGION_VERTICES`` squared pairs, in blocks.
    """
    start = poly
    end = np.roll(poly, -1, axis=0)
    n = poly.shape[0]
    if n < 4:
        return None
    edges = np.column_stack([start, end])
    k = np.arange(n)
    for lo in range(0, n, 256):
        rows = k[lo : lo + 256]
        # An edge touches itself and its two neighbours at shared vertices: skip those.
        d = np.abs(rows[:, None] - k[None, :])
        adjacent = (d <= 1) | (d == n - 1)
        hit = segments_cross_walls(start[rows], end[rows], edges, ignore=adjacent)
        if hit.any():
            i = int(rows[np.argmax(hit)])
            for j in range(n):
                skip = abs(i - j) <= 1 or abs(i - j) == n - 1
                if not skip and segments_cross_walls(start[i], end[i], edges[j])[0]:
                    return i, j
    return None


def _region_problems(source: str, m: SemanticMap) -> list[Problem]:
    """Regions whose outline crosses itself (which room a point is in becomes ambiguous)."""
    out = []
    for i, poly in enumerate(m.region_polygons):
        crossing = _first_self_crossing(poly)
        if crossing is not None:
            a, b = crossing
            out.append(
                Problem(
                    source,
                    f"regions[{i}].polygon",
                    f"region {m.region_names[i]!r} is not a simple polygon: its edge from "
                    f"point {a} crosses its edge from point {b}",
                    "warning",
                )
            )
    return out


def _alike_level_problems(source: str, m: SemanticMap) -> list[Problem]:
    """Levels drawn the same (:func:`app.maps.symmetry.alike_levels`): the same place on
    each sees the same, so a person is located on one of them only from a known floor
    (a start the app gives, or the barometer's count of storeys from one); one warning
    per group."""
    names = [lv.id for lv in m.layout.levels]
    out = []
    for group in alike_levels(m):
        ids = ", ".join(repr(names[k]) for k in group)
        out.append(
            Problem(
                source,
                "levels",
                f"levels {ids} look the same: every wall and object of each lies where the "
                "others have one of its kind, so from what the camera sees nobody can tell "
                "which of these floors they are on; a person is located on one only after "
                "starting at a known floor (initial_pose.level) or riding from one with a "
                "barometer; an object that only one floor has (a sign, a named desk) tells "
                "them apart",
                "warning",
            )
        )
    return out


def _symmetry_problems(source: str, m: SemanticMap) -> list[Problem]:
    """A map a rotation carries onto itself (:mod:`app.maps.symmetry`): each place has a
    twin that sees the same, and nobody is located there without a compass (one warning
    naming every such turn)."""
    turns = rotational_symmetries(m)
    if not turns:
        return []
    cx, cy, _ = turns[0]
    angles = [f"{math.degrees(a):.0f}" for _, _, a in turns]
    degrees = " and ".join([", ".join(angles[:-1]), angles[-1]] if len(angles) > 1 else angles)
    levels = " on every level (stairs, lifts and escalators onto their like)"
    every = levels if m.layout.levels else ""
    return [
        Problem(
            source,
            "objects",
            f"the map turns onto itself under a rotation of {degrees} deg about "
            f"({cx:.2f}, {cy:.2f}){every}: every wall onto a wall and every object onto one of "
            "its class, so each place has a twin that sees the same and no one is located "
            "on this map without a compass heading or a known start; an object that only "
            "one side has (a sign, a door of its own class) tells them apart",
            "warning",
        )
    ]


def _object_fixes(source: str, m: SemanticMap) -> tuple[Fixes, list[Problem]]:
    """Objects outside the walls: snapped onto a wall when close, else a warning."""
    walls = m.walls
    if walls.shape[0] == 0:
        return {}, []
    fixes: Fixes = {}
    out: list[Problem] = []
    xy = m.object_xy
    # The plane's x offset of each object's level (0 without levels): messages and
    # fixes are in the file's frame.
    shift = m.layout.offsets(m.layout.object_level)
    near, nearest, _ = nearest_walls(xy, walls)
    mounted = near < MOUNT_TOLERANCE_M
    candidates = np.flatnonzero(~mounted)
    outside = candidates[~enclosed(xy[candidates], walls)] if candidates.size else candidates
    for i in outside:
        i = int(i)
        label = m.object_labels[i]
        what = f"{m.class_of(i)}" + (f" {label!r}" if label else "")
        if near[i] <= SNAP_M:
            w = walls[nearest[i]]
            d = w[2:4] - w[0:2]
            t = float(np.clip(np.dot(xy[i] - w[0:2], d) / max(float(d @ d), 1e-12), 0.0, 1.0))
            p = w[0:2] + t * d - (shift[i], 0.0)
            fixes[i] = (float(p[0]), float(p[1]))
            out.append(
                Problem(
                    source,
                    f"objects[{i}]",
                    f"{what} at ({xy[i, 0] - shift[i]:.2f}, {xy[i, 1]:.2f}) lies "
                    f"{near[i] * 100:.0f} cm outside walls[{int(nearest[i])}]; moved onto it "
                    f"at ({p[0]:.2f}, {p[1]:.2f})",
                    "warning",
                )
            )
        else:
            out.append(
                Problem(
                    source,
                    f"objects[{i}]",
                    f"{what} at ({xy[i, 0] - shift[i]:.2f}, {xy[i, 1]:.2f}) is outside the walls "
                    f"({near[i]:.2f} m from the nearest); nobody inside can stand near it",
                    "warning",
                )
            )
    return fixes, out


def _free_space_problem(
    source: str, m: SemanticMap, prepare_grids: bool, cache_dir: Path | None
) -> tuple[Problem | None, PreparedMap | None, FreeSpaceGrid]:
    """No free space at all. With ``prepare_grids`` the map's grids are prepared here
    (read from ``cache_dir`` when there, and returned), else only the free space is
    built. The free space comes back too (the levels' checks read it)."""
    prepared = prepare(m, cache_dir) if prepare_grids else None
    fs = build_free_space(m, m.grid_resolution_m) if prepared is None else prepared.free_space
    if fs.free_cells.size:
        return None, prepared, fs
    return _no_free_space(source), None, fs


def _no_free_space(source: str, where: str = "") -> Problem:
    return Problem(
        source,
        "walls",
        f"the map has no free space{where}: no place is enclosed by walls on all four sides "
        f"and at least {WALL_CLEARANCE_M} m from every wall",
    )


def _level_problems(source: str, m: SemanticMap, fs: FreeSpaceGrid) -> list[Problem]:
    """Levels with no free space, and connector stops outside their level's free space
    (a stop must hold room to stand: its polygon's centre, or failing that a point of
    a 10 cm raster inside it, is free)."""
    from app.maps.geometry import first_polygon, polygon_edges

    layout = m.layout
    if not layout.has_levels:
        return []
    out: list[Problem] = []
    cols = fs.mask.shape[1]
    free_x = fs.origin_x + (fs.free_cells % cols + 0.5) * fs.resolution_m
    free_level = layout.level_of_plane_x(free_x)
    for lv in layout.levels:
        if not np.any(free_level == lv.index):
            out.append(_no_free_space(source, f" on level {lv.id!r}"))
    for c, conn in enumerate(m.spec.connectors):
        for s, stop in enumerate(conn.stops):
            k = layout.level_index(stop.level)
            poly = layout.to_plane(np.array(stop.polygon, dtype=np.float64), k)
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            gx, gy = np.meshgrid(
                np.arange(lo[0], hi[0] + 0.1, 0.1), np.arange(lo[1], hi[1] + 0.1, 0.1)
            )
            raster = np.vstack(
                [poly.mean(axis=0)[None, :], np.column_stack([gx.ravel(), gy.ravel()])]
            )
            within = first_polygon(raster, *polygon_edges([poly])) >= 0
            if not np.any(fs.is_free(raster[within, 0], raster[within, 1])):
                label = f" ({conn.label})" if conn.label else ""
                out.append(
                    Problem(
                        source,
                        f"connectors[{c}].stops[{s}].polygon",
                        f"{conn.kind} {conn.id!r}{label}: its stop on level {stop.level!r} "
                        "holds no free space (it lies outside the level's walls or within "
                        f"the walls' clearance)",
                    )
                )
    return out


# --------------------------------------------------------------------- entry points
def check_data(
    data: object,
    *,
    source: str = "map",
    expected_name: str | None = None,
    prepare_grids: bool = False,
    cache_dir: Path | None = None,
) -> CheckResult:
    """Check already-decoded JSON; the map (with fixes applied) when there is no error.

    With ``prepare_grids`` a usable map also gets its grids (:func:`app.maps.prepare.
    prepare`, through ``cache_dir``), so loading builds the free space only once.
    """
    problems = _count_problems(source, data)
    if problems:
        return CheckResult(source, None, problems)
    try:
        spec = validate_spec(data, source=source, expected_name=expected_name)
    except MapError as exc:
        return CheckResult(
            source, None, [Problem(source, field, text) for field, text in exc.fields]
        )
    problems = _coordinate_problems(source, spec)
    if problems:
        return CheckResult(source, None, problems)
    m = SemanticMap(spec)
    problems = _extent_problems(source, m)
    if problems:
        return CheckResult(source, None, problems)
    problems += _overlapping_walls(source, m.walls)
    problems += _region_problems(source, m)
    fixes, object_problems = _object_fixes(source, m)
    problems += object_problems
    if fixes:
        fixed = m.to_json()
        for i, (x, y) in fixes.items():
            fixed["objects"][i]["x"], fixed["objects"][i]["y"] = x, y  # type: ignore[index]
        m = parse_map(fixed, source=source, expected_name=expected_name)
    empty, prepared, fs = _free_space_problem(source, m, prepare_grids, cache_dir)
    if empty is not None:
        return CheckResult(source, None, [*problems, empty])
    level_errors = _level_problems(source, m, fs)
    if level_errors:
        return CheckResult(source, None, [*problems, *level_errors])
    problems += _symmetry_problems(source, m)
    problems += _alike_level_problems(source, m)
    return CheckResult(source, m, problems, prepared)


def check_file(
    path: str | Path, *, prepare_grids: bool = False, cache_dir: Path | None = None
) -> CheckResult:
    """Check one map file: it must exist, be small enough, be JSON and pass every check
    (and prepare its grids, see :func:`check_data`)."""
    p = Path(path)
    source = str(p)
    if p.is_symlink() and not p.exists():
        target = os.readlink(p)
        return CheckResult(
            source, None, [Problem(source, "(file)", f"broken symbolic link to {target!r}")]
        )
    if not p.is_file():
        return CheckResult(source, None, [Problem(source, "(file)", "no such map file")])
    size = p.stat().st_size
    if size > MAX_FILE_BYTES:
        return CheckResult(
            source,
            None,
            [
                Problem(
                    source,
                    "(file)",
                    f"{size:,} bytes; map files of at most {MAX_FILE_BYTES:,} bytes are accepted",
                )
            ],
        )
    try:
        with p.open("rb") as f:
            raw = f.read(MAX_FILE_BYTES + 1)
        data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except OSError as exc:
        return CheckResult(source, None, [Problem(source, "(file)", f"cannot read it ({exc})")])
    except (json.JSONDecodeError, UnicodeDecodeError, ValueError) as exc:
        return CheckResult(source, None, [Problem(source, "(file)", f"not valid JSON ({exc})")])
    return check_data(
        data,
        source=source,
        expected_name=p.stem,
        prepare_grids=prepare_grids,
        cache_dir=cache_dir,
    )


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


def load_map_dirs(
    directories: Iterable[str | Path], *, cache_dir: Path | None = None
) -> tuple[dict[str, SemanticMap], list[Problem]]:
    """Every usable ``*.json`` map in the directories, prepared, keyed by name.

    A file with errors is skipped and its problems logged as errors; warnings are
    logged and the map is served. Later directories win on a name clash. Returns the
    maps and every problem found.
    """
    maps: dict[str, SemanticMap] = {}
    problems: list[Problem] = []
    for directory in directories:
        d = Path(directory)
        if not d.is_dir():
            problem = Problem(str(d), "(directory)", "not a directory of maps; skipped")
            log.error("%s", problem)
            problems.append(problem)
            continue
        for path in sorted(d.glob("*.json")):
            result = check_file(path, prepare_grids=True, cache_dir=cache_dir)
            problems += result.problems
            if result.map is None:
                log.error("map file skipped: %s", "; ".join(str(p) for p in result.problems))
                continue
            for p in result.problems:
                log.warning("%s", p)
            prepared = result.prepared or prepare(result.map, cache_dir)
            log.info(
                "map %s: %d walls, %d objects; grids %s in %.3f s",
                result.map.name,
                result.map.walls.shape[0],
                result.map.object_count,
                "read from the cache" if prepared.from_cache else "built",
                prepared.seconds,
            )
            maps[result.map.name] = result.map
    return maps, problems


def load_map(path: str | Path, *, cache_dir: Path | None = None) -> SemanticMap:
    """Load, check and prepare one map file (:func:`check_file`; its grids read from
    ``cache_dir`` when there, else built, and cached there).

    Its ``name`` must match the file name. Warnings are dropped (their fixes, such as
    an object snapped onto a wall, are applied).

    Raises:
        MapError: with every error found, each naming its field.
    """
    result = check_file(path, prepare_grids=True, cache_dir=cache_dir)
    if result.map is None:
        errors = result.errors
        raise MapError("; ".join(str(p) for p in errors), [(p.field, p.message) for p in errors])
    return result.map


def load_map_dir(directory: str | Path) -> dict[str, SemanticMap]:
    """Load and prepare every ``*.json`` map in a directory (:func:`load_map`), keyed by
    name (sorted); any error raises."""
    d = Path(directory)
    if not d.is_dir():
        raise MapError(f"{d}: not a directory of maps")
    return {m.name: m for m in (load_map(p) for p in sorted(d.glob("*.json")))}
