"""Whether to tell a person they are located, and how far off they may be.

:class:`ConvergenceGate` decides ``converged`` with hysteresis: gained once the heaviest
cluster is tight and heavy, has stayed put for a few frames, explains the detections, a
global search has run since it formed (or a tight known start rules other places out),
the alternatives it found are improbable and the protection radius is narrow
(:data:`GAIN_PROTECTION_M`); held until the cluster spreads, lightens
or jumps, the detections stop fitting, an object in clear view keeps going unreported,
the odometry breaks off, dead reckoning lasts too long, an alternative gains
probability, or the estimate slides away from where the odometry carries it
(:mod:`~app.localization.slide`). :func:`protection_radius` is the radius around the
pose that holds the truth with 99 % probability under the whole belief (the filter also
bounds it below by what systematic bearing errors can do,
:mod:`~app.localization.dilution`, and widens it by residuals the noise does not explain
and by a slide away from the odometry, :func:`widened_radius`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.fastmath import hypot
from app.localization.resampling import systematic_indexes
from app.localization.types import Estimate
from app.maps.geometry import wrap_rad
from app.state import from_plain

#: The reasons that, alone, let a fix go for doubt (ConvergenceGate.let_go_for_doubt).
#: A jump joined the alternative (issues 27 and 28): a fix let go at 0.15 m of error for
#: a one-step jump was then held 12 s to a first fix's radius by a geometry bound of
#: 1.6-1.7 m (the venue's PDR walks at 180 deg, seed 1). Measured, same machine: venue
#: PDR 180 deg Second Floor 89.8 -> 92.0 % of walking frames, every condition still 0
#: confidently wrong (seeds 10-29 at PDR 180 deg the same); phone suite 13 -> 13
#: confidently wrong at 5 frames/s and 59 -> 59 at 10, availability unchanged to four
#: places; integrity suite 3 -> 3, availability 0.8758 -> 0.8760.
#: Weak geometry joined them too: a bound grown past ``hold_geometry_m`` questions nothing
#: about the place, only how closely it is known (continuation.GEOMETRY_DOUBT_FRAMES).
DOUBT_ONLY: tuple[tuple[str, ...], ...] = (("alternative",), ("jump",), ("weak geometry",))


@dataclass(frozen=True)
class FitQuality:
    """How well the estimated pose explains the recent detections (see the filter).

    ``fit``: smoothed mean squared bearing residual (in stds) of the detections that an
    object explains better than the clutter floor does; ``unexplained``: smoothed share
    of detections the clutter floor explains better (false ones, or a wrong pose);
    ``bad_frame``: this frame alone says the pose is wrong (most of at least three
    detections unexplained).
    """

    fit: float
    unexplained: float
    bad_frame: bool = False
    #: An object in clear view keeps going unreported (:mod:`~app.localization.unseen`).
    contradicted: bool = False
    #: ... and one such object was never reported at this place (not a far object the
    #: detector sees now and then, missed by chance for a few frames).
    never_reported: bool = False
    #: A contradiction that lapsed has its objects reported where the estimate now puts
    #: them (:attr:`~app.localization.unseen.UnseenObjects.resolved`).
    resolved: bool = False


class ConvergenceGate:
    """``converged`` with hysteresis: hard to gain, lost only for a real reason.

    **Gained** when the heaviest cluster is tight and heavy (:func:`estimate_pose`) and
    has stayed put (moving no more than the odometry allows plus ``tolerance_m``,
    turning no more than ``tolerance_rad``) for ``frames`` consecutive frames, explains
    what the camera sees (``fit`` at most ``gain_fit``, at most ``gain_unexplained`` of
    the detections left to clutter, no object in clear view going unreported:
    :mod:`~app.localization.unseen`), detections arrived in the last
    ``gain_without_evidence`` frames, the recent bearings' geometry pins the fix within
    ``gain_geometry_m`` (:mod:`~app.localization.dilution`), a global consistency search
    has run since the cluster formed, the alternatives it found hold at most
    ``gain_alternatives`` of the probability (:mod:`~app.localization.evidence`; and
    long-lived rivals, their evidence counted at a discount, ``gain_rivals``) and
    held no more than ``hold_alternatives`` on any of those frames (a fix gained on
    frames whose competitor would have released it held is given up soon after), and
    the estimate has not slid more than ``hold_slide_m`` from a recent converged one
    carried by the odometry (:mod:`~app.localization.slide`). The filter then takes the
    gain back (:meth:`withhold`) while the fix's protection radius is wider than
    :data:`GAIN_PROTECTION_M`.

    **Held** while the cluster stays reasonably heavy and tight (``hold_*``), does not
    jump, still explains the detections (looser ``hold_fit`` and ``hold_unexplained``,
    no frame that most detections contradict, no object in clear view going
    unreported), dead reckoning has not lasted longer
    than ``hold_without_evidence`` frames, the odometry has not broken off (a frame
    without it after frames with it: the person may have been carried anywhere), the
    geometry still pins the fix within ``hold_geometry_m``,
    the alternatives stay below ``hold_alternatives`` (counting those that survived
    their probation), and the estimate does not slide more than ``hold_slide_m``. Only
    frames with two detections or more count towards a light cluster: frames without
    any leave freshly injected particles unweighed, and a lone bearing fits a whole
    curve of poses, over which it spreads the weight (measured: through a 66-degree
    camera, 8 of 14 releases of a right fix on the office suite were a cluster lightened
    by frames seeing one object). A false detection
    explained by clutter does not count against the estimate; a kidnap, a pose
    drifting away from the evidence, or an alternative place gaining probability does.

    **Hysteresis against flapping** (a person hearing "found", "not sure", "found"
    learns to trust neither). A fit past the hold thresholds releases only once it has
    lasted ``hold_misfit_frames`` frames with detections in a row: a real phone's
    bearings all shift for a moment while it turns with an unannounced latency, and the
    smoothed fit crosses ``hold_fit`` for a frame or two at the right place; a kidnap
    still shows at once (bad frames, a jump, an alternative), a pose drifting away
    from the evidence within a second. An object in clear view going unreported
    releases at once (on a stale map it is what catches a fix pulled a metre off), but
    once it has, or once one has kept a fix from being gained at this place,
    ``converged`` is gained only after ``regain_after_unseen_frames`` frames with
    detections free of it, or once the detector reports its objects again where the
    estimate puts them (``FitQuality.resolved``): a far object the detector reports
    now and then would otherwise flag, clear and flag again, and an object that left
    the view unresolved would come back into it, each time taking back a fix just
    given. The frames towards a gain are also held to the odometry
    (:mod:`~app.localization.slide`): a cloud dragged off while nothing was converged
    is not gained mid-drag.
    """

    gain_fit: float = 2.0
    hold_fit: float = 4.0
    gain_unexplained: float = 0.35
    hold_unexplained: float = 0.6
    #: The alternatives' share a gain is held to, and the share (of those past their
    #: probation) that lets a held fix go.
    gain_alternatives: float = 0.01
    #: The share a gain is held to with the tracker's long-lived rivals counted at
    #: ``rival_weight`` of their evidence (:attr:`EvidenceTracker.gain_share`: twice the
    #: evidence asked against a look-alike that has lasted 10 s). At 1 % (the plain
    #: share's bound) a rival at 0.01 % of the plain probability kept a fix back; at 3 %
    #: one at 0.09 % does. The share overstates the risk several times over on maps as
    #: drawn (docs/results/phone.md, the alternatives' reliability): of 528 episodes at
    #: 1-3 % (0.018 on average: about 9.5 to expect) none had the estimate more than a
    #: metre off, of 503 at 3-10 % (about 28) one; on stale maps it says little (16-29 %
    #: of the episodes off at every share up to 30 %). Measured on the phone suite
    #: (seeds 0-9): the door corridor through a 66 deg camera at PDR grade with 30 %
    #: missed detections, right within 0.4 m and not told for 28 s behind rivals one
    #: door pitch away (seed 0), 0.574 -> 0.629 of its right frames told. The plain
    #: share's bound stays at 1 %: at 3 % too, the office suite's stale map at 180 deg
    #: and 10 frames/s went 5 -> 21 confidently-wrong frames (seeds 0-9) and 2 -> 18
    #: (10-29), first fixes on a moved object's drag.
    gain_rivals: float = 0.03
    hold_alternatives: float = 0.05
    #: 10 frames is 2 s at 5 frames/s; 75 frames is 15 s.
    gain_without_evidence: int = 10
    hold_without_evidence: int = 75
    hold_mass: float = 0.6
    hold_std_xy_m: float = 0.5
    hold_std_theta_rad: float = float(np.radians(20.0))
    #: A held fix is let go when the estimate jumps more than this (m) beyond the
    #: motion in one step: it was off by about that much, or is now. Measured on the
    #: phone suite at 10 frames/s (a step every 0.2 s): a fix on the office suite's
    #: stale map pulled 0.4 m back in one step by a moved table, then held 0.8-1.5 m
    #: behind for 11 s; 0.5 -> 0.3 m: confidently wrong 190 -> 151 of 463,552 frames,
    #: availability at most 0.005 lower, flips at most 0.60 a minute as before; at 5
    #: frames/s nothing confidently wrong moved, availability at most 0.011 lower, flips
    #: at most 0.76 a minute (0.69). 0.2 m let a new 1.5 m drag through.
    hold_jump_m: float = 0.3
    #: The radius systematic bearing errors can reach (:mod:`~app.localization.dilution`)
    #: at most this to gain, and this to hold (m): a fix that geometry pins no closer is no
    #: location to tell a person, however tight the cloud.
    gain_geometry_m: float = 3.0
    hold_geometry_m: float = 5.0
    #: Frames in a row the cluster may stay lighter than ``hold_mass`` (a frame with a
    #: single detection can lend freshly injected particles a passing share).
    hold_light_frames: int = 3
    #: How far (m) the estimate may lie from a converged one a few seconds ago carried by
    #: the odometry (:mod:`~app.localization.slide`): 0.5 m, half the error the
    #: integrity suite calls wrong. Drags by a moved object measured 0.5-0.9 m over
    #: 5 s, converged estimates within 0.5 m of the truth rarely more than 0.5 m.
    hold_slide_m: float = 0.5
    #: Frames with detections in a row the fit may stay past ``hold_fit`` or
    #: ``hold_unexplained`` before ``converged`` is given up (1 s at 5 frames/s).
    hold_misfit_frames: int = 5
    #: Frames with detections free of an unseen-object contradiction that gaining
    #: ``converged`` again takes once one has taken it away (5 s at 5 frames/s), unless
    #: it is resolved first (``FitQuality.resolved``).
    regain_after_unseen_frames: int = 25
    #: Frames with detections in a row an unseen-object contradiction must last to let
    #: a held fix go, unless one of its objects was never reported at this place
    #: (``FitQuality.never_reported``: then at once). Traced on the venue suite at PDR
    #: grade through a 66-degree camera (seed 4): a door 7.3 m away, reported now and
    #: then, flagged for one frame (its miss evidence just past the threshold) and
    #: reported the next took a right fix away, and the first-fix rules gave it back
    #: 64 s later. On the phone suite's stale office through a 180-degree camera (seed
    #: 3) a fix 1.0 m off was kept one frame longer by an object 3 m away never
    #: reported there.
    hold_unseen_frames: int = 2
    #: A jump of the estimate farther than this (m) leaves the place an unseen-object
    #: contradiction was raised at (the unseen check's counts start again past 1 m too).
    unseen_place_m: float = 1.0

    def __init__(
        self, frames: int = 5, tolerance_m: float = 0.3, tolerance_rad: float = np.radians(15.0)
    ) -> None:
        self.frames = frames
        self.tolerance_m = tolerance_m
        self.tolerance_rad = tolerance_rad
        self.reset()

    def reset(self) -> None:
        self._streak = 0
        self._last: Estimate | None = None
        self._held = False
        self._light = 0
        self._misfit = 0
        #: Frames with detections since the last unseen-object contradiction, counted
        #: once one has taken ``converged`` away (None: none has since the last reset).
        self._since_unseen: int | None = None
        #: Frames with detections in a row that raised an unseen-object contradiction.
        self._unseen_run = 0
        self.lost_because: tuple[str, ...] = ()
        #: Why the last :meth:`confirm` gave no fix while none was held (for diagnostics,
        #: ``tools/why_not_located.py``): the gain's tests it failed, or the reason the
        #: filter took the gain back (:meth:`withhold`); () while a fix is held.
        self.not_gained_because: tuple[str, ...] = ()

    def checkpoint(self) -> dict[str, Any]:
        """The gate's memory (its last estimate as it is: frozen)."""
        return {
            "streak": self._streak,
            "last": self._last,
            "held": self._held,
            "light": self._light,
            "misfit": self._misfit,
            "since_unseen": self._since_unseen,
            "unseen_run": self._unseen_run,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        self._streak = int(state["streak"])
        self._last = from_plain(Estimate | None, state["last"])
        self._held = bool(state["held"])
        self._light = int(state["light"])
        self._misfit = int(state.get("misfit", 0))
        since = state.get("since_unseen")
        self._since_unseen = None if since is None else int(since)
        self._unseen_run = int(state.get("unseen_run", 0))

    def confirm(
        self,
        raw: Estimate,
        moved_m: float = 0.0,
        turned_rad: float = 0.0,
        quality: FitQuality | None = None,
        frames_without_evidence: int = 0,
        alternatives: float = 0.0,
        searched_ago: int | None = 0,
        motion_lost: bool = False,
        confirmed_alternatives: float | None = None,
        evidence_frame: bool = True,
        geometry_m: float = 0.0,
        slide_m: float = 0.0,
        lone_detection: bool = False,
        gain_share: float = 0.0,
    ) -> Estimate:
        """``raw`` with ``converged`` decided by the rules above; ``gain_share``: the
        alternatives' share with long-lived rivals' evidence discounted
        (EvidenceTracker.gain_share), held to ``gain_rivals`` for a gain."""
        last = self._last
        self._last = raw
        step = hypot(raw.x - last.x, raw.y - last.y) if last is not None else np.inf
        turn = abs(wrap_rad(float(raw.theta_rad - last.theta_rad))) if last else np.pi
        self._count_unseen(quality, evidence_frame, step)
        if self._held:
            top = raw.hypotheses[0] if raw.hypotheses else None
            light = top is None or top.weight < self.hold_mass
            if light and evidence_frame and not lone_detection:
                self._light += 1
            elif not light:
                self._light = 0
            against = alternatives if confirmed_alternatives is None else confirmed_alternatives
            reasons = {
                "light": top is None or self._light >= self.hold_light_frames,
                "wide": self._wide(raw),
                "jump": step > moved_m + self.hold_jump_m,
                "misfit": self._misfit_lasts(quality, evidence_frame),
                "bad frame": quality is not None and quality.bad_frame,
                "unseen object": quality is not None
                and quality.contradicted
                and (quality.never_reported or self._unseen_run >= self.hold_unseen_frames),
                "dead reckoning": frames_without_evidence > self.hold_without_evidence,
                "alternative": against > self.hold_alternatives,
                "odometry lost": motion_lost,
                "weak geometry": geometry_m > self.hold_geometry_m,
                "slide": slide_m > self.hold_slide_m,
            }
            self._held = not any(reasons.values())
            if not self._held:
                self._streak = 0
                self._misfit = 0
                if reasons["unseen object"]:
                    self._since_unseen = 0
                #: Why ``converged`` was last lost (for diagnostics and the suite).
                self.lost_because = tuple(k for k, v in reasons.items() if v)
                self.not_gained_because = tuple(f"let go: {k}" for k in self.lost_because)
            return raw.with_converged(self._held)
        # The gain's tests on this frame's fit, each True where it fails: one table for
        # the gain and for the reasons it gives (not_gained_because).
        failed = {
            "misfit": quality is None
            or quality.fit > self.gain_fit
            or quality.unexplained > self.gain_unexplained,
            "bad frame": quality is not None and quality.bad_frame,
            "unseen object": quality is not None and quality.contradicted,
            "dead reckoning": frames_without_evidence > self.gain_without_evidence,
            "weak geometry": geometry_m > self.gain_geometry_m,
            "slide": slide_m > self.hold_slide_m,
            "alternative": alternatives > self.hold_alternatives,
        }
        fits = not any(failed.values())
        steady = (
            raw.converged
            and fits
            and step <= moved_m + self.tolerance_m
            and turn <= abs(turned_rad) + self.tolerance_rad
        )
        self._streak = self._streak + 1 if steady else (1 if raw.converged and fits else 0)
        # A search since the cluster formed.
        searched = searched_ago is not None and searched_ago < self._streak
        rival = alternatives > self.gain_alternatives or gain_share > self.gain_rivals
        self._held = self._streak >= self.frames and searched and not rival and self._unseen_cleared
        if self._held:
            self.not_gained_because = ()
        else:
            # The gain's alternatives test is the stricter one (it implies the fit's); a
            # search is asked of a streak already begun.
            failed["alternative"] = rival
            failed["unseen object lately"] = not self._unseen_cleared
            failed["no search yet"] = not searched and (searched_ago is None or self._streak > 0)
            shortfalls = tuple(k for k, v in {"cluster": not raw.converged, **failed}.items() if v)
            # Every test passed but the fix has not stayed put for ``frames`` frames.
            self.not_gained_because = shortfalls or ("not steady yet",)
        return raw.with_converged(self._held)

    def shift_x(self, dx_m: float) -> None:
        """The person rode to another level, ``dx_m`` across the filter's plane: the
        last estimate, against which the next one's step is measured, rides along."""
        if self._last is not None:
            self._last = replace(self._last, x=self._last.x + dx_m)

    def _wide(self, raw: Estimate) -> bool:
        """Whether the cluster is wider than a held fix's may be (``hold_std_*``)."""
        return (
            max(raw.std_x_m, raw.std_y_m) > self.hold_std_xy_m
            or raw.std_theta_rad > self.hold_std_theta_rad
        )

    def cluster_holds(self, raw: Estimate) -> bool:
        """Whether ``raw``'s cluster passes the tests a held fix's does (its top place at
        least ``hold_mass`` of the weight, no wider than ``hold_std_*``), looser than
        the clustering's ``converged`` a first gain asks for (estimate.ClusterSettings:
        0.9 of the weight within 0.25 m)."""
        top = raw.hypotheses[0] if raw.hypotheses else None
        return top is not None and top.weight >= self.hold_mass and not self._wide(raw)

    def withhold(self, because: str = "wide radius") -> None:
        """Take back a gain :meth:`confirm` just made, because the fix's protection
        radius is too wide to tell (:data:`GAIN_PROTECTION_M`), or for another of the
        filter's tests (``because`` names it). The streak stays: the next frame that
        passes the gain's tests with a narrower radius is a gain."""
        self._held = False
        self.not_gained_because = (because,)

    @property
    def streak(self) -> int:
        """Frames in a row the estimate has been steady and fitting towards a gain (0
        after a release; held at ``frames`` or more while converged)."""
        return self._streak

    @property
    def let_go_for_doubt(self) -> bool:
        """Whether no fix is held and the last one was let go only because an
        alternative gained probability, only because its estimate jumped further in one
        step than the motion allows (``hold_jump_m``), or only because the bearings'
        geometry no longer bounded it (``hold_geometry_m``): the place was questioned,
        not refuted (:mod:`~app.localization.continuation`)."""
        return not self._held and self.lost_because in DOUBT_ONLY

    @property
    def held(self) -> bool:
        """Whether ``converged`` was given in the last :meth:`confirm` (and not reset)."""
        return self._held

    @property
    def _unseen_cleared(self) -> bool:
        """Whether the last unseen-object contradiction (if any) is long enough past."""
        since = self._since_unseen
        return since is None or since >= self.regain_after_unseen_frames

    def _count_unseen(self, quality: FitQuality | None, evidence_frame: bool, step: float) -> None:
        """Frames with detections since an object in clear view last went unreported at
        this place (None: none has since the estimate came here).

        A contradiction counts whether or not ``converged`` was held when it came: one
        that kept a fix from being gained and lapsed only because its object left the
        view is as unresolved as one that took a fix away; one whose objects the
        detector now reports where the estimate puts them (``FitQuality.resolved``) is
        resolved. Once the estimate jumps farther than ``unseen_place_m`` it was about
        another place, and is forgotten.
        """
        if evidence_frame:
            contradicted = quality is not None and quality.contradicted
            self._unseen_run = self._unseen_run + 1 if contradicted else 0
        if quality is not None and quality.contradicted:
            self._since_unseen = 0
        elif self._since_unseen is None:
            return
        elif quality is not None and quality.resolved:
            self._since_unseen = None
            return
        elif step > self.unseen_place_m:
            self._since_unseen = None
        elif evidence_frame:
            self._since_unseen += 1

    def _misfit_lasts(self, quality: FitQuality | None, evidence_frame: bool) -> bool:
        """Whether the fit has been past the hold thresholds for ``hold_misfit_frames``
        frames with detections in a row (no fit measured at all: at once)."""
        if quality is None:
            return True
        if quality.fit <= self.hold_fit and quality.unexplained <= self.hold_unexplained:
            self._misfit = 0
        elif evidence_frame:
            self._misfit += 1
        return self._misfit >= self.hold_misfit_frames


#: Probability the protection radius must hold (docs/API.md, FrameResult.protection_m).
PROTECTION_PROBABILITY = 0.99
#: A fix is first told (``converged`` gained, or given again) only with a protection
#: radius of at most this (m); once told, it is held on the gate's rules, however wide
#: its radius grows. The radius is a bound on what the cloud, the bearings' geometry and
#: the residuals allow: a fix it puts no closer than a metre and a half relies on a few
#: objects, and a map whose furniture moved since it was drawn pulls just such a fix a
#: metre or more off while its radius covers it (measured on the phone suite's stale
#: office map, 10 seeds: every confidently-wrong span but one began at a gain with a
#: radius of 1.5-3.7 m). 1.5 m keeps most narrow cameras' fixes (a 66-degree camera's
#: radius is rarely under a metre); a gain whose radius is over a metre is told as
#: "Location found, to within about 2 metres." (:mod:`app.feedback.narrator`).
GAIN_PROTECTION_M = 1.5
#: Particles (a systematic resample) whose distances give the radius's quantile.
PROTECTION_SAMPLE = 1_000
#: Calibration of the radius on the integrity suite (docs/results/integrity.md): the
#: cloud's own 99 % radius, scaled by this factor, plus this floor (m).
PROTECTION_SCALE = 1.5
PROTECTION_FLOOR_M = 0.05


#: Relative margin between a squared distance's order and its distance's: the two
#: roundings of dx*dx + dy*dy and the C library's last-bit error in hypot move a
#: distance by far less (about 1e-15 of it).
_ORDER_MARGIN = 1e-12


#: Up to this many values above the order statistic sought, :func:`_order_statistics`
#: keeps the largest ones in a short sorted run instead of partitioning all of them.
_TOP_RUN = 32


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _order_statistics(sq, lo, hi):  # fmt: skip  # pragma: no cover - compiled
    """The ``lo``-th and ``hi``-th smallest of ``sq`` (ascending, from 0; ``hi`` is
    ``lo`` or ``lo + 1``), the very values a partition picks.

    The radius asks for the 99th percentile: the 990th of 1,000, so only the 11 largest
    matter. They are kept in a sorted run while the values pass once (most fall below
    its least and are passed over): 1.0 us against 3.4 us for ``np.partition`` (1,000
    squared distances of a converged cloud). A NaN, which the run would pass over, or a
    deeper statistic partitions as before."""
    n = sq.shape[0]
    top = n - lo  # the run: the top largest, ascending; sq's lo-th smallest is its first
    if top <= _TOP_RUN:
        run = np.full(top, -np.inf)
        nan = False
        for v in sq:
            if v > run[0]:
                j = 0
                while j + 1 < top and run[j + 1] < v:
                    run[j] = run[j + 1]
                    j += 1
                run[j] = v
            elif v != v:
                nan = True
        if not nan:
            return run[0], run[hi - lo]
    part = np.partition(sq, lo)
    s_hi = part[lo]
    if hi > lo:  # the next order statistic: the least of those after lo
        s_hi = part[lo + 1]
        for k in range(lo + 2, n):
            s_hi = min(s_hi, part[k])
    return part[lo], s_hi


@njit(cache=True, nogil=True, error_model="numpy")
def _drawn_distances(x, y, w, n, u0, ex, ey, lo):  # fmt: skip  # pragma: no cover - compiled
    """The ``lo``-th and ``lo + 1``-th smallest of ``hypot(x - ex, y - ey)`` over ``n``
    particles drawn by systematic resampling with offset ``u0`` (ascending order
    statistics counted from 0; the second is the first when ``lo`` is the last).

    The very numbers of numpy's ``hypot`` (both call the C library's) and a partition,
    without a thousand ``hypot`` calls (15 ns each): the squared distances are ranked
    instead, and ``hypot`` runs only on the few whose squared distance lies within
    ``_ORDER_MARGIN`` of the two sought. A squared distance below that band belongs to
    a distance below every distance in it, one above to one above, so the two order
    statistics are the band's, counted past the ones below.
    """
    idx = systematic_indexes(w, n, u0)
    sq = np.empty(n)
    for k in range(n):
        i = idx[k]
        dx = x[i] - ex
        dy = y[i] - ey
        sq[k] = dx * dx + dy * dy
    hi = min(lo + 1, n - 1)
    s_lo, s_hi = _order_statistics(sq, lo, hi)
    # (The 1e-300: squared distances that underflow, under 1e-154 m, all fall in it.)
    low = s_lo * (1.0 - _ORDER_MARGIN) - 1e-300
    high = s_hi * (1.0 + _ORDER_MARGIN) + 1e-300
    below = 0
    band = np.empty(n)
    m = 0
    for k in range(n):
        if sq[k] < low:
            below += 1
        elif sq[k] <= high:
            i = idx[k]
            band[m] = np.hypot(x[i] - ex, y[i] - ey)
            m += 1
    ranked = np.sort(band[:m])
    return ranked[lo - below], ranked[hi - below]


@functools.lru_cache(maxsize=64)
def _gaussian_radius_stds(need: float) -> float:
    """sqrt(-2 ln(1 - need)), ``need`` at most 0.9999: the radius, in standard
    deviations, of a round Gaussian that holds ``need`` of its probability. Kept: all
    but the frames with alternatives ask for the same ``need``, and numpy's scalar
    calls cost more than the lookup."""
    return float(np.sqrt(-2.0 * np.log(1.0 - min(need, 0.9999))))


def protection_radius(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    weights: NDArray[np.float64],
    estimate: Estimate,
    rng: np.random.Generator,
    alternative_share: float = 0.0,
    alternatives_reach_m: float = 0.0,
) -> float:
    """Radius (m) around the estimate holding the truth with 99 % probability.

    The whole belief counts: the filter's particles (far clusters included) hold
    ``1 - alternative_share`` of the probability, the alternatives of
    :mod:`~app.localization.evidence` the rest, all within ``alternatives_reach_m``.
    Within the particles, the radius is the larger of their weighted quantile and the
    Gaussian radius of the heaviest cluster's spread (sqrt(-2 ln(1 - q)) times its
    largest standard deviation), scaled by ``PROTECTION_SCALE`` plus
    ``PROTECTION_FLOOR_M`` (calibrated on the integrity suite).
    """
    q = PROTECTION_PROBABILITY
    need = 1.0 if alternative_share >= 1.0 - q else q / (1.0 - alternative_share)
    # np.quantile's linear interpolation between the two order statistics around pos
    # (at a whole pos, the second's share is 0).
    pos = min(need, 1.0) * (PROTECTION_SAMPLE - 1)
    lo = math.floor(pos)
    d_lo, d_next = _drawn_distances(
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64),
        PROTECTION_SAMPLE, rng.random(), float(estimate.x), float(estimate.y), lo,
    )  # fmt: skip
    r_particles = float(d_lo + (pos - lo) * (d_next - d_lo))
    # (Scaling is monotone: the larger of the two scaled is the larger one scaled.)
    r = max(PROTECTION_SCALE * r_particles + PROTECTION_FLOOR_M, cluster_radius(estimate, need))
    if alternative_share >= 1.0 - q:
        r = max(r, alternatives_reach_m)
    return r


