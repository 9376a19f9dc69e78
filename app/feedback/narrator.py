"""What to say after each frame: the items, and the text for speech.

Honesty first: while the filter has not converged, no position, region or
map-derived direction is stated as fact. The narrator then says the location is not
yet certain, reports what the camera sees right now in relative terms, and names
competing regions when the hypotheses disagree.

Once converged, ``items`` lists the map objects matched to this frame's detections,
then the nearest other visible objects. ``text`` holds only what is new: an object
already announced at the same clock position is not repeated until it moves by an
hour on the clock, its distance changes notably, or a minute has passed. Entering a
region is announced. ``describe=True`` ("Where am I?") gives a full description now.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.feedback.phrasing import (
    FEET_PER_METRE,
    Style,
    Units,
    article,
    capitalize,
    clock_distance_hours,
    clock_from_bearing_deg,
    direction_phrase,
    distance_phrase,
)
from app.localization.sensor import Observation
from app.localization.types import Detection, Estimate, Odometry
from app.maps.geometry import wrap_rad
from app.maps.model import SemanticMap
from app.maps.prepare import ensure_prepared

#: Repeat an unchanged announcement after this long (seconds).
REPEAT_AFTER_S = 60.0
#: Routine object updates are spoken at most this often (seconds), so speech keeps up.
MIN_GAP_S = 2.0
#: Hypotheses lighter than this are not named as alternatives.
MIN_ALTERNATIVE_WEIGHT = 0.1
#: Above this position std (m) distances are hedged with "roughly".
CERTAIN_STD_M = 0.25
#: ... and above this protection radius (m): converged, but the belief a little wider.
CERTAIN_PROTECTION_M = 1.0
#: A suggestion (turn or walk) is spoken at most this often (seconds; docs/API.md).
SUGGEST_EVERY_S = 10.0
#: A camera narrower than this is turned to see more; a full turn on the spot (or a
#: wider camera) has shown what there is to see from here: walking helps next.
LOOK_AROUND_FOV_DEG = 300.0
FULL_TURN_RAD = 2.0 * math.pi
#: After walking this far (m) while not located, looking around is worth it again.
WALK_SOME_M = 3.0
SUGGESTION_WORDS = {
    "turn": "Turn slowly on the spot to look around.",
    "walk": "Walk a few steps to help me find where you are.",
}
#: Said instead of a suggestion where the map turns onto itself and only its twin places
#: are left to tell apart: neither turning nor walking can.
TWINS_WORDS = (
    "This place looks the same turned round, so I cannot tell which way you face "
    "without a compass heading."
)


#: Said instead of a suggestion where the belief is one place on floors that look alike:
#: neither turning nor walking on this floor can tell which floor it is.
ALIKE_LEVELS_WORDS = (
    "These floors look the same, so I cannot tell which floor you are on from what I see."
)


def found_sentence(protection_m: float | None, units: Units = "metric") -> str:
    """What is said as the person is located: with the protection radius when it is wider
    than ``CERTAIN_PROTECTION_M`` ("Location found, to within about 2 metres."), so that
    a fix that may be a metre or two off is never told as a plain one. The radius is a
    bound, so it is rounded up (to the metre, or the foot), never down. A fix is gained
    only with a radius of at most 1.5 m (``convergence.GAIN_PROTECTION_M``); through a
    phone's 66-degree camera most gains come with a radius over a metre (measured on the
    phone suite, CHANGELOG)."""
    if protection_m is None or protection_m <= CERTAIN_PROTECTION_M:
        return "Location found."
    if units == "imperial":
        bound = math.ceil(protection_m * FEET_PER_METRE - 1e-9) / FEET_PER_METRE
    else:
        bound = float(math.ceil(protection_m - 1e-9))
    return f"Location found, to within {distance_phrase(bound, units)}."


@dataclass(frozen=True)
class FeedbackOptions:
    style: Style = "clock"
    units: Units = "metric"
    max_items: int = 3


@dataclass(frozen=True)
class FeedbackItem:
    """One object in the feedback; direction and distance are None when not known."""

    cls: str
    label: str | None
    clock: int | None
    bearing_deg: float | None
    distance_m: float | None


@dataclass(frozen=True)
class Feedback:
    text: str
    items: list[FeedbackItem] = field(default_factory=list)
    #: While not located, what would help most: "turn", "walk", or None.
    suggestion: str | None = None


@dataclass
class _Said:
    clock: int
    distance_m: float | None
    at_s: float


class Narrator:
    """Per-session narrator; remembers what was said to avoid repeating it."""

    def __init__(self, semantic_map: SemanticMap, options: FeedbackOptions | None = None) -> None:
        self.map = ensure_prepared(semantic_map)  # its visibility grid, built now if need be
        self.options = options or FeedbackOptions()
        self._said: dict[tuple[object, ...], _Said] = {}
        self._region: str | None = None
        self._was_converged = False
        self._status_at: float | None = None
        self._ambiguity: tuple[str, ...] = ()
        self._objects_at: float | None = None
        self._class_index = {c: i for i, c in enumerate(semantic_map.classes)}
        #: While not located: how far the person turned on the spot and walked since the
        #: last look around, and when a suggestion was last spoken.
        self._turned_rad = 0.0
        self._walked_m = 0.0
        self._suggested_at: float | None = None

    # ------------------------------------------------------------- checkpoints
    def checkpoint(self) -> dict[str, Any]:
        """What was said and when, as plain data (times as this narrator saw them)."""
        return {
            "said": [
                [list(key), said.clock, said.distance_m, said.at_s]
                for key, said in self._said.items()
            ],
            "region": self._region,
            "was_converged": self._was_converged,
            "status_at": self._status_at,
            "ambiguity": list(self._ambiguity),
            "objects_at": self._objects_at,
            "turned_rad": self._turned_rad,
            "walked_m": self._walked_m,
            "suggested_at": self._suggested_at,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a :meth:`checkpoint`. Times from another process's clock (frames
        without timestamps) only make an announcement come once more: a time in the
        future counts as long ago."""
        self._said = {tuple(k): _Said(int(c), d, float(at)) for k, c, d, at in state["said"]}
        self._region = state["region"]
        self._was_converged = bool(state["was_converged"])
        self._status_at = state["status_at"]
        self._ambiguity = tuple(state["ambiguity"])
        self._objects_at = state["objects_at"]
        # (checkpoints from before suggestions hold none of these)
        self._turned_rad = float(state.get("turned_rad", 0.0))
        self._walked_m = float(state.get("walked_m", 0.0))
        self._suggested_at = state.get("suggested_at")

    # ------------------------------------------------------------------ public
    def update(
        self,
        estimate: Estimate,
        detections: Sequence[Detection],
        *,
        timestamp_s: float | None,
        describe: bool = False,
        fov_deg: float = 360.0,
        fov_centre_deg: float = 0.0,
        observation: Observation | None = None,
        odometry: Odometry | None = None,
        gone: NDArray[np.bool_] | None = None,
        twins: bool = False,
        levels_alike: bool = False,
    ) -> Feedback:
        """Feedback for one frame (see the module docstring for the rules).

        ``fov_deg`` and ``fov_centre_deg``: the camera's field of view and the direction
        of its middle relative to the body (a yawed phone camera). ``observation``: the
        filter's :func:`~app.localization.sensor.prepare_observation` of these very
        detections on this map, when at hand (its arrays are then used as they are).
        ``gone``: per map object, whether the filter took it for moved or taken away
        since the map was drawn (:meth:`app.localization.unseen.UnseenObjects.forgive`):
        such an object is not said, since where the map has it is not where it is.
        ``twins``: only the map's twin places (:mod:`app.maps.symmetry`) keep the fix
        from being told: nothing is suggested, and the words say why.
        ``levels_alike``: only the same place on floors that look alike keeps it
        (:func:`app.maps.symmetry.alike_levels`): likewise.
        """
        now = time.monotonic() if timestamp_s is None else float(timestamp_s)
        if estimate.converged:
            self._turned_rad = self._walked_m = 0.0
            self._suggested_at = None
            fov = (fov_deg, fov_centre_deg)
            return self._located(estimate, detections, now, describe, fov, observation, gone)
        dets = [d for d in detections if d.score > 0 and d.cls in self.map.class_members]
        feedback = self._uncertain(estimate, dets, now, describe)
        suggestion: str | None = self._suggest(odometry, fov_deg)
        words = SUGGESTION_WORDS[suggestion] if suggestion is not None else ""
        if twins:
            suggestion, words = None, TWINS_WORDS
        elif levels_alike:
            suggestion, words = None, ALIKE_LEVELS_WORDS
        text = feedback.text
        last = self._suggested_at
        # (a time in the future, from another process's clock, counts as long ago)
        if describe or last is None or not 0.0 <= now - last < SUGGEST_EVERY_S:
            text = f"{text} {words}" if text else words
            self._suggested_at = now
        return Feedback(text, feedback.items, suggestion)

    def _suggest(self, odometry: Odometry | None, fov_deg: float) -> str:
        """What would help most while not located: turning on the spot until a narrow
        camera has looked all around, else walking (until a few metres, then looking
        around again)."""
        if odometry is not None:
            self._turned_rad += abs(odometry.turn_rad)
            self._walked_m += math.hypot(odometry.forward_m, odometry.left_m)
        if self._walked_m >= WALK_SOME_M:
            self._turned_rad = self._walked_m = 0.0
        if fov_deg < LOOK_AROUND_FOV_DEG and self._turned_rad < FULL_TURN_RAD:
            return "turn"
        return "walk"

    # ------------------------------------------------------------- not located
    def _uncertain(
        self, estimate: Estimate, dets: list[Detection], now: float, describe: bool
    ) -> Feedback:
        opts = self.options
        # Most confident first, then what is most nearly ahead.
        seen = sorted(dets, key=lambda d: (-d.score, abs(d.bearing_rad)))[: opts.max_items]
        items = [
            FeedbackItem(
                d.cls,
                None,
                clock_from_bearing_deg(math.degrees(d.bearing_rad)),
                round(math.degrees(d.bearing_rad), 1),
                None,
            )
            for d in seen
        ]
        parts: list[str] = []
        regions = self._candidate_regions(estimate)
        first = self._was_converged or self._status_at is None
        stale = self._status_at is not None and now - self._status_at >= REPEAT_AFTER_S
        if describe or first or stale or regions != self._ambiguity:
            if self._was_converged:
                parts.append("I am no longer sure where you are.")
            if len(regions) >= 2:
                parts.append(f"You may be in {' or '.join(regions)}; not certain yet.")
            else:
                parts.append("Your location is not certain yet.")
            self._status_at = now
            self._ambiguity = regions
        self._was_converged = False
        self._region = None
        fresh = []
        for d in seen if describe or self._gap_passed(now) else []:
            clock = clock_from_bearing_deg(math.degrees(d.bearing_rad))
            if describe or self._is_new(("seen", d.cls, clock), clock, None, now):
                fresh.append(
                    f"{article(d.cls)} {direction_phrase(math.degrees(d.bearing_rad), opts.style)}"
                )
        if fresh:
            self._objects_at = now
            parts.append(f"I see {_join(fresh)}; still working out where you are.")
        return Feedback(" ".join(parts), items)

    def _candidate_regions(self, estimate: Estimate) -> tuple[str, ...]:
        names: list[str] = []
        for h in estimate.hypotheses:
            if h.weight < MIN_ALTERNATIVE_WEIGHT:
                continue
            r = self.map.region_at(h.x, h.y)
            if r is not None and r not in names:
                names.append(r)
        return tuple(names)

    # ----------------------------------------------------------------- located
    def _located(
        self,
        estimate: Estimate,
        detections: Sequence[Detection],
        now: float,
        describe: bool,
        fov: tuple[float, float],
        observation: Observation | None,
        gone: NDArray[np.bool_] | None = None,
    ) -> Feedback:
        opts = self.options
        certain = max(estimate.std_x_m, estimate.std_y_m) <= CERTAIN_STD_M and (
            estimate.protection_m is None or estimate.protection_m <= CERTAIN_PROTECTION_M
        )
        ordered, rel, dist = self._ordered_objects(estimate, detections, fov, observation, gone)
        # The few shown objects' offsets and distances read from plain lists: indexing
        # the arrays with a list of them cost more than converting them whole.
        rel_xy, dist_m = rel.tolist(), dist.tolist()
        items = []
        for n in ordered[: opts.max_items]:
            dx, dy = rel_xy[n]
            bearing = math.degrees(wrap_rad(math.atan2(dy, dx) - estimate.theta_rad))
            items.append(
                FeedbackItem(
                    self.map.class_of(n),
                    self.map.object_labels[n],
                    clock_from_bearing_deg(bearing),
                    round(bearing, 1),
                    round(dist_m[n], 2),
                )
            )
        parts: list[str] = []
        if not self._was_converged:
            parts.append(found_sentence(estimate.protection_m, opts.units))
        region = self.map.region_at(estimate.x, estimate.y)
        if describe or region != self._region:
            if region is not None:
                parts.append(f"You are in {region}.")
            elif describe:
                parts.append("You are outside the named areas of this map.")
        self._region = region
        self._was_converged = True
        self._status_at = None
        spoken = False
        for n, item in zip(
            ordered, items if describe or self._gap_passed(now) else [], strict=False
        ):
            if describe or self._is_new(("obj", int(n)), item.clock, item.distance_m, now):
                spoken = True
                name = item.label or item.cls
                where = direction_phrase(item.bearing_deg or 0.0, opts.style)
                far = distance_phrase(item.distance_m or 0.0, opts.units, certain=certain)
                parts.append(f"{capitalize(name)} {where}, {far}.")
        if spoken:
            self._objects_at = now
        return Feedback(" ".join(parts), items)

    def _ordered_objects(
        self,
        estimate: Estimate,
        detections: Sequence[Detection],
        fov: tuple[float, float],
        observation: Observation | None = None,
        gone: NDArray[np.bool_] | None = None,
    ) -> tuple[list[int], NDArray[np.float64], NDArray[np.float64]]:
        """Objects matched to this frame's detections first (nearest first), then the
        nearest visible others (the first object on a tie in distance); none of the
        objects ``gone``.

        Also each object's offset from the pose, shape (N, 2), and distance, shape (N,).

        The matching is the sensor model's own correspondence (eq. 3, :func:`match_detections
        <app.localization.sensor.match_detections>`) at the estimated pose only, within
        the camera's view, with the same arithmetic, so it picks the same objects: the
        largest cosine of the bearing error, the first object on a tie. Detections are
        taken in the sensor model's order (by class, then as given). The camera may
        look off the body's forward by centre_deg: the pose turns by it and the bearings
        (relative to the body) by the opposite, so each detection still points the same
        way while the field of view is centred on the camera.

        The filter's observation of the frame holds the same detections (those of the
        map's classes with a positive score) in the same order, their cosines and sines
        computed already: with the camera facing forward they are used as they are.
        """
        fov_deg, centre_deg = fov
        centre = math.radians(centre_deg)
        theta = estimate.theta_rad + centre
        if observation is not None and centre == 0.0:
            cos_b, sin_b = observation.det_cos, observation.det_sin
            cls = self.map.class_indexes(observation.classes)[observation.det_group]
        else:
            by_class = sorted(
                (d for d in detections if d.score > 0 and d.cls in self.map.class_members),
                key=lambda d: d.cls,
            )
            bearing = np.array([d.bearing_rad - centre for d in by_class], dtype=np.float64)
            cos_b, sin_b = np.cos(bearing), np.sin(bearing)
            cls = np.array([self._class_index[d.cls] for d in by_class], dtype=np.int64)
        # Line of sight from the map's precomputed grid (the cell around the pose).
        visible = self.map.visibility.row(estimate.x, estimate.y)
        if gone is not None and gone.any():
            visible = visible & ~gone
        # The cosines and sines by numpy (its own SIMD versions: the compiled code's C
        # library may differ in the last bit), the rest compiled.
        order, rel, dist = _order_objects(
            float(estimate.x), float(estimate.y), float(np.cos(theta)), float(np.sin(theta)),
            self.map.object_xy, visible, fov_deg < 360.0,
            _cos_half_fov(fov_deg), cos_b, sin_b, cls,
            self.map.object_class,
        )  # fmt: skip
        return order.tolist(), rel, dist

    # ------------------------------------------------------------ repetition
    def _gap_passed(self, now: float) -> bool:
        return self._objects_at is None or not 0 <= now - self._objects_at < MIN_GAP_S

    def _is_new(
        self, key: tuple[object, ...], clock: int | None, distance_m: float | None, now: float
    ) -> bool:
        """True when this announcement adds something; remembers it if so."""
        said = self._said.get(key)
        changed = (
            said is None
            or clock is None
            or clock_distance_hours(said.clock, clock) >= 1
            or now - said.at_s >= REPEAT_AFTER_S
            or now < said.at_s
            or (
                distance_m is not None
                and said.distance_m is not None
                and abs(distance_m - said.distance_m) >= max(1.0, 0.3 * said.distance_m)
            )
        )
        if changed:
            self._said[key] = _Said(clock or 0, distance_m, now)
        return changed


