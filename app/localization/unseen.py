"""Objects the estimate says are in plain view, that the camera keeps not reporting.

The sensor model of the paper (eqs. 2-3) only weighs what the detector reports: an
object the pose should see but that is never reported costs nothing. In a room that a
rotation maps onto itself except for one door, the mirror-image pose then explains
every detection as well as the true pose, and a false detection that happens to
point at the mirror's door tips the evidence its way. Yet from the mirror pose that
door is a few metres straight ahead, frame after frame, and no detection ever points
at it.

This module keeps that negative evidence for the gate of ``converged`` only (it never
moves a particle): per object, a decaying count of frames in which the estimate had it
*clearly in view* (line of sight on the visibility grid, within ``near_m``, at least
``margin_rad`` inside the field of view, of a class the detector has reported at least
once in this session, and no farther than the detector has been seen to report objects
of that class, or of any class while that one has not been seen yet: a detector that
only reports small objects up close is not held to more) and of those in which a
detection of its class pointed at it (within ``cutoff_sigmas`` of its bearing). An
object in clear view for ``min_expected`` frames' worth of count yet seen in at most
``max_seen_share`` of them, and missed in more of them than a detector with this
session's hit rate would miss by chance (``chance_miss``), marks the estimate as
*contradicted*: converged is not gained, and is given up. The hit rate is learnt from
the objects in clear view that the detector does report now and then: a detector that
misses a third of what is in view (distance, blur, occlusion by people) must miss an
object for longer before its absence says the pose is wrong. It is learnt per band of
distance (``band_m``): a detector reports a door 2 m away nearly every frame and one
7 m away, small in the image, perhaps two frames in three, so each miss weighs by the
rate at the object's distance then (a decayed sum of the misses' log-probabilities,
:attr:`UnseenObjects.miss_evidence`); a band with few frames leans on the rate over
all distances.

An object can be forgiven (:meth:`UnseenObjects.forgive`): once the filter knows its
converged place is the only one that explains what is seen (a recent global search found
no other) and knows it within a metre, an object flagged there is taken for moved or
gone from the world since the map was drawn, and flags nothing any more. One whose class
keeps being reported near it (a near miss) was moved (:attr:`UnseenObjects.moved`): the
filter then also takes it out of its sensor model
(:meth:`~app.localization.models.BearingSensorModel.exclude`), since its detections,
weighed against its drawn place, would drag the estimate to where that place explains
them. One with no detection of its class near it stays in the sensor model: it may be
there after all, missed by the detector, and still tells look-alike places apart.

An object is also taken for moved when it dragged a held fix off the odometry
(:meth:`UnseenObjects.take_moved`, from
:meth:`~app.localization.filter.ParticleFilter._blame_the_slide`): the fix was let go
for the slide, and without that object the place the recent frames fit best goes back
to where the odometry carried the fix.

A contradiction that lapses because the detector now reports its objects where the
estimate puts them is resolved (:attr:`UnseenObjects.resolved`): the estimate that
missed them was off, and has moved.

Only frames with detections count (a blocked camera reports nothing at all, which says
nothing about any one object). When the estimate jumps by more than ``jump_m`` the
counts start again: they were about another place.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import FilterConfig
from app.localization.fastmath import hypot
from app.localization.sensor import Observation
from app.maps.geometry import wrap_scalar as _wrap
from app.maps.model import SemanticMap


@dataclass(frozen=True)
class UnseenSettings:
    """What "clearly in view" means, and how much not seeing it takes."""

    near_m: float = 8.0
    #: Closer than this the bearing to an object's reference point is ill-defined.
    min_m: float = 0.7
    margin_rad: float = float(np.radians(10.0))
    #: A detection within this many of its class's stds of the object's bearing sees it.
    cutoff_sigmas: float = 4.0
    #: A detection of an object's class within the angle this much to the side of the
    #: object's reference point subtends (m) is no near miss (``near_miss_rad``): up
    #: close a box's centre is not that point (a table seen from a metre spans 70 deg,
    #: the detector boxes the part in view, a phone's frame cuts it), so it says
    #: nothing of the object having moved. Traced on long sessions (the office suite's
    #: walk there and back four times, PDR odometry, 360 deg, a map as drawn,
    #: tools/long_session.py): a table passed 0.6-1.6 m away, its boxes 10-15 deg off
    #: its centre, was taken for moved and left the sensor model; without it a
    #: look-alike place 7 m along took the belief and a fix was gained there (13 frames
    #: confidently wrong; 6 in another walk). Counting such detections as seeing the
    #: object instead (no contradiction either) kept a stale map's moved table from
    #: the unseen check: one walk of the phone suite's stale office lost the person for
    #: most of it (availability 0.49 -> 0.11). Beyond about 3.5 m the class's cutoff is
    #: the wider angle.
    extent_m: float = 0.5
    #: Per-frame decay of the counts (about 7 frames of memory).
    decay: float = 0.85
    min_expected: float = 4.0
    max_seen_share: float = 0.15
    jump_m: float = 1.0
    #: The detector's hit rate, learnt from the objects in clear view that it does
    #: report now and then (an object never reported is the question, not the rate):
    #: decayed sums of their frames in clear view and of those it was reported in, per
    #: frame by ``rate_decay`` (about 50 frames of memory), starting from a prior worth
    #: ``rate_prior_frames`` frames at ``rate_prior``.
    rate_decay: float = 0.98
    rate_prior: float = 0.9
    rate_prior_frames: float = 10.0
    #: The hit rate is learnt per band of distance this wide (m; bands up to ``near_m``),
    #: each starting from the rate over all distances, worth ``band_prior_frames``
    #: frames. Traced on the venue suite through a 66-degree camera: a door 7.1 m away
    #: missed in 3.6 of its 4.2 decayed frames in clear view let a right fix go, by a
    #: rate of 0.83 learnt mostly from objects a few metres away; the phone suite's
    #: detector (app/simulation/phone.py) reports an object at 7 m about 64 % of the
    #: time and one at 2 m 94 %.
    band_m: float = 2.0
    band_prior_frames: float = 10.0
    #: An object flagged by the counts must also have been missed more than a detector
    #: with the learnt hit rate would miss it by chance: that rate's miss probability to
    #: the power of the decayed missed frames must be below this. At a 90 % hit rate the
    #: counts ask more already (3.4 misses against 2.7); at 80 % it takes 3.9, at 70 %
    #: (a detector missing 30 % of what is in view) 5.2. Stricter (4e-4) gained more
    #: availability on the phone suite but let a stale map's moved objects drag a
    #: converged estimate over 1 m (5 frames); looser (1e-2) kept a corridor's flips.
    chance_miss: float = 2e-3
    #: A detection of an object's class within this angle of its bearing (but not close
    #: enough to see it, nor within its extent, ``extent_m``) is a near miss: the object
    #: may have been moved since the map was drawn (:meth:`UnseenObjects.forgive`).
    near_miss_rad: float = float(np.radians(25.0))
    #: A contradiction that lapsed is resolved once each object it flagged is reported
    #: in at least this share of its decayed frames in clear view (and has at least
    #: ``min_expected`` of them): the estimate that missed it has moved to where it is
    #: seen (:attr:`UnseenObjects.resolved`).
    resolved_share: float = 0.5
    #: ... and only once the contradiction has flagged on this many frames with
    #: detections (a held fix's ``ConvergenceGate.hold_unseen_frames``): one frame's flag
    #: is what an estimate dragged along by a moved object shows as the object's bearing
    #: sweeps through the edge of what sees it, and the reports after it are the drag's
    #: (phone suite, stale office at 360 deg, seed 0: resolved so, a fix gained 0.5 m off
    #: was dragged on to 0.8 m beyond its radius by a plant moved 1.3 m).
    resolve_after_flags: int = 2


DEFAULT_UNSEEN = UnseenSettings()


class UnseenObjects:
    """Decaying per-object counts of frames in clear view and frames seen."""

    def __init__(
        self,
        semantic_map: SemanticMap,
        config: FilterConfig,
        settings: UnseenSettings = DEFAULT_UNSEEN,
    ) -> None:
        self.map = semantic_map
        self.config = config
        self.settings = settings
        #: How many bands of distance the hit rate is learnt in.
        self.bands = max(1, math.ceil(settings.near_m / settings.band_m))
        self.reported = np.zeros(len(semantic_map.classes), dtype=bool)
        #: Per class, the farthest an object of it was seen from the estimate (m; 0 while
        #: none was): how far this detector reports such objects.
        self.reach_m = np.zeros(len(semantic_map.classes))
        #: Per band of distance (``band_m``), decayed frames in clear view, and
        #: reported, of the objects the detector does report (the hit rate's sums,
        #: :class:`UnseenSettings`): the detector's, kept over a reset as the classes are.
        self.rate_sums = np.zeros((self.bands, 2))
        #: Objects taken for gone from the world (a stale map, :meth:`forgive`): they
        #: flag nothing any more in this session.
        self.absent = np.zeros(semantic_map.object_count, dtype=bool)
        #: Of those, the ones forgiven with near misses: moved, not taken away.
        self.moved = np.zeros(semantic_map.object_count, dtype=bool)
        # The camera's view as the frame's count takes it (rad): its centre off the
        # body's forward, and the half-width in which an object is in clear view. The
        # config and settings are frozen, so each frame would compute the same two.
        self._fov_centre_rad = float(np.radians(config.fov_centre_deg))
        self._clear_half_fov_rad = float(np.radians(config.fov_deg) / 2.0 - settings.margin_rad)
        self.reset()

    def reset(self) -> None:
        """Forget the counts (not the classes the detector has reported)."""
        n = self.map.object_count
        self.expected = np.zeros(n)
        self.seen = np.zeros(n)
        #: Decayed frames in clear view with a near miss of the object (its class
        #: reported within ``near_miss_rad`` of it, but not seeing it).
        self.near = np.zeros(n)
        #: Decayed sums, over the frames an object was in clear view and not reported,
        #: of minus the log of the chance of that miss (the miss rate at its distance).
        self.miss_evidence = np.zeros(n)
        self._at: tuple[float, float] | None = None
        self._contradicted: bool | None = None  # None: compute from the counts
        #: The last frame's objects in clear view, and how many of them went unreported.
        self.frame_expected = 0
        self.frame_missed = 0
        #: The objects flagged since the last resolution (:attr:`resolved`), and on how
        #: many frames with detections. Cleared only by a resolution or a jump (this
        #: reset): an object of a contradiction that lapsed unresolved stays, so a later
        #: one is resolved only once that object is reported too. A brake kept on
        #: purpose: letting such objects go once the gate's wait is over let a moved
        #: plant, reported near its drawn place, resolve its own contradiction and a
        #: fix gained after it drift 1.05 m off (CHANGELOG, tried and not kept).
        self.lately = np.zeros(n, dtype=bool)
        self.flag_frames = 0
        #: Whether the last :meth:`update` resolved a lapsed contradiction.
        self.resolved = False

    @property
    def contradicted(self) -> bool:
        """Whether an object in clear view has gone unreported (module docstring).

        After :meth:`update` the frame's kernel has answered it already (the same
        comparisons, element by element); otherwise it is computed here."""
        if self._contradicted is not None:
            return self._contradicted
        return bool(self._flagged().any())

    def _flagged(self) -> NDArray[np.bool_]:
        """Per object, whether its counts flag it (:attr:`contradicted`'s formula)."""
        st = self.settings
        return (
            (self.expected >= st.min_expected)
            & (self.seen <= st.max_seen_share * self.expected)
            & (self.miss_evidence >= -math.log(st.chance_miss))
            & ~self.absent
        )

    @property
    def never_reported(self) -> bool:
        """Whether an object the counts flag has not been reported once at this place
        (not a far one the detector reports now and then: ConvergenceGate's
        ``hold_unseen_frames``)."""
        return bool((self._flagged() & (self.seen <= 0.0)).any())

    def forgive(self) -> int:
        """Take the objects flagged now for moved or gone from the world (those with near
        misses for moved, :attr:`moved`); how many there were. A fixture (a door, a
        window: :attr:`~app.maps.model.SemanticMap.fixed`) is never taken for moved: it
        is taken for gone (an opening drawn as a door that the detector never calls
        one), and stays in the sensor model.

        For a caller that knows the estimate is right although an object in clear view
        goes unreported: the filter calls it when a global search of the last few
        seconds found no other place that explains the detections as well (in a mirror
        image of a room or a twin office there is one, and the object then stays a
        contradiction), with its fix known within a metre and not sliding off the
        odometry. What is left is a map drawn before the object was moved or taken away.
        """
        flagged = self._flagged()
        fixed = self.map.fixed
        self.absent |= flagged
        near = self.near > self.settings.max_seen_share * self.expected
        self.moved |= flagged & near & ~fixed
        self._contradicted = None
        return int(flagged.sum())

    def take_moved(self, obj: int) -> None:
        """Take the movable object ``obj`` for moved since the map was drawn (it dragged
        a fix off the odometry: :meth:`~app.localization.filter.ParticleFilter.
        _blame_the_slide`): it flags nothing any
        more, and the filter takes it out of its sensor model."""
        if self.map.fixed[obj]:
            raise ValueError(f"object {obj} is a fixture: fixtures are never taken for moved")
        self.absent[obj] = True
        self.moved[obj] = True
        self._contradicted = None

    def miss_rates(self) -> NDArray[np.float64]:
        """Per band of distance, the learnt chance that an object in clear view goes
        unreported in a frame (:class:`UnseenSettings`)."""
        st = self.settings
        return _miss_rates(
            self.rate_sums, st.rate_prior, st.rate_prior_frames, st.band_prior_frames
        )

    def update(
        self,
        x: float,
        y: float,
        theta: float,
        obs: Observation,
        visible_row: NDArray[np.bool_] | None,
    ) -> None:
        """Count one frame at the estimate (x, y, theta); frames without detections skip."""
        self.resolved = False
        if obs.empty:
            return
        st = self.settings
        if self._at is not None and hypot(x - self._at[0], y - self._at[1]) > st.jump_m:
            self.reset()
        self._at = (x, y)
        # The observation's class groups as the map's class indices.
        group_class = self.map.class_indexes(obs.classes)
        self.reported[group_class] = True
        with_row = visible_row is not None and self.config.visibility
        fov_check = self.config.fov_deg < 360.0
        # The objects' directions by numpy's arctan2, whose last bit can differ from the
        # C library's that compiled code calls (numpy has its own SIMD version).
        dx = self.map.object_xy[:, 0] - x
        dy = self.map.object_xy[:, 1] - y
        (
            self.expected,
            self.seen,
            self.near,
            self.miss_evidence,
            self.frame_expected,
            self.frame_missed,
            self._contradicted,
        ) = _count_frame(
            dx, dy, np.arctan2(dy, dx), float(theta), self.map.object_class, self.reported,
            np.ascontiguousarray(visible_row if with_row else self.reported, dtype=np.bool_),
            with_row, fov_check,
            self._fov_centre_rad, self._clear_half_fov_rad,
            obs.det_bearing, obs.det_group, group_class, obs.group_kappa,
            st.near_m, st.min_m, st.cutoff_sigmas, st.decay, st.min_expected, st.max_seen_share,
            self.reach_m, self.expected, self.seen, self.near, self.miss_evidence, self.absent,
            self.rate_sums, st.band_m, st.rate_decay, st.rate_prior, st.rate_prior_frames,
            st.band_prior_frames, st.chance_miss, st.near_miss_rad, st.extent_m,
        )  # fmt: skip
        self._note_lately()

    def _note_lately(self) -> None:
        """Keep the objects a contradiction flags, and tell when one that lapsed is
        resolved (:attr:`resolved`).

        A contradiction lapses in one of two ways: its object leaves the estimate's clear
        view unresolved (the gate then waits, ConvergenceGate.regain_after_unseen_frames),
        or the detector reports it where the estimate now puts it. Traced on the phone
        suite's stale office at 360 deg (seed 2): a table 1.3 m away went unreported
        while a first fix converging on the person was 0.9-0.3 m off, then was reported
        in 4 of its 6.6 decayed frames at 0.06 m, and "not sure" lasted 5 s more. Once
        every object flagged since the last resolution (on at least
        ``resolve_after_flags`` frames) is reported in ``resolved_share`` of its decayed
        frames in clear view (at least ``min_expected`` of them), the contradiction is
        resolved: the place that missed it was not this one. One
        forgiven (:meth:`forgive`) is not: the gate's wait after it is the margin a
        stale map's moved objects need (measured: a first fix gained at once after a
        removed door was forgiven, on the same suite, seed 3, was dragged 1.1 m off by
        a moved plant and a table added since)."""
        if self.contradicted:
            self.lately |= self._flagged()
            self.flag_frames += 1
            return
        st = self.settings
        if not self.lately.any() or self.flag_frames < st.resolve_after_flags:
            return
        exp, seen = self.expected[self.lately], self.seen[self.lately]
        reported = (exp >= st.min_expected) & (seen >= st.resolved_share * exp)
        if bool(np.all(reported & ~self.absent[self.lately])):
            self.lately[:] = False
            self.flag_frames = 0
            self.resolved = True

    @property
    def frame_contradicts(self) -> bool:
        """Whether the last frame left at least half of the objects in clear view
        unreported (or had none in clear view to judge by)."""
        return self.frame_expected == 0 or 2 * self.frame_missed >= self.frame_expected

    def checkpoint(self) -> dict[str, Any]:
        return {
            "expected": self.expected,
            "seen": self.seen,
            "reported": self.reported,
            "reach": self.reach_m,
            # The sums over all bands under the key a version before the bands reads
            # (a rolling upgrade's older worker restores the session), the bands beside.
            "rate": self.rate_sums.sum(axis=0),
            "rate_bands": self.rate_sums,
            "absent": self.absent,
            "moved": self.moved,
            "near": self.near,
            "miss": self.miss_evidence,
            "at": None if self._at is None else list(self._at),
            "lately": self.lately,
            "flag_frames": self.flag_frames,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        self.expected = np.array(state["expected"], dtype=np.float64)
        self.seen = np.array(state["seen"], dtype=np.float64)
        self.reported = np.array(state["reported"], dtype=bool)
        self.reach_m = np.array(state.get("reach", np.zeros(self.reported.size)), dtype=float)
        # (a checkpoint from before the learnt hit rate starts from its prior; one from
        # before its bands of distance spreads its sums evenly over them)
        bands = state.get("rate_bands")
        if bands is not None:
            self.rate_sums = np.array(bands, dtype=np.float64)
        else:
            rate = np.array(state.get("rate", np.zeros(2)), dtype=np.float64)
            self.rate_sums = np.repeat(rate[None, :] / self.bands, self.bands, axis=0)
        near = state.get("near")
        self.near = np.zeros(self.expected.size) if near is None else np.array(near, dtype=float)
        miss = state.get("miss")
        if miss is None:  # (before the misses were weighed: all at the rate over all bands)
            st = self.settings
            hit = _pooled_hit_rate(self.rate_sums, st.rate_prior, st.rate_prior_frames)
            miss = (self.expected - self.seen) * -math.log(_miss_of(hit))
        self.miss_evidence = np.array(miss, dtype=np.float64)
        absent = state.get("absent")
        self.absent = (
            np.zeros(self.map.object_count, dtype=bool)
            if absent is None
            else np.array(absent, dtype=bool)
        )
        # (checkpoints from before moved objects were forgiven hold none)
        moved = state.get("moved")
        self.moved = (
            np.zeros(self.map.object_count, dtype=bool)
            if moved is None
            else np.array(moved, dtype=bool)
        )
        at = state["at"]
        self._at = None if at is None else (float(at[0]), float(at[1]))
        self._contradicted = None
        # (checkpoints from before lapsed contradictions were resolved hold none)
        lately = state.get("lately")
        self.lately = (
            np.zeros(self.map.object_count, dtype=bool)
            if lately is None
            else np.array(lately, dtype=bool)
        )
        self.flag_frames = int(state.get("flag_frames", 0))
        self.resolved = False


@njit(cache=True)
def _pooled_hit_rate(rate_sums, prior, prior_frames):  # pragma: no cover - compiled
    """The hit rate over all bands of distance, from ``prior`` worth ``prior_frames``."""
    return (rate_sums[:, 1].sum() + prior * prior_frames) / (rate_sums[:, 0].sum() + prior_frames)


@njit(cache=True)
def _miss_of(hit):  # pragma: no cover - compiled
    """One minus a hit rate, kept off 0 and 1 (its log is a miss's weight)."""
    return min(max(1.0 - hit, 1e-6), 1.0 - 1e-9)


@njit(cache=True)
def _miss_rates(rate_sums, prior, prior_frames, band_prior_frames):  # pragma: no cover - compiled
    """:meth:`UnseenObjects.miss_rates`: per band, the hit rate from its sums starting from
    the rate over all bands (:func:`_pooled_hit_rate`), and one minus it."""
    pooled = _pooled_hit_rate(rate_sums, prior, prior_frames)
    out = np.empty(rate_sums.shape[0])
    for b in range(rate_sums.shape[0]):
        hit = (rate_sums[b, 1] + pooled * band_prior_frames) / (rate_sums[b, 0] + band_prior_frames)
        out[b] = _miss_of(hit)
    return out


@njit(cache=True)
def _count_frame(dx, dy, direction, theta, object_class, reported, visible_row, with_row, fov_check, fov_centre, half_fov, det_bearing, det_group, group_class, group_kappa, near_m, min_m, cutoff_sigmas, decay, min_expected, max_seen_share, reach, expected, seen, near, miss_evidence, absent, rate_sums, band_m, rate_decay, rate_prior, rate_prior_frames, band_prior_frames, chance_miss, near_miss_rad, extent_m):  # fmt: skip  # noqa: E501  # pragma: no cover - compiled
    """One frame's counts at the pose (its offsets ``dx``, ``dy`` to the objects, their
    ``direction`` and the heading ``theta``), with numpy's arithmetic of the
    vectorized form it replaces, element by element (the same bits; compiled because
    the filter runs it every frame on a few dozen objects, where numpy's per-call cost
    was most of the time): the objects in view, those a detection of their class
    points at, the detector's reach per class (``reach``, updated in place), then the
    decayed counts, the hit rate's sums per band of distance and the misses' evidence
    at the bands' rates after this frame. Returns the new counts and evidence, the
    frame's objects in clear view and missed, and whether an object is now flagged as
    unseen (:attr:`UnseenObjects.contradicted`'s comparisons)."""
    n = object_class.shape[0]
    dist = np.empty(n)
    view = np.zeros(n, dtype=np.bool_)
    hit = np.zeros(n, dtype=np.bool_)
    close = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        dist[i] = np.hypot(dx[i], dy[i])
        c = object_class[i]
        v = dist[i] <= near_m and dist[i] >= min_m and reported[c]
        if with_row:
            v = v and visible_row[i]
        bearing = _wrap(direction[i] - theta)
        if fov_check:
            v = v and abs(_wrap(bearing - fov_centre)) <= half_fov
        view[i] = v
        if not v:
            continue
        extent = np.arctan2(extent_m, dist[i])
        for k in range(det_bearing.shape[0]):
            g = det_group[k]
            if group_class[g] != c:
                continue
            within = cutoff_sigmas / np.sqrt(group_kappa[g])
            off = abs(_wrap(det_bearing[k] - bearing))
            if off <= within:
                hit[i] = True
                break
            if off <= near_miss_rad and off > extent:
                close[i] = True
    # How far this detector reports each class, learnt from what it reported; a class
    # never seen yet is expected as far as any class was.
    for i in range(n):
        if hit[i]:
            reach[object_class[i]] = max(reach[object_class[i]], dist[i])
    top = reach.max()
    new_expected = np.empty(n)
    new_seen = np.empty(n)
    new_near = np.empty(n)
    in_clear = 0
    missed = 0
    bands = rate_sums.shape[0]
    band = np.zeros(n, dtype=np.int64)
    clear = np.zeros(n, dtype=np.bool_)
    rate_sums *= rate_decay
    for i in range(n):
        r = reach[object_class[i]]
        clear[i] = view[i] and dist[i] <= (r if r > 0.0 else top)
        band[i] = min(int(dist[i] / band_m), bands - 1)
        new_expected[i] = decay * expected[i] + (1.0 if clear[i] else 0.0)
        new_seen[i] = decay * seen[i] + (1.0 if clear[i] and hit[i] else 0.0)
        new_near[i] = decay * near[i] + (1.0 if clear[i] and close[i] and not hit[i] else 0.0)
        if clear[i]:
            in_clear += 1
            if not hit[i]:
                missed += 1
            # The hit rate counts the objects this detector does report now and then.
            if new_seen[i] > max_seen_share * new_expected[i]:
                rate_sums[band[i], 0] += 1.0
                rate_sums[band[i], 1] += 1.0 if hit[i] else 0.0
    miss_rate = _miss_rates(rate_sums, rate_prior, rate_prior_frames, band_prior_frames)
    needed = -np.log(chance_miss)
    new_miss = np.empty(n)
    flagged = False
    for i in range(n):
        new_miss[i] = decay * miss_evidence[i] + (
            -np.log(miss_rate[band[i]]) if clear[i] and not hit[i] else 0.0
        )
        if (
            new_expected[i] >= min_expected
            and new_seen[i] <= max_seen_share * new_expected[i]
            and new_miss[i] >= needed
            and not absent[i]
        ):
            flagged = True
    return new_expected, new_seen, new_near, new_miss, in_clear, missed, flagged
