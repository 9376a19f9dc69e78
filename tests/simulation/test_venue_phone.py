"""A real phone's effects on the venue's walks (simulate_venue_phone), and the venue
suite's phone condition filtered as the service filters a session."""

from __future__ import annotations

import numpy as np
import pytest

from app.localization.types import Odometry
from app.maps.geometry import wrap_angle
from app.simulation.phone import PhoneEffects, PhoneFrame, vio_phone
from app.simulation.simulator import SimulationConfig
from app.simulation.venue import venue_legs, venue_map
from app.simulation.venue_walk import Barometer, VenueFrame, simulate_venue, simulate_venue_phone

MAP = venue_map()
START, LEGS = venue_legs()


def walk(effects: PhoneEffects, seed: int = 2, **config: object) -> list[VenueFrame]:
    cfg = SimulationConfig(path=((0.0, 0.0),), **config)  # type: ignore[arg-type]
    return simulate_venue_phone(MAP, START, LEGS, cfg, effects, np.random.default_rng(seed))


def test_without_effects_the_phone_walks_the_venue_walk() -> None:
    fs = walk(PhoneEffects(), bearing_noise_deg=0.0)
    plain = simulate_venue(
        MAP, START, LEGS, SimulationConfig(path=((0.0, 0.0),)), np.random.default_rng(2)
    )
    assert len(fs) == len(plain)  # nothing dropped
    layout = MAP.layout
    for vf, ref in zip(fs, plain, strict=True):
        f = vf.frame
        assert isinstance(f, PhoneFrame) and f.detections_age_s is None
        assert (vf.level, vf.leg, vf.riding, vf.file_pose) == (
            ref.level,
            ref.leg,
            ref.riding,
            ref.file_pose,
        )
        # The truth is in the plane, on the true level; the barometer reads the same.
        assert f.truth == ref.frame.truth
        assert f.truth.x == vf.file_pose.x + float(layout.offsets(vf.level))
        assert vf.altitude == ref.altitude
        # Every detection is of an object on the true level, at its bearing.
        for d, s in zip(f.detections, f.sources, strict=True):
            assert int(layout.level_of_plane_x(MAP.object_xy[s, 0])) == vf.level
            dx, dy = MAP.object_xy[s] - (f.truth.x, f.truth.y)
            true = wrap_angle(np.arctan2(dy, dx) - f.truth.theta_rad)
            assert abs(float(wrap_angle(d.bearing_rad - true))) < 1e-9


def _composed(odometry: list[Odometry | None]) -> tuple[float, float, float]:
    x = y = th = 0.0
    for o in odometry:
        assert o is not None
        x += np.cos(th) * o.forward_m - np.sin(th) * o.left_m
        y += np.sin(th) * o.forward_m + np.cos(th) * o.left_m
        th += o.turn_rad
    return x, y, th


def test_the_odometry_never_sees_a_level_and_dropped_frames_carry_their_motion() -> None:
    ideal = PhoneEffects(drop_prob=0.1)
    fs = walk(ideal)
    assert sum(vf.frame.dropped_before for vf in fs) > 20  # type: ignore[attr-defined]
    assert fs[0].frame.odometry is None
    # Noise-free odometry (no grade: the walk's, set to 0) composes to the file-frame walk
    # across every ride, a lift's included.
    exact = walk(ideal, odometry_noise_m=0.0, odometry_noise_deg=0.0)
    x, y, th = _composed([vf.frame.odometry for vf in exact[1:]])
    first, last = exact[0].file_pose, exact[-1].file_pose
    c, s = np.cos(first.theta_rad), np.sin(first.theta_rad)
    dx, dy = last.x - first.x, last.y - first.y
    assert np.hypot(x - (c * dx + s * dy), y - (-s * dx + c * dy)) < 1e-6
    assert abs(float(wrap_angle(th - (last.theta_rad - first.theta_rad)))) < 1e-6


