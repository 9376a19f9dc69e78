"""`bearings experiments --suite venue`: a walk through three floors by lift, stairs and escalator.

The venue (:mod:`app.simulation.venue`, 24 m x 14 m floors joined by a lift, stairs and
two escalators) is walked from a global start on the Ground Floor: the hall, the lift
up two floors, the Second Floor, the stairs down, the First Floor, the escalator down,
the Ground Floor, the escalator up, the First Floor's office (about 6 minutes at
0.5 m/s, 5 frames/s). The camera sees 360 deg, misses 10 % of what is in view and
reports 0.2 false detections a frame; the barometer drifts (a random offset, a rate
of up to 0.6 m a minute and a random walk) with 0.25 m of noise a reading.

Conditions: with the barometer (``Frame.altitude``), and without it; and with it on a
poorer phone (30 % of what is in view missed, 0.5 false detections a frame, 0.4 m of
barometer noise). These three give an idealized detector and near-exact odometry to the
library's default filter. ``phone-vio`` is the walk as a real phone sends it: every
effect of :func:`~app.simulation.phone.vio_phone` (latency 0.1-0.3 s announced,
duplicates 15 %, class confusion 3 %, detection falling with distance, box-centre bias,
10 % dropped frames, VIO odometry's scale and drift, +-8 deg of sway while striding, 0.5
false detections a frame; :func:`~app.simulation.venue_walk.simulate_venue_phone`) with
the barometer, through a filter configured as the service configures a session with
``odometry.source: vio`` (:func:`app.service.sessions.filter_config`), for the venue and
for the one-level maps alike; ``phone-vio-180`` and ``phone-vio-66`` are that phone with
a camera of 180 and 66 degrees (a phone held in the hand) instead of 360;
``phone-pdr-180`` and ``phone-pdr-66`` the same phone with step-counting (PDR)
odometry, its session configured with ``odometry.source: pdr``.

Figures, pooled over the seeds:

* **level right**: share of converged frames whose level is the true one;
* **confidently wrong**: converged frames more than 1 m from the truth or on another
  level (a wrong level is a wrong position);
* **level confirmed after a ride**: for each ride, the time from leaving the connector
  (the end of the ride, door wait included) to the first frame from the ride's start on
  that confirms the new level (the level the feedback announces,
  :meth:`~app.localization.floors.FloorTracker.after_estimate`: a converged fix on it,
  or the barometer's count of storeys from a fix, once the belief agrees; 0 when it was
  confirmed before the person left); the share within 5 s;
* **wrong level confirmed**: frames confirming a level other than the person's (each
  would be a wrong "You are on ..." or a wrong fix): never expected;
* **located after a ride**: the same time to the first converged frame on the new
  level within 1 m of the truth (the place on it, not only the floor);
* **availability per level**: share of a level's walking frames that are converged
  and right (within 1 m, on the level), against the same frames given to a filter on
  that level alone (a map of that level only, a one-level map): with a known start at
  the leg's first pose, as the venue's filter had the person localized before the
  ride; the first leg from a global start in both;
* **availability once located** (like with like): the same share over the frames of
  each walking leg from the later of the two filters' first fixes in it on, the same
  frames for both. The one-level filter is told the floor; the venue's, from a global
  start, is not, and spreads the same particles over every floor (three times fewer a
  floor here), so it takes longer to its first fix: that cost is the **first fix**
  figure (seconds from a leg's first frame to its first right frame), kept apart.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.bench import machine_line
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.types import Estimate, InitialPose
from app.maps.model import SemanticMap, parse_map
from app.simulation.phone import PhoneEffects, pdr_phone, vio_phone
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import VENUE_NAME, venue_legs, venue_map, venue_spec
from app.simulation.venue_walk import (
    Barometer,
    Leg,
    Ride,
    VenueFrame,
    simulate_venue,
    simulate_venue_phone,
)

#: Converged frames this far off (m), or on another level, are confidently wrong.
WRONG_M = 1.0
#: A level change is to be confirmed within this long after leaving a connector (s).
CONFIRM_S = 5.0
#: Frames a second the walks are sent at unless told (``--rate-hz``).
RATE_HZ = 5.0


@dataclass(frozen=True)
class Condition:
    """Whether the frames carry the barometer's altitude, and the detector and barometer
    the walk is simulated with; with ``phone``, a real phone's effects on the frames
    (its ``false_rate`` replaces ``false_rate``) and a filter configured as the service's."""

    barometer: bool
    miss_prob: float = 0.1
    false_rate: float = 0.2
    barometer_noise_m: float = Barometer().noise_m
    phone: PhoneEffects | None = None
    #: The camera's field of view (degrees, centred on the heading).
    fov_deg: float = 360.0


