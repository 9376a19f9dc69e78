"""Simulate a person walking waypoints with a spherical camera and noisy odometry.

:func:`simulate` turns a :class:`SimulationConfig` into frames, each with the ground
truth, the (noisy) odometry since the previous frame in the previous body frame, and
the (noisy, faulty) detections — exactly what a phone app would send to the service.
Every fault is a parameter; the same ``rng`` seed gives the same frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.localization.camera import Camera
from app.localization.types import Detection, Odometry, Pose
from app.maps.geometry import wrap_angle
from app.maps.model import SemanticMap
from app.simulation.camera import CameraModel, visible_objects

#: Plausible widths of objects (metres) for simulated pixel boxes; others get the default.
OBJECT_WIDTH_M = {"door": 0.9, "window": 1.2, "table": 1.4, "plant": 0.5, "printer": 0.6}
DEFAULT_OBJECT_WIDTH_M = 0.6


@dataclass(frozen=True)
class CompassBias:
    """From ``start_s`` to ``end_s`` the compass reads ``bias_deg`` off (indoor steel)."""

    start_s: float
    end_s: float
    bias_deg: float


@dataclass(frozen=True)
class CornerVisit:
    """At ``start_s`` turn to face the nearest corner, hold ``hold_s`` seconds, turn back."""

    start_s: float
    hold_s: float


@dataclass(frozen=True)
class SimulationConfig:
    """A walk and everything that can go wrong on it. Angles in degrees, lengths in metres."""

    path: tuple[tuple[float, float], ...]
    speed_mps: float = 0.5
    rate_hz: float = 5.0
    turn_rate_deg_s: float = 90.0
    fov_deg: float = 360.0
    max_range_m: float = 15.0
    bearing_noise_deg: float = 2.0
    #: Score of true detections: drawn uniformly from this range (equal ends: constant).
    score_range: tuple[float, float] = (1.0, 1.0)
    #: Independent probability that a visible object is missed.
    miss_prob: float = 0.0
    #: The paper's "random amount lost each step, up to all": each frame draws a share.
    random_loss: bool = False
    #: Mean number of false detections per frame (Poisson), random class and bearing.
    false_rate: float = 0.0
    false_score_range: tuple[float, float] = (0.3, 0.7)
    #: Width of the blocked sector in front (degrees) while holding at a corner.
    blocked_sector_deg: float = 180.0
    corner_visits: tuple[CornerVisit, ...] = ()
    #: Extra time intervals (start_s, end_s) with the front sector blocked.
    blocked_intervals: tuple[tuple[float, float], ...] = ()
    odometry_noise_m: float = 0.02
    odometry_noise_deg: float = 1.0
    #: At this time the person is carried to ``kidnap_pose`` (x, y, theta_deg), no odometry.
    kidnap_at_s: float | None = None
    kidnap_pose: tuple[float, float, float] | None = None
    #: Stop after this long even if the path is not finished (None: walk to the end).
    duration_s: float | None = None
    #: A phone camera: its field of view replaces ``fov_deg`` (turned by its yaw and
    #: principal point), and :meth:`SimFrame.to_contract` can give pixel boxes.
    camera: Camera | None = None
    #: Compass noise std (degrees); None: the frames carry no compass heading.
    compass_std_deg: float | None = None
    #: Intervals when the compass is biased (magnetic disturbance).
    compass_biases: tuple[CompassBias, ...] = ()


@dataclass(frozen=True)
class SimFrame:
    """One simulated frame: what the app sends, plus the ground truth."""

    t: float
    truth: Pose
    odometry: Odometry | None
    detections: list[Detection] = field(default_factory=list)
    blocked: bool = False
    #: Angular width of each detection's object as seen (degrees), for pixel boxes.
    widths_deg: tuple[float, ...] = ()
    #: The compass reading (radians, CCW from +x) and its std (degrees), or None.
    compass_rad: float | None = None
    compass_std_deg: float | None = None

    def boxes(self, camera: Camera) -> list[tuple[float, float] | None]:
        """Each detection as a pixel box ``(u_min, u_max)`` of ``camera``, None out of view."""
        widths = self.widths_deg or (5.0,) * len(self.detections)
        return [
            camera.box_of(float(np.degrees(d.bearing_rad)), w)
            for d, w in zip(self.detections, widths, strict=True)
        ]

    def to_contract(self, camera: Camera | None = None) -> dict[str, object]:
        """The ``Frame`` JSON of docs/API.md, with the ground truth in ``truth``.

        With ``camera``, detections give pixel boxes (rounded to 0.1 pixel) instead of
        bearings; with a compass reading, the frame carries ``heading``.
        """
        odo = None
        if self.odometry is not None:
            odo = {
                "forward_m": round(self.odometry.forward_m, 5),
                "left_m": round(self.odometry.left_m, 5),
                "turn_deg": round(float(np.degrees(self.odometry.turn_rad)), 4),
            }
        dets: list[dict[str, object]] = []
        boxes = self.boxes(camera) if camera is not None else [None] * len(self.detections)
        for d, box in zip(self.detections, boxes, strict=True):
            if camera is None:
                where: dict[str, object] = {
                    "bearing_deg": round(float(np.degrees(d.bearing_rad)), 3)
                }
            elif box is None:
                continue
            else:
                where = {"box": {"u_min_px": round(box[0], 1), "u_max_px": round(box[1], 1)}}
            dets.append({"class": d.cls, **where, "score": round(d.score, 3)})
        out: dict[str, object] = {
            "timestamp": round(self.t, 3),
            "odometry": odo,
            "detections": dets,
            "describe": False,
            "truth": {
                "x": round(self.truth.x, 4),
                "y": round(self.truth.y, 4),
                "theta_deg": round(float(np.degrees(self.truth.theta_rad)), 3),
            },
        }
        if self.compass_rad is not None:
            out["heading"] = {
                "heading_deg": round(float(np.degrees(self.compass_rad)), 3),
                "std_deg": self.compass_std_deg,
            }
        return out


def _corners(semantic_map: SemanticMap) -> np.ndarray:
    """Points where walls meet (end points shared by two or more walls), shape (C, 2)."""
    ends = np.vstack([semantic_map.walls[:, 0:2], semantic_map.walls[:, 2:4]])
    keys, counts = np.unique(np.round(ends, 3), axis=0, return_counts=True)
    shared = keys[counts >= 2]
    return shared if shared.size else keys


def truth_poses(cfg: SimulationConfig, semantic_map: SemanticMap) -> list[tuple[Pose, bool, bool]]:
    """Ground-truth pose per frame, whether the view is blocked then, and whether the
    person was just carried there (kidnapped)."""
    dt = 1.0 / cfg.rate_hz
    step_turn = np.radians(cfg.turn_rate_deg_s) * dt
    pts = [np.array(p, dtype=np.float64) for p in cfg.path]
    pos = pts[0].copy()
    seg = 1
    heading = float(np.arctan2(*(pts[1] - pts[0])[::-1])) if len(pts) > 1 else 0.0
    corners = _corners(semantic_map) if semantic_map.walls.shape[0] else np.zeros((0, 2))
    visits = sorted(cfg.corner_visits, key=lambda v: v.start_s)
    phase, phase_end, target = "walk", 0.0, 0.0
    t = 0.0
    out: list[tuple[Pose, bool, bool]] = []
    kidnapped = False
    just_carried = False

    def turn_towards(goal: float) -> bool:
        nonlocal heading
        diff = float(wrap_angle(goal - heading))
        if abs(diff) <= step_turn:
            heading = float(wrap_angle(goal))
            return True
        heading = float(wrap_angle(heading + np.sign(diff) * step_turn))
        return False

    while True:
        blocked = phase == "hold" or any(a <= t < b for a, b in cfg.blocked_intervals)
        out.append((Pose(float(pos[0]), float(pos[1]), heading), blocked, just_carried))
        just_carried = False
        if cfg.duration_s is not None and t + dt > cfg.duration_s + 1e-9:
            break
        if phase == "walk" and seg >= len(pts):
            break
        t += dt
        if cfg.kidnap_at_s is not None and not kidnapped and t >= cfg.kidnap_at_s:
            kidnapped = True
            kx, ky, kt = cfg.kidnap_pose or (pts[0][0], pts[0][1], 0.0)
            pos = np.array([kx, ky], dtype=np.float64)
            heading = float(np.radians(kt))
            just_carried = True
            continue
        if phase == "walk" and visits and t >= visits[0].start_s and corners.size:
            visit = visits.pop(0)
            nearest = corners[np.argmin(np.hypot(*(corners - pos).T))]
            target = float(np.arctan2(nearest[1] - pos[1], nearest[0] - pos[0]))
            phase, phase_end = "to_corner", visit.hold_s
        if phase == "to_corner":
            if turn_towards(target):
                phase, phase_end = "hold", t + phase_end
            continue
        if phase == "hold":
            if t >= phase_end:
                phase = "walk"
            continue
        goal = pts[seg] - pos
        dist = float(np.hypot(*goal))
        if dist < 1e-9:
            seg += 1
            continue
        if not turn_towards(float(np.arctan2(goal[1], goal[0]))):
            continue
        move = min(cfg.speed_mps * dt, dist)
        pos = pos + goal / dist * move
        if move >= dist - 1e-12:
            seg += 1
    return out


def _odometry(prev: Pose, cur: Pose, cfg: SimulationConfig, rng: np.random.Generator) -> Odometry:
    dx, dy = cur.x - prev.x, cur.y - prev.y
    c, s = np.cos(prev.theta_rad), np.sin(prev.theta_rad)
    fwd = c * dx + s * dy + rng.normal(0.0, cfg.odometry_noise_m)
    left = -s * dx + c * dy + rng.normal(0.0, cfg.odometry_noise_m)
    turn = float(wrap_angle(cur.theta_rad - prev.theta_rad))
    turn += rng.normal(0.0, np.radians(cfg.odometry_noise_deg))
    return Odometry(float(fwd), float(left), float(turn))


def _detections(
    semantic_map: SemanticMap,
    pose: Pose,
    blocked: bool,
    cfg: SimulationConfig,
    camera: CameraModel,
    rng: np.random.Generator,
) -> tuple[list[Detection], list[float]]:
    """Noisy detections and each one's angular width (degrees)."""
    idx, bearing = visible_objects(semantic_map, pose, camera)
    keep = np.ones(idx.size, dtype=bool)
    if blocked:
        keep &= np.abs(bearing) > np.radians(cfg.blocked_sector_deg) / 2.0
    if cfg.miss_prob > 0.0:
        keep &= rng.random(idx.size) >= cfg.miss_prob
    if cfg.random_loss:
        keep &= rng.random(idx.size) >= rng.random()
    noisy = wrap_angle(bearing + rng.normal(0.0, np.radians(cfg.bearing_noise_deg), idx.size))
    lo, hi = cfg.score_range
    scores = rng.uniform(lo, hi, idx.size) if hi > lo else np.full(idx.size, lo)
    dist = np.hypot(*(semantic_map.object_xy[idx] - np.array([pose.x, pose.y])).T)
    dets, widths = [], []
    for i, b, sc, k, d in zip(idx, noisy, scores, keep, dist, strict=True):
        if k:
            cls = semantic_map.class_of(int(i))
            dets.append(Detection(cls, float(b), float(sc)))
            size = OBJECT_WIDTH_M.get(cls, DEFAULT_OBJECT_WIDTH_M)
            widths.append(float(np.degrees(2.0 * np.arctan2(size / 2.0, max(d, 0.3)))))
    n_false = int(rng.poisson(cfg.false_rate)) if cfg.false_rate > 0 else 0
    half = np.radians(min(camera.fov_deg, 360.0)) / 2.0
    centre = np.radians(camera.fov_centre_deg)
    for _ in range(n_false):
        cls = semantic_map.classes[int(rng.integers(len(semantic_map.classes)))]
        b = float(wrap_angle(centre + rng.uniform(-half, half)))
        dets.append(Detection(cls, b, float(rng.uniform(*cfg.false_score_range))))
        widths.append(float(rng.uniform(5.0, 30.0)))
    order = rng.permutation(len(dets))
    return [dets[i] for i in order], [widths[i] for i in order]


