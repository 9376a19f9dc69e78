"""Which fixes a gain continues, and so need not be narrow to be told.

A first fix is told only once its protection radius is narrow
(:data:`~app.localization.convergence.GAIN_PROTECTION_M`): a person who has heard
nothing yet loses little by waiting. A fix that takes up one the person was just told, at
the place it left off, is not a first fix, and holding it to that radius only keeps a
right answer from them. :class:`Continuation` keeps the four such cases the filter
knows, each from the moment it starts to the next fix or its deadline:

* a **known start** (the app's ``initial_pose``) until the first fix: that fix continues
  the pose the app gave (a start given within half a metre is itself a radius of
  1.5 m, and a narrow camera standing still pins the place no closer along its line of
  sight);
* a fix told as the person came into a connector's stop (or rode between levels) and
  let go there, for ``STOP_EXIT_FRAMES`` frames out of the stop;
* a ride the belief placed the person in one connector for, though it held no fix
  (:meth:`~app.localization.floors.FloorTracker.pinned_stop`: the barometer says they
  rode, the belief says which connector), for ``STOP_EXIT_FRAMES`` frames out of the
  stop, whose car or flight the bearings' geometry carries as a fix; frames on which the
  gain waits for nothing but the evidence tracker's search are not counted (once its
  searches find nothing they come every ``max_search_every`` frames, as many as the
  window: a run of steady frames broken once after a search waited for the next one
  beyond the window);
* a fix let go for doubt alone (an alternative gained probability, then was refuted;
  its estimate jumped further in one step than the motion allows; or the evidence
  swapped the belief onto a place within the told radius), for ``DOUBT_FRAMES`` frames;
  one let go only because the bearings' geometry no longer bounded it (nothing in view
  pinned it for a while, :mod:`~app.localization.dilution`), for
  ``GEOMETRY_DOUBT_FRAMES``.

The gain's other tests still apply (the slide check among them), and a gain the gate
holds is never tested again for its radius. A fix let go for doubt is also taken up with
the cluster a held fix keeps, not a first gain's tighter one
(:meth:`~app.localization.convergence.ConvergenceGate.cluster_holds`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from app.localization.slide import SLIDE_FRAMES

#: A fix told as the person came into a connector's stop (or a ride) and let go there (a
#: lift car shows the same on every floor; a ride moves the cloud by the barometer, not
#: the view) is taken up again on leaving it without the narrow radius a first fix needs,
#: for this many frames out of the stop (5 s at 5 frames/s: the time the venue suite
#: allows for a level change to be confirmed). The exit is as good as a known start: the
#: person left the connector there. Measured on the venue suite: held to the narrow
#: radius, the place was found 3.0 s after a stairs ride with a barometer (median,
#: against 0.0), and without one the floor was confirmed within 5 s of 4 of 10 lift
#: rides (against 10); with no limit of frames, a fix lost later in the walk was regained
#: 2.4 m off with an 18 m radius (PDR, 180 degrees). Counting a fix let go in the lift
#: car before the ride began (a phone's narrow camera facing its wall), the place after a
#: ride through a 66-degree camera was found within 5 s 25 -> 32 times of 40 (VIO),
#: 23 -> 28 (PDR).
STOP_EXIT_FRAMES = 25
#: A fix let go for doubt alone and taken up again within this many frames continues it:
#: it returns to the place told (after an alternative, the slide check holds the regain
#: within ``hold_slide_m`` of the told fix carried by the odometry, over as many frames;
#: a swap's place lay within the told radius). Measured on the venue suite through a
#: 66-degree camera: a fix let go for an alternative refuted 4 s later stayed "not sure"
#: for 37-50 s at 0.1 m of error, each gain taken back for a radius of 2-3 m, and one
#: swapped 0.13 m for 59 s.
DOUBT_FRAMES = SLIDE_FRAMES
#: A fix let go only because its bound grew past the gate's (``hold_geometry_m``: a
#: narrow camera saw too little for too long) was not questioned at all, and is taken up
#: again without a narrow radius for this many frames (10 s at 5 frames/s). Longer than
#: DOUBT_FRAMES: on such a release the cloud spreads for a couple of seconds and the gain
#: then waits for the evidence tracker's next search. Traced on the venue suite through a
#: 66-degree camera with PDR odometry (seed 0, Second Floor): let go at 0.43 m of error,
#: a geometry bound of 1.3-2 m again 12 frames later, the search's wait ending 32 frames
#: after the release, then held to a first fix's 1.5 m radius for the rest of the floor
#: (over 150 frames, 0.1-0.5 m off) where the floor's own map kept its fix.
GEOMETRY_DOUBT_FRAMES = 2 * SLIDE_FRAMES


def doubt_frames(lost_because: tuple[str, ...]) -> int:
    """How many frames a fix let go for doubt alone, for ``lost_because`` (the gate's),
    is continued."""
    return GEOMETRY_DOUBT_FRAMES if lost_because == ("weak geometry",) else DOUBT_FRAMES


class Continuation:
    """The fixes the next gain would continue (module docstring), frame by frame."""

    def __init__(self, known_start: bool = False) -> None:
        self.reset(known_start)

    def reset(self, known_start: bool = False) -> None:
        """Nothing to continue but, with ``known_start``, the pose the app gave."""
        #: Until the first fix from a known start.
        self.known_start = known_start
        #: Frames out of a connector's stop since a fix told as the person came into it
        #: (or rode between levels) was let go there; None without one.
        self.out_of_stop: int | None = None
        #: Frames since a fix was let go for doubt alone; None without one.
        self.since_doubt: int | None = None
        #: ... and how many it is continued for (:func:`doubt_frames`).
        self.doubt_frames = DOUBT_FRAMES
        #: Whether ``out_of_stop`` counts from a ride the belief was pinned for.
        self.pinned = False

    @property
    def active(self) -> bool:
        """Whether a gain now continues a fix (and is not held to the narrow radius)."""
        return self.known_start or self.out_of_stop is not None or self.since_doubt is not None

    def rode_pinned(self) -> None:
        """A ride the belief placed the person in one connector for: its exit is taken
        up as a told fix let go in the stop is."""
        self.out_of_stop = 0
        self.pinned = True

    def doubted(self, frames: int = DOUBT_FRAMES) -> None:
        """A fix was let go for doubt alone (or swapped onto a place its radius held):
        continued for ``frames`` frames."""
        self.since_doubt, self.doubt_frames = 0, frames

    def after_frame(
        self,
        *,
        let_go_for_doubt: bool,
        told: bool,
        in_stop: bool,
        was_told: bool,
        doubt_frames: int = DOUBT_FRAMES,
        search_wait: bool = False,
    ) -> None:
        """This frame's end: ``let_go_for_doubt``, the gate let a fix go for doubt alone
        on it (continued for ``doubt_frames``); ``told``, a fix is told after it;
        ``in_stop``, its estimate is in a connector's stop or between floors;
        ``was_told``, a fix was told after the frame before; ``search_wait``, the gain
        waited for nothing but a search on it (not counted out of a pinned ride's stop)."""
        if let_go_for_doubt:
            self.doubted(doubt_frames)
        elif self.since_doubt is not None:
            self.since_doubt += 1
            if told or self.since_doubt > self.doubt_frames:
                self.since_doubt = None
        if told:
            self.out_of_stop = None
            self.known_start = False
            self.pinned = False
        elif in_stop:
            if self.out_of_stop is not None or was_told:
                self.out_of_stop = 0
            if was_told:
                self.pinned = False
        elif self.out_of_stop is not None and not (self.pinned and search_wait):
            self.out_of_stop += 1
            if self.out_of_stop > STOP_EXIT_FRAMES:
                self.out_of_stop = None
                self.pinned = False

    def checkpoint(self, levels: bool) -> dict[str, Any]:
        """The filter's checkpoint keys (``out_of_stop`` on maps with several levels
        only, as before this class kept them)."""
        state: dict[str, Any] = {
            "from_known_start": self.known_start,
            "since_doubt": self.since_doubt,
            "doubt_frames": self.doubt_frames,
        }
        if levels:
            state["out_of_stop"] = self.out_of_stop
            state["pinned_exit"] = self.pinned
        return state

    def restore(self, state: Mapping[str, Any]) -> None:
        """From a filter's checkpoint (older ones lack some keys: nothing to continue)."""
        # (071f311's checkpoints kept a flag beside the count: the count stands only
        # with the flag.)
        out = state.get("out_of_stop") if state.get("fix_into_stop", True) else None
        self.out_of_stop = None if out is None else int(out)
        self.pinned = self.out_of_stop is not None and bool(state.get("pinned_exit", False))
        self.known_start = bool(state.get("from_known_start", False))
        doubt = state.get("since_doubt")
        self.since_doubt = None if doubt is None else int(doubt)
        self.doubt_frames = int(state.get("doubt_frames", DOUBT_FRAMES))