CONDITIONS: dict[str, Condition] = {
    "barometer": Condition(True),
    "no-barometer": Condition(False),
    # A poorer phone: a third of what is in view missed, more false detections, a
    # noisier barometer (a reality check of the thresholds tuned on the first two).
    "barometer-poor-detector": Condition(
        True, miss_prob=0.3, false_rate=0.5, barometer_noise_m=0.4
    ),
    # A real phone with visual-inertial tracking (the phone suite's vio-360: its misses
    # are the detector's falling with distance), a service session's filter.
    "phone-vio": Condition(True, miss_prob=0.0, phone=vio_phone()),
    # The same phone held in the hand: a camera of 180 deg, and of 66 deg (most phones).
    "phone-vio-180": Condition(True, miss_prob=0.0, phone=vio_phone(), fov_deg=180.0),
    "phone-vio-66": Condition(True, miss_prob=0.0, phone=vio_phone(), fov_deg=66.0),
    # The phones whose tracking counts steps (pedestrian dead reckoning).
    "phone-pdr-180": Condition(True, miss_prob=0.0, phone=pdr_phone(), fov_deg=180.0),
    "phone-pdr-66": Condition(True, miss_prob=0.0, phone=pdr_phone(), fov_deg=66.0),
}


@dataclass(frozen=True)
class LegAvailability:
    """One walking leg: frames right for the venue's filter and the one-level filter,
    over the whole leg and over the frames from both filters' first fixes on.

    The one-level filter starts a leg after a ride at the person's pose (0.3 m, 10 deg),
    which the venue's filter knows only when it was located as the ride began: the bar
    to meet. ``one_global_right`` counts a second one-level filter started with no
    knowledge (what that floor's map alone gives a person arriving by lift or stairs);
    on a leg that begins the walk both are the same filter."""

    level: int
    frames: int
    venue_right: int
    one_right: int
    #: Seconds from the leg's first frame to each filter's first right frame (inf: none).
    venue_first_fix_s: float
    one_first_fix_s: float
    #: Frames from the later first fix on, and how many of them each filter had right.
    located_frames: int
    venue_right_located: int
    one_right_located: int
    #: Whether the leg began with a global start (else after a ride).
    global_start: bool
    #: Frames right for a one-level filter started with no knowledge (global start).
    one_global_right: int


@dataclass
class VenueRun:
    """One seed of one condition: per frame the truth, the estimate and its level."""

    condition: str
    seed: int
    t: np.ndarray
    level: np.ndarray  # true level index
    est_level: np.ndarray
    err_m: np.ndarray  # plane distance (a wrong level is tens of metres)
    converged: np.ndarray
    leg: np.ndarray
    riding: np.ndarray
    #: Per ride: (kind, end time s, to level, level confirmed s, located s; inf: never).
    rides: list[tuple[str, float, int, float, float]]
    #: Frames confirming a level other than the person's.
    wrong_level_confirmed: int
    legs: list[LegAvailability]
    step_ms: np.ndarray


def leg_availability(
    level: int,
    t: np.ndarray,
    venue_right: np.ndarray,
    one_right: np.ndarray,
    global_start: bool,
    one_global_right: np.ndarray | None = None,
) -> LegAvailability:
    """:class:`LegAvailability` of one walking leg from its frames' times and, per
    frame, whether each filter was converged and right (``one_global_right``: the
    one-level filter started with no knowledge; None: ``one_right``'s is one)."""
    one_global = one_right if one_global_right is None else one_global_right

    def first(right: np.ndarray) -> int | None:
        hits = np.flatnonzero(right)
        return int(hits[0]) if hits.size else None

    fv, fo = first(venue_right), first(one_right)
    start = max(fv, fo) if fv is not None and fo is not None else t.size
    return LegAvailability(
        level=level,
        frames=int(t.size),
        venue_right=int(venue_right.sum()),
        one_right=int(one_right.sum()),
        venue_first_fix_s=float(t[fv] - t[0]) if fv is not None else float("inf"),
        one_first_fix_s=float(t[fo] - t[0]) if fo is not None else float("inf"),
        located_frames=int(t.size - start),
        venue_right_located=int(venue_right[start:].sum()),
        one_right_located=int(one_right[start:].sum()),
        global_start=global_start,
        one_global_right=int(one_global.sum()),
    )


