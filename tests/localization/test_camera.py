"""Camera models: pixel boxes to bearings (both models, the 360-degree seam, the yaw
offset), the field of view they imply, and that the filter honours it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.localization.camera import BoxError, Camera
from app.localization.config import FilterConfig
from app.localization.types import Detection, Pose
from app.simulation.camera import CameraModel, visible_objects
from tests.helpers import room
from tests.localization.test_sensor import loglik

EQUI = Camera("equirectangular", 3840)
#: fx = cx = W/2: the image edges are exactly 45 degrees off the axis.
PIN = Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0)
#: Column of a 30-degree bearing on PIN: cx - fx * tan(30 deg).
U30 = 1000.0 - 1000.0 * math.tan(math.radians(30.0))

# camera, u_min, u_max, expected bearing (degrees)
CASES = [
    (EQUI, 1900, 1940, 0.0),  # centre column: straight ahead
    (EQUI, 950, 970, 90.0),  # a quarter to the left of centre: left
    (EQUI, 2870, 2890, -90.0),  # a quarter to the right: right
    (EQUI, 0, 0, 180.0),  # the left edge is straight behind
    (EQUI, 3840, 3840, 180.0),  # and so is the right edge (+180, not -180)
    (EQUI, 3800, 40, 180.0),  # wraps the seam: centre on the edge, behind
    (EQUI, 3700, 100, -178.125),  # wraps: centre 3820, just right of behind
    (EQUI, 3790, 150, 175.3125),  # wraps: centre 50, just left of behind
    (EQUI, 3800, 3840, -178.125),  # touches the edge without wrapping
    (Camera("equirectangular", 1000), 200, 300, 90.0),  # any width
    (Camera("equirectangular", 3840, yaw_offset_deg=30.0), 1900, 1940, 30.0),  # yaw
    (Camera("equirectangular", 3840, yaw_offset_deg=30.0), 3800, 40, -150.0),  # yaw + seam
    (Camera("equirectangular", 3840, yaw_offset_deg=-90.0), 950, 970, 0.0),
    (PIN, 990, 1010, 0.0),
    (PIN, 0, 0, 45.0),
    (PIN, 2000, 2000, -45.0),
    (PIN, 0, 2000, 0.0),
    (PIN, U30 - 40, U30 + 40, 30.0),
    (PIN, 2000 - U30 - 40, 2000 - U30 + 40, -30.0),
    (Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0, yaw_offset_deg=90.0), 0, 0, 135.0),
    (Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0, yaw_offset_deg=-170.0), 0, 0, -125.0),
    (Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0, yaw_offset_deg=150.0), 0, 0, -165.0),
    (
        Camera("pinhole", 1920, fx_px=1480.0, cx_px=960.0),
        812,
        901,
        math.degrees(math.atan(103.5 / 1480)),
    ),
]


@pytest.mark.parametrize(("camera", "u_min", "u_max", "expected"), CASES)
def test_box_gives_the_known_bearing(camera: Camera, u_min, u_max, expected: float) -> None:
    got = camera.box_bearing_deg(u_min, u_max)
    # Wrapped to (-180, 180]; float arithmetic on pixel columns (1e-9 degrees is ~1e5 ulps).
    assert -180.0 < got <= 180.0
    assert got == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize(
    ("camera", "fov", "centre"),
    [
        (EQUI, 360.0, 0.0),
        (Camera("equirectangular", 3840, yaw_offset_deg=45.0), 360.0, 0.0),
        (PIN, 90.0, 0.0),
        (Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0, yaw_offset_deg=90.0), 90.0, 90.0),
        # Principal point off-centre: 45 deg to the left, atan(1.5) to the right.
        (
            Camera("pinhole", 2500, fx_px=1000.0, cx_px=1000.0),
            45.0 + math.degrees(math.atan(1.5)),
            (45.0 - math.degrees(math.atan(1.5))) / 2.0,
        ),
    ],
)
def test_field_of_view_follows_from_the_camera(camera: Camera, fov: float, centre: float) -> None:
    assert camera.fov_deg == pytest.approx(fov, abs=1e-9)
    assert camera.fov_centre_deg == pytest.approx(centre, abs=1e-9)


@pytest.mark.parametrize(
    ("camera", "u_min", "u_max", "words"),
    [
        (EQUI, -1, 10, "u_min_px"),
        (EQUI, 10, 3841, "u_max_px"),
        (PIN, 1200, 800, "only a 360-degree"),
        (PIN, float("nan"), 800, "outside the image"),
    ],
)
def test_bad_boxes_are_refused_with_a_reason(camera, u_min, u_max, words: str) -> None:
    with pytest.raises(BoxError, match=words):
        camera.box_bearing_deg(u_min, u_max)


@pytest.mark.parametrize(
    "camera",
    [
        EQUI,
        Camera("equirectangular", 3840, yaw_offset_deg=-60.0),
        PIN,
        Camera("pinhole", 1920, fx_px=1480.0, cx_px=900.0, yaw_offset_deg=20.0),
    ],
)
@pytest.mark.parametrize("bearing", [0.0, 12.5, -30.0, 40.0, 179.0, -179.0])
def test_simulated_boxes_give_their_bearing_back(camera: Camera, bearing: float) -> None:
    box = camera.box_of(bearing, 8.0)
    off = abs((bearing - camera.fov_centre_deg + 180.0) % 360.0 - 180.0)
    if off > camera.fov_deg / 2.0:
        assert box is None
        return
    assert box is not None
    u_min, u_max = box
    if camera.model == "pinhole" and (u_min == 0.0 or u_max == camera.width_px):
        return  # cut at the image edge, as a detector's box is
    assert camera.box_bearing_deg(u_min, u_max) == pytest.approx(bearing, abs=1e-9)


def test_camera_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="fx_px"):
        Camera("pinhole", 1920)
    with pytest.raises(ValueError, match="width_px"):
        Camera("equirectangular", 0)


# ------------------------------------------------------- the filter's field of view
#: Door straight ahead of a person at (3, 2) facing +x; window to their left.
AHEAD_AND_LEFT = room([{"class": "door", "x": 6, "y": 2}, {"class": "window", "x": 3, "y": 4}])
#: A 90-degree phone camera turned to the person's left.
LEFT_CAM = Camera("pinhole", 2000, fx_px=1000.0, cx_px=1000.0, yaw_offset_deg=90.0)


def _config(camera: Camera, **kw: object) -> FilterConfig:
    return FilterConfig(fov_deg=camera.fov_deg, fov_centre_deg=camera.fov_centre_deg, **kw)


@pytest.mark.parametrize("kernel", [True, False], ids=["kernel", "reference"])
def test_a_pinhole_field_of_view_limits_what_the_filter_expects(kernel: bool) -> None:
    m = AHEAD_AND_LEFT
    pose = (3.0, 2.0, 0.0)
    door_ahead = [Detection("door", 0.0)]
    window_left = [Detection("window", math.pi / 2)]
    wide = FilterConfig(clutter=False)
    narrow_left = _config(LEFT_CAM, clutter=False)
    narrow_ahead = _config(PIN, clutter=False)
    # A 360-degree camera may see both.
    assert loglik(m, wide, *pose, door_ahead, kernel=kernel)[0] == pytest.approx(0.0, abs=1e-3)
    # The camera turned left cannot see the door ahead: nothing explains that detection...
    assert loglik(m, narrow_left, *pose, door_ahead, kernel=kernel)[0] == -np.inf
    # ... but it sees the window on the left, at the bearing the body frame gives it.
    got = loglik(m, narrow_left, *pose, window_left, kernel=kernel)[0]
    assert got == pytest.approx(0.0, abs=1e-3)
    # The same camera pointing ahead sees the door and not the window.
    assert loglik(m, narrow_ahead, *pose, door_ahead, kernel=kernel)[0] == pytest.approx(
        0.0, abs=1e-3
    )
    assert loglik(m, narrow_ahead, *pose, window_left, kernel=kernel)[0] == -np.inf


def test_kernel_and_reference_agree_with_a_turned_field_of_view() -> None:
    m = room(
        [
            {"class": "door", "x": 6, "y": 3},
            {"class": "window", "x": 1.5, "y": 0},
            {"class": "window", "x": 4.5, "y": 0},
            {"class": "table", "x": 2, "y": 2.5},
        ]
    )
    rng = np.random.default_rng(3)
    pts = m.free_space.sample(2000, rng)
    th = rng.uniform(-np.pi, np.pi, 2000)
    cam = Camera("pinhole", 1920, fx_px=900.0, cx_px=700.0, yaw_offset_deg=-35.0)
    cfg = _config(cam)
    dets = [Detection("door", 0.3), Detection("window", -1.0), Detection("table", 2.0)]
    fast = loglik(m, cfg, pts[:, 0], pts[:, 1], th, dets)
    slow = loglik(m, cfg, pts[:, 0], pts[:, 1], th, dets, kernel=False)
    # The kernel works in float32 (sensor_kernel's docstring): 1e-3 where weights matter.
    near = np.isfinite(slow) & (slow > -50)
    assert np.allclose(fast[near], slow[near], atol=1e-3)


def test_the_simulated_camera_sees_only_its_field() -> None:
    m = AHEAD_AND_LEFT
    pose = Pose(3.0, 2.0, 0.0)
    left = CameraModel(LEFT_CAM.fov_deg, 15.0, LEFT_CAM.fov_centre_deg)
    idx, bearing = visible_objects(m, pose, left)
    assert [m.class_of(int(i)) for i in idx] == ["window"]
    assert bearing[0] == pytest.approx(math.pi / 2)