def test_a_real_phone_on_the_venue_sways_while_striding_only_and_says_its_latency() -> None:
    still = walk(PhoneEffects())
    fs = walk(PhoneEffects(sway_deg=8.0))
    kinds = [getattr(leg, "kind", "walk") for leg in LEGS]
    swayed = {
        kinds[vf.leg]
        for vf, ref in zip(fs, still, strict=True)
        if abs(float(wrap_angle(vf.frame.truth.theta_rad - ref.frame.truth.theta_rad))) > 1e-9
    }
    assert "walk" in swayed and "stairs" in swayed
    assert not swayed & {"elevator", "escalator"}
    every = walk(vio_phone())
    ages = [vf.frame.detections_age_s for vf in every]  # type: ignore[attr-defined]
    assert all(a is not None and 0.1 <= a <= 0.3 for a in ages)
    assert len(every) < len(still)  # dropped frames
    assert all(vf.altitude is not None for vf in every)


def test_no_barometer_no_altitude() -> None:
    cfg = SimulationConfig(path=((0.0, 0.0),))
    fs = simulate_venue_phone(
        MAP, START, LEGS, cfg, PhoneEffects(), np.random.default_rng(0), barometer=None
    )
    assert all(vf.altitude is None for vf in fs)
    noisy = simulate_venue_phone(
        MAP, START, LEGS, cfg, PhoneEffects(), np.random.default_rng(0), Barometer(noise_m=0.4)
    )
    assert all(vf.altitude is not None for vf in noisy)


def test_a_walk_through_a_wall_is_refused_with_the_stretch_that_crosses_it() -> None:
    """A walking leg drawn by hand through a wall of its level (here the riverside
    station's newsstand, a kiosk on the Ground Floor's corridor) is no walk anybody
    can make: the simulator says which leg, which stretch and which level."""
    from app.maps.check import load_map
    from app.resources import bundled_maps_dir
    from app.simulation.venue_walk import Walk

    station = load_map(bundled_maps_dir() / "riverside_station.json")
    cfg = SimulationConfig(path=((0.0, 0.0),))
    through = [Walk(((-2.5, 0.0), (15.0, 0.0)))]
    with pytest.raises(ValueError, match=r"walk leg 0: the stretch from \(-2\.5, 0\.0\) to "
                       r"\(15\.0, 0\.0\) crosses a wall of level L0"):  # fmt: skip
        simulate_venue(station, "L0", through, cfg, np.random.default_rng(0))
    around = [Walk(((-2.5, 1.5), (15.0, 1.5)))]
    frames = simulate_venue(station, "L0", around, cfg, np.random.default_rng(0))
    assert frames[-1].frame.truth.x - frames[0].frame.truth.x > 17.0


@pytest.mark.parametrize("phone", [False, True])
def test_a_lift_car_moves_with_its_doors_shut(phone: bool) -> None:
    """While the lift moves, its rider sees none of the floors it passes (before, the
    simulated car showed each of them through its doorway); while the doors are open,
    before and after, the floor the car stands at is in view, and the stairs and
    escalators are ridden in full view."""
    cfg: dict[str, object] = {"miss_prob": 0.0, "false_rate": 0.0}
    if phone:
        frames = walk(PhoneEffects(), **cfg)
    else:
        sim = SimulationConfig(path=((0.0, 0.0),), **cfg)  # type: ignore[arg-type]
        frames = simulate_venue(MAP, START, LEGS, sim, np.random.default_rng(2))
    kinds = [getattr(leg, "kind", "walk") for leg in LEGS]
    lift = [vf for vf in frames if vf.riding and kinds[vf.leg] == "elevator"]
    # The car moves from the first frame off the Ground Floor's altitude to the first at
    # the Second Floor's (9 m), doors shut.
    off = next(i for i, vf in enumerate(lift) if vf.true_altitude_m > 0.0)
    at = next(i for i, vf in enumerate(lift) if vf.true_altitude_m == 9.0)
    moving, waiting = lift[off : at + 1], lift[:off] + lift[at + 1 :]
    assert len(moving) > 30 and len({vf.level for vf in moving}) == 3  # passes the First
    assert all(not vf.frame.detections for vf in moving)
    assert len(waiting) > 20 and all(vf.frame.detections for vf in waiting)
    others = [vf for vf in frames if vf.riding and kinds[vf.leg] != "elevator"]
    assert sum(bool(vf.frame.detections) for vf in others) > 0.9 * len(others)
