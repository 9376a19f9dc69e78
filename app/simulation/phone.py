"""What a real phone does to the frames: every effect of issue 27, each switchable.

:func:`simulate_phone` walks the same waypoints as :func:`~app.simulation.simulator.simulate`
but the frames come from a phone held in the hand with a real detector and real
odometry. Each effect is a field of :class:`PhoneEffects` (off by default, so
``PhoneEffects()`` is the idealized person of the paper) and draws from its own random
stream, so switching one effect changes nothing the others produce. Magnitudes of the
presets (:func:`vio_phone`, :func:`pdr_phone`, :data:`EFFECT_PRESETS`) follow published
orders of magnitude:

1. **Latency** 100-300 ms between the camera's exposure and the end of the frame's
   odometry: the camera pipeline (tens of ms) plus on-device detector inference (tens
   of ms on a phone's neural accelerator, over a hundred on its CPU, in MLPerf Mobile's
   and the detectors' own published phone benchmarks) plus the app's queueing. The frame
   says ``detections_age_s`` when the app knows it (``latency_known``), or omits it.
2. **Duplicates**: a detector whose non-maximum suppression leaves two neighbouring
   boxes on one object (a door and its frame, two halves of a long table); 15 % of
   true detections in the presets, a magnitude chosen here, not a published one.
3. **Class confusion** of a few percent (the contract's default ``sensor.class_error``
   is 0.03; COCO confusion matrices of small detectors put a few percent of true
   positives in a neighbouring class).
4. **Detection probability and score falling with distance**: far objects are small in
   the image, and on COCO the small-object recall and precision of YOLO- and SSD-class
   detectors are well under those of large objects (about half or less); here half
   the objects are missed at ``detect_half_m`` (9 m) and scores fall from about 0.95
   near to about 0.5 at 15 m.
5. **Box-centre bias**: the box's centre is not the object's (a door seen obliquely, a
   table's box including its chairs): each object has a fixed bias of up to
   ``box_bias_share`` (a third) of its angular half-width, so it matters for wide objects
   seen close and vanishes far away.
6. **Dropped frames**: the app skips a frame (detector busy, thermal throttling); the
   next frame carries the motion of both; 10 % of frames in the presets (chosen here).
7. **Odometry at VIO grade** (ARKit / ARCore visual-inertial tracking: scale within
   about 2 %, heading drift about 2 deg a minute, the order found by indoor evaluations
   of phone VIO such as Feigl et al. 2020, "Localization limitations of ARCore, ARKit,
   and Hololens") or **PDR grade** (pedestrian dead reckoning from steps: step-length
   error up to about 10 % and uncorrected consumer-gyro heading drift up to about 10 deg
   a minute, the ranges of Harle 2013, "A survey of indoor inertial positioning systems
   for pedestrians"; coarser per-frame noise). Scale and drift rate are drawn once per
   walk: they are biases, not noise.
8. **Camera sway** of about +-8 deg around the walking direction at the stride
   frequency (a phone held in the hand yaws with each stride) while walking.
9. **False detections** 0.3-1 a frame (Poisson; 0.5 in the presets), random class and
   bearing in view, scores 0.3-0.7.
10. **A stale map**: the world differs from the map the filter has: objects moved by
    1-1.5 m (10 % of them), removed (5 %), or added (5 %) since it was drawn
    (:mod:`app.simulation.stale`).

The truth of a frame is the phone's pose (position and camera heading, sway included)
at the end of its odometry; the detections describe the camera ``age`` seconds earlier.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from app.localization.camera import Camera
from app.localization.types import Detection, Odometry, Pose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel, visible_objects
from app.simulation.simulator import (
    DEFAULT_OBJECT_WIDTH_M,
    OBJECT_WIDTH_M,
    SimFrame,
    SimulationConfig,
    truth_poses,
)
from app.simulation.stale import StaleMap, stale_world


@dataclass(frozen=True)
class OdometryGrade:
    """Odometry errors of one kind of phone tracking. Scale and drift are drawn once per
    walk (uniform within the bounds, either sign); the noise is per frame."""

    name: str
    #: Largest relative error of the distance moved (0.02: within 2 %).
    scale_error_max: float
    #: Largest heading drift (degrees per minute, either direction).
    drift_deg_per_min_max: float
    #: Per-frame translation noise std as a share of the distance moved then (standing
    #: still measures no motion), and rotation noise std (degrees; a gyro's random walk).
    noise_share: float
    noise_deg: float


#: ARKit / ARCore visual-inertial odometry: scale within 2 %, drift about 2 deg a minute.
VIO = OdometryGrade("vio", 0.02, 2.0, 0.03, 0.1)
#: Pedestrian dead reckoning: step length off up to 10 %, drift up to 10 deg a minute.
PDR = OdometryGrade("pdr", 0.10, 10.0, 0.15, 0.4)


@dataclass(frozen=True)
class PhoneEffects:
    """Which effects are on, and how strong. The defaults switch everything off."""

    #: Range (s) of the detections' age behind the odometry's end; None: no latency.
    latency_s: tuple[float, float] | None = None
    #: The app knows the age and sends ``detections_age_s``.
    latency_known: bool = True
    #: Probability that a true detection comes with a second, neighbouring box.
    duplicate_prob: float = 0.0
    #: Probability that a detection's class is another class of the map.
    class_confusion: float = 0.0
    #: Detection probability and score fall with distance (half missed at detect_half_m).
    range_falloff: bool = False
    detect_half_m: float = 9.0
    #: Largest box-centre bias as a share of the object's angular half-width.
    box_bias_share: float = 0.0
    #: Probability that a frame is dropped (its motion goes to the next frame).
    drop_prob: float = 0.0
    #: Odometry grade; None: the walk's own noise (``odometry_noise_m``/``_deg``), no bias.
    odometry: OdometryGrade | None = None
    #: Camera sway amplitude (degrees) around the walking direction, and its frequency.
    sway_deg: float = 0.0
    sway_hz: float = 0.9
    #: Mean false detections per frame (Poisson).
    false_rate: float = 0.0
    #: The world differs from the filter's map; None: the map is right.
    stale: StaleMap | None = None


#: One effect at a time, at the magnitudes of the issue (the suite's single-effect rows).
EFFECT_PRESETS: dict[str, PhoneEffects] = {
    "latency": PhoneEffects(latency_s=(0.1, 0.3)),
    "latency-unknown": PhoneEffects(latency_s=(0.1, 0.3), latency_known=False),
    "duplicates": PhoneEffects(duplicate_prob=0.15),
    "confusion": PhoneEffects(class_confusion=0.03),
    "range-falloff": PhoneEffects(range_falloff=True),
    "box-bias": PhoneEffects(box_bias_share=1.0 / 3.0),
    "dropped": PhoneEffects(drop_prob=0.1),
    "vio-odometry": PhoneEffects(odometry=VIO),
    "pdr-odometry": PhoneEffects(odometry=PDR),
    "sway": PhoneEffects(sway_deg=8.0),
    "false": PhoneEffects(false_rate=0.5),
    "stale-map": PhoneEffects(stale=StaleMap()),
}


def vio_phone(**overrides: object) -> PhoneEffects:
    """Every effect but the stale map, with VIO-grade odometry."""
    every = PhoneEffects(
        latency_s=(0.1, 0.3),
        duplicate_prob=0.15,
        class_confusion=0.03,
        range_falloff=True,
        box_bias_share=1.0 / 3.0,
        drop_prob=0.1,
        odometry=VIO,
        sway_deg=8.0,
        false_rate=0.5,
    )
    return replace(every, **overrides)  # type: ignore[arg-type]


def pdr_phone(**overrides: object) -> PhoneEffects:
    """Every effect but the stale map, with PDR-grade odometry."""
    return vio_phone(odometry=PDR, **overrides)


@dataclass(frozen=True)
class PhoneFrame(SimFrame):
    """A simulated phone frame: a :class:`SimFrame` plus the detections' age."""

    #: What the frame tells the service (s), None when the app does not know it.
    detections_age_s: float | None = None
    #: The true age of the detections (s), known or not.
    true_age_s: float = 0.0
    #: Frames dropped just before this one (their motion is in this one's odometry).
    dropped_before: int = 0
    #: Per detection: the map index of the object it came from, -1 for a false one.
    sources: tuple[int, ...] = field(default=())

    def to_contract(self, camera: Camera | None = None) -> dict[str, object]:
        """The ``Frame`` JSON of docs/API.md, with ``detections_age_s`` when known."""
        out = super().to_contract(camera)
        if self.detections_age_s is not None:
            out["detections_age_s"] = self.detections_age_s
        return out


