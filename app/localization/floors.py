"""Which floor: the particles' level, changed only at connectors, driven by the barometer.

On a map with several levels (:mod:`app.maps.levels`) the filter runs in the plane
where level k lies ``k * pitch`` metres east of level 0, so a particle's level is
where its x lies and objects, walls and visibility are per level with no change to any
kernel. What this module adds is the only way from one level to another: a particle
inside a connector's stop may move to another stop of that connector (an elevator or
a ramp: any level it serves, one at a time; stairs and escalators: the neighbouring
level; an escalator only its way), its x shifted by the two levels' offsets.

When frames carry the phone's barometric altitude (relative to a reference of the
phone's own, and wandering slowly: weather, ventilation), a :class:`FloorTracker`
follows it. The readings are smoothed over the last ``SMOOTH_S``; an *anchor* holds
the altitude of the floor the person is on and follows slow drift while the altitude
stays near it. When the smoothed altitude leaves the anchor by ``CHANGE_SHARE`` of a
storey (up or down), a level change is under way: every particle in a stop whose
connector goes that way moves one level that way, every other particle is judged to be
on a floor the barometer has left (its weight times ``STAY_LIKELIHOOD``), and the anchor
moves by the change the moved particles made. A ride of several floors is several such
steps. This is HULOP/NavCog's idea (detect *that* the person changes level from the
barometer, move particles only through the map's transitions), with the level a part of
each particle, so a belief on the wrong floor is a wrong position: tens of metres from
the truth in the plane, never "converged" there.

While the smoothed altitude is more than ``DRIFT_SHARE`` of a storey from the anchor, or
rises or falls as fast as a lift does, and some of the belief stands in a connector's
stop (nobody rides a lift from the middle of a shop floor: elsewhere such a reading is
the barometer's noise), the person is between floors
(:attr:`FloorTracker.in_transit`; once started, until the altitude is back within
``RATE_ENTRY_M`` of the anchor or a level has changed): the filter then calls nobody
located, starts its convergence test afresh (a fix it held when the barometer called the
person between floors is only withheld, and goes on being tested, until a level changes:
a poor barometer's noise does that to a walking person now and then), and neither
injects particles nor lets the evidence search move the cloud (a lift car looks the same
on every floor; the barometer, not the view, says where a ride ends), so every particle
the change meets descends from the ones that entered the connector.

The ride's steps are also counted (:attr:`FloorTracker.net_storeys`, up positive): a
person gone up a storey from wherever they started stands on no lowest floor, so a
belief that missed a ride (not yet located, none of it in the lift's stop: the filter
starts again over every level) is kept off the levels no start could reach
(:meth:`FloorTracker.level_allowed`). Storeys, not metres: the barometer wanders by
metres over an hour, a ride's steps do not; a frame without altitude breaks the count.
Such a restart is not blind either: whoever the barometer saw change level has just
left a connector going that way, so half of the new cloud stands in those connectors'
stops on the levels the count allows (:meth:`FloorTracker.arrivals`; a lift's favoured
at a lift's rate), the rest over those levels for a change no connector on the map
explains. Measured on the venue suite (66-degree camera, VIO grade): a walk whose cloud
missed the lift, lost on the Second Floor for the whole leg before, found its place
there after 41 s, and after the stairs on the First Floor after 2 s instead of 68 s.

A held fix farther than its protection radius from every connector's stop cannot have
ridden one: a level change the barometer shows then, which no particle could make, is
its reference moving (a pressurized zone, a glitch of the sensor), and the tracker
follows the new reading instead of restarting the belief and counting a storey
(:meth:`FloorTracker._jumped`); the filter asks the same of the last fix told once it
is let go, its radius grown by the walk since. Measured with a 4.5 m jump of the
reference (no ride) injected into the venue suite's walks (VIO, 180 deg camera, 10
seeds): 100 s into the walk, 170 frames confidently on a wrong floor before, 6 after.
A person passing a connector's stop as the reference jumps could have ridden, but not
as fast as the readings stepped: a step no rider climbs (``MAX_CLIMB_MPS``, beyond the
readings' own noise) is followed at once, the readings before it and the anchor moved
by it (:meth:`FloorTracker._follow_step`). The same 4.5 m jump 200 s into the walks had
come as one walk passed the foot of the stairs: taken for a climb, the count of storeys
it left put that walk confidently one floor up for 30 frames, 100 s later.

A belief that did make the change is not always located either: through a phone's
narrow camera the cloud can follow the person for minutes, tight and right, while the
bearings' geometry keeps its radius above what a first fix needs. When most of it made
the change and nearly all of it then stands in one stop
(:meth:`FloorTracker.pinned_stop`), the ride says more than the view: the person just
left that connector. Its stop is then a fix the filter carries (the circle holding it),
and the first fix out of it continues the ride's (:mod:`app.localization.continuation`),
as a known start's does.

The same count says the floor a ride ends on: from the last converged fix's level (or,
without one, when the count leaves a single level possible), the level so many storeys
up or down is confirmed, and announced, once the belief agrees
(:meth:`FloorTracker.after_estimate`), before the view has found the place on it.

Without altitude, a particle in a stop moves to a level its connector reaches with a
small probability per frame (``BLIND_RATE``), and what is seen on each level decides;
an estimate inside a stop is then between floors too (nothing tells the floor there),
though the filter keeps a fix it held on entering while the view keeps the belief on
its floor (``share_on_level``, see ``ParticleFilter._step``).
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.maps.geometry import (
    first_polygon,
    point_segment_distance,
    points_in_polygon,
    polygon_edges,
)
from app.maps.model import SemanticMap

#: The tracker's windows and rates are set in seconds and turned into frames by the
#: session's frame period: the median of the latest ``PERIOD_FRAMES`` times between
#: frames (rounded to ``PERIOD_ROUND_S``: a phone's timestamps jitter by less), or
#: ``NOMINAL_PERIOD_S`` until a frame's time is known. Counted in frames, the same
#: windows at 10 frames/s smoothed half as long and let the anchor follow a ride twice
#: as fast: measured on the venue's walks re-simulated at 10 frames/s, a walk on the
#: stairs was confidently one floor off for 5 frames (the anchor drifted towards the
#: climb, and the change came 5 frames after the truth passed the stairs' midpoint).
NOMINAL_PERIOD_S = 0.2
PERIOD_FRAMES = 25
PERIOD_ROUND_S = 1e-3
#: Frames faster than this are taken to come at this period (the windows' longest).
MIN_PERIOD_S = 1.0 / 60.0
#: Seconds of readings averaged for the level-change test.
SMOOTH_S = 1.0
#: A lift passing a floor without stopping is between floors too: the means of the newer
#: and the older half of the last ``2 * RATE_HALF_S`` of readings differ by
#: ``LIFT_RISE_M`` or more (0.6 m/s: lifts run at 1-2.5 m/s; a person on stairs or an
#: escalator rises about 0.3 m/s; the noise of that difference is about 0.16 m for
#: readings of 0.25 m at 5 frames/s, less at more).
RATE_HALF_S = 1.0
LIFT_RISE_M = 0.6
#: How far the smoothed altitude must also have left the anchor for the rate test to
#: start a ride (m): about 2 stds of a 5-reading mean of readings 0.4 m apart (a poor
#: barometer), which a lift at 1 m/s covers in about half a second.
RATE_ENTRY_M = 0.4
#: A level change is under way when the smoothed altitude leaves the anchor by this
#: share of the storey height towards the next level (more than half: after the
#: anchor moves a storey, the way back needs a fifth of a storey more).
CHANGE_SHARE = 0.6
#: While the smoothed altitude is within this share of a storey of the anchor, the
#: anchor follows it by ``DRIFT_GAIN`` of the difference every ``NOMINAL_PERIOD_S``
#: (drift tolerance: a time constant of about 10 s; a ride crosses the band in a few
#: seconds and moves the anchor by a few centimetres).
DRIFT_SHARE = 0.25
DRIFT_GAIN = 0.02
#: A step of the barometer's readings faster than any rider climbs is its reference
#: moving (a door opening on a pressurized zone, a glitch of the sensor), not a ride,
#: wherever the person stands: the mean of the newest two updates this far past the
#: median of the four before them (in metres: ``MAX_CLIMB_MPS`` times the time between
#: the two groups' mean times, plus ``STEP_SIGMAS`` standard deviations of that
#: difference), each of the two at least half as far. An update is a reading that
#: differs from the one before, timed by the frame it first came with: a phone whose
#: barometer updates once a second repeats its reading over the frames between, and a
#: ride's climb over that second arrives as one step. Lifts in stations, shopping
#: centres and offices run at 1-2.5 m/s; skyscrapers' express lifts (up to 10 m/s) are
#: faster, and their steps would be taken for jumps.
MAX_CLIMB_MPS = 3.0
STEP_SIGMAS = 4.0
#: Updates the step test compares (the newest two against the median of the rest).
STEP_UPDATES = 6
#: The readings' noise for that test is estimated from this many of the latest
#: differences between consecutive updates (their median absolute value; the reported
#: ``std_m`` until there are ``NOISE_MIN_UPDATES``): phones report a conservative
#: figure, the readings say what it is.
NOISE_UPDATES = 50
NOISE_MIN_UPDATES = 10
#: Median |N(0, 2)| over the standard deviation of one reading: sqrt(2) times the
#: normal's upper quartile.
_MEDIAN_ABS_DIFF = float(np.sqrt(2.0)) * NormalDist().inv_cdf(0.75)
#: Likelihood of the barometer's level change for a particle that could not change level.
STAY_LIKELIHOOD = 1e-4
STAY_LOG = float(np.log(STAY_LIKELIHOOD))
#: A level change that less than this share of the weight could make contradicts the
#: belief: the filter starts again (over every level).
CONTRADICTED_SHARE = 0.01
#: ... with this share of the new cloud in the stops the change can have ended in
#: (:meth:`FloorTracker.arrivals`): whoever changed level has just left a connector.
#: The rest is spread over every level the barometer leaves possible, for a change no
#: connector on the map explains (an unmapped service lift, a pressure jump).
ARRIVAL_SHARE = 0.5
#: A level change made by at least this share of the weight, leaving at least
#: ``PINNED_SHARE`` of it in one stop, pins the person to that stop: the belief placed
#: them in that connector before the ride, and the barometer says they rode
#: (:meth:`FloorTracker.pinned_stop`).
PINNED_MOVED_SHARE = 0.5
PINNED_SHARE = 0.99
#: A held fix farther than its protection radius plus this from every connector's stop
#: (metres: a stride or two the odometry may not have shown) cannot have ridden one.
JUMP_MARGIN_M = 1.0
#: Rounds of drawing points in a stop before :meth:`FloorTracker.arrivals` gives up.
ARRIVAL_TRIES = 8
#: Without altitude: every ``NOMINAL_PERIOD_S``, the probability that a particle in a
#: stop moves.
BLIND_RATE = 0.02
#: A level change the barometer shows rising or falling at a lift's rate (the rate test,
#: ``LIFT_RISE_M``) weighs the particles that changed level by stairs, an escalator or a
#: ramp by this: a person climbing stairs at 0.2-0.5 m/s reads that fast with a chance of
#: a few percent (the rate test's noise, about 0.16 m for readings of 0.25 m; about 10 %
#: for a poor barometer's 0.4 m), a lift's rider nearly always.
WALKED_AT_LIFT_RATE = 0.1
#: A ride that changed level is over once the barometer has stood still: the slope of a
#: least-squares line through the readings of the last ``STILL_S`` seconds or more under
#: ``STILL_MPS`` (stairs and escalators rise 0.2-0.5 m/s), over enough readings that the
#: slope's noise (from the readings' measured noise) is at most half of it: 4.2 s of
#: readings of 0.25 m at 5 frames/s, 5.6 s of a poor barometer's 0.4 m (over 3 s its
#: slope's noise, 0.12 m/s, called a climb of the stairs still now and then: measured on
#: the venue suite's poorer phone, a stairs ride's place found 3.2 s after it instead of
#: at once); if the altitude then stands a quarter storey or more from the anchor
#: (``DRIFT_SHARE``), the anchor had lagged the barometer's drift as the ride began (it
#: follows drift with a time constant of about 10 s) and is taken where the altitude
#: stands. Before, the person stayed "between
#: floors" until the readings' noise brought them within the band: traced on the venue
#: suite (PDR, 66 deg, a belief not located as the lift left; the smoothed altitude 1.2-1.4
#: m short of the anchor after two storeys), the Second Floor was said 10.2 s after the
#: lift, not within 5 s.
STILL_S = 3.0
STILL_MPS = 0.1
#: The smallest storey height believed, metres (levels closer than this are one storey).
MIN_STOREY_M = 1.0
#: A level the barometer counted storeys to from a fix is confirmed without a new fix
#: once at least this share of the belief has stood on it for ``LEVEL_SURE_S`` seconds
#: of frames in a row: the person hears the floor while the
#: view, through a phone's narrow camera leaving a lift car, has yet to show where on it
#: they are.
LEVEL_SURE_SHARE = 0.99
LEVEL_SURE_S = 1.0
#: The readings kept: the rate test's window at ``MIN_PERIOD_S``.
MAX_READINGS = int(np.ceil(2.0 * RATE_HALF_S / MIN_PERIOD_S))


@dataclass(frozen=True, slots=True)
class AltitudeReading:
    """The phone's barometric altitude relative to a reference it keeps fixed, and its
    standard deviation, metres."""

    relative_m: float
    std_m: float = 0.5


class FloorTracker:
    """Level changes of one filter's particles (maps with two or more levels only).

    Attributes:
        level_probability: the share of the weight on the estimate's level after the
            last :meth:`after_estimate`; None before.
        changes: how many level changes the barometer has shown.
    """

    def __init__(self, semantic_map: SemanticMap) -> None:
        layout = semantic_map.layout
        if len(layout.levels) < 2:
            raise ValueError("a FloorTracker needs a map with two or more levels")
        self.layout = layout
        self.free = semantic_map.free_space
        polygons = []
        stop_level = []
        # Per stop: the next level its connector reaches down / up (-1: none).
        targets: list[tuple[int, int]] = []
        reach: list[tuple[int, ...]] = []
        lift: list[bool] = []
        for conn in layout.connectors:
            for stop in conn.stops:
                polygons.append(stop.plane_polygon)
                stop_level.append(stop.level)
                lift.append(conn.kind == "elevator")
                options = conn.reachable(stop.level)
                below = [lv for lv in options if lv < stop.level]
                above = [lv for lv in options if lv > stop.level]
                targets.append((max(below) if below else -1, min(above) if above else -1))
                reach.append(options)
        self._edges, self._starts = polygon_edges(polygons)
        self._polygons = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons]
        self._stop_level = np.array(stop_level, dtype=np.int64)
        self._target = np.array(targets, dtype=np.int64).reshape(-1, 2)
        self._reach = reach
        #: Per stop, whether its connector is a lift.
        self._lift = np.array(lift, dtype=bool)
        elevations = np.array([lv.elevation_m for lv in layout.levels])
        self._elevation = elevations
        #: Per level, its storey: the rank of its elevation among the levels' (a ride's
        #: step moves a person one storey).
        self._storey = np.searchsorted(np.unique(elevations), elevations).astype(np.int64)
        steps = np.abs(np.diff(np.sort(elevations)))
        self.storey_m = float(max(steps.min() if steps.size else MIN_STOREY_M, MIN_STOREY_M))
        self.reset()

    def reset(self) -> None:
        """Forget the barometer (a new start)."""
        self._readings: deque[float] = deque(maxlen=MAX_READINGS)
        #: Frames with altitude so far, and their time (seconds, the tracker's own clock).
        self._frames = 0
        self._clock = 0.0
        #: The latest times between frames, seconds (the frame period, :meth:`_period`).
        self._intervals: deque[float] = deque(maxlen=PERIOD_FRAMES)
        #: The latest updates (a reading other than the one before): the reading, and
        #: the time and number of the frame it first came with, for the step test
        #: (STEP_UPDATES) ...
        self._updates: deque[tuple[float, float, int]] = deque(maxlen=STEP_UPDATES)
        #: ... and the latest |differences| of consecutive updates (NOISE_UPDATES).
        self._diffs: deque[float] = deque(maxlen=NOISE_UPDATES)
        self.anchor_m: float | None = None
        self.changes = 0
        #: Storeys the barometer's steps have taken the person up (down: negative) since
        #: the chain of readings began (a frame without altitude breaks it).
        self.net_storeys = 0
        #: How often the count of storeys was dropped as wrong (after_estimate, apply).
        self.counts_dropped = 0
        self.level_probability: float | None = None
        #: Whether the barometer says the person is between floors (the smoothed
        #: altitude more than ``DRIFT_SHARE`` of a storey from the anchor).
        self.in_transit = False
        #: Whether a level has changed since the person was last not between floors.
        self._changed_in_transit = False
        #: The level last confirmed (:meth:`after_estimate`), and whether this step
        #: confirmed a level other than the one before (the first fix included).
        self.confirmed_level: int | None = None
        self.newly_confirmed = False
        #: Whether this step confirmed the estimate's level (again or anew).
        self.confirmed_now = False
        #: Frames in a row the belief has stood on the counted level (``LEVEL_SURE_*``).
        self._sure_frames = 0
        #: The storey the chain of readings began on, as the last converged fix implies
        #: (its level's storey less the storeys counted by then); None: no fix since
        #: the chain began.
        self._start_storey: int | None = None
        #: The level the barometer carries a confirmed fix to (None: none confirmed,
        #: or the chain broke: a frame without altitude, a contradiction).
        self.carried_level: int | None = None
        #: Whether the last frame came without altitude, whether it changed level, and
        #: how far the heaviest particle that changed moved in the plane (metres).
        self.blind = False
        self.changed = False
        self.first_change = False
        self.shift_x_m = 0.0
        #: The way of the last level change (up: True) and whether the barometer rose or
        #: fell at a lift's rate then (:meth:`arrivals`).
        self._last_up = True
        self._last_at_lift_rate = False
        #: The share of the weight that made the last level change (:meth:`pinned_stop`).
        self.moved_share = 0.0
        #: Jumps of the barometer's reference followed: steps of its readings faster
        #: than any rider climbs (:meth:`_follow_step`), and level changes it showed
        #: far from every connector (:meth:`_jumped`).
        self.reference_jumps = 0

    # ------------------------------------------------------------ the particles
    def stop_of(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.int64]:
        """The stop each particle stands in (index over every connector's stops), or -1."""
        if not self._starts.size:
            return np.full(x.shape, -1, dtype=np.int64)
        return first_polygon(np.column_stack([x, y]), self._edges, self._starts)

    def quiet_frame(self) -> None:
        """A frame answered between two steps (the filter's pacing): no level changed
        or was confirmed on it, whatever the last step did."""
        self.changed = False
        self.first_change = False
        self.newly_confirmed = False
        self.confirmed_now = False

    def in_stop(self, x: float, y: float) -> bool:
        """Whether plane point (x, y) lies in a connector's stop (a lift car, the foot
        or head of stairs or an escalator)."""
        return bool(self.stop_of(np.array([x]), np.array([y]))[0] >= 0)

    def _share_in_stops(
        self, x: NDArray[np.float64], y: NDArray[np.float64], log_w: NDArray[np.float64]
    ) -> float:
        """The share of the weight on particles standing in a connector's stop."""
        inside = self.stop_of(x, y) >= 0
        if not inside.any():
            return 0.0
        if not np.isfinite(log_w).any():
            return float(inside.mean())
        w = np.exp(log_w - log_w.max())
        return float(w[inside].sum() / w.sum())

    def _move(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        which: NDArray[np.int64],
        to: NDArray[np.int64],
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """x of the particles ``which`` moved to levels ``to``, and whether each landed
        in free space (one that did not stays where it was)."""
        new_x = x.copy()
        frm = self.layout.level_of_plane_x(x[which])
        moved_x = x[which] + self.layout.offsets(to) - self.layout.offsets(frm)
        ok = self.free.is_free(moved_x, y[which])
        new_x[which[ok]] = moved_x[ok]
        return new_x, ok

    def apply(
        self,
        x: NDArray[np.float64],
        y: NDArray[np.float64],
        log_w: NDArray[np.float64],
        altitude: AltitudeReading | None,
        rng: np.random.Generator,
        fix: tuple[float, float, float] | None = None,
        seconds: float | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
        """The particles' x and log-weights after this frame's level changes, and
        whether the barometer contradicts the whole belief (a level change, and less
        than ``CONTRADICTED_SHARE`` of the weight could make it). ``fix``: a fix held
        (plane x, y and its protection radius), which such a change does not move when
        no connector's stop lies within its radius (:meth:`_jumped`). ``seconds``: the
        time since the previous frame (None: not known, and the step test starts over,
        since a guess could make a lift's climb look faster than it was)."""
        self.blind = altitude is None
        self.changed = False
        self.first_change = False
        self.shift_x_m = 0.0
        if seconds is not None and seconds > 0.0:
            self._intervals.append(float(seconds))
        if altitude is None:
            self.carried_level = None
            self.in_transit = False
            self._changed_in_transit = False
            self._break_count()  # (the person may have changed level unseen)
            return self._blind(x, y, rng), log_w, False
        if seconds is None:
            self._updates.clear()
        else:
            self._clock += max(float(seconds), 0.0)
        reading = float(altitude.relative_m)
        self._readings.append(reading)
        self._frames += 1
        if not self._updates or reading != self._updates[-1][0]:
            if self._updates:
                self._diffs.append(abs(reading - self._updates[-1][0]))
            self._updates.append((reading, self._clock, self._frames))
            self._follow_step(float(altitude.std_m))
        recent = list(self._readings)
        smoothed = float(np.mean(recent[-self._frames_in(SMOOTH_S) :]))
        half = self._frames_in(RATE_HALF_S)
        window = recent[-2 * half :]
        moving = len(window) == 2 * half and (
            abs(float(np.mean(window[half:])) - float(np.mean(window[:half]))) >= LIFT_RISE_M
        )
        if self.anchor_m is None:
            self.anchor_m = smoothed
            return x, log_w, False
        delta = smoothed - self.anchor_m
        threshold = CHANGE_SHARE * self.storey_m
        band = DRIFT_SHARE * self.storey_m
        if (
            self._changed_in_transit
            and band <= abs(delta) < threshold
            and self._still(float(altitude.std_m))
        ):
            # The ride that changed level is over short of (or past) the storeys added
            # to the anchor (STILL_S): the anchor is taken where the altitude stands.
            self.anchor_m = smoothed
            self.in_transit = False
            self._changed_in_transit = False
            return x, log_w, False
        if abs(delta) < threshold:
            # Only a person in a connector can be between floors: while less than
            # CONTRADICTED_SHARE of the weight stands in a stop, a reading that looks
            # like a ride is the barometer's noise or drift (a full storey's change
            # would still contradict such a belief, below).
            # The rate test starts a ride only once the altitude has also left the
            # anchor by RATE_ENTRY_M (a noisy barometer's half-means cross LIFT_RISE_M
            # now and then at rest); it keeps one going through a floor passed without
            # stopping, where the altitude is back near a level's.
            ride_rate = moving and (self.in_transit or abs(delta) >= RATE_ENTRY_M)
            riding = abs(delta) >= band or ride_rate
            # A transit that has changed no level yet ends only once the altitude is back
            # within RATE_ENTRY_M of the anchor (which meanwhile follows it as it does at
            # rest): a ride slower than the rate test, started by it, does not drop out
            # of transit for the frames before the altitude reaches the band; the
            # barometer's noise settles back.
            settling = self.in_transit and not self._changed_in_transit
            settling = settling and abs(delta) >= RATE_ENTRY_M
            self.in_transit = (riding or settling) and self._share_in_stops(
                x, y, log_w
            ) >= CONTRADICTED_SHARE
            if not (self.in_transit and riding):
                self.anchor_m += DRIFT_GAIN * self._periods() * delta
            if not self.in_transit:
                self._changed_in_transit = False
            return x, log_w, False
        self.in_transit = True
        up = delta > 0
        self._last_up, self._last_at_lift_rate = up, moving
        stop = self.stop_of(x, y)
        inside = np.flatnonzero(stop >= 0)
        to = self._target[stop[inside], 1 if up else 0]
        go = to >= 0
        which, to = inside[go], to[go]
        new_x, landed = self._move(x, y, which, to)
        moved = which[landed]
        prior = np.exp(log_w - log_w.max()) if np.isfinite(log_w).any() else np.ones(x.shape)
        moved_share = float(prior[moved].sum() / prior.sum())
        if moved_share < CONTRADICTED_SHARE and self._jumped(fix):
            # Nobody changes floor far from every connector: the barometer's reference
            # moved (a pressurized zone, a glitch). It is followed, not believed.
            self.anchor_m = smoothed
            self.in_transit = False
            self._changed_in_transit = False
            self.reference_jumps += 1
            return x, log_w, False
        self.moved_share = moved_share
        stayed = np.ones(x.shape, dtype=bool)
        stayed[moved] = False
        log_w = log_w + np.where(stayed, np.log(STAY_LIKELIHOOD), 0.0)
        if moving:
            # As fast as a lift: the ones that took the stairs (a cloud not yet located,
            # in the lift car and at the foot of the stairs alike) are less likely.
            walked = moved[~self._lift[stop[moved]]]
            log_w[walked] += np.log(WALKED_AT_LIFT_RATE)
        if moved.size:
            frm = self.layout.level_of_plane_x(x[moved])
            rise = self._elevation[to[landed]] - self._elevation[frm]
            w = prior[moved]
            top = int(np.argmax(w))
            self.shift_x_m = float(
                self.layout.offsets(to[landed][top]) - self.layout.offsets(frm[top])
            )
            self.anchor_m += float(np.sum(w * rise) / max(float(np.sum(w)), 1e-300))
            self.carried_level = self._carry(frm, to[landed], w)
        else:
            self.anchor_m += threshold * 2.0 if up else -threshold * 2.0
        self.changes += 1
        self.net_storeys += 1 if up else -1
        allowed = self.level_allowed()
        if allowed is not None and not allowed.any():
            # More storeys one way than the venue has: the count went wrong somewhere (a
            # jump of the barometer's reference taken for a ride) and says nothing.
            self._break_count(wrong=True)
        self.changed = True
        #: Whether this change is the first of its ride (a ride of several floors makes
        #: several).
        self.first_change = not self._changed_in_transit
        self._changed_in_transit = True
        if moved_share < CONTRADICTED_SHARE:
            self.carried_level = None
        return new_x, log_w, moved_share < CONTRADICTED_SHARE

    def _still(self, reported_std_m: float) -> bool:
        """Whether the latest readings lie on a line rising or falling slower than
        ``STILL_MPS``: those of ``STILL_S`` seconds, or more, so that the slope's noise
        is at most half of ``STILL_MPS`` (False while there are not that many). The
        noise is counted in updates, not frames: a barometer updating once a second
        repeats each reading over the frames between, which add no sample (counted in
        frames, 3 of 40 simulated 0.3 m/s climbs of the stairs through readings of 0.25 or
        0.4 m updated at 1 Hz were called still midway; none counted in updates)."""
        period = self._period()
        step = self._update_period()
        # A line's slope through n readings dt apart, each of std s, has std
        # s / sqrt(dt^2 n (n^2 - 1) / 12).
        std = self._reading_std(reported_std_m)
        enough = float(np.cbrt(12.0 * std**2 / ((STILL_MPS / 2.0) ** 2 * step**2)))
        updates = int(np.ceil(enough)) + 1
        n = max(self._frames_in(STILL_S), int(np.ceil(updates * step / period - 1e-9)), 5)
        if n > len(self._readings):
            return False
        r = np.fromiter(itertools.islice(reversed(self._readings), n), dtype=np.float64)
        t = np.arange(n, dtype=np.float64) * -period
        tc = t - t.mean()
        slope = float(np.dot(tc, r - r.mean()) / np.dot(tc, tc))
        return abs(slope) < STILL_MPS

    def _update_period(self) -> float:
        """Seconds between the barometer's updates (readings other than the one before),
        over the latest ``STEP_UPDATES``; the frame period until two are known, and
        never less."""
        period = self._period()
        if len(self._updates) < 2:
            return period
        first, last = self._updates[0], self._updates[-1]
        return max((last[1] - first[1]) / (len(self._updates) - 1), period)

    def _reading_std(self, reported_std_m: float) -> float:
        """The barometer's noise, metres: from the latest differences between its
        updates (``NOISE_UPDATES``), the reported figure until there are
        ``NOISE_MIN_UPDATES``."""
        if len(self._diffs) >= NOISE_MIN_UPDATES:
            return float(np.median(np.fromiter(self._diffs, dtype=np.float64))) / _MEDIAN_ABS_DIFF
        return reported_std_m

    def _period(self) -> float:
        """The session's frame period, seconds: the median of the latest times between
        frames (``NOMINAL_PERIOD_S`` before one is known), rounded to
        ``PERIOD_ROUND_S``, no shorter than ``MIN_PERIOD_S``."""
        if not self._intervals:
            return NOMINAL_PERIOD_S
        median = float(np.median(np.fromiter(self._intervals, dtype=np.float64)))
        return max(round(median / PERIOD_ROUND_S) * PERIOD_ROUND_S, MIN_PERIOD_S)

    def _frames_in(self, seconds: float) -> int:
        """How many frames make ``seconds`` at the session's frame period (at least 1)."""
        return max(round(seconds / self._period()), 1)

    def _periods(self) -> float:
        """A frame's length in ``NOMINAL_PERIOD_S`` (what a rate given per nominal
        period is scaled by)."""
        return self._period() / NOMINAL_PERIOD_S

    def _follow_step(self, reported_std_m: float) -> None:
        """Take a step of the updates faster than any rider climbs (``MAX_CLIMB_MPS``)
        for the reference moving: the readings before it, and the anchor, move by it, as
        if the reference had always been the new one."""
        if len(self._updates) < STEP_UPDATES or self.anchor_m is None:
            return
        values = np.array([v for v, _, _ in self._updates])
        times = np.array([t for _, t, _ in self._updates])
        rise = values[-2:] - float(np.median(values[:-2]))
        if rise[0] * rise[1] <= 0.0:
            return
        std = self._reading_std(reported_std_m)
        # The mean of two readings against the median of four (variance about pi/2 / 4).
        spread = std * float(np.sqrt(0.5 + np.pi / 8.0))
        climb = MAX_CLIMB_MPS * float(np.mean(times[-2:]) - np.mean(times[:-2]))
        needed = climb + STEP_SIGMAS * spread
        if abs(float(np.mean(rise))) < needed or float(np.min(np.abs(rise))) < 0.5 * needed:
            return
        step = float(np.mean(rise))
        first = self._updates[-2][2]  # the frame the step first came with
        after = self._frames - first + 1  # readings since then, the newest ones
        readings = list(self._readings)
        cut = max(len(readings) - after, 0)
        moved = [v + step for v in readings[:cut]] + readings[cut:]
        self._readings = deque(moved, maxlen=MAX_READINGS)
        self._updates = deque(
            ((v, t, k) if k >= first else (v + step, t, k) for v, t, k in self._updates),
            maxlen=STEP_UPDATES,
        )
        self.anchor_m += step
        self.reference_jumps += 1

    def _carry(
        self, frm: NDArray[np.int64], to: NDArray[np.int64], w: NDArray[np.float64]
    ) -> int | None:
        """Where the carried level went: the heaviest destination of the particles that
        left it (None when none did)."""
        if self.carried_level is None:
            return None
        mine = frm == self.carried_level
        if not mine.any():
            return None
        totals = np.bincount(to[mine], weights=w[mine], minlength=len(self.layout.levels))
        return int(np.argmax(totals))

    def _break_count(self, wrong: bool = False) -> None:
        """Start the count of storeys afresh, with no fix to count from (a frame without
        altitude; ``wrong``: a count the view or the venue contradicts,
        :attr:`counts_dropped`)."""
        self.net_storeys = 0
        self._start_storey = None
        if wrong:
            self.counts_dropped += 1

    def _jumped(self, fix: tuple[float, float, float] | None) -> bool:
        """Whether a level change no particle could make comes from a fix held farther
        than its protection radius from every connector's stop: the person cannot have
        ridden (else the belief missed the ride, and starts again at the exits)."""
        if fix is None or not self._starts.size:
            return False
        x, y, radius = fix
        nearest = float(point_segment_distance([[x, y]], self._edges).min())
        return nearest > radius + JUMP_MARGIN_M and not self.in_stop(x, y)

    def arrivals(
        self, n: int, rng: np.random.Generator
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Up to ``n`` plane points where the last level change can have let the person
        off: uniform in each stop from which a connector leads that way (escalators
        only their way), moved to the level it reaches, on a level :meth:`level_allowed`
        leaves. Each such stop draws an equal share, one of stairs, an escalator or a
        ramp ``WALKED_AT_LIFT_RATE`` of a lift's when the barometer moved at a lift's
        rate. Fewer points (none) where the stops leave too little free space."""
        side = 1 if self._last_up else 0
        source = np.flatnonzero(self._target[:, side] >= 0)
        to = self._target[source, side]
        allowed = self.level_allowed()
        if allowed is not None:
            keep = allowed[to]
            source, to = source[keep], to[keep]
        empty = np.empty(0)
        if not source.size or n <= 0:
            return empty, empty
        share = np.where(
            self._lift[source] | (not self._last_at_lift_rate), 1.0, WALKED_AT_LIFT_RATE
        )
        counts = rng.multinomial(n, share / share.sum())
        xs, ys = [], []
        for s, target, want in zip(source.tolist(), to.tolist(), counts.tolist(), strict=True):
            poly = self._polygons[s]
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            got: list[NDArray[np.float64]] = []
            have = 0
            for _ in range(ARRIVAL_TRIES):
                if have >= want:
                    break
                pts = rng.uniform(lo, hi, size=(2 * (want - have) + 16, 2))
                pts = pts[points_in_polygon(pts, poly)]
                pts = pts[self.free.is_free(pts[:, 0], pts[:, 1])]
                px, landed = self._move(
                    pts[:, 0], pts[:, 1], np.arange(len(pts)), np.full(len(pts), target)
                )
                pts = np.column_stack([px, pts[:, 1]])[landed][: want - have]
                got.append(pts)
                have += len(pts)
            if got:
                both = np.concatenate(got)
                xs.append(both[:, 0])
                ys.append(both[:, 1])
        if not xs:
            return empty, empty
        return np.concatenate(xs), np.concatenate(ys)

    def pinned_stop(
        self, x: NDArray[np.float64], y: NDArray[np.float64], w: NDArray[np.float64]
    ) -> tuple[float, float, float] | None:
        """After a level change most of the belief made (``PINNED_MOVED_SHARE``), the stop
        that holds all but ``1 - PINNED_SHARE`` of the weight ``w`` now, as its centre
        and the radius of the circle about it holding the stop (plane metres); None when
        the belief is not pinned to one stop."""
        if not self.changed or self.moved_share < PINNED_MOVED_SHARE:
            return None
        stop = self.stop_of(x, y)
        inside = stop >= 0
        if not inside.any():
            return None
        totals = np.bincount(stop[inside], weights=w[inside], minlength=len(self._polygons))
        best = int(np.argmax(totals))
        if totals[best] < PINNED_SHARE * float(w.sum()):
            return None
        poly = self._polygons[best]
        cx, cy = (poly.min(axis=0) + poly.max(axis=0)) / 2.0
        radius = float(np.max(np.hypot(poly[:, 0] - cx, poly[:, 1] - cy)))
        return float(cx), float(cy), radius

    def level_allowed(self) -> NDArray[np.bool_] | None:
        """Per level, whether the barometer's steps since its chain of readings began
        leave the person possibly on it (None: every level). Gone up a storey from
        wherever they started, a person is on no lowest floor: a belief that missed the
        ride (a cloud not yet located, all of it outside the lift's stop) must not
        settle there on a look-alike place. Counted in storeys, not metres: the
        barometer wanders by metres over an hour, a ride's steps do not."""
        if self.net_storeys == 0:
            return None
        start = self._storey - self.net_storeys
        return (start >= 0) & (start <= int(self._storey.max()))

    def rule_out_levels(
        self, x: NDArray[np.float64], log_w: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """``log_w`` with the particles on a level :meth:`level_allowed` rules out
        weighed as unlikely as one that stayed put through a level change."""
        allowed = self.level_allowed()
        if allowed is None:
            return log_w
        level = self.layout.level_of_plane_x(x)
        return log_w + np.where(allowed[level], 0.0, np.log(STAY_LIKELIHOOD))

    def injected_log_w(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Log-weights for particles the recovery injects at plane x: as unlikely as one
        that stayed through a level change on a level :meth:`place_allowed` rules out
        (the barometer's count, the level it carries a confirmed fix to), else 0. What
        the view suggests on another floor is no reason to believe the barometer missed
        a ride (measured on the venue suite, PDR grade at 180 deg: a fix held into the
        lift car, its view blank, swapped for places upstairs that injected particles
        found to fit the few boxes, 26 s lost after the ride)."""
        return np.where(self._place_levels()[self.layout.level_of_plane_x(x)], 0.0, STAY_LOG)

    def place_allowed(self, x: float, y: float) -> bool:
        """Whether the evidence search may keep an alternative at plane point (x, y):
        not on a level the barometer's steps rule out (:meth:`level_allowed`), nor on
        a level other than the one the barometer carries a confirmed fix to. Such an
        alternative would say that fix stood on the wrong floor, which the alternatives
        of its day had ruled out, and the barometer has counted every storey since: a
        look-alike hall upstairs fits a narrow camera's few boxes as well as this one
        and, searched for afresh, took a located person's fix from them (the venue
        suite's 66-degree camera: about 4 % of the Ground Floor's walking frames).
        Anywhere while no level is carried (no fix yet, a broken chain, no barometer:
        then only what is seen tells the floors apart)."""
        return bool(self._place_levels()[self.layout.level_of(x)])

    def _place_levels(self) -> NDArray[np.bool_]:
        """Per level, whether a place may be on it (:meth:`place_allowed`)."""
        allowed = self.level_allowed()
        ok = np.ones(len(self.layout.levels), dtype=bool) if allowed is None else allowed
        if self.carried_level is not None and not self.blind:
            ok = ok & (np.arange(ok.size) == self.carried_level)
        return ok

    def _blind(
        self, x: NDArray[np.float64], y: NDArray[np.float64], rng: np.random.Generator
    ) -> NDArray[np.float64]:
        """No altitude: a few particles in stops move to a level their connector reaches."""
        pick = np.flatnonzero(rng.random(x.shape[0]) < BLIND_RATE * self._periods())
        if not pick.size:
            return x
        stop = self.stop_of(x[pick], y[pick])
        keep = stop >= 0
        which, stop = pick[keep], stop[keep]
        if not which.size:
            return x
        to = np.array(
            [
                self._reach[s][int(rng.integers(len(self._reach[s])))] if self._reach[s] else -1
                for s in stop
            ],
            dtype=np.int64,
        )
        go = to >= 0
        return self._move(x, y, which[go], to[go])[0]

    def between_floors(self, x: float, y: float) -> bool:
        """Whether a person at plane point (x, y) may be between floors: the barometer
        says so, or without one the point lies in a connector's stop (a lift car looks
        the same on every floor: only leaving it tells which)."""
        if self.in_transit:
            return True
        if not self.blind:
            return False
        return self.in_stop(x, y)

    def counted_level(self) -> int | None:
        """The level the barometer's steps lead to: from the last converged fix, that
        fix's storey plus the storeys counted since; without one, the only level
        :meth:`level_allowed` leaves (two storeys up in a three-storey venue: the top
        floor, wherever the person started). None: neither says, or no single level
        stands on that storey."""
        if self._start_storey is None:
            allowed = self.level_allowed()
            only = np.flatnonzero(allowed) if allowed is not None else np.array([])
            return int(only[0]) if only.size == 1 else None
        on = np.flatnonzero(self._storey == self._start_storey + self.net_storeys)
        return int(on[0]) if on.size == 1 else None

    def share_on_level(
        self, x: NDArray[np.float64], w: NDArray[np.float64], estimate_x: float
    ) -> float:
        """The share of the (normalized) weights ``w`` on the level of plane x
        ``estimate_x``."""
        mine = self.layout.level_of(estimate_x)
        return float(np.sum(w[self.layout.level_of_plane_x(x) == mine]))

    def after_estimate(
        self, x: NDArray[np.float64], w: NDArray[np.float64], estimate_x: float, converged: bool
    ) -> None:
        """Keep the share of the weight on the estimate's level
        (:attr:`level_probability`) and confirm that level (:attr:`confirmed_level`,
        :attr:`newly_confirmed` when it changed) when the estimate is converged, or when
        it is the level the barometer's steps lead to from the last fix
        (:meth:`counted_level`) and the belief has agreed (``LEVEL_SURE_SHARE``) for
        ``LEVEL_SURE_S`` seconds of frames while nobody is between floors. The second is the
        floor without the place: the storeys counted from a fix say which floor the
        person left the lift or the stairs on, while through a narrow camera the place
        on it takes a few more seconds of looking (the cloud may even have lost the
        person in the lift car). Without a fix since the chain began (a global start not
        yet located, a frame without altitude) nothing is counted, and a look-alike
        floor the belief merely drifted to is never confirmed this way."""
        self.level_probability = self.share_on_level(x, w, estimate_x)
        mine = self.layout.level_of(estimate_x)
        counted = (
            not converged
            and not self.blind
            and not self.in_transit
            and self.counted_level() == mine
            and self.level_probability >= LEVEL_SURE_SHARE
        )
        self._sure_frames = self._sure_frames + 1 if counted else 0
        confirmed = converged or self._sure_frames >= self._frames_in(LEVEL_SURE_S)
        self.confirmed_now = confirmed
        self.newly_confirmed = confirmed and mine != self.confirmed_level
        if confirmed:
            self.confirmed_level = mine
        if converged and not self.blind:
            allowed = self.level_allowed()
            if allowed is not None and not allowed[mine]:
                # A fix passed every test of the gate on a level the count of storeys
                # rules out (its particles weighed STAY_LIKELIHOOD a frame there): the
                # count is what went wrong (a jump of the barometer's reference taken
                # for a ride while the belief was not located). Kept, it would hold the
                # belief off the person's floor after every ride to come.
                self._break_count(wrong=True)
            self.carried_level = mine
            self._start_storey = int(self._storey[mine]) - self.net_storeys

    # ------------------------------------------------------------ checkpoints
    def checkpoint(self) -> dict[str, Any]:
        return {
            "readings": list(self._readings),
            "frames": self._frames,
            "clock": self._clock,
            "intervals": list(self._intervals),
            "updates": [list(u) for u in self._updates],
            "diffs": list(self._diffs),
            "anchor_m": self.anchor_m,
            "changes": self.changes,
            "net_storeys": self.net_storeys,
            "level_probability": self.level_probability,
            "in_transit": self.in_transit,
            "changed_in_transit": self._changed_in_transit,
            "confirmed_level": self.confirmed_level,
            "sure_frames": self._sure_frames,
            "start_storey": self._start_storey,
            "carried_level": self.carried_level,
            "blind": self.blind,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        self._readings = deque((float(v) for v in state["readings"]), maxlen=MAX_READINGS)
        # (An older checkpoint: no updates, no noise measured yet.)
        self._frames = int(state.get("frames", 0))
        self._clock = float(state.get("clock", 0.0))
        self._intervals = deque(
            (float(v) for v in state.get("intervals", [])), maxlen=PERIOD_FRAMES
        )
        updates = [u for u in state.get("updates", []) if len(u) == 3]
        self._updates = deque(
            ((float(v), float(t), int(k)) for v, t, k in updates), maxlen=STEP_UPDATES
        )
        self._diffs = deque((float(v) for v in state.get("diffs", [])), maxlen=NOISE_UPDATES)
        anchor = state["anchor_m"]
        self.anchor_m = None if anchor is None else float(anchor)
        self.changes = int(state["changes"])
        self.net_storeys = int(state.get("net_storeys", 0))  # (older: no chain known)
        p = state["level_probability"]
        self.level_probability = None if p is None else float(p)
        self.in_transit = bool(state["in_transit"])
        self._changed_in_transit = bool(state.get("changed_in_transit", False))
        confirmed = state["confirmed_level"]
        self.confirmed_level = None if confirmed is None else int(confirmed)
        self.newly_confirmed = False
        self.confirmed_now = False
        self._sure_frames = int(state.get("sure_frames", 0))  # (older: none counted)
        start = state.get("start_storey")
        self._start_storey = None if start is None else int(start)
        carried = state["carried_level"]
        self.carried_level = None if carried is None else int(carried)
        self.blind = bool(state["blind"])


def spread_over_levels(
    x: NDArray[np.float64],
    semantic_map: SemanticMap,
    levels: tuple[int, ...],
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """A known start's particles' x (drawn on ``levels[0]``) dealt evenly over ``levels``:
    a position known on the floor plan, its floor not (the same x and y on each)."""
    layout = semantic_map.layout
    pick = np.asarray(levels, dtype=np.int64)[rng.integers(len(levels), size=x.shape[0])]
    return x + layout.offsets(pick) - layout.offsets(levels[0])