def single_level_map(level_id: str) -> SemanticMap:
    """The venue's level ``level_id`` alone, as a map file without levels."""
    spec = venue_spec()
    keep = {
        key: [
            {k: v for k, v in item.items() if k != "level"}
            for item in spec[key]  # type: ignore[attr-defined]
            if item["level"] == level_id
        ]
        for key in ("walls", "objects", "regions")
    }
    return parse_map({"name": f"venue-{level_id}", **keep})


def _walk(
    seed: int, cond: Condition, rate_hz: float | None = None
) -> tuple[SemanticMap, list[VenueFrame], list[Leg]]:
    m = venue_map()
    start, legs = venue_legs()
    cfg = SimulationConfig(
        path=((0.0, 0.0),),
        miss_prob=cond.miss_prob,
        false_rate=cond.false_rate,
        fov_deg=cond.fov_deg,
        rate_hz=RATE_HZ if rate_hz is None else rate_hz,
    )
    baro = Barometer(noise_m=cond.barometer_noise_m)
    rng = np.random.default_rng(seed)
    if cond.phone is not None:
        frames = simulate_venue_phone(m, start, legs, cfg, cond.phone, rng, baro)
    else:
        frames = simulate_venue(m, start, legs, cfg, rng, baro)
    return m, frames, legs


def filter_config(cond: Condition, particles: int) -> FilterConfig:
    """The library's default filter, or for a real phone the service's session filter
    for the phone's odometry source."""
    if cond.phone is None:
        return FilterConfig(particles=particles)
    from app.service.sessions import filter_config as session_filter_config
    from app.service.types import SensorSpec, SessionSpec

    grade = cond.phone.odometry
    source = grade.name if grade is not None else "unknown"
    spec = SessionSpec(
        map_name=VENUE_NAME, odometry_source=source, sensor=SensorSpec(fov_deg=cond.fov_deg)
    )
    return session_filter_config(spec, particles)


def step(
    pf: ParticleFilter,
    vf: VenueFrame,
    prev_t: float | None,
    *,
    first: bool = False,
    barometer: bool,
) -> Estimate:
    """One frame through the filter as a session steps it (the detections' age when the
    phone gives it, the time since the previous frame); ``first``: without odometry."""
    f = vf.frame
    age = getattr(f, "detections_age_s", None)
    return pf.step(
        None if first else f.odometry,
        f.detections,
        altitude=vf.altitude if barometer else None,
        detections_age_s=age or 0.0,
        frame_s=None if prev_t is None else f.t - prev_t,
    )