#: Order of the random streams (a new effect goes at the end: seeds keep their worlds).
_STREAMS = (
    "sway",
    "latency",
    "odometry",
    "drop",
    "miss",
    "bearing",
    "bias",
    "confusion",
    "duplicate",
    "false",
    "order",
    "stale",
    "score",
)


def phone_streams(rng: np.random.Generator) -> dict[str, np.random.Generator]:
    """One random stream per effect, spawned from ``rng`` (:func:`phone_frames` draws
    from them)."""
    return dict(zip(_STREAMS, rng.spawn(len(_STREAMS)), strict=True))


def _camera_model(walk: SimulationConfig) -> CameraModel:
    if walk.camera is not None:
        return CameraModel(walk.camera.fov_deg, walk.max_range_m, walk.camera.fov_centre_deg)
    return CameraModel(walk.fov_deg, walk.max_range_m)


def _phone_poses(
    walk: SimulationConfig,
    semantic_map: SemanticMap,
    effects: PhoneEffects,
    rng: np.random.Generator,
    facing_deg: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Per tick: the phone's pose (x, y, camera heading) shape (T, 3), blocked, carried.

    A one-point path is a person standing there facing ``facing_deg`` for
    ``walk.duration_s`` seconds."""
    if len(walk.path) == 1:
        if walk.duration_s is None:
            raise ValueError("a one-point path (standing still) needs duration_s")
        n = round(walk.duration_s * walk.rate_hz) + 1
        x, y = walk.path[0]
        stand = Pose(float(x), float(y), float(np.radians(facing_deg)))
        ticks = [(stand, False, False)] * n
    else:
        ticks = truth_poses(walk, semantic_map)
    xyz = np.array([[p.x, p.y, p.theta_rad] for p, _, _ in ticks], dtype=np.float64)
    blocked = np.array([b for _, b, _ in ticks], dtype=bool)
    carried = np.array([c for _, _, c in ticks], dtype=bool)
    add_sway(xyz, walk.rate_hz, effects, rng)
    return xyz, blocked, carried


def add_sway(
    xyz: NDArray[np.float64],
    rate_hz: float,
    effects: PhoneEffects,
    rng: np.random.Generator,
    striding: NDArray[np.bool_] | None = None,
) -> None:
    """Turn the camera headings ``xyz[:, 2]`` (in place) by the hand's sway at the stride
    frequency, on the ticks the phone moved (and, given ``striding``, where it is true:
    a person standing on an escalator moves without striding)."""
    if effects.sway_deg > 0.0 and len(xyz) > 1:
        t = np.arange(len(xyz)) / rate_hz
        phase = rng.uniform(0.0, 2.0 * np.pi)
        walking = np.zeros(len(xyz), dtype=bool)
        walking[1:] = np.hypot(*np.diff(xyz[:, :2], axis=0).T) > 1e-9
        if striding is not None:
            walking &= striding
        sway = np.radians(effects.sway_deg) * np.sin(2.0 * np.pi * effects.sway_hz * t + phase)
        xyz[:, 2] = wrap_angle(xyz[:, 2] + np.where(walking, sway, 0.0))


def _pose_at(xyz: NDArray[np.float64], tick: float) -> Pose:
    """The phone's pose at a fractional tick (linear in position and heading)."""
    tick = min(max(tick, 0.0), len(xyz) - 1.0)
    i = min(int(np.floor(tick)), len(xyz) - 2) if len(xyz) > 1 else 0
    if len(xyz) == 1:
        return Pose(float(xyz[0, 0]), float(xyz[0, 1]), float(xyz[0, 2]))
    f = tick - i
    a, b = xyz[i], xyz[i + 1]
    theta = a[2] + f * float(wrap_angle(b[2] - a[2]))
    return Pose(
        float(a[0] + f * (b[0] - a[0])), float(a[1] + f * (b[1] - a[1])), float(wrap_angle(theta))
    )


def _increments(
    xyz: NDArray[np.float64],
    walk: SimulationConfig,
    effects: PhoneEffects,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """Measured motion per tick (forward, left, turn) in the previous tick's frame, (T, 3);
    row 0 is unused."""
    d = np.diff(xyz[:, :2], axis=0)
    c, s = np.cos(xyz[:-1, 2]), np.sin(xyz[:-1, 2])
    fwd = c * d[:, 0] + s * d[:, 1]
    left = -s * d[:, 0] + c * d[:, 1]
    turn = wrap_angle(np.diff(xyz[:, 2]))
    n = len(fwd)
    grade = effects.odometry
    if grade is None:
        scale, drift = 1.0, 0.0
        noise_m = np.full(n, walk.odometry_noise_m)
        noise_rad = np.radians(walk.odometry_noise_deg)
    else:
        scale = 1.0 + rng.uniform(-grade.scale_error_max, grade.scale_error_max)
        drift = np.radians(rng.uniform(-1.0, 1.0) * grade.drift_deg_per_min_max) / 60.0
        noise_m = grade.noise_share * np.hypot(fwd, left)
        noise_rad = np.radians(grade.noise_deg)
    dt = 1.0 / walk.rate_hz
    out = np.zeros((n + 1, 3))
    out[1:, 0] = scale * fwd + rng.normal(0.0, noise_m, n)
    out[1:, 1] = scale * left + rng.normal(0.0, noise_m, n)
    out[1:, 2] = turn + drift * dt + rng.normal(0.0, noise_rad, n)
    return out


def _compose(increments: NDArray[np.float64]) -> Odometry:
    """Several motions in a row as one, in the first one's starting frame."""
    x = y = th = 0.0
    for fwd, left, turn in increments:
        x += np.cos(th) * fwd - np.sin(th) * left
        y += np.sin(th) * fwd + np.cos(th) * left
        th += turn
    return Odometry(float(x), float(y), float(wrap_angle(th)))


def _width_rad(cls: str, distance_m: float) -> float:
    """The angular width (radians) of an object of class ``cls`` this far away."""
    size = OBJECT_WIDTH_M.get(cls, DEFAULT_OBJECT_WIDTH_M)
    return float(2.0 * np.arctan2(size / 2.0, max(distance_m, 0.3)))


def detect_probability(distance_m: NDArray[np.float64], half_m: float) -> NDArray[np.float64]:
    """Chance that a detector finds an object this far away: 0.95 near, half at ``half_m``."""
    return 0.95 / (1.0 + (distance_m / half_m) ** 3)


def _detections(
    world: SemanticMap,
    pose: Pose,
    blocked: bool,
    walk: SimulationConfig,
    camera: CameraModel,
    effects: PhoneEffects,
    bias_share: NDArray[np.float64],
    streams: dict[str, np.random.Generator],
) -> tuple[list[Detection], list[float], list[int]]:
    """One frame's detections, each one's angular width (deg) and source object (-1: false)."""
    idx, bearing = visible_objects(world, pose, camera)
    k = idx.size
    dist = np.hypot(*(world.object_xy[idx] - np.array([pose.x, pose.y])).T) if k else np.zeros(0)
    # Every stream draws a fixed number of values per visible object whatever the switches,
    # so one effect on or off leaves the others' draws alone.
    keep = np.ones(k, dtype=bool)
    if blocked:
        keep &= np.abs(bearing) > np.radians(walk.blocked_sector_deg) / 2.0
    miss_u = streams["miss"].random((k, 2))
    if walk.miss_prob > 0.0:
        keep &= miss_u[:, 0] >= walk.miss_prob
    p_seen = detect_probability(dist, effects.detect_half_m)
    if effects.range_falloff:
        keep &= miss_u[:, 1] < p_seen
    width = np.array(
        [_width_rad(world.class_of(int(i)), float(d)) for i, d in zip(idx, dist, strict=True)]
    )
    noise = streams["bearing"].normal(0.0, np.radians(walk.bearing_noise_deg), k)
    bias = bias_share[idx] * effects.box_bias_share * width / 2.0 if k else np.zeros(0)
    measured = wrap_angle(bearing + noise + bias)
    score_n = streams["score"].normal(0.0, 0.05, k)
    score_u = streams["score"].random(k)
    lo, hi = walk.score_range
    if effects.range_falloff:
        near = 0.35 + 0.6 / (1.0 + (dist / effects.detect_half_m) ** 2)
        score = np.clip(near + score_n, 0.05, 1.0)
    else:
        score = np.full(k, lo) if hi <= lo else lo + (hi - lo) * score_u
    conf_u = streams["confusion"].random(k)
    conf_pick = streams["confusion"].integers(0, 1 << 30, k)
    dup_u = streams["duplicate"].random((k, 3))
    classes = world.classes
    dets: list[Detection] = []
    widths: list[float] = []
    sources: list[int] = []
    for j in np.flatnonzero(keep):
        obj = int(idx[j])
        cls = world.class_of(obj)
        if conf_u[j] < effects.class_confusion and len(classes) > 1:
            others = [c for c in classes if c != cls]
            cls = others[int(conf_pick[j]) % len(others)]
        dets.append(Detection(cls, float(measured[j]), float(score[j])))
        widths.append(float(np.degrees(width[j])))
        sources.append(obj)
        if dup_u[j, 0] < effects.duplicate_prob:
            side = 1.0 if dup_u[j, 1] < 0.5 else -1.0
            shift = side * (0.3 + 0.4 * dup_u[j, 2]) * width[j] / 2.0
            dets.append(
                Detection(cls, float(wrap_angle(measured[j] + shift)), float(0.8 * score[j]))
            )
            widths.append(float(np.degrees(width[j])) * 0.6)
            sources.append(obj)
    false_rng = streams["false"]
    n_false = int(false_rng.poisson(effects.false_rate)) if effects.false_rate > 0 else 0
    half = np.radians(min(camera.fov_deg, 360.0)) / 2.0
    centre = np.radians(camera.fov_centre_deg)
    for _ in range(n_false):
        cls = classes[int(false_rng.integers(len(classes)))]
        b = float(wrap_angle(centre + false_rng.uniform(-half, half)))
        dets.append(Detection(cls, b, float(false_rng.uniform(0.3, 0.7))))
        widths.append(float(false_rng.uniform(5.0, 30.0)))
        sources.append(-1)
    order = streams["order"].permutation(len(dets))
    return (
        [dets[i] for i in order],
        [widths[i] for i in order],
        [sources[i] for i in order],
    )


def simulate_phone(
    semantic_map: SemanticMap,
    walk: SimulationConfig,
    effects: PhoneEffects,
    rng: np.random.Generator,
    *,
    facing_deg: float = 0.0,
) -> list[PhoneFrame]:
    """Frames of one walk as a phone would send them (plus the truth).

    ``walk`` gives the path, speed, rate, field of view (or ``camera``), bearing noise,
    independent misses (``miss_prob``) and blocked intervals; its ``false_rate``,
    ``random_loss``, kidnap and compass are not used here (``effects.false_rate`` gives
    the false detections). A one-point path stands still, facing ``facing_deg``, for
    ``walk.duration_s``. The first frame, and a frame right after a kidnap, carry no
    odometry.
    """
    streams = phone_streams(rng)
    world = semantic_map
    if effects.stale is not None:
        world = stale_world(semantic_map, effects.stale, streams["stale"])
    xyz, blocked, carried = _phone_poses(walk, semantic_map, effects, streams["sway"], facing_deg)
    return phone_frames(world, xyz, blocked, carried, walk, effects, streams)


def phone_frames(
    world: SemanticMap,
    xyz: NDArray[np.float64],
    blocked: NDArray[np.bool_],
    carried: NDArray[np.bool_],
    walk: SimulationConfig,
    effects: PhoneEffects,
    streams: dict[str, np.random.Generator],
    plane_x: NDArray[np.float64] | None = None,
) -> list[PhoneFrame]:
    """The frames a phone sends from the phone's true poses, one per tick of ``walk``'s
    rate: ``xyz`` (T, 3), sway included (:func:`add_sway`), in the frame the odometry
    measures in, with whether the view is blocked and whether the person was just carried
    there (no odometry) per tick; ``streams`` from :func:`phone_streams`.

    ``plane_x``: on a map with levels, per tick the plane x offset of the level the phone
    is on (:meth:`~app.maps.levels.LevelLayout.offsets`): the camera sees, and the truth
    is, in the plane, while the odometry never sees an offset. A dropped frame's tick is
    missing from the result (``frame.t * walk.rate_hz`` gives a frame's tick).
    """
    camera = _camera_model(walk)
    steps = _increments(xyz, walk, effects, streams["odometry"])
    n = len(xyz)
    lat = streams["latency"]
    base_age = lat.uniform(*effects.latency_s) if effects.latency_s is not None else 0.0
    jitter = lat.uniform(-0.03, 0.03, n)
    drop_u = streams["drop"].random(n)
    bias_share = streams["bias"].uniform(-1.0, 1.0, world.object_count)
    dt = 1.0 / walk.rate_hz

    def shifted(pose: Pose, tick: float) -> Pose:
        if plane_x is None:
            return pose
        k = min(max(round(tick), 0), n - 1)
        return Pose(pose.x + float(plane_x[k]), pose.y, pose.theta_rad)

    frames: list[PhoneFrame] = []
    last = 0
    for i in range(n):
        if i > 0 and not carried[i] and i < n - 1 and drop_u[i] < effects.drop_prob:
            continue  # dropped: its motion goes to the next frame sent
        age = 0.0
        if effects.latency_s is not None:
            lo, hi = effects.latency_s
            age = round(float(np.clip(base_age + jitter[i], lo, hi)), 3)
        seen_tick = i - age / dt
        seen_at = shifted(_pose_at(xyz, seen_tick), seen_tick)
        dets, widths, sources = _detections(
            world, seen_at, bool(blocked[i]), walk, camera, effects, bias_share, streams
        )
        odo = None if i == 0 or carried[i] else _compose(steps[last + 1 : i + 1])
        truth = shifted(Pose(float(xyz[i, 0]), float(xyz[i, 1]), float(xyz[i, 2])), i)
        known = effects.latency_s is not None and effects.latency_known
        frames.append(
            PhoneFrame(
                t=round(i * dt, 6),
                truth=truth,
                odometry=odo,
                detections=dets,
                blocked=bool(blocked[i]),
                widths_deg=tuple(widths),
                detections_age_s=age if known else None,
                true_age_s=age,
                dropped_before=i - last - 1 if i > 0 else 0,
                sources=tuple(sources),
            )
        )
        last = i
    return frames
