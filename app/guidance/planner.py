"""Shortest walkable paths to a target through the map's free space.

Once per map and target, a :class:`Plan` runs Dijkstra's algorithm (scipy's compiled
``csgraph.dijkstra``) over the map's free-space grid, from the target outwards: every
walkable cell learns its walking distance to the target and the next cell towards it.
Cells closer than ``CLEARANCE_M`` to a wall are left out so that paths keep a little
room from walls and door frames; a second run over the whole free space serves a person
in a passage narrower than that. A target point in a wall (a door) is joined to the
walkable cells around it that see it.

Per frame, :meth:`Plan.route` follows those next-cell links from the person's cell (or
the nearest such cell in sight, for an estimate close to a wall) and
straightens the staircase of cells into the few straight legs a person would walk
(a leg goes on as long as the straight line stays walkable), so the first leg's end
is the next turn. No search runs per frame.

A venue with several levels has them side by side in the free space's plane
(:mod:`app.maps.levels`); :mod:`~app.guidance.levels` joins them at the connectors'
stops, so the same search crosses levels, escalators only their way, lifts and ramps
only for a step-free plan. A route then ends at the first connector it rides, and says
which (:attr:`Route.ride`); once the person is on the next level, the route from there
goes on.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.guidance.levels import Ride, StopNode, entry_edges, ride_edges, stop_nodes
from app.guidance.targets import DestinationSpec, Target, resolve
from app.maps.geometry import points_in_polygon, segments_cross_walls, wrap_deg
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared

#: Paths keep at least about this much room from walls where the map allows (metres).
CLEARANCE_M = 0.3
#: A target point joins the walkable cells within this distance that see it (metres).
JOIN_RADIUS_M = 1.0
#: ... or, when none is that close, within this distance.
MAX_JOIN_RADIUS_M = 3.0
#: A pose off the walkable cells (estimate near a wall) snaps to one within this (metres).
MAX_SNAP_M = 1.5
#: A bend of the path smaller than this is no turn worth a word (degrees).
MIN_TURN_DEG = 15.0
#: Plans kept per map (least recently used dropped first).
CACHE_SIZE = 16

_lock = threading.Lock()


class Unreachable(ValueError):
    """No walkable path leads to the target (or from the given pose)."""


@dataclass(frozen=True)
class Route:
    """The straightened shortest path from a pose to the target.

    Attributes:
        points: the pose, each turn, and the end point, shape (P, 2), metres, in the
            map's plane (a level's own frame shifted, see app.maps.levels).
        length_m: walking length of the polyline, metres.
        end_object: the map object reached (-1 for a point, a region or a connector).
        ride: the change of level the polyline leads to (it ends at the middle of that
            connector's stop), or None when it leads to the target.
    """

    points: NDArray[np.float64]
    length_m: float
    end_object: int
    ride: Ride | None = None


@dataclass(frozen=True)
class _Layer:
    """Dijkstra's answer over one set of walkable cells.

    ``node[cell]`` is the graph node of a grid cell (-1 when not walkable); for each
    node, ``dist`` its walking distance to the target, ``pred`` the next node towards it
    and ``source`` the virtual node (target point) it leads to; nodes ``n`` to
    ``first_target`` are connector stops (:mod:`app.guidance.levels`), the rest the
    target's virtual nodes.
    """

    walkable: NDArray[np.bool_]  # flat, one per grid cell
    node: NDArray[np.int64]
    cells: NDArray[np.int64]
    dist: NDArray[np.float64]
    pred: NDArray[np.int32]
    source: NDArray[np.int32]
    n: int
    first_target: int

    def reaches(self, cell: int) -> bool:
        k = self.node[cell]
        return bool(k >= 0 and np.isfinite(self.dist[k]))


class Plan:
    """Walking distances to one target over one map's free space (built once).

    Two layers: the cells at least ``CLEARANCE_M`` from walls (paths keep that room where
    they can) and the whole free space (for a person in a passage too narrow for that).
    """

    def __init__(self, semantic_map: SemanticMap, target: Target) -> None:
        self.map = ensure_prepared(semantic_map)  # its free space, built now if need be
        self.target = target
        #: Connector stops as graph nodes (none on a map without levels).
        self.stops: list[StopNode] = stop_nodes(semantic_map.layout, target.step_free)
        fs = semantic_map.free_space
        self.res = fs.resolution_m
        self.origin = np.array([fs.origin_x, fs.origin_y])
        self.shape = fs.mask.shape
        free = fs.mask
        # scipy (ndimage here, csgraph in _build) is imported on the first plan, not with
        # the service: it is a tenth of a second that no server start needs to wait for.
        from scipy import ndimage

        # Distance from each free cell centre to the nearest cell that is not free; the
        # free space already keeps WALL_CLEARANCE_M (0.1 m) plus half a cell from walls.
        room = ndimage.distance_transform_edt(free) * self.res
        roomy = free & (room >= max(CLEARANCE_M - 0.1, 0.0))
        self.layers: list[_Layer] = []
        for walkable in (roomy, free):
            try:
                self.layers.append(self._build(walkable))
            except Unreachable:
                continue
        if not self.layers:
            raise Unreachable(
                f"no walkable path leads to {target.name} on map {semantic_map.name!r}"
            )

    # ------------------------------------------------------------------ build
    def _centres(self, flat: NDArray[np.int64]) -> NDArray[np.float64]:
        r, c = np.divmod(flat, self.shape[1])
        return self.origin + (np.column_stack([c, r]) + 0.5) * self.res

    def _build(self, walkable: NDArray[np.bool_]) -> _Layer:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        rows, cols = self.shape
        cells = np.flatnonzero(walkable)
        n = cells.size
        node = np.full(rows * cols, -1, dtype=np.int64)
        node[cells] = np.arange(n)
        r, c = np.divmod(cells, cols)
        src, dst, wt = [], [], []
        # Right, up, and both diagonals (the graph is undirected); a diagonal step only
        # where both cells beside it are walkable, so no path cuts a wall's corner.
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            rr, cc = r + dr, c + dc
            ok = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)
            ok[ok] &= walkable[rr[ok], cc[ok]]
            if dr and dc:
                ok[ok] &= walkable[r[ok] + dr, c[ok]] & walkable[r[ok], c[ok] + dc]
            src.append(np.arange(n)[ok])
            dst.append(node[rr[ok] * cols + cc[ok]])
            wt.append(np.full(int(ok.sum()), self.res * float(np.hypot(dr, dc))))
        # Nodes n .. n + S - 1 are connector stops, each tied to the cells inside it.
        layout = self.map.layout
        stops = len(self.stops)
        in_cell, in_stop, in_w = entry_edges(self.stops, layout, self._centres(cells))
        src.append(in_cell)
        dst.append(in_stop + n)
        wt.append(in_w)
        seeds, seed_w, seed_src = self._seeds(cells)
        first = n + stops
        k = max(len(self.target.points), 1)
        # Node first + j is target point j (a region has one virtual node, first).
        src.append(seed_src + first)
        dst.append(node[seeds])
        wt.append(seed_w)
        s = np.concatenate(src)
        d = np.concatenate(dst)
        w = np.concatenate(wt) + 1e-9  # csgraph treats an explicit 0 as no edge
        # Walking goes both ways; a ride only its way. The search runs from the target
        # outwards, so a ride from stop a to stop b is the edge b -> a.
        ride_a, ride_b, ride_w = ride_edges(self.stops, layout)
        rows = np.r_[s, d, ride_b + n]
        cols_ = np.r_[d, s, ride_a + n]
        size = first + k
        graph = coo_matrix((np.r_[w, w, ride_w], (rows, cols_)), shape=(size, size))
        dist, pred, source = dijkstra(
            graph.tocsr(),
            directed=True,
            indices=np.arange(first, first + k),
            return_predecessors=True,
            min_only=True,
        )
        if not np.isfinite(dist[:n]).any():
            raise Unreachable(f"nothing walkable reaches {self.target.name}")
        return _Layer(walkable.reshape(-1), node, cells, dist, pred, source, n, first)

    def _seeds(
        self, cells: NDArray[np.int64]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]:
        """Walkable cells joined to the target: (cells, distance to the target, which point)."""
        t = self.target
        centres = self._centres(cells)
        if t.kind == "region":
            inside = points_in_polygon(centres, self.map.region_polygons[t.region])
            if not inside.any():
                raise Unreachable(f"no walkable part of region {t.name}")
            found = cells[inside]
            return found, np.zeros(found.size), np.zeros(found.size, dtype=np.int64)
        out_c, out_w, out_s = [], [], []
        for j, (point, obj) in enumerate(zip(t.points, t.objects, strict=True)):
            d = np.hypot(*(centres - point).T)
            for radius in (JOIN_RADIUS_M, MAX_JOIN_RADIUS_M):
                near = np.flatnonzero(d <= radius)
                if near.size == 0:
                    continue
                if obj >= 0:
                    sees = self.map.line_of_sight(centres[near], [int(obj)])[:, 0]
                else:
                    ends = np.broadcast_to(point, (near.size, 2))
                    sees = ~segments_cross_walls(centres[near], ends, self.map.walls)
                near = near[sees]
                if near.size:
                    out_c.append(cells[near])
                    out_w.append(d[near])
                    out_s.append(np.full(near.size, j, dtype=np.int64))
                    break
        if not out_c:
            raise Unreachable(f"no walkable place near {t.name}")
        return np.concatenate(out_c), np.concatenate(out_w), np.concatenate(out_s)

    # -------------------------------------------------------------- per frame
    def _cell_of(self, x: float, y: float) -> int:
        rows, cols = self.shape
        c = int(np.clip(np.floor((x - self.origin[0]) / self.res), 0, cols - 1))
        r = int(np.clip(np.floor((y - self.origin[1]) / self.res), 0, rows - 1))
        return r * cols + c

    def _snap(self, layer: _Layer, start: NDArray[np.float64]) -> int | None:
        """The nearest cell of ``layer`` that leads to the target and that the person sees
        (no wall between), within ``MAX_SNAP_M``; None when there is none."""
        rows, cols = self.shape
        reach = int(np.ceil(MAX_SNAP_M / self.res))
        c0, r0 = divmod(self._cell_of(*start), cols)[::-1]
        rr, cc = np.mgrid[
            max(r0 - reach, 0) : min(r0 + reach + 1, rows),
            max(c0 - reach, 0) : min(c0 + reach + 1, cols),
        ]
        flat = (rr * cols + cc).reshape(-1)
        k = layer.node[flat]
        ok = k >= 0
        ok[ok] = np.isfinite(layer.dist[k[ok]])
        flat = flat[ok]
        centres = self._centres(flat)
        d = np.hypot(*(centres - start).T)
        near = d <= MAX_SNAP_M
        flat, centres, d = flat[near], centres[near], d[near]
        if not flat.size:
            return None
        order = np.argsort(d, kind="stable")
        ends = centres[order]
        blocked = segments_cross_walls(np.broadcast_to(start, ends.shape), ends, self.map.walls)
        seen = np.flatnonzero(~blocked)
        return int(flat[order[seen[0]]]) if seen.size else None

    def route(self, x: float, y: float, level: int | str | None = None) -> Route:
        """The straightened shortest path from (x, y) to the target, or to the first
        connector it rides (:attr:`Route.ride`).

        Args:
            x, y: the person's position, metres: in the frame of ``level`` when one is
                given (its index in ordinal order or its id), else in the map's plane
                (the file's frame for a map without levels).

        Raises:
            Unreachable: no cell that leads to the target is within ``MAX_SNAP_M`` in
                sight (outside the building, or in a walled-off part).
            KeyError: ``level`` is no level of the map.
        """
        if level is not None:
            layout = self.map.layout
            k = layout.level_index(level) if isinstance(level, str) else int(level)
            if not layout.has_levels and k == 0:
                pass  # one level: the plane is the file's frame
            elif not 0 <= k < len(layout.levels):
                raise KeyError(f"level index {k} is not a level of map {self.map.name!r}")
            else:
                x, y = (float(v) for v in layout.to_plane([x, y], k)[0])
        start = np.array([x, y], dtype=np.float64)
        flat = self._cell_of(x, y)
        for layer in self.layers:
            relax = 0.0
            cell: int | None = flat
            if not layer.reaches(flat):
                cell = self._snap(layer, start)
                if cell is None:
                    continue
                relax = float(np.hypot(*(self._centres(np.array([cell]))[0] - start))) + self.res
            assert cell is not None  # reached, or snapped onto a reachable cell above
            return self._route(layer, start, int(cell), relax)
        way = "step-free path (lifts and ramps only)" if self.target.step_free else "walkable path"
        raise Unreachable(f"no {way} from here to {self.target.name}")

    def _route(self, layer: _Layer, start: NDArray[np.float64], cell: int, relax: float) -> Route:
        chain = [int(layer.node[cell])]
        while chain[-1] < layer.first_target and layer.pred[chain[-1]] >= 0:
            chain.append(int(layer.pred[chain[-1]]))
        cut, ride = self._first_ride(layer, chain)
        cell_nodes = np.array([c for c in chain[:cut] if c < layer.n], dtype=np.int64)
        pts = self._centres(layer.cells[cell_nodes])
        end_object = -1
        if ride is None and self.target.kind != "region":
            j = int(layer.source[int(cell_nodes[0])]) - layer.first_target  # which point
            pts = np.vstack([pts, self.target.points[j]])
            end_object = int(self.target.objects[j])
        if ride is not None:
            # The stop's middle is a region's end: the person walks onto it, no wall between.
            legs = self._straighten(layer, start, pts, -1, relax, special_end=False)
        else:
            legs = self._straighten(layer, start, pts, end_object, relax)
        legs = self._merge_small_bends(layer, legs, end_object, relax, special_end=ride is None)
        return Route(legs, _length(legs), end_object, ride)

    def _first_ride(self, layer: _Layer, chain: list[int]) -> tuple[int, Ride | None]:
        """Where the chain's walk on this level ends (an index into it) and the ride
        that follows; (len(chain), None) when it reaches the target without one.

        A run of stop nodes whose first and last lie on one level is no ride (a path
        that only crossed a stop): its nodes are passed over."""
        if not self.stops:
            return len(chain), None  # one level: nothing to ride
        k = 0
        while k < len(chain):
            if not layer.n <= chain[k] < layer.first_target:
                k += 1
                continue
            end = k
            while end + 1 < len(chain) and layer.n <= chain[end + 1] < layer.first_target:
                end += 1
            first, last = self.stops[chain[k] - layer.n], self.stops[chain[end] - layer.n]
            if first.level != last.level:
                return k, Ride(first.connector, first.level, last.level)
            k = end + 1
        return len(chain), None

    def _clear(
        self, layer: _Layer, a: NDArray[np.float64], b: NDArray[np.float64], relax_m: float
    ) -> bool:
        """Whether the straight line a -> b stays walkable (see :func:`_line_clear`)."""
        return bool(_line_clear(a[0], a[1], b[0], b[1], *self._grid_args(layer, relax_m)))

    def _grid_args(self, layer: _Layer, relax_m: float) -> tuple[object, ...]:
        rows, cols = self.shape
        return (
            layer.walkable,
            self.map.free_space.mask.reshape(-1),
            float(self.origin[0]),
            float(self.origin[1]),
            1.0 / self.res,
            rows,
            cols,
            0.5 * self.res,
            relax_m,
        )

    def _merge_small_bends(
        self,
        layer: _Layer,
        points: NDArray[np.float64],
        end_object: int,
        relax_m: float,
        special_end: bool = True,
    ) -> NDArray[np.float64]:
        """Drop inner points where the path bends by less than ``MIN_TURN_DEG`` (no turn
        worth a word), where the straight line past them stays walkable too."""
        keep = [points[0]]
        last = len(points) - 1
        for k in range(1, last):
            into = _heading_deg(keep[-1], points[k])
            out = _heading_deg(points[k], points[k + 1])
            if abs(wrap_deg(out - into)) < MIN_TURN_DEG:
                relax = relax_m if len(keep) == 1 else 0.0
                if k + 1 == last and special_end and self.target.kind != "region":
                    clear = self._sees_end(layer, keep[-1], points[k + 1], end_object, relax)
                else:
                    clear = self._clear(layer, keep[-1], points[k + 1], relax)
                if clear:
                    continue
            keep.append(points[k])
        keep.append(points[-1])
        return np.array(keep)

    def _straighten(
        self,
        layer: _Layer,
        start: NDArray[np.float64],
        chain: NDArray[np.float64],
        end_object: int,
        relax_m: float = 0.0,
        special_end: bool | None = None,
    ) -> NDArray[np.float64]:
        """Legs from ``start`` along ``chain``: each goes on while the line stays clear.

        A leg ends at the last chain point before the first one its start cannot see in
        a straight walkable line. The final point of a door or other object target may
        sit in a wall and is tested by :meth:`_sees_end` instead.
        """
        out = [start]
        anchor = start
        i, last = 0, chain.shape[0] - 1
        if special_end is None:
            special_end = self.target.kind != "region"
        while i < last:
            stop = last - 1 if special_end else last
            args = self._grid_args(layer, relax_m)
            reach = int(_reach(anchor[0], anchor[1], chain, i + 1, stop, *args))
            if (
                reach == stop
                and special_end
                and self._sees_end(layer, anchor, chain[last], end_object, relax_m)
            ):
                reach = last
            reach = max(reach, i + 1)  # at least one step of progress
            anchor = chain[reach]
            out.append(anchor)
            i = reach
            relax_m = 0.0  # only the person's own first leg may start off the cells
        return np.array(out)

    def _sees_end(
        self,
        layer: _Layer,
        a: NDArray[np.float64],
        end: NDArray[np.float64],
        obj: int,
        relax_m: float = 0.0,
    ) -> bool:
        """Whether the final point (maybe in a wall) is reachable in a straight line:
        walkable until ``JOIN_RADIUS_M`` before it, then no wall crossed."""
        d = end - a
        length = float(np.hypot(*d))
        if length < 1e-9:
            return True
        cut = max(length - JOIN_RADIUS_M, 0.0)
        if cut > 0 and not self._clear(layer, a, a + d * (cut / length), relax_m):
            return False
        ignore = self.map.mounted_walls[obj] if obj >= 0 and self.map.walls.shape[0] else None
        return not segments_cross_walls(a[None], end[None], self.map.walls, ignore=ignore)[0]


@njit(cache=True, nogil=True)
def _line_clear(
    ax, ay, bx, by, walkable, free, ox, oy, inv_res, rows, cols, step, relax
):  # pragma: no cover - compiled
    """Whether the line a -> b stays on walkable cells, sampled every ``step`` metres; the
    first ``relax`` metres need only be in the free space."""
    dx, dy = bx - ax, by - ay
    length = np.sqrt(dx * dx + dy * dy)
    n = max(int(np.ceil(length / step)), 1)
    for s in range(n + 1):
        f = s / n
        c = min(max(int(np.floor((ax + f * dx - ox) * inv_res)), 0), cols - 1)
        r = min(max(int(np.floor((ay + f * dy - oy) * inv_res)), 0), rows - 1)
        k = r * cols + c
        if walkable[k] or (f * length <= relax and free[k]):
            continue
        return False
    return True


@njit(cache=True, nogil=True)
def _reach(
    ax, ay, chain, start, stop, walkable, free, ox, oy, inv_res, rows, cols, step, relax
):  # pragma: no cover - compiled
    """The last index j in start..stop with every chain[start..j] clear from a (start - 1
    when chain[start] is not)."""
    for j in range(start, stop + 1):
        if not _line_clear(
            ax,
            ay,
            chain[j, 0],
            chain[j, 1],
            walkable,
            free,
            ox,
            oy,
            inv_res,
            rows,
            cols,
            step,
            relax,
        ):
            return j - 1
    return stop


def warm_up() -> None:
    """Compile the line tests now (or load them from the disk cache), so that no frame
    waits for the compiler."""
    cells = np.ones(4, dtype=np.bool_)
    chain = np.zeros((2, 2))
    _reach(0.0, 0.0, chain, 0, 1, cells, cells, 0.0, 0.0, 1.0, 2, 2, 0.5, 0.0)
    _line_clear(0.0, 0.0, 1.0, 1.0, cells, cells, 0.0, 0.0, 1.0, 2, 2, 0.5, 0.0)


def _heading_deg(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    return math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))


def _length(points: NDArray[np.float64]) -> float:
    return float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0


def plan_for(semantic_map: SemanticMap, spec: DestinationSpec) -> Plan:
    """The map's plan for ``spec``, built on first use and cached (thread-safe).

    Raises:
        UnknownDestination: the map has nothing by that name.
        Unreachable: nothing walkable leads there.
    """
    target = resolve(semantic_map, spec)
    with _lock:
        # The map keeps its plans (the latest CACHE_SIZE, by spec), so they go with it.
        cache: OrderedDict[tuple[object, ...], Plan] = semantic_map.derived_value(
            ("guidance_plans",), OrderedDict
        )
        plan = cache.get(spec.key)
        if plan is not None:
            cache.move_to_end(spec.key)
            return plan
    plan = Plan(semantic_map, target)
    with _lock:
        cache[spec.key] = plan
        while len(cache) > CACHE_SIZE:
            cache.popitem(last=False)
    return plan


__all__ = ["Plan", "Route", "Unreachable", "plan_for"]