def cluster_radius(estimate: Estimate, need: float = PROTECTION_PROBABILITY) -> float:
    """The part of :func:`protection_radius` that the heaviest cluster's spread alone
    gives (m): the radius of a round Gaussian with its largest standard deviation that
    holds ``need`` of the probability, scaled as the whole radius is. Needs no draw, so
    it serves for a pose that is only a candidate."""
    sigma = max(estimate.std_x_m, estimate.std_y_m)
    return PROTECTION_SCALE * (_gaussian_radius_stds(need) * sigma) + PROTECTION_FLOOR_M


def widened_radius(radius_m: float, fit: float | None, slide_m: float) -> float:
    """``radius_m`` widened by what the estimate's own evidence says it may have missed.

    ``fit`` (:class:`FitQuality`) is the smoothed mean squared bearing residual in stds
    of what the fit allows for (the noise, plus a real detector's steady bias in the
    service): at most about 1 when those explain the residuals. Past 1 the errors are
    larger than the radius assumed, and a radius in proportion to them (the geometry's
    is) grows with ``sqrt(fit)``. ``slide_m`` is how far the estimate lies from where
    the odometry carries a recent converged one (:mod:`~app.localization.slide`): one of
    the two is off by about that much, and the radius, a bound on this one alone,
    cannot say which, so it is added. Measured on the phone suite's stale maps (objects
    moved 1-1.5 m): estimates dragged 0.5-0.9 m off while cloud and geometry stayed a
    few decimetres wide, protection coverage 0.973 and 0.981 (docs/results/phone.md).
    """
    scale = math.sqrt(fit) if fit is not None and fit > 1.0 else 1.0
    return radius_m * scale + max(slide_m, 0.0)