def run_condition(
    condition: str,
    seed: int,
    particles: int,
    on_step: Callable[[ParticleFilter, VenueFrame, Estimate], None] | None = None,
    alter: Callable[[list[VenueFrame]], list[VenueFrame]] | None = None,
    rate_hz: float | None = None,
) -> VenueRun:
    """One walk of ``condition`` through the venue's filter (and, leg by leg, through
    each level's own map); ``on_step(filter, frame, estimate)`` after each of the
    venue filter's frames (a tool's look at its state, e.g. ``tools/odometry_scale.py``);
    ``alter`` changes the simulated frames first, one for one (effects the simulator
    was not built with, ``tools/venue_gaps.py``); ``rate_hz`` the frames a second the
    phone sends (default :data:`RATE_HZ`)."""
    cond = CONDITIONS[condition]
    m, frames, legs = _walk(seed, cond, rate_hz)
    if alter is not None:
        walked = len(frames)
        frames = alter(frames)
        if len(frames) != walked:
            raise ValueError(f"alter must keep the walk's {walked} frames, one for one")
    barometer = cond.barometer
    config = filter_config(cond, particles)
    pf = ParticleFilter(m, config, rng=np.random.default_rng(seed + 1))
    n = len(frames)
    est_level = np.zeros(n, dtype=np.int64)
    err = np.zeros(n)
    conv = np.zeros(n, dtype=bool)
    step_ms = np.zeros(n)
    # Per frame, the level this step confirmed (-1: none).
    confirmed = np.full(n, -1, dtype=np.int64)
    for i, vf in enumerate(frames):
        f = vf.frame
        started = time.perf_counter()
        est = step(pf, vf, frames[i - 1].frame.t if i else None, barometer=barometer)
        step_ms[i] = (time.perf_counter() - started) * 1e3
        if on_step is not None:
            on_step(pf, vf, est)
        est_level[i] = m.layout.level_of(est.x)
        err[i] = float(np.hypot(est.x - f.truth.x, est.y - f.truth.y))
        conv[i] = est.converged
        floors = pf.floors
        if floors is not None and floors.confirmed_now and floors.confirmed_level is not None:
            confirmed[i] = floors.confirmed_level
    t = np.array([vf.frame.t for vf in frames])
    level = np.array([vf.level for vf in frames])
    leg = np.array([vf.leg for vf in frames])
    riding = np.array([vf.riding for vf in frames])
    right = conv & (est_level == level) & (err <= WRONG_M)
    rides = []
    for k, spec in enumerate(legs):
        if not isinstance(spec, Ride):
            continue
        ride_i = np.flatnonzero(leg == k)
        start_i, end_i = int(ride_i[0]), int(ride_i[-1])
        to = m.layout.level_index(spec.to_level)
        # The first frame from the ride's start confirming the new level (during the
        # door wait: 0), and the first from its last frame on converged and right there.
        said = np.flatnonzero(confirmed[start_i:] == to)
        level_s = max(float(t[start_i + said[0]] - t[end_i]), 0.0) if said.size else math.inf
        ok = np.flatnonzero(right[end_i:] & (level[end_i:] == to))
        located_s = float(t[end_i + ok[0]] - t[end_i]) if ok.size else math.inf
        rides.append((spec.kind, float(t[end_i]), to, level_s, located_s))
    leg_rows = []
    for k, spec in enumerate(legs):
        if isinstance(spec, Ride):
            continue
        idx = np.flatnonzero(leg == k)
        lv = int(level[idx[0]])
        single = single_level_map(m.layout.levels[lv].id)
        first = frames[idx[0]].file_pose
        known = None if k == 0 else InitialPose(first.x, first.y, first.theta_rad, 0.3, 0.17)
        starts = [known] if known is None else [known, None]
        one_rights = []
        for n, start in enumerate(starts):
            rng = np.random.default_rng(seed + 2 + k + 100 * n)
            one = ParticleFilter(single, config, rng=rng, initial_pose=start)
            one_right = np.zeros(idx.size, dtype=bool)
            for i, j in enumerate(idx.tolist()):
                prev_t = None if j == idx[0] else frames[j - 1].frame.t
                est = step(one, frames[j], prev_t, first=j == idx[0], barometer=False)
                fp = frames[j].file_pose
                close = float(np.hypot(est.x - fp.x, est.y - fp.y)) <= WRONG_M
                one_right[i] = est.converged and close
            one_rights.append(one_right)
        leg_rows.append(
            leg_availability(lv, t[idx], right[idx], one_rights[0], known is None, one_rights[-1])
        )
    wrong_said = int(np.sum((confirmed >= 0) & (confirmed != level)))
    return VenueRun(
        condition,
        seed,
        t,
        level,
        est_level,
        err,
        conv,
        leg,
        riding,
        rides,
        wrong_said,
        leg_rows,
        step_ms,
    )


def _job(args: tuple[str, int, int, float | None]) -> VenueRun:
    condition, seed, particles, rate_hz = args
    return run_condition(condition, seed, particles, rate_hz=rate_hz)


