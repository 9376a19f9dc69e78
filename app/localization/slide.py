"""Whether the estimate keeps to the odometry: a cloud dragged off by a stale map.

An object moved since the map was drawn (a table 1.3 m from where the map has it) is
detected every frame where the map says nothing is. At the true pose each of its
detections costs the clutter floor; a pose a metre off explains it, at the price of
a few degrees on the objects that did not move. Frame after frame the second is about
as likely as the first, and the cloud, whose motion noise lets it slip a few
centimetres a frame, slides towards it: measured on the phone suite's stale maps, the
estimate fell 0.6-0.9 m behind the odometry over 5 s of walking while the cloud stayed
a few centimetres wide, every detection looked explained, and the gate said
"converged" a metre off (docs/results/phone.md). The fit at one frame cannot tell:
from the dragged pose the moved object fits and the others are a little off.

The odometry can tell. Over a few seconds it is good to centimetres at VIO grade and
to a tenth of the distance at PDR grade, and it does not know the map. So the check
keeps the converged estimates of the last ``SLIDE_FRAMES`` frames with the odometry's
dead reckoning at each, and measures how far the estimate now lies from the oldest of
them (at least ``MIN_FRAMES`` old) carried forward by the odometry since: the *slide*. A
converged estimate that slid more than the gate allows (:class:`~app.localization.
convergence.ConvergenceGate`, ``hold_slide_m``) is not one to tell a person: either
it, or the one before, was wrong by about that much.

That comparison has to allow the old estimate's heading its error (a few degrees, up to
``HEADING_TOLERANCE_DEG``), which swings the carried position sideways by a metre over
6 m of walking: a drag across the line of walking hides in it. So, when the odometry's
source is known, the check also adds up the *slip*: frame by frame, how far the estimate
moved other than the odometry carried it along the estimate's own heading of the frame
before, over the run of anchored frames (at most ``SLIDE_FRAMES``). Each frame's
heading is the estimate's own, so a heading error no longer swings anything; what the
slip must allow is the odometry's scale error, ``slip_share`` of the distance walked
(``SLIP_SCALE_STDS`` times the source's scale uncertainty: 5 % at VIO grade). Measured
on the phone suite's stale office through a 180-degree camera, a moved object dragged a
fix sideways by 1-3 cm a frame, which the slide let through: with the slip, 33 frames
more than 1 m off while converged instead of 46, every scenario without a stale map
unchanged (docs/results/phone.md). What is left forms a metre off before any fix does,
or is gained again mid-drag by a run too short for the slip to see.

A fix let go for a slide is where the drag shows: the filter then asks which movable
object, left out, takes the place the recent frames fit best back to where the odometry
carried the fix (:meth:`OdometryCheck.carried_xy`), and takes that one for moved
(:meth:`~app.localization.filter.ParticleFilter._blame_the_slide`).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from app.localization.motion import compose_odometry
from app.localization.types import Odometry
from app.maps.geometry import wrap_rad

#: Frames between the estimate compared and the one it is compared with (5 s at 5 Hz:
#: long enough for a drag of a few centimetres a frame to add up, short enough for the
#: odometry's drift to stay small).
SLIDE_FRAMES = 25
#: The youngest estimate compared with (2 s at 5 Hz): a cloud that converged a metre
#: off and is being dragged further shows within seconds of converging.
MIN_FRAMES = 10
#: How far the heading of the estimate compared with may be off (degrees), at least: a
#: latency of up to 0.3 s the app does not report while turning at 30 deg/s. A filter
#: that allows its heading more slack (``FilterConfig.heading_slack_deg``: a real
#: detector's latency while turning, the hand's sway) allows this check as much.
HEADING_TOLERANCE_DEG = 10.0
#: The slip's tolerance in standard deviations of the odometry source's scale
#: (:data:`~app.localization.odometry_bias.BIAS_PRIORS`): 2.5 x 2 % at VIO grade.
SLIP_SCALE_STDS = 2.5

Pose = tuple[float, float, float]
Move = tuple[float, float]
#: A frame's share of the slip: along x, along y, the distance walked (m).
Term = tuple[float, float, float]


class OdometryCheck:
    """The recent converged estimates with the dead reckoning at each (module docstring).

    ``scale_tolerance``: how far off the odometry's scale may be, a share of the
    distance walked (the motion model's translation noise share for the odometry's
    source: 0.15 at PDR grade, 0.1 otherwise); ``heading_tolerance_deg``: how far off the
    heading of the estimate compared with may be (at least ``HEADING_TOLERANCE_DEG``);
    ``slip_share``: the slip's allowance, a share of the distance walked (None: no slip
    measured, the odometry's source unknown to the filter).
    """

    def __init__(
        self,
        scale_tolerance: float = 0.1,
        heading_tolerance_deg: float = 0.0,
        slip_share: float | None = None,
    ) -> None:
        self.scale_tolerance = scale_tolerance
        self.heading_tolerance_rad = math.radians(max(HEADING_TOLERANCE_DEG, heading_tolerance_deg))
        self.slip_share = slip_share
        self.reset()

    def reset(self) -> None:
        """Forget the history (odometry lost, the belief started over or moved elsewhere)."""
        #: Dead reckoning: the odometry composed since the last reset.
        self._reckoned: Pose = (0.0, 0.0, 0.0)
        #: Per frame: the dead reckoning then, the estimate kept as an anchor (None if
        #: not), whether it is a candidate's (see :meth:`add`), and the odometry's move
        #: into the frame (forward, left; None: none known).
        self._past: deque[tuple[Pose, Pose | None, bool, Move | None]] = deque(maxlen=SLIDE_FRAMES)
        #: Per frame of ``_past``, its share of the slip (:meth:`_slip_m`) once the frame
        #: after it is known, else None (see :func:`_slip_term`).
        self._terms: deque[Term | None] = deque(maxlen=SLIDE_FRAMES)
        #: This frame's move (:meth:`moved`), kept with the frame by :meth:`add`.
        self._move: Move | None = None

    def moved(self, odometry: Odometry) -> None:
        """The person moved by ``odometry``."""
        reckoned = compose_odometry(Odometry(*self._reckoned), odometry)
        assert reckoned is not None  # (both motions known)
        self._reckoned = (reckoned.forward_m, reckoned.left_m, reckoned.turn_rad)
        self._move = (odometry.forward_m, odometry.left_m)

    def slide_m(self, x: float, y: float) -> float:
        """How far (x, y) lies from where the odometry carries the oldest converged
        estimate of the last ``SLIDE_FRAMES`` frames (at least ``MIN_FRAMES`` old), m;
        0 without such an estimate.

        Neither end is exact: that estimate's heading may be off by a few degrees (a
        latency the app does not report, a turn), which swings the carried position
        sideways by the distance walked times the error, and the odometry's scale is off
        by up to ``scale_tolerance`` of it (PDR grade). Neither is a slide, so the
        carried position is the whole band of them: walked distances within
        ``scale_tolerance`` of the odometry's, turned by up to ``heading_tolerance_rad``.
        The slide is the distance from (x, y) to that band.
        """
        slip = self._slip_m(x, y)
        compared = self._compared()
        if compared is None:
            return slip
        # Where the estimate lies relative to the estimate then, in its heading.
        (ex, ey, et), (forward, left) = compared
        c, s = math.cos(et), math.sin(et)
        px, py = x - ex, y - ey
        slide = _distance_to_band(
            (c * px + s * py, -s * px + c * py),
            (forward, left),
            self.scale_tolerance,
            self.heading_tolerance_rad,
        )
        return max(slide, slip)

    def carried_xy(self) -> tuple[float, float] | None:
        """Where the odometry carries the estimate :meth:`slide_m` compares with (the
        middle of its band: the odometry's own scale, the estimate's own heading then);
        None without one."""
        compared = self._compared()
        if compared is None:
            return None
        (ex, ey, et), (forward, left) = compared
        c, s = math.cos(et), math.sin(et)
        return (ex + c * forward - s * left, ey + s * forward + c * left)

    def _compared(self) -> tuple[Pose, Move] | None:
        """The estimate :meth:`slide_m` compares with (the oldest kept of the last
        ``SLIDE_FRAMES`` frames, at least ``MIN_FRAMES`` old), and the dead reckoning's
        motion since then in its own pose then (forward, left); None without one."""
        old_enough = len(self._past) - MIN_FRAMES + 1
        first = next((i for i in range(old_enough) if self._past[i][1] is not None), None)
        if first is None:
            return None
        (rx, ry, rt), estimate_then, *_ = self._past[first]
        assert estimate_then is not None
        dx, dy = self._reckoned[0] - rx, self._reckoned[1] - ry
        c, s = math.cos(rt), math.sin(rt)
        return estimate_then, (c * dx + s * dy, -s * dx + c * dy)

    def _slip_m(self, x: float, y: float) -> float:
        """How far the estimate moved, over the run of anchored frames that ends with
        this one at (x, y), other than the odometry carried it along the estimate's own
        heading of each frame before, less ``slip_share`` of the distance walked
        (module docstring); 0 without a known source or a run."""
        if self.slip_share is None or not self._past:
            return 0.0
        # The newest frame's share from (x, y) and this frame's move, then the older
        # frames' shares as kept, newest first: the same sums in the same order as
        # computing every share again (25 frames' cosines, sines and hypot each frame
        # were about 3 % of a loaded worker's CPU; the kept shares are added up in a
        # quarter of the time).
        first = _slip_term(self._past[-1][1], x, y, self._move)
        if first is None:
            return 0.0
        sx, sy, walked = first
        terms = self._terms
        for k in range(len(terms) - 2, -1, -1):
            term = terms[k]
            if term is None:
                break
            tx, ty, step = term
            sx += tx
            sy += ty
            walked += step
        return max(0.0, math.hypot(sx, sy) - self.slip_share * walked)

    def add(
        self, x: float, y: float, theta: float, converged: bool, candidate: bool = False
    ) -> None:
        """Record this frame's estimate, kept as an anchor when ``converged`` (a told
        fix, or a frame of doubt the filter holds to the told fix) or a
        ``candidate``: one of a run of frames on the way to gaining converged (the
        gate's streak). A gain is checked against the run's first estimates as a fix
        is held against its own: a cloud dragged off while no fix was held (a moved
        object pulling it) is not gained mid-drag. :meth:`drop_candidates` forgets
        the run's when it breaks."""
        anchor = converged or candidate
        pose = (x, y, theta) if anchor else None
        if self._past:  # the frame before now has the frame after it: its share is known
            self._terms[-1] = _slip_term(self._past[-1][1], x, y, self._move, pose is None)
        self._past.append((self._reckoned, pose, candidate, self._move))
        self._terms.append(None)
        self._move = None

    def drop_candidates(self) -> None:
        """Forget the candidates' anchors (their run broke: they were not confirmed)."""
        past = self._past
        for k, (reckoned, estimate, candidate, move) in enumerate(past):
            if candidate and estimate is not None:
                past[k] = (reckoned, None, False, move)
        self._count_terms()

    def _count_terms(self) -> None:
        """Every frame's share of the slip again, from ``_past`` (:meth:`add`)."""
        past = self._past
        self._terms.clear()
        for k in range(len(past) - 1):
            after = past[k + 1][1]
            if after is None:
                self._terms.append(None)
            else:
                self._terms.append(_slip_term(past[k][1], after[0], after[1], past[k + 1][3]))
        if past:
            self._terms.append(None)

    def checkpoint(self) -> dict[str, Any]:
        return {"reckoned": self._reckoned, "past": list(self._past)}

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it existed)."""
        self.reset()
        if state is None:
            return
        self._reckoned = _pose(state["reckoned"])
        for reckoned, estimate, *rest in state["past"]:
            pose = None if estimate is None else _pose(estimate)
            candidate = bool(rest[0]) if rest else False
            # (older checkpoints kept no moves: the slip starts its run afresh)
            move = rest[1] if len(rest) > 1 else None
            move = None if move is None else (float(move[0]), float(move[1]))
            self._past.append((_pose(reckoned), pose, candidate, move))
        self._count_terms()


def _slip_term(
    estimate: Pose | None, nx: float, ny: float, move: Move | None, gone: bool = False
) -> Term | None:
    """One frame's share of the slip: how far the estimate went from ``estimate`` to
    (nx, ny), the next frame's, other than ``move`` (the odometry's into that frame)
    carried it along ``estimate``'s heading, and the distance ``move`` walked; None where
    the run breaks (no estimate kept, no move known, or the next frame's estimate
    ``gone``)."""
    if estimate is None or move is None or gone:
        return None
    ex, ey, et = estimate
    forward, left = move
    c, s = math.cos(et), math.sin(et)
    return (
        (nx - ex) - (c * forward - s * left),
        (ny - ey) - (s * forward + c * left),
        math.hypot(forward, left),
    )


def _pose(value: Any) -> Pose:
    return (float(value[0]), float(value[1]), float(value[2]))


def _distance_to_band(
    point: tuple[float, float],
    motion: tuple[float, float],
    scale_tolerance: float,
    heading_tolerance_rad: float,
) -> float:
    """Distance from ``point`` to the band of places ``motion`` (forward, left) leads to
    from the origin with its length off by up to ``scale_tolerance`` of it and its
    direction by up to ``heading_tolerance_rad``: a sector of an annulus."""
    length = math.hypot(*motion)
    near, far = length * (1.0 - scale_tolerance), length * (1.0 + scale_tolerance)
    radius = math.hypot(*point)
    if length == 0.0 or radius == 0.0:
        return max(0.0, radius - far, near - radius)
    off = math.atan2(point[1], point[0]) - math.atan2(motion[1], motion[0])
    off = wrap_rad(off)
    if abs(off) <= heading_tolerance_rad:
        return max(0.0, radius - far, near - radius)
    # Outside the sector: the nearest point is on its nearer straight edge.
    edge = math.atan2(motion[1], motion[0]) + math.copysign(heading_tolerance_rad, off)
    ux, uy = math.cos(edge), math.sin(edge)
    along = min(max(point[0] * ux + point[1] * uy, near), far)
    return math.hypot(point[0] - along * ux, point[1] - along * uy)
