"""The narrator's objects: the sensor model's own correspondence (eq. 3) at the estimate.

The narrator matches detections at one pose with its own few array operations; these
tests hold its choices to those of :func:`app.localization.sensor.match_detections`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.feedback import Narrator
from app.localization.config import FilterConfig
from app.localization.sensor import match_detections, prepare_observation
from app.localization.types import Detection, Estimate, Hypothesis
from app.maps.model import SemanticMap, parse_map
from tests.feedback.test_narrator import TWO_OFFICES
from tests.helpers import paper_office


def sensor_model_order(
    m: SemanticMap, est: Estimate, dets: list[Detection], fov_deg: float, centre_deg: float
) -> list[int]:
    """Matched objects (nearest first), then the nearest visible others, with the
    correspondence from the sensor model's functions."""
    visible = m.visibility.row(est.x, est.y)
    dist = np.hypot(*(m.object_xy - np.array([est.x, est.y])).T)
    matched: list[int] = []
    if dets:
        config = FilterConfig(fov_deg=fov_deg, visibility=True, max_range_m=None)
        centre = math.radians(centre_deg)
        turned = [Detection(d.cls, d.bearing_rad - centre, d.score) for d in dets]
        _, index = match_detections(
            np.array([est.x]),
            np.array([est.y]),
            np.array([est.theta_rad + centre]),
            prepare_observation(turned, m, config),
            m,
            config,
            visible[None, :],
        )
        matched = list(dict.fromkeys(int(i) for i in index[:, 0] if i >= 0))
    matched.sort(key=lambda i: dist[i])
    others = np.argsort(dist, kind="stable")  # the first object on a tie
    return matched + [int(i) for i in others if visible[i] and i not in matched]


def pose(x: float, y: float, theta: float) -> Estimate:
    return Estimate(x, y, theta, 0.05, 0.05, 0.03, True, (Hypothesis(x, y, theta, 1.0),), 1000)


@pytest.mark.parametrize("m", [TWO_OFFICES, paper_office()], ids=lambda m: m.name)
def test_same_objects_as_the_sensor_model(m: SemanticMap) -> None:
    rng = np.random.default_rng(11)
    lo_x, lo_y, hi_x, hi_y = m.bounds
    for k in range(600):
        if k % 5 == 0:  # standing on an object
            x, y = m.object_xy[rng.integers(m.object_count)].tolist()
        else:
            x, y = rng.uniform(lo_x, hi_x), rng.uniform(lo_y, hi_y)
        theta = rng.uniform(-4.0, 4.0)
        dets = []
        for _ in range(rng.integers(0, 8)):
            cls = m.classes[rng.integers(len(m.classes))]
            target = m.object_xy[rng.choice(m.class_members[cls])]
            aimed = math.atan2(target[1] - y, target[0] - x) - theta
            bearing = aimed if rng.random() < 0.5 else rng.uniform(-math.pi, math.pi)
            dets.append(Detection(cls, bearing, 1.0))
        fov = (360.0, 180.0, 90.0)[k % 3]
        centre = (0.0, 30.0, -170.0)[k % 3 if k % 2 else 0]
        order, _, _ = Narrator(m)._ordered_objects(pose(x, y, theta), dets, (fov, centre))
        assert order == sensor_model_order(m, pose(x, y, theta), dets, fov, centre), k
        # Given the filter's observation of the same detections (with some the filter
        # leaves out: a class the map lacks, a zero score), the very same answer.
        given = [*dets, Detection("unicorn", 0.3, 1.0), Detection(m.classes[0], 0.1, 0.0)]
        rng.shuffle(given)
        obs = prepare_observation(given, m, FilterConfig())
        plain = Narrator(m)._ordered_objects(pose(x, y, theta), given, (fov, centre))
        got = Narrator(m)._ordered_objects(pose(x, y, theta), given, (fov, centre), obs)
        assert got[0] == plain[0], k
        assert np.array_equal(got[1], plain[1]) and np.array_equal(got[2], plain[2]), k


def test_a_tie_goes_to_the_first_object() -> None:
    """Two windows mirror each other about the detected bearing: both fit it equally."""
    m = parse_map(
        {
            "name": "mirror",
            "objects": [
                {"class": "door", "x": -3, "y": 0},
                {"class": "window", "x": 2, "y": 1, "label": "first"},
                {"class": "window", "x": 2, "y": -1, "label": "second"},
            ],
        }
    )
    dets = [Detection("window", 0.0)]
    order, _, _ = Narrator(m)._ordered_objects(pose(0.0, 0.0, 0.0), dets, (360.0, 0.0))
    assert order[0] == 1 == sensor_model_order(m, pose(0.0, 0.0, 0.0), dets, 360.0, 0.0)[0]
    fb = Narrator(m).update(pose(0.0, 0.0, 0.0), dets, timestamp_s=0.0)
    assert fb.items[0].label == "first"