def summarize(runs: list[VenueRun]) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    names = [lv.name for lv in venue_map().layout.levels]
    for condition in CONDITIONS:
        mine = [r for r in runs if r.condition == condition]
        if not mine:
            continue
        conv = np.concatenate([r.converged for r in mine])
        lvl_ok = np.concatenate([r.est_level == r.level for r in mine])
        err = np.concatenate([r.err_m for r in mine])
        wrong = conv & (~lvl_ok | (err > WRONG_M))
        rides = [ride for r in mine for ride in r.rides]
        confirm = np.array([ride[3] for ride in rides])
        located = np.array([ride[4] for ride in rides])
        by_kind = {}
        for kind in sorted({k for k, *_ in rides}):
            c = np.array([ride[3] for ride in rides if ride[0] == kind])
            p = np.array([ride[4] for ride in rides if ride[0] == kind])
            c_median, c_max, c_within = _ride_times(c)
            p_median, p_max, p_within = _ride_times(p)
            by_kind[kind] = {
                "rides": int(c.size),
                "median_s": c_median,
                "max_s": c_max,
                "within_5s": c_within,
                "located_median_s": p_median,
                "located_max_s": p_max,
                "located_within_5s": p_within,
            }
        confirm_median, confirm_max, confirm_within = _ride_times(confirm)
        located_median, located_max, located_within = _ride_times(located)
        per_level = {
            name: _availability([g for r in mine for g in r.legs if g.level == lv])
            for lv, name in enumerate(names)
        }
        all_legs = [g for r in mine for g in r.legs]
        first_fix = {
            start: _first_fix([g for g in all_legs if g.global_start == (start == "global start")])
            for start in ("global start", "after a ride")
        }
        rows.append(
            {
                "condition": condition,
                "seeds": len(mine),
                "frames": int(conv.size),
                "converged_frames": int(conv.sum()),
                "level_right_share": float(lvl_ok[conv].mean()) if conv.any() else float("nan"),
                "wrong_level_frames": int(np.sum(conv & ~lvl_ok)),
                "confidently_wrong_frames": int(wrong.sum()),
                "rides": int(confirm.size),
                "confirmed_within_5s": confirm_within,
                "median_confirm_s": confirm_median,
                "max_confirm_s": confirm_max,
                "wrong_level_confirmed_frames": sum(r.wrong_level_confirmed for r in mine),
                "located_within_5s": located_within,
                "median_located_s": located_median,
                "max_located_s": located_max,
                "by_kind": by_kind,
                "availability": per_level,
                "first_fix": first_fix,
                "median_step_ms": float(np.median(np.concatenate([r.step_ms for r in mine]))),
            }
        )
    return rows


def _ride_times(seconds: np.ndarray) -> tuple[float, float, int]:
    """Median and maximum of the seconds after rides, and how many are within
    ``CONFIRM_S``."""
    return (
        float(np.median(seconds)),
        float(np.max(seconds)),
        int(np.sum(seconds <= CONFIRM_S)),
    )


def _share(right: int, frames: int) -> float:
    return right / frames if frames else float("nan")


def _availability(legs: list[LegAvailability]) -> dict[str, float | int]:
    """One level's availability, venue and one-level: over every walking frame and
    over the frames both filters had had their first fix (like with like)."""
    frames = sum(g.frames for g in legs)
    located = sum(g.located_frames for g in legs)
    return {
        "frames": frames,
        "venue": _share(sum(g.venue_right for g in legs), frames),
        "one_level": _share(sum(g.one_right for g in legs), frames),
        "one_level_global": _share(sum(g.one_global_right for g in legs), frames),
        "located_frames": located,
        "venue_located": _share(sum(g.venue_right_located for g in legs), located),
        "one_level_located": _share(sum(g.one_right_located for g in legs), located),
    }


def _first_fix(legs: list[LegAvailability]) -> dict[str, float | int]:
    """Seconds to the first fix of a leg, venue and one-level: median and max."""
    venue = np.array([g.venue_first_fix_s for g in legs])
    one = np.array([g.one_first_fix_s for g in legs])
    return {
        "legs": len(legs),
        "venue_median_s": float(np.median(venue)),
        "venue_max_s": float(np.max(venue)),
        "one_level_median_s": float(np.median(one)),
        "one_level_max_s": float(np.max(one)),
    }


def _f(v: float, fmt: str) -> str:
    return "never" if v == float("inf") else ("n/a" if v != v else format(v, fmt))


def markdown_table(rows: list[dict[str, object]]) -> str:
    lines = [
        "| condition | converged frames | level right | wrong-level frames | confidently "
        "wrong | level confirmed <= 5 s after a ride | median / max (s) | wrong level "
        "confirmed | located <= 5 s after a ride | median / max (s) | step (ms, median) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['condition']} | {r['converged_frames']:,} of {r['frames']:,} | "
            f"{100 * float(r['level_right_share']):.2f} % | {r['wrong_level_frames']} | "  # type: ignore[arg-type]
            f"{r['confidently_wrong_frames']} | {r['confirmed_within_5s']} of {r['rides']} | "
            f"{_f(float(r['median_confirm_s']), '.1f')} / {_f(float(r['max_confirm_s']), '.1f')} | "  # type: ignore[arg-type]
            f"{r['wrong_level_confirmed_frames']} | {r['located_within_5s']} of {r['rides']} | "
            f"{_f(float(r['median_located_s']), '.1f')} / {_f(float(r['max_located_s']), '.1f')} | "  # type: ignore[arg-type]
            f"{float(r['median_step_ms']):.2f} |"  # type: ignore[arg-type]
        )
    return "\n".join(lines)


