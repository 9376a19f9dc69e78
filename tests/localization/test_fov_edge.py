"""The field of view's soft edge in the filter's weights (models.FOV_EDGE_STDS), and the
evidence tracker's hard one."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.models import FOV_EDGE_STDS, BearingSensorModel
from app.localization.types import Detection
from app.maps.check import load_map
from app.resources import bundled_maps_dir
from app.simulation.scenarios import paper_config
from app.simulation.simulator import simulate

OFFICE = load_map(bundled_maps_dir() / "paper_office.json")
FOV = 66.0
CONFIG = FilterConfig(particles=500, fov_deg=FOV, bearing_std_deg=2.0)
MARGIN = FOV_EDGE_STDS * CONFIG.bearing_std_deg


def _pose_seeing(obj: int, bearing_deg: float) -> tuple[float, float, float]:
    """A pose 1.5 m from object ``obj``, in line of sight, that has it at ``bearing_deg``."""
    ox, oy = OFFICE.object_xy[obj]
    for a in np.radians(np.arange(0.0, 360.0, 10.0)):
        x, y = ox - 1.5 * math.cos(a), oy - 1.5 * math.sin(a)
        if bool(OFFICE.free_space.is_free(x, y)) and OFFICE.line_of_sight([[x, y]])[0, obj]:
            return x, y, float(a - math.radians(bearing_deg))
    raise AssertionError("no pose sees the object")


def _score(model: BearingSensorModel, pose: tuple[float, float, float], det: Detection) -> float:
    obs = model.observe([det])
    x, y, t = (np.array([v]) for v in pose)
    return float(model.log_likelihood(x, y, t, obs)[0])


def test_an_object_just_beyond_the_edge_still_explains_a_detection_at_it() -> None:
    soft = BearingSensorModel(OFFICE, CONFIG, OFFICE.visibility, fov_margin_deg=MARGIN)
    hard = BearingSensorModel(OFFICE, CONFIG, OFFICE.visibility)
    obj = 0
    cls = OFFICE.class_of(obj)
    edge = FOV / 2.0
    # The camera reports the object at its edge; from this pose it lies half a margin
    # beyond it: the hard edge takes the detection for clutter, the soft one for it.
    pose = _pose_seeing(obj, edge + MARGIN / 2.0)
    det = Detection(cls, math.radians(edge - 0.5), 0.9)
    assert _score(soft, pose, det) > _score(hard, pose, det) + 1.0
    # Beyond the margin, both take it for clutter; well inside the edge, both match.
    far = _pose_seeing(obj, edge + 2.0 * MARGIN + 3.0)
    assert _score(soft, far, det) == _score(hard, far, det)
    inside = _pose_seeing(obj, edge - 5.0)
    inner = Detection(cls, math.radians(edge - 5.0), 0.9)
    assert _score(soft, inside, inner) == _score(hard, inside, inner)


def test_the_filter_weighs_with_the_soft_edge_and_the_tracker_with_the_hard_one() -> None:
    pf = ParticleFilter(OFFICE, CONFIG, rng=np.random.default_rng(0))
    assert isinstance(pf.sensor, BearingSensorModel)
    assert pf.sensor.fov_margin_deg == MARGIN
    assert pf.evidence is not None
    assert isinstance(pf.evidence.sensor, BearingSensorModel)
    assert pf.evidence.sensor.fov_margin_deg == 0.0
    # A moved object leaves both.
    pf._exclude_from_models([2])
    assert pf.sensor.excluded == pf.evidence.sensor.excluded == (2,)
    # A 360-degree camera has no edge: one model.
    wide = ParticleFilter(OFFICE, replace(CONFIG, fov_deg=360.0), rng=np.random.default_rng(0))
    assert wide.evidence is not None and wide.evidence.sensor is wide.sensor


def test_a_narrow_cameras_weights_no_longer_favour_poses_behind_the_person() -> None:
    """At the true pose of each frame of a walk (every detection exact up to 2 deg of
    noise, a 66 deg camera), what a pose 0.1 m ahead and 0.1 m behind lose."""
    frames = simulate(OFFICE, paper_config("nominal", FOV), np.random.default_rng(4))[:400]
    soft = BearingSensorModel(OFFICE, CONFIG, OFFICE.visibility, fov_margin_deg=MARGIN)
    hard = BearingSensorModel(OFFICE, CONFIG, OFFICE.visibility)
    loss = {"soft": np.zeros(2), "hard": np.zeros(2)}
    for f in frames:
        if not f.detections:
            continue
        c, s = math.cos(f.truth.theta_rad), math.sin(f.truth.theta_rad)
        x = np.array([f.truth.x, f.truth.x + 0.1 * c, f.truth.x - 0.1 * c])
        y = np.array([f.truth.y, f.truth.y + 0.1 * s, f.truth.y - 0.1 * s])
        t = np.full(3, f.truth.theta_rad)
        for name, model in (("soft", soft), ("hard", hard)):
            ll = model.log_likelihood(x, y, t, model.observe(f.detections))
            loss[name] += ll[0] - ll[1:]
    ahead_hard, behind_hard = loss["hard"]
    ahead_soft, behind_soft = loss["soft"]
    # The hard edge charges a pose ahead far more than one behind ...
    assert ahead_hard > 2.0 * behind_hard
    # ... the soft edge charges it much less (what is left is the bearings' own
    # geometry, and the objects a pose behind sees unreported, which cost nothing).
    assert ahead_soft < 0.75 * ahead_hard
    assert ahead_soft - behind_soft < 0.75 * (ahead_hard - behind_hard)
