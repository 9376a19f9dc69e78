"""Rotations that carry a floor onto itself: twin places no bearing can tell apart.

The filter senses only what each object is and in which direction it lies from the body
(walls hide objects and bound where a person can be). A rotation of the floor that takes
every wall onto a wall and every object onto an object of its own class gives every pose
a twin, the pose rotated with it, that sees exactly what the pose sees, frame after
frame, whatever the person does: no detection, no walk and no search can ever favour
one of the two. Only a heading from outside the map (a compass), or a start the app
gave, tells them apart. The filter asks :func:`rotational_symmetries` once per map.

A map drawn from a real plan is rarely exactly symmetric; one that is (a hall whose
doors and windows repeat every way round) is handled here, and a map symmetric but for
one object (the paper office and its door) is not a twin case: that object tells the
two apart once it is seen, which the evidence tracker weighs.

Only rotations about the objects' centroid are sought (a finite floor's rigid motions
onto itself are rotations about a fixed point, and an object set's centroid is fixed by
any of them); mirror images are no twins, since a mirror turns every bearing's sign.
Walls must match segment for segment: a wall drawn in one piece on one side and in two
on the other is taken for asymmetric, which leaves the filter as without this check.
On a map with levels a turn is a twin only when it carries every level onto itself, the
same turn about the same point of the file's frame (each level's walls onto its walls,
its objects onto its objects of their class), and every connector's stop onto a stop
on its level of a connector of the same kind, way and levels served: then a pose and
its twin ride the same connectors to twin places, and no floor tells them apart either.
A venue only one of whose floors turns onto itself has no twins: a ride to another
floor tells them apart. In the plane the filter works in (each level shifted along x,
:class:`app.maps.levels.LevelLayout`) the turn is applied in the pose's own level's
frame (:func:`twin_pose` with the map's layout). Maps with levels are also checked for
levels that look alike (:func:`alike_levels`): floors drawn the same, wall for wall and
object for object at the same places, as an office tower's often are. A place on one
of them and the same place on the others see the same; only the barometer's count of
storeys from a known floor, or a start the app gave, tells them apart.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from app.maps.geometry import wrap_rad
from app.maps.levels import LevelLayout
from app.maps.model import SemanticMap

#: Objects and wall ends this close (m) to their rotated images count as matched: well
#: under what a bearing with a 2-degree noise tells apart a few metres away.
SYMMETRY_TOLERANCE_M = 0.05


def rotational_symmetries(
    semantic_map: SemanticMap, tol_m: float = SYMMETRY_TOLERANCE_M
) -> tuple[tuple[float, float, float], ...]:
    """The rotations other than the identity that carry the map onto itself, each as
    (centre x, centre y, angle rad in (0, 2 pi)), smallest angle first; kept per map."""
    return semantic_map.derived_value(
        ("rotational_symmetries", float(tol_m)), lambda: _find(semantic_map, tol_m)
    )


def _rotate(
    xy: NDArray[np.float64], centre: NDArray[np.float64], angle: float
) -> NDArray[np.float64]:
    c, s = math.cos(angle), math.sin(angle)
    rel = xy - centre
    return np.column_stack((c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1])) + centre


def twin_pose(
    x: float,
    y: float,
    theta: float,
    twin: tuple[float, float, float],
    layout: LevelLayout | None = None,
) -> tuple[float, float, float]:
    """The pose (x, y, theta) carried by ``twin``, a turn ``(cx, cy, angle)`` of
    :func:`rotational_symmetries`: the twin place that sees what the pose sees. With the
    ``layout`` of a map with levels, (x, y) is a plane point and the turn is made in its
    level's frame (the twin is on the same level)."""
    cx, cy, angle = twin
    shift = 0.0 if layout is None else float(layout.offsets(layout.level_of(x)))
    ((tx, ty),) = _rotate(np.array([[x - shift, y]]), np.array([cx, cy]), angle)
    return float(tx) + shift, float(ty), wrap_rad(theta + angle)


def _onto(
    xy: NDArray[np.float64], cls: NDArray[np.int64], other_xy: NDArray[np.float64],
    other_cls: NDArray[np.int64], tol_m: float,
) -> bool:  # fmt: skip
    """Whether every object (``xy``, ``cls``) lies within ``tol_m`` of one of the others of
    its class (a k-d tree per class: a floor may have thousands of objects)."""
    for k in np.unique(cls):
        targets = other_xy[other_cls == k]
        if targets.shape[0] == 0:
            return False
        dist, _ = cKDTree(targets).query(xy[cls == k], distance_upper_bound=tol_m)
        if not np.isfinite(dist).all():
            return False
    return True


def _walls_match(walls: NDArray[np.float64], image: NDArray[np.float64], tol_m: float) -> bool:
    """Whether every rotated wall (rows x1, y1, x2, y2) lies on a wall, end for end
    (either way round): within ``tol_m`` as a point of the four coordinates, which
    holds each end within it too."""
    if walls.shape[0] == 0:
        return True
    tree = cKDTree(walls)
    same, _ = tree.query(image, distance_upper_bound=tol_m)
    swapped, _ = tree.query(image[:, [2, 3, 0, 1]], distance_upper_bound=tol_m)
    return bool((np.isfinite(same) | np.isfinite(swapped)).all())