@functools.lru_cache(maxsize=16)
def _cos_half_fov(fov_deg: float) -> float:
    """cos(fov_deg / 2) by numpy, kept: a session's camera keeps its field of view, and
    numpy's calls on a scalar cost more than the lookup every frame."""
    return float(np.cos(np.radians(fov_deg) / 2.0))


def _join(words: list[str]) -> str:
    if len(words) <= 1:
        return "".join(words)
    return ", ".join(words[:-1]) + " and " + words[-1]


def warm_up() -> None:
    """Compile the ordering kernel now (or load it from the disk cache): compiled on a
    session's first located frame instead, it held the event loop for about 0.7 s on a
    machine without numba's cache."""
    ones, none = np.ones(2), np.zeros(1, dtype=np.int64)
    seen = np.ones(2, dtype=np.bool_)
    seen.flags.writeable = False  # as the visibility rows are (another compiled variant)
    _order_objects(0.0, 0.0, 1.0, 0.0, np.ones((2, 2)), seen, True, 0.5, ones[:1], ones[:1], none, none)  # fmt: skip  # noqa: E501


@njit(cache=True, nogil=True)
def _order_objects(ex, ey, cos_t, sin_t, obj_xy, visible, fov_check, cos_half_fov, cos_b, sin_b, cls, object_class):  # fmt: skip  # noqa: E501  # pragma: no cover - compiled
    """:meth:`Narrator._ordered_objects` past the detections' arrays: (the objects'
    order, their offsets from (ex, ey), shape (N, 2), their distances).

    For each detection (in the given order) its best object: the unit vector towards
    each object in the camera's frame (its forward part also says whether the object
    is in the field of view), then the largest cosine of the bearing error, the first
    on a tie; detections with none of their class in view match nothing. The matched
    objects, each once, sorted by distance (stable), then the other visible objects by
    distance (stable). numpy's element-wise arithmetic of the vectorized form, in its
    order; its ``hypot`` is the C library's, as here.
    """
    n = obj_xy.shape[0]
    rel = np.empty((n, 2))
    dist = np.empty(n)
    bx = np.empty(n)
    by = np.empty(n)
    seen = np.empty(n, dtype=np.bool_)
    for i in range(n):
        dx = obj_xy[i, 0] - ex
        dy = obj_xy[i, 1] - ey
        rel[i, 0] = dx
        rel[i, 1] = dy
        dist[i] = np.hypot(dx, dy)
        reach = dist[i] + 1e-12
        bx[i] = (cos_t * dx + sin_t * dy) / reach
        by[i] = (-sin_t * dx + cos_t * dy) / reach
        seen[i] = visible[i] and (bx[i] >= cos_half_fov or not fov_check)
    taken = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    found = 0
    for k in range(cls.shape[0]):
        top = -np.inf
        pick = -1
        for i in range(n):
            if object_class[i] != cls[k] or not seen[i]:
                continue
            c = cos_b[k] * bx[i] + sin_b[k] * by[i]
            if pick < 0 or c > top:
                top, pick = c, i
        if pick >= 0 and np.isfinite(top) and not taken[pick]:
            taken[pick] = True
            # Insertion by distance, after any equally far: a stable sort.
            j = found
            while j > 0 and dist[order[j - 1]] > dist[pick]:
                order[j] = order[j - 1]
                j -= 1
            order[j] = pick
            found += 1
    for i in np.argsort(dist, kind="mergesort"):
        if visible[i] and not taken[i]:
            order[found] = i
            found += 1
    return order[:found], rel, dist