def _compass(t: float, pose: Pose, cfg: SimulationConfig, rng: np.random.Generator) -> float | None:
    """The compass reading at ``t``: truth plus noise plus any bias then (radians)."""
    if cfg.compass_std_deg is None:
        return None
    bias = sum(b.bias_deg for b in cfg.compass_biases if b.start_s <= t < b.end_s)
    noise = rng.normal(0.0, cfg.compass_std_deg)
    return float(wrap_angle(pose.theta_rad + np.radians(bias + noise)))


def simulate(
    semantic_map: SemanticMap, config: SimulationConfig, rng: np.random.Generator
) -> list[SimFrame]:
    """Frames of one walk: ground truth, noisy odometry and noisy detections.

    The first frame has no odometry (nothing came before it), and so has the frame
    right after a kidnap (the person was carried; no motion was measured).
    """
    # The compass draws from its own stream (spawning does not advance ``rng``): the same
    # seed then gives the same world with and without a compass, a paired comparison.
    compass_rng = rng.spawn(1)[0] if config.compass_std_deg is not None else rng
    camera = CameraModel(config.fov_deg, config.max_range_m)
    if config.camera is not None:
        camera = CameraModel(
            config.camera.fov_deg, config.max_range_m, config.camera.fov_centre_deg
        )
    truth = truth_poses(config, semantic_map)
    frames: list[SimFrame] = []
    dt = 1.0 / config.rate_hz
    for i, (pose, blocked, jumped) in enumerate(truth):
        t = i * dt
        odo = None if i == 0 or jumped else _odometry(truth[i - 1][0], pose, config, rng)
        dets, widths = _detections(semantic_map, pose, blocked, config, camera, rng)
        frames.append(
            SimFrame(
                round(t, 6),
                pose,
                odo,
                dets,
                blocked,
                tuple(widths),
                _compass(t, pose, config, compass_rng),
                config.compass_std_deg,
            )
        )
    return frames