def _file_frame(semantic_map: SemanticMap) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The map's walls (rows x1, y1, x2, y2) and objects' (x, y) in the file's frame, each
    level's in its own (the plane's arrays shift each level along x)."""
    spec = semantic_map.spec
    walls = np.array([[w.x1, w.y1, w.x2, w.y2] for w in spec.walls], dtype=np.float64)
    xy = np.array([[o.x, o.y] for o in spec.objects], dtype=np.float64)
    return walls.reshape(-1, 4), xy.reshape(-1, 2)


def _stop_points(layout: LevelLayout) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each connector stop's centroid (file frame) and a class per connector kind, way,
    levels served and the stop's own level: a stop must turn onto a stop of that class."""
    keys: dict[tuple[object, ...], int] = {}
    xy, cls = [], []
    for conn in layout.connectors:
        for stop in conn.stops:
            key = (conn.kind, conn.direction, conn.levels, stop.level)
            cls.append(keys.setdefault(key, len(keys)))
            xy.append(stop.polygon.mean(axis=0))
    return np.array(xy, dtype=np.float64).reshape(-1, 2), np.array(cls, dtype=np.int64)


def _find(semantic_map: SemanticMap, tol_m: float) -> tuple[tuple[float, float, float], ...]:
    layout = semantic_map.layout
    # In the file's frame: on a map with levels every level turns about the same point.
    walls, xy = _file_frame(semantic_map)
    cls = np.asarray(semantic_map.object_class, dtype=np.int64)
    if xy.shape[0] == 0:
        return ()
    # An object turns onto an object of its class on its own level.
    n_cls = int(cls.max()) + 1
    cls = cls + n_cls * np.asarray(layout.object_level, dtype=np.int64)
    wall_level = np.asarray(layout.wall_level, dtype=np.int64)
    stops_xy, stops_cls = _stop_points(layout)
    centre = xy.mean(axis=0)
    rel = xy - centre
    radius = np.hypot(rel[:, 0], rel[:, 1])
    far = int(np.argmax(radius))
    if radius[far] <= tol_m:  # every object at one point: nothing to turn
        return ()
    # The farthest object goes onto an object of its class as far from the centre: each
    # such object gives the one angle a symmetry could have.
    base = math.atan2(rel[far, 1], rel[far, 0])
    found = []
    for j in np.flatnonzero((cls == cls[far]) & (np.abs(radius - radius[far]) <= tol_m)):
        angle = (math.atan2(rel[j, 1], rel[j, 0]) - base) % (2.0 * math.pi)
        # (the identity, and the farthest object's own image within the tolerance)
        if min(angle, 2.0 * math.pi - angle) * radius[far] <= tol_m:
            continue
        # Every object's image on an object of its class.
        if not _onto(_rotate(xy, centre, angle), cls, xy, cls, tol_m):
            continue
        if stops_xy.shape[0] and not _onto(
            _rotate(stops_xy, centre, angle), stops_cls, stops_xy, stops_cls, tol_m
        ):
            continue
        image = np.hstack(
            (_rotate(walls[:, :2], centre, angle), _rotate(walls[:, 2:], centre, angle))
        )
        if all(
            _walls_match(walls[wall_level == k], image[wall_level == k], tol_m)
            for k in np.unique(wall_level)
        ):
            found.append((float(centre[0]), float(centre[1]), angle))
    return tuple(sorted(found, key=lambda r: r[2]))


def alike_levels(
    semantic_map: SemanticMap, tol_m: float = SYMMETRY_TOLERANCE_M
) -> tuple[tuple[int, ...], ...]:
    """Groups of two or more levels (indexes, ascending) that look the same: each one's
    walls lie on the others' walls and its objects on objects of their class, at the same
    places of the floor (within ``tol_m``), both ways. () for a map with one level or
    none; kept per map."""
    return semantic_map.derived_value(
        ("alike_levels", float(tol_m)), lambda: _alike(semantic_map, tol_m)
    )


def _alike(semantic_map: SemanticMap, tol_m: float) -> tuple[tuple[int, ...], ...]:
    layout = semantic_map.layout
    if layout.count < 2:
        return ()
    # Each level's walls and objects in the file's frame (every level's own).
    walls, obj_xy = _file_frame(semantic_map)
    obj_cls = np.asarray(semantic_map.object_class, dtype=np.int64)
    per_level = [
        (walls[layout.wall_level == k], obj_xy[layout.object_level == k],
         obj_cls[layout.object_level == k])
        for k in range(layout.count)
    ]  # fmt: skip

    def same(a: int, b: int) -> bool:
        wa, xa, ca = per_level[a]
        wb, xb, cb = per_level[b]
        if wa.shape[0] != wb.shape[0] or xa.shape[0] != xb.shape[0] or xa.shape[0] == 0:
            return False
        return (
            _onto(xa, ca, xb, cb, tol_m)
            and _onto(xb, cb, xa, ca, tol_m)
            and _walls_match(wb, wa, tol_m)
            and _walls_match(wa, wb, tol_m)
        )

    groups: list[list[int]] = []
    for k in range(layout.count):
        for group in groups:
            if same(group[0], k):
                group.append(k)
                break
        else:
            groups.append([k])
    return tuple(tuple(g) for g in groups if len(g) > 1)