def markdown(
    rows: list[dict[str, object]],
    *,
    seconds: float,
    particles: int,
    seeds: int,
    first_seed: int = 0,
    rate_hz: float = RATE_HZ,
) -> str:
    command = "bearings experiments --suite venue"
    counted = f"{seeds} seeds per condition"
    if first_seed:
        command += f" --first-seed {first_seed} --seeds {seeds}"
        counted += f", {first_seed} to {first_seed + seeds - 1}"
    if rate_hz != RATE_HZ:
        command += f" --rate-hz {rate_hz:g}"
    counted += f", {rate_hz:g} frames/s"
    out = [
        "# Venue suite: three floors, lift, stairs and escalators",
        "",
        f"`{command}` ({counted}, {particles:,} "
        f"particles, {seconds:.0f} s). The walk, the venue and the definitions are in "
        "`app/experiments/venue.py`; every number below comes from that run.",
        "",
        machine_line(),
        "",
        markdown_table(rows),
        "",
        "## Confirming the level after each ride",
        "",
        "The level (what the feedback announces) and the place on it (converged and "
        "right), seconds after leaving the connector.",
        "",
        "| condition | connector | rides | level confirmed <= 5 s | median / max (s) | "
        "located <= 5 s | median / max (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for kind, k in r["by_kind"].items():  # type: ignore[attr-defined]
            out.append(
                f"| {r['condition']} | {kind} | {k['rides']} | {k['within_5s']} | "
                f"{_f(k['median_s'], '.1f')} / {_f(k['max_s'], '.1f')} | "
                f"{k['located_within_5s']} | "
                f"{_f(k['located_median_s'], '.1f')} / {_f(k['located_max_s'], '.1f')} |"
            )
    out += [
        "",
        "## Availability per level (walking frames converged and right)",
        "",
        "Every walking frame, and (like with like) the frames of each leg from the later "
        "of the two filters' first fixes in it on: the same frames for both. The level "
        "alone (one-level map) starts each leg after a ride at the person's pose (0.3 m, "
        "10 deg), as the venue's filter knows it only if it was located as the ride "
        "began: the bar. The same map started with no knowledge, what that floor's map "
        "alone gives a person arriving by lift or stairs, is shown beside it (the first "
        "leg starts so in both).",
        "",
        "| condition | level | frames | venue | that level alone (one-level map) | "
        "one-level map, no known start | frames once both located | venue | "
        "one-level map |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for name, a in r["availability"].items():  # type: ignore[attr-defined]
            out.append(
                f"| {r['condition']} | {name} | {a['frames']:,} | {100 * a['venue']:.1f} % | "
                f"{100 * a['one_level']:.1f} % | {100 * a['one_level_global']:.1f} % | "
                f"{a['located_frames']:,} | "
                f"{100 * a['venue_located']:.1f} % | {100 * a['one_level_located']:.1f} % |"
            )
    out += [
        "",
        "## First fix of a walking leg (s from its first frame to its first right frame)",
        "",
        "| condition | leg starts with | legs | venue median / max | one-level median / max |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        for start, k in r["first_fix"].items():  # type: ignore[attr-defined]
            out.append(
                f"| {r['condition']} | {start} | {k['legs']} | "
                f"{_f(k['venue_median_s'], '.1f')} / {_f(k['venue_max_s'], '.1f')} | "
                f"{_f(k['one_level_median_s'], '.1f')} / {_f(k['one_level_max_s'], '.1f')} |"
            )
    return "\n".join(out) + "\n"


def run(
    out: Path,
    *,
    seeds: int,
    particles: int,
    workers: int,
    first_seed: int = 0,
    rate_hz: float | None = None,
) -> list[dict[str, object]]:
    """Run every condition for ``seeds`` seeds from ``first_seed`` on, the phone sending
    ``rate_hz`` frames a second (default :data:`RATE_HZ`); write venue.md and venue.json
    to ``out``."""
    from app.experiments.runner import map_jobs

    seed_range = range(first_seed, first_seed + seeds)
    jobs = [(c, s, particles, rate_hz) for c in CONDITIONS for s in seed_range]
    started = time.perf_counter()
    runs = map_jobs(_job, jobs, workers)
    seconds = time.perf_counter() - started
    rows = summarize(runs)
    out.mkdir(parents=True, exist_ok=True)
    (out / "venue.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    (out / "venue.md").write_text(
        markdown(
            rows,
            seconds=seconds,
            particles=particles,
            seeds=seeds,
            first_seed=first_seed,
            rate_hz=RATE_HZ if rate_hz is None else rate_hz,
        ),
        encoding="utf-8",
    )
    return rows
